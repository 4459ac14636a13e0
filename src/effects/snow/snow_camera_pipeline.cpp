// brume — `brume snow`: an RGB-D frame in, the snowy image out (the flakes of the field and the
// analytic snow, composed with haze's medium in haze's composite), with the run's record; with
// --lidar the frame's scan through the same snowfall (brume/snow.hpp; docs/snow.md).
#include <cstdio>
#include <optional>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/pipeline.hpp"
#include "brume/snow.hpp"
#include "effects/rain/rain_gpu.hpp"
#include "effects/rain/streaks_pipeline.hpp"
#include "pipeline/camera_scan_arrays.hpp"

namespace brume {

namespace {

struct CameraSnowJob {
  InputFiles input;
  RangeStep prepare;
  CameraSnowParams snow;
  std::string mask;
  OutputFiles output;
  std::string lidar, lidar_out;  // --lidar IN.bin --lidar-out OUT.bin: the scan through the same snow
};

const std::vector<MapOutput>& camera_snow_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"transmission", "write the analytic media's transmission (haze and the snow not drawn), 1 channel", ""},
  };
  return m;
}

const ParamTable<CameraSnowJob>& camera_snow_job_table() {
  static const ParamTable<CameraSnowJob> t = [] {
    ParamTable<CameraSnowJob> d("snow");
    d.nest(&CameraSnowJob::input, input_param_table(true))
        .nest(&CameraSnowJob::prepare, range_step_param_table())
        .nest(&CameraSnowJob::snow, camera_snow_param_table())
        .text("mask", &CameraSnowJob::mask,
              "grey image of the image's size: the snow applies where it is white, the image is kept where it is "
              "black, mixed in between (its value over the file's full scale); default: everywhere")
        .reads_file()
        .nest(&CameraSnowJob::output, output_param_table(camera_snow_map_outputs()))
        .text("lidar", &CameraSnowJob::lidar,
              "a KITTI velodyne .bin to snow on with the same --rate, --distribution, --flake-density, --fall-speed "
              "and --snow-seed as its --seed (brume lidar snow's model and its defaults), written to --lidar-out "
              "with the image")
        .reads_file()
        .text("lidar-out", &CameraSnowJob::lidar_out, "the snowy scan of --lidar (KITTI .bin: the points that return)")
        .writes_file_of("lidar", ".bin");
    return d;
  }();
  return t;
}

void check_camera_snow_job(const CameraSnowJob& j) {
  validate_camera_snow(j.snow);
  check_streak_lens(j.snow.f_number, j.input.depth, "the flakes");
  check_streak_frames(j.snow.frame, j.snow.frame_interval_s, j.snow.ego_speed_m_s, j.snow.poses,
                      j.input.depth.kitti_calib, kStreakCalibHowCli);
  check_camera_scan_flags(j.lidar, j.lidar_out, "snows on a scan");
  if (!j.lidar.empty()) validate_lidar_snow(camera_snow_lidar_params(j.snow));
}

// The camera's snow on an image and its measured range (the CLI's job and brume.snow's array
// form): rain's steps around render_camera_snow; the record's blocks.
StreakRun run_camera_snow(ConstImageView rgb, ConstImageView measured_range, const DepthSource& depth,
                          const CameraSnowParams& p, const RangeStep& step, const Exec& exec,
                          const std::set<std::string>& given) {
  const double coc = streak_coc_px(p.f_number, p.focus_distance_m, depth, rgb.width(), rgb.height());
  return run_camera_streaks(rgb, measured_range, depth, step, exec, given, coc, p.visibility_m, p.airlight, "snow",
                            [&](const CameraRainScene& scene, Image* tr, nlohmann::json& block) {
                              CameraSnowStats st;
                              Image out = render_camera_snow(scene, p, exec, &st, tr);
                              block = camera_snow_record(p, st);
                              block["pose_files"] = streak_pose_files(p.poses, depth.kitti_calib);
                              return out;
                            });
}

nlohmann::json run_camera_snow_job(const CameraSnowJob& job, const ExecOptions& eo, const RunContext& given_ctx) {
  RunContext ctx = given_ctx;
  if (!job.lidar.empty()) {
    // The scan does not depend on the image: snowed on first, written with the image's outputs.
    check_camera_snow_job(job);
    const LidarSnowParams lp = camera_snow_lidar_params(job.snow);
    run_camera_scan_file(ctx, job.lidar, job.lidar_out, "", "lidar_snow",
                         [&](const float* in, float* out, std::size_t n, std::uint8_t* labels, const std::string& what,
                             nlohmann::json& block) {
                       const LidarSnowStats st = lidar_snow(in, out, n, lp, labels, what);
                       block = lidar_snow_record(lp, st);
                       return st.run.lost;
                     });
  }
  const EffectJob<CameraSnowJob> e{
      "snow",
      camera_snow_job_table(),
      camera_snow_map_outputs(),
      160,
      [&](const CameraSnowJob& j, const ExecOptions&) { check_camera_snow_job(j); },
      [&](const CameraSnowJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.snow.airlight) check_airlight_sky(in, "snow");
        StreakRun run = run_camera_snow(in.rgb, in.depth.range, j.input.depth, j.snow, with_camera(j.prepare, in.depth),
                                        exec, ctx.given);
        if (!j.mask.empty()) apply_streak_mask(run.rgb, in.rgb, j.mask, in.record);
        return EffectOutput{std::move(run.rgb), {{"transmission", std::move(run.transmission)}}, std::move(run.record),
                            "", {}};
      }};
  return run_effect_job(e, job, eo, ctx);
}

}  // namespace

CommandDef snow_command() {
  CommandDef c = make_command<CameraSnowJob>({
      .name = "snow",
      .cli = "snow",
      .summary = "snow on an RGB-D image: the flakes of a snowfall lit by the scene's sky and ground, depth-tested "
                 "and blurred over the exposure, the rest as extinction in haze's composite (--backend gpu: the "
                 "per-pixel passes and the flakes' splat on the GPU, their enumeration on the CPU)",
      .table = &camera_snow_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const CameraSnowJob& j, const std::set<std::string>& g) {
        check_camera_snow_job(j);
        check_range_step(j.prepare, g);
      },
      .run = &run_camera_snow_job,
      .report =
          [](const CameraSnowJob& j, const nlohmann::json& rec) {
            const auto& r = rec["snow"];
            std::fprintf(stderr,
                         "brume snow: %s  %.4g mm/h (water), T %.4g s: %zu flakes drawn (mean path %.3g px), "
                         "extinction %.4g 1/m beyond %.4g m\n",
                         j.output.out.c_str(), r["rate_mm_h"].get<double>(), r["exposure_s"].get<double>(),
                         r["flakes_drawn"].get<std::size_t>(), r["mean_streak_px"].get<double>(),
                         r["extinction_per_m"].get<double>(), r["z_split_m"].get<double>());
          },
  });
  // The extinction a LiDAR beam sees in this job's media (brume/lidar_camera.hpp's hook): the
  // flakes' geometric extinction with the narrow beam's Q = 2, plus haze's 3.912/V.
  c.extinction_per_m = [](const nlohmann::json& job, double) -> std::optional<double> {
    CameraSnowJob j;
    camera_snow_job_table().from_json(j, job, "job");
    if (!j.snow.flakes.rate_mm_h) return std::nullopt;
    return snow_sizes(j.snow.flakes).extinction_per_m(kLidarSnowQ) +
           (j.snow.visibility_m ? 3.912 / *j.snow.visibility_m : 0.0);
  };
  // Rate log-uniform over 0.2-5 mm/h water equivalent: light snow (a few tenths of a mm/h) to a
  // heavy snowfall (5 mm/h: several centimetres of fresh snow an hour); log because the flakes'
  // look changes over decades of the rate. The flakes' seed is drawn per frame (seed()), as
  // rain's: a fixed seed would draw the same flakes at the same pixels in every frame.
  // --backend gpu: the per-pixel passes and the streaks' splat on the GPU (effects/rain/rain_gpu.hpp).
  c.gpu_passes = streak_gpu_passes();
  c.sampling = make_sampling<CameraSnowParams>(
      camera_snow_param_table(), {{"rate", "loguniform(0.2, 5)", {}}, {"snow-seed", "seed()", {}}},
      [](const CameraSnowParams& p, const std::set<std::string>&) { validate_camera_snow(p); });
  // brume.snow(rgb, range, lidar=points): as brume.rain (the image and its range dense; a scan
  // given as lidar= is snowed on with the same snowfall and seed, its points and labels returned).
  static const auto call = streak_array_call_table(camera_snow_param_table());
  std::vector<ArrayArg> args = rgb_range_args(ArrayArg::As::dense);
  args.push_back({"lidar", 1, true, ArrayArg::As::view, true, true});
  c.arrays = make_array_form<CameraSnowParams>(
      "snow", "",
      "Snow on an RGB-D image: the flakes of a snowfall over the exposure, lit by the image's sky and ground, "
      "depth-tested against the range, and the snow not drawn as extinction (with visibility, haze's too, in haze's "
      "composite). rate in mm/h (water equivalent) is required; the intrinsics (fx.. or fov_x/fov_y) are keywords. "
      "lidar=points (an (N, 4) float32 array of x, y, z, intensity) snows on the frame's scan with the same snowfall "
      "and snow_seed (brume.lidar.snow's model and defaults): lidar holds the points that return, lidar_labels one "
      "uint8 per input point (0 kept, 1 moved to a flake, 2 lost); kitti_calib=FILE (KITTI's calib/N.txt) places "
      "the camera of poses=. As `brume snow`.",
      args, call, {"rgb", "transmission", "lidar", "lidar_labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<CameraSnowParams>& k, const Exec& e,
         const std::set<std::string>& g) {
        const CameraSnowParams& p = k.p;
        check_streak_frames(p.frame, p.frame_interval_s, p.ego_speed_m_s, p.poses, k.depth.kitti_calib,
                            kStreakCalibHowPython);
        check_streak_array_calib(k.depth.kitti_calib, !p.poses.empty(), "brume.snow");
        const LidarSnowParams lp = camera_snow_lidar_params(p);
        return streak_array_result(
            in, "brume.snow(): lidar", "lidar_snow",
            [&](const float* src, float* out, std::size_t n, std::uint8_t* labels, nlohmann::json& block) {
              const LidarSnowStats st = lidar_snow(src, out, n, lp, labels, "brume.snow(): lidar");
              block = lidar_snow_record(lp, st);
              return st.run.lost;
            },
            [&] { return run_camera_snow(in[0].dense.view(), in[1].dense.view(), k.depth, p, k.prepare, e, g); });
      },
      [](const ArrayCall<CameraSnowParams>& k, const std::set<std::string>& g) {
        validate_camera_snow(k.p);
        check_streak_lens(k.p.f_number, k.depth, "the flakes");
        check_streak_frames(k.p.frame, k.p.frame_interval_s, k.p.ego_speed_m_s, k.p.poses, k.depth.kitti_calib,
                            kStreakCalibHowPython);
        check_range_step(k.prepare, g);
      });
  // A call that snowed on a scan says so in its job (an empty lidar block), as brume.rain's.
  streak_array_lidar_job(c);
  return c;
}

}  // namespace brume
