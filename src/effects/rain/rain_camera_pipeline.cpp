// brume — `brume rain`: an RGB-D frame in, the rainy image out (the streaks of the drop field and
// the analytic rain, composed with haze's medium in haze's composite), with the run's record
// (brume/rain.hpp; docs/rain.md, "The camera").
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/rain.hpp"
#include "brume/record.hpp"
#include "effects/rain/falling.hpp"
#include "effects/rain/rain_gpu.hpp"
#include "effects/rain/streaks.hpp"
#include "effects/rain/streaks_pipeline.hpp"
#include "pipeline/camera_scan_arrays.hpp"
#include "core/warnings.hpp"

namespace brume {

namespace {

struct CameraRainJob {
  InputFiles input;
  RangeStep prepare;
  CameraRainParams rain;
  std::string mask;
  OutputFiles output;
  std::string lidar, lidar_out;  // --lidar IN.bin --lidar-out OUT.bin: the scan through the same rain
};

const std::vector<MapOutput>& camera_rain_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"transmission", "write the analytic media's transmission (haze and the rain not drawn), 1 channel", ""},
  };
  return m;
}

const ParamTable<CameraRainJob>& camera_rain_job_table() {
  static const ParamTable<CameraRainJob> t = [] {
    ParamTable<CameraRainJob> d("rain");
    d.nest(&CameraRainJob::input, input_param_table(true))
        .nest(&CameraRainJob::prepare, range_step_param_table())
        .nest(&CameraRainJob::rain, camera_rain_param_table())
        .text("mask", &CameraRainJob::mask,
              "grey image of the image's size: the rain applies where it is white, the image is kept where it is "
              "black, mixed in between (its value over the file's full scale; e.g. a car's hood or a tunnel); "
              "default: everywhere")
        .reads_file()
        .nest(&CameraRainJob::output, output_param_table(camera_rain_map_outputs()))
        .text("lidar", &CameraRainJob::lidar,
              "a KITTI velodyne .bin to rain on with the same --rate, --rain-seed, --drop-min and --drop-max (brume "
              "lidar rain's model and its defaults), written to --lidar-out with the image")
        .reads_file()
        .text("lidar-out", &CameraRainJob::lidar_out, "the rainy scan of --lidar (KITTI .bin: the points that return)")
        .writes_file_of("lidar", ".bin");
    return d;
  }();
  return t;
}

// The scan's rain: brume lidar rain's parameters with the camera's rate, seed, drop sizes and return
// mode; with `kitti_calib` (the depth block's, when the scan is drawn in the camera's frame) the
// drops are the camera's.
LidarRainParams camera_rain_lidar_params(const CameraRainParams& p, const std::string& kitti_calib = "") {
  LidarRainParams lp;
  lp.drops = p.drops;
  lp.seed = p.seed;
  lp.return_mode = p.return_mode;
  lp.kitti_calib = kitti_calib;
  // The scan at the image's frame of the sequence: the same time, wind and motion.
  lp.frame = p.frame, lp.frame_interval_s = p.frame_interval_s;
  lp.wind = p.wind, lp.ego_speed_m_s = p.ego_speed_m_s, lp.poses = p.poses;
  return lp;
}

// The scan's block of a camera's rain: brume lidar rain's, and a warning when its drops are not the
// image's (no calibration places the scan in the camera's frame).
nlohmann::json camera_rain_lidar_block(const LidarRainParams& lp, const LidarRainStats& st, bool camera_frame_wanted,
                                       const std::string& how, bool print) {
  nlohmann::json block = lidar_rain_record(lp, st);
  if (camera_frame_wanted && lp.kitti_calib.empty()) {
    const std::string w = "the scan's drops are drawn in the scan's own frame, not the camera's (no KITTI calibration "
                          "places it): the image's streaks and the scan's drop echoes are not the same drops; " + how;
    block["warnings"].push_back(w);
    if (print) print_warning("rain", w);
  }
  return block;
}

// The calibration that places the job's scan in the camera's frame (none: its own frame).
std::string camera_rain_lidar_calib(const CameraRainJob& j) {
  return j.rain.lidar_frame == "camera" ? j.input.depth.kitti_calib : std::string();
}

// The rain's checks that need no pixels (the CLI's and brume.rain's).
void check_camera_rain(const CameraRainParams& p, const DepthSource& depth, const std::string& calib_how) {
  validate_camera_rain(p);
  check_streak_lens(p.f_number, depth, "the streaks");
  check_streak_frames(p.frame, p.frame_interval_s, p.ego_speed_m_s, p.poses, depth.kitti_calib, calib_how);
}

void check_camera_rain_job(const CameraRainJob& j) {
  check_camera_rain(j.rain, j.input.depth, kStreakCalibHowCli);
  check_camera_scan_flags(j.lidar, j.lidar_out, "rains on a scan");
  if (!j.lidar.empty() && !j.rain.poses.empty() && j.rain.lidar_frame == "scan")
    throw Error("--poses '" + j.rain.poses +
                "' with --lidar-frame scan: the scan's pose from camera 0's poses needs its drops in camera 2's frame; "
                "give --lidar-frame camera (with --kitti-calib), or --ego-speed instead of --poses");
  if (!j.lidar.empty()) validate_lidar_rain(camera_rain_lidar_params(j.rain, camera_rain_lidar_calib(j)));
}

// The camera's rain on an image and its measured range (the CLI's job and brume.rain's array
// form): completed and prepared as haze does it, haze's airlight (and with --visibility its
// medium), the streaks and the analytic rain; the record's blocks.
using CameraRainRun = StreakRun;
CameraRainRun run_camera_rain(ConstImageView rgb, ConstImageView measured_range, const DepthSource& depth,
                              const CameraRainParams& p, const RangeStep& step, const Exec& exec,
                              const std::set<std::string>& given) {
  const double coc = streak_coc_px(p.f_number, p.focus_distance_m, depth, rgb.width(), rgb.height());
  return run_camera_streaks(rgb, measured_range, depth, step, exec, given, coc, p.visibility_m, p.airlight, "rain",
                            [&](const CameraRainScene& scene, Image* tr, nlohmann::json& block) {
                              CameraRainStats st;
                              Image out = render_camera_rain(scene, p, exec, &st, tr);
                              block = camera_rain_record(p, st);
                              block["pose_files"] = streak_pose_files(p.poses, depth.kitti_calib);
                              return out;
                            });
}

nlohmann::json run_camera_rain_job(const CameraRainJob& job, const ExecOptions& eo, const RunContext& given_ctx) {
  RunContext ctx = given_ctx;
  if (!job.lidar.empty()) {
    // The scan does not depend on the image: rained on first, written with the image's outputs.
    check_camera_rain_job(job);
    const LidarRainParams lp = camera_rain_lidar_params(job.rain, camera_rain_lidar_calib(job));
    run_camera_scan_file(ctx, job.lidar, job.lidar_out, "", "lidar_rain",
                         [&](const float* in, float* out, std::size_t n, std::uint8_t* labels, const std::string& what,
                             nlohmann::json& block) {
                       const LidarRainStats st = lidar_rain(in, out, n, lp, labels, what);
                       block = camera_rain_lidar_block(lp, st, job.rain.lidar_frame == "camera",
                                                       "give --kitti-calib (KITTI's Tr_velo_to_cam, R0_rect, P2)", true);
                       return st.run.lost;
                     });
  }
  const EffectJob<CameraRainJob> e{
      "rain",
      camera_rain_job_table(),
      camera_rain_map_outputs(),
      160,
      [&](const CameraRainJob& j, const ExecOptions&) { check_camera_rain_job(j); },
      [&](const CameraRainJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.rain.airlight) check_airlight_sky(in, "rain");
        CameraRainRun run = run_camera_rain(in.rgb, in.depth.range, j.input.depth, j.rain,
                                            with_camera(j.prepare, in.depth), exec, ctx.given);
        if (!j.mask.empty()) apply_streak_mask(run.rgb, in.rgb, j.mask, in.record);
        return EffectOutput{std::move(run.rgb), {{"transmission", std::move(run.transmission)}}, std::move(run.record),
                            "", {}};
      }};
  return run_effect_job(e, job, eo, ctx);
}

}  // namespace

CommandDef rain_command() {
  CommandDef c = make_command<CameraRainJob>({
      .name = "rain",
      .cli = "rain",
      .summary = "rain on an RGB-D image: streaks of the drop field depth-tested against the scene (Garg & Nayar), "
                 "the rest as extinction in haze's composite (--backend gpu: the per-pixel passes and the "
                 "streaks' splat on the GPU, the drops' enumeration on the CPU)",
      .table = &camera_rain_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const CameraRainJob& j, const std::set<std::string>& g) {
        check_camera_rain_job(j);
        check_range_step(j.prepare, g);
      },
      .run = &run_camera_rain_job,
      .report =
          [](const CameraRainJob& j, const nlohmann::json& rec) {
            const auto& r = rec["rain"];
            std::fprintf(stderr,
                         "brume rain: %s  %.4g mm/h, T %.4g s: %zu drops drawn (mean streak %.3g px), extinction "
                         "%.4g 1/m beyond %.4g m\n",
                         j.output.out.c_str(), r["rate_mm_h"].get<double>(), r["exposure_s"].get<double>(),
                         r["drops_drawn"].get<std::size_t>(), r["mean_streak_px"].get<double>(),
                         r["extinction_per_m"].get<double>(), r["z_split_m"].get<double>());
          },
  });
  // The extinction a LiDAR beam sees in this job's media (brume/lidar_camera.hpp's hook): the rain's
  // with the narrow beam's Q = 2 (what --lidar's scan is attenuated by), plus haze's 3.912/V.
  c.extinction_per_m = [](const nlohmann::json& job, double) -> std::optional<double> {
    CameraRainJob j;
    camera_rain_job_table().from_json(j, job, "job");
    if (!j.rain.drops.rate_mm_h) return std::nullopt;
    return rain_extinction_per_m(*j.rain.drops.rate_mm_h, kLidarRainQ) + (j.rain.visibility_m ? 3.912 / *j.rain.visibility_m : 0.0);
  };
  // Rate log-uniform over 1-100 mm/h: light rain (1-2.5 mm/h) to a cloudburst (100 mm/h: the
  // international visibility code's heaviest row, docs/rain.md); log because the rain's extinction
  // grows as R^0.63 and its look changes over decades, not steps of mm/h. The drop field's seed
  // is drawn per frame (seed(): 53 bits of the frame's hash), so that no two frames share their
  // drops: a fixed seed would draw the same streaks at the same pixels in every frame of a
  // dataset shot from one camera.
  // --backend gpu: the per-pixel passes and the streaks' splat on the GPU (effects/rain/rain_gpu.hpp).
  c.gpu_passes = streak_gpu_passes();
  c.sampling = make_sampling<CameraRainParams>(
      camera_rain_param_table(), {{"rate", "loguniform(1, 100)", {}}, {"rain-seed", "seed()", {}}},
      [](const CameraRainParams& p, const std::set<std::string>&) { validate_camera_rain(p); });
  // brume.rain(rgb, range, lidar=points): the image and its range dense (in place when
  // C-contiguous); a scan given as lidar= is rained on with the same rate, seed and drop sizes
  // (brume lidar rain's model and defaults, as --lidar), its points and labels returned.
  static const auto call = streak_array_call_table(camera_rain_param_table());
  std::vector<ArrayArg> args = rgb_range_args(ArrayArg::As::dense);
  args.push_back({"lidar", 1, true, ArrayArg::As::view, true, true});
  c.arrays = make_array_form<CameraRainParams>(
      "rain", "",
      "Rain on an RGB-D image: the streaks of a Marshall-Palmer drop field over the exposure, depth-tested "
      "against the range (Garg & Nayar), and the rain not drawn as extinction (with visibility, haze's too, in "
      "haze's composite). rate in mm/h is required; the intrinsics (fx.. or fov_x/fov_y) are keywords. "
      "lidar=points (an (N, 4) float32 array of x, y, z, intensity) rains on the frame's scan with the same rate, "
      "rain_seed and drop sizes (brume.lidar.rain's model and defaults): lidar holds the points that return, "
      "lidar_labels one uint8 per input point (0 kept, 1 moved to a drop, 2 lost); kitti_calib=FILE (KITTI's "
      "calib/N.txt) draws the scan's drops in the camera's frame (lidar_frame='camera': the image's drops) and "
      "places the camera of poses=. As `brume rain`.",
      args, call, {"rgb", "transmission", "lidar", "lidar_labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<CameraRainParams>& k, const Exec& e,
         const std::set<std::string>& g) {
        check_streak_frames(k.p.frame, k.p.frame_interval_s, k.p.ego_speed_m_s, k.p.poses, k.depth.kitti_calib,
                            kStreakCalibHowPython);
        const bool scan = in.size() > 2 && in[2].present;
        check_streak_array_calib(k.depth.kitti_calib, !k.p.poses.empty() || (scan && k.p.lidar_frame == "camera"),
                                 "brume.rain");
        if (scan && !k.p.poses.empty() && k.p.lidar_frame == "scan")
          throw Error("brume.rain(): poses= with lidar_frame='scan': the poses place camera 0, and the scan in its "
                      "own frame has no pose among them; give lidar_frame='camera' (with kitti_calib=)");
        const LidarRainParams lp =
            camera_rain_lidar_params(k.p, k.p.lidar_frame == "camera" ? k.depth.kitti_calib : std::string());
        return streak_array_result(
            in, "brume.rain(): lidar", "lidar_rain",
            [&](const float* src, float* out, std::size_t n, std::uint8_t* labels, nlohmann::json& block) {
              const LidarRainStats st = lidar_rain(src, out, n, lp, labels, "brume.rain(): lidar");
              block = camera_rain_lidar_block(lp, st, k.p.lidar_frame == "camera",
                                              "give kitti_calib=FILE (KITTI's Tr_velo_to_cam, R0_rect, P2)", false);
              return st.run.lost;
            },
            [&] { return run_camera_rain(in[0].dense.view(), in[1].dense.view(), k.depth, k.p, k.prepare, e, g); });
      },
      [](const ArrayCall<CameraRainParams>& k, const std::set<std::string>& g) {
        check_camera_rain(k.p, k.depth, kStreakCalibHowPython);
        check_range_step(k.prepare, g);
      });
  // A call that rained on a scan says so in its job (an empty lidar block).
  streak_array_lidar_job(c);
  return c;
}

}  // namespace brume
