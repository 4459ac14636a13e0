// brume — `brume lidar fog`: a KITTI .bin scan in, the foggy scan out, with
// its record and optionally the uncut soft-target curve (brume/lidar_fog.hpp).
#include <cstdio>
#include <filesystem>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/height_profile.hpp"
#include "brume/io.hpp"
#include "brume/lidar_fog.hpp"
#include "brume/record.hpp"
#include "effects/lidar/lidar_fog_job.hpp"

namespace brume {

namespace fs = std::filesystem;

// The medium's constants and the run's figures, for the record.
nlohmann::json lidar_fog_record(const LidarFogParams& p, const LidarFogStats& st) {
  const LidarFogMedium m = lidar_fog_medium(p);
  auto finite_or_null = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  const bool layered = p.profile && *p.profile != HeightProfile::constant;
  nlohmann::json j = {
      {"model", layered ? "Hahner et al. ICCV 2021 (from the paper's equations) with brume's height-layered fog "
                          "along each beam"
                        : "Hahner et al. ICCV 2021, homogeneous fog (from the paper's equations)"},
      {"alpha_per_m", finite_or_null(m.alpha)},
      {"alpha_from", layered      ? "profile (per beam: optical depth along it)"
                     : p.profile  ? "profile constant (its density)"
                     : p.alpha_per_m ? "alpha"
                                     : "visibility (3.912/V)"},
      {"mor_m", finite_or_null(m.mor_m)},
      {"beta_b_per_m_sr", finite_or_null(m.beta_b)},
      {"lidar_ratio_sr", p.lidar_ratio_sr ? *p.lidar_ratio_sr : kLidarPaperRatioSr},
      {"beta0_per_sr", m.beta0},
      {"c_a_m3_per_s", m.c_a},
      {"pulse_length_m", m.pulse_m},
      {"table_step_m", m.pulse_m / kLidarStepsPerPulse},
      {"seed", p.seed},
      {"noise", p.noise}};
  if (p.profile) j["profile"] = enum_name(height_profile_names(), *p.profile);
  if (layered) {
    const RigidTransform t = lidar_world_from_scan(p);
    nlohmann::json rot = nlohmann::json::array();
    for (const auto& row : t.rotation.m) rot.push_back({row[0], row[1], row[2]});
    j["world_from_scan"] = {{"rotation", rot},
                            {"translation_m", {t.translation.x, t.translation.y, t.translation.z}},
                            {"from", p.pose.kitti_calib.empty()
                                         ? "--sensor-height (the scan's z axis up)"
                                         : "--kitti-calib (Tr_velo_to_cam, R0_rect, P2) and camera 2's pose"}};
    j["elevation_step_deg"] = p.elevation_step_deg;
  }
  j.update(st.record());
  return j;
}

const ParamTable<LidarFogJob>& lidar_fog_job_table() {
  static const ParamTable<LidarFogJob> t = [] {
    ParamTable<LidarFogJob> d("files");
    d.text("points", &LidarFogJob::points, "the scan: KITTI velodyne .bin (float32 x, y, z, reflectance)")
        .reads_file()
        .nest(&LidarFogJob::fog, lidar_fog_param_table())
        .text("out", &LidarFogJob::out, "the foggy scan, KITTI .bin (same points, same order, same count)")
        .writes_file()
        .text("record", &LidarFogJob::record, "write a JSON record that `brume run` repeats")
        .writes_file()
        .text("soft-curve", &LidarFogJob::soft_curve,
              "write the uncut soft-target power P_soft(R) as CSV range_m,power_w (0 to the scan's farthest point); with "
              "--profile the level beam's, from the scan's origin")
        .writes_file();
    return d;
  }();
  return t;
}

nlohmann::json run_lidar_fog_job(const LidarFogJob& job, const RunContext& ctx) {
  lidar_fog_job_table().validate(job);
  validate_lidar_fog(job.fog);
  if (job.points.empty()) throw Error("no scan given: use --points FILE.bin (KITTI velodyne)");
  if (job.out.empty()) throw Error("no output given: use --out FILE.bin");
  check_kitti_bin_output(job.out, "--out");
  if (!job.record.empty()) check_record_path(job.record);
  if (!job.soft_curve.empty()) check_output_dir(job.soft_curve, "--soft-curve");

  const std::vector<float> in = read_kitti_bin(job.points, "--points", kLidarFogBytesPerPoint);
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  const LidarFogStats st = lidar_fog(in.data(), out.data(), n, job.fog, "--points '" + job.points + "'");

  nlohmann::json inputs = {{"points", {{"path", job.points}, {"sha256", sha256_file(job.points)}, {"points", n}}}};
  if (job.fog.profile && !job.fog.pose.kitti_calib.empty())
    inputs["kitti_calib"] = {{"path", job.fog.pose.kitti_calib}, {"sha256", sha256_file(job.fog.pose.kitti_calib)}};
  if (job.fog.profile && !job.fog.fog.camera.view_matrix_file.empty())
    inputs["view_matrix"] = {{"path", job.fog.fog.camera.view_matrix_file},
                             {"sha256", sha256_file(job.fog.fog.camera.view_matrix_file)}};
  if (job.fog.profile == HeightProfile::table)
    inputs[kDensityTableInput] = {{"path", job.fog.fog.table_file}, {"sha256", sha256_file(job.fog.fog.table_file)}};
  const nlohmann::json rec =
      job_record("lidar fog", ctx, lidar_fog_job_table().to_json(job), inputs, {{"lidar", lidar_fog_record(job.fog, st)}},
                 false);
  OutputSet outs;
  outs.write_text(job.out, kitti_bin_bytes(out.data(), n), "--out");
  if (!job.soft_curve.empty()) {
    double far = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = in[4 * i], y = in[4 * i + 1], z = in[4 * i + 2];
      far = std::max(far, std::sqrt(x * x + y * y + z * z));
    }
    outs.write_text(job.soft_curve, soft_curve_csv(lidar_soft_curve(job.fog, far)), "--soft-curve");
  }
  if (!job.record.empty()) outs.write_text(job.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  return rec;
}

Image lidar_fog_array(const ConstImageView& v, const LidarFogParams& p, const std::string& what, LidarFogStats& stats) {
  std::vector<float> dense;
  const float* src = scan_points(v, what, dense);
  Image out(4, v.height(), 1);
  stats = lidar_fog(src, out.data.data(), static_cast<std::size_t>(v.height()), p, what);
  return out;
}

CommandDef lidar_fog_command() {
  CommandDef c = make_command<LidarFogJob>({
      .name = "lidar fog",
      .cli = "lidar fog",
      .summary = "fog a LiDAR scan (KITTI .bin): attenuated returns and fog returns (Hahner et al. 2021)",
      .table = &lidar_fog_job_table(),
      .writes_record = true,
      .check = [](const LidarFogJob& j, const std::set<std::string>&) { validate_lidar_fog(j.fog); },
      .run = [](const LidarFogJob& j, const ExecOptions&, const RunContext& ctx) { return run_lidar_fog_job(j, ctx); },
      .report = [](const LidarFogJob& j, const nlohmann::json& rec) {
        const auto& l = rec["lidar"];
        char medium[96];
        if (l["alpha_per_m"].is_number())
          std::snprintf(medium, sizeof medium, "alpha %.4g 1/m", l["alpha_per_m"].get<double>());
        else
          std::snprintf(medium, sizeof medium, "profile %s, %zu tables", l["profile"].get<std::string>().c_str(),
                        l["tables"].get<std::size_t>());
        std::fprintf(stderr, "brume lidar fog: %s  %s  %zu of %zu points turned into fog (%.2f %%)\n", j.out.c_str(),
                     medium, l["soft_points"].get<std::size_t>(), l["points"].get<std::size_t>(),
                     100 * l["soft_fraction"].get<double>());
      },
  });
  // Visibility log-uniform over 50-1000 m: alpha 0.0039-0.078 1/m, which holds
  // the paper's experiments (alpha 0.005-0.06); on KITTI 000001 fog returns
  // appear below ~100 m (9 % of the points at 50 m) and beyond it the returns
  // are attenuated only (e^{-2 alpha R} = 0.68 at 50 m for V = 1000 m).
  // Sampled: the fog only; the noise's seed is the caller's (a transform
  // derives it from its seed and key).
  c.sampling = make_sampling<LidarFogParams>(
      lidar_fog_param_table(), {{"visibility", "loguniform(50, 1000)", {"alpha"}}},
      [](const LidarFogParams& p, const std::set<std::string>&) { validate_lidar_fog(p); });
  c.extinction_per_m = [](const nlohmann::json& job, double height_m) -> std::optional<double> {
    LidarFogJob j;
    lidar_fog_job_table().from_json(j, job, "job");
    if (j.fog.profile) {  // the profile's density at that height (brume fog's)
      HeightMedium f = j.fog.fog;
      f.profile = *j.fog.profile;
      const DensityTable table = f.profile == HeightProfile::table ? read_density_table(f.table_file) : DensityTable{};
      return height_density(f, table, 0.0).at(height_m);
    }
    if (!j.fog.visibility_m && !j.fog.alpha_per_m) return std::nullopt;  // no fog given yet
    return lidar_fog_medium(j.fog).alpha;
  };
  // brume.lidar.fog(points): an (N, 4) float32 array (x, y, z, intensity),
  // read in place when C-contiguous; the foggy points as a new (N, 4) array.
  static const auto call = array_call_table(lidar_fog_param_table(), kArrayNone);
  c.arrays = make_array_form<LidarFogParams>(
      "lidar_fog", "brume.lidar.fog",
      "Fog on a LiDAR scan (Hahner et al. 2021, homogeneous): points is an (N, 4) float32 array of x, y, z [m] and "
      "intensity (KITTI reflectance in [0, 1] with the default intensity_scale 255). Returns the foggy (N, 4) points: "
      "attenuated returns and returns moved to the fog's peak. Exactly one of visibility, alpha; or a height-layered fog: "
      "profile with its fields (density, falloff, ...) and the scan's pose (kitti_calib with camera_height, or "
      "sensor_height). As `brume lidar fog`.",
      {{"points", 1, false, ArrayArg::As::view, false, true}}, call, {"points", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<LidarFogParams>& k, const Exec&, const std::set<std::string>&) {
        LidarFogStats st;
        Image out = lidar_fog_array(in[0].view, k.p, "brume.lidar.fog(): points", st);
        ArrayResult r;
        r.record["lidar"] = lidar_fog_record(k.p, st);
        r.images["points"] = std::move(out);
        return r;
      });
  return c;
}

}  // namespace brume
