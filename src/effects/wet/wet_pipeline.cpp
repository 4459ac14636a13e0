// brume — `brume wet`: an RGB-D frame in, its ground wet (darker, with the scene's mirror image)
// out, with --lidar the scan's ground returns through the same film; and `brume lidar wet`
// (brume/wet.hpp; docs/wet-ground.md).
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/medium.hpp"
#include "brume/pipeline.hpp"
#include "brume/record.hpp"
#include "brume/wet.hpp"
#include "core/text.hpp"
#include "effects/wet/wet_gpu.hpp"
#include "pipeline/camera_scan_arrays.hpp"
#include "pipeline/scan_job.hpp"
#include "core/warnings.hpp"

namespace brume {

namespace {

// Where the ground is in the image (block "ground").
struct WetGround {
  CameraPose camera;                 // --pitch, --roll, --camera-height, --view-matrix
  double ground_tolerance_m = 0.15;  // [m] > 0
  std::string mask;                  // --ground-mask: a grey image, the ground where > 1/2
  std::optional<Rgb> airlight;       // the sky a ray leaving the frame sees; unset: haze's estimate
  WetMarch march = WetMarch::above_ground;  // --mirror-march
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
             "auto")
        .choice("mirror-march", &WetGround::march, wet_march_names(),
                "which pixels a mirrored ray can meet: above-ground leaves the plane's own pixels out once the ray "
                "is higher above the plane than --ground-tolerance (it cannot pass behind the plane's surface), so "
                "a ray over open ground crosses it a block at a time (needs --camera-height, else blocks runs); "
                "blocks asks every pixel (the rule of records before it)")
        .since(4, "blocks");
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
        .writes_file_of("lidar", ".bin")
        .text("lidar-labels", &CameraWetJob::lidar_labels,
              "one byte per point of --lidar: 0 off the ground, 1 wet ground kept, 2 lost")
        .writes_file_of("lidar", ".labels.u8")
        .nest(&CameraWetJob::scan, wet_scan_param_table());
    return d;
  }();
  return t;
}

// The camera's settings that name no file (brume.wet's keywords): the film, the ground less its
// mask's and its view matrix's files, the scan's.
// The plane's share of the known downward pixels below which the record warns of a pose that
// misses the ground (KITTI 000001 at its pose: about half; a wrong height: under 1 %).
constexpr double kWetGroundShareWarn = 0.02;

struct CameraWetParams {
  WetFilm wet;
  WetGround ground;
  WetScan scan;
};

const ParamTable<CameraWetParams>& camera_wet_param_table() {
  static const ParamTable<CameraWetParams> t = [] {
    ParamTable<CameraWetParams> d("wet");
    d.nest(&CameraWetParams::wet, wet_film_param_table())
        .nest_except(&CameraWetParams::ground, wet_ground_param_table(), {"ground-mask", "view-matrix"})
        .nest(&CameraWetParams::scan, wet_scan_param_table());
    return d;
  }();
  return t;
}

// What a pose that misses the ground could be instead: the plane that most of the lower half's
// points (every 4th pixel of every 4th row, in the camera's frame) lie on -- RANSAC over 256
// deterministic triples, inliers within 5 cm + 1 % of their range, refined by least squares (the
// inliers' covariance's least eigenvector) -- as the camera's height above it, pitch and roll
// (those whose up vector, cv_from_world·y, is the plane's normal). "" when no plane holds a third
// of the points, or the plane is steeper than 45 degrees to the camera's up.
std::string fitted_ground_hint(const Image& range, const Camera& cam) {
  std::vector<Vec3> pts;
  for (int y = cam.height / 2 + 2; y < cam.height; y += 4)
    for (int x = 2; x < cam.width; x += 4) {
      const float r = range.at(x, y);
      if (!(std::isfinite(r) && r > 0.0f)) continue;
      const Vec3 d = cam.pixel_ray_cv(x, y);
      const double k = r / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
      pts.push_back({d.x * k, d.y * k, d.z * k});
    }
  if (pts.size() < 30) return "";
  const auto near = [](const Vec3& n, double off, const Vec3& q) {
    const double r = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    return std::fabs(n.x * q.x + n.y * q.y + n.z * q.z + off) <= 0.05 + 0.01 * r;
  };
  std::uint64_t draw = 0;  // the triples: brume/medium.hpp's counter-based hash of their count
  const auto pick = [&] {
    return static_cast<std::size_t>(hash_unit(hash_fold(0x6772'6f75'6e64ull, draw++)) * static_cast<double>(pts.size()));
  };
  Vec3 best_n{0, 0, 0};
  double best_off = 0.0;
  std::size_t best = 0;
  for (int it = 0; it < 256; ++it) {
    const Vec3 &a = pts[pick()], &b = pts[pick()], &c = pts[pick()];
    const Vec3 u{b.x - a.x, b.y - a.y, b.z - a.z}, v{c.x - a.x, c.y - a.y, c.z - a.z};
    Vec3 n{u.y * v.z - u.z * v.y, u.z * v.x - u.x * v.z, u.x * v.y - u.y * v.x};
    const double len = std::sqrt(n.x * n.x + n.y * n.y + n.z * n.z);
    if (!(len > 1e-9)) continue;
    n = {n.x / len, n.y / len, n.z / len};
    double off = -(n.x * a.x + n.y * a.y + n.z * a.z);
    if (off < 0.0) n = {-n.x, -n.y, -n.z}, off = -off;  // the camera (the origin) on the normal's side
    if (!(-n.y > std::sqrt(0.5))) continue;             // the cv frame's up is -y: within 45 degrees
    std::size_t in = 0;
    for (const Vec3& q : pts) in += near(n, off, q);
    if (in > best) best = in, best_n = n, best_off = off;
  }
  if (3 * best < pts.size()) return "";
  // Least squares on the inliers: the normal is the covariance's least eigenvector (power iteration
  // on tr(C)·I − C), the offset through their centroid.
  Vec3 m{0, 0, 0};
  std::vector<Vec3> in;
  for (const Vec3& q : pts)
    if (near(best_n, best_off, q)) in.push_back(q), m.x += q.x, m.y += q.y, m.z += q.z;
  const double k = 1.0 / static_cast<double>(in.size());
  m = {m.x * k, m.y * k, m.z * k};
  double C[3][3] = {};
  for (const Vec3& q : in) {
    const double d[3] = {q.x - m.x, q.y - m.y, q.z - m.z};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) C[i][j] += d[i] * d[j] * k;
  }
  const double tr = C[0][0] + C[1][1] + C[2][2];
  double n[3] = {best_n.x, best_n.y, best_n.z};
  for (int it = 0; it < 100; ++it) {
    double w[3];
    for (int i = 0; i < 3; ++i) w[i] = tr * n[i] - (C[i][0] * n[0] + C[i][1] * n[1] + C[i][2] * n[2]);
    const double len = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    for (int i = 0; i < 3; ++i) n[i] = w[i] / len;
  }
  if (n[0] * best_n.x + n[1] * best_n.y + n[2] * best_n.z < 0.0)
    for (double& x : n) x = -x;
  const double height = -(n[0] * m.x + n[1] * m.y + n[2] * m.z);  // the plane n·P + height = 0: the camera above
  // The pose whose up vector in the cv frame is n: try the angles' signs against the camera's own
  // convention (rotation_from_ypr, world_from_camera) and keep the one that gives n back.
  const double pitch = std::asin(std::max(-1.0, std::min(1.0, n[2]))) * 180.0 / 3.14159265358979323846;
  const double roll0 = std::atan2(n[0], -n[1]) * 180.0 / 3.14159265358979323846;
  double best_err = 1e9, bp = 0.0, br = 0.0;
  for (double sp : {1.0, -1.0})
    for (double sr : {1.0, -1.0}) {
      Camera c = cam;
      c.orientation = rotation_from_ypr(0.0, sp * pitch, sr * roll0);
      const Mat3 r = c.world_from_camera().rotation;  // cv into world: its second row is the world's up
      const double e = std::fabs(r.m[1][0] - n[0]) + std::fabs(r.m[1][1] - n[1]) + std::fabs(r.m[1][2] - n[2]);
      if (e < best_err) best_err = e, bp = sp * pitch, br = sr * roll0;
    }
  if (best_err > 1e-6) return "";
  return "; the lower half's points (" + text::g(100.0 * static_cast<double>(in.size()) / pts.size(), 2) +
         " % of them) lie on a plane " + text::g(height, 3) + " m below the camera at pitch " + text::g(bp + 0.0, 3) +
         " deg, roll " + text::g(br + 0.0, 3) + " deg: the ground's pose, if that plane is the ground";
}

// The film's and the ground's checks that need no pixels (the CLI's and brume.wet's); `masked`: a
// ground mask is given (the CLI's --ground-mask FILE, brume.wet's ground_mask= array).
void check_camera_wet(const WetFilm& film, const WetGround& g, bool masked, bool mask_flag) {
  validate_wet_film(film);
  if (!masked && std::isnan(g.camera.height_m) && g.camera.view_matrix_file.empty())
    throw Error(std::string("wet ground needs the ground: give --camera-height M (with --pitch and --roll: the ground "
                            "plane)") +
                (mask_flag ? ", or --ground-mask FILE" : ", or ground_mask=ARRAY"));
}

void check_camera_wet_job(const CameraWetJob& j) {
  check_camera_wet(j.wet, j.ground, !j.ground.mask.empty(), true);
  check_camera_scan_flags(j.lidar, j.lidar_out, "wets a scan's ground", j.lidar_labels);
}

// The camera's wet ground on an image and its measured range (the CLI's job and brume.wet's array
// form): completed and prepared as haze does it, haze's airlight for the mirrored rays that leave the
// frame, the film; the record's blocks. `mask`: the ground (1 channel in [0, 1]) or empty.
struct CameraWetRun {
  Image rgb, ground;
  nlohmann::json record;
};
CameraWetRun run_camera_wet(ConstImageView rgb, ConstImageView measured_range, const DepthSource& depth,
                            const WetFilm& film, const WetGround& g, ConstImageView mask, const RangeStep& step,
                            const Exec& exec, const std::set<std::string>& given) {
  const int W = rgb.width(), H = rgb.height();
  const Camera cam = depth_camera(depth, W, H, g.camera);
  const CompletedRange done = complete_step(measured_range, rgb, step, given, exec.threads);
  const ConstImageView measured = done.view(measured_range);
  // Haze's analysis for its airlight: the sky a mirrored ray leaving the frame sees.
  HazeParams hp;
  hp.airlight = g.airlight;
  hp.kappa_s = 0.0;
  const HazeAnalysis ha = analyse_haze(rgb, measured, hp);
  PreparedRange prep = prepare_step(measured, step, given, exec.threads, true);
  prep.record["complete"] = done.record;

  WetScene scene;
  scene.rgb = rgb;
  scene.range = prep.range;
  scene.camera = cam;
  scene.ground_tolerance_m = g.ground_tolerance_m;
  scene.sky = ha.airlight;
  scene.mask = mask;
  scene.march = g.march;
  // The GPU's backend: the whole per-pixel pass in one fragment shader (effects/wet/wet_gpu.hpp).
  BackendChoice backend = choose_backend(exec);
  const auto t0 = std::chrono::steady_clock::now();
  WetStats st;
  CameraWetRun run;
  GpuTiming gpu_timing;
  run.rgb = backend.gpu ? render_wet_gpu(*backend.gpu, scene, film, &st, &run.ground, gpu_timing)
                        : render_wet(scene, film, exec, &st, &run.ground);
  const WetOptics o(film);
  nlohmann::json& rec = run.record;
  rec["wet"] = wet_optics_record(film, o);
  rec["wet"]["camera"] = camera_record(cam);
  rec["wet"]["ground_rule"] = mask.width() == 0 ? "the pixel's 3-D point within ground_tolerance of the plane y = 0"
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
  rec["wet"]["mirror_march"] = enum_name(wet_march_names(), st.march);
  if (st.march != g.march)
    rec["wet"]["mirror_march_because"] = "no camera height: the plane's pixels are not known, every pixel is asked";
  if (mask.width() == 0) {
    // A pose that misses the ground wets next to nothing without a word: compared, on every 4th
    // pixel of every 4th row, with the known pixels whose rays go down (the ground can only be
    // there), the plane's share below kWetGroundShareWarn says so.
    std::size_t down = 0, on = 0;
    for (int y = 2; y < H; y += 4)
      for (int x = 2; x < W; x += 4) {
        const float r = prep.range.at(x, y);
        if (!(std::isfinite(r) && r > 0.0f) || !(cam.world_ray(x, y).y < 0.0)) continue;
        ++down;
        on += run.ground.at(x, y) > 0.5f;
      }
    if (down > 0 && static_cast<double>(on) < kWetGroundShareWarn * static_cast<double>(down)) {
      const YawPitchRoll a = cam.ypr();
      rec["wet"]["warnings"].push_back(
          "the ground plane " + text::g(cam.position_m.y, 4) + " m below the camera (pitch " +
          text::g(a.pitch_deg + 0.0, 3) + " deg, roll " + text::g(a.roll_deg + 0.0, 3) + " deg) holds " +
          text::g(100.0 * static_cast<double>(on) / static_cast<double>(down), 2) +
          " % of the known pixels that look down (sampled 1 in 16): the film wets almost nothing; check the "
          "camera's height, pitch and roll, or give the ground as a mask" +
          fitted_ground_hint(prep.range, cam));
    }
  }
  rec["wet"]["airlight_linear_rgb"] = ha.airlight;
  rec["wet"]["airlight_source"] = ha.airlight_source;
  rec["prepare"] = prep.record;
  rec["execution"] = backend.record;
  if (backend.gpu) {
    rec["execution"]["timing"] = {{"clock", gpu_timing.gpu_timer ? "timer queries" : "glFinish wall time"},
                                  {"upload_ms", gpu_timing.upload_ms},
                                  {"wet_pass_ms", gpu_timing.composite_ms},
                                  {"read_back_ms", gpu_timing.readback_ms}};
    rec["execution"]["march"] =
        "the GPU marches every pixel of the mirrored ray's image (the CPU skips the blocks its min-depth pyramids "
        "clear: the same samples up to rounding; above-ground, it tests each sample for the plane's pixels, the CPU reads a second "
        "depth map without them), in float from the ray's pixel (the CPU from the vanishing point, in double): a "
        "bisection's midpoint halfway between two pixels rounds to either, so a ray may take the pixel beside the "
        "CPU's (0.3-0.7 % of the ground in the tests)";
  } else {
    rec["execution"]["timing"] = cpu_timing_record(t0, 0);
  }
  return run;
}

LidarWetParams camera_wet_lidar_params(const CameraWetJob& j) { return {j.wet, j.scan}; }

nlohmann::json run_camera_wet_job(const CameraWetJob& job, const ExecOptions& eo, const RunContext& given_ctx) {
  RunContext ctx = given_ctx;
  if (!job.lidar.empty()) {
    // The scan does not depend on the image: wetted first, written with the image's outputs.
    check_camera_wet_job(job);
    const LidarWetParams lp = camera_wet_lidar_params(job);
    run_camera_scan_file(ctx, job.lidar, job.lidar_out, job.lidar_labels, "lidar_wet",
                         [&](const float* in, float* out, std::size_t n, std::uint8_t* labels, const std::string& what,
                             nlohmann::json& block) {
                           const LidarWetStats st = lidar_wet(in, out, n, lp, labels, what);
                           block = lidar_wet_record(lp, st);
                           return st.lost;
                         });
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
        }
        CameraWetRun run = run_camera_wet(in.rgb, in.depth.range, j.input.depth, j.wet, j.ground,
                                          mask.width > 0 ? ConstImageView(mask) : ConstImageView(),
                                          with_camera(j.prepare, in.depth), exec, ctx.given);
        return EffectOutput{std::move(run.rgb), {{"ground", std::move(run.ground)}}, std::move(run.record), "", {}};
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
      .batchable = true,
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
            if (r.contains("warnings"))
              for (const auto& w : r["warnings"]) print_warning("wet", w.get<std::string>());
          },
  });
  // The extinction a LiDAR beam sees in this job's media (brume/lidar_camera.hpp's hook): none, the
  // film lies on the ground, not in the air.
  c.extinction_per_m = [](const nlohmann::json&, double) -> std::optional<double> { return 0.0; };
  // --backend gpu: the ground, the darkening and the mirror's march in one pass (effects/wet/wet_gpu.hpp).
  c.gpu_passes = {"wet.apply"};
  // The film log-uniform over 0.05-2 mm: a damp road (a twentieth of the default 1 mm roughness
  // wetted) to a road under water (the film over its texture: f = 1 from 1 mm on, about a fifth of
  // the draws); log because the look follows f = h/d, which a damp road spans in tenths of a
  // millimetre. The dry albedo uniform over 0.05-0.25: fresh (dark) to aged (grey) asphalt, which a
  // dataset's roads span; concrete's 0.3-0.4 is given by hand. The scan's detection draws get a seed
  // per frame (seed()), as rain's drop field: a fixed one would keep or lose the same point indices
  // in every frame's ground.
  c.sampling = make_sampling<LidarWetParams>(
      lidar_wet_param_table(),
      {{"film", "loguniform(0.05, 2)", {}}, {"ground-albedo", "uniform(0.05, 0.25)", {}}, {"scan-seed", "seed()", {}}},
      [](const LidarWetParams& p, const std::set<std::string>&) { validate_lidar_wet(p); });
  // brume.wet(rgb, range, lidar=points): the image and its range dense (in place when C-contiguous);
  // a scan given as lidar= passes the same film (brume lidar wet's model and defaults, as --lidar),
  // its points and labels returned. ground_mask= (the CLI's --ground-mask): an H x W bool or float array, the
  // ground where True or above 1/2, taken as the CLI takes a mask file's pixels over its full scale.
  static const auto call = array_call_table(camera_wet_param_table(), kArrayPrepare | kArrayIntrinsics | kArrayExec);
  std::vector<ArrayArg> args = rgb_range_args(ArrayArg::As::dense);
  args.push_back({"lidar", 1, true, ArrayArg::As::view, true, true});
  args.push_back({"ground_mask", 1, true, ArrayArg::As::image, true, false, true});
  c.arrays = make_array_form<CameraWetParams>(
      "wet", "",
      "Wet ground on an RGB-D image: the ground (the plane from camera_height, pitch and roll) darker by Lekner & "
      "Dorf's factor for its albedo and wetted fraction, holding the scene's mirror image (Fresnel's R_F at each "
      "pixel's incidence, the mirrored ray marched through the range map). film in mm is required; the intrinsics "
      "(fx.. or fov_x/fov_y) and camera_height are keywords. lidar=points (an (N, 4) float32 array of x, y, z, "
      "intensity) passes the frame's scan through the same film (brume.lidar.wet's model and defaults): lidar holds "
      "the points that return, lidar_labels one uint8 per input point (0 off the ground, 1 wet ground, 2 lost). "
      "ground_mask (an H x W bool array, or float above 0.5) gives the ground instead of the plane's tolerance, as "
      "--ground-mask. ground is 1 on the ground the film covers. As `brume wet`.",
      args, call, {"rgb", "ground", "lidar", "lidar_labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<CameraWetParams>& k, const Exec& e,
         const std::set<std::string>& g) {
        const bool masked = in[3].present;
        check_camera_wet(k.p.wet, k.p.ground, masked, false);
        check_range_step(k.prepare, g);
        if (masked && (in[3].view.width() != in[0].view.width() || in[3].view.height() != in[0].view.height()))
          throw Error("brume.wet(): ground_mask is " + in[3].view.size_string() + " but rgb is " +
                      in[0].view.size_string() +
                      "; give a mask of the image's size");
        ArrayResult r;
        // the scan first (as the CLI: its errors before the image's work)
        const std::string what = "brume.wet(): lidar";
        const LidarWetParams lp{k.p.wet, k.p.scan};
        LidarWetStats st;
        if (camera_scan_arrays(in, 2, what, r, [&](const float* src, float* out, std::size_t n, std::uint8_t* labels) {
              st = lidar_wet(src, out, n, lp, labels, what);
              return st.lost;
            }))
          r.record["lidar_wet"] = lidar_wet_record(lp, st);
        CameraWetRun run = run_camera_wet(in[0].dense.view(), in[1].dense.view(), k.depth, k.p.wet, k.p.ground,
                                          masked ? in[3].view : ConstImageView(), k.prepare, e, g);
        r.images["rgb"] = std::move(run.rgb);
        r.images["ground"] = std::move(run.ground);
        for (auto& [name, v] : run.record.items()) r.record[name] = std::move(v);
        return r;
      },
      [](const ArrayCall<CameraWetParams>& k, const std::set<std::string>& g) {
        check_camera_wet(k.p.wet, k.p.ground, false, false);
        check_range_step(k.prepare, g);
      });
  mark_scan_in_job(*c.arrays, 2);  // a call that wetted a scan says so in its job, as rain's
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
