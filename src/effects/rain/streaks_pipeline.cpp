// brume — the steps `brume rain` and `brume snow` share around their camera pass
// (effects/rain/streaks_pipeline.hpp): rain's, moved here unchanged (issue #58).
#include "effects/rain/streaks_pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "brume/depth.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/record.hpp"
#include "effects/rain/rain_gpu.hpp"
#include "pipeline/camera_scan_arrays.hpp"
#include "shared/prelude_cpp.h"

namespace brume {


double streak_coc_px(std::optional<double> f_number, std::optional<double> focus_distance_m, const DepthSource& depth,
                     int width, int height) {
  if (!f_number) return 0.0;
  DofParams dp;
  dp.lens = depth.lens;
  dp.f_number = f_number;
  dp.focus_distance_m = focus_distance_m;
  validate_dof(dp);
  return coc_infinity_px(dp, width, height);
}

void check_streak_lens(std::optional<double> f_number, const DepthSource& depth, const std::string& particles) {
  if (f_number && !depth.lens.focal_length_mm)
    throw Error("--f-number blurs " + particles + " by the thin lens, which needs the camera in millimetres: give "
                "--focal-length MM and --sensor-width MM, or drop --f-number (a pinhole)");
}

StreakRun run_camera_streaks(ConstImageView rgb, ConstImageView measured_range, const DepthSource& depth,
                             const RangeStep& step, const Exec& exec, const std::set<std::string>& given, double coc,
                             std::optional<double> visibility_m, std::optional<Rgb> airlight, const std::string& block,
                             const std::function<Image(const CameraRainScene&, Image*, nlohmann::json&)>& render) {
  namespace sh = brume::shared;
  const int W = rgb.width(), H = rgb.height();
  const Camera cam = depth_camera(depth, W, H);
  const CompletedRange done = complete_step(measured_range, rgb, step, given, exec.threads);
  const ConstImageView measured = done.view(measured_range);
  // Haze's analysis: its airlight, and with --visibility its medium (sky beyond it, blur).
  HazeParams hp;
  hp.visibility_m = visibility_m;
  hp.airlight = airlight;
  if (!hp.visibility_m) hp.kappa_s = 0.0;
  const HazeAnalysis ha = analyse_haze(rgb, measured, hp);
  PreparedRange prep = prepare_step(measured, step, given, exec.threads, true);
  prep.record["complete"] = done.record;

  CameraRainScene scene;
  scene.rgb = rgb;
  scene.range = prep.range;
  if (!prep.sky_weight.empty()) scene.sky_weight = prep.sky_weight;
  scene.k = cam.k;
  scene.coc_infinity_px = coc;
  scene.kitti_calib = depth.kitti_calib;
  scene.airlight = ha.airlight;
  scene.haze_sigma_per_m = hp.visibility_m ? ha.extinction_per_m : 0.0;
  if (hp.visibility_m) {
    // Haze's composite (Hansard eq. 2-4) on the joint transmission, with haze's blur scale.
    scene.composite = [&](const Image& tau0) {
      Image scale(W, H, 1);
      const float s0 = static_cast<float>(hp.diffusion.sigma0), smax = static_cast<float>(ha.sigma_max);
      const float inv = static_cast<float>(1.0 / ha.range_max_m);
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const float r = prep.range.at(x, y);
          const float rn = std::isfinite(r) && r > 0.0f ? r * inv : 1.0f;
          scale.data[static_cast<std::size_t>(y) * W + x] = sh::brume_target_scale(rn, s0, smax);
        }
      return scatter_blur(rgb, tau0, scale, ha.sigma_max, hp.diffusion, hp.composite, ha.airlight, exec).rgb;
    };
  }
  // The GPU's backend: the per-pixel step (the analytic media and haze's composite) and the streaks'
  // splat on the GPU, the particles' enumeration on the CPU (effects/rain/rain_gpu.hpp).
  BackendChoice backend = choose_backend(exec);
  GpuTiming gpu_timing;
  StreakSplatTiming splat_timing;
  std::optional<GpuStreakSplatter> splatter;
  if (backend.gpu) {
    scene.background = [&](const CameraRainOptics& optics, Image* tr) {
      return streak_background_gpu(*backend.gpu, scene, optics, hp, ha, hp.visibility_m.has_value(), exec.gpu_filter,
                                   tr, gpu_timing);
    };
    splatter.emplace(*backend.gpu, splat_timing);
    scene.splatter = &*splatter;
  }
  const auto t0 = std::chrono::steady_clock::now();
  StreakRun run;
  nlohmann::json& rec = run.record;
  run.rgb = render(scene, &run.transmission, rec[block]);
  rec[block]["camera"] = camera_record(cam);
  rec[block]["coc_infinity_px"] = coc;
  rec[block]["airlight_linear_rgb"] = ha.airlight;
  rec[block]["airlight_source"] = ha.airlight_source;
  rec[block]["sky_rule"] =
      "the sky lies beyond the unbounded media: transmission 0 (the airlight) when there is " + block +
      " or haze, blended across the horizon margin by the preparation's sky weight";
  if (hp.visibility_m) rec["haze"] = haze_record(hp, ha);
  rec["prepare"] = prep.record;
  rec["execution"] = backend.record;
  rec["execution"]["timing"] = cpu_timing_record(t0, 0);
  if (backend.gpu) {
    rec["execution"]["gpu_timing"] = gpu_timing_record(gpu_timing);
    rec["execution"]["gpu_splat_timing"] = streak_splat_timing_record(splat_timing);
    rec["execution"]["split"] = streak_gpu_split();
  }
  return run;
}

ArrayResult streak_array_result(
    const std::vector<ArrayIn>& in, const std::string& what, const std::string& lidar_block,
    const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*, nlohmann::json&)>& scan,
    const std::function<StreakRun()>& image) {
  ArrayResult r;
  nlohmann::json block;  // the scan first (as the CLI: its errors before the image's work)
  if (camera_scan_arrays(in, 2, what, r, [&](const float* src, float* out, std::size_t n, std::uint8_t* labels) {
        return scan(src, out, n, labels, block);
      }))
    r.record[lidar_block] = std::move(block);
  StreakRun run = image();
  r.images["rgb"] = std::move(run.rgb);
  r.images["transmission"] = std::move(run.transmission);
  for (auto& [name, v] : run.record.items()) r.record[name] = std::move(v);
  return r;
}

void streak_array_lidar_job(CommandDef& c) { mark_scan_in_job(*c.arrays, 2); }

void apply_streak_mask(Image& out, const Image& rgb, const std::string& mask_path, nlohmann::json& record) {
  const int W = rgb.width, H = rgb.height;
  FileInfo minfo;
  const Image mask = read_scalar(mask_path, "", &minfo);
  if (mask.width != W || mask.height != H)
    throw Error("--mask '" + mask_path + "' is " + mask.size_string() + " but --image is " + rgb.size_string() +
                "; give a mask of the image's size");
  const float full = minfo.integer ? (minfo.bits > 8 ? 65535.0f : 255.0f) : 1.0f;
  for (std::size_t i = 0; i < mask.data.size(); ++i) {
    const float v = mask.data[i] / full;
    if (!(v == v)) throw Error("--mask '" + mask_path + "' holds NaN; give a grey image with values in [0, 1]");
    const float m = std::min(1.0f, std::max(0.0f, v));
    for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = m * out.data[i * 3 + c] + (1.0f - m) * rgb.data[i * 3 + c];
  }
  record["mask"] = file_record(mask_path, minfo, mask);
}

void check_streak_array_calib(const std::string& kitti_calib, bool uses, const std::string& fn) {
  if (!kitti_calib.empty() && !uses)
    throw Error(fn + "(): kitti_calib='" + kitti_calib +
                "' places the camera of poses= (and rain's lidar= scan in the camera's frame), but this call has "
                "neither: it would change nothing; drop it, or give poses= (or lidar= to brume.rain)");
}

}  // namespace brume
