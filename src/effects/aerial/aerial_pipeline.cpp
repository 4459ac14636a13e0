// brume — the aerial pipeline: what `brume aerial` does, as a library call,
// in the shape every effect follows (brume/pipeline.hpp): analyse the
// measured range (R_max, Iinf from the sky, the Gamma tables), prepare it,
// dispatch once on Exec, record.
#include <cstdio>
#include <chrono>
#include <algorithm>
#include <cmath>

#include "brume/command.hpp"
#include "brume/aerial.hpp"
#include "brume/sky.hpp"
#include "brume/error.hpp"
#include "brume/gpu_aerial.hpp"
#include "brume/io.hpp"
#include "brume/record.hpp"
#include "effects/aerial/aerial_job.hpp"
#include "core/text.hpp"
#include "core/warnings.hpp"

namespace brume {

namespace {

nlohmann::json gamma_json(const std::array<double, 3>& g) { return {g[0], g[1], g[2]}; }

nlohmann::json aerial_record(const AerialParams& p, const AerialAnalysis& a, std::size_t floored) {
  nlohmann::json j;
  j["parameters"] = aerial_param_table().to_json(p);
  j["units"] = aerial_param_table().units();
  j["diffusion"] = diffusion_record(p.diffusion, a.plan);
  nlohmann::json g = nlohmann::json::object(), g1 = nlohmann::json::object();
  Atmosphere from = p.atmosphere;
  if (p.from_turbidity) from.turbidity = *p.from_turbidity;
  for (double s : {100.0, 1000.0, 10000.0}) {
    const std::string k = std::to_string(static_cast<int>(s)) + "_m";
    g[k] = gamma_json(attenuation_direct(p.atmosphere, a.sensitivity, s));
    if (p.from_turbidity) g1[k] = gamma_json(attenuation_direct(from, a.sensitivity, s));
  }
  j["derived"] = {
      {"mode", to_string(a.mode)},
      {"range_max_m", a.range_max_m},
      {"range_min_m", a.range_min_m},
      {"distance_max_m", a.range_max_m * p.distance_scale},
      {"unknown_range_pixels", a.unknown_pixels},
      {"sky_rule", "pixels unknown in the measured range (NaN, inf, 0) are left unchanged by every mode"},
      {"sensitivity", {{"source", a.sensitivity.source},
                       {"sha256", a.sensitivity.sha256},
                       {"space", a.sensitivity.space == SensitivitySpace::xyz ? "xyz (M diag(Gamma) M^-1 on linear sRGB)"
                                                                              : "camera_rgb"}}},
      {"gamma_at", g},
      {"gamma_table", {{"samples", a.gamma.log_gamma.size()}, {"step_m", a.gamma.step_m},
                       {"interpolation", "linear in ln Gamma; beyond the table along its last slope"}}},
      {"airlight_linear_rgb", a.airlight},
      {"airlight_source", a.airlight_source},
      {"beta_550_per_m", a.beta_550_per_m},
      {"kappa_s_normalised", a.kappa_s},
      {"sigma_max_px", a.sigma_max},
  };
  if (p.path == AerialPath::slant) j["derived"]["slant_path"] = a.slant_record;
  if (!a.airlight_where.is_null()) j["derived"]["airlight_where"] = a.airlight_where;
  if (a.mode == AerialMode::rerender) {
    j["derived"]["from_gamma_at"] = g1;
    j["derived"]["from_airlight_linear_rgb"] = a.from_airlight;
    j["derived"]["from_airlight_source"] = a.from_airlight_source;
  }
  if (a.mode != AerialMode::render) {
    j["derived"]["gamma_floor_rule"] = a.mode == AerialMode::remove ? "divides by max(Gamma, gamma_floor)"
                                                                    : "Gamma1 floored at gamma_floor";
    j["derived"]["floored_pixels"] = floored;
  }
  return j;
}

// The preview (brume/preview.hpp): GpuAerial::render's passes (src/effects/aerial/aerial_gpu.cpp).
// Its maps: the ln Gamma table(s) (N x 1, read with texelFetch; one table in
// both slots unless re-rendering, as the native path binds them) and the sky
// mask (1 where the measured range is unknown).
// The slant path's 2-D table as an nr x nm map (row j: s_M = j step), as the GPU's.
Image slant_gamma_map(const SlantAttenuationTable& t) {
  Image m(t.nr, t.nm, 3);
  for (std::size_t i = 0; i < t.log_gamma.size(); ++i)
    for (int c = 0; c < 3; ++c) m.data[i * 3 + c] = t.log_gamma[i][c];
  return m;
}

Image log_gamma_map(const AttenuationTable& t) {
  Image m(static_cast<int>(std::max<std::size_t>(2, t.log_gamma.size())), 1, 3);  // 2 x 1 at least, as the GPU's
  for (std::size_t i = 0; i < t.log_gamma.size(); ++i)
    for (int c = 0; c < 3; ++c) m.data[i * 3 + c] = t.log_gamma[i][c];
  return m;
}

PreviewFrame aerial_preview(const nlohmann::json& job, const PreviewInputs& in) {
  AerialJob j;
  aerial_job_table().from_json(j, job, "job");
  // (--turbidity auto was refused by the command's check: the page names no sky photo.)
  const AerialParams& p = j.aerial;
  if (!p.turbidity_rule.empty())
    throw Error("the preview takes the turbidity as a number; --turbidity " + p.turbidity_rule +
                " is fitted by brume aerial (its record's turbidity_fit gives T): preview with --turbidity T");
  // --path slant: the files' camera for the inputs at 1/scale (its rays'
  // elevations give each pixel's dh); a target-altitude file is the files'
  // size, which the page's smaller scales do not have.
  const bool slant = p.path == AerialPath::slant;
  AerialGeometry geo;
  if (slant) {
    if (!j.target_altitude.empty())
      throw Error("the preview takes the slant path's altitudes from the camera (--pitch, --roll and the "
                  "intrinsics); --target-altitude '" + j.target_altitude + "' is a map of the files' size, which "
                  "the page's scales do not have: run brume aerial with it, or preview with the camera's pose");
    Image none;
    geo = aerial_geometry(j, j.input.depth, preview_full_width(in), preview_full_height(in), none);
    geo.camera->k = preview_intrinsics(geo.camera->k, in.scale);
    geo.camera->width = in.rgb.width;
    geo.camera->height = in.rgb.height;
  }
  AerialAnalysis a;
  analyse_aerial(in.rgb, in.measured, p, a, 0, slant ? &geo : nullptr);
  const bool rerender = a.mode == AerialMode::rerender;
  PreviewFrame frame;
  nlohmann::json& plan = frame.plan;
  const std::string table = frame.add_map("aerial.gamma", log_gamma_map(a.gamma));
  const std::string table_from = rerender ? frame.add_map("aerial.gamma-from", log_gamma_map(a.gamma_from)) : table;
  const std::string sky =
      frame.add_map("aerial.sky", a.sky.data.empty() ? Image(in.rgb.width, in.rgb.height, 1) : std::move(a.sky));
  // The slant path's inputs; level: the level table stands in (uSlant 0: never read).
  const std::string slant_dh = slant ? frame.add_map("aerial.slant-dh", std::move(a.slant_dh)) : table;
  const std::string slant_table = slant ? frame.add_map("aerial.slant-gamma", slant_gamma_map(a.slant_gamma)) : table;
  const std::string slant_table_from =
      slant && rerender ? frame.add_map("aerial.slant-gamma-from", slant_gamma_map(a.slant_gamma_from)) : slant_table;
  const AttenuationTable& tf = rerender ? a.gamma_from : a.gamma;
  const std::array<float, 3> A = aerial_working_colour(a, a.airlight), A1 = aerial_working_colour(a, a.from_airlight);
  const bool blur = a.plan.iterations > 0 && a.mode != AerialMode::remove;
  auto f = [](double x) { return preview_f(static_cast<float>(x)); };
  const char* fmt = p.diffusion.precision == Precision::f16 ? "RGBA16F" : "RGBA32F";
  plan["targets"] = {{"f0", fmt}, {"f0b", fmt}, {"f1", fmt}, {"f1b", fmt}, {"aux", "RG32F"},
                     {"out", "RGBA32F"}, {"att", "RGBA32F"}};
  plan["steps"] = nlohmann::json::array();
  plan["steps"].push_back({{"pass", "aerial.premultiply"},
                           {"in", {"image", "range", table, table_from, slant_dh, slant_table, slant_table_from}},
                           {"out", {"f0", "f1", "aux"}},
                           {"uniforms",
                            {{"uStep", f(a.gamma.step_m)},
                             {"uLast", preview_i(static_cast<int>(a.gamma.log_gamma.size()) - 1)},
                             {"uStepFrom", f(tf.step_m)},
                             {"uLastFrom", preview_i(static_cast<int>(tf.log_gamma.size()) - 1)},
                             {"uA1", preview_f3(A1.data())},
                             {"uDistanceScale", f(p.distance_scale)},
                             {"uFar", f(a.range_max_m * p.distance_scale)},
                             {"uInvRangeMax", f(1.0 / a.range_max_m)},
                             {"uSigma0", f(p.diffusion.sigma0)},
                             {"uSigmaMax", f(a.sigma_max)},
                             {"uMode", preview_i(aerial_mode_index(a.mode))},
                             {"uXyz", preview_i(a.sensitivity.space == SensitivitySpace::xyz ? 1 : 0)},
                             {"uA", preview_f3(A.data())},
                             {"uFloor", f(p.gamma_floor)},
                             {"uSlant", preview_i(slant ? 1 : 0)},
                             {"uInvScaleHeight", preview_f2(static_cast<float>(1.0 / kRayleighScaleHeightM),
                                                            static_cast<float>(1.0 / kMieScaleHeightM))},
                             {"uSlantInvStep", preview_f2(slant ? static_cast<float>(1.0 / a.slant_gamma.step_r_m) : 0.0f,
                                                          slant ? static_cast<float>(1.0 / a.slant_gamma.step_m_m) : 0.0f)},
                             {"uSlantNr", preview_i(slant ? a.slant_gamma.nr : 2)},
                             {"uSlantNm", preview_i(slant ? a.slant_gamma.nm : 2)}}}});
  std::string f0 = "f0", f1 = "f1";
  if (blur) {  // F0 and F1 diffused with the same rates: the CPU's six channels with one sigma map
    preview_rates_step(plan, p.diffusion, a.plan, "aux");
    preview_iterate_step(plan, p.diffusion, a.plan, "f0", "f0b", "f0.blurred");
    preview_iterate_step(plan, p.diffusion, a.plan, "f1", "f1b", "f1.blurred");
    f0 = "f0.blurred", f1 = "f1.blurred";
  }
  plan["steps"].push_back({{"pass", "aerial.composite"},
                           {"in", {f0, f1, "image", "range", sky}},
                           {"out", {"out", "att"}},
                           {"uniforms",
                            {{"uA", preview_f3(A.data())},
                             {"uMode", preview_i(aerial_mode_index(a.mode))},
                             {"uXyz", preview_i(a.sensitivity.space == SensitivitySpace::xyz ? 1 : 0)}}}});
  plan["result"] = "out";
  plan["derived"] = aerial_record(p, a, 0)["derived"];
  plan["derived"].erase("floored_pixels");  // counted by the run, not the preview
  plan["derived"]["iterations"] = blur ? a.plan.iterations : 0;
  return frame;
}

}  // namespace

const std::vector<MapOutput>& aerial_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"attenuation", "write Gamma per channel after the blur (Gamma2/Gamma1 for a re-render), 3 channels, float",
       "Gamma2/Gamma1 of a re-render exceeds 1, and an integer file would quantise a measured transfer"},
      {"scale-map", "write the target scale sigma(x) in pixels (float file)", "sigma is in pixels and exceeds 1"},
  };
  return m;
}

const ParamTable<AerialJob>& aerial_job_table() {
  static const ParamTable<AerialJob> t = [] {
    ParamTable<AerialJob> d("aerial");
    d.nest(&AerialJob::input, input_param_table(true))
        .nest(&AerialJob::prepare, range_step_param_table())
        .nest(&AerialJob::aerial, aerial_param_table())
        .nest(&AerialJob::output, output_param_table(aerial_map_outputs()))
        .nest(&AerialJob::lidar, camera_lidar_param_table())
        .text("target-altitude", &AerialJob::target_altitude,
              "--path slant: each pixel's altitude in metres above sea level (e.g. rendered from a DEM; one channel, "
              "the image's size; integer files as stored counts), instead of --altitude + range x sin(elevation) "
              "from the intrinsics and --pitch/--roll")
        .reads_file()
        .text("turbidity-from", &AerialJob::turbidity_from,
              "take --turbidity from a `brume sky fit` JSON (refused when the fit is flagged unreliable)")
        .reads_file("", 0, 5)
        .text("sky-image", &AerialJob::sky_image,
              "--turbidity auto: the sky photo to fit T on, as brume sky fit (refused when unreliable); its flags "
              "carry --sky-")
        .reads_file()
        .text("sky-image-layer", &AerialJob::sky_image_layer,
              "the layer of a --sky-image with layers (NAME.R, NAME.G, NAME.B of a multilayer OpenEXR)");
    transfer_param(d, "sky-image-transfer", &AerialJob::sky_image_transfer,
                   "--sky-image")
        .text("sky-mask", &AerialJob::sky_mask, "grey image of --sky-image's size: > half scale marks usable sky")
        .reads_file()
        .nest(&AerialJob::sky_view, sky_view_param_table(), "sky-")
        .nest(&AerialJob::sky_sun, sun_param_table(), "sky-")
        .nest(&AerialJob::sky_fit, sky_fit_param_table(), "sky-");
    return d;
  }();
  return t;
}

AerialGeometry aerial_geometry(const AerialJob& job, const DepthSource& depth, int width, int height, Image& store) {
  AerialGeometry g;
  if (job.aerial.path != AerialPath::slant) {
    if (!job.target_altitude.empty())
      throw Error("--target-altitude '" + job.target_altitude + "' gives the targets' altitudes for --path slant; "
                  "give --path slant, or drop --target-altitude");
    return g;
  }
  if (!job.target_altitude.empty()) {
    const CameraPose none;
    if (job.aerial.camera.pitch_deg != none.pitch_deg || job.aerial.camera.roll_deg != none.roll_deg ||
        !job.aerial.camera.view_matrix_file.empty())
      throw Error("--target-altitude '" + job.target_altitude + "' gives every pixel's altitude; the pose (--pitch, "
                  "--roll, --view-matrix) would give it a second time: drop one of them");
    store = read_scalar(job.target_altitude);
    g.target_altitude = store;
    g.target_altitude_name = "--target-altitude '" + job.target_altitude + "'";
    return g;
  }
  try {
    g.camera = depth_camera(depth, width, height, job.aerial.camera);
  } catch (const Error& e) {
    std::string why = e.what();
    const std::string lead = "planar depth needs the camera: ";  // depth_intrinsics' words for --z
    if (why.rfind(lead, 0) == 0) why = why.substr(lead.size());
    throw Error("--path slant takes each pixel's target altitude from its ray's elevation, which needs the camera's "
                "intrinsics: " + why + "; or give --target-altitude FILE (metres above sea level per pixel)");
  }
  return g;
}

namespace {

AerialRun run_aerial_at(DenseImageRef rgb, DenseImageRef measured, const AerialParams& p, const RangeStep& prepare,
                        const CompletedRange& done, const Exec& exec, const std::set<std::string>& given,
                        const AerialGeometry* geometry) {
  AerialRun run;
  analyse_aerial(rgb, measured, p, run.analysis, exec.threads, geometry);
  PreparedRange prep = prepare_step(measured.view(), prepare, given, exec.threads);
  prep.record["complete"] = done.record;
  // The slant path on the GPU: the premultiply pass takes each pixel's dh and
  // the 2-D table (aerial_premultiply.frag).
  BackendChoice backend = choose_backend(exec);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json timing;
  if (backend.gpu) {
    GpuAerial ga(*backend.gpu, rgb, prep.range);
    run.result = ga.render(p, run.analysis, exec.gpu_filter);
    timing = gpu_timing_record(ga.timing());
  } else {
    run.result = apply_aerial(rgb, prep.range, p, run.analysis, exec);
    timing = cpu_timing_record(t0, run.analysis.plan.iterations);
  }
  run.record["aerial"] = aerial_record(p, run.analysis, run.result.floored_pixels);
  // Below zero (issue #59): removal on a photograph whose far land is darker
  // than the model's air allows (tone mapping, a wrong airlight or T) gives
  // negative radiance. Counted on the output whatever a writer later does
  // with it (an integer file stores 0), and said.
  {
    const Image& o = run.result.rgb;
    const std::size_t n = o.pixels();
    std::size_t negative = 0, ground = 0;
    std::array<std::size_t, 3> per{};
    float least = 0.0f;
    for (std::size_t i = 0; i < n; ++i) {
      if (!run.analysis.sky.data.empty() && run.analysis.sky.data[i] > 0.0f) continue;
      ++ground;
      bool neg = false;
      for (int c = 0; c < 3; ++c) {
        const float v = o.data[3 * i + c];
        if (v < 0.0f) ++per[c], neg = true, least = std::min(least, v);
      }
      negative += neg;
    }
    const double share = ground ? static_cast<double>(negative) / static_cast<double>(ground) : 0.0;
    run.record["aerial"]["derived"]["negative_pixels"] = {
        {"count", negative},
        {"of_ground_pixels", ground},
        {"fraction", share},
        {"per_channel", per},
        {"least_value", least},
        {"rule", "pixels outside the sky with a channel below 0 in the output (linear); an integer file stores them "
                 "as 0, a float file keeps them"}};
    if (negative) {
      const std::string w = text::g(100.0 * share, 3) + " % of the ground pixels (" + std::to_string(negative) +
                            ") came out below zero in a channel (least " + text::g(least, 3) + ")" +
                            (run.analysis.mode == AerialMode::remove
                                 ? ": the photo's land is darker than the model's air allows at --turbidity " +
                                       text::g(p.atmosphere.turbidity) + " with airlight " +
                                       text::g(run.analysis.airlight[0], 3) + "," + text::g(run.analysis.airlight[1], 3) +
                                       "," + text::g(run.analysis.airlight[2], 3) +
                                       " (a tone-mapped photo, a lower turbidity, the horizon's airlight, the "
                                       "observer's --altitude; docs/aerial.md)"
                                 : run.analysis.mode == AerialMode::rerender
                                       ? ": a re-render to clearer air subtracts more airlight than the photo's land "
                                         "holds (a lower --from-turbidity, or the photo's own --from-horizon)"
                                       : ": the input image has negative values");
      run.record["aerial"]["warnings"].push_back(w);
      print_warning("aerial", w);
    }
  }
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  return run;
}

}  // namespace

AerialRun run_aerial(DenseImageRef rgb, DenseImageRef measured_range, const AerialParams& p, const RangeStep& prepare,
                     const Exec& exec, const std::set<std::string>& given, const AerialGeometry* geometry) {
  validate_aerial(p, given);
  AerialRun run;
  // Statistics (R_max, Iinf, the sky mask) from the measured range; the
  // effect runs on the prepared one, whose smooth sky margin only shapes the
  // blur near the horizon (sky pixels themselves stay unchanged).
  // A sparse map is completed first (guided by rgb; its sky stays unknown), when the step says so.
  const CompletedRange done = complete_step(measured_range.view(), rgb.view(), prepare, given, exec.threads);
  const DenseImageRef measured = done.applied ? DenseImageRef(done.range) : measured_range;
  // --turbidity contrast: T fitted on this photo first; everything after runs
  // at the fitted T (the aerial block's parameters record the T used, the job
  // keeps "contrast" so that `brume run` refits).
  AerialParams fitted;
  std::optional<TurbidityContrastFit> contrast;
  if (p.turbidity_rule == "contrast") {
    contrast = fit_turbidity_contrast(rgb, measured, p, geometry, exec.threads);
    fitted = p;
    fitted.atmosphere.turbidity = contrast->turbidity;
    fitted.turbidity_rule.clear();
  }
  const AerialParams& p_used = contrast ? fitted : p;
  run = run_aerial_at(rgb, measured, p_used, prepare, done, exec, given, geometry);
  if (contrast) {
    run.record["turbidity_fit"] = contrast->record;
    if (!contrast->warning.empty()) {
      run.record["aerial"]["warnings"].push_back(contrast->warning);
      print_warning("aerial", contrast->warning);
    }
  }
  return run;
}

AerialTurbidity resolve_aerial_turbidity(AerialJob& job, const std::set<std::string>& given) {
  // --turbidity-from: the sky fit's T replaces --turbidity, and the record
  // holds the resolved value (so `brume run` finds the two consistent).
  double& turbidity = job.aerial.atmosphere.turbidity;
  // --turbidity auto --sky-image: the same fit as `brume sky fit`, before the
  // photo is read; an unreliable fit is refused with its reasons. The record
  // keeps the job as given (--turbidity auto: `brume run` refits the recorded,
  // hash-checked sky image with the same seed, so finds the same T) and the
  // fit's result under "turbidity_fit"; the aerial block records the T used.
  AerialTurbidity out;
  nlohmann::json& sky_fit_record = out.fit_record;
  nlohmann::json& sky_image_record = out.image_record;
  if (job.sky_image.empty()) {
    for (const std::string& g : given)
      if (g.rfind("sky-", 0) == 0)
        throw Error("--" + g + " describes the sky photo of --turbidity auto, but --sky-image was not given; give "
                    "--turbidity auto --sky-image FILE, or drop --" + g);
  } else {
    if (!job.turbidity_from.empty())
      throw Error("--sky-image '" + job.sky_image + "' and --turbidity-from '" + job.turbidity_from +
                  "' both give the turbidity; use one of them");
    if (!job.aerial.turbidity_rule.empty())
      throw Error("--sky-image '" + job.sky_image + "' is for --turbidity auto (T fitted on the sky photo), but "
                  "--turbidity is " + job.aerial.turbidity_rule + " (T fitted on the image's terrain); "
                  "give one of them");
    if (!std::isnan(turbidity))
      throw Error("--sky-image '" + job.sky_image + "' is for --turbidity auto (T fitted on the sky photo), but "
                  "--turbidity is " + std::to_string(turbidity) + "; give --turbidity auto, or drop --sky-image");
    aerial_job_table().validate(job);  // the --sky- flags' ranges, before the fit reads anything
    SkyImageFit f = fit_sky_image_file(job.sky_image, job.sky_image_transfer, job.sky_mask, job.sky_view, job.sky_sun,
                                       job.sky_fit, "--sky-", job.sky_image_layer);
    const nlohmann::json& j = f.fit;
    if (!j.value("reliable", false)) {
      std::string why;
      for (const auto& w : j.value("unreliable_because", nlohmann::json::array()))
        why += (why.empty() ? "" : "; ") + w.get<std::string>();
      throw Error("--sky-image '" + job.sky_image + "': the turbidity fit (T = " +
                  std::to_string(j["turbidity"].get<double>()) + ") is unreliable (" +
                  (why.empty() ? "no reason given" : why) +
                  "); give --turbidity T yourself, or fit a clearer part of the sky (--sky-mask)");
    }
    const double t = j["turbidity"].get<double>();
    turbidity = t;
    sky_fit_record = {{"turbidity", t},
                      {"turbidity_spread", j["turbidity_spread"]},
                      {"sun", j["sun"]},
                      {"inlier_fraction", j["inlier_fraction"]},
                      {"residual", j["residual"]},
                      {"reliable", true},
                      {"fit_ms", f.fit_ms}};
    sky_image_record = f.image_record;
    if (!f.mask_record.is_null()) sky_fit_record["mask"] = f.mask_record;
  }
  if (!job.turbidity_from.empty()) {
    if (!job.aerial.turbidity_rule.empty())
      throw Error("--turbidity-from '" + job.turbidity_from + "' gives the turbidity and --turbidity " +
                  job.aerial.turbidity_rule + " fits it on the image; give one of them");
    const double t = turbidity_from_fit_json(job.turbidity_from);
    out.from_record = {{"path", job.turbidity_from}, {"sha256", sha256_file(job.turbidity_from)}};
    // (--turbidity auto with --turbidity-from: the fit in the file is the auto.)
    if (given.count("turbidity") && !std::isnan(turbidity) && turbidity != t)
      throw Error("--turbidity " + std::to_string(job.aerial.atmosphere.turbidity) + " and --turbidity-from '" +
                  job.turbidity_from + "' (T = " + std::to_string(t) + ") disagree; give one of them");
    job.aerial.atmosphere.turbidity = t;
  }
  return out;
}

nlohmann::json run_aerial_job(const AerialJob& given_job, const ExecOptions& eo, const RunContext& ctx) {
  AerialJob job = given_job;
  const AerialTurbidity tf = resolve_aerial_turbidity(job, ctx.given);
  const EffectJob<AerialJob> e{
      "aerial",
      aerial_job_table(),
      aerial_map_outputs(),
      190,
      [&](const AerialJob& j, const ExecOptions&) { validate_aerial(j.aerial, ctx.given); },
      [&](const AerialJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.aerial.airlight) check_airlight_sky(in, "aerial");
        Image altitude;
        const AerialGeometry geo = aerial_geometry(j, j.input.depth, in.rgb.width, in.rgb.height, altitude);
        AerialRun run = run_aerial(in.rgb, in.depth.range, j.aerial, with_camera(j.prepare, in.depth), exec, ctx.given,
                                   &geo);
        if (!j.target_altitude.empty())
          in.record["target_altitude"] = {{"path", j.target_altitude}, {"sha256", sha256_file(j.target_altitude)}};
        if (!tf.fit_record.is_null()) {
          run.record["turbidity_fit"] = tf.fit_record;
          in.record["sky_image"] = tf.image_record;
        }
        if (!tf.from_record.is_null()) in.record["turbidity_from"] = tf.from_record;
        return EffectOutput{std::move(run.result.rgb),
                            {{"attenuation", std::move(run.result.attenuation)},
                             {"scale-map", std::move(run.result.scale)}},
                            std::move(run.record)};
      }};
  AerialJob recorded = job;
  if (!tf.fit_record.is_null()) recorded.aerial.atmosphere.turbidity = NAN;  // auto: refitted by brume run
  return run_effect_job(e, job, eo, ctx, &recorded);
}

CommandDef aerial_command() {
  CommandDef c = make_command<AerialJob>({
      .name = "aerial",
      .cli = "aerial",
      .summary = "spectral aerial perspective from turbidity: render, re-render, remove (Morales eq. 3.11-3.13)",
      .table = &aerial_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const AerialJob& j, const std::set<std::string>& g) {
        validate_aerial(j.aerial, g);
        check_range_step(j.prepare, g);
      },
      .run = &run_aerial_job,
      .report = [](const AerialJob& j, const nlohmann::json& rec) {
        const auto& d = rec["aerial"]["derived"];
        const auto& g = d["gamma_at"]["1000_m"];
        std::string below;  // records before the count have none
        if (d.contains("negative_pixels") && d["negative_pixels"]["count"].get<std::size_t>() > 0)
          below = "  below zero " + text::g(100.0 * d["negative_pixels"]["fraction"].get<double>(), 3) +
                  " % (least " + text::g(d["negative_pixels"]["least_value"].get<double>(), 3) + ")";
        std::fprintf(stderr, "brume aerial: %s  %s%s  R_max %.4g m  Gamma(1 km) %.4f %.4f %.4f  sigma_max %.3g px%s (%s)\n",
                     j.output.out.c_str(), d["mode"].get<std::string>().c_str(),
                     j.aerial.path == AerialPath::slant ? " (slant path)" : "", d["range_max_m"].get<double>(),
                     g[0].get<double>(), g[1].get<double>(), g[2].get<double>(), d["sigma_max_px"].get<double>(),
                     below.c_str(), rec["execution"]["backend"].get<std::string>().c_str());
      },
  });
  // Turbidity 2-10 (Morales Table 3.1, corrected: clear air from about 2.7,
  // light haze 4.5, haze 9.8; fog at 19 is haze's and fog's job), uniform
  // since the Mie coefficient is affine in T; observer altitude 0-1500 m (sea
  // level to high plateaus, where most outdoor datasets are shot); blur gain
  // as haze.
  c.sampling = make_sampling<AerialParams>(aerial_param_table(),
                                           {{"turbidity", "uniform(2, 10)", {}},
                                            {"altitude", "uniform(0, 1500)", {}},
                                            {"lambda", "uniform(0, 8)", {}}},
                                           &validate_aerial);
  c.gpu_passes = {"aerial.premultiply", "diffusion.rates", "diffusion.iterate", "aerial.composite"};
  c.preview = &aerial_preview;
  // The sky-photo fit's flags describe a file the page cannot name.
  c.preview_fixed = {"sky", "sky-image-transfer"};
  // The medium at a wavelength (the LiDAR's, brume/lidar_camera.hpp): Rayleigh
  // + Mie at the observer's altitude, per metre of the range map (s = R x
  // distance-scale). A re-render or a removal has no one medium for a scan.
  c.spectral_extinction_per_m = [](const nlohmann::json& job, double lambda_nm) -> std::optional<double> {
    AerialJob j;
    aerial_job_table().from_json(j, job, "job");
    if (j.aerial.remove)
      throw Error("--lidar with --remove: the image's aerial perspective is taken away, the scan has none to add; "
                  "drop --lidar (or fog the scan with brume lidar fog)");
    if (j.aerial.from_turbidity)
      throw Error("--lidar with --from-turbidity: a re-render changes the medium of a photo that already has one, "
                  "a scan is clear; render (drop --from-turbidity) to fog the scan with --turbidity");
    if (j.aerial.path == AerialPath::slant)
      throw Error("--lidar with --path slant: the scan is fogged with the coefficients at --altitude along level "
                  "beams (one extinction per metre); give --path level to fog the scan, or run brume lidar fog on it");
    resolve_aerial_turbidity(j, {});  // --turbidity-from or --turbidity auto: T as the run takes it
    return aerial_extinction_per_m(lambda_nm, j.aerial.atmosphere) * j.aerial.distance_scale;
  };
  // brume.aerial takes the whole `brume aerial` job but its files: the
  // turbidity from a sky fit's JSON (turbidity_from=) or fitted on a sky photo
  // (turbidity="auto", sky_image=, the sky_* keywords) resolves as the CLI
  // resolves it, and the record holds the same "turbidity_fit" and inputs'
  // "sky_image". sky_image is a file, as on the command line (its record
  // hashes it, so `brume run` can refit it); for a sky already in memory call
  // brume.sky.fit and pass turbidity=.
  static const auto call = [] {
    std::set<std::string> skip;
    for (const auto& d : input_param_table(true).params()) skip.insert(d.spec.name);
    for (const auto& d : output_param_table(aerial_map_outputs()).params()) skip.insert(d.spec.name);
    for (const auto& d : camera_lidar_param_table().params()) skip.insert(d.spec.name);  // files: brume.lidar.fog
    return array_call_table(aerial_job_table(), kArrayExec | kArrayIntrinsics, skip);
  }();
  c.arrays = make_array_form<AerialJob>(
      "aerial", "",
      "Spectral aerial perspective from turbidity (Morales): render, re-render (from_turbidity) or remove, with "
      "optional scattering blur (lambda_). The turbidity is given, read from a `brume sky fit` JSON "
      "(turbidity_from=) or fitted on a sky photo (turbidity='auto', sky_image=FILE, sky_* keywords), refused "
      "when the fit is unreliable. As `brume aerial`.",
      rgb_range_args(ArrayArg::As::dense), call, {"rgb", "attenuation", "scale", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<AerialJob>& k, const Exec& e, const std::set<std::string>& g) {
        const AerialTurbidity tf = resolve_aerial_turbidity(k.p, g);
        Image altitude;
        const AerialGeometry geo = aerial_geometry(k.p, k.depth, in[0].dense.width, in[0].dense.height, altitude);
        AerialRun r = run_aerial(in[0].dense, in[1].dense, k.p.aerial, k.p.prepare, e, g, &geo);
        if (!k.p.target_altitude.empty())
          r.record["inputs"]["target_altitude"] = {{"path", k.p.target_altitude},
                                                   {"sha256", sha256_file(k.p.target_altitude)}};
        if (!tf.fit_record.is_null()) {
          r.record["turbidity_fit"] = tf.fit_record;
          r.record["sky_image"] = tf.image_record;  // under "inputs", as in the CLI's record
          k.p.aerial.atmosphere.turbidity = NAN;     // recorded as given (auto), as the CLI does
        }
        if (!tf.from_record.is_null()) r.record["inputs"]["turbidity_from"] = tf.from_record;
        return ArrayResult{{{"rgb", std::move(r.result.rgb)},
                            {"attenuation", std::move(r.result.attenuation)},
                            {"scale", std::move(r.result.scale)}},
                           std::move(r.record),
                           {},
                           {}};
      },
      [](const ArrayCall<AerialJob>& k, const std::set<std::string>& g) {
        validate_aerial(k.p.aerial, g);
        check_range_step(k.p.prepare, g);
      });
  add_camera_lidar(c);
  return c;
}

}  // namespace brume
