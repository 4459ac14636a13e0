// brume — `brume blur`: the diffusion engine alone (brume/blur.hpp).
#include "brume/blur.hpp"

#include <chrono>
#include <cmath>
#include <sstream>

#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/record.hpp"

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
        .nest(&BlurJob::diffusion, diffusion_param_table())
        .nest(&BlurJob::output, output_param_table({}));
    return d;
  }();
  return t;
}

nlohmann::json run_blur_job(const BlurJob& job, const ExecOptions& eo, const RunContext& ctx) {
  blur_job_table().validate(job);
  const DiffusionParams& dp = job.diffusion;
  if (job.sigma && !job.scale_map.empty())
    throw Error("give either --sigma (a constant scale) or --scale-map (a per-pixel scale), not both");
  if (!job.sigma && job.scale_map.empty())
    throw Error("blur needs a target scale: give --sigma S (px) or --scale-map FILE");
  if (job.sigma && *job.sigma < dp.sigma0) {
    std::ostringstream m;
    m << "--sigma " << *job.sigma << " px is below the inner scale --sigma0 " << dp.sigma0
      << " px; diffusion can only add blur. The Gaussian applied is sqrt(sigma^2 - sigma0^2): give --sigma >= --sigma0";
    throw Error(m.str());
  }
  const Exec exec = eo.exec();
  check_outputs(job.output, {});

  LoadedInputs in = load_inputs(job.input, false);

  check_working_memory("blur", in.rgb, 110);  // measured peak bytes per pixel (README "Reliability")
  const Image& rgb = in.rgb;
  Image smap;
  FileInfo map_info;
  double smax = job.sigma.value_or(dp.sigma0);
  if (!job.scale_map.empty()) {
    smap = read_scalar(job.scale_map, "", &map_info);
    if (smap.width != rgb.width || smap.height != rgb.height)
      throw Error("--scale-map '" + job.scale_map + "' is " + smap.size_string() + " but --image '" + job.input.image +
                  "' is " + rgb.size_string() + "; they must be the same size");
    for (float v : smap.data)
      if (std::isfinite(v)) smax = std::max(smax, static_cast<double>(v));
  } else {
    smap = Image(rgb.width, rgb.height, 1, static_cast<float>(*job.sigma));
  }
  Image f(rgb.width, rgb.height, 4);
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    for (int k = 0; k < 3; ++k) f.data[i * 4 + k] = rgb.data[i * 3 + k];
    f.data[i * 4 + 3] = 1.0f;
  }
  BackendChoice backend = choose_backend(exec);
  DiffusionPlan plan;
  nlohmann::json timing;
  const auto t0 = std::chrono::steady_clock::now();
  if (backend.gpu) {
    GpuTiming t;
    plan = diffuse_gpu(*backend.gpu, f, smap, smax, dp, exec.gpu_filter, &t);
    timing = gpu_timing_record(t);
  } else {
    plan = diffuse(f, smap, smax, dp, exec);
    timing = cpu_timing_record(t0, plan.iterations);
  }
  Image out(rgb.width, rgb.height, 3);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int k = 0; k < 3; ++k) out.data[i * 3 + k] = f.data[i * 4 + k];

  nlohmann::json inputs = in.record, run;
  if (!job.scale_map.empty()) inputs["scale_map"] = file_record(job.scale_map, map_info, smap);
  else run["sigma_px"] = *job.sigma;
  run["diffusion"] = diffusion_record(dp, plan);
  run["execution"] = backend.record;
  run["execution"]["timing"] = timing;
  run["effective_gaussian_px"] = job.sigma ? std::sqrt(*job.sigma * *job.sigma - dp.sigma0 * dp.sigma0) : -1.0;
  const nlohmann::json rec =
      job_record("blur", ctx, blur_job_table().to_json(job), std::move(inputs), run, eo.timing);
  write_outputs(job.output, {}, out, {}, &in.image_info, rec);
  return rec;
}

}  // namespace brume
