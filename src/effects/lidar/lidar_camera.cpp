// brume — a camera effect's --lidar: the frame's scan fogged by the camera's
// own medium, written and recorded with the image (brume/lidar_camera.hpp).
#include "brume/lidar_camera.hpp"

#include <cmath>
#include <algorithm>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <utility>
#include <vector>

#include "brume/error.hpp"
#include "brume/height_profile.hpp"
#include "brume/io.hpp"
#include "brume/lidar_fog.hpp"
#include "brume/medium.hpp"
#include "core/text.hpp"

namespace brume {

namespace fs = std::filesystem;

namespace {
// brume lidar fog's medium and pose flags: on a camera effect the medium is
// the camera's (its --visibility, --density, --profile ... and its pose), so
// they are not the LiDAR block's.
std::set<std::string> medium_names() {
  std::set<std::string> s = {"visibility", "alpha", "profile"};
  for (const auto& d : lidar_fog_param_table().params())
    if (height_medium_param_table().declares(d.spec.name) || lidar_pose_param_table().declares(d.spec.name))
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
        .reads_file()
        .text("lidar-out", &CameraLidar::out,
              "the foggy scan, KITTI .bin (same points, same order, same count); needs --lidar")
        .writes_file_of("lidar", ".bin")
        .real("lidar-wavelength", &CameraLidar::wavelength_nm, "nm", Range::closed(380.0, 2000.0),
              "the LiDAR's wavelength, where a spectral medium's extinction is taken (aerial: Rayleigh + Mie); "
              "grey media (haze, fog) are the same at every wavelength and refuse it")
        .nest_json(&CameraLidar::medium, lidar_fog_param_table(), "lidar-", medium_names());
    return d;
  }();
  return t;
}

namespace {

// The depth block's --kitti-calib: it places a scan in a medium that varies with height.
constexpr const char* kCalib = "kitti-calib";

// What the wrapper keeps of a command: its name and its medium's hooks.
struct Hooks {
  std::string name;
  std::function<std::optional<double>(const nlohmann::json&, double)> extinction;
  std::function<std::optional<double>(const nlohmann::json&, double)> spectral;
  std::function<std::shared_ptr<const HeightMedium>(const nlohmann::json&)> height;
};
Hooks hooks_of(const CommandDef& c) {
  return {c.cli.empty() ? c.name : c.cli, c.extinction_per_m, c.spectral_extinction_per_m, c.height_medium};
}

// The job's medium where it varies with height, else null.
std::shared_ptr<const HeightMedium> height_medium_of(const Hooks& h, const nlohmann::json& job) {
  return h.height ? h.height(job) : nullptr;
}

// brume lidar fog's messages name its flags (--r2); here they are --lidar-r2.
std::string lidar_flags(const std::string& text) {
  return prefix_flag_mentions(text, "lidar-",
                              [](const std::string& n) { return n != "visibility" && n != "alpha" &&
                                                                lidar_fog_param_table().declares(n); });
}

CameraLidarMedium medium_of(const Hooks& h, const nlohmann::json& job, double wavelength_nm) {
  CameraLidarMedium m;
  if (height_medium_of(h, job)) {  // no one alpha: the profile's integral along each beam (lidar_params_from_profile)
    m.alpha_per_m = NAN;
    m.rule = "the camera's height profile, integrated along each beam (the scan placed by --kitti-calib and the "
             "camera's pose)";
    return m;
  }
  std::optional<double> a;
  if (h.spectral) {
    a = h.spectral(job, wavelength_nm);
    m.rule = "the camera's spectral extinction at the LiDAR's wavelength " + text::g(wavelength_nm) + " nm";
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
    throw Error("--lidar: the camera's extinction " + text::g(*a) + " 1/m is not a finite value >= 0");
  m.alpha_per_m = *a;
  return m;
}

// The model's parameters of a scan fogged by the job's medium (alpha = the
// camera's extinction, or the camera's height profile along each beam),
// checked; `given`: the names set explicitly. Shared by the command line's
// --lidar and the array forms' lidar=.
LidarFogParams scan_params(const Hooks& h, const nlohmann::json& job, const CameraLidar& L,
                           const std::set<std::string>& given, CameraLidarMedium& medium) {
  if (job.contains("scene") && job["scene"].contains("scene-scale") && !job["scene"]["scene-scale"].is_null())
    throw Error("--scene-scale scales the image's medium to the frame's median range, but the scan's fog needs the "
                "medium in metres along its beams: give the lengths in metres (drop --scene-scale) to fog a scan");
  if (given.count("lidar-wavelength") && !h.spectral)
    throw Error("--lidar-wavelength: the medium of " + h.name +
                " is grey (its extinction is the same at every wavelength), so the wavelength would change "
                "nothing; drop it");
  medium = medium_of(h, job, L.wavelength_nm);
  // The block's own settings (pulse, receiver, noise, seed), as the LiDAR fog's.
  LidarFogParams settings;
  if (L.medium.is_object())
    for (const auto& [n, v] : L.medium.items()) lidar_fog_param_table().at(n).set(settings, v);
  LidarFogParams params;
  if (std::isnan(medium.alpha_per_m)) {
    // A height profile: the job's profile and camera pose (its command's
    // height_medium), the scan placed by the depth block's --kitti-calib
    // (Tr_velo_to_cam, R0_rect, P2) relative to camera 2, whose pose the
    // profile already takes.
    const std::shared_ptr<const HeightMedium> hm = height_medium_of(h, job);
    const std::string calib = job.contains("depth") ? job["depth"].value(kCalib, std::string()) : std::string();
    if (calib.empty())
      throw Error("--lidar with --profile " + enum_name(height_profile_names(), hm->profile) +
                  ": the fog varies with height, so the scan needs its pose in the camera's world; give "
                  "--kitti-calib FILE (its Tr_velo_to_cam and R0_rect place the scan relative to camera 2, whose "
                  "--camera-height, --pitch and --roll the fog takes), or use --profile constant --density D");
    LidarPose pose;
    pose.kitti_calib = calib;
    try {
      params = lidar_params_from_profile(*hm, pose, settings);
    } catch (const Error& e) {
      throw Error(lidar_flags(e.what()));
    }
  } else {
    params = settings;
    params.visibility_m.reset();
    params.alpha_per_m = medium.alpha_per_m;
  }
  try {
    validate_lidar_fog(params);
  } catch (const Error& e) {
    throw Error(lidar_flags(e.what()));
  }
  return params;
}

// The record's "lidar" block of a fogged scan: the medium's own (brume lidar
// fog's, with its parameters), with how alpha followed from the camera and
// the wavelength.
nlohmann::json scan_record(const Medium& medium, const ScanRun& run, const CameraLidarMedium& m, double wavelength_nm) {
  nlohmann::json block = medium.scan_record(run);
  block["alpha_from"] = m.rule;
  block["wavelength_nm"] = wavelength_nm;
  return block;
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
  r.params = scan_params(h, job, L, given, r.medium);
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
    const std::vector<float> in = read_kitti_bin(c.lidar.points, "--lidar", kLidarFogBytesPerPoint);
    const std::size_t n = in.size() / 4;
    std::vector<float> out(in.size());
    const std::unique_ptr<Medium> medium = lidar_fog_as_medium(c.params);
    ScanRun run;
    try {
      run = scan_through_media({medium.get()}, in.data(), out.data(), n, "--lidar '" + c.lidar.points + "'");
    } catch (const Error& e) {
      throw Error(lidar_flags(e.what()));
    }
    RunContext with = ctx;
    if (!with.extra.is_object()) with.extra = nlohmann::json::object();
    with.extra["lidar"] = scan_record(*medium, run, c.medium, c.lidar.wavelength_nm);
    with.extra["inputs"]["lidar"] = {
        {"path", c.lidar.points}, {"sha256", sha256_file(c.lidar.points)}, {"points", n}};
    if (std::isnan(c.medium.alpha_per_m)) {  // a height profile: the calibration placed the scan (an input too)
      const std::string calib = job.at("depth").at("kitti-calib").get<std::string>();
      with.extra["inputs"]["kitti_calib"] = {{"path", calib}, {"sha256", sha256_file(calib)}};
    }
    with.files.push_back({c.lidar.out, kitti_bin_bytes(out.data(), n), "--lidar-out"});
    return inner(job, eo, with);
  };
}

// ---- the array forms: brume.haze(rgb, range, lidar=points, lidar_seed=...) ----
// Their keywords: the block less its files (the array stands for --lidar,
// the Result's "lidar" for --lidar-out).
struct ArrayLidar {
  CameraLidar lidar;
};
const ParamTable<ArrayLidar>& array_lidar_table() {
  static const ParamTable<ArrayLidar> t = [] {
    ParamTable<ArrayLidar> d("lidar");
    d.nest_except(&ArrayLidar::lidar, camera_lidar_param_table(), {"lidar", "lidar-out"});
    return d;
  }();
  return t;
}

// The call's values that the command's job declares (block and name): the
// job its medium's hooks read.
nlohmann::json job_of_call(const nlohmann::json& call, const std::vector<ParamSpec>& specs) {
  nlohmann::json job = nlohmann::json::object();
  for (const ParamSpec& s : specs)
    if (call.contains(s.block) && call[s.block].contains(s.name)) job[s.block][s.name] = call[s.block][s.name];
  return job;
}

std::string keyword_of(std::string flag) {
  for (char& ch : flag)
    if (ch == '-') ch = '_';
  return flag;
}

// A medium that varies with height (fog's profiles) also takes kitti_calib=:
// the depth block's --kitti-calib (kCalib), which places the scan in the fog's world.
ParamSpec calib_spec() {
  ParamSpec s = depth_param_table().at(kCalib).spec;
  s.help = "KITTI calibration (calib/N.txt) for lidar= in a fog that varies with height: its Tr_velo_to_cam, "
           "R0_rect and P2 place the scan relative to camera 2, whose camera_height, pitch and roll the fog takes";
  return s;
}

// Adds the scan to an array form: the keyword array lidar= (an (N, 4) scan,
// read in place), the block's settings as keywords, the foggy scan as the
// Result's "lidar" and the record's "lidar" block, as the command line's
// --lidar-out and record hold them (the same function fogs both).
void add_array_lidar(const Hooks& h, const std::vector<ParamSpec>& job_specs, ArrayForm& a) {
  const ParamTable<ArrayLidar>& t = array_lidar_table();
  const std::size_t scan = a.args.size();
  a.args.push_back({"lidar", 1, true, ArrayArg::As::view, true, true});
  for (const Param<ArrayLidar>& d : t.params()) a.specs.push_back(d.spec);
  a.defaults.update(t.to_json(ArrayLidar{}));
  const bool layered = static_cast<bool>(h.height);
  if (layered) {
    a.specs.push_back(calib_spec());
    a.defaults[a.specs.back().block][kCalib] = "";
  }
  a.fields.insert(a.fields.end() - (a.fields.empty() || a.fields.back() != "record" ? 0 : 1), "lidar");
  a.summary += " lidar=points (an (N, 4) float32 scan of x, y, z [m] and intensity, KITTI's layout) is fogged by "
               "the same medium (alpha = the camera's extinction; the lidar_* keywords are brume.lidar.fog's) and "
               "returned as lidar, as --lidar/--lidar-out.";
  a.build = [inner = a.build, &t, layered](const JobValues& values) {
    JobValues own;
    ArrayLidar l;
    bool settings = false;
    std::string calib;
    for (const auto& [n, v] : values) {
      if (layered && n == kCalib) {
        calib_spec().check(v);
        calib = v.get<std::string>();
      } else if (const Param<ArrayLidar>* d = t.find(n)) {
        d->spec.check(v);
        d->set(l, v);
        settings = true;
      } else {
        own.emplace_back(n, v);
      }
    }
    nlohmann::json call = inner(own);
    if (settings) call["lidar"] = t.to_json(l)["lidar"];  // only when set: a call without a scan records none
    if (!calib.empty()) call[calib_spec().block][kCalib] = calib;
    return call;
  };
  // The image's checks on the call without the scan's block (its settings are
  // checked with the scan, when a call gives one).
  a.check = [inner = a.check, &t](const nlohmann::json& call, const std::set<std::string>& given) {
    nlohmann::json own = call;
    own.erase("lidar");
    const std::string block = calib_spec().block;
    if (own.contains(block) && own[block].contains(kCalib)) own[block].erase(kCalib);
    std::set<std::string> g;
    for (const std::string& n : given)
      if (!t.declares(n) && n != kCalib) g.insert(n);
    if (inner) inner(own, g);
  };
  a.run = [h, inner = a.run, job_specs, scan, fn = a.public_name, &t](
              const std::vector<ArrayIn>& in, const nlohmann::json& call, const Exec& e,
              const std::set<std::string>& given) {
    nlohmann::json own = call;
    ArrayLidar l;
    const bool settings = own.contains("lidar");
    if (settings) {
      t.from_json(l, nlohmann::json{{"lidar", own["lidar"]}}, "call");
      own.erase("lidar");
    }
    // kitti_calib= (a layered medium's): the scan's, not the image's call. A
    // job's (a CLI record of a --velodyne depth source) is no setting given.
    const std::string block = calib_spec().block;
    std::string calib;
    if (own.contains(block) && own[block].contains(kCalib)) {
      calib = own[block][kCalib].get<std::string>();
      own[block].erase(kCalib);
    }
    const bool calib_given = given.count(kCalib) > 0;
    const std::vector<ArrayIn> arrays(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(std::min(scan, in.size())));
    if (scan >= in.size() || !in[scan].present) {
      if (calib_given)
        throw Error(fn + "(): kitti_calib places the LiDAR scan in the fog's world, but no lidar= scan is given: "
                         "pass the frame's scan as lidar=points, or drop kitti_calib");
      if (settings) {
        std::string names;
        for (const std::string& n : given)
          if (t.declares(n)) names += (names.empty() ? "" : ", ") + keyword_of(n);
        throw Error(fn + "(): " +
                    (names.empty() ? std::string("the job's lidar block (a record that fogged a scan)")
                                   : "keyword " + names) +
                    " sets the LiDAR scan's fog, but no lidar= scan is given: pass the frame's scan as lidar=points "
                    "(an (N, 4) float32 array of x, y, z, intensity), or drop it");
      }
      ArrayResult r = inner(arrays, own, e, given);
      r.images["lidar"] = Image();  // None
      return r;
    }
    nlohmann::json job = job_of_call(own, job_specs);
    const bool varies = height_medium_of(h, job) != nullptr;
    if (varies && calib.empty())
      throw Error(fn + "(): lidar= with a fog that varies with height: the scan needs its pose in the fog's world; "
                       "give kitti_calib=FILE (KITTI's calib/N.txt: Tr_velo_to_cam and R0_rect place the scan "
                       "relative to camera 2, whose camera_height, pitch and roll the fog takes), or use "
                       "profile='constant' with density=D");
    if (!varies && calib_given)
      throw Error(fn + "(): kitti_calib places the scan in a fog that varies with height; this medium is the same "
                       "at every height, so it would change nothing; drop it");
    if (varies) job[block][kCalib] = calib;
    CameraLidarMedium m;
    std::unique_ptr<Medium> medium;
    ScanRun run;
    Image out;
    try {  // the scan first (milliseconds): its errors before the image's work, as on the command line
      medium = lidar_fog_as_medium(scan_params(h, job, l.lidar, given, m));
    } catch (const Error& err) {
      throw Error(fn + "(): lidar: " + err.what());
    }
    try {
      std::vector<float> dense;
      const float* points = scan_points(in[scan].view, fn + "(): lidar", dense);
      out = Image(4, in[scan].view.height(), 1);
      run = scan_through_media({medium.get()}, points, out.data.data(),
                               static_cast<std::size_t>(in[scan].view.height()), fn + "(): lidar");
    } catch (const Error& err) {
      throw Error(lidar_flags(err.what()));
    }
    ArrayResult r = inner(arrays, own, e, given);
    r.record["lidar"] = scan_record(*medium, run, m, l.lidar.wavelength_nm);
    r.job["lidar"] = t.to_json(l)["lidar"];
    if (varies) {  // the file that placed the scan: in the job as the command line's, and an input with its hash
      r.job[block][kCalib] = calib;
      r.record["inputs"]["kitti_calib"] = {{"path", calib}, {"sha256", sha256_file(calib)}};
    }
    r.images["lidar"] = std::move(out);
    return r;
  };
}

}  // namespace

CameraLidarMedium camera_lidar_medium(const CommandDef& c, const nlohmann::json& job, double wavelength_nm) {
  return medium_of(hooks_of(c), job, wavelength_nm);
}

namespace {
// The wrapping, once the definition is complete (its hooks, run, check,
// summary and array form set, in whatever order its function set them).
void join_scan(CommandDef& c) {
  const Hooks h = hooks_of(c);
  c.run = with_lidar(h, c.run);
  if (c.cli_run) c.cli_run = with_lidar(h, c.cli_run);
  if (c.arrays) add_array_lidar(h, c.specs, *c.arrays);
  c.preview_fixed.push_back("lidar");  // the scan's settings change no pixel of the preview
  c.check = [h, inner = c.check](const nlohmann::json& job, const std::set<std::string>& given, bool full) {
    inner(job, given, full);
    if (full) check_lidar(h, job, given);
  };
  c.report = [inner = c.report](const nlohmann::json& job, const nlohmann::json& rec) {
    if (inner) inner(job, rec);
    if (!rec.is_object() || !rec.contains("lidar") || !rec["lidar"].contains("soft_points")) return;
    const auto& l = rec["lidar"];
    const std::string medium = l["alpha_per_m"].is_number() ? "alpha " + text::g(l["alpha_per_m"].get<double>()) + " 1/m"
                                                             : "the profile along each beam";
    std::fprintf(stderr, "  and its scan: %s  %s  %zu of %zu points turned into fog (%.2f %%)\n",
                 job["lidar"].value("lidar-out", "").c_str(), medium.c_str(), l["soft_points"].get<std::size_t>(),
                 l["points"].get<std::size_t>(), 100 * l["soft_fraction"].get<double>());
  };
}

}  // namespace

void add_camera_lidar(CommandDef& c) { c.finish.push_back(&join_scan); }

}  // namespace brume
