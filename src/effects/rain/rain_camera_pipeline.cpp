// brume — `brume rain`: an RGB-D frame in, the rainy image out (the streaks of the drop field and
// the analytic rain, composed with haze's medium in haze's composite), with the run's record
// (brume/rain.hpp; docs/rain.md, "The camera").
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
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
#include "pipeline/camera_scan_arrays.hpp"
#include "shared/prelude_cpp.h"

namespace brume {

namespace sh = brume::shared;
namespace fs = std::filesystem;

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

// The thin lens's circle of confusion at infinity [px] (dof's), 0 for a pinhole.
double rain_coc_px(const CameraRainParams& p, const DepthSource& depth, int width, int height) {
  if (!p.f_number) return 0.0;
  DofParams dp;
  dp.lens = depth.lens;
  dp.f_number = p.f_number;
  dp.focus_distance_m = p.focus_distance_m;
  validate_dof(dp);
  return coc_infinity_px(dp, width, height);
}

// The scan's rain: brume lidar rain's parameters with the camera's rate, seed and drop sizes.
LidarRainParams camera_rain_lidar_params(const CameraRainParams& p) {
  LidarRainParams lp;
  lp.drops = p.drops;
  lp.seed = p.seed;
  return lp;
}

// The rain's checks that need no pixels (the CLI's and brume.rain's).
void check_camera_rain(const CameraRainParams& p, const DepthSource& depth) {
  validate_camera_rain(p);
  if (p.f_number && !depth.lens.focal_length_mm)
    throw Error("--f-number blurs the streaks by the thin lens, which needs the camera in millimetres: give "
                "--focal-length MM and --sensor-width MM, or drop --f-number (a pinhole)");
}

void check_camera_rain_job(const CameraRainJob& j) {
  check_camera_rain(j.rain, j.input.depth);
  if (j.lidar.empty() != j.lidar_out.empty())
    throw Error(j.lidar.empty() ? "--lidar-out names the rainy scan of --lidar IN.bin: give --lidar too, or drop "
                                  "--lidar-out"
                                : "--lidar rains on a scan: give --lidar-out OUT.bin for it, or drop --lidar");
  if (!j.lidar.empty()) {
    validate_lidar_rain(camera_rain_lidar_params(j.rain));
    // (its folder is checked when the job runs: brume batch plans before it makes the frames' folders)
    if (fs::path(j.lidar_out).extension() != ".bin")
      throw Error("--lidar-out '" + j.lidar_out + "': a scan is written as a KITTI .bin (float32 x, y, z, "
                  "intensity); name it *.bin");
  }
}

// The camera's rain on an image and its measured range (the CLI's job and brume.rain's array
// form): completed and prepared as haze does it, haze's airlight (and with --visibility its
// medium), the streaks and the analytic rain; the record's blocks.
struct CameraRainRun {
  Image rgb, transmission;
  nlohmann::json record;
};
CameraRainRun run_camera_rain(ConstImageView rgb, ConstImageView measured_range, const DepthSource& depth,
                              const CameraRainParams& p, const RangeStep& step, const Exec& exec,
                              const std::set<std::string>& given) {
  const int W = rgb.width(), H = rgb.height();
  const Camera cam = depth_camera(depth, W, H);
  const double coc = rain_coc_px(p, depth, W, H);
  const CompletedRange done = complete_step(measured_range, rgb, step, given, exec.threads);
  const ConstImageView measured = done.view(measured_range);
  // Haze's analysis: its airlight, and with --visibility its medium (sky beyond it, blur).
  HazeParams hp;
  hp.visibility_m = p.visibility_m;
  hp.airlight = p.airlight;
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
  const auto t0 = std::chrono::steady_clock::now();
  CameraRainStats st;
  CameraRainRun run;
  run.rgb = render_camera_rain(scene, p, exec, &st, &run.transmission);
  nlohmann::json& rec = run.record;
  rec["rain"] = camera_rain_record(p, st);
  rec["rain"]["camera"] = camera_record(cam);
  rec["rain"]["coc_infinity_px"] = coc;
  rec["rain"]["airlight_linear_rgb"] = ha.airlight;
  rec["rain"]["airlight_source"] = ha.airlight_source;
  rec["rain"]["sky_rule"] =
      "the sky lies beyond the unbounded media: transmission 0 (the airlight) when there is rain or haze, "
      "blended across the horizon margin by the preparation's sky weight";
  if (hp.visibility_m) rec["haze"] = haze_record(hp, ha);
  rec["prepare"] = prep.record;
  rec["execution"]["backend"] = "cpu";
  rec["execution"]["timing"] = cpu_timing_record(t0, 0);
  return run;
}

nlohmann::json run_camera_rain_job(const CameraRainJob& job, const ExecOptions& eo, const RunContext& given_ctx) {
  RunContext ctx = given_ctx;
  if (!job.lidar.empty()) {
    // The scan does not depend on the image: rained on first, written with the image's outputs.
    check_camera_rain_job(job);
    check_kitti_bin_output(job.lidar_out, "--lidar-out");
    const LidarRainParams lp = camera_rain_lidar_params(job.rain);
    const std::vector<float> in = read_kitti_bin(job.lidar, "--lidar");
    const std::size_t n = in.size() / 4;
    std::vector<float> out(in.size());
    const LidarRainStats st = lidar_rain(in.data(), out.data(), n, lp, nullptr, "--lidar '" + job.lidar + "'");
    ctx.files.push_back({job.lidar_out, kitti_bin_bytes(out.data(), n - st.run.lost), "--lidar-out"});
    if (!ctx.extra.is_object()) ctx.extra = nlohmann::json::object();
    ctx.extra["inputs"]["lidar"] = {{"path", job.lidar}, {"sha256", sha256_file(job.lidar)}, {"points", n}};
    ctx.extra["lidar_rain"] = lidar_rain_record(lp, st);
  }
  const EffectJob<CameraRainJob> e{
      "rain",
      camera_rain_job_table(),
      camera_rain_map_outputs(),
      160,
      [&](const CameraRainJob& j, const ExecOptions&) { check_camera_rain_job(j); },
      [&](const CameraRainJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.rain.airlight) check_airlight_sky(in, "rain");
        const int W = in.rgb.width, H = in.rgb.height;
        CameraRainRun run = run_camera_rain(in.rgb, in.depth.range, j.input.depth, j.rain,
                                            with_camera(j.prepare, in.depth), exec, ctx.given);
        Image& out = run.rgb;
        if (!j.mask.empty()) {
          FileInfo minfo;
          const Image mask = read_scalar(j.mask, "", &minfo);
          if (mask.width != W || mask.height != H)
            throw Error("--mask '" + j.mask + "' is " + mask.size_string() + " but --image is " + in.rgb.size_string() +
                        "; give a mask of the image's size");
          const float full = minfo.integer ? (minfo.bits > 8 ? 65535.0f : 255.0f) : 1.0f;
          for (std::size_t i = 0; i < mask.data.size(); ++i) {
            const float v = mask.data[i] / full;
            if (!(v == v)) throw Error("--mask '" + j.mask + "' holds NaN; give a grey image with values in [0, 1]");
            const float m = std::min(1.0f, std::max(0.0f, v));
            for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = m * out.data[i * 3 + c] + (1.0f - m) * in.rgb.data[i * 3 + c];
          }
          in.record["mask"] = file_record(j.mask, minfo, mask);
        }
        return EffectOutput{std::move(out), {{"transmission", std::move(run.transmission)}}, std::move(run.record), "",
                            {}};
      }};
  return run_effect_job(e, job, eo, ctx);
}

}  // namespace

CommandDef rain_command() {
  CommandDef c = make_command<CameraRainJob>({
      .name = "rain",
      .cli = "rain",
      .summary = "rain on an RGB-D image: streaks of the drop field depth-tested against the scene (Garg & Nayar), "
                 "the rest as extinction in haze's composite",
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
  c.sampling = make_sampling<CameraRainParams>(
      camera_rain_param_table(), {{"rate", "loguniform(1, 100)", {}}, {"rain-seed", "seed()", {}}},
      [](const CameraRainParams& p, const std::set<std::string>&) { validate_camera_rain(p); });
  // brume.rain(rgb, range, lidar=points): the image and its range dense (in place when
  // C-contiguous); a scan given as lidar= is rained on with the same rate, seed and drop sizes
  // (brume lidar rain's model and defaults, as --lidar), its points and labels returned.
  static const auto call =
      array_call_table(camera_rain_param_table(), kArrayPrepare | kArrayIntrinsics | kArrayExec);
  std::vector<ArrayArg> args = rgb_range_args(ArrayArg::As::dense);
  args.push_back({"lidar", 1, true, ArrayArg::As::view, true, true});
  c.arrays = make_array_form<CameraRainParams>(
      "rain", "",
      "Rain on an RGB-D image: the streaks of a Marshall-Palmer drop field over the exposure, depth-tested "
      "against the range (Garg & Nayar), and the rain not drawn as extinction (with visibility, haze's too, in "
      "haze's composite). rate in mm/h is required; the intrinsics (fx.. or fov_x/fov_y) are keywords. "
      "lidar=points (an (N, 4) float32 array of x, y, z, intensity) rains on the frame's scan with the same rate, "
      "rain_seed and drop sizes (brume.lidar.rain's model and defaults): lidar holds the points that return, "
      "lidar_labels one uint8 per input point (0 kept, 1 moved to a drop, 2 lost). As `brume rain`.",
      args, call, {"rgb", "transmission", "lidar", "lidar_labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<CameraRainParams>& k, const Exec& e,
         const std::set<std::string>& g) {
        ArrayResult r;
        // the scan first (as the CLI: its errors before the image's work)
        const std::string what = "brume.rain(): lidar";
        const LidarRainParams lp = camera_rain_lidar_params(k.p);
        LidarRainStats st;
        if (camera_scan_arrays(in, 2, what, r, [&](const float* src, float* out, std::size_t n, std::uint8_t* labels) {
              st = lidar_rain(src, out, n, lp, labels, what);
              return st.run.lost;
            }))
          r.record["lidar_rain"] = lidar_rain_record(lp, st);
        CameraRainRun run = run_camera_rain(in[0].dense.view(), in[1].dense.view(), k.depth, k.p, k.prepare, e, g);
        r.images["rgb"] = std::move(run.rgb);
        r.images["transmission"] = std::move(run.transmission);
        for (auto& [name, v] : run.record.items()) r.record[name] = std::move(v);
        return r;
      },
      [](const ArrayCall<CameraRainParams>& k, const std::set<std::string>& g) {
        check_camera_rain(k.p, k.depth);
        check_range_step(k.prepare, g);
      });
  // A call that rained on a scan says so in its job, as the camera effects' lidar= does: an empty
  // lidar block (the scan's rain has no settings of its own: the rain's rate, seed and drops).
  mark_scan_in_job(*c.arrays, 2);
  return c;
}

}  // namespace brume
