// brume — the LiDAR fog: parameters, the homogeneous model and the entry
// point (brume/lidar_fog.hpp has the equations; the height-layered model is
// in lidar_fog_layered.cpp, the tables both use in lidar_fog_tables.hpp).
#include "brume/lidar_fog.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>

#include "brume/error.hpp"
#include "brume/height_profile.hpp"
#include "core/text.hpp"
#include "effects/lidar/lidar_fog_tables.hpp"

namespace brume {

using namespace lidar_detail;

namespace {

// The overlap ξ(r) and the soft integrand's g(r) = ξ(r)·e^{−2αr}/r².
struct Integrand {
  double r1, r2, alpha;
  double xi(double r) const { return overlap(r, r1, r2); }
  double g(double r) const { return r <= r1 ? 0.0 : xi(r) * std::exp(-2.0 * alpha * r) / (r * r); }
  double node(std::size_t, double r) const { return g(r); }
  double mid(std::size_t, double r) const { return g(r); }
};

// The soft model of one run: the uncut curve at the nodes, its peak, and the
// peak of the curve cut at each node below the uncut peak.
class SoftModel {
 public:
  SoftModel(const LidarFogParams& p, const LidarFogMedium& m, double range_end_m) : c_(m.pulse_m) {
    const Integrand f{p.r1_m, p.r2_m, m.alpha};
    const double h = m.pulse_m / kLidarStepsPerPulse;
    // The uncut maximum lies in [0, R2 + L]; one more pulse of nodes for the cut tails.
    const double end = std::max(range_end_m, p.r2_m + m.pulse_m) + 2 * h;
    lidar_table_nodes(end, h, p.tau_h_ns, range_end_m > p.r2_m + m.pulse_m ? "the scan's farthest point" : "--r2 and one pulse");
    nodes_ = static_cast<std::size_t>(std::ceil(end / h)) + 1;
    c_.extend(f, nodes_);
    k_ = m.c_a * p.p0_w * m.beta_b * 2.0 / kSpeedOfLight;
    uncut_.resize(nodes_);
    for (std::size_t j = 0; j < nodes_; ++j) uncut_[j] = c_.cut(k_, j, j);
    // The uncut peak, searched where it lies.
    const std::size_t search = std::min(nodes_, static_cast<std::size_t>(std::ceil((p.r2_m + m.pulse_m) / h)) + 2);
    peak_node_ = 0;
    for (std::size_t j = 1; j < search; ++j)
      if (uncut_[j] > uncut_[peak_node_]) peak_node_ = j;
    // Cut peaks at the nodes up to the uncut peak: prefix maximum and the cut tail.
    near_peak_.resize(peak_node_ + 2);
    near_range_.resize(peak_node_ + 2);
    std::size_t pre = 0;
    const std::size_t n = kLidarStepsPerPulse;
    for (std::size_t k = 0; k < near_peak_.size(); ++k) {
      if (k >= peak_node_) {
        near_peak_[k] = uncut_[peak_node_];
        near_range_[k] = peak_node_ * h;
        continue;
      }
      if (uncut_[k] > uncut_[pre]) pre = k;
      double best = uncut_[pre];
      std::size_t at = pre;
      if (k * h > p.r1_m)
        for (std::size_t j = k + 1; j < k + n && j < nodes_; ++j) {
          const double v = c_.cut(k_, j, k);
          if (v > best) best = v, at = j;
        }
      near_peak_[k] = best;
      near_range_[k] = at * h;
    }
    h_ = h;
  }

  double step() const { return h_; }
  std::size_t nodes() const { return nodes_; }
  const std::vector<double>& uncut() const { return uncut_; }
  double peak_w() const { return uncut_[peak_node_]; }
  double peak_range() const { return peak_node_ * h_; }

  // The soft peak's power [W] and range [m] for a cut at R0.
  void peak(double r0, double& power, double& range) const {
    const double u = r0 / h_;
    if (u >= static_cast<double>(peak_node_)) {
      power = uncut_[peak_node_];
      range = peak_node_ * h_;
      return;
    }
    const std::size_t k = static_cast<std::size_t>(u);
    interpolate_peak(k >= 1, k >= 1 ? near_peak_[k - 1] : 0.0, near_peak_[k], near_peak_[k + 1], near_range_[k],
                     near_range_[k + 1], u - static_cast<double>(k), power, range);
  }

 private:
  Cumulative c_;
  double k_ = 0.0, h_ = 0.0;
  std::size_t nodes_ = 0, peak_node_ = 0;
  std::vector<double> uncut_, near_peak_, near_range_;
};

double range_m(const float* q) {
  const double x = q[0], y = q[1], z = q[2];
  return std::sqrt(x * x + y * y + z * z);
}

}  // namespace

namespace lidar_detail {
void throw_overflow(const float* in, long long index, const std::string& what) {
  const float* q = in + 4 * index;
  throw Error(what + ": point " + std::to_string(index) + " (intensity " + text::g(q[3]) + ", range " + text::g(range_m(q)) +
              " m) gives a fog return whose intensity overflows float32; its intensity or range is not a LiDAR's: "
              "drop the point or check the scan");
}
}  // namespace lidar_detail

namespace {

// The flags of a height-layered fog: the profile's fields and camera 2's
// pose, nested from the height medium's table (brume/height_profile.hpp:
// the camera effects' names, units, ranges, help).
const std::vector<std::string>& profile_fields() {
  static const std::vector<std::string> v = {"density",   "falloff",     "base-height", "band-center",
                                             "band-half-width", "ramp-bottom", "ramp-top", "table"};
  return v;
}
const std::vector<std::string>& pose_fields() {
  static const std::vector<std::string> v = {"yaw", "pitch", "roll", "camera-height", "camera-x", "camera-z",
                                             "view-matrix"};
  return v;
}

}  // namespace

const ParamTable<LidarPose>& lidar_pose_param_table() {
  static const ParamTable<LidarPose> t = [] {
    ParamTable<LidarPose> d("lidar");
    d.text("kitti-calib", &LidarPose::kitti_calib,
           "KITTI calibration (P2, R0_rect, Tr_velo_to_cam) that places the scan in camera 2's frame, which "
           "--camera-height, --pitch, --roll place in the fog (as the camera effects take them); for a --profile "
           "that depends on height")
        .reads_file("", 0, 4)
        .real("sensor-height", &LidarPose::sensor_height_m, "m", Range::any(),
              "without --kitti-calib: height of the scan's origin above the ground plane, the scan's z axis up; for "
              "a --profile that depends on height",
              "none");
    return d;
  }();
  return t;
}

const ParamTable<LidarFogParams>& lidar_fog_param_table() {
  static const ParamTable<LidarFogParams> t = [] {
    ParamTable<LidarFogParams> d("lidar");
    d.real("visibility", &LidarFogParams::visibility_m, "m", Range::above(0.0),
           "meteorological visibility V of a homogeneous fog; alpha = 3.912/V (Koschmieder, as the camera effects); "
           "give it, --alpha or --profile",
           "none")
        .infinite()
        .real("alpha", &LidarFogParams::alpha_per_m, "1/m", Range::at_least(0.0),
              "extinction coefficient alpha of a homogeneous fog; give it, --visibility or --profile", "none")
        .real("tau-h", &LidarFogParams::tau_h_ns, "ns", Range::left_open(0.0, 1000.0), "half-power pulse width tau_H")
        .real("p0", &LidarFogParams::p0_w, "W", Range::above(0.0), "peak power P0 of the pulse")
        .real("a-r", &LidarFogParams::a_r_m2, "m^2", Range::above(0.0), "receiver aperture A_r")
        .real("l-r", &LidarFogParams::l_r, "1", Range::left_open(0.0, 1.0), "receiver efficiency l_r")
        .real("gamma", &LidarFogParams::gamma, "1", Range::left_open(0.0, 1.0),
              "hard target reflectivity Gamma (beta0 = Gamma/pi)")
        .real("r1", &LidarFogParams::r1_m, "m", Range::above(0.0),
              "range where the transmitter-receiver overlap begins (xi = 0 below)")
        .real("r2", &LidarFogParams::r2_m, "m", Range::above(0.0),
              "range of full overlap (xi = 1 above; linear from --r1); must exceed --r1")
        .real("beta-b", &LidarFogParams::beta_b, "1/(m sr)", Range::at_least(0.0),
              "backscatter coefficient of a homogeneous fog; auto: 0.046/MOR with MOR = ln(20)/alpha (the paper's); "
              "with --profile use --lidar-ratio")
        .real("intensity-scale", &LidarFogParams::intensity_scale, "1", Range::above(0.0),
              "multiplies the input's intensities into the model's [0, 255] (255: KITTI's reflectance in [0, 1]; "
              "1: a scan already in [0, 255]); a scan mostly above 255 after it is refused")
        .choice("noise", &LidarFogParams::noise, {"on", "off"}, "range noise on the points turned into fog")
        .real("range-noise", &LidarFogParams::range_noise_m, "m", Range::at_least(0.0),
              "standard deviation of that noise (Gaussian, redrawn below --r1)")
        .count("seed", &LidarFogParams::seed, "1", Range::at_least(0.0), "seed of the noise (same seed, same scan)")
        .real("lidar-ratio", &LidarFogParams::lidar_ratio_sr, "sr", Range::above(0.0),
              "extinction-to-backscatter ratio S of the fog: beta_b = alpha/S, with --profile delta(y)/S (the local "
              "density's); auto: the paper's 0.046/MOR, S = ln(20)/0.046 = 65.1 sr");
    ParamSpec prof;
    prof.name = "profile";
    prof.kind = ParamKind::choice;
    for (const auto& [e, name] : height_profile_names()) prof.choices.emplace_back(name);
    prof.optional = true;
    prof.unset_word = "none";
    prof.help =
        "height-layered fog along each beam: brume fog's density profile (--density, --falloff, --base-height, "
        "--band-*, --ramp-*, --table) with the scan's pose (--kitti-calib and --camera-height, or --sensor-height); "
        "none: a homogeneous fog (--visibility or --alpha)";
    d.custom(
        prof,
        [](const LidarFogParams& p) {
          return p.profile ? nlohmann::json(enum_name(height_profile_names(), *p.profile)) : nlohmann::json();
        },
        [](LidarFogParams& p, const nlohmann::json& v) {
          if (v.is_null()) p.profile.reset();
          else p.profile = parse_enum(height_profile_names(), v.get<std::string>(), "--profile");
        });
    d.nest_except(&LidarFogParams::fog, height_medium_param_table(), {"profile"})
        .nest(&LidarFogParams::pose, lidar_pose_param_table())
        .real("elevation-step", &LidarFogParams::elevation_step_deg, "deg", Range::closed(0.001, 1.0),
              "with --profile: width of the elevation bins (in sin(elevation), as radians) that share one soft-return "
              "table; a beam is at most half of it from its table's (docs/lidar.md: the error bound)");
    return d;
  }();
  return t;
}

void validate_lidar_fog(const LidarFogParams& p) {
  const ParamTable<LidarFogParams>& t = lidar_fog_param_table();
  t.validate(p);
  if (!(p.r2_m > p.r1_m))
    throw Error("--r2 " + text::g(p.r2_m) + " must exceed --r1 " + text::g(p.r1_m) +
                " (the overlap rises from 0 at R1 to 1 at R2); give --r2 greater than --r1");
  if (p.beta_b && p.lidar_ratio_sr)
    throw Error("--beta-b " + text::g(*p.beta_b) + " and --lidar-ratio " + text::g(*p.lidar_ratio_sr) +
                " both set the fog's backscatter (beta_b = alpha/S); give one of them");
  auto is_set = [&](const std::string& name) { return t.is_set(p, name, {}); };
  if (!p.profile) {
    if (p.visibility_m.has_value() == p.alpha_per_m.has_value())
      throw Error(p.visibility_m ? "--visibility and --alpha both given; give one of them (alpha = 3.912/V)"
                                 : "no fog given: use --visibility V (metres) or --alpha A (1/m), or a height-layered "
                                   "fog with --profile");
    std::vector<std::string> layered = profile_fields();
    layered.insert(layered.end(), pose_fields().begin(), pose_fields().end());
    layered.insert(layered.end(), {"kitti-calib", "sensor-height", "elevation-step"});
    for (const std::string& f : layered)
      if (is_set(f))
        throw Error("--" + f + " describes a height-layered fog, which needs --profile (exponential, band, ramp, "
                    "table or constant); the fog of --visibility or --alpha is homogeneous: drop --" + f +
                    " or give --profile");
    return;
  }
  const std::string prof = "--profile " + enum_name(height_profile_names(), *p.profile);
  if (p.alpha_per_m || p.visibility_m)
    throw Error(prof + " and " + (p.alpha_per_m ? "--alpha" : "--visibility") +
                " both give the fog: --alpha and --visibility are a homogeneous fog's extinction, --profile a "
                "height-layered one's (its --density, ...); give one of them");
  if (p.beta_b)
    throw Error("--beta-b " + text::g(*p.beta_b) + " is one backscatter coefficient for a homogeneous fog; with " + prof +
                " the backscatter follows the local density: give --lidar-ratio S instead (beta_b = delta(y)/S; the "
                "paper's 0.046/MOR is S = 65.1 sr)");
  HeightMedium f = p.fog;
  f.profile = *p.profile;
  validate_height_medium(f);  // the profile's fields; a pose with --profile constant
  if (*p.profile == HeightProfile::constant) {
    for (const char* n : {"kitti-calib", "sensor-height", "elevation-step"})
      if (is_set(n))
        throw Error(std::string("--") + n + " places the beams in the fog's heights, but " + prof +
                    " does not depend on height; drop it");
    return;
  }
  const CameraPose& cam = p.fog.camera;
  if (!p.pose.kitti_calib.empty()) {
    if (p.pose.sensor_height_m)
      throw Error("--sensor-height and --kitti-calib both place the scan; with the calibration the LiDAR's height is "
                  "camera 2's (--camera-height) plus the calibration's offset: give one of them");
    if (std::isnan(cam.height_m) && cam.view_matrix_file.empty())
      throw Error(prof + " with --kitti-calib needs camera 2's height above the ground: give --camera-height METRES "
                  "(and --pitch, --roll, as the camera effects take them), or the whole pose with --view-matrix FILE");
  } else {
    for (const std::string& n : pose_fields())
      if (is_set(n))
        throw Error("--" + n + " poses camera 2, which only --kitti-calib relates to the scan; without a calibration "
                    "the scan's z axis is up and --sensor-height places its origin: give --kitti-calib FILE or drop --" +
                    n);
    if (!p.pose.sensor_height_m)
      throw Error(prof + " needs the LiDAR's height in the fog: give --sensor-height METRES (the scan's origin above "
                  "the ground plane, its z axis up), or --kitti-calib FILE with --camera-height (camera 2's pose, as the "
                  "camera effects take it)");
  }
}

LidarFogParams lidar_params_from_profile(const HeightMedium& medium, const LidarPose& pose, LidarFogParams base) {
  base.visibility_m.reset();
  base.alpha_per_m.reset();
  base.beta_b.reset();
  base.profile = medium.profile;
  base.fog = medium;
  base.pose = medium.profile == HeightProfile::constant ? LidarPose{} : pose;
  if (medium.profile == HeightProfile::constant) base.fog.camera = CameraPose{};
  return base;
}

static bool layered(const LidarFogParams& p) { return p.profile && *p.profile != HeightProfile::constant; }

LidarFogMedium lidar_fog_medium(const LidarFogParams& p) {
  validate_lidar_fog(p);
  LidarFogMedium m;
  if (layered(p)) {
    m.alpha = NAN;
    m.mor_m = NAN;
    m.beta_b = NAN;
  } else {
    m.alpha = p.profile ? p.fog.density_per_m  // constant: the homogeneous model, α = D0
                        : p.alpha_per_m ? *p.alpha_per_m : (std::isinf(*p.visibility_m) ? 0.0 : 3.912 / *p.visibility_m);
    m.mor_m = m.alpha > 0 ? std::log(20.0) / m.alpha : INFINITY;
    m.beta_b = p.beta_b           ? *p.beta_b
               : p.lidar_ratio_sr ? m.alpha / *p.lidar_ratio_sr
                                  : 0.046 * m.alpha / std::log(20.0);  // 0.046/MOR
  }
  m.beta0 = p.gamma / kPi;
  m.c_a = kSpeedOfLight * p.l_r * p.a_r_m2 / 2.0;
  m.pulse_m = kSpeedOfLight * p.tau_h_ns * 1e-9;
  return m;
}

RigidTransform lidar_world_from_scan(const LidarFogParams& p) {
  validate_lidar_fog(p);
  if (!layered(p))
    throw Error("the scan's pose is used by a height-layered fog only (--profile other than constant)");
  RigidTransform t;
  if (p.pose.kitti_calib.empty()) {
    // The scan's x forward (north), y left (west), z up: a proper rotation.
    t.rotation.m[0][0] = 0, t.rotation.m[0][1] = -1, t.rotation.m[0][2] = 0;
    t.rotation.m[1][0] = 0, t.rotation.m[1][1] = 0, t.rotation.m[1][2] = 1;
    t.rotation.m[2][0] = -1, t.rotation.m[2][1] = 0, t.rotation.m[2][2] = 0;
    t.translation = {0.0, *p.pose.sensor_height_m, 0.0};
    return t;
  }
  // The one reader checks it (brume/depth.hpp): finite numbers, R0_rect and
  // Tr_velo_to_cam rotations, P2's focal lengths > 0.
  const KittiCalib c = read_kitti_calib(p.pose.kitti_calib);
  Mat3 r0, tr;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r0.m[i][j] = c.R0[3 * i + j], tr.m[i][j] = c.Tr[4 * i + j];
  const Mat3 a = r0 * tr;  // velodyne -> rectified camera, a rotation
  // Camera 2's centre in rectified camera-0 coordinates: P2 = K [I | t] (as depth's project_velodyne).
  const double* P = c.P2;
  const double fx = P[0], sk = P[1], cx = P[2], fy = P[5], cy = P[6], tz = P[11];
  const double ty = (P[7] - cy * tz) / fy;
  const double tx = (P[3] - sk * ty - cx * tz) / fx;
  const Vec3 b = r0 * Vec3{c.Tr[3], c.Tr[7], c.Tr[11]};
  const Vec3 in_cam2{b.x + tx, b.y + ty, b.z + tz};  // the scan's origin from camera 2's centre
  const Camera cam = make_camera(Intrinsics{1.0, 1.0, NAN, NAN}, 1, 1, p.fog.camera);
  cam.require_height("--profile " + enum_name(height_profile_names(), *p.profile) + " with --kitti-calib");
  const RigidTransform wc = cam.world_from_camera();
  t.rotation = wc.rotation * a;
  t.translation = wc.apply(in_cam2);
  return t;
}

SoftCurve lidar_soft_curve(const LidarFogParams& p, double range_end_m) {
  const LidarFogMedium m = lidar_fog_medium(p);
  if (layered(p)) return layered_soft_curve(p, m, range_end_m);
  const SoftModel s(p, m, range_end_m);
  SoftCurve c;
  c.step_m = s.step();
  const std::size_t n = std::min(s.nodes(), static_cast<std::size_t>(
                                                std::ceil(std::max(range_end_m, p.r2_m + m.pulse_m) / s.step())) + 1);
  c.power_w.assign(s.uncut().begin(), s.uncut().begin() + n);
  c.peak_w = s.peak_w();
  c.peak_range_m = s.peak_range();
  return c;
}

std::string soft_curve_csv(const SoftCurve& c) {
  std::string s = "range_m,power_w\n";
  char b[80];
  for (std::size_t j = 0; j < c.power_w.size(); ++j) {
    std::snprintf(b, sizeof b, "%.9g,%.9g\n", j * c.step_m, c.power_w[j]);
    s += b;
  }
  return s;
}

nlohmann::json LidarFogStats::record() const {
  nlohmann::json j = {{"points", points},
                      {"soft_points", soft},
                      {"soft_fraction", points ? static_cast<double>(soft) / points : 0.0},
                      {"points_within_r1", zero_range},
                      {"soft_peak_w", peak_w},
                      {"soft_peak_range_m", peak_range_m},
                      {"table_ms", table_ms},
                      {"points_ms", points_ms}};
  if (tables > 0 || std::isfinite(origin_height_m)) {
    j["tables"] = tables;
    j["table_nodes"] = table_nodes;
    j["bin_offset_max_sin"] = bin_offset_max;
    j["origin_height_m"] = origin_height_m;
    j["origin_density_per_m"] = origin_density_per_m;
  }
  return j;
}

LidarFogStats lidar_fog(const float* in, float* out, std::size_t n, const LidarFogParams& p, const std::string& what) {
  const LidarFogMedium m = lidar_fog_medium(p);
  // Every point checked before anything is written: the scan's validation
  // that every reader of a scan makes (brume/depth.hpp), then the model's scale.
  validate_scan(in, n, what);
  std::size_t above = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (static_cast<double>(in[4 * i + 3]) * p.intensity_scale > 255.0) ++above;
  if (n > 0 && 2 * above > n)
    throw Error("--intensity-scale " + text::g(p.intensity_scale) + ": " + text::g(100.0 * above / n) +
                " % of the intensities of " + what + " times it exceed 255, the model's scale [0, 255]; KITTI's reflectance is in [0, 1] "
                "(scale 255); for a scan already in [0, 255] give --intensity-scale 1");
  if (layered(p)) return layered_fog(in, out, n, p, m, what);
  LidarFogStats st;
  st.points = n;
  if (!(m.alpha > 0.0)) {  // no fog: the scan as it is, bit for bit
    if (out != in) std::memcpy(out, in, n * 4 * sizeof(float));
    return st;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const SoftModel s(p, m, 0.0);
  const auto t1 = std::chrono::steady_clock::now();
  st.peak_w = s.peak_w();
  st.peak_range_m = s.peak_range();
  const PointRule rule(p, m);
  // Each point on its own (the noise is counter-based), so the loop runs on
  // every core with the same result, in chunks of 4096 points handed out one
  // at a time (a thread that lost its core to another process holds up the
  // others by one chunk, not by half the scan), and on one thread below
  // kLidarParallelPoints (lidar_fog_tables.hpp has the measurement).
  std::size_t soft = 0, near = 0;
  long long overflow = static_cast<long long>(n);  // the first point whose fog intensity overflows float32
  const long long count = static_cast<long long>(n);
#pragma omp parallel for schedule(dynamic, 4096) reduction(+ : soft, near) reduction(min : overflow) \
    if (n >= kLidarParallelPoints)
  for (long long ii = 0; ii < count; ++ii) {
    const std::size_t i = static_cast<std::size_t>(ii);
    const float* q = in + 4 * i;
    float* o = out + 4 * i;
    const double x = q[0], y = q[1], z = q[2], inten = q[3];
    const double r0 = std::sqrt(x * x + y * y + z * z);
    const double att = std::exp(-2.0 * m.alpha * r0);
    if (r0 <= p.r1_m || !(inten > 0.0)) {
      near += r0 <= p.r1_m;
      o[0] = q[0], o[1] = q[1], o[2] = q[2], o[3] = static_cast<float>(inten * att);
      continue;
    }
    double peak_w, peak_r;
    s.peak(r0, peak_w, peak_r);
    bool over = false;
    if (rule.place(q, o, i, r0, att, peak_w, peak_r, over)) ++soft;
    if (over) overflow = std::min(overflow, ii);
  }
  if (overflow < count) throw_overflow(in, overflow, what);
  const auto t2 = std::chrono::steady_clock::now();
  st.soft = soft;
  st.zero_range = near;
  st.table_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  st.points_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  return st;
}

// ---- KITTI .bin (read by depth: src/depth/scan.cpp) ----
}  // namespace brume
