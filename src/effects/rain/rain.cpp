// brume — rain's physics, its drop field and rain on a LiDAR scan as a
// particle medium (brume/rain.hpp states the equations; docs/rain.md).
#include "brume/rain.hpp"

#include "effects/rain/falling.hpp"
#include "effects/rain/rain_internal.hpp"
#include "media/scan_points_check.hpp"
#include "media/scan_returns.hpp"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/math_constants.hpp"  // kPi: one definition (unity builds)
#include "core/text.hpp"

namespace brume {

namespace {
// A cell's index in a table: Teschner et al. 2003's spatial hash (three
// large primes, xor), cheap where the drop field's hash need not be.
std::size_t rain_cell_hash(const RainCell& c) {
  return static_cast<std::size_t>((static_cast<std::uint64_t>(c.ix) * 73856093u) ^
                                  (static_cast<std::uint64_t>(c.iy) * 19349663u) ^
                                  (static_cast<std::uint64_t>(c.iz) * 83492791u));
}
// The drop field's words, so that its draws are none of the speckle's.
constexpr std::uint64_t kRainFieldTag = 0x7261696e6669656cull;  // "rainfiel"
}  // namespace

double atlas_zero_speed_mm() { return std::log(10.3 / 9.65) / 0.6; }

double marshall_palmer_lambda_per_mm(double rate_mm_h) { return 4.1 * std::pow(rate_mm_h, -0.21); }

double marshall_palmer_density(double rate_mm_h, double d_mm) {
  if (rate_mm_h == 0.0) return 0.0;
  return kMarshallPalmerN0 * std::exp(-marshall_palmer_lambda_per_mm(rate_mm_h) * d_mm);
}

double atlas_terminal_velocity_m_per_s(double d_mm) { return 9.65 - 10.3 * std::exp(-0.6 * d_mm); }

double rain_extinction_per_m(double rate_mm_h, double q) {
  if (rate_mm_h == 0.0) return 0.0;
  const double l = marshall_palmer_lambda_per_mm(rate_mm_h);
  // ∫_0^∞ D²·e^{−ΛD} dD = 2/Λ³; mm² per m³ is 1e−6 per m.
  return q * (kPi / 4.0) * 2.0 * kMarshallPalmerN0 / (l * l * l) * 1e-6;
}

double rain_drops_per_m3(double rate_mm_h, double d_min_mm, double d_max_mm) {
  if (rate_mm_h == 0.0) return 0.0;
  const double l = marshall_palmer_lambda_per_mm(rate_mm_h);
  return kMarshallPalmerN0 / l * (std::exp(-l * d_min_mm) - std::exp(-l * d_max_mm));
}

// ---- the drop field ---------------------------------------------------------------------

RainField::RainField(double rate_mm_h, double d_min_mm, double d_max_mm, std::uint64_t seed, std::uint64_t frame)
    : RainField(rate_mm_h > 0.0 ? kMarshallPalmerN0 : 0.0,
                rate_mm_h > 0.0 ? marshall_palmer_lambda_per_mm(rate_mm_h) : 0.0, d_min_mm, d_max_mm, seed, frame,
                kRainFieldTag) {}

RainField::RainField(double n0, double lambda_per_mm, double d_min_mm, double d_max_mm, std::uint64_t seed,
                     std::uint64_t frame, std::uint64_t tag)
    : d_min_(d_min_mm), d_max_(d_max_mm), key_(hash_fold(hash_fold(seed, tag), frame)) {
  if (n0 > 0.0 && lambda_per_mm > 0.0) {
    lambda_ = lambda_per_mm;
    // rain_drops_per_m3's expression, for any n0 and λ.
    n_ = n0 / lambda_ * (std::exp(-lambda_ * d_min_) - std::exp(-lambda_ * d_max_));
    tail_ = std::exp(-lambda_ * d_max_);
    scale_ = kRainCellM * kRainCellM * kRainCellM * n0 / lambda_;
  }
}

void RainField::cell_drops(const RainCell& cell, double d_floor_mm, std::vector<RainDrop>& out) const {
  for_each_drop(cell, d_floor_mm, [&](const Vec3& at, double s) { out.push_back({at, diameter_mm(s)}); });
}

double RainField::measure_above(double d_mm) const {
  if (n_ <= 0.0) return 0.0;
  const double d = std::max(d_mm, d_min_);
  if (d >= d_max_) return 0.0;
  return d == d_min_ ? kRainCellM * kRainCellM * kRainCellM * n_ : scale_ * (std::exp(-lambda_ * d) - tail_);
}

double RainField::diameter_mm(double s) const {
  // M(D) = s: e^{−ΛD} = s/scale + e^{−Λ·D_max}; rounding only can leave [D_min, D_max].
  const double d = -std::log(s / scale_ + tail_) / lambda_;
  return std::min(std::max(d, d_min_), d_max_);
}

void RainField::cone_cells(const MediumRay& ray, double t0, double t1, double half_width, std::vector<RainCell>& out) {
  out.clear();
  if (!(t1 > t0)) return;
  const double c = kRainCellM;
  const double o[3] = {ray.origin.x, ray.origin.y, ray.origin.z};
  const double d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
  std::int64_t idx[3];
  double tmax[3], tdelta[3];
  int step[3];
  for (int a = 0; a < 3; ++a) {
    const double p = o[a] + t0 * d[a];
    idx[a] = static_cast<std::int64_t>(std::floor(p / c));
    step[a] = d[a] > 0.0 ? 1 : d[a] < 0.0 ? -1 : 0;
    const double inf = std::numeric_limits<double>::infinity();
    tmax[a] = step[a] > 0   ? (static_cast<double>(idx[a] + 1) * c - o[a]) / d[a]
              : step[a] < 0 ? (static_cast<double>(idx[a]) * c - o[a]) / d[a]
                            : inf;
    tdelta[a] = step[a] != 0 ? c / std::abs(d[a]) : inf;
  }
  // Each cell once, in the order the DDA meets it: an open-addressing set of
  // indices into `out` (a sort of the list cost 17 % of a scan's time).
  // Sized for the steps' boxes (about three cells a step) at a load below a half.
  thread_local std::vector<std::uint32_t> table;  // index + 1; 0: empty
  const double steps = (t1 - t0) * (std::abs(d[0]) + std::abs(d[1]) + std::abs(d[2])) / c + 3.0;
  std::size_t size = 64;
  while (static_cast<double>(size) < 8.0 * steps && size < (std::size_t(1) << 24)) size *= 2;
  table.assign(size, 0u);
  const auto slot_of = [&](const RainCell& c) {
    const std::size_t mask = table.size() - 1;
    std::size_t i = rain_cell_hash(c) & mask;
    while (table[i] != 0 && !(out[table[i] - 1] == c)) i = (i + 1) & mask;
    return i;
  };
  const auto insert = [&](const RainCell& c) {
    const std::size_t i = slot_of(c);
    if (table[i] != 0) return;
    out.push_back(c);
    table[i] = static_cast<std::uint32_t>(out.size());
    if (2 * out.size() > table.size()) {  // keep the load below a half
      std::fill(table.begin(), table.end(), 0u);
      table.resize(table.size() * 2, 0u);
      for (std::size_t k = 0; k < out.size(); ++k) table[slot_of(out[k])] = static_cast<std::uint32_t>(k + 1);
    }
  };
  double ta = t0;
  for (;;) {
    const double tb = std::min({tmax[0], tmax[1], tmax[2], t1});
    // The segment [ta, tb] within this cell, widened by the cone's radius at tb.
    const double w = tb * half_width;
    std::int64_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const double pa = o[a] + std::max(ta, t0) * d[a], pb = o[a] + tb * d[a];
      lo[a] = static_cast<std::int64_t>(std::floor((std::min(pa, pb) - w) / c));
      hi[a] = static_cast<std::int64_t>(std::floor((std::max(pa, pb) + w) / c));
    }
    for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z) insert({x, y, z});
    if (tb >= t1) break;
    const int a = tmax[0] <= tmax[1] ? (tmax[0] <= tmax[2] ? 0 : 2) : (tmax[1] <= tmax[2] ? 1 : 2);
    idx[a] += step[a];
    ta = tmax[a];
    tmax[a] += tdelta[a];
  }
}

// ---- the parameters ----------------------------------------------------------------------

const ParamTable<RainDrops>& rain_drops_param_table() {
  static const ParamTable<RainDrops> t = [] {
    ParamTable<RainDrops> d("rain");
    d.real("rate", &RainDrops::rate_mm_h, "mm/h", Range::closed(0.0, 500.0),
           "rain rate R (Marshall-Palmer drop sizes: N0 = 8000 m^-3 mm^-1, Lambda = 4.1 R^-0.21 mm^-1; one drop "
           "field for the camera and the LiDAR); 0: no rain, the input back as the other media leave it",
           "none")
        .real("drop-min", &RainDrops::drop_min_mm, "mm", Range::at_least(atlas_zero_speed_mm()),
              "smallest drawn drop D_min; Atlas's fall speed is negative below 0.1087 mm")
        .real("drop-max", &RainDrops::drop_max_mm, "mm", Range::left_open(0.0, 10.0),
              "largest drawn drop D_max (larger drops break up); must exceed --drop-min");
    return d;
  }();
  return t;
}

void validate_rain_drops(const RainDrops& d) {
  rain_drops_param_table().validate(d);
  if (!d.rate_mm_h) throw Error("no rain rate given: use --rate R (mm/h, in [0, 500])");
  if (!(d.drop_max_mm > d.drop_min_mm))
    throw Error("--drop-max " + text::g(d.drop_max_mm) + " must exceed --drop-min " + text::g(d.drop_min_mm) +
                " (the drawn drops' diameters lie between them); give a larger --drop-max");
}

const ParamTable<LidarRainParams>& lidar_rain_param_table() {
  static const ParamTable<LidarRainParams> t = [] {
    ParamTable<LidarRainParams> d("rain");
    d.nest(&LidarRainParams::drops, rain_drops_param_table())
        .real("divergence", &LidarRainParams::divergence_mrad, "mrad", Range::left_open(0.0, 50.0),
              "full divergence theta of the LiDAR's beam: a drop meets a beam when its centre lies in the cone")
        .real("drop-reflectance", &LidarRainParams::drop_reflectance, "1", Range::closed(0.0, 1.0),
              "a drop's backscatter rho_d as a Lambertian reflectance of its cross-section, on the scan's intensity "
              "scale (default 2 pi/S, S = 18 sr: liquid water drops' lidar ratio; docs/rain.md)")
        .real("noise-floor", &LidarRainParams::noise_floor, "1/m^2", Range::above(0.0),
              "noise floor F: the weakest mean return power (intensity/range^2) the sensor detects; default below "
              "KITTI 000001's weakest non-zero return (7.7e-6)")
        .real("blind-range", &LidarRainParams::blind_range_m, "m", Range::at_least(0.0),
              "r_min: the sensor reports no return nearer (no drop echo there)")
        .count("seed", &LidarRainParams::seed, "1", Range::at_least(0.0),
               "seed of the drop field and of the detection draws (same seed, same scan)");
    declare_return_mode(d, &LidarRainParams::return_mode, "a beam", "drop");
    d.count("frame", &LidarRainParams::frame, "1", Range::at_least(0.0),
               "frame K of a sequence: the drop field at t = K * --frame-interval, each drop moved in closed form "
               "by its fall speed v(D), --wind and the sensor's motion (--ego-speed or --poses); 0: the field as "
               "hashed")
        .since(4, 0)
        .real("frame-interval", &LidarRainParams::frame_interval_s, "s", Range::left_open(0.0, 3600.0),
              "time between frames (KITTI's Velodyne: 0.1 s, 10 Hz)")
        .since(4, 0.1)
        .text("wind", &LidarRainParams::wind,
              "wind X,Y,Z in m/s in the drop field's frame (x forward, y left, z up), moving the drops between "
              "frames")
        .since(4, "0,0,0")
        .real("ego-speed", &LidarRainParams::ego_speed_m_s, "m/s", Range::closed(-100.0, 100.0),
              "the sensor's speed along its forward (x) axis: at frame K it has moved s * K * --frame-interval "
              "(not with --poses)")
        .since(4, 0.0)
        .text("poses", &LidarRainParams::poses,
              "KITTI odometry poses: one line of 12 numbers per frame, camera 0's 3x4 [R|t] into the world (no "
              "header); the sensor at --frame K is placed by line K relative to line 0 (needs --kitti-calib: its "
              "Tr_velo_to_cam and R0_rect)")
        .reads_file()
        .since(4, "")
        .text("kitti-calib", &LidarRainParams::kitti_calib,
              "KITTI calibration (Tr_velo_to_cam, R0_rect, P2): the drop field in camera 2's frame, the one brume "
              "rain draws its streaks in, so that the scan's drops are the camera's; none: the scan's own frame")
        .reads_file()
        .since(4, "");
    return d;
  }();
  return t;
}

void validate_lidar_rain(const LidarRainParams& p) {
  lidar_rain_param_table().validate(p);
  validate_rain_drops(p.drops);
  (void)parse_wind_m_s(p.wind);
  check_sequence_flags(p.frame, p.frame_interval_s, p.ego_speed_m_s, p.poses, p.kitti_calib,
                       "the scan's pose needs --kitti-calib FILE (its Tr_velo_to_cam and R0_rect place the Velodyne "
                       "relative to camera 0)");
}

Vec3 rain_drop_at(const Vec3& c, double d_mm, double t_s, const Vec3& wind) {
  if (t_s == 0.0) return c;
  return falling_at(c, atlas_terminal_velocity_m_per_s(d_mm), t_s, wind);
}

Vec3 falling_at(const Vec3& c, double fall_m_s, double t_s, const Vec3& wind) {
  if (t_s == 0.0) return c;
  const double base = std::floor((c.z - kRainLayerBaseM) / kRainLayerM) * kRainLayerM + kRainLayerBaseM;
  double dz = std::fmod(c.z - base + (wind.z - fall_m_s) * t_s, kRainLayerM);
  if (dz < 0.0) dz += kRainLayerM;
  if (dz >= kRainLayerM) dz = 0.0;  // rounding of a tiny negative remainder
  return {c.x + wind.x * t_s, c.y + wind.y * t_s, base + dz};
}

void falling_source_spans(double z_lo, double z_hi, double f_lo, double f_hi, double t_s,
                          std::vector<std::pair<std::int64_t, std::int64_t>>& spans) {
  const double c = kRainCellM, H = kRainLayerM, base0 = kRainLayerBaseM;
  const std::int64_t cells_per_layer = static_cast<std::int64_t>(H / c);
  const std::int64_t j0 = static_cast<std::int64_t>(std::floor((z_lo - base0) / H)),
                     j1 = static_cast<std::int64_t>(std::floor((z_hi - base0) / H));
  for (std::int64_t j = j0; j <= j1; ++j) {
    const double lb = base0 + static_cast<double>(j) * H;
    const std::int64_t cb = static_cast<std::int64_t>(std::llround(lb / c));  // the layer's first cell
    const double a = std::max(z_lo, lb), e = std::min(z_hi, lb + H);
    const double s0 = a + f_lo * t_s - c, s1 = e + f_hi * t_s + c;  // source heights, unwrapped
    if (s1 - s0 >= H) {
      spans.push_back({cb, cb + cells_per_layer - 1});
      continue;
    }
    double m0 = std::fmod(s0 - lb, H);
    if (m0 < 0.0) m0 += H;
    const double m1 = m0 + (s1 - s0);
    const std::int64_t i0 = static_cast<std::int64_t>(std::floor(m0 / c));
    const std::int64_t i1 = static_cast<std::int64_t>(std::floor(m1 / c));
    if (i1 < cells_per_layer) {
      spans.push_back({cb + i0, cb + i1});
    } else {
      spans.push_back({cb + i0, cb + cells_per_layer - 1});
      spans.push_back({cb, cb + std::min(i0 - 1, i1 - cells_per_layer)});
    }
  }
}

bool falling_min_speed(std::int64_t iz, double z_lo, double z_hi, double f_lo, double f_hi, double t_s, double& f) {
  // A particle of this cell lands in [z_lo, z_hi] (within its layer) only when f·t ≡ z_s − z (mod H):
  // the smallest such f >= f_lo.
  const double c = kRainCellM, H = kRainLayerM, base0 = kRainLayerBaseM;
  const double lz = static_cast<double>(iz) * c;
  const double lb = base0 + std::floor((lz - base0) / H) * H;
  const double top = std::min(z_hi, lb + H), bottom = std::max(z_lo, lb);
  if (top < bottom) return false;
  const double a = lz - top - 1e-6, b = lz + c - bottom + 1e-6;
  const double ft_lo = f_lo * t_s - 1e-9 * (1.0 + std::abs(f_lo * t_s));
  const double ft = std::max(ft_lo, a + std::ceil((ft_lo - b) / H) * H);
  f = ft / t_s;
  return !(f > f_hi + 1e-9);  // no particle falls that fast
}

double atlas_diameter_below_mm(double v) {
  return v > 0.0 && v < 9.65 ? -std::log((9.65 - v) / 10.3) / 0.6 * (1.0 - 1e-9) : 0.0;
}

// ---- the scan's pose in the drop field ------------------------------------------------------

namespace {

RigidTransform compose(const RigidTransform& a, const RigidTransform& b) {  // a after b
  const Vec3 t = a.rotation * b.translation;
  return {a.rotation * b.rotation, {t.x + a.translation.x, t.y + a.translation.y, t.z + a.translation.z}};
}
RigidTransform inverse(const RigidTransform& a) {
  const Mat3 rt = a.rotation.transposed();
  const Vec3 t = rt * a.translation;
  return {rt, {-t.x, -t.y, -t.z}};
}
RigidTransform rigid_3x4(const double* m) {  // row-major 3x4 [R|t]
  RigidTransform r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.rotation.m[i][j] = m[4 * i + j];
  r.translation = {m[3], m[7], m[11]};
  return r;
}

// Line `k` (from 0) of a KITTI poses file as a rigid transform; errors name --poses.
RigidTransform read_kitti_pose(const std::string& path, std::uint64_t k) {
  static const InputLimit kPosesLimit{1u << 28, "a poses file is a line of 12 numbers per frame"};
  std::istringstream in(read_input_file(path, "--poses", kPosesLimit));
  std::string line;
  std::uint64_t n = 0;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (n++ != k) continue;
    std::istringstream ls(line);
    double m[12];
    int got = 0;
    std::string tok;
    while (ls >> tok) {
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (got >= 12 || end != tok.c_str() + tok.size() || !std::isfinite(v))
        throw Error("--poses '" + path + "': line " + std::to_string(n) + " is not 12 finite numbers (a 3x4 [R|t] " +
                    "row by row, KITTI odometry's format without a header)");
      m[got++] = v;
    }
    if (got != 12)
      throw Error("--poses '" + path + "': line " + std::to_string(n) + " has " + std::to_string(got) +
                  " numbers; each line is 12 (a 3x4 [R|t] row by row)");
    const RigidTransform r = rigid_3x4(m);
    const Mat3 q = r.rotation * r.rotation.transposed();
    double err = 0.0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) err = std::max(err, std::abs(q.m[i][j] - (i == j ? 1.0 : 0.0)));
    const Mat3& a = r.rotation;
    const double det = a.m[0][0] * (a.m[1][1] * a.m[2][2] - a.m[1][2] * a.m[2][1]) -
                       a.m[0][1] * (a.m[1][0] * a.m[2][2] - a.m[1][2] * a.m[2][0]) +
                       a.m[0][2] * (a.m[1][0] * a.m[2][1] - a.m[1][1] * a.m[2][0]);
    if (err > 1e-3 || det < 0.0)
      throw Error("--poses '" + path + "': line " + std::to_string(n) +
                  "'s 3x3 part is not a rotation (orthonormal within 1e-3, determinant +1)");
    return r;
  }
  throw Error("--poses '" + path + "' has " + std::to_string(n) + " poses; --frame " + std::to_string(k) +
              " needs line " + std::to_string(k + 1) + " (frames count from 0)");
}

// Camera 2's centre from camera 0's (rectified): P2 = K·[I | b], b = K⁻¹·P2[:, 3].
RigidTransform cam2_from_cam0(const KittiCalib& c) {
  const double* P = c.P2;
  const double bz = P[11], by = (P[7] - P[6] * bz) / P[5], bx = (P[3] - P[1] * by - P[2] * bz) / P[0];
  RigidTransform r;
  r.translation = {bx, by, bz};
  return r;
}
// The field's axes from the cv frame: x = z_cv, y = −x_cv, z = −y_cv (brume rain's camera).
RigidTransform field_from_cv() {
  RigidTransform f;
  f.rotation.m[0][0] = 0, f.rotation.m[0][2] = 1;
  f.rotation.m[1][0] = -1, f.rotation.m[1][1] = 0;
  f.rotation.m[2][1] = -1, f.rotation.m[2][2] = 0;
  return f;
}
bool is_identity(const RigidTransform& w) {
  bool identity = w.translation.x == 0.0 && w.translation.y == 0.0 && w.translation.z == 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) identity = identity && w.rotation.m[i][j] == (i == j ? 1.0 : 0.0);
  return identity;
}

// How many pose lines a KITTI poses file holds (not checked: read_kitti_pose checks the lines it reads).
std::uint64_t kitti_pose_count(const std::string& path) {
  static const InputLimit kPosesLimit{1u << 28, "a poses file is a line of 12 numbers per frame"};
  std::istringstream in(read_input_file(path, "--poses", kPosesLimit));
  std::string line;
  std::uint64_t n = 0;
  while (std::getline(in, line))
    if (line.find_first_not_of(" \t\r") != std::string::npos) ++n;
  return n;
}

}  // namespace

void check_sequence_flags(std::uint64_t frame, double frame_interval_s, double ego_speed_m_s, const std::string& poses,
                          const std::string& kitti_calib, const std::string& calib_why) {
  if (!poses.empty() && kitti_calib.empty())
    throw Error("--poses '" + poses + "' holds camera 0's poses; " + calib_why);
  if (!poses.empty() && ego_speed_m_s != 0.0)
    throw Error("--ego-speed " + text::g(ego_speed_m_s) + " with --poses '" + poses +
                "': the poses already move the sensor; give one of them");
  const double t = static_cast<double>(frame) * frame_interval_s;
  if (!(t <= 1e6))
    throw Error("--frame " + std::to_string(frame) + " at --frame-interval " + text::g(frame_interval_s) +
                " s is " + text::g(t) + " s into the sequence; at most 1e6 s (11 days) is supported");
}

void check_streak_frames(std::uint64_t frame, double frame_interval_s, double ego_speed_m_s, const std::string& poses,
                         const std::string& kitti_calib, const std::string& calib_how) {
  check_sequence_flags(frame, frame_interval_s, ego_speed_m_s, poses, kitti_calib,
                       "the camera's pose needs a KITTI calibration to place camera 2 (the image's) relative to "
                       "camera 0: " + calib_how);
}

StreakPose streak_camera_pose(std::uint64_t frame, double frame_interval_s, double ego_speed_m_s,
                              const std::string& poses, const std::string& kitti_calib) {
  StreakPose pose;
  pose.t_s = static_cast<double>(frame) * frame_interval_s;
  if (poses.empty()) {
    pose.world_from_camera.translation.x = ego_speed_m_s * pose.t_s;
    pose.velocity = {ego_speed_m_s, 0.0, 0.0};
    pose.moved = pose.t_s != 0.0;
    return pose;
  }
  // Camera 2 at frame k in the field's world (camera 2 at frame 0, the field's axes): F·C2·P0⁻¹·Pk·C2⁻¹·F⁻¹.
  pose.from_poses = true;
  const RigidTransform c2 = cam2_from_cam0(read_kitti_calib(kitti_calib)), f = field_from_cv();
  const RigidTransform to_cam0 = compose(c2, inverse(read_kitti_pose(poses, 0)));
  const auto at = [&](std::uint64_t k) {
    if (k == 0) return RigidTransform{};
    const RigidTransform rel = compose(to_cam0, compose(read_kitti_pose(poses, k), inverse(c2)));
    return compose(f, compose(rel, inverse(f)));
  };
  const std::uint64_t n = kitti_pose_count(poses);
  if (n < 2)
    throw Error("--poses '" + poses + "' has " + std::to_string(n) +
                " pose; the camera's motion over the exposure needs two (frames K and K + 1, or K - 1 and K)");
  if (frame >= n) (void)read_kitti_pose(poses, frame);  // its error: the line missing
  pose.world_from_camera = at(frame);
  const bool last = frame + 1 >= n;
  const RigidTransform a = last ? at(frame - 1) : pose.world_from_camera, b = last ? pose.world_from_camera : at(frame + 1);
  const Vec3& pa = a.translation;
  const Vec3& pb = b.translation;
  pose.velocity = {(pb.x - pa.x) / frame_interval_s, (pb.y - pa.y) / frame_interval_s, (pb.z - pa.z) / frame_interval_s};
  pose.moved = !is_identity(pose.world_from_camera) || pose.t_s != 0.0;
  pose.rotated = !is_identity(RigidTransform{pose.world_from_camera.rotation, {}});
  return pose;
}

LidarRainPose lidar_rain_pose(const LidarRainParams& p) {
  LidarRainPose pose;
  pose.t_s = static_cast<double>(p.frame) * p.frame_interval_s;
  pose.wind = parse_wind_m_s(p.wind);
  RigidTransform field_from_velo;  // identity without a calibration
  RigidTransform cam0_from_velo;
  if (!p.kitti_calib.empty()) {
    const KittiCalib c = read_kitti_calib(p.kitti_calib);
    RigidTransform r0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) r0.rotation.m[i][j] = c.R0[3 * i + j];
    cam0_from_velo = compose(r0, rigid_3x4(c.Tr));  // camera 0, rectified
    field_from_velo = compose(field_from_cv(), compose(cam2_from_cam0(c), cam0_from_velo));
    pose.frame = "camera 2's (KITTI calibration: x forward, y left, z up, origin at its centre)";
  } else {
    pose.frame = "the scan's own";
  }
  if (!p.poses.empty() && p.frame != 0) {
    // The Velodyne at frame K in the field's frame at frame 0: V·C⁻¹·P0⁻¹·PK·C.
    const RigidTransform p0 = read_kitti_pose(p.poses, 0), pk = read_kitti_pose(p.poses, p.frame);
    const RigidTransform rel = compose(inverse(p0), pk);  // camera 0 at K into camera 0 at 0
    pose.world_from_sensor =
        compose(field_from_velo, compose(inverse(cam0_from_velo), compose(rel, cam0_from_velo)));
  } else {
    if (!p.poses.empty()) (void)read_kitti_pose(p.poses, 0);  // checked even at frame 0
    pose.world_from_sensor = field_from_velo;
    pose.world_from_sensor.translation.x += p.ego_speed_m_s * pose.t_s;
  }
  pose.general = !is_identity(pose.world_from_sensor) || pose.t_s != 0.0;
  return pose;
}

// ---- rain on a LiDAR scan ------------------------------------------------------------------

namespace {

// The cell-major pass's beams and scratch (LidarRain::scan_echoes_by_cell).
struct CellPassBeam {  // what a drop's test reads
  Vec3 dir;
  double r, t1;
};
struct CellPassEntry {  // a beam in a bin: its test's inputs inline (one read per bin)
  CellPassBeam beam;
  std::uint32_t k;  // its index in the pass's beams
};
struct CellPassBest {
  double key = -1.0;  // what the return mode compares: the power (strongest) or the range (last)
  double power = -1.0, t = 0.0, reported = 0.0;
  bool redo = false;
};
struct CellPassSpan {
  int d0, d1, e0, e1;  // bins [d0, d1] (mod nD) × [e0, e1]
};
struct CellPassGroup {
  double lo[3] = {2, 2, 2}, hi[3] = {-2, -2, -2}, T = -1.0;
};
struct CellPassScratch {
  std::vector<CellPassBeam> all, beams;
  std::vector<CellPassEntry> in_bin;
  std::vector<std::size_t> point_of, point;
  std::vector<std::uint32_t> key, at, start, fill, order;
  std::vector<std::uint64_t> held;
  std::vector<CellPassBest> best;
  std::vector<CellPassSpan> spans;
  std::vector<float> brick_T;
  std::vector<std::int64_t> bricks;
  std::vector<CellPassGroup> groups;
  std::vector<double> u_max;
};

class LidarRain final : public Medium {
 public:
  explicit LidarRain(const LidarRainParams& p, LidarRainSearch search = LidarRainSearch::chosen)
      : p_(p),
        search_(search),
        sigma_(rain_extinction_per_m(*p.drops.rate_mm_h, kLidarRainQ)),
        field_(*p.drops.rate_mm_h, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed),
        theta_(p.divergence_mrad * 1e-3),
        cos_half_(1.0 / std::sqrt(1.0 + theta_ / 2.0 * (theta_ / 2.0))),
        last_(p.return_mode == "last"),
        pose_(lidar_rain_pose(p)) {
    // D_t(r) = θ·r²·√(F/ρ_d) [m]: the smallest drop whose echo can reach F at r.
    if (field_.drops_per_m3() > 0.0 && p.drop_reflectance > 0.0) {
      k_ = theta_ * std::sqrt(p.noise_floor / p.drop_reflectance);
      reach_ = std::sqrt(p.drops.drop_max_mm * 1e-3 / k_);
    }
  }

  double extinction_per_m() const override { return sigma_; }

  void particles(const MediumRay& ray, double range_m, double, std::vector<Particle>& out) const override {
    if (pose_.general) {  // the beam's best drop in the field's world (a beam from the scan's origin)
      const float q[4] = {static_cast<float>(ray.dir.x * range_m), static_cast<float>(ray.dir.y * range_m),
                          static_cast<float>(ray.dir.z * range_m), 0.0f};
      std::vector<ScanEcho> e;
      scan_echoes_general(q, 1, e);
      for (const ScanEcho& x : e) out.push_back({x.range_m, x.intensity, 0.0, {}});
      return;
    }
    visit(ray, range_m, [&](double t, double power, double) { out.push_back({t, power * range_m * range_m, 0.0, {}}); });
  }

  // The strongest drop echo above the floor per beam (the others never win):
  // for a scan of kLidarRainByCellBeams beams or more, the scan's drops drawn
  // once, cell by cell, each tested against the beams whose cones can hold it
  // (scan_echoes_by_cell; a beam whose answer it cannot vouch for bit for bit
  // is redone by visit() alone); for fewer, beam by beam (the same echoes).
  void scan_echoes(const float* points, std::size_t n, std::vector<ScanEcho>& out) const override {
    if (reach_ <= 0.0) return;
    if (pose_.general || search_ == LidarRainSearch::general) return scan_echoes_general(points, n, out);
    const bool by_cell = search_ == LidarRainSearch::by_cell ||
                         (search_ == LidarRainSearch::chosen && n >= kLidarRainByCellBeams);
    if (by_cell) scan_echoes_by_cell(points, n, out);
    else scan_echoes_by_beam(points, n, out);
  }

  // The same answer beam by beam (visit() over each beam's cone cells): the
  // reference the cell-major pass must repeat bit for bit.
  void scan_echoes_by_beam(const float* points, std::size_t n, std::vector<ScanEcho>& out) const {
    if (reach_ <= 0.0) return;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = points[4 * i], y = points[4 * i + 1], z = points[4 * i + 2];
      const double r = std::sqrt(x * x + y * y + z * z);
      if (!(r > p_.blind_range_m)) continue;
      double best = -1.0, best_t = 0.0, best_rep = 0.0;
      beam_best(x, y, z, r, best, best_t, best_rep);
      if (best >= 0.0) out.push_back({i, best_t, best * r * r, best_rep});
    }
  }

  nlohmann::json scan_record(const ScanRun& run) const override {
    return lidar_rain_record(p_, {run, drawn_, pose_.frame});
  }

  std::size_t drawn() const { return drawn_; }
  const std::string& field_frame() const { return pose_.frame; }
  LidarRain(const LidarRain&) = delete;

 private:
  // The cell's nearest range from o along any direction in a cone: its distance × cos(θ/2), at least r_min.
  double near_range(const RainCell& cell, const double o[3]) const {
    const double c = kRainCellM;
    const std::int64_t ci[3] = {cell.ix, cell.iy, cell.iz};
    double dist2 = 0.0;
    for (int a = 0; a < 3; ++a) {
      const double lo = static_cast<double>(ci[a]) * c, hi = lo + c;
      const double g = std::max({lo - o[a], 0.0, o[a] - hi});
      dist2 += g * g;
    }
    return std::max(p_.blind_range_m, std::sqrt(dist2) * cos_half_);
  }

  // A drop's echo on the beam from o along dir to range_m: false outside the
  // cone over [r_min, range_m) or below the floor; else its range t, power P_d
  // and apparent reflectance ρ_d·e^{−2σt}·a.
  bool echo(const Vec3& at, double s, const double o[3], const Vec3& dir, double range_m, double& t, double& power,
            double& reported) const {
    const double hw = theta_ / 2.0;
    const double px = at.x - o[0], py = at.y - o[1], pz = at.z - o[2];
    t = px * dir.x + py * dir.y + pz * dir.z;
    if (!(t >= p_.blind_range_m && t < range_m)) return false;
    const double perp2 = std::max(0.0, px * px + py * py + pz * pz - t * t);
    if (perp2 > t * hw * t * hw) return false;
    const double frac = std::min(1.0, std::pow(field_.diameter_mm(s) * 1e-3 / (theta_ * t), 2));
    reported = p_.drop_reflectance * std::exp(-2.0 * sigma_ * t) * frac;
    power = reported / (t * t);
    return power >= p_.noise_floor;
  }

  // The strongest of visit()'s echoes on the beam to (x, y, z) at range r (ties: the first met).
  void beam_best(double x, double y, double z, double r, double& best, double& best_t, double& best_rep) const {
    const MediumRay b{{0.0, 0.0, 0.0}, {x / r, y / r, z / r}};
    visit(b, r, [&](double t, double power, double reported) {
      if (last_ ? best < 0.0 || t > best_t : power > best) best = power, best_t = t, best_rep = reported;
    });
  }

  void scan_echoes_by_cell(const float* points, std::size_t n, std::vector<ScanEcho>& out) const;
  // u_max[j] (kMeasureBounds + 1 of them, j = dist2·inv_dq for squared distances up to r_far²):
  // an upper bound of the first uniform draw of a cell at least √dist2 away that holds a drop the
  // thinning keeps (its measure M(k·r_near²), r_near >= √dist2·cos(θ/2), with a margin); returns inv_dq.
  static constexpr int kMeasureBounds = 4096;
  double measure_bounds(double r_far, std::vector<double>& u_max) const {
    const double inv_dq = kMeasureBounds / (r_far * r_far);
    u_max.resize(kMeasureBounds + 1);
    for (int j = 0; j <= kMeasureBounds; ++j) {
      const double r_lo = std::max(p_.blind_range_m, std::sqrt(j / inv_dq) * cos_half_ * (1.0 - 1e-12));
      const double m_up = field_.measure_above(k_ * r_lo * r_lo * 1e3 * (1.0 - 1e-12));
      u_max[j] = m_up > 0.0 ? -std::expm1(-m_up * (1.0 + 1e-6)) + 1e-12 : 0.0;
    }
    return inv_dq;
  }
  void scan_echoes_general(const float* points, std::size_t n, std::vector<ScanEcho>& out) const;

  // Calls f(t, P_d, ρ_d·e^{−2σt}·a) for every drop in the beam's cone over
  // [r_min, range) whose echo power P_d reaches the floor.
  template <class F>
  void visit(const MediumRay& ray, double range_m, F&& f) const {
    if (reach_ <= 0.0) return;
    const double t1 = std::min(range_m, reach_), hw = theta_ / 2.0;
    RainField::cone_cells(ray, p_.blind_range_m, t1, hw, cells_);
    const double o[3] = {ray.origin.x, ray.origin.y, ray.origin.z};
    for (const RainCell& cell : cells_) {
      const double r_near = near_range(cell, o);
      if (r_near >= t1) continue;
      const double dfl = k_ * r_near * r_near * 1e3;
      if (cache_.empty()) cache_.resize(kSlots);  // only visit() uses it
      Slot& slot = cache_[slot_of(cell)];
      const bool same = slot.cell == cell && slot.dfl == dfl;  // a scan's beams: the same cell, the same floor
      const double m = same ? slot.m : field_.measure_above(dfl);
      if (!(m > 0.0)) continue;
      const auto test = [&](const Vec3& at, double s) {
        double t, power, reported;
        if (echo(at, s, o, ray.dir, range_m, t, power, reported)) f(t, power, reported);
      };
      // Neighbouring beams cross the same cells: a cell's drops are kept in
      // a direct-mapped cache, drawn to some measure m_s; a request of m <= m_s
      // takes the prefix s <= m of them (the same drops, largest first).
      if (slot.cell == cell && slot.m >= m && slot.n <= kSlotDrops) {
        for (std::uint32_t j = 0; j < slot.n && slot.s[j] <= m; ++j) test(slot.at[j], slot.s[j]);
        continue;
      }
      slot.cell = cell, slot.dfl = dfl, slot.m = m, slot.n = 0;
      field_.for_each_drop_within(cell, m, [&](const Vec3& at, double s) {
        ++drawn_;
        if (slot.n < kSlotDrops) slot.at[slot.n] = at, slot.s[slot.n] = s;
        ++slot.n;  // beyond kSlotDrops: not kept (drawn again next time)
        test(at, s);
      });
    }
  }

  // A cache slot: a cell's drops as drawn to the measure m (n > kSlotDrops: not kept).
  // A cell whose measure is 0 is never stored (its slot keeps another's).
  static constexpr std::uint32_t kSlotDrops = 16;
  static constexpr std::size_t kSlots = std::size_t(1) << 14;
  struct Slot {
    RainCell cell{INT64_MIN, INT64_MIN, INT64_MIN};
    double dfl = -1.0, m = -1.0;  // the diameter [mm] and measure it was drawn to
    std::uint32_t n = 0;
    std::array<Vec3, kSlotDrops> at;
    std::array<double, kSlotDrops> s;
  };
  static std::size_t slot_of(const RainCell& c) { return rain_cell_hash(c) & (kSlots - 1); }

  LidarRainParams p_;
  LidarRainSearch search_;
  double sigma_;
  RainField field_;
  double theta_, cos_half_, k_ = 0.0, reach_ = 0.0;
  bool last_;
  LidarRainPose pose_;
  mutable std::vector<RainCell> cells_;
  mutable std::vector<Slot> cache_;
  mutable std::size_t drawn_ = 0;
};

// A direction's azimuth as a "diamond angle" in [0, 4): monotone in the
// azimuth φ, |dD/dφ| <= 1, without a trigonometric call (0 on the z axis).
double diamond_angle(double x, double y) {
  if (x == 0.0 && y == 0.0) return 0.0;
  if (y >= 0.0) return x >= 0.0 ? y / (x + y) : 1.0 - x / (y - x);
  return x < 0.0 ? 2.0 - y / (-x - y) : 3.0 + x / (x - y);
}

// The scan's beams from the sensor into S.all (their directions, through `rotation` when given,
// unit length) and S.point_of; e_lo, e_hi their directions' z range. Beams within the blind zone
// or reaching no cell before r_reach are left out.
void gather_beams(CellPassScratch& S, const float* points, std::size_t n, double r_min, double reach,
                  const Mat3* rotation, double& e_lo, double& e_hi) {
  S.all.clear(), S.point_of.clear();
  e_lo = 2.0, e_hi = -2.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = points[4 * i], y = points[4 * i + 1], z = points[4 * i + 2];
    const double r = std::sqrt(x * x + y * y + z * z);
    if (!(r > r_min)) continue;
    Vec3 u{x / r, y / r, z / r};
    if (rotation) {  // unit length again (a calibration's rotation is orthonormal to its digits only)
      const Vec3 d = *rotation * Vec3{x, y, z};
      const double dn = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
      u = {d.x / dn, d.y / dn, d.z / dn};
    }
    const CellPassBeam b{u, r, std::min(r, reach)};
    if (!(b.t1 > r_min)) continue;  // visit() meets no cell
    e_lo = std::min(e_lo, b.dir.z), e_hi = std::max(e_hi, b.dir.z);
    S.all.push_back(b), S.point_of.push_back(i);
  }
}

// The pass's beams in their points' order.
const std::vector<std::uint32_t>& beams_in_point_order(CellPassScratch& S) {
  S.order.resize(S.beams.size());
  for (std::size_t k = 0; k < S.beams.size(); ++k) S.order[k] = static_cast<std::uint32_t>(k);
  std::sort(S.order.begin(), S.order.end(), [&](std::uint32_t a, std::uint32_t b) { return S.point[a] < S.point[b]; });
  return S.order;
}

// The beams binned by direction (diamond angle, sin elevation; bins of w in both, at least 2ψ, at
// most 4 M bins), each in every bin its cone (half-angle ψ, rounded up) can reach: S.beams and
// S.point (from S.all and S.point_of) in their bins' order, S.start and S.in_bin the bins' beams,
// S.held which bins hold one.
struct BeamBins {
  double e_lo = 0.0, inv_w = 0.0, inv_wD = 0.0;
  int nD = 1, nE = 1;
  int e_bin(double e) const { return std::min(nE - 1, std::max(0, static_cast<int>(std::floor((e - e_lo) * inv_w)))); }
  int d_bin(const Vec3& d) const { return std::min(nD - 1, static_cast<int>(diamond_angle(d.x, d.y) * inv_wD)); }
  // The bin of a drop at p (from the beams' origin; q2 = |p|²) when it holds a beam, else -1.
  std::ptrdiff_t bin(double x, double y, double z, double q2, double e_hi,
                     const std::vector<std::uint64_t>& held) const {
    const double e = z / std::sqrt(q2);
    if (!(e >= e_lo && e <= e_hi)) return -1;
    const int je = std::min(nE - 1, static_cast<int>((e - e_lo) * inv_w));
    int jd = static_cast<int>(diamond_angle(x, y) * inv_wD);
    if (jd >= nD) jd -= nD;
    const std::size_t b = static_cast<std::size_t>(je) * nD + jd;
    return held[b / 64] >> (b % 64) & 1u ? static_cast<std::ptrdiff_t>(b) : -1;
  }
};
BeamBins bin_beams(CellPassScratch& S, double psi, double& e_lo, double& e_hi) {
  BeamBins bb;
  const double sin_psi = std::sin(psi);
  e_lo = std::max(-1.0, e_lo - psi - 1e-9), e_hi = std::min(1.0, e_hi + psi + 1e-9);
  double w = std::max(2.0 * psi, 5e-4);
  while ((4.0 / w) * ((e_hi - e_lo) / w + 1.0) > 4e6) w *= 2.0;
  const int nD = std::max(1, static_cast<int>(std::ceil(4.0 / w)));
  const double wD = 4.0 / nD, inv_wD = nD / 4.0, inv_w = 1.0 / w;
  const int nE = std::max(1, static_cast<int>(std::ceil((e_hi - e_lo) * inv_w)));
  const std::size_t bins = static_cast<std::size_t>(nD) * nE;
  bb.e_lo = e_lo, bb.inv_w = inv_w, bb.inv_wD = inv_wD, bb.nD = nD, bb.nE = nE;
  const auto e_bin = [&](double e) { return bb.e_bin(e); };
  const auto d_bin = [&](const Vec3& d) { return bb.d_bin(d); };
  std::vector<CellPassBeam>& all = S.all;
  std::vector<std::size_t>& point_of = S.point_of;
  // The beams in the order of their bins (neighbouring drops read neighbouring beams).
  std::vector<CellPassBeam>& beams = S.beams;
  std::vector<std::size_t>& point = S.point;
  beams.resize(all.size()), point.resize(all.size());
  {
    std::vector<std::uint32_t>&key = S.key, &at = S.at;
    key.resize(all.size()), at.assign(bins + 1, 0u);
    for (std::size_t k = 0; k < all.size(); ++k) {
      key[k] = static_cast<std::uint32_t>(static_cast<std::size_t>(e_bin(all[k].dir.z)) * nD + d_bin(all[k].dir));
      ++at[key[k] + 1];
    }
    for (std::size_t b = 1; b <= bins; ++b) at[b] += at[b - 1];
    for (std::size_t k = 0; k < all.size(); ++k) {
      const std::uint32_t j = at[key[k]]++;
      beams[j] = all[k], point[j] = point_of[k];
    }
  }
  std::vector<CellPassSpan>& spans = S.spans;
  spans.resize(beams.size());
  std::vector<std::uint32_t>& start = S.start;
  start.assign(bins + 1, 0u);
  for (std::size_t k = 0; k < beams.size(); ++k) {
    const Vec3& d = beams[k].dir;
    CellPassSpan& sp = spans[k];
    sp.e0 = e_bin(d.z - psi - 1e-9), sp.e1 = e_bin(d.z + psi + 1e-9);
    // A cone about a direction at elevation el spans asin(sin ψ/cos el) of azimuth.
    const double cos_el = std::sqrt(d.x * d.x + d.y * d.y);
    const double D = diamond_angle(d.x, d.y);
    double dphi = 4.0;
    if (cos_el > 1.01 * sin_psi + 1e-9) dphi = std::asin(std::min(1.0, sin_psi / cos_el * (1.0 + 1e-6))) * (1.0 + 1e-6) + 1e-9;
    if (2.0 * dphi + 2.0 * wD >= 4.0) {
      sp.d0 = 0, sp.d1 = nD - 1;
    } else {
      sp.d0 = static_cast<int>(std::floor((D - dphi) * inv_wD)), sp.d1 = static_cast<int>(std::floor((D + dphi) * inv_wD));
    }
    for (int e = sp.e0; e <= sp.e1; ++e)
      for (int j = sp.d0; j <= sp.d1; ++j) ++start[static_cast<std::size_t>(e) * nD + ((j % nD) + nD) % nD + 1];
  }
  // Which bins hold a beam, a bit each (in cache where the index is not: most drops meet no beam).
  std::vector<std::uint64_t>& held = S.held;
  held.assign(bins / 64 + 1, 0u);
  for (std::size_t b = 0; b < bins; ++b)
    if (start[b + 1]) held[b / 64] |= std::uint64_t(1) << (b % 64);
  for (std::size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
  std::vector<CellPassEntry>& in_bin = S.in_bin;
  in_bin.resize(start.back());
  {
    std::vector<std::uint32_t>& fill = S.fill;
    fill.assign(start.begin(), start.end() - 1);
    for (std::size_t k = 0; k < beams.size(); ++k) {
      const CellPassSpan& sp = spans[k];
      for (int e = sp.e0; e <= sp.e1; ++e)
        for (int j = sp.d0; j <= sp.d1; ++j)
          in_bin[fill[static_cast<std::size_t>(e) * nD + ((j % nD) + nD) % nD]++] = {beams[k], static_cast<std::uint32_t>(k)};
    }
  }
  return bb;
}

// The scan's drop echoes cell by cell (what scan_echoes_by_beam finds beam by
// beam, bit for bit):
//  1. the beams are binned by direction (diamond angle, sin elevation), each
//     in every bin its cone (half-angle atan(θ/2), rounded up) can reach;
//  2. coarse groups of beams mark the bricks (B³ cells) their cones cross,
//     out to min(range, 1.01·r_reach), with the farthest range of the group;
//  3. each cell of a marked brick is drawn once, to the measure visit() draws
//     it to (its nearest range: the same for every beam from the origin); a
//     cell whose first draw already exceeds an upper bound of that measure
//     (tabulated by distance) holds no such drop and costs three hashes;
//  4. each drop is tested, by visit()'s own arithmetic (echo()), against the
//     beams of its direction's bin; it counts for a beam when visit() would
//     have met its cell there (nearest range below min(range, r_reach)).
// visit() meets a cell when the DDA's widened boxes hold it: a drop at least
// 1 nm inside the cone and strictly inside its cell is in them whatever the
// rounding. A beam with a drop nearer the cone's edge, past r_reach, or on its
// cell's upper face, or with two strongest echoes of equal power (visit()'s
// order decides), is redone by visit() alone.
void LidarRain::scan_echoes_by_cell(const float* points, std::size_t n, std::vector<ScanEcho>& out) const {
  const double hw = theta_ / 2.0, c = kRainCellM, r_min = p_.blind_range_m;
  const double o0[3] = {0.0, 0.0, 0.0};
  const double psi = std::atan(hw) * (1.0 + 1e-6) + 1e-9;  // the cone's half-angle, rounded up
  // Scratch reused from call to call (a scan's worth of arrays: no page faults after the first).
  thread_local CellPassScratch S;
  double e_lo, e_hi;
  gather_beams(S, points, n, r_min, reach_, nullptr, e_lo, e_hi);
  if (S.all.empty()) return;
  const BeamBins bb = bin_beams(S, psi, e_lo, e_hi);
  const int nD = bb.nD, nE = bb.nE;
  const auto e_bin = [&](double e) { return bb.e_bin(e); };
  const auto d_bin = [&](const Vec3& d) { return bb.d_bin(d); };
  std::vector<CellPassBeam>& beams = S.beams;
  std::vector<std::size_t>& point = S.point;
  std::vector<CellPassBest>& best = S.best;
  best.assign(beams.size(), CellPassBest{});
  const std::vector<std::uint32_t>& start = S.start;
  const std::vector<std::uint64_t>& held = S.held;
  const std::vector<CellPassEntry>& in_bin = S.in_bin;
  // 2. The bricks the cones cross: groups of G×G bins, each group's direction
  // box (its beams' unit vectors, widened by ψ) swept over its ranges.
  constexpr int B = 4;  // cells per brick edge
  const double bm = B * c;
  const double r_far = 1.01 * reach_ * std::sqrt(1.0 + hw * hw) * (1.0 + 1e-9) + 1e-9;
  const std::int64_t nb = static_cast<std::int64_t>(std::ceil(r_far / bm)) + 1;  // bricks within [-nb, nb) per axis
  std::int64_t blo[3] = {nb, nb, nb}, bhi[3] = {-nb, -nb, -nb}, bn[3] = {0, 0, 0};  // the grid: the sweeps' box
  std::vector<float>& brick_T = S.brick_T;
  std::vector<std::int64_t>& bricks = S.bricks;
  bricks.clear();
  {
    constexpr int G = 4;
    const int gD = (nD + G - 1) / G, gE = (nE + G - 1) / G;
    std::vector<CellPassGroup>& groups = S.groups;
    groups.assign(static_cast<std::size_t>(gD) * gE, CellPassGroup{});
    for (const CellPassBeam& b : beams) {
      CellPassGroup& g = groups[static_cast<std::size_t>(e_bin(b.dir.z) / G) * gD + d_bin(b.dir) / G];
      const double u[3] = {b.dir.x, b.dir.y, b.dir.z};
      for (int a = 0; a < 3; ++a) g.lo[a] = std::min(g.lo[a], u[a]), g.hi[a] = std::max(g.hi[a], u[a]);
      g.T = std::max(g.T, std::min(b.r, 1.01 * reach_));  // no drop beyond 1.01 r_reach reaches the floor
    }
    // Sweep every group (pass 0: the grid's box; pass 1: mark its bricks).
    for (int pass = 0; pass < 2; ++pass) {
      if (pass == 1) {
        for (int a = 0; a < 3; ++a) bn[a] = std::max<std::int64_t>(0, bhi[a] - blo[a] + 1);
        brick_T.assign(static_cast<std::size_t>(bn[0] * bn[1] * bn[2]), -1.0f);
      }
      for (const CellPassGroup& g : groups) {
        if (g.T < 0.0) continue;
        double lo[3], hi[3];
        for (int a = 0; a < 3; ++a) lo[a] = g.lo[a] - psi - 1e-9, hi[a] = g.hi[a] + psi + 1e-9;
        // A drop in a cone lies at |p| in [r_min, T·√(1 + (θ/2)²)].
        const double r_end = g.T * std::sqrt(1.0 + hw * hw) * (1.0 + 1e-9) + 1e-9;
        const float T = static_cast<float>(g.T * (1.0 + 1e-6));
        for (double ra = r_min; ra < r_end; ra += bm) {
          const double rb = std::min(r_end, ra + bm);
          std::int64_t b0[3], b1[3];
          for (int a = 0; a < 3; ++a) {
            const double x0 = std::min(ra * lo[a], rb * lo[a]), x1 = std::max(ra * hi[a], rb * hi[a]);
            b0[a] = std::max(-nb, static_cast<std::int64_t>(std::floor(x0 / bm)));
            b1[a] = std::min(nb - 1, static_cast<std::int64_t>(std::floor(x1 / bm)));
          }
          if (pass == 0) {
            for (int a = 0; a < 3; ++a) blo[a] = std::min(blo[a], b0[a]), bhi[a] = std::max(bhi[a], b1[a]);
            continue;
          }
          for (std::int64_t x = b0[0]; x <= b1[0]; ++x)
            for (std::int64_t y = b0[1]; y <= b1[1]; ++y)
              for (std::int64_t z = b0[2]; z <= b1[2]; ++z) {
                const std::int64_t id = ((x - blo[0]) * bn[1] + (y - blo[1])) * bn[2] + (z - blo[2]);
                float& t = brick_T[static_cast<std::size_t>(id)];
                if (t < 0.0f) bricks.push_back(id);
                t = std::max(t, T);
              }
        }
      }
    }
  }
  // 3. An upper bound of a cell's measure by its squared distance: visit()
  // draws to M(k·r_near²), r_near >= √dist2·cos(θ/2); the cell holds no drop
  // when its first draw u > 1 − e^{−M} (with a margin).
  const int nq = kMeasureBounds;
  const double inv_dq = measure_bounds(r_far, S.u_max);
  const std::vector<double>& u_max = S.u_max;
  // 4. The cells' drops against the beams of their bins.
  std::size_t drawn = 0;
  for (const std::int64_t id : bricks) {
    const double T = brick_T[static_cast<std::size_t>(id)];
    const double T2 = T * T * (1.0 + hw * hw) * (1.0 + 1e-9) + 1e-9;
    const std::int64_t bz = id % bn[2] + blo[2], by = (id / bn[2]) % bn[1] + blo[1], bx = id / (bn[1] * bn[2]) + blo[0];
    for (std::int64_t ix = bx * B; ix < bx * B + B; ++ix) {
      const double lx = static_cast<double>(ix) * c, gx = std::max({lx, 0.0, -(lx + c)});
      for (std::int64_t iy = by * B; iy < by * B + B; ++iy) {
        const double ly = static_cast<double>(iy) * c, gy = std::max({ly, 0.0, -(ly + c)});
        const double gxy = gx * gx + gy * gy;
        if (gxy >= T2) continue;
        const std::uint64_t col = field_.column_hash(ix, iy);
        for (std::int64_t iz = bz * B; iz < bz * B + B; ++iz) {
          const double lz = static_cast<double>(iz) * c, gz = std::max({lz, 0.0, -(lz + c)});
          const double dist2 = gxy + gz * gz;
          if (dist2 >= T2) continue;
          const std::uint64_t h = RainField::cell_hash(col, iz);
          const double u0 = RainField::first_unit(h);
          const std::size_t j = static_cast<std::size_t>(dist2 * inv_dq);
          if (j > static_cast<std::size_t>(nq) || u0 > u_max[j]) continue;
          const RainCell cell{ix, iy, iz};
          const double r_near = near_range(cell, o0);
          if (!(r_near < T)) continue;
          const double m = field_.measure_above(k_ * r_near * r_near * 1e3);
          if (!(m > 0.0)) continue;
          const double cell_hi[3] = {lx + c, ly + c, lz + c};
          field_.for_each_drop_hashed(cell, h, m, [&](const Vec3& at, double s) {
            ++drawn;
            const double q2 = at.x * at.x + at.y * at.y + at.z * at.z;
            const std::ptrdiff_t bin = bb.bin(at.x, at.y, at.z, q2, e_hi, held);
            if (bin < 0) return;
            for (std::uint32_t q = start[bin]; q < start[bin + 1]; ++q) {
              const CellPassBeam& b = in_bin[q].beam;
              double t, power, reported;
              if (!echo(at, s, o0, b.dir, b.r, t, power, reported)) continue;
              if (!(r_near < b.t1)) continue;  // visit() skips the cell on this beam
              CellPassBest& o = best[in_bin[q].k];
              // Robustly in visit()'s cells: 1 nm inside the cone, before t1, inside the cell.
              const double perp2 = std::max(0.0, q2 - t * t);
              const double in = t * hw * (1.0 - 1e-12) - 1e-9;
              if (!(in > 0.0 && perp2 + 1e-14 * (q2 + 1.0) <= in * in && t <= b.t1 * (1.0 - 1e-9) &&
                    at.x < cell_hi[0] && at.y < cell_hi[1] && at.z < cell_hi[2]))
                o.redo = true;
              const double key = last_ ? t : power;
              if (key > o.key) {
                o.key = key, o.power = power, o.t = t, o.reported = reported;
              } else if (key == o.key) {
                o.redo = true;  // visit()'s order would choose
              }
            }
          });
        }
      }
    }
  }
  drawn_ += drawn;
  // In the points' order; the beams the pass cannot vouch for, beam by beam.
  for (const std::uint32_t k : beams_in_point_order(S)) {
    CellPassBest& o = best[k];
    const CellPassBeam& b = beams[k];
    if (o.redo) {
      o.power = -1.0;
      const float* q = points + 4 * point[k];
      beam_best(q[0], q[1], q[2], b.r, o.power, o.t, o.reported);
    }
    if (o.power >= 0.0) out.push_back({point[k], o.t, o.power * b.r * b.r, o.reported});
  }
}

// The scan's drop echoes where the field is not the scan's frame as hashed (a calibration, a pose,
// a frame K > 0): the beams in the field's world (origin O, rotated directions), binned by
// direction as above; every cell whose drops can land in a cone at time t (its layer's column
// above the cones, as far as the drops' fall speeds reach over t) drawn once, to the diameter the
// nearest landing range needs; each drop moved by rain_drop_at and tested against the beams of its
// direction's bin by echo(). The same model as visit()'s; no beam-by-beam reference (none exists
// for a moving field), the ties to the first met.
void LidarRain::scan_echoes_general(const float* points, std::size_t n, std::vector<ScanEcho>& out) const {
  if (reach_ <= 0.0) return;
  const double hw = theta_ / 2.0, c = kRainCellM, r_min = p_.blind_range_m, t_s = pose_.t_s;
  const Mat3& R = pose_.world_from_sensor.rotation;
  const Vec3& O = pose_.world_from_sensor.translation;
  const Vec3& wind = pose_.wind;
  const double o[3] = {O.x, O.y, O.z};
  const double psi = std::atan(hw) * (1.0 + 1e-6) + 1e-9;
  thread_local CellPassScratch S;
  double e_lo, e_hi;
  gather_beams(S, points, n, r_min, reach_, &R, e_lo, e_hi);
  if (S.all.empty()) return;
  const BeamBins bb = bin_beams(S, psi, e_lo, e_hi);
  std::vector<CellPassBeam>& beams = S.beams;
  std::vector<std::size_t>& point = S.point;
  std::vector<CellPassBest>& best = S.best;
  best.assign(beams.size(), CellPassBest{});
  // The source columns: bricks of B×B cells, shifted back by the wind, that a cone's horizontal
  // extent crosses (each beam swept in steps of a brick).
  constexpr int B = 4;
  const double bm = B * c;
  const double r_far = 1.01 * reach_ * std::sqrt(1.0 + hw * hw) * (1.0 + 1e-9) + 1e-9;
  const double sx = wind.x * t_s, sy = wind.y * t_s;  // the drops' horizontal drift since t = 0
  const std::int64_t gx0 = static_cast<std::int64_t>(std::floor((O.x - sx - r_far) / bm)) - 1,
                     gy0 = static_cast<std::int64_t>(std::floor((O.y - sy - r_far) / bm)) - 1;
  const std::int64_t gn = static_cast<std::int64_t>(std::ceil(2.0 * r_far / bm)) + 3;
  // Per brick column, the cells' heights [lo, hi] the cones reach there (lo > hi: none).
  std::vector<std::int64_t> column(static_cast<std::size_t>(2 * gn * gn), 0);
  for (std::size_t k = 0; k < column.size(); k += 2) column[k] = INT64_MAX, column[k + 1] = INT64_MIN;
  for (const CellPassBeam& b : beams) {
    for (double ta = r_min; ta < b.t1; ta += bm) {
      const double tb = std::min(b.t1, ta + bm), w = tb * hw * 1.01 + 1e-6;
      const double xa = O.x + ta * b.dir.x, xb = O.x + tb * b.dir.x, ya = O.y + ta * b.dir.y, yb = O.y + tb * b.dir.y;
      const double za = O.z + ta * b.dir.z, zb = O.z + tb * b.dir.z;
      const std::int64_t cz0 = static_cast<std::int64_t>(std::floor((std::min(za, zb) - w) / c)),
                         cz1 = static_cast<std::int64_t>(std::floor((std::max(za, zb) + w) / c));
      const std::int64_t x0 = static_cast<std::int64_t>(std::floor((std::min(xa, xb) - w - sx) / bm)) - gx0,
                         x1 = static_cast<std::int64_t>(std::floor((std::max(xa, xb) + w - sx) / bm)) - gx0,
                         y0 = static_cast<std::int64_t>(std::floor((std::min(ya, yb) - w - sy) / bm)) - gy0,
                         y1 = static_cast<std::int64_t>(std::floor((std::max(ya, yb) + w - sy) / bm)) - gy0;
      for (std::int64_t gx = std::max<std::int64_t>(0, x0); gx <= std::min(gn - 1, x1); ++gx)
        for (std::int64_t gy = std::max<std::int64_t>(0, y0); gy <= std::min(gn - 1, y1); ++gy) {
          std::int64_t* z = &column[static_cast<std::size_t>(2 * (gx * gn + gy))];
          z[0] = std::min(z[0], cz0), z[1] = std::max(z[1], cz1);
        }
    }
  }
  // A cell's measure bound by the squared distance of its drops' landing place (as the cell pass).
  const int nq = kMeasureBounds;
  const double inv_dq = measure_bounds(r_far, S.u_max);
  const std::vector<double>& u_max = S.u_max;
  const double T2 = r_far * r_far;
  const double v_hi = atlas_terminal_velocity_m_per_s(p_.drops.drop_max_mm) - wind.z;
  std::size_t drawn = 0;
  std::vector<std::pair<std::int64_t, std::int64_t>> spans;  // source cells [iz0, iz1]
  for (std::int64_t gx = 0; gx < gn; ++gx)
    for (std::int64_t gy = 0; gy < gn; ++gy) {
      const std::int64_t* zc = &column[static_cast<std::size_t>(2 * (gx * gn + gy))];
      if (zc[0] > zc[1]) continue;
      // The heights drops must land at in this column.
      const double z_lo = static_cast<double>(zc[0]) * c, z_hi = static_cast<double>(zc[1] + 1) * c;
      for (std::int64_t ix = (gx0 + gx) * B; ix < (gx0 + gx) * B + B; ++ix) {
        // The landing place's horizontal gap to O (the cell shifted by the drift).
        const double lx = static_cast<double>(ix) * c + sx, dx = std::max({lx - O.x, 0.0, O.x - (lx + c)});
        for (std::int64_t iy = (gy0 + gy) * B; iy < (gy0 + gy) * B + B; ++iy) {
          const double ly = static_cast<double>(iy) * c + sy, dy = std::max({ly - O.y, 0.0, O.y - (ly + c)});
          const double gxy = dx * dx + dy * dy;
          if (gxy >= T2) continue;
          // Which source heights land in [z_lo, z_hi]: at t = 0 those; else per layer, the landing
          // heights moved up by the fall over t, f·t with f in [v(D_lo) − w_z, v(D_max) − w_z].
          spans.clear();
          double f_lo = 0.0;  // [m/s] the slowest fall (less the wind's w_z) of a drop drawn in this column
          if (t_s == 0.0) {
            spans.push_back({zc[0], zc[1]});
          } else {
            const double r_lo = std::max(r_min, std::sqrt(gxy) * cos_half_ * (1.0 - 1e-12));
            const double d_lo = std::max(p_.drops.drop_min_mm, k_ * r_lo * r_lo * 1e3 * (1.0 - 1e-12));
            if (d_lo > p_.drops.drop_max_mm) continue;
            f_lo = atlas_terminal_velocity_m_per_s(d_lo) - wind.z;
            falling_source_spans(z_lo, z_hi, f_lo, v_hi, t_s, spans);
          }
          const std::uint64_t col = field_.column_hash(ix, iy);
          for (const auto& [iz0, iz1] : spans)
            for (std::int64_t iz = iz0; iz <= iz1; ++iz) {
              // The nearest landing range: at t = 0 the cell's own distance, else the column's.
              double dist2 = gxy;
              if (t_s == 0.0) {
                const double lz = static_cast<double>(iz) * c, dz = std::max({lz - O.z, 0.0, O.z - (lz + c)});
                dist2 += dz * dz;
              }
              if (dist2 >= T2) continue;
              const std::uint64_t h = RainField::cell_hash(col, iz);
              const std::size_t jq = static_cast<std::size_t>(dist2 * inv_dq);
              if (jq > static_cast<std::size_t>(nq) || RainField::first_unit(h) > u_max[jq]) continue;
              const double r_near = std::max(r_min, std::sqrt(dist2) * cos_half_);
              double d_cut = k_ * r_near * r_near * 1e3;
              if (t_s != 0.0) {
                // A drop of this cell lands in [z_lo, z_hi] (within its layer) only when f·t ≡ z_s − z
                // (mod H), f = v(D) − w_z: the smallest such f >= f_lo gives the smallest diameter that
                // can (v increases with D), below which the cell's drops, drawn largest first, are not drawn.
                double f;
                if (!falling_min_speed(iz, z_lo, z_hi, f_lo, v_hi, t_s, f)) continue;
                d_cut = std::max(d_cut, atlas_diameter_below_mm(f + wind.z));  // v(D*) of the smallest that can land
              }
              const double m = field_.measure_above(d_cut);
              if (!(m > 0.0)) continue;
              field_.for_each_drop_hashed({ix, iy, iz}, h, m, [&](const Vec3& at0, double s) {
                ++drawn;
                const Vec3 at = t_s == 0.0 ? at0 : rain_drop_at(at0, field_.diameter_mm(s), t_s, wind);
                if (!(at.z >= z_lo && at.z <= z_hi)) return;
                const double px = at.x - O.x, py = at.y - O.y, pz = at.z - O.z;
                const double q2 = px * px + py * py + pz * pz;
                if (!(q2 < T2 && q2 > 0.0)) return;
                const std::ptrdiff_t bin = bb.bin(px, py, pz, q2, e_hi, S.held);
                if (bin < 0) return;
                for (std::uint32_t q = S.start[bin]; q < S.start[bin + 1]; ++q) {
                  const CellPassBeam& b = S.in_bin[q].beam;
                  double t, power, reported;
                  if (!echo(at, s, o, b.dir, b.r, t, power, reported)) continue;
                  CellPassBest& ob = best[S.in_bin[q].k];
                  const double key = last_ ? t : power;
                  if (key > ob.key) ob.key = key, ob.power = power, ob.t = t, ob.reported = reported;
                }
              });
            }
        }
      }
    }
  drawn_ += drawn;
  for (const std::uint32_t k : beams_in_point_order(S))
    if (best[k].power >= 0.0) out.push_back({point[k], best[k].t, best[k].power * beams[k].r * beams[k].r, best[k].reported});
}

}  // namespace

std::unique_ptr<Medium> lidar_rain_as_medium(const LidarRainParams& p) {
  validate_lidar_rain(p);
  return std::make_unique<LidarRain>(p);
}

std::unique_ptr<Medium> lidar_rain_as_medium_searching(const LidarRainParams& p, LidarRainSearch search) {
  validate_lidar_rain(p);
  return std::make_unique<LidarRain>(p, search);
}

LidarRainStats lidar_rain(const float* in, float* out, std::size_t n, const LidarRainParams& p, std::uint8_t* labels,
                          const std::string& what) {
  validate_lidar_rain(p);
  check_scan_points(in, n, what);
  const LidarRain m(p);
  const ScanDetection detection{p.noise_floor, p.seed};
  LidarRainStats st;
  st.field_frame = m.field_frame();
  st.run = scan_through_media({&m}, in, out, n, what, &detection, labels, scan_return(p.return_mode));
  st.drops_drawn = m.drawn();
  return st;
}

nlohmann::json lidar_rain_record(const LidarRainParams& p, const LidarRainStats& st) {
  const double r = p.drops.rate_mm_h.value_or(0.0);
  const std::size_t moved = st.run.echoes, lost = st.run.lost;
  nlohmann::json files = nlohmann::json::object();  // the files the pose was read from, hashed (brume run checks them)
  if (!p.poses.empty()) files["poses"] = {{"path", p.poses}, {"sha256", sha256_file(p.poses)}};
  if (!p.kitti_calib.empty()) files["kitti_calib"] = {{"path", p.kitti_calib}, {"sha256", sha256_file(p.kitti_calib)}};
  return {{"model",
           "Marshall-Palmer 1948 drop sizes, Atlas et al. 1973 fall speed; per beam the drops in its cone echo "
           "(Kilic et al. 2021, from the paper's equations), the strongest return wins, speckle detection against "
           "the noise floor"},
          {"rate_mm_h", r},
          {"n0_per_m3_mm", kMarshallPalmerN0},
          {"lambda_per_mm", r > 0.0 ? nlohmann::json(marshall_palmer_lambda_per_mm(r)) : nlohmann::json(nullptr)},
          {"extinction_per_m", rain_extinction_per_m(r, kLidarRainQ)},
          {"extinction_q", kLidarRainQ},
          {"extinction_q_from", "a narrow beam loses the drops' forward diffraction lobe: Q = 2 (extinction paradox)"},
          {"drops_per_m3", rain_drops_per_m3(r, p.drops.drop_min_mm, p.drops.drop_max_mm)},
          {"divergence_mrad", p.divergence_mrad},
          {"drop_reflectance", p.drop_reflectance},
          {"drop_reflectance_from",
           "2 pi/S, S the lidar ratio of liquid water drops (about 18 sr; Pinnick et al. 1983); docs/rain.md"},
          {"noise_floor_per_m2", p.noise_floor},
          {"blind_range_m", p.blind_range_m},
          {"drop_min_mm", p.drops.drop_min_mm},
          {"drop_max_mm", p.drops.drop_max_mm},
          {"cell_m", kRainCellM},
          {"seed", p.seed},
          {"return_mode", p.return_mode},
          {"frame", p.frame},
          {"frame_interval_s", p.frame_interval_s},
          {"time_s", static_cast<double>(p.frame) * p.frame_interval_s},
          {"wind_m_s", p.wind},
          {"ego_speed_m_s", p.ego_speed_m_s},
          {"field_frame", st.field_frame},
          {"pose_files", files},
          {"layer_m", kRainLayerM},
          {"layer_base_m", kRainLayerBaseM},
          {"layer_from",
           "a falling drop wraps within its layer of the field's world frame (it leaves at the bottom, re-enters at "
           "the top), so that the field stays a homogeneous Poisson field at every time; the layers' edges lie "
           "16 m below and above the sensor at frame 0"},
          {"points", st.run.points},
          {"kept", st.run.points - moved - lost},
          {"moved_to_drops", moved},
          {"lost", lost},
          {"drops_drawn", st.drops_drawn}};
}

}  // namespace brume
