// brume — the sky commands' pipelines: `brume sky render` (files out) and
// `brume sky fit` (image in, JSON and an optional scatter plot out), with
// their declared parameters (include/brume/sky.hpp).
#include <cstdio>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <cctype>
#include <fstream>
#include <set>
#include <unistd.h>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/gpu_sky.hpp"
#include "brume/record.hpp"
#include "brume/sky.hpp"
#include "effects/sky/sky_job.hpp"

namespace brume {

namespace fs = std::filesystem;

namespace {


nlohmann::json sun_json(const SunFound& s) {
  nlohmann::json j = {{"zenith_deg", s.direction.zenith_deg}, {"azimuth_deg", s.direction.azimuth_deg}, {"source", s.source}};
  if (!s.record.is_null())
    for (auto it = s.record.begin(); it != s.record.end(); ++it) j[it.key()] = it.value();
  return j;
}

}  // namespace

// ---- render -----------------------------------------------------------------------------
const ParamTable<SkyRenderParams>& sky_render_param_table() {
  static const ParamTable<SkyRenderParams> t = [] {
    ParamTable<SkyRenderParams> d("sky");
    d.real("turbidity", &SkyRenderParams::turbidity, "1", Range::closed(kSkyTurbidityMin, kSkyTurbidityMax),
           "atmospheric turbidity T (Preetham's model is valid on [1.7, 20])")
        .nest(&SkyRenderParams::sun, sun_param_table())
        .nest(&SkyRenderParams::view, sky_view_param_table())
        .integer("width", &SkyRenderParams::width, "px", Range::closed(1, 65536), "image width")
        .integer("height", &SkyRenderParams::height, "px", Range::closed(1, 65536), "image height")
        .rgb("ground", &SkyRenderParams::ground, "1", Range::at_least(0.0),
             "linear RGB below the horizon; none: NaN there", "none")
        .boolean("sun-disc", &SkyRenderParams::sun_disc, "draw the sun's disc (the Preetham model has none)")
        .real("sun-disc-radius", &SkyRenderParams::sun_disc_radius_deg, "deg", Range::left_open(0.0, 10.0),
              "angular radius of the drawn disc (point-sampled at pixel centres)")
        .real("sun-luminance", &SkyRenderParams::sun_luminance_kcd, "kcd/m^2", Range::above(0.0),
              "luminance of the drawn disc (the sun: about 1.6e6 kcd/m^2)")
        .real("exposure", &SkyRenderParams::exposure, "1", Range::above(0.0),
              "multiplies every value (1: linear sRGB in kcd/m^2)");
    return d;
  }();
  return t;
}

const ParamTable<SkyRenderJob>& sky_render_job_table() {
  static const ParamTable<SkyRenderJob> t = [] {
    ParamTable<SkyRenderJob> d("sky render");
    d.nest(&SkyRenderJob::sky, sky_render_param_table()).nest(&SkyRenderJob::output, output_param_table({}));
    return d;
  }();
  return t;
}

SkyRenderRun run_sky_render(const SkyRenderParams& p, const Exec& exec) {
  sky_render_param_table().validate(p);
  check_sky_turbidity(p.turbidity);
  if (p.sun.sun == "auto") throw Error("--sun auto finds the sun in a photo (brume sky fit); to render, give --sun-zenith/--sun-azimuth or --date --latitude --longitude");
  const SkyGeometry g = sky_geometry(p.view, p.width, p.height);
  const SunFound sun = resolve_sun(p.sun, nullptr, false, &g);
  // The backend rules of every effect (choose_backend): --backend auto takes a
  // hardware GPU, never a software rasteriser.
  BackendChoice backend = choose_backend(exec);
  const auto t0 = std::chrono::steady_clock::now();
  SkyRenderRun run;
  nlohmann::json timing;
  if (backend.gpu) {
    GpuTiming gt;
    run.rgb = render_sky_gpu(*backend.gpu, p, sun.direction, g, &gt);
    timing = gpu_timing_record(gt);
  } else {
    run.rgb = render_sky(p, sun.direction, g, exec);
    timing = cpu_timing_record(t0, 0);
  }
  run.record["sky"] = {{"model", "Preetham, Shirley, Smits 1999 (Perez 1993 distribution)"},
                       {"units", "linear sRGB (D65), kcd/m^2 times --exposure"},
                       {"sun", sun_json(sun)},
                       {"zenith", {{"Y_kcd_m2", sky_zenith(p.turbidity, sun.direction.zenith_deg * 3.14159265358979323846 / 180).Y_kcd}}}};
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  return run;
}

nlohmann::json run_sky_render_job(const SkyRenderJob& job, const ExecOptions& eo, const RunContext& ctx) {
  sky_render_job_table().validate(job);
  const SkyRenderParams& p = job.sky;
  check_sky_turbidity(p.turbidity);
  if (p.sun.sun == "auto") throw Error("--sun auto finds the sun in a photo (brume sky fit); to render, give --sun-zenith/--sun-azimuth or --date --latitude --longitude");
  const SkyGeometry g = sky_geometry(p.view, p.width, p.height);
  resolve_sun(p.sun, nullptr, false, &g);  // every sun error before any output check, as before
  const Exec exec = eo.exec();
  check_outputs(job.output, {});
  if (job.output.keep_layers)
    throw Error("--keep-layers keeps the layers of an input image, and brume sky render reads none; drop --keep-layers");
  SkyRenderRun run = run_sky_render(p, exec);
  const nlohmann::json rec =
      job_record("sky render", ctx, sky_render_job_table().to_json(job), nlohmann::json::object(), run.record, eo.timing);
  write_outputs(job.output, {}, run.rgb, {}, nullptr, rec);
  return rec;
}

// ---- fit --------------------------------------------------------------------------------
const ParamTable<SkyFitOptions>& sky_fit_param_table() {
  static const ParamTable<SkyFitOptions> t = [] {
    ParamTable<SkyFitOptions> f("fit");
    f.integer("samples", &SkyFitOptions::samples, "1", Range::closed(10, 100000), "sky samples per sampling")
        .count("seed", &SkyFitOptions::seed, "1", Range::at_least(0.0), "random seed (same seed, same result)")
        .integer("repeats", &SkyFitOptions::repeats, "1", Range::closed(1, 100),
                 "independent samplings; the median is reported, their spread as turbidity_spread")
        .integer("ransac-iterations", &SkyFitOptions::ransac_iterations, "1", Range::closed(1, 10000),
                 "RANSAC hypotheses per sampling")
        .real("inlier-threshold", &SkyFitOptions::inlier_threshold, "1", Range::left_open(0.0, 2.0),
              "|log(measured/model)| of an inlier (0.1: 10 %)")
        .real("sun-exclusion", &SkyFitOptions::sun_exclusion_deg, "deg", Range::closed(0.0, 89.0),
              "samples at least this far from the sun (its disc, glare and lens flare)")
        .real("max-zenith", &SkyFitOptions::max_zenith_deg, "deg", Range::left_open(0.0, 90.0),
              "samples at most this far from the zenith (the horizon: ground, trees, haze layers)");
    return f;
  }();
  return t;
}

const ParamTable<SkyFitJob>& sky_fit_job_table() {
  static const ParamTable<SkyFitJob> t = [] {
    ParamTable<SkyFitJob> d("sky fit");
    d.text("image", &SkyFitJob::image, "the sky photo (HDR/EXR linear; PNG/JPEG/TIFF sRGB unless --image-transfer)")
        .reads_file()
        .text("image-layer", &SkyFitJob::image_layer,
              "the layer of a file with layers read as the photo (NAME.R, NAME.G, NAME.B of a multilayer OpenEXR); "
              "empty: the plain R, G, B, or the file's only colour layer");
    transfer_param(d, "image-transfer", &SkyFitJob::image_transfer, "the photo")
        .text("mask", &SkyFitJob::mask, "grey image of the same size: > half scale marks usable sky (default: all)")
        .reads_file()
        .nest(&SkyFitJob::view, sky_view_param_table())
        .nest(&SkyFitJob::sun, sun_param_table())
        .nest(&SkyFitJob::fit, sky_fit_param_table())
        .text("out", &SkyFitJob::out, "the fit as JSON (turbidity, spread, sun, inliers, residual, reliable, samples)")
        .writes_file()
        .text("plot", &SkyFitJob::plot, "PNG scatter of measured against model luminance (Morales Fig. 2.5)")
        .writes_file();
    return d;
  }();
  return t;
}

namespace {

// The sky's flags as another command spells them: every "--name" of the sky
// view, sun and fit blocks (and --image, --mask) in `msg` becomes "--sky-name"
// (one pass over the text, so --sun-zenith is not prefixed twice).
std::string prefix_sky_flags(const std::string& msg, const std::string& flags) {
  std::set<std::string> names = {"image", "mask", "image-transfer", "image-layer"};
  for (const auto& p : sky_view_param_table().params()) names.insert(p.spec.name);
  for (const auto& p : sun_param_table().params()) names.insert(p.spec.name);
  for (const auto& p : sky_fit_param_table().params()) names.insert(p.spec.name);
  std::string out;
  for (std::size_t i = 0; i < msg.size();) {
    if (msg.compare(i, 2, "--") == 0) {
      std::size_t j = i + 2;
      while (j < msg.size() && (std::isalnum(static_cast<unsigned char>(msg[j])) || msg[j] == '-')) ++j;
      const std::string name = msg.substr(i + 2, j - i - 2);
      if (names.count(name)) {
        out += flags + name;
        i = j;
        continue;
      }
    }
    out += msg[i++];
  }
  return out;
}

}  // namespace

SkyImageFit fit_sky_data(DenseImageRef rgb, bool integer_image, const Image* mask, const SkyViewParams& view,
                         const SunParams& sun_params, const SkyFitOptions& fit) {
  const SkyGeometry g = sky_geometry(view, rgb.width, rgb.height);
  const SunFound sun = resolve_sun(sun_params, &rgb, integer_image, &g);
  const auto t0 = std::chrono::steady_clock::now();
  SkyFitResult r;
  try {
    r = fit_sky_image(rgb, integer_image, g, sun.direction, mask, fit);
  } catch (const Error& e) {
    throw SkyFitError(e.what());
  }
  SkyImageFit out;
  out.fit_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  out.fit = sky_fit_json(r, sun);
  return out;
}

SkyImageFit fit_sky_image_file(const std::string& image, const TransferFunction& transfer, const std::string& mask_path,
                               const SkyViewParams& view, const SunParams& sun_params, const SkyFitOptions& fit,
                               const std::string& flags, const std::string& layer) {
  if (flags != "--") {
    try {
      return fit_sky_image_file(image, transfer, mask_path, view, sun_params, fit, "--", layer);
    } catch (const Error& e) {
      throw Error(prefix_sky_flags(e.what(), flags));
    }
  }
  const std::string image_flag = flags + "image", mask_flag = flags + "mask";
  FileInfo info;
  ColorRead how;
  how.transfer = transfer;
  how.layer = layer;
  how.layer_flag = "--image-layer";
  const Image rgb = read_color(image, how, &info);
  const bool integer_image = info.integer;
  (void)sky_geometry(view, rgb.width, rgb.height);  // view errors before mask errors, as before
  Image mask;
  FileInfo minfo;
  if (!mask_path.empty()) {
    mask = read_scalar(mask_path, "", &minfo);
    if (mask.width != rgb.width || mask.height != rgb.height)
      throw Error(mask_flag + " '" + mask_path + "' is " + mask.size_string() + " but " + image_flag + " '" + image +
                  "' is " + rgb.size_string() + "; give a mask of the image's size");
    const float half = minfo.integer ? (minfo.bits > 8 ? 32767.5f : 127.5f) : 0.5f;
    for (float& v : mask.data) v = v > half ? 1.0f : 0.0f;
  }
  SkyImageFit out;
  try {
    out = fit_sky_data(rgb, integer_image, mask_path.empty() ? nullptr : &mask, view, sun_params, fit);
  } catch (const Error& e) {
    if (dynamic_cast<const SkyFitError*>(&e)) throw Error(image_flag + " '" + image + "': " + e.what());
    throw;
  }
  out.image_record = file_record(image, info, rgb);
  if (!mask_path.empty()) out.mask_record = file_record(mask_path, minfo, mask);
  return out;
}

nlohmann::json run_sky_fit_job(const SkyFitJob& job, const RunContext& ctx, SkyPlotter plotter) {
  if (!plotter) plotter = ctx.plot;
  sky_fit_job_table().validate(job);
  if (job.image.empty()) throw Error("sky fit needs a sky photo: give --image FILE");
  if (job.out.empty()) throw Error("sky fit writes its result as JSON: give --out fit.json");
  check_output_dir(job.out, "--out");
  if (!job.plot.empty()) {
    if (!plotter) throw Error("--plot: this caller has no plotter (the brume command line draws it)");
    check_writable(job.plot, WriteOptions{}, "--plot");
  }
  const SkyImageFit f =
      fit_sky_image_file(job.image, job.image_transfer, job.mask, job.view, job.sun, job.fit, "--", job.image_layer);
  nlohmann::json j = f.fit;
  nlohmann::json rec = run_record_header("sky fit", ctx.argv);
  rec["job"] = sky_fit_job_table().to_json(job);
  rec["inputs"]["image"] = f.image_record;
  if (!job.mask.empty()) rec["inputs"]["mask"] = f.mask_record;
  rec["method"] = "log-luminance fit with a closed-form scale, T by Eigen Levenberg-Marquardt over "
                  "T = 1.7 + 18.3/(1+e^-p) from a 48-point grid, RANSAC against clouds (include/brume/sky.hpp)";
  rec["fit_ms"] = f.fit_ms;
  j["record"] = rec;
  OutputSet outs;
  outs.write_text(job.out, j.dump(2) + "\n", "--out");
  if (!job.plot.empty()) {
    WriteOptions wo;
    wo.bits = "8";
    outs.write(job.plot, plotter(j), wo, "--plot");
  }
  outs.commit();
  return j;
}

double turbidity_from_fit_json(const std::string& path, const std::string& flag) {
  // A regular file (brume/io.hpp; a missing one is FileNotFound, Python's
  // FileNotFoundError) of at most 16 MiB (a fit's JSON is a few kB).
  std::string text;
  try {
    text = read_input_file(path, flag, {16u << 20, "a sky fit's JSON is a few kB"});
  } catch (const FileNotFound&) {
    throw FileNotFound(flag + " '" + path + "' does not exist; give the JSON written by brume sky fit --out");
  }
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const std::exception& e) {
    throw Error(flag + " '" + path + "' is not JSON (" + e.what() + "); give the JSON written by brume sky fit --out");
  }
  if (!j.is_object() || !j.contains("turbidity") || !j["turbidity"].is_number())
    throw Error(flag + " '" + path + "' has no number 'turbidity'; give the JSON written by brume sky fit --out");
  // Read by type, never get<>() on what a hand-edited file may hold instead
  // (a JSON type error would end in "internal error"; issue #15, reproduced
  // by fuzz/corpus/sky_fit_json/reliable_not_bool.json).
  const auto rel = j.find("reliable");
  if (rel != j.end() && !rel->is_boolean())
    throw Error(flag + " '" + path + "': 'reliable' is " + rel->dump() + ", not true or false; give the JSON "
                "written by brume sky fit --out");
  if (rel == j.end() || !rel->get<bool>()) {
    std::string why;
    if (j.contains("unreliable_because") && j["unreliable_because"].is_array())
      for (const auto& w : j["unreliable_because"])
        why += (why.empty() ? "" : "; ") + (w.is_string() ? w.get<std::string>() : w.dump());
    throw Error(flag + " '" + path + "': the fit is flagged unreliable (" + (why.empty() ? "no reason given" : why) +
                "); give --turbidity T yourself, or fit a clearer part of the sky (--mask)");
  }
  const double t = j["turbidity"].get<double>();
  if (!(t >= 1.0 && t <= 20.0)) throw Error(flag + " '" + path + "': turbidity " + std::to_string(t) + " is outside [1, 20]");
  return t;
}

CommandDef sky_render_command() {
  CommandDef c = make_command<SkyRenderJob>({
      .name = "sky render",
      .cli = "sky render",
      .summary = "render a Preetham sky (linear sRGB, kcd/m^2) for a turbidity and a sun",
      .table = &sky_render_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .run = &run_sky_render_job,
      .report = [](const SkyRenderJob& j, const nlohmann::json& rec) {
        const auto& s = rec["sky"]["sun"];
        std::fprintf(stderr, "brume sky render: %s  T %.4g  sun zenith %.3f azimuth %.3f (%s)\n", j.output.out.c_str(),
                     j.sky.turbidity, s["zenith_deg"].get<double>(), s["azimuth_deg"].get<double>(),
                     s["source"].get<std::string>().c_str());
      },
  });
  c.gpu_passes = {"sky.render"};
  // brume.sky.render(**keywords): a sky image, no input array.
  static const auto call = array_call_table(sky_render_param_table(), kArrayExec);
  c.arrays = make_array_form<SkyRenderParams>(
      "sky_render", "brume.sky.render",
      "A Preetham sky in linear sRGB (kcd/m^2 x exposure), NaN (or ground) below the horizon. As `brume sky "
      "render`.",
      {}, call, {"rgb", "record"}, false,
      [](const std::vector<ArrayIn>&, ArrayCall<SkyRenderParams>& k, const Exec& e, const std::set<std::string>&) {
        SkyRenderRun r = run_sky_render(k.p, e);
        ArrayResult out{{{"rgb", std::move(r.rgb)}}, std::move(r.record), {}, {}};
        out.record["inputs"] = nlohmann::json::object();
        return out;
      });
  return c;
}

CommandDef sky_fit_command() {
  CommandDef c = make_command<SkyFitJob>({
      .name = "sky fit",
      .cli = "sky fit",
      .summary = "estimate the turbidity of a sky photo (RANSAC + Levenberg-Marquardt), JSON out",
      .table = &sky_fit_job_table(),
      .writes_record = true,
      .run = [](const SkyFitJob& j, const ExecOptions&, const RunContext& ctx) { return run_sky_fit_job(j, ctx); },
      .report = [](const SkyFitJob&, const nlohmann::json& j) {
        // The result is this command's product: stdout.
        std::printf("turbidity %.4f  spread %.4f  sun zenith %.3f azimuth %.3f (%s)  inliers %.0f %%  residual %.4f  %s\n",
                    j["turbidity"].get<double>(), j["turbidity_spread"].get<double>(),
                    j["sun"]["zenith_deg"].get<double>(), j["sun"]["azimuth_deg"].get<double>(),
                    j["sun"]["source"].get<std::string>().c_str(), 100 * j["inlier_fraction"].get<double>(),
                    j["residual"].get<double>(), j["reliable"].get<bool>() ? "reliable" : "UNRELIABLE");
        for (const auto& w : j["unreliable_because"]) std::printf("  unreliable: %s\n", w.get<std::string>().c_str());
      },
  });
  // brume.sky.fit(rgb, mask=None): the photo as an array (an integer one
  // enables saturation detection, as an 8/16-bit file does), the mask > 0.5
  // marking usable sky; the Result's fit is the JSON `brume sky fit` writes.
  static const auto call =
      array_call_table(sky_fit_job_table(), kArrayNone, {"image", "image-transfer", "mask", "out", "plot"});
  c.arrays = make_array_form<SkyFitJob>(
      "sky_fit", "brume.sky.fit",
      "Turbidity of a sky photo (Preetham model, RANSAC against clouds). mask: > 0.5 marks usable sky. Integer rgb "
      "(transfer=) enables saturation detection, as an 8/16-bit file does. As `brume sky fit`; the result's `fit` is "
      "its JSON.",
      {{"rgb", 3, false, ArrayArg::As::dense}, {"mask", 1, true, ArrayArg::As::image}}, call,
      {"turbidity", "reliable", "fit", "record"}, false,
      [](const std::vector<ArrayIn>& in, ArrayCall<SkyFitJob>& k, const Exec&, const std::set<std::string>&) {
        const DenseImageRef img = in[0].dense;
        Image* mask = in[1].present ? in[1].image : nullptr;
        if (mask) {
          if (mask->width != img.width || mask->height != img.height)
            throw Error("brume.sky.fit(): mask is " + mask->size_string() + " but rgb is " + img.size_string() +
                        "; give a mask of the image's size");
          for (float& v : mask->data) v = v > 0.5f ? 1.0f : 0.0f;
        }
        sky_fit_job_table().validate(k.p);
        const SkyImageFit f = fit_sky_data(img, in[0].integer, mask, k.p.view, k.p.sun, k.p.fit);
        ArrayResult r;
        r.record["fit_ms"] = f.fit_ms;
        r.more = {{"turbidity", f.fit.value("turbidity", nlohmann::json())},
                  {"reliable", f.fit.value("reliable", nlohmann::json(false))},
                  {"fit", f.fit}};
        return r;
      });
  return c;
}

}  // namespace brume
