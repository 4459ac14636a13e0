// The height-layered LiDAR fog (brume/lidar_fog.hpp, docs/lidar.md "Height-
// layered fog", issue #41 item 3): a constant profile against the homogeneous
// model bit for bit; the hard returns against the closed-form optical depth
// of an exponential profile along level, climbing and descending beams (and
// through KITTI's calibration and a camera pose, composed here by hand); the
// soft returns against an independent double-precision integral of the
// soft-target equation with the local density (adaptive Simpson in the
// pulse's time t, where the library uses fixed Simpson in range on a table);
// the elevation bins against per-beam runs within the documented bound; the
// pose and the bad inputs; `brume lidar fog --profile` with `brume run`.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/fog_params.hpp"
#include "brume/height_profile.hpp"
#include "brume/lidar_fog.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace lidar_layered_tests {

const char* kScan = "kitti_object_000001/velodyne/000001.bin";
const char* kCalib = "kitti_object_000001/calib/000001.txt";
constexpr double kC = 299792458.0;
const double kPaperRatio = 0.046 / std::log(20.0);  // β_b/α of the paper's 0.046/MOR

// An exponential ground fog seen from a LiDAR at `ys` metres (no calibration).
LidarFogParams exponential(double d0, double b, double y0, double ys) {
  LidarFogParams p;
  p.profile = HeightProfile::exponential;
  p.fog.density_per_m = d0;
  p.fog.falloff_per_m = b;
  p.fog.base_height_m = y0;
  p.pose.sensor_height_m = ys;
  p.noise = "off";
  return p;
}

// Points along the beam of elevation θ (radians, azimuth 30°) at the given ranges, intensity i.
void beam(std::vector<float>& v, double theta, std::initializer_list<double> ranges, float i = 0.5f) {
  for (double r : ranges)
    v.insert(v.end(), {static_cast<float>(r * std::cos(theta) * std::cos(0.52)),
                       static_cast<float>(r * std::cos(theta) * std::sin(0.52)),
                       static_cast<float>(r * std::sin(theta)), i});
}

double beam_range(const float* q) {
  const double x = q[0], y = q[1], z = q[2];
  return std::sqrt(x * x + y * y + z * z);
}

// ---- the independent reference ----
// A density of height δ(y) and its optical depth along a beam from height ys
// climbing at s = sin θ, in closed form.
struct DensityProfile {
  std::function<double(double)> delta;       // δ(y) [1/m]
  std::function<double(double, double)> F;   // F(r; s) [1]
};
DensityProfile exponential_profile(double d0, double b, double y0, double ys) {
  DensityProfile p;
  p.delta = [=](double y) { return d0 * std::exp(-b * (y - y0)); };
  // F = D0/(B s)·(e^{−B(ys−Y0)} − e^{−B(ys + r s − Y0)}); level: δ(ys)·r.
  p.F = [=](double r, double s) {
    if (s == 0.0 || b == 0.0) return d0 * std::exp(-b * (ys - y0)) * r;
    return d0 / (b * s) * (std::exp(-b * (ys - y0)) - std::exp(-b * (ys + r * s - y0)));
  };
  return p;
}
DensityProfile band_profile(double d0, double yc, double w, double ys) {
  DensityProfile p;
  p.delta = [=](double y) {
    const double u = y - yc;
    return std::abs(u) <= w ? 0.5 * d0 * (1.0 + std::cos(M_PI * u / w)) : 0.0;
  };
  // D(u) = D0/2·(u + (W/π) sin(πu/W)) on [−W, W], held outside; F = ΔD/s.
  auto anti = [=](double y) {
    const double u = std::clamp(y - yc, -w, w);
    return 0.5 * d0 * (u + w / M_PI * std::sin(M_PI * u / w));
  };
  p.F = [=](double r, double s) { return (anti(ys + r * s) - anti(ys)) / s; };
  return p;
}

// P_soft(R; R0) = C_A·P0·∫_0^{2τ_H} sin²(πt/(2τ_H))·β_b(r)·ξ(r)·e^{−2F(r)}/r²·U(R0 − r) dt,
// r = R − ct/2, β_b(r) = ratio·δ(ys + r s): adaptive Simpson on the pieces
// between the breakpoints (ξ's kinks at R1 and R2, the cut at R0).
struct LayeredReference {
  DensityProfile prof;
  double ys, s, ratio, c_a, p0, tau, r1, r2;
  LayeredReference(const LidarFogParams& p, DensityProfile pr, double ys_, double s_) : prof(std::move(pr)), ys(ys_), s(s_) {
    ratio = p.lidar_ratio_sr ? 1.0 / *p.lidar_ratio_sr : kPaperRatio;
    c_a = kC * p.l_r * p.a_r_m2 / 2;
    p0 = p.p0_w;
    tau = p.tau_h_ns * 1e-9;
    r1 = p.r1_m;
    r2 = p.r2_m;
  }
  double integrand(double t, double R, double R0) const {
    const double r = R - kC * t / 2;
    if (r <= r1 || r > R0) return 0.0;
    const double xi = r >= r2 ? 1.0 : (r - r1) / (r2 - r1);
    const double sn = std::sin(M_PI * t / (2 * tau));
    return sn * sn * ratio * prof.delta(ys + r * s) * xi * std::exp(-2 * prof.F(r, s)) / (r * r);
  }
  double simpson(double a, double b, double fa, double fm, double fb, double whole, double eps, int depth,
                 double R, double R0) const {
    const double m = 0.5 * (a + b), lm = 0.5 * (a + m), rm = 0.5 * (m + b);
    const double flm = integrand(lm, R, R0), frm = integrand(rm, R, R0);
    const double left = (m - a) / 6 * (fa + 4 * flm + fm), right = (b - m) / 6 * (fm + 4 * frm + fb);
    if (depth <= 0 || std::abs(left + right - whole) <= 15 * eps) return left + right + (left + right - whole) / 15;
    return simpson(a, m, fa, flm, fm, left, eps / 2, depth - 1, R, R0) +
           simpson(m, b, fm, frm, fb, right, eps / 2, depth - 1, R, R0);
  }
  // The pieces of [0, 2τ_H] between the breakpoints.
  std::vector<double> pieces(double R, double R0) const {
    std::vector<double> cuts = {0.0, 2 * tau};
    for (double rr : {r1, r2, R0}) {
      const double t = 2 * (R - rr) / kC;
      if (t > 0 && t < 2 * tau) cuts.push_back(t);
    }
    std::sort(cuts.begin(), cuts.end());
    return cuts;
  }
  // For scanning: 8-point Gauss-Legendre on 6 panels of each piece.
  double power_fast(double R, double R0) const {
    static const double x[8] = {-0.9602898564975363, -0.7966664774136267, -0.5255324099163290, -0.1834346424956498,
                                0.1834346424956498,  0.5255324099163290,  0.7966664774136267,  0.9602898564975363};
    static const double w[8] = {0.1012285362903763, 0.2223810344533745, 0.3137066458778873, 0.3626837833783620,
                                0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};
    const std::vector<double> cuts = pieces(R, R0);
    double sum = 0.0;
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k)
      for (int q = 0; q < 6; ++q) {
        const double a = cuts[k] + (cuts[k + 1] - cuts[k]) * q / 6, b = cuts[k] + (cuts[k + 1] - cuts[k]) * (q + 1) / 6;
        for (int i = 0; i < 8; ++i) sum += 0.5 * (b - a) * w[i] * integrand(0.5 * (a + b) + 0.5 * (b - a) * x[i], R, R0);
      }
    return c_a * p0 * sum;
  }
  // The reference: adaptive Simpson on each piece to an absolute tolerance of
  // 1e-11 of the integral (the fast rule's estimate), shared by length.
  double power(double R, double R0 = INFINITY) const {
    const double scale = power_fast(R, R0) / (c_a * p0);
    if (scale == 0.0) return 0.0;
    const std::vector<double> cuts = pieces(R, R0);
    double sum = 0.0;
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
      const double a = cuts[k], b = cuts[k + 1], m = 0.5 * (a + b);
      const double fa = integrand(a, R, R0), fm = integrand(m, R, R0), fb = integrand(b, R, R0);
      const double whole = (b - a) / 6 * (fa + 4 * fm + fb);
      sum += simpson(a, b, fa, fm, fb, whole, 1e-11 * scale * (b - a) / (2 * tau), 30, R, R0);
    }
    return c_a * p0 * sum;
  }
  // The cut curve's maximum: a scan at the table's step over [R1, R0 + L]
  // (the uncut curve, R0 = ∞: over [R1, scan_end]) with the fast rule, then
  // a golden refinement of the reference around the best node.
  void peak(double R0, double step, double& best_p, double& best_r, double scan_end = INFINITY) const {
    best_p = 0.0, best_r = 0.0;
    const double end = std::min(R0 + kC * tau, scan_end);
    for (double R = r1; R <= end; R += step) {
      const double v = power_fast(R, R0);
      if (v > best_p) best_p = v, best_r = R;
    }
    double a = best_r - step, b = best_r + step;
    for (int i = 0; i < 40; ++i) {
      const double m1 = b - (b - a) * 0.618033988749895, m2 = a + (b - a) * 0.618033988749895;
      if (power(m1, R0) < power(m2, R0)) a = m1; else b = m2;
    }
    best_r = 0.5 * (a + b);
    best_p = power(best_r, R0);
  }
};

// P_hard,clear(R0) = C_A·P0·β0·ξ(R0)/R0²: the soft peak of a fog point is its intensity ratio times it.
double hard_clear(const LidarFogParams& p, double r0) {
  const double xi = r0 >= p.r2_m ? 1.0 : (r0 - p.r1_m) / (p.r2_m - p.r1_m);
  return kC * p.l_r * p.a_r_m2 / 2 * p.p0_w * (p.gamma / M_PI) * xi / (r0 * r0);
}

// The KITTI calibration's numbers, read here (not by brume's reader).
struct Calib {
  double P2[12], R0[9], Tr[12];
};
Calib read_calib(const std::string& path) {
  Calib c{};
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    std::istringstream s(line);
    std::string key;
    s >> key;
    if (key == "P2:") for (double& v : c.P2) s >> v;
    if (key == "R0_rect:") for (double& v : c.R0) s >> v;
    if (key == "Tr_velo_to_cam:") for (double& v : c.Tr) s >> v;
  }
  return c;
}

// A velodyne point in camera 2's frame (OpenCV axes, from its centre):
// R0_rect·(Tr·p) plus camera 2's offset from P2 = K [I | t].
std::array<double, 3> in_camera2(const Calib& c, const double p[3]) {
  double cam[3], rect[3];
  for (int r = 0; r < 3; ++r) cam[r] = c.Tr[4 * r] * p[0] + c.Tr[4 * r + 1] * p[1] + c.Tr[4 * r + 2] * p[2] + c.Tr[4 * r + 3];
  for (int r = 0; r < 3; ++r) rect[r] = c.R0[3 * r] * cam[0] + c.R0[3 * r + 1] * cam[1] + c.R0[3 * r + 2] * cam[2];
  const double* P = c.P2;
  const double tz = P[11], ty = (P[7] - P[6] * tz) / P[5], tx = (P[3] - P[1] * ty - P[2] * tz) / P[0];
  return {rect[0] + tx, rect[1] + ty, rect[2] + tz};
}

// The world height of a camera-2 point for a camera at height h with
// pitch φ and roll ρ (yaw 0), by brume/camera.hpp's conventions: the eye
// frame is (x, −y, −z) of OpenCV's; roll turns about eye +z, then pitch
// about eye +x (> 0 raises the optical axis −z).
double world_height(const std::array<double, 3>& v, double h, double pitch_deg, double roll_deg) {
  const double phi = pitch_deg * M_PI / 180, rho = roll_deg * M_PI / 180;
  const double ex = v[0], ey = -v[1], ez = -v[2];
  const double ry = std::sin(rho) * ex + std::cos(rho) * ey;  // after the roll (z unchanged)
  return h + std::cos(phi) * ry - std::sin(phi) * ez;
}

}  // namespace lidar_layered_tests
using namespace lidar_layered_tests;

// A constant profile is the homogeneous model with α = its density: the same
// code, so the scans agree bit for bit (tolerance 0), noise on, with and
// without a lidar ratio, and the soft curves too.
TEST(LidarFogLayered, ConstantProfileIsTheHomogeneousModelBitForBit) {
  const std::vector<float> in = have_data(kScan) ? read_kitti_bin(data_path(kScan), "test") : [] {
    std::vector<float> v;
    for (int k = 0; k < 2000; ++k) beam(v, -0.4 + 0.0003 * k, {1.2 + 0.04 * k}, 0.01f * (k % 90));
    return v;
  }();
  const std::size_t n = in.size() / 4;
  for (double d0 : {0.05, 0.13}) {
    for (bool ratio : {false, true}) {
      SCOPED_TRACE(d0);
      LidarFogParams c;
      c.profile = HeightProfile::constant;
      c.fog.density_per_m = d0;
      c.seed = 11;
      LidarFogParams h;
      h.alpha_per_m = d0;
      h.seed = 11;
      if (ratio) c.lidar_ratio_sr = h.lidar_ratio_sr = 20.0;
      std::vector<float> a(in.size(), -1.0f), b(in.size(), -2.0f);
      const LidarFogStats sa = lidar_fog(in.data(), a.data(), n, c);
      const LidarFogStats sb = lidar_fog(in.data(), b.data(), n, h);
      EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0);
      EXPECT_EQ(sa.soft, sb.soft);
      EXPECT_GT(sa.soft, 0u);
      EXPECT_EQ(lidar_soft_curve(c, 40.0).power_w, lidar_soft_curve(h, 40.0).power_w);
      EXPECT_EQ(lidar_fog_medium(c).alpha, d0);
    }
  }
}

// The layered machinery on a fog that does not change with height (an
// exponential profile with B = 0): the tables per elevation bin against the
// homogeneous model's single table. Hard intensities within float rounding of
// the optical depth (brume's fog integral is float: F = r·δ to a few ulp),
// soft intensities within 1e-6 (the same Simpson cells, β_b·e^{−2F} formed in
// another order and F in float), the same points turned into fog (bar
// ratios within 1e-5 of the threshold), fog points at the same range (float
// rounding of the coordinates).
TEST(LidarFogLayered, AFogConstantInHeightMatchesTheHomogeneousTables) {
  std::vector<float> in;
  std::mt19937 g(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int k = 0; k < 4000; ++k) beam(in, (u(g) - 0.7) * 0.5, {0.95 + 70 * u(g) * u(g)}, static_cast<float>(u(g)));
  const std::size_t n = in.size() / 4;
  for (double d0 : {0.05, 0.12}) {
    SCOPED_TRACE(d0);
    LidarFogParams lay = exponential(d0, 0.0, 0.0, 1.7);
    LidarFogParams hom;
    hom.alpha_per_m = d0;
    hom.noise = "off";
    std::vector<float> a(in.size()), b(in.size());
    const LidarFogStats sa = lidar_fog(in.data(), a.data(), n, lay);
    const LidarFogStats sb = lidar_fog(in.data(), b.data(), n, hom);
    EXPECT_GT(sa.tables, 10u);
    std::size_t differ = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const float* q = &in[4 * i];
      const bool fa = std::memcmp(q, &a[4 * i], 12) != 0, fb = std::memcmp(q, &b[4 * i], 12) != 0;
      if (fa != fb) {
        ++differ;
        continue;
      }
      if (!fa) {
        const double F = d0 * beam_range(q);
        EXPECT_NEAR(a[4 * i + 3], b[4 * i + 3], b[4 * i + 3] * (1e-6 * std::max(1.0, 2 * F)) + 1e-30) << i;
      } else {
        EXPECT_NEAR(a[4 * i + 3], b[4 * i + 3], 1e-6 * b[4 * i + 3]) << i;
        EXPECT_NEAR(beam_range(&a[4 * i]), beam_range(&b[4 * i]), 1e-5) << i;
      }
    }
    EXPECT_LE(differ, 2u);
    EXPECT_NEAR(static_cast<double>(sa.soft), static_cast<double>(sb.soft), 2.0);
    EXPECT_GT(sb.soft, n / 50);
  }
}

// Hard returns: i·e^{−2F} with F the closed-form optical depth of an
// exponential profile along the beam, F = δ(y_s)·R level and
// F = D0/(B sin θ)·(e^{−B(y_s−Y0)} − e^{−B(y_s+R sin θ−Y0)}) climbing or
// descending. Tolerance: F comes from brume's float fog integral (relative
// error a few float ulp, ≤ 1e-6), so e^{−2F} is within 2F·1e-6 relative,
// plus the float output's rounding.
TEST(LidarFogLayered, HardReturnsFollowTheClosedFormOpticalDepth) {
  const double d0 = 0.03, b = 0.12, y0 = 0.5, ys = 1.8;
  const LidarFogParams p = exponential(d0, b, y0, ys);
  const DensityProfile prof = exponential_profile(d0, b, y0, ys);
  const std::vector<double> thetas = {0.0, 0.05, 0.2, 0.6, -0.04, -0.09};
  std::vector<float> in;
  for (double th : thetas) beam(in, th, {0.5, 1.5, 3.0, 7.0, 15.0, 30.0, 60.0, 120.0});
  std::vector<float> out(in.size());
  const LidarFogStats st = lidar_fog(in.data(), out.data(), in.size() / 4, p);
  std::size_t hard = 0;
  for (std::size_t i = 0; i < in.size() / 4; ++i) {
    const float* q = &in[4 * i];
    if (std::memcmp(q, &out[4 * i], 12) != 0) continue;  // a fog return
    ++hard;
    const double r = beam_range(q), s = q[2] / r;
    const double F = prof.F(r, s), want = q[3] * std::exp(-2 * F);
    EXPECT_NEAR(out[4 * i + 3], want, want * 1e-6 * std::max(1.0, 2 * F) + 1e-7 * want) << "R " << r << " s " << s;
  }
  EXPECT_GE(hard, in.size() / 4 * 2 / 3);  // the far level points become fog; most stay hard
  EXPECT_EQ(hard + st.soft, in.size() / 4);
  EXPECT_NEAR(st.origin_height_m, ys, 1e-12);
  EXPECT_NEAR(st.origin_density_per_m, prof.delta(ys), 1e-15);
}

// The same through KITTI's calibration and a camera pose (camera 2 at
// 1.65 m, pitch 2°, roll −1.5°): each point's world height and its beam's
// climb composed here from the calibration's numbers, F in closed form.
TEST(LidarFogLayered, KittiCalibrationAndCameraPosePlaceTheBeams) {
  BRUME_REQUIRE_DATA(kCalib);
  const double d0 = 0.05, b = 0.3, y0 = 0.0, h = 1.65, pitch = 2.0, roll = -1.5;
  LidarFogParams p;
  p.profile = HeightProfile::exponential;
  p.fog.density_per_m = d0;
  p.fog.falloff_per_m = b;
  p.fog.camera.height_m = h;
  p.fog.camera.pitch_deg = pitch;
  p.fog.camera.roll_deg = roll;
  p.pose.kitti_calib = data_path(kCalib);
  p.noise = "off";
  const Calib c = read_calib(data_path(kCalib));
  const double zero[3] = {0, 0, 0};
  const double ys = world_height(in_camera2(c, zero), h, pitch, roll);
  EXPECT_NEAR(ys, 1.73, 0.02);  // KITTI's Velodyne is mounted 1.73 m above the road (camera 2 at 1.65)
  const RigidTransform w = lidar_world_from_scan(p);
  EXPECT_NEAR(w.translation.y, ys, 1e-9);
  const DensityProfile prof = exponential_profile(d0, b, y0, ys);
  std::vector<float> in;
  for (double az : {0.0, 0.8, 2.0, -1.2, 3.0})
    for (double el : {-0.35, -0.1, -0.01, 0.03})
      for (double r : {2.5, 8.0, 21.0, 47.0})
        in.insert(in.end(), {static_cast<float>(r * std::cos(el) * std::cos(az)),
                             static_cast<float>(r * std::cos(el) * std::sin(az)), static_cast<float>(r * std::sin(el)),
                             0.4f});
  std::vector<float> out(in.size());
  lidar_fog(in.data(), out.data(), in.size() / 4, p);
  std::size_t hard = 0;
  for (std::size_t i = 0; i < in.size() / 4; ++i) {
    const float* q = &in[4 * i];
    const double pt[3] = {q[0], q[1], q[2]};
    const double r = beam_range(q);
    const double s = (world_height(in_camera2(c, pt), h, pitch, roll) - ys) / r;
    EXPECT_NEAR((w.rotation * Vec3{pt[0], pt[1], pt[2]}).y / r, s, 1e-9);
    if (std::memcmp(q, &out[4 * i], 12) != 0) continue;
    ++hard;
    const double F = prof.F(r, s), want = q[3] * std::exp(-2 * F);
    EXPECT_NEAR(out[4 * i + 3], want, want * 1e-6 * std::max(1.0, 2 * F) + 1e-7 * want) << i;
  }
  EXPECT_GT(hard, in.size() / 8);
}

// The soft returns against the reference integral with the local density.
// A lidar ratio small enough that every point turns into fog exposes each
// point's cut peak: its intensity is i·P_peak/P_hard,clear(R0), its range the
// peak's. Tolerances as the homogeneous model's (test_lidar_fog.cpp): 2e-4 of
// the power (quadratic interpolation between 1-cm nodes near R1) and 1.5
// table steps in range (node maxima, linear in R0). Exponential fog falling
// steeply with height (B = 0.4/m) on a level, a climbing and a descending
// beam, and a band the climbing beam enters.
TEST(LidarFogLayered, SoftReturnsMatchTheSoftTargetEquationWithTheLocalDensity) {
  struct Case {
    const char* name;
    LidarFogParams p;
    DensityProfile prof;
    double theta;
  };
  const double ys = 1.7;
  std::vector<Case> cases;
  for (double th : {0.0, 0.3, -0.12}) cases.push_back({"exponential", exponential(0.08, 0.4, 0.0, ys),
                                                       exponential_profile(0.08, 0.4, 0.0, ys), th});
  LidarFogParams band = exponential(0.0, 0.0, 0.0, ys);
  band.profile = HeightProfile::band;
  band.fog = HeightMedium{};
  band.fog.density_per_m = 0.15;
  band.fog.band_center_m = 2.5;  // the beam starts inside the band and leaves it 9.3 m out
  band.fog.band_half_width_m = 2.0;
  cases.push_back({"band", band, band_profile(0.15, 2.5, 2.0, ys), 0.3});
  for (Case& c : cases) {
    SCOPED_TRACE(std::string(c.name) + " theta " + std::to_string(c.theta));
    c.p.lidar_ratio_sr = 1e-6;  // unphysical: every point, the nearest too, turns into fog
    std::vector<float> in;
    beam(in, c.theta, {0.95, 1.3, 2.777, 4.2, 6.0, 9.5, 16.0, 25.0});
    std::vector<float> out(in.size());
    const LidarFogStats st = lidar_fog(in.data(), out.data(), in.size() / 4, c.p);
    ASSERT_EQ(st.soft, in.size() / 4);
    const double step = kC * c.p.tau_h_ns * 1e-9 / kLidarStepsPerPulse;
    const LayeredReference ref(c.p, c.prof, ys, in[2] / beam_range(&in[0]));
    for (std::size_t i = 0; i < in.size() / 4; ++i) {
      const double r0 = beam_range(&in[4 * i]);
      SCOPED_TRACE(r0);
      double pp, pr;
      ref.peak(r0, step, pp, pr);
      ASSERT_GT(pp, 0.0);
      const double got = out[4 * i + 3] / in[4 * i + 3] * hard_clear(c.p, r0);
      EXPECT_NEAR(got, pp, 2e-4 * pp);
      EXPECT_NEAR(beam_range(&out[4 * i]), pr, 1.5 * step);
    }
  }
}

// --soft-curve of a layered fog is the level beam's uncut curve from the
// scan's origin: every node within 1e-6 of the peak power of the reference
// (as the homogeneous curve's test), its peak within a step and 1e-4.
TEST(LidarFogLayered, TheLevelBeamsSoftCurveMatchesTheReference) {
  const double ys = 2.5;
  for (double b : {0.0, 0.5}) {
    SCOPED_TRACE(b);
    LidarFogParams p = exponential(0.07, b, 1.0, ys);
    const SoftCurve c = lidar_soft_curve(p, 30.0);
    const LayeredReference ref(p, exponential_profile(0.07, b, 1.0, ys), ys, 0.0);
    ASSERT_GT(c.power_w.size(), 3000u);
    double worst = 0.0;
    for (std::size_t j = 0; j < c.power_w.size(); j += 13)
      worst = std::max(worst, std::abs(c.power_w[j] - ref.power(j * c.step_m)));
    EXPECT_LT(worst, 1e-6 * c.peak_w);
    double pp, pr;
    ref.peak(INFINITY, c.step_m, pp, pr, 30.0);
    EXPECT_NEAR(c.peak_range_m, pr, c.step_m);
    EXPECT_NEAR(c.peak_w, pp, 1e-4 * pp);
  }
}

// The elevation bins: a KITTI scan (or a synthetic one) fogged with bins of
// Δ = 0.1° (the default) and 0.2° against the same points fogged one beam at a time (a bin of one
// beam has its table at the beam's own elevation). The soft peaks differ by
// at most the documented bound
//   |ΔP| ≤ C_A·P0·(2/c)/S·Λ·(Δ/2)·(L/2)·(1/R1 + δ_max)
// (Λ = B·δ_max for the exponential, δ_max over the beams' heights) plus
// 1e-4 of the power for the two tables' own interpolation.
TEST(LidarFogLayered, ElevationBinsStayWithinTheirErrorBound) {
  std::vector<float> in;
  if (have_data(kScan)) {
    in = read_kitti_bin(data_path(kScan), "test");
  } else {
    std::mt19937 g(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int k = 0; k < 20000; ++k) beam(in, (u(g) - 0.9) * 0.45, {1.0 + 60 * u(g) * u(g)}, static_cast<float>(u(g)));
  }
  const double d0 = 0.06, b = 0.25, ys = 1.73;
  for (double step : {0.1, 0.2}) {  // the default and twice it
  SCOPED_TRACE(step);
  LidarFogParams p = exponential(d0, b, 0.0, ys);
  p.elevation_step_deg = step;
  p.lidar_ratio_sr = 1e-4;  // every point with R0 > R1 and i > 0 becomes fog: its intensity is its soft peak
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  const LidarFogStats st = lidar_fog(in.data(), out.data(), n, p);
  const double delta = step * M_PI / 180;
  EXPECT_LE(st.bin_offset_max, delta / 2);
  EXPECT_GT(st.tables, 20u);
  // The densest height a table's beam reaches: the lowest point, less the
  // farthest range times the largest offset of a beam from its table's.
  double rmax = 0.0, zmin = 0.0;
  for (std::size_t i = 0; i < n; ++i) rmax = std::max(rmax, beam_range(&in[4 * i])), zmin = std::min(zmin, double(in[4 * i + 2]));
  const double dmax = d0 * std::exp(-b * (ys + zmin - rmax * st.bin_offset_max));
  const double pulse = kC * 20e-9, k = kC * p.l_r * p.a_r_m2 / 2 * p.p0_w * (2 / kC) / *p.lidar_ratio_sr;
  const double bound = k * (b * dmax) * st.bin_offset_max * (pulse / 2) * (1 / p.r1_m + dmax);
  double worst = 0.0, worst_rel = 0.0;
  std::size_t checked = 0;
  for (std::size_t i = 0; i < n; i += n / 300) {
    const float* q = &in[4 * i];
    const double r0 = beam_range(q);
    if (!(r0 > 1.0 && q[3] > 0.0f)) continue;
    float one[4];
    lidar_fog(q, one, 1, p);
    const double exact = one[3] / q[3] * hard_clear(p, r0), binned = out[4 * i + 3] / q[3] * hard_clear(p, r0);
    EXPECT_LE(std::abs(binned - exact), bound + 1e-4 * exact) << i << " R0 " << r0;
    worst = std::max(worst, std::abs(binned - exact));
    worst_rel = std::max(worst_rel, std::abs(binned - exact) / exact);
    ++checked;
  }
  EXPECT_GT(checked, 150u);
  std::printf("  bins %.1f deg: %zu tables, worst |dP| %.3g W (%.2g relative) against the bound %.3g W\n", step,
              st.tables, worst, worst_rel, bound);
  }
}

// The pose and the bad inputs: a clear Error naming the flags.
TEST(LidarFogLayered, BadInputsAreRefusedNamingTheFlags) {
  const LidarFogParams good = exponential(0.05, 0.1, 0.0, 1.7);
  EXPECT_NO_THROW(validate_lidar_fog(good));
  auto says = [](LidarFogParams p, const std::string& what) {
    const std::string e = error_of([&] { validate_lidar_fog(p); });
    EXPECT_NE(e.find(what), std::string::npos) << "'" << e << "' lacks '" << what << "'";
  };
  LidarFogParams p = good;
  p.alpha_per_m = 0.1;
  says(p, "--profile exponential and --alpha");
  p = good;
  p.visibility_m = 50;
  says(p, "--visibility");
  p = good;
  p.beta_b = 0.001;
  says(p, "--lidar-ratio");
  p = good;
  p.pose.sensor_height_m.reset();
  says(p, "--sensor-height");
  p = good;
  p.pose.sensor_height_m = NAN;
  says(p, "--sensor-height");
  p = good;
  p.fog.camera.pitch_deg = 3.0;  // a camera pose without a calibration
  says(p, "--pitch poses camera 2");
  p = good;
  p.pose.kitti_calib = "calib.txt";
  says(p, "--sensor-height and --kitti-calib");
  p.pose.sensor_height_m.reset();
  says(p, "--camera-height");
  p.fog.camera.height_m = 1.65;
  p.fog.camera.pitch_deg = NAN;
  says(p, "--pitch");
  p = good;
  p.fog.band_center_m = 3.0;  // a band's field with an exponential profile (brume fog's rule)
  says(p, "--band-center");
  p = good;
  p.profile = HeightProfile::constant;
  p.fog.falloff_per_m = HeightMedium{}.falloff_per_m;
  says(p, "--sensor-height");  // a constant profile does not depend on height
  LidarFogParams h;
  h.alpha_per_m = 0.1;
  h.fog.falloff_per_m = 0.2;
  says(h, "--profile");  // a profile's field without a profile
  h.fog = HeightMedium{};
  h.beta_b = 0.001;
  h.lidar_ratio_sr = 30;
  says(h, "--beta-b 0.001 and --lidar-ratio 30");
  EXPECT_NE(error_of([&] { lidar_fog_param_table().set_text(h, "elevation-step", "0"); }).find("--elevation-step"),
            std::string::npos);
  // Files and pose that only the run reads.
  std::vector<float> pts;
  beam(pts, 0.0, {3.0, 9.0});
  std::vector<float> out(pts.size(), -7.0f);
  p = good;
  p.pose.sensor_height_m.reset();
  p.pose.kitti_calib = "/nonexistent/calib.txt";
  p.fog.camera.height_m = 1.65;
  EXPECT_NE(error_of([&] { lidar_fog(pts.data(), out.data(), 2, p); }).find("--kitti-calib '/nonexistent/calib.txt'"),
            std::string::npos);
  EXPECT_EQ(out[0], -7.0f);  // nothing written
  p = good;
  p.profile = HeightProfile::table;
  p.fog = HeightMedium{};
  p.fog.table_file = "/nonexistent/fog.csv";
  EXPECT_NE(error_of([&] { lidar_fog(pts.data(), out.data(), 2, p); }).find("--table"), std::string::npos);
  // A point farther than any LiDAR's return.
  pts[4] = 5e6f;
  EXPECT_NE(error_of([&] { lidar_fog(pts.data(), out.data(), 2, good); }).find("point 1"), std::string::npos);
  // Classic OpenGL fog is no medium: fog's command hands a scan no height medium.
  const CommandDef* fog = find_command("fog");
  ASSERT_TRUE(fog && fog->height_medium);
  EXPECT_EQ(fog->height_medium(fog->build({{"classic", "exp2"}})), nullptr);
  EXPECT_EQ(fog->height_medium(fog->build({{"profile", "constant"}})), nullptr);
  EXPECT_NE(fog->height_medium(fog->build({{"profile", "band"}})), nullptr);
}

// A camera effect's fog becomes the LiDAR's through lidar_params_from_profile:
// the profile, its fields and the camera pose travel (a HeightMedium: nothing
// of the image, airlight or blur); with a constant profile the pose is dropped; the
// extinction the list of commands reports at a height is the fog's.
TEST(LidarFogLayered, ACameraFogBecomesTheLidarsFog) {
  FogParams f;
  f.profile = HeightProfile::ramp;
  f.density_per_m = 0.09;
  f.ramp_bottom_m = 1.0;
  f.ramp_top_m = 12.0;
  f.camera.height_m = 1.65;
  f.camera.pitch_deg = 1.0;
  f.lambda = 3.0;
  f.airlight = Rgb{0.8f, 0.8f, 0.85f};
  LidarFogParams base;
  base.seed = 4;
  base.visibility_m = 100.0;
  const LidarFogParams p = lidar_params_from_profile(f, LidarPose{"calib.txt", std::nullopt}, base);
  EXPECT_EQ(p.profile, HeightProfile::ramp);
  EXPECT_FALSE(p.visibility_m);
  EXPECT_EQ(p.seed, 4u);
  EXPECT_EQ(p.fog.density_per_m, 0.09);
  EXPECT_EQ(p.fog.ramp_top_m, 12.0);
  EXPECT_EQ(p.fog.camera.height_m, 1.65);
  EXPECT_EQ(p.fog.camera.pitch_deg, 1.0);
  EXPECT_EQ(p.pose.kitti_calib, "calib.txt");
  EXPECT_NO_THROW(validate_lidar_fog(p));
  f = FogParams{};  // a camera's constant fog (brume fog refuses a pose and the ramp's fields with it)
  f.profile = HeightProfile::constant;
  f.density_per_m = 0.09;
  const LidarFogParams c = lidar_params_from_profile(f, LidarPose{"calib.txt", std::nullopt}, base);
  EXPECT_TRUE(c.pose.kitti_calib.empty());
  EXPECT_NO_THROW(validate_lidar_fog(c));
  EXPECT_EQ(lidar_fog_medium(c).alpha, 0.09);
  // The list of commands' medium: the ramp's density at a height.
  const CommandDef* lidar = find_command("lidar fog");
  ASSERT_TRUE(lidar && lidar->extinction_per_m);
  const nlohmann::json job = lidar->build({{"profile", "ramp"}, {"density", 0.09}, {"ramp-bottom", 1.0},
                                           {"ramp-top", 12.0}, {"sensor-height", 1.7}});
  EXPECT_NEAR(*lidar->extinction_per_m(job, 0.5), 0.09, 1e-15);
  EXPECT_NEAR(*lidar->extinction_per_m(job, 6.5), 0.045, 1e-15);
  EXPECT_EQ(*lidar->extinction_per_m(job, 20.0), 0.0);
}

// `brume lidar fog --profile` end to end: the record names the profile, the
// pose and its inputs (the calibration and the density table with their
// SHA-256), `brume run` repeats it bit for bit; bad inputs write nothing.
class LidarFogLayeredCli : public ScratchDirTest {};

TEST_F(LidarFogLayeredCli, RunsAndBrumeRunRepeatsIt) {
  BRUME_REQUIRE_DATA(kScan);
  {
    std::ofstream t(p("fog.csv"));
    t << "height_m,density_per_m\n-5,0.12\n0.5,0.1\n3,0.02\n8,0\n";
    std::ifstream a(data_path(kCalib));
    std::ofstream b(p("calib.txt"));
    b << a.rdbuf();
  }
  fs::create_directories(p("first"));
  const std::string args = "lidar fog --points " + data_path(kScan) +
                           " --profile table --table " + p("fog.csv") + " --kitti-calib " + p("calib.txt") +
                           " --camera-height 1.65 --pitch 0.5 --seed 2 --out " + p("first/o.bin") + " --record " +
                           p("first/o.json") + " --soft-curve " + p("first/s.csv");
  const CliRun r = run(args);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("profile table"), std::string::npos) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  const auto& l = rec["lidar"];
  EXPECT_EQ(l["profile"], "table");
  EXPECT_TRUE(l["alpha_per_m"].is_null());
  EXPECT_NEAR(l["origin_height_m"].get<double>(), 1.73, 0.03);
  EXPECT_GT(l["tables"].get<int>(), 50);
  EXPECT_GT(l["soft_points"].get<int>(), 0);
  EXPECT_EQ(rec["job"]["lidar"]["profile"], "table");
  EXPECT_EQ(rec["job"]["camera"]["pitch"], 0.5);
  EXPECT_EQ(rec["inputs"]["kitti_calib"]["path"], p("calib.txt"));
  EXPECT_EQ(rec["inputs"]["fog_table"]["path"], p("fog.csv"));
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  for (const char* f : {"o.bin", "s.csv"}) {
    const std::string a = file_bytes(p(std::string("first/") + f)), b = file_bytes(p(std::string("again/") + f));
    EXPECT_TRUE(!a.empty() && a == b) << f;
  }
  // A changed calibration: brume run refuses the record.
  {
    std::ofstream b(p("calib.txt"), std::ios::app);
    b << "\n";
  }
  const CliRun changed = run("run " + p("first/o.json") + " --out-dir " + p("third"));
  EXPECT_NE(changed.status, 0);
  EXPECT_NE(changed.output.find("calib.txt"), std::string::npos) << changed.output;
}

TEST_F(LidarFogLayeredCli, BadInputsWriteNothing) {
  std::vector<float> pts;
  beam(pts, 0.0, {2.0, 5.0, 9.0, 30.0});
  {
    std::ofstream f(p("in.bin"), std::ios::binary);
    f << kitti_bin_bytes(pts.data(), pts.size() / 4);
  }
  const std::string tail = " --points " + p("in.bin") + " --out " + p("o.bin") + " --record " + p("o.json") +
                           " --soft-curve " + p("s.csv");
  struct Case {
    std::string args, says;
  };
  for (const Case& c :
       {Case{"--profile exponential --sensor-height 1.7 --alpha 0.1", "--profile exponential and --alpha"},
        Case{"--profile band --band-center 2 --sensor-height 1.7 --visibility 80", "--visibility"},
        Case{"--profile exponential --kitti-calib " + p("missing.txt") + " --camera-height 1.6", "--kitti-calib"},
        Case{"--profile exponential --sensor-height nan", "--sensor-height"},
        Case{"--profile exponential --kitti-calib " + p("missing.txt") + " --camera-height 1.6 --roll nan", "--roll"},
        Case{"--profile exponential", "--sensor-height"},
        Case{"--profile exponential --sensor-height 1.7 --beta-b 0.01", "--lidar-ratio"},
        Case{"--alpha 0.1 --falloff 0.2", "--profile"}}) {
    SCOPED_TRACE(c.args);
    const CliRun r = run("lidar fog " + c.args + tail);
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find(c.says), std::string::npos) << r.output;
    for (const char* f : {"o.bin", "o.json", "s.csv"}) EXPECT_FALSE(fs::exists(p(f))) << f;
  }
}
