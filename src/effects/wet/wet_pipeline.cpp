// brume — `brume wet`: an RGB-D frame in, its ground wet (darker, with the scene's mirror image)
// out, with --lidar the scan's ground returns through the same film; and `brume lidar wet`
// (brume/wet.hpp; docs/wet-ground.md).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/record.hpp"
#include "brume/wet.hpp"
#include "pipeline/scan_job.hpp"

namespace brume {

namespace {

// Where the ground is in the image (block "ground").
struct WetGround {
  CameraPose camera;                 // --pitch, --roll, --camera-height, --view-matrix
  double ground_tolerance_m = 0.15;  // [m] > 0
  std::string mask;                  // --ground-mask: a grey image, the ground where > 1/2
  std::optional<Rgb> airlight;       // the sky a ray leaving the frame sees; unset: haze's estimate
};

const ParamTable<WetGround>& wet_ground_param_table() {
  static const ParamTable<WetGround> t = [] {
    ParamTable<WetGround> d("ground");
    d.nest_except(&WetGround::camera, camera_pose_param_table(), {"yaw", "camera-x", "camera-z"})
        .real("ground-tolerance", &WetGround::ground_tolerance_m, "m", Range::above(0.0),
              "a pixel whose 3-D point (range, intrinsics, --camera-height, --pitch, --roll) lies within this of the "
              "ground plane is ground")
        .text("ground-mask", &WetGround::mask,
              "grey image of the image's size: the ground where it is above half its full scale (instead of the "
              "plane's test; the pose still gives the plane's normal)")
        .reads_file()
        .rgb("airlight", &WetGround::airlight, "linear RGB", Range::at_least(0.0),
             "the sky's colour a mirrored ray that leaves the frame sees; default: haze's estimate from the image",
             "auto");
    return d;
  }();
  return t;
}

struct CameraWetJob {
  InputFiles input;
  RangeStep prepare;
  WetFilm wet;
  WetGround ground;
  OutputFiles output;
  std::string lidar, lidar_out, lidar_labels;  // the scan through the same film
  WetScan scan;
};

const std::vector<MapOutput>& wet_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"ground", "write the ground the film covers (1 ground, 0 elsewhere), 1 channel", ""},
  };
  return m;
}

const ParamTable<CameraWetJob>& camera_wet_job_table() {
  static const ParamTable<CameraWetJob> t = [] {
    ParamTable<CameraWetJob> d("wet");
    d.nest(&CameraWetJob::input, input_param_table(true))
        .nest(&CameraWetJob::prepare, range_step_param_table())
        .nest(&CameraWetJob::wet, wet_film_param_table())
        .nest(&CameraWetJob::ground, wet_ground_param_table())
        .nest(&CameraWetJob::output, output_param_table(wet_map_outputs()))
        .text("lidar", &CameraWetJob::lidar,
              "a KITTI velodyne .bin whose ground returns pass the same film (brume lidar wet's model), written to "
              "--lidar-out with the image")
        .reads_file()
        .text("lidar-out", &CameraWetJob::lidar_out, "the wet scan of --lidar (KITTI .bin: the points that return)")
        .writes_file_of("lidar", "bin")
        .text("lidar-labels", &CameraWetJob::lidar_labels,
              "one byte per point of --lidar: 0 off the ground, 1 wet ground kept, 2 lost")
        .writes_file()
        .nest(&CameraWetJob::scan, wet_scan_param_table());
    return d;
  }();
  return t;
}

void check_camera_wet_job(const CameraWetJob& j) {
  validate_wet_film(j.wet);
  if (j.lidar.empty() != j.lidar_out.empty())
    throw Error(j.lidar.empty() ? "--lidar-out names the wet scan of --lidar IN.bin: give --lidar too, or drop "
                                  "--lidar-out"
                                : "--lidar wets a scan's ground: give --lidar-out OUT.bin for it, or drop --lidar");
  if (j.lidar.empty() && !j.lidar_labels.empty())
    throw Error("--lidar-labels labels the points of --lidar IN.bin: give --lidar and --lidar-out, or drop it");
  if (!j.lidar.empty()) check_kitti_bin_output(j.lidar_out, "--lidar-out");
  if (!j.lidar_labels.empty()) check_output_dir(j.lidar_labels, "--lidar-labels");
  if (j.ground.mask.empty() && std::isnan(j.ground.camera.height_m) && j.ground.camera.view_matrix_file.empty())
    throw Error("wet ground needs the ground: give --camera-height M (with --pitch and --roll: the ground plane), or "
                "--ground-mask FILE");
}

LidarWetParams camera_wet_lidar_params(const CameraWetJob& j) { return {j.wet, j.scan}; }

nlohmann::json run_camera_wet_job(const CameraWetJob& job, const ExecOptions& eo, const RunContext& given_ctx) {
  RunContext ctx = given_ctx;
  if (!job.lidar.empty()) {
    // The scan does not depend on the image: wetted first, written with the image's outputs.
    check_camera_wet_job(job);
    const LidarWetParams lp = camera_wet_lidar_params(job);
    const std::vector<float> in = read_kitti_bin(job.lidar, "--lidar");
    const std::size_t n = in.size() / 4;
    std::vector<float> out(in.size());
    std::string labels(n, '\0');
    const LidarWetStats st = lidar_wet(in.data(), out.data(), n, lp, reinterpret_cast<std::uint8_t*>(labels.data()),
                                       "--lidar '" + job.lidar + "'");
    ctx.files.push_back({job.lidar_out, kitti_bin_bytes(out.data(), n - st.lost), "--lidar-out"});
    if (!job.lidar_labels.empty()) ctx.files.push_back({job.lidar_labels, labels, "--lidar-labels"});
    if (!ctx.extra.is_object()) ctx.extra = nlohmann::json::object();
    ctx.extra["inputs"]["lidar"] = {{"path", job.lidar}, {"sha256", sha256_file(job.lidar)}, {"points", n}};
    ctx.extra["lidar_wet"] = lidar_wet_record(lp, st);
  }
  const EffectJob<CameraWetJob> e{
      "wet",
      camera_wet_job_table(),
      wet_map_outputs(),
      64,
      [&](const CameraWetJob& j, const ExecOptions&) { check_camera_wet_job(j); },
      [&](const CameraWetJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.ground.airlight) check_airlight_sky(in, "wet");
        const int W = in.rgb.width, H = in.rgb.height;
        const Camera cam = depth_camera(j.input.depth, W, H, j.ground.camera);
        const RangeStep step = with_camera(j.prepare, in.depth);
        const CompletedRange done = complete_step(in.depth.range, in.rgb, step, ctx.given, exec.threads);
        const ConstImageView measured = done.view(in.depth.range);
        // Haze's analysis for its airlight: the sky a mirrored ray leaving the frame sees.
        HazeParams hp;
        hp.airlight = j.ground.airlight;
        hp.kappa_s = 0.0;
        const HazeAnalysis ha = analyse_haze(in.rgb, measured, hp);
        PreparedRange prep = prepare_step(measured, step, ctx.given, exec.threads, true);
        prep.record["complete"] = done.record;

        WetScene scene;
        scene.rgb = in.rgb;
        scene.range = prep.range;
        scene.camera = cam;
        scene.ground_tolerance_m = j.ground.ground_tolerance_m;
        scene.sky = ha.airlight;
        Image mask;
        if (!j.ground.mask.empty()) {
          FileInfo minfo;
          mask = read_scalar(j.ground.mask, "", &minfo);
          if (mask.width != W || mask.height != H)
            throw Error("--ground-mask '" + j.ground.mask + "' is " + mask.size_string() + " but --image is " +
                        in.rgb.size_string() + "; give a mask of the image's size");
          const float full = minfo.integer ? (minfo.bits > 8 ? 65535.0f : 255.0f) : 1.0f;
          for (float& v : mask.data) {
            if (!(v == v))
              throw Error("--ground-mask '" + j.ground.mask + "' holds NaN; give a grey image (ground white)");
            v /= full;
          }
          in.record["ground_mask"] = file_record(j.ground.mask, minfo, mask);
          scene.mask = mask;
        }
        const auto t0 = std::chrono::steady_clock::now();
        WetStats st;
        Image ground;
        Image out = render_wet(scene, j.wet, exec, &st, &ground);
        const WetOptics o(j.wet);
        nlohmann::json rec;
        rec["wet"] = wet_optics_record(j.wet, o);
        rec["wet"]["camera"] = camera_record(cam);
        rec["wet"]["ground_rule"] = j.ground.mask.empty()
                                        ? "the pixel's 3-D point within ground_tolerance of the plane y = 0"
                                        : "the ground mask above 1/2 (the pose gives the plane's normal)";
        rec["wet"]["ground_pixels"] = st.ground;
        rec["wet"]["mirror_hits"] = st.hits;
        rec["wet"]["mirror_sky_pixels"] = st.sky_pixels;
        rec["wet"]["mirror_left_frame"] = st.left_frame;
        rec["wet"]["mirror_rule"] =
            "the pixel's ray mirrored about the plane's normal, marched in screen space through the range map in "
            "steps of " + std::to_string(kWetMarchStepPx) +
            " px, hit where it passes a pixel's range by more than " + std::to_string(kWetHitMargin) +
            " of it (bisected to 1/64 step); at its vanishing point it takes the pixel there; leaving the frame, the "
            "airlight";
        rec["wet"]["airlight_linear_rgb"] = ha.airlight;
        rec["wet"]["airlight_source"] = ha.airlight_source;
        rec["prepare"] = prep.record;
        rec["execution"]["backend"] = "cpu";
        rec["execution"]["timing"] = cpu_timing_record(t0, 0);
        return EffectOutput{std::move(out), {{"ground", std::move(ground)}}, std::move(rec), "", {}};
      }};
  return run_effect_job(e, job, eo, ctx);
}

nlohmann::json run_lidar_wet_job(const LidarWetJob& job, const RunContext& ctx) {
  lidar_wet_job_table().validate(job);
  validate_lidar_wet(job.wet);
  return run_scan_file_job("lidar wet", ctx, lidar_wet_job_table().to_json(job),
                           {job.points, job.out, job.labels, job.record},
                           [&](const float* in, float* out, std::size_t n, std::uint8_t* labels, const std::string& what,
                               nlohmann::json& blocks) {
                             const LidarWetStats st = lidar_wet(in, out, n, job.wet, labels, what);
                             blocks["wet"] = lidar_wet_record(job.wet, st);
                             return st.lost;
                           });
}

}  // namespace

const ParamTable<LidarWetJob>& lidar_wet_job_table() {
  static const ParamTable<LidarWetJob> t = [] {
    ParamTable<LidarWetJob> d("files");
    d.text("points", &LidarWetJob::points, "the scan: KITTI velodyne .bin (float32 x, y, z, reflectance)")
        .reads_file()
        .nest(&LidarWetJob::wet, lidar_wet_param_table())
        .text("out", &LidarWetJob::out,
              "the wet scan, KITTI .bin: the points that return, in input order (ground points weakened by the "
              "film); lost points are left out")
        .writes_file()
        .text("labels", &LidarWetJob::labels, "write one byte per input point: 0 off the ground, 1 wet ground, 2 lost")
        .writes_file()
        .text("record", &LidarWetJob::record, "write a JSON record that `brume run` repeats")
        .writes_file();
    return d;
  }();
  return t;
}

CommandDef wet_command() {
  CommandDef c = make_command<CameraWetJob>({
      .name = "wet",
      .cli = "wet",
      .summary = "wet ground on an RGB-D image: darker ground (Lekner & Dorf) and the scene's mirror image in the film "
                 "(Fresnel), with --lidar the scan's ground returns through the same film",
      .table = &camera_wet_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .check = [](const CameraWetJob& j, const std::set<std::string>& g) {
        check_camera_wet_job(j);
        check_range_step(j.prepare, g);
      },
      .run = &run_camera_wet_job,
      .report =
          [](const CameraWetJob& j, const nlohmann::json& rec) {
            const auto& r = rec["wet"];
            std::fprintf(stderr,
                         "brume wet: %s  film %.4g mm, wetted fraction %.3g: K_eff %.4g on %zu ground pixels (mirror: "
                         "%zu hits, %zu sky, %zu leave the frame)\n",
                         j.output.out.c_str(), r["film_mm"].get<double>(), r["wetted_fraction"].get<double>(),
                         r["k_eff"].get<double>(), r["ground_pixels"].get<std::size_t>(),
                         r["mirror_hits"].get<std::size_t>(), r["mirror_sky_pixels"].get<std::size_t>(),
                         r["mirror_left_frame"].get<std::size_t>());
          },
  });
  // The extinction a LiDAR beam sees in this job's media (brume/lidar_camera.hpp's hook): none, the
  // film lies on the ground, not in the air.
  c.extinction_per_m = [](const nlohmann::json&, double) -> std::optional<double> { return 0.0; };
  return c;
}

CommandDef lidar_wet_command() {
  CommandDef c = make_command<LidarWetJob>({
      .name = "lidar wet",
      .cli = "lidar wet",
      .summary = "wet ground under a LiDAR scan (KITTI .bin): ground returns through the water film at their "
                 "incidence (Fresnel, Lekner & Dorf), weak ones lost",
      .table = &lidar_wet_job_table(),
      .writes_record = true,
      .check = [](const LidarWetJob& j, const std::set<std::string>&) { validate_lidar_wet(j.wet); },
      .run = [](const LidarWetJob& j, const ExecOptions&, const RunContext& ctx) { return run_lidar_wet_job(j, ctx); },
      .report =
          [](const LidarWetJob& j, const nlohmann::json& rec) {
            const auto& r = rec["wet"];
            std::fprintf(stderr, "brume lidar wet: %s  film %.4g mm: of %zu points, %zu on the ground, %zu lost\n",
                         j.out.c_str(), r["film_mm"].get<double>(), r["points"].get<std::size_t>(),
                         r["ground"].get<std::size_t>(), r["lost"].get<std::size_t>());
          },
  });
  // brume.lidar.wet(points): an (N, 4) float32 array (x, y, z, intensity), read in place when
  // C-contiguous; the points that return as a new (K, 4) array and the labels as N bytes.
  static const auto call = array_call_table(lidar_wet_param_table(), kArrayNone);
  c.arrays = make_array_form<LidarWetParams>(
      "lidar_wet", "brume.lidar.wet",
      "Wet ground under a LiDAR scan (one water film: Fresnel at each ground point's incidence, Lekner & Dorf's "
      "internal reflection): points is an (N, 4) float32 array of x, y, z [m] (sensor frame, z up) and intensity. "
      "Returns points, the (K, 4) points that return in input order (None when none does), and labels, one uint8 per "
      "input point: 0 off the ground (unchanged), 1 wet ground, 2 lost. film in mm is required. As `brume lidar wet`.",
      {{"points", 1, false, ArrayArg::As::view, false, true}}, call, {"points", "labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<LidarWetParams>& k, const Exec&, const std::set<std::string>&) {
        LidarWetStats st;
        ArrayResult r = scan_array_result(in[0].view, "brume.lidar.wet(): points",
                                          [&](const float* src, float* out, std::size_t n, std::uint8_t* labels) {
                                            st = lidar_wet(src, out, n, k.p, labels, "brume.lidar.wet(): points");
                                            return st.lost;
                                          });
        r.record["wet"] = lidar_wet_record(k.p, st);
        return r;
      },
      [](const ArrayCall<LidarWetParams>& k, const std::set<std::string>&) { validate_lidar_wet(k.p); });
  return c;
}

}  // namespace brume
