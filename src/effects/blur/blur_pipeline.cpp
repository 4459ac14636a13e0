// brume — `brume blur`: the diffusion engine alone (brume/blur.hpp).
#include "brume/command.hpp"
#include "brume/blur.hpp"

#include <cstdio>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "brume/error.hpp"
#include "core/text.hpp"
#include "brume/gpu_context.hpp"
#include "brume/record.hpp"
#include "effects/blur/blur_job.hpp"

namespace brume {

const ParamTable<BlurJob>& blur_job_table() {
  static const ParamTable<BlurJob> t = [] {
    ParamTable<BlurJob> d("blur");
    d.nest(&BlurJob::input, input_param_table(false))
        // At most 10 000 px: wider than any image the pixel limit admits is a
        // mistake (1e9 px would ask the standard scheme for 2e18 iterations).
        .real("sigma", &BlurJob::sigma, "px", Range::left_open(0.0, 1e4),
              "constant target scale (the result is a Gaussian of sqrt(sigma^2 - sigma0^2))", "none")
        .text("scale-map", &BlurJob::scale_map, "per-pixel target scale in px (1-channel float file)")
        .reads_file()
        .nest(&BlurJob::diffusion, diffusion_param_table())
        .nest(&BlurJob::output, output_param_table({}));
    return d;
  }();
  return t;
}

namespace {
void check_blur_scale(std::optional<double> sigma, bool has_map, const DiffusionParams& dp) {
  if (sigma && has_map)
    throw Error("give either --sigma (a constant scale) or --scale-map (a per-pixel scale), not both");
  if (!sigma && !has_map) throw Error("blur needs a target scale: give --sigma S (px) or --scale-map FILE");
  if (sigma && *sigma < dp.sigma0) {
    std::ostringstream m;
    m << "--sigma " << *sigma << " px is below the inner scale --sigma0 " << dp.sigma0
      << " px; diffusion can only add blur. The Gaussian applied is sqrt(sigma^2 - sigma0^2): give --sigma >= --sigma0";
    throw Error(m.str());
  }
}
}  // namespace

namespace {
// Both entry points: `owned`, when given, holds the pixels of `rgb` and may
// become the working buffer itself.
BlurRun blur_impl(ConstImageView rgb, Image* owned, std::optional<double> sigma, const Image* scale_map,
                  const DiffusionParams& dp, const Exec& exec) {
  diffusion_param_table().validate(dp);
  check_blur_scale(sigma, scale_map != nullptr, dp);
  if (sigma && !std::isfinite(*sigma)) throw Error("--sigma must be a finite number of pixels");
  if (rgb.channels() != 3)
    throw Error("blur: the image has " + std::to_string(rgb.channels()) + " channels; give linear RGB (3 channels)");
  double smax = sigma.value_or(dp.sigma0);
  if (scale_map) {
    if (scale_map->width != rgb.width() || scale_map->height != rgb.height() || scale_map->channels != 1)
      throw Error("--scale-map is " + scale_map->size_string() + "x" + std::to_string(scale_map->channels) +
                  " but the image is " + rgb.size_string() + "; give one channel of the image's size");
    // The largest finite scale (smax starts at sigma0 > 0, so values below 0
    // do not matter): sixteen running maxima, branch-free, so that the loop
    // vectorises (the one-at-a-time form took ~2 ms of a 1600 x 1120 map);
    // v > m is false for NaN, v <= FLT_MAX for +inf.
    float m16[16] = {};
    const std::vector<float>& d = scale_map->data;
    std::size_t i = 0;
    for (; i + 16 <= d.size(); i += 16)
      for (int j = 0; j < 16; ++j) {
        const float v = d[i + j];
        m16[j] = ((v > m16[j]) & (v <= std::numeric_limits<float>::max())) ? v : m16[j];
      }
    for (; i < d.size(); ++i)
      if (std::isfinite(d[i])) m16[0] = std::max(m16[0], d[i]);
    for (float m : m16) smax = std::max(smax, static_cast<double>(m));
  }
  // The plan's bounds before any work (brume/diffusion.hpp): --sigma's range
  // alone (10 000 px) let the standard scheme run for hours on a small image.
  plan_diffusion(dp, smax, rgb.width(), rgb.height(),
                 scale_map ? "the largest value of --scale-map (" + text::g(smax) + " px): lower the map's scales"
                           : "--sigma " + text::g(smax) + " px: lower it");
  BackendChoice backend = choose_backend(exec);
  // The engine's working buffer, filled straight from the caller's pixels
  // (the view is read in place): on the CPU in f32, a constant scale or the
  // invariant schemes' scale map diffuse the RGB values themselves (rows of
  // three values a pixel: a quarter less work and memory than RGBA, and no
  // packing after); otherwise RGBA with alpha 1 (the standard scheme's
  // conductance rows, binary16 storage and the GPU's textures take four
  // channels).
  const bool rgb_rows = !backend.gpu && dp.precision == Precision::f32 &&
                        (!scale_map || dp.scheme != Scheme::standard);
  const int fc = rgb_rows ? 3 : 4;
  Image f;
  if (rgb_rows && owned) {
    f = std::move(*owned);  // the decoded image is the working buffer: no copy
  } else {
    f = Image(rgb.width(), rgb.height(), fc);
    for (int y = 0; y < rgb.height(); ++y) {
      const float* src = rgb.row(y);
      float* dst = f.row(y);
      for (int x = 0; x < rgb.width(); ++x) {
        for (int k = 0; k < 3; ++k) dst[x * fc + k] = src[x * rgb.pixel_stride() + k];
        if (fc == 4) dst[x * 4 + 3] = 1.0f;
      }
    }
  }
  BlurRun run;
  nlohmann::json timing;
  const auto t0 = std::chrono::steady_clock::now();
  if (backend.gpu) {
    // The GPU pass samples a scale texture, so a constant scale is one.
    GpuTiming t;
    const Image smap = scale_map ? Image() : Image(rgb.width(), rgb.height(), 1, static_cast<float>(*sigma));
    run.plan = diffuse_gpu(*backend.gpu, f, scale_map ? *scale_map : smap, smax, dp, exec.gpu_filter, &t);
    timing = gpu_timing_record(t);
  } else {
    // A constant scale needs no map on the CPU (the same bits without its
    // 4 bytes a pixel, nor the rates' 4 more, first touched in every run).
    run.plan = scale_map ? diffuse(f, *scale_map, smax, dp, exec) : diffuse(f, *sigma, dp, exec);
    timing = cpu_timing_record(t0, run.plan.iterations);
  }
  // RGBA -> RGB in f's own buffer (pixel i's three values move down to 3i,
  // never past a pixel not yet moved), which then becomes the result: no
  // fresh image-sized buffer, whose first-touch page faults cost more than
  // the copy (~2-10 ms at 1600x1120 on the hosts measured).
  if (fc == 4) {
    const std::size_t np = rgb.pixels();
    for (std::size_t i = 0; i < np; ++i)
      for (int k = 0; k < 3; ++k) f.data[i * 3 + k] = f.data[i * 4 + k];
    f.data.resize(np * 3);
    f.channels = 3;
  }
  run.rgb = std::move(f);
  if (sigma) run.record["sigma_px"] = *sigma;
  run.record["diffusion"] = diffusion_record(dp, run.plan);
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  run.record["effective_gaussian_px"] = sigma ? std::sqrt(*sigma * *sigma - dp.sigma0 * dp.sigma0) : -1.0;
  return run;
}
}  // namespace

BlurRun run_blur(ConstImageView rgb, std::optional<double> sigma, const Image* scale_map, const DiffusionParams& dp,
                 const Exec& exec) {
  return blur_impl(rgb, nullptr, sigma, scale_map, dp, exec);
}

BlurRun run_blur(Image&& rgb, std::optional<double> sigma, const Image* scale_map, const DiffusionParams& dp,
                 const Exec& exec) {
  return blur_impl(rgb, &rgb, sigma, scale_map, dp, exec);
}

nlohmann::json run_blur_job(const BlurJob& job, const ExecOptions& eo, const RunContext& ctx) {
  blur_job_table().validate(job);
  const DiffusionParams& dp = job.diffusion;
  check_blur_scale(job.sigma, !job.scale_map.empty(), dp);
  const Exec exec = eo.exec();
  check_outputs(job.output, {});

  LoadedInputs in = load_inputs(job.input, false);

  check_working_memory("blur", in.rgb, 110);  // measured peak bytes per pixel (docs/reliability.md)
  const Image& rgb = in.rgb;
  Image smap;
  FileInfo map_info;
  if (!job.scale_map.empty()) {
    smap = read_scalar(job.scale_map, "", &map_info);
    if (smap.width != rgb.width || smap.height != rgb.height)
      throw Error("--scale-map '" + job.scale_map + "' is " + smap.size_string() + " but --image '" + job.input.image +
                  "' is " + rgb.size_string() + "; they must be the same size");
  }
  // The decoded image is handed over (blurred in its own buffer where the
  // engine's rows are RGB); nothing below reads it again.
  BlurRun run = run_blur(std::move(in.rgb), job.sigma, job.scale_map.empty() ? nullptr : &smap, dp, exec);

  nlohmann::json inputs = in.record;
  if (!job.scale_map.empty()) inputs["scale_map"] = file_record(job.scale_map, map_info, smap);
  EffectOutput out{std::move(run.rgb), {}, nlohmann::json::object()};
  const OutputLayers layers = compose_output_layers(job.output, &in, out);
  if (!layers.record.is_null()) run.record["output_layers"] = layers.record;
  const nlohmann::json rec =
      job_record("blur", ctx, blur_job_table().to_json(job), std::move(inputs), run.record, eo.timing);
  write_outputs(job.output, {}, out.main, {}, &in.image_info, rec, {}, &layers);
  return rec;
}

CommandDef blur_command() {
  CommandDef c = make_command<BlurJob>({
      .name = "blur",
      .cli = "blur",
      .summary = "the diffusion engine alone: Gaussian or space-variant blur",
      .table = &blur_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .run = &run_blur_job,
      .report = [](const BlurJob& j, const nlohmann::json& rec) {
        std::fprintf(stderr, "brume blur: %s  sigma_max %.3g px  %d iterations (%s, %s)\n", j.output.out.c_str(),
                     rec["diffusion"]["sigma_max_px"].get<double>(), rec["diffusion"]["iterations"].get<int>(),
                     rec["diffusion"]["scheme"].get<std::string>().c_str(),
                     rec["diffusion"]["precision"].get<std::string>().c_str());
      },
  });
  c.gpu_passes = {"diffusion.rates", "diffusion.iterate"};
  // brume.blur(rgb, scale_map=None): the image read in place (a view), the
  // scale map an Image; the input and output files are the arrays.
  static const auto call = [] {
    std::set<std::string> skip;
    for (const auto& d : input_param_table(false).params()) skip.insert(d.spec.name);
    for (const auto& d : output_param_table({}).params()) skip.insert(d.spec.name);
    skip.insert("scale-map");  // a numpy argument here, not a file
    return array_call_table(blur_job_table(), kArrayExec, skip);
  }();
  c.arrays = make_array_form<BlurJob>(
      "blur", "",
      "The diffusion engine alone: a Gaussian of sqrt(sigma^2 - sigma0^2) (sigma=) or a space-variant blur to a "
      "per-pixel scale map in px (scale_map=). As `brume blur`. A float32 rgb is read in place (no copy).",
      {{"rgb", 3, false, ArrayArg::As::view}, {"scale_map", 1, true, ArrayArg::As::image}}, call, {"rgb", "record"},
      false, [](const std::vector<ArrayIn>& in, ArrayCall<BlurJob>& k, const Exec& e, const std::set<std::string>&) {
        BlurRun r = run_blur(in[0].view, k.p.sigma, in[1].present ? in[1].image : nullptr, k.p.diffusion, e);
        return ArrayResult{{{"rgb", std::move(r.rgb)}}, std::move(r.record), {}, {}};
      });
  return c;
}

}  // namespace brume
