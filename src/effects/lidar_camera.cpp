// brume — a camera effect's --lidar: the frame's scan fogged by the camera's
// own medium, written and recorded with the image (brume/lidar_camera.hpp).
#include "brume/lidar_camera.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <utility>
#include <vector>

#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/io.hpp"

namespace brume {

namespace fs = std::filesystem;

namespace {
// brume lidar fog's medium and pose flags: on a camera effect the medium is
// the camera's (its --visibility, --density, --profile ... and its pose), so
// they are not the LiDAR block's.
std::set<std::string> medium_names() {
  std::set<std::string> s = {"visibility", "alpha", "profile"};
  for (const auto& d : lidar_fog_param_table().params())
    if (fog_param_table().declares(d.spec.name) || lidar_pose_param_table().declares(d.spec.name))
      s.insert(d.spec.name);
  return s;
}
}  // namespace

const ParamTable<CameraLidar>& camera_lidar_param_table() {
  static const ParamTable<CameraLidar> t = [] {
    ParamTable<CameraLidar> d("lidar");
    d.text("lidar", &CameraLidar::points,
           "the frame's LiDAR scan, KITTI velodyne .bin (float32 x, y, z, reflectance): fogged with the camera's "
           "medium (alpha = its extinction) and written to --lidar-out with the image (docs/lidar.md)")
        .text("lidar-out", &CameraLidar::out,
              "the foggy scan, KITTI .bin (same points, same order, same count); needs --lidar")
        .writes_file_of("lidar", ".bin")
        .real("lidar-wavelength", &CameraLidar::wavelength_nm, "nm", Range::closed(380.0, 2000.0),
              "the LiDAR's wavelength, where a spectral medium's extinction is taken (aerial: Rayleigh + Mie); "
              "grey media (haze, fog) are the same at every wavelength and refuse it")
        .nest(&CameraLidar::fog, lidar_fog_param_table(), "lidar-", medium_names());
    return d;
  }();
  return t;
}

namespace {

// What the wrapper keeps of a command: its name and its medium's hooks.
struct Hooks {
  std::string name;
  std::function<std::optional<double>(const nlohmann::json&, double)> extinction;
  std::function<std::optional<double>(const nlohmann::json&, double)> spectral;
  std::function<bool(const nlohmann::json&)> layered;
};
Hooks hooks_of(const CommandDef& c) {
  return {c.cli.empty() ? c.name : c.cli, c.extinction_per_m, c.spectral_extinction_per_m, c.layered_medium};
}

std::string num6(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

// brume lidar fog's messages name its flags (--r2); here they are --lidar-r2.
std::string lidar_flags(const std::string& text) {
  return prefix_flag_mentions(text, "lidar-",
                              [](const std::string& n) { return n != "visibility" && n != "alpha" &&
                                                                lidar_fog_param_table().declares(n); });
}

CameraLidarMedium medium_of(const Hooks& h, const nlohmann::json& job, double wavelength_nm) {
  CameraLidarMedium m;
  if (h.layered && h.layered(job)) {  // no one alpha: brume fog's integral along each beam (lidar_params_from_fog)
    m.alpha_per_m = NAN;
    m.rule = "the camera's height profile, integrated along each beam (the scan placed by --kitti-calib and the "
             "camera's pose)";
    return m;
  }
  std::optional<double> a;
  if (h.spectral) {
    a = h.spectral(job, wavelength_nm);
    m.rule = "the camera's spectral extinction at the LiDAR's wavelength " + num6(wavelength_nm) + " nm";
  } else if (h.extinction) {
    a = h.extinction(job, 0.0);
    m.rule = "the camera's extinction (a grey medium: the same at every wavelength)";
  } else {
    throw Error("--lidar: brume " + h.name + " models no medium to fog a scan with");
  }
  if (!a)
    throw Error("--lidar needs the camera's medium in metres (the scan's ranges are metres), but this " + h.name +
                " job has no physical extinction: give --visibility V in metres (haze; or --range-max R with "
                "--kappa-a/--kappa-s), a fog height profile rather than --classic, or drop --lidar");
  if (!std::isfinite(*a) || *a < 0.0)
    throw Error("--lidar: the camera's extinction " + num6(*a) + " 1/m is not a finite value >= 0");
  m.alpha_per_m = *a;
  return m;
}

// The job's lidar block, checked; `on` false when no scan is asked for.
struct Checked {
  bool on = false;
  CameraLidar lidar;
  CameraLidarMedium medium;
  LidarFogParams params;  // the model's, with alpha = the camera's extinction
};
Checked check_lidar(const Hooks& h, const nlohmann::json& job, const std::set<std::string>& given) {
  Checked r;
  if (job.is_object() && job.contains("lidar"))
    camera_lidar_param_table().from_json(r.lidar, nlohmann::json{{"lidar", job["lidar"]}}, "job");
  const CameraLidar& L = r.lidar;
  r.on = !L.points.empty() || !L.out.empty();
  if (!r.on) {
    for (const std::string& n : given)
      if (camera_lidar_param_table().declares(n))
        throw Error("--" + n + " is a setting of the LiDAR scan, but no --lidar is given; add --lidar IN.bin "
                    "--lidar-out OUT.bin, or drop --" + n);
    return r;
  }
  if (L.points.empty())
    throw Error("--lidar-out '" + L.out + "' without --lidar: give the frame's scan with --lidar IN.bin (KITTI "
                "velodyne), or drop --lidar-out");
  if (L.out.empty())
    throw Error("--lidar '" + L.points + "' without --lidar-out: name the foggy scan with --lidar-out OUT.bin, or "
                "drop --lidar");
  if (fs::path(L.out).extension() != ".bin")
    throw Error("--lidar-out '" + L.out + "': a scan is written as a KITTI .bin (float32 x, y, z, intensity); "
                "name it *.bin");
  if (given.count("lidar-wavelength") && !h.spectral)
    throw Error("--lidar-wavelength: the medium of " + h.name +
                " is grey (its extinction is the same at every wavelength), so the wavelength would change "
                "nothing; drop it");
  r.medium = medium_of(h, job, L.wavelength_nm);
  if (std::isnan(r.medium.alpha_per_m)) {
    // A height profile: the fog job's profile and pose, the scan placed by
    // the depth block's --kitti-calib (Tr_velo_to_cam, R0_rect, P2) relative
    // to camera 2, whose pose the fog already takes.
    FogJob f;
    fog_job_table().from_json(f, job, "job");
    if (f.input.depth.kitti_calib.empty())
      throw Error("--lidar with --profile " + enum_name(fog_profile_names(), f.fog.profile) +
                  ": the fog varies with height, so the scan needs its pose in the camera's world; give "
                  "--kitti-calib FILE (its Tr_velo_to_cam and R0_rect place the scan relative to camera 2, whose "
                  "--camera-height, --pitch and --roll the fog takes), or use --profile constant --density D");
    LidarPose pose;
    pose.kitti_calib = f.input.depth.kitti_calib;
    try {
      r.params = lidar_params_from_fog(f.fog, pose, L.fog);
    } catch (const Error& e) {
      throw Error(lidar_flags(e.what()));
    }
  } else {
    r.params = L.fog;
    r.params.visibility_m.reset();
    r.params.alpha_per_m = r.medium.alpha_per_m;
  }
  try {
    validate_lidar_fog(r.params);
  } catch (const Error& e) {
    throw Error(lidar_flags(e.what()));
  }
  return r;
}

using RunFn = std::function<nlohmann::json(const nlohmann::json&, const ExecOptions&, const RunContext&)>;

// The run with the scan: fogged first (milliseconds), then handed to the
// camera's run as a companion file and record blocks, so that the image,
// the maps, the scan and the record are renamed into place together.
RunFn with_lidar(const Hooks& h, RunFn inner) {
  return [h, inner = std::move(inner)](const nlohmann::json& job, const ExecOptions& eo, const RunContext& ctx) {
    const Checked c = check_lidar(h, job, ctx.given);
    if (!c.on) return inner(job, eo, ctx);
    check_kitti_bin_output(c.lidar.out, "--lidar-out");
    const std::vector<float> in = read_kitti_bin(c.lidar.points, "--lidar");
    const std::size_t n = in.size() / 4;
    std::vector<float> out(in.size());
    LidarFogStats st;
    try {
      st = lidar_fog(in.data(), out.data(), n, c.params, "--lidar '" + c.lidar.points + "'");
    } catch (const Error& e) {
      throw Error(lidar_flags(e.what()));
    }
    nlohmann::json block = lidar_fog_record(c.params, st);
    block["alpha_from"] = c.medium.rule;
    block["wavelength_nm"] = c.lidar.wavelength_nm;
    block["parameters"] = lidar_fog_param_table().to_json(c.params);
    RunContext with = ctx;
    if (!with.extra.is_object()) with.extra = nlohmann::json::object();
    with.extra["lidar"] = std::move(block);
    with.extra["inputs"]["lidar"] = {
        {"path", c.lidar.points}, {"sha256", sha256_file(c.lidar.points)}, {"points", n}};
    with.files.push_back({c.lidar.out, kitti_bin_bytes(out.data(), n), "--lidar-out"});
    return inner(job, eo, with);
  };
}

}  // namespace

CameraLidarMedium camera_lidar_medium(const CommandDef& c, const nlohmann::json& job, double wavelength_nm) {
  return medium_of(hooks_of(c), job, wavelength_nm);
}

void add_camera_lidar(CommandDef& c) {
  const Hooks h = hooks_of(c);
  c.run = with_lidar(h, c.run);
  if (c.cli_run) c.cli_run = with_lidar(h, c.cli_run);
  c.preview_fixed.push_back("lidar");  // the scan's settings change no pixel of the preview
  c.check = [h, inner = c.check](const nlohmann::json& job, const std::set<std::string>& given, bool full) {
    inner(job, given, full);
    if (full) check_lidar(h, job, given);
  };
  c.report = [inner = c.report](const nlohmann::json& job, const nlohmann::json& rec) {
    if (inner) inner(job, rec);
    if (!rec.is_object() || !rec.contains("lidar") || !rec["lidar"].contains("soft_points")) return;
    const auto& l = rec["lidar"];
    const std::string medium = l["alpha_per_m"].is_number() ? "alpha " + num6(l["alpha_per_m"].get<double>()) + " 1/m"
                                                             : "the profile along each beam";
    std::fprintf(stderr, "  and its scan: %s  %s  %zu of %zu points turned into fog (%.2f %%)\n",
                 job["lidar"].value("lidar-out", "").c_str(), medium.c_str(), l["soft_points"].get<std::size_t>(),
                 l["points"].get<std::size_t>(), 100 * l["soft_fraction"].get<double>());
  };
}

}  // namespace brume
