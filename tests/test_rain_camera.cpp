// Rain on a camera's image (brume/rain.hpp, issue #56's camera part): σ_cam against the LiDAR's
// σ and Q_eff's fit, streak lengths and coverage against the drops of the field enumerated here
// (written again from the header's equations), the energy a rain adds against the exposure, its
// fluctuation's T^−½ law, the depth test, drawn + analytic transmittance against e^{−σr}, and
// `brume rain` with `brume run` of its record (KITTI 000001 when the data is present).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/rain.hpp"
#include "effects/rain/rain_internal.hpp"
#include "streak_scene.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace rain_camera_tests {

constexpr double kPi = 3.14159265358979323846;

CameraRainParams params(double rate, double exposure_s, std::uint64_t seed) {
  CameraRainParams p;
  p.drops.rate_mm_h = rate;
  p.exposure_s = exposure_s;
  p.seed = seed;
  return p;
}


// σ_cam is Q_eff/2 of the LiDAR's σ, bit for bit (the same ∫D²N), at the rates; Q_eff's
// default is the least-squares fit in ln V of 3.912/σ_cam to the visibility code's rain rows.
TEST(CameraRain, ExtinctionIsHalfQeffOfTheLidarsBitForBit) {
  for (double r : {1.0, 5.0, 25.0, 100.0})
    for (double q : {kCameraRainQEff, 1.0, 2.0}) {
      EXPECT_EQ(camera_rain_extinction_per_m(r, q), q / 2.0 * rain_extinction_per_m(r, kLidarRainQ)) << r << " " << q;
      // The recorded σ is the same double.
      const CameraRainParams p = [&] {
        CameraRainParams x = params(r, 1.0 / 60, 0);
        x.q_eff = q;
        return x;
      }();
      Intrinsics k;
      k.fx = k.fy = 500;
      k.cx = k.cy = 10;
      EXPECT_EQ(CameraRainOptics(p, k, 0.0).sigma_cam(), camera_rain_extinction_per_m(r, q));
    }
  // The fit, written again: ln Q = mean(ln(2·3.912/σ_lidar(R)) − ln V(R)).
  const double rows[4][2] = {{2.5, 5900.0}, {12.5, 2800.0}, {25.0, 1900.0}, {100.0, 770.0}};
  double s = 0.0;
  for (const auto& row : rows) {
    const double l = 4.1 * std::pow(row[0], -0.21), sigma = kPi * 8000.0 / (l * l * l) * 1e-6;
    s += std::log(2.0 * 3.912 / sigma) - std::log(row[1]);
  }
  EXPECT_NEAR(kCameraRainQEff, std::exp(s / 4.0), 0.005);
}

// ∫D²N between two diameters against Simpson's rule (20 000 intervals: 1e−12 relative).
TEST(CameraRain, PartialMomentIsTheIntegral) {
  for (double r : {1.0, 25.0, 100.0}) {
    const double l = 4.1 * std::pow(r, -0.21);
    const double a = 0.3, b = 6.0;
    const int m = 20000;
    const double h = (b - a) / m;
    double s = 0.0;
    for (int i = 0; i <= m; ++i) {
      const double d = a + i * h, f = d * d * 8000.0 * std::exp(-l * d);
      s += (i == 0 || i == m) ? f : (i % 2 ? 4 * f : 2 * f);
    }
    EXPECT_NEAR(rain_d2_between(r, a, b), s * h / 3.0, 1e-10 * s * h / 3.0);
  }
}

// Streak length and coverage on the drops of one cell layer (z in [4, 4.125) m), enumerated here
// from the field: each isolated streak is a vertical line of length fy·v(D)·T/z (the fall alone),
// measured as √(12·(var_v − 1/6)) of its coverage (a uniform segment's variance L²/12, plus the
// bilinear splat's 1/6), within 0.5 px; its coverage sums to (π/4)D²fx·fy·r/z³ within 1 %.
TEST(CameraRain, StreakLengthIsFallTimesExposureOverDepth) {
  const int W = 240, H = 240;
  const double f = 1000.0, T = 1.0 / 60;
  const Flat fl = flat(W, H, f, 1.0f, 1000.0);
  CameraRainParams p = params(25.0, T, 11);
  p.z_near_m = 4.0, p.z_split_m = 4.125, p.epsilon = 0.0, p.drops.drop_min_mm = 1.0;
  const Image out = render_camera_rain(scene_of(fl, false, {0, 0, 0}), p, two_threads());
  // Each thread owns a band of rows and the drops keep one order: the image is the same on one thread.
  Exec one;
  one.threads = 1;
  const Image single = render_camera_rain(scene_of(fl, false, {0, 0, 0}), p, one);
  ASSERT_EQ(std::memcmp(out.data.data(), single.data.data(), out.data.size() * sizeof(float)), 0);
  // The drops, written again: cv = (−y, −z, x) of the field's (x forward, y left, z up).
  const RainField field(25.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  struct D {
    double u, v, len, mass;
  };
  std::vector<D> drops;
  std::vector<RainDrop> cell;
  for (std::int64_t iy = -8; iy <= 8; ++iy)
    for (std::int64_t iz = -8; iz <= 8; ++iz) {
      cell.clear();
      field.cell_drops({32, iy, iz}, 0.0, cell);
      for (const RainDrop& d : cell) {
        const double x = -d.at.y, y = -d.at.z, z = d.at.x, r = std::sqrt(x * x + y * y + z * z);
        const double dm = d.d_mm * 1e-3;
        drops.push_back({f * x / z + fl.k.cx, f * y / z + fl.k.cy, f * atlas_terminal_velocity_m_per_s(d.d_mm) * T / z,
                         kPi / 4 * dm * dm * f * f * r / (z * z * z)});
      }
    }
  int checked = 0;
  for (std::size_t i = 0; i < drops.size(); ++i) {
    const D& d = drops[i];
    const int x0 = static_cast<int>(d.u) - 4, x1 = static_cast<int>(d.u) + 5;
    const int y0 = static_cast<int>(d.v - d.len / 2) - 4, y1 = static_cast<int>(d.v + d.len / 2) + 5;
    if (x0 < 0 || y0 < 0 || x1 >= W || y1 >= H) continue;
    bool alone = true;
    for (std::size_t j = 0; j < drops.size() && alone; ++j)
      if (j != i && std::abs(drops[j].u - d.u) < 10 && std::abs(drops[j].v - d.v) < (drops[j].len + d.len) / 2 + 10)
        alone = false;
    if (!alone) continue;
    double s = 0.0, sv = 0.0, svv = 0.0;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const double a = 1.0 - out.at(x, y, 0);  // one streak: 1 − (1 − α) = α
        s += a, sv += a * y, svv += a * y * y;
      }
    const double mean = sv / s, var = svv / s - mean * mean;
    EXPECT_NEAR(std::sqrt(12.0 * (var - 1.0 / 6.0)), d.len, 0.5) << "drop " << i;
    EXPECT_NEAR(s, d.mass, 0.01 * d.mass) << "drop " << i;  // a fall keeps r and z: the area is constant
    ++checked;
  }
  EXPECT_GE(checked, 5) << drops.size() << " drops";
}

// The energy the rain adds, Σ(I − I_bg), does not depend on T (mean of 8 seeds, within 1 %): the
// same drops (the seed's) for every T, falling from 2 to 10 m; only the drops whose streaks cross
// the frame's top and bottom differ.
TEST(CameraRain, EnergyIsIndependentOfExposure) {
  const int W = 320, H = 200;
  const Flat fl = flat(W, H, 500.0, 0.0f, 1000.0);
  const double ts[5] = {0.008, 0.016, 0.033, 0.066, 0.125};
  double energy[5] = {0, 0, 0, 0, 0};
  for (std::uint64_t seed = 1; seed <= 8; ++seed)
    for (int k = 0; k < 5; ++k) {
      CameraRainParams p = params(25.0, ts[k], seed);
      p.z_near_m = 2.0, p.z_split_m = 10.0, p.epsilon = 0.0, p.drops.drop_min_mm = 0.5;
      const Image out = render_camera_rain(scene_of(fl, false, {1, 1, 1}), p, two_threads());
      double s = 0.0;
      for (int i = 0; i < W * H; ++i) s += out.data[3 * static_cast<std::size_t>(i)];
      energy[k] += s / 8.0;
    }
  for (int k = 0; k < 5; ++k) EXPECT_NEAR(energy[k] / energy[2], 1.0, 0.01) << "T = " << ts[k];
}

// The fluctuation's standard deviation over a flat background goes as T^−½ (mean variance of 8
// seeds, within 5 %), for T in {8, 16, 33, 66, 125} ms: drops of 0.5 mm and more from 1 to 4 m,
// a wind of 20 m/s across the view (so that every streak is long against the splat: 40 px and
// more), every drop drawn (ε = 0).
TEST(CameraRain, FluctuationGoesAsTheInverseRootOfExposure) {
  const int W = 160, H = 120;
  const Flat fl = flat(W, H, 1000.0, 0.0f, 1000.0);
  const double ts[5] = {0.008, 0.016, 0.033, 0.066, 0.125};
  double var[5] = {0, 0, 0, 0, 0};
  for (std::uint64_t seed = 1; seed <= 8; ++seed)
    for (int k = 0; k < 5; ++k) {
      CameraRainParams p = params(25.0, ts[k], seed);
      p.z_near_m = 1.0, p.z_split_m = 4.0, p.epsilon = 0.0, p.drops.drop_min_mm = 0.5, p.wind = "0,20,0";
      const Image out = render_camera_rain(scene_of(fl, false, {1, 1, 1}), p, two_threads());
      double s = 0.0, ss = 0.0;
      for (int i = 0; i < W * H; ++i) {
        const double a = out.data[3 * static_cast<std::size_t>(i)];
        s += a, ss += a * a;
      }
      const double m = s / (W * H);
      var[k] += (ss / (W * H) - m * m) / 8.0;
    }
  for (int k = 0; k < 5; ++k)
    EXPECT_NEAR(std::sqrt(var[k] * ts[k]) / std::sqrt(var[2] * ts[2]), 1.0, 0.05) << "T = " << ts[k];
}

// A wall at 2 m (planar depth) over the left half hides every drop behind it: there the streaks
// are those of the same seed drawn up to z_split = 2 m. Tolerances: a splat's bilinear footprint
// reaches the neighbouring pixel, whose ray meets the wall up to 0.2 % farther here (the
// anti-aliasing at depth edges), so nothing beyond 2.02 m may show; the 1 % softness in front of
// the wall takes at most 1 % of the coverage.
TEST(CameraRain, AWallHidesTheDropsBehindIt) {
  const int W = 200, H = 150;
  Flat wall = flat(W, H, 300.0, 1.0f, 1000.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) {
      const double a = (x - wall.k.cx) / 300.0, b = (y - wall.k.cy) / 300.0;
      wall.range.at(x, y) = static_cast<float>(2.0 * std::sqrt(1 + a * a + b * b));
    }
  const Flat far = flat(W, H, 300.0, 1.0f, 1000.0);
  CameraRainParams p = params(100.0, 1.0 / 60, 5);
  p.epsilon = 0.0, p.drops.drop_min_mm = 0.3, p.z_split_m = 8.0;
  const Image with = render_camera_rain(scene_of(wall, false, {0, 0, 0}), p, two_threads());
  const Image open = render_camera_rain(scene_of(far, false, {0, 0, 0}), p, two_threads());
  p.z_split_m = 2.0;
  const Image near = render_camera_rain(scene_of(far, false, {0, 0, 0}), p, two_threads());
  p.z_split_m = 2.02;
  const Image slack = render_camera_rain(scene_of(far, false, {0, 0, 0}), p, two_threads());
  double a_with = 0.0, a_near = 0.0, a_open = 0.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) {
      const double aw = 1.0 - with.at(x, y, 0);
      EXPECT_LE(aw, 1.0 - slack.at(x, y, 0) + 1e-6) << x << "," << y;
      a_with += aw, a_near += 1.0 - near.at(x, y, 0), a_open += 1.0 - open.at(x, y, 0);
    }
  EXPECT_GT(a_near, 0.0);
  EXPECT_NEAR(a_with / a_near, 1.0, 0.01);
  EXPECT_GT(a_open, 1.2 * a_near);  // the drops beyond 2 m are many: the wall hides something
  // The right half (but for the splats at the edge) is the open scene's.
  for (int y = 0; y < H; ++y)
    for (int x = W / 2 + 8; x < W; ++x) ASSERT_EQ(with.at(x, y, 0), open.at(x, y, 0)) << x << "," << y;
}

// Drawn + analytic transmittance is e^{−σ_cam·r} in expectation: a white scene at range r, black
// drops, no airlight; the image's mean over 4 seeds within 1 % at r = 10, 50 and 200 m (z_split
// 20 m: 10 m is mostly drawn, 50 and 200 m mostly analytic), at the default thinning.
TEST(CameraRain, DrawnAndAnalyticTransmittanceIsBeerLambert) {
  const int W = 240, H = 120;
  for (double r : {10.0, 50.0, 200.0}) {
    Flat fl = flat(W, H, 250.0, 1.0f, r);
    double mean = 0.0;
    for (std::uint64_t seed = 1; seed <= 4; ++seed) {
      const CameraRainParams p = params(100.0, 1.0 / 60, seed);
      const Image out = render_camera_rain(scene_of(fl, true, {0, 0, 0}), p, two_threads());
      double s = 0.0;
      for (int i = 0; i < W * H; ++i) s += out.data[3 * static_cast<std::size_t>(i)];
      mean += s / (W * H) / 4.0;
    }
    const double expect = std::exp(-camera_rain_extinction_per_m(100.0) * r);
    EXPECT_NEAR(mean / expect, 1.0, 0.01) << "r = " << r;
  }
}

TEST(CameraRain, BadParametersAreRefused) {
  CameraRainParams p;
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--rate"), std::string::npos);
  p.drops.rate_mm_h = 5.0;
  p.wind = "1,2";
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--wind"), std::string::npos);
  p.wind = "1,x,3";
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--wind"), std::string::npos);
  p.wind = "0,0,0";
  p.f_number = 2.8;
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--focus-distance"), std::string::npos);
  p.f_number.reset();
  p.z_split_m = 0.1;
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--z-split"), std::string::npos);
}

// ---- frames of a sequence (--frame, --frame-interval, --poses) --------------------------------

// The frames' scene: a flat grey scene of 96 x 64 px, f = 60 px, at 40 m.
Flat frames_scene() { return flat(96, 64, 60.0, 0.3f, 40.0); }
CameraRainParams frames_params() {
  CameraRainParams p = params(40.0, 1.0 / 60.0, 5);
  p.wind = "1,-2,0.5", p.ego_speed_m_s = 8.0, p.z_split_m = 8.0;
  return p;
}

// Frame 0 (its flags' defaults, and --frame 0 given) is today's image bit for bit: the fingerprint
// main's library (fbf627f, before the frames) gives for this scene, wind and ego speed.
TEST(CameraRainFrames, FrameZeroIsTodaysImage) {
  const Flat fl = frames_scene();
  CameraRainParams p = frames_params();
  EXPECT_EQ(fingerprint(render_camera_rain(scene_of(fl, true), p, two_threads())), 0x9c975f190cb1b4ddull);
  p.frame = 0, p.frame_interval_s = 0.05;
  EXPECT_EQ(fingerprint(render_camera_rain(scene_of(fl, true), p, two_threads())), 0x9c975f190cb1b4ddull);
}

// Frames 1 and 2 are other images, each the same on one thread and on two (the moving pass's
// order does not depend on the threads).
TEST(CameraRainFrames, FramesDifferAndAreDeterministic) {
  const Flat fl = frames_scene();
  CameraRainParams p = frames_params();
  const auto h = frame_fingerprints([&](std::uint64_t k, const Exec& e) {
    p.frame = k;
    return render_camera_rain(scene_of(fl, true), p, e);
  });
  EXPECT_EQ(h[0], 0x9c975f190cb1b4ddull);
  EXPECT_NE(h[1], 0u);
  EXPECT_NE(h[2], 0u);
  EXPECT_NE(h[1], h[0]);
  EXPECT_NE(h[2], h[1]);
  EXPECT_NE(h[2], h[0]);
}

// A drawn drop: its mid-exposure centre in the field's axes at the camera (x forward, y left, z
// up), its diameter (from the streak's area, (π/4)·D²·fx·fy) and its cv velocity.
struct Drawn {
  Vec3 at;
  double d_mm;
  double u[3];
};
std::vector<Drawn> drawn_drops(const CameraRainScene& s, const CameraRainParams& p) {
  StreakSlabs slabs;
  (void)render_camera_rain_drawn(s, p, two_threads(), nullptr, nullptr, &slabs);
  std::vector<Drawn> out;
  for (const std::vector<Streak>& slab : slabs)
    for (const Streak& k : slab)
      out.push_back({{k.c[2], -k.c[0], -k.c[1]}, std::sqrt(k.area / (kPi / 4.0 * s.k.fx * s.k.fy)) * 1e3,
                     {k.u[0], k.u[1], k.u[2]}});
  return out;
}
// The drawn drop at `at` within `tol` [m] (null: none).
const Drawn* find_drop(const std::vector<Drawn>& drops, const Vec3& at, double tol) {
  for (const Drawn& d : drops)
    if (std::abs(d.at.x - at.x) <= tol && std::abs(d.at.y - at.y) <= tol && std::abs(d.at.z - at.z) <= tol) return &d;
  return nullptr;
}

// Every drop of `field` whose place at t (rain_drop_at: the scan's closed form) can lie over the
// landing box [x0, x1] × [y0, y1] [m], as f(place, D): the cells under the box shifted back by the
// wind's drift, over the whole of the layer's height (every source a wrapped fall can come from).
template <class F>
void for_each_field_drop_at(const RainField& field, double d_min_mm, double t, const Vec3& wind, double x0, double x1,
                            double y0, double y1, F&& f) {
  const double c = kRainCellM;
  const auto cell_of = [c](double v) { return static_cast<std::int64_t>(std::floor(v / c)); };
  std::vector<RainDrop> cell;
  for (std::int64_t ix = cell_of(x0 - wind.x * t); ix <= cell_of(x1 - wind.x * t); ++ix)
    for (std::int64_t iy = cell_of(y0 - wind.y * t); iy <= cell_of(y1 - wind.y * t); ++iy)
      for (std::int64_t iz = cell_of(kRainLayerBaseM); iz < cell_of(kRainLayerBaseM + kRainLayerM); ++iz) {
        cell.clear();
        field.cell_drops({ix, iy, iz}, d_min_mm, cell);
        for (const RainDrop& d : cell) f(rain_drop_at(d.at, d.d_mm, t, wind), d.d_mm);
      }
}

// The key test: at frame K the camera draws the scan's drops. The field is enumerated here cell by
// cell over the whole of a layer's height (every source a wrapped fall can come from), each drop
// moved by rain_drop_at (the scan's closed form) and taken to the camera at x = s·t: every drop the
// camera draws is one of these (the same place within 1e-9 m: the same closed form and the same
// subtraction, exact but for the order of a sum; the same diameter within 1e-9 relative: from the
// streak's area), and every one of these whose centre projects at least a pixel inside the image,
// at planar depth [z_near, z_split) and above the thinning's D_t there, is drawn. Frame 3 (0.3 s:
// no drop wraps) and frame 200 (20 s: every drop has wrapped several times). Then the scan: beams
// aimed at large drawn drops (D >= 2.5 mm, 2.5-4 m away) of a scan at the same frame, wind and ego
// speed (brume lidar rain's LidarRainParams) report them at their range (within 1e-4 m: float32
// points).
TEST(CameraRainFrames, TheCamerasDropsAtFrameKAreTheScans) {
  const Flat fl = flat(64, 48, 60.0, 0.3f, 1000.0);
  CameraRainParams p = params(40.0, 1.0 / 60.0, 5);
  p.drops.drop_min_mm = 2.0;  // a few drops a cubic metre: the field is enumerated here whole
  p.wind = "1,-2,0.5", p.ego_speed_m_s = 8.0, p.z_split_m = 4.0;
  const Vec3 wind{1.0, -2.0, 0.5};
  const CameraRainOptics optics(p, fl.k, 0.0);
  for (const std::uint64_t K : {std::uint64_t{3}, std::uint64_t{200}}) {
    p.frame = K;
    const double t = static_cast<double>(K) * p.frame_interval_s, ox = p.ego_speed_m_s * t;
    const std::vector<Drawn> cam = drawn_drops(scene_of(fl, false, {1, 1, 1}), p);
    ASSERT_GT(cam.size(), 50u) << "frame " << K;
    const RainField field(40.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
    std::size_t expected = 0, matched = 0;
    std::vector<char> used(cam.size(), 0);
    for_each_field_drop_at(field, p.drops.drop_min_mm, t, wind, ox - 1.0, ox + 5.0, -4.5, 4.5,
                           [&](const Vec3& w, double d_mm) {
      const Vec3 q{w.x - ox, w.y, w.z};
      if (!(q.x >= p.z_near_m && q.x < p.z_split_m) || d_mm < optics.threshold_mm(q.x)) return;
      const double u = fl.k.fx * -q.y / q.x + fl.k.cx, v = fl.k.fy * -q.z / q.x + fl.k.cy;
      const bool inside = u >= 0.5 && u <= 64 - 1.5 && v >= 0.5 && v <= 48 - 1.5;
      const Drawn* got = find_drop(cam, q, 1e-9);
      if (got) {
        ++matched;
        used[static_cast<std::size_t>(got - cam.data())] = 1;
        EXPECT_NEAR(got->d_mm, d_mm, 1e-9 * d_mm);
        // Its motion: fall, wind and the camera's speed, in the cv frame.
        const double uu[3] = {-wind.y, atlas_terminal_velocity_m_per_s(d_mm) - wind.z, wind.x - p.ego_speed_m_s};
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(got->u[a], uu[a], 1e-12);
      }
      if (inside) {
        ++expected;
        EXPECT_TRUE(got) << "frame " << K << ": the field's drop at " << q.x << ", " << q.y << ", " << q.z << " (D "
                         << d_mm << " mm, pixel " << u << ", " << v << ") is not drawn";
      }
    });
    EXPECT_GT(expected, 30u);
    for (std::size_t i = 0; i < cam.size(); ++i)
      EXPECT_TRUE(used[i]) << "frame " << K << ": a drawn drop at " << cam[i].at.x << ", " << cam[i].at.y << ", "
                           << cam[i].at.z << " is none of the field's";
    EXPECT_EQ(matched, cam.size());

    // The scan at the same frame: beams at the large drawn drops, a faint target 3 m beyond each.
    LidarRainParams lp;
    lp.drops = p.drops, lp.seed = p.seed, lp.wind = p.wind, lp.ego_speed_m_s = p.ego_speed_m_s, lp.frame = K;
    std::vector<float> pts;
    std::vector<double> range;
    for (const Drawn& d : cam) {
      const double r = std::sqrt(d.at.x * d.at.x + d.at.y * d.at.y + d.at.z * d.at.z);
      if (d.d_mm < 2.5 || r < 2.5 || r > 4.0) continue;
      const double k = (r + 3.0) / r;
      pts.insert(pts.end(), {static_cast<float>(d.at.x * k), static_cast<float>(d.at.y * k),
                             static_cast<float>(d.at.z * k), 0.02f});
      range.push_back(r);
    }
    ASSERT_GE(range.size(), 3u) << "frame " << K;
    std::vector<float> out(pts.size());
    std::vector<std::uint8_t> labels(range.size());
    (void)lidar_rain(pts.data(), out.data(), range.size(), lp, labels.data());
    std::size_t at = 0;
    for (std::size_t i = 0; i < range.size(); ++i) {
      if (labels[i] == 2) continue;  // lost
      const float* q = &out[4 * at++];
      EXPECT_EQ(labels[i], 1) << "frame " << K << ": the beam at drop " << i << " reports its target";
      EXPECT_NEAR(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]), range[i], 1e-4) << "frame " << K;
    }
  }
}

// A turning camera (--poses: camera 0 yawed 30° and pitched 4° at frame 2, moved 1.5 m; the
// calibration's camera 2 at camera 0, so that its pose is the line's): the drops it draws are the
// field's moved by rain_drop_at and taken into its axes here (cv: R^T·(x − t), written again from
// KITTI's convention, not the library's composition), both ways as in the test above, within 1e-9 m
// (a rotation's rounding, ~1e-15 m at these distances).
TEST(CameraRainFrames, ATurningCameraDrawsTheFieldInItsAxes) {
  const fs::path dir = fs::temp_directory_path() / ("brume_rain_turn_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string calib = (dir / "calib.txt").string(), poses = (dir / "poses.txt").string();
  const double yaw = 30.0 * kPi / 180.0, pitch = 4.0 * kPi / 180.0;
  // R = R_y(yaw)·R_x(pitch) in the cv frame (y down: a yaw about y turns the view to the right).
  const double cy_ = std::cos(yaw), sy_ = std::sin(yaw), cp = std::cos(pitch), sp = std::sin(pitch);
  const double R[3][3] = {{cy_, sy_ * sp, sy_ * cp}, {0.0, cp, -sp}, {-sy_, cy_ * sp, cy_ * cp}};
  const double T[3] = {0.4, -0.1, 1.5};
  {
    std::ofstream f(calib);
    f << "P2: 60 0 31.5 0 0 60 23.5 0 0 0 1 0\nR0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";
    std::ofstream g(poses);
    g.precision(17);
    g << "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0.7\n";
    for (int k = 2; k < 4; ++k) {
      for (int i = 0; i < 3; ++i) g << R[i][0] << " " << R[i][1] << " " << R[i][2] << " " << T[i] * (k - 1) << " ";
      g << "\n";
    }
  }
  const Flat fl = flat(64, 48, 60.0, 0.3f, 1000.0);
  CameraRainParams p = params(40.0, 1.0 / 60.0, 5);
  p.drops.drop_min_mm = 2.5, p.wind = "1,-2,0.5", p.z_split_m = 4.0, p.frame = 2, p.poses = poses;
  CameraRainScene s = scene_of(fl, false, {1, 1, 1});
  s.kitti_calib = calib;
  const std::vector<Drawn> cam = drawn_drops(s, p);
  ASSERT_GT(cam.size(), 20u);
  const Vec3 wind{1.0, -2.0, 0.5};
  const double t = 0.2;
  const CameraRainOptics optics(p, fl.k, 0.0);
  const RainField field(40.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  std::vector<char> used(cam.size(), 0);
  std::size_t expected = 0;
  // The camera's centre in the field's axes: (z, −x, −y) of T.
  const double ox = T[2], oy = -T[0], reach = 6.0;
  for_each_field_drop_at(field, p.drops.drop_min_mm, t, wind, ox - reach, ox + reach, oy - reach, oy + reach,
                         [&](const Vec3& w, double d_mm) {
    const double x[3] = {-w.y - T[0], -w.z - T[1], w.x - T[2]};  // cv, less the camera's centre
    double v[3];
    for (int i = 0; i < 3; ++i) v[i] = R[0][i] * x[0] + R[1][i] * x[1] + R[2][i] * x[2];  // R^T·x
    const Vec3 q{v[2], -v[0], -v[1]};
    if (!(q.x >= p.z_near_m && q.x < p.z_split_m) || d_mm < optics.threshold_mm(q.x)) return;
    const double u = 60.0 * v[0] / v[2] + fl.k.cx, vv = 60.0 * v[1] / v[2] + fl.k.cy;
    const Drawn* got = find_drop(cam, q, 1e-9);
    if (got) used[static_cast<std::size_t>(got - cam.data())] = 1;
    if (u >= 0.5 && u <= 62.5 && vv >= 0.5 && vv <= 46.5) {
      ++expected;
      EXPECT_TRUE(got) << "the field's drop at " << q.x << ", " << q.y << ", " << q.z << " is not drawn";
    }
  });
  EXPECT_GT(expected, 20u);
  for (std::size_t i = 0; i < cam.size(); ++i)
    EXPECT_TRUE(used[i]) << "a drawn drop at " << cam[i].at.x << ", " << cam[i].at.y << ", " << cam[i].at.z
                         << " is none of the field's";
  fs::remove_all(dir);
}

// --ego-speed s moves the field back past the camera by s·t: at frame 4 every drop drawn at speed 8
// is one drawn at speed 0 moved by (−s·t, 0, 0) (within 1e-9 m), wherever that one is in the
// picture (a pixel inside, before z_split, above the thinning's D_t), and it comes at the camera s
// faster.
TEST(CameraRainFrames, EgoSpeedMovesTheFieldBackBySpeedTimesTime) {
  const Flat fl = flat(64, 48, 60.0, 0.3f, 1000.0);
  CameraRainParams p = params(40.0, 1.0 / 60.0, 7);
  p.drops.drop_min_mm = 2.0, p.wind = "0.5,1,0", p.z_split_m = 8.0, p.frame = 4, p.epsilon = 0.0;  // every drop drawn
  const std::vector<Drawn> still = drawn_drops(scene_of(fl, false, {1, 1, 1}), p);
  p.ego_speed_m_s = 8.0;
  const std::vector<Drawn> moving = drawn_drops(scene_of(fl, false, {1, 1, 1}), p);
  const double st = 8.0 * 0.4;
  const CameraRainOptics optics(p, fl.k, 0.0);
  std::size_t checked = 0;
  for (const Drawn& d : moving) {
    const Vec3 q{d.at.x + st, d.at.y, d.at.z};  // where the camera standing still sees it
    if (!(q.x < p.z_split_m) || d.d_mm < optics.threshold_mm(q.x)) continue;
    const double u = fl.k.fx * -q.y / q.x + fl.k.cx, v = fl.k.fy * -q.z / q.x + fl.k.cy;
    if (!(u >= 0.5 && u <= 62.5 && v >= 0.5 && v <= 46.5)) continue;
    ++checked;
    const Drawn* got = find_drop(still, q, 1e-9);
    ASSERT_TRUE(got) << "the drop at " << d.at.x << " m is not drawn " << st << " m farther without the ego speed";
    EXPECT_NEAR(d.u[2], got->u[2] - 8.0, 1e-12);
  }
  EXPECT_GT(checked, 30u);
}

// A KITTI poses file of a pure translation along camera 0's forward axis, s·Δt a line, places the
// camera as --ego-speed s does: the same drops (within 1e-9 m: camera 2's offset from the
// calibration is added and taken off again), the same motion, the same image within 1e-5.
TEST(CameraRainFrames, PosesOfAPureTranslationAreTheEgoSpeed) {
  const fs::path dir = fs::temp_directory_path() / ("brume_rain_poses_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string calib = (dir / "calib.txt").string(), poses = (dir / "poses.txt").string();
  {
    std::ofstream f(calib);
    f << "P2: 60 0 31.5 3.6 0 60 23.5 0.3 0 0 1 0.004\nR0_rect: 1 0 0 0 1 0 0 0 1\n"
         "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27\n";
    std::ofstream g(poses);
    for (int k = 0; k < 6; ++k) g << "1 0 0 0 0 1 0 0 0 0 1 " << 0.8 * k << "\n";
  }
  const Flat fl = flat(64, 48, 60.0, 0.3f, 1000.0);
  CameraRainParams p = params(40.0, 1.0 / 60.0, 3);
  p.drops.drop_min_mm = 1.5, p.wind = "0.5,1,0.2", p.z_split_m = 6.0, p.frame = 3;
  p.ego_speed_m_s = 8.0;
  const std::vector<Drawn> ego = drawn_drops(scene_of(fl, false, {1, 1, 1}), p);
  const Image ego_img = render_camera_rain(scene_of(fl, false, {1, 1, 1}), p, two_threads());
  p.ego_speed_m_s = 0.0, p.poses = poses;
  CameraRainScene s = scene_of(fl, false, {1, 1, 1});
  s.kitti_calib = calib;
  const std::vector<Drawn> posed = drawn_drops(s, p);
  const Image posed_img = render_camera_rain(s, p, two_threads());
  ASSERT_GT(ego.size(), 30u);
  EXPECT_EQ(posed.size(), ego.size());
  for (const Drawn& d : ego) {
    const Drawn* got = find_drop(posed, d.at, 1e-9);
    ASSERT_TRUE(got) << "the drop at " << d.at.x << ", " << d.at.y << ", " << d.at.z;
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(got->u[a], d.u[a], 1e-9);
  }
  ASSERT_EQ(posed_img.data.size(), ego_img.data.size());
  for (std::size_t i = 0; i < ego_img.data.size(); ++i) ASSERT_NEAR(posed_img.data[i], ego_img.data[i], 1e-5f) << i;
  fs::remove_all(dir);
}

class CameraRainCli : public ScratchDirTest {};

// `brume rain` from files, and `brume run` of its record: the same image bit for bit. Rate 0
// without --visibility gives the image back.
TEST_F(CameraRainCli, RunsAndBrumeRunRepeatsIt) {
  const Scene s = scene(96, 64, 12);
  write_image(p("in.exr"), s.rgb, WriteOptions{});
  write_image(p("range.exr"), s.range, WriteOptions{});
  fs::create_directories(p("first"));
  const std::string in = " --image " + p("in.exr") + " --range " + p("range.exr") + " --fx 80 ";
  const CliRun r = run("rain" + in + "--rate 25 --rain-seed 4 --wind 0,2,0 --ego-speed 10 --visibility 300 --out " +
                       p("first/o.exr") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["command"], "rain");
  EXPECT_EQ(rec["job"]["rain"]["rain-seed"], 4);
  for (const char* k : {"seed", "z_split_m", "epsilon", "q_eff", "drop_min_mm", "drop_max_mm", "exposure_s"})
    EXPECT_TRUE(rec["rain"].contains(k)) << k;
  EXPECT_EQ(rec["rain"]["extinction_per_m"].get<double>(), camera_rain_extinction_per_m(25.0));
  EXPECT_GT(rec["rain"]["drops_drawn"].get<std::size_t>(), 0u);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.exr"), p("again/o.exr"));
  const CliRun zero = run("rain" + in + "--rate 0 --out " + p("zero.exr"));
  ASSERT_EQ(zero.status, 0) << zero.output;
  const Image z = read_color(p("zero.exr"));
  ASSERT_EQ(z.data.size(), s.rgb.data.size());
  for (std::size_t i = 0; i < z.data.size(); ++i) ASSERT_NEAR(z.data[i], s.rgb.data[i], 1e-6f) << i;
  // --mask: black on the left half keeps the image there.
  Image mask(96, 64, 1, 1.0f);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 48; ++x) mask.at(x, y) = 0.0f;
  write_image(p("mask.exr"), mask, WriteOptions{});
  const CliRun masked = run("rain" + in + "--rate 100 --mask " + p("mask.exr") + " --out " + p("masked.exr"));
  ASSERT_EQ(masked.status, 0) << masked.output;
  const Image m = read_color(p("masked.exr"));
  double changed = 0.0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 96; ++x)
      for (int c = 0; c < 3; ++c) {
        if (x < 48) ASSERT_EQ(m.at(x, y, c), s.rgb.at(x, y, c)) << x << "," << y;
        else changed += std::abs(m.at(x, y, c) - s.rgb.at(x, y, c));
      }
  EXPECT_GT(changed, 0.0);
  // --lidar: the scan through the same rain, as brume lidar rain writes it.
  std::vector<float> pts;
  for (int i = 0; i < 2000; ++i) {
    const double a = 0.003 * i, r = 3.0 + 0.02 * i;
    pts.insert(pts.end(), {static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)), -1.0f,
                           static_cast<float>((i % 7) / 7.0)});
  }
  {
    std::ofstream f(p("scan.bin"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  }
  fs::create_directories(p("l"));
  const CliRun both = run("rain" + in + "--rate 50 --rain-seed 9 --lidar " + p("scan.bin") + " --lidar-out " +
                          p("l/o.bin") + " --out " + p("l/o.exr") + " --record " + p("l/o.json"));
  ASSERT_EQ(both.status, 0) << both.output;
  const CliRun alone = run("lidar rain --points " + p("scan.bin") + " --rate 50 --seed 9 --out " + p("alone.bin"));
  ASSERT_EQ(alone.status, 0) << alone.output;
  EXPECT_EQ(file_bytes(p("l/o.bin")), file_bytes(p("alone.bin")));
  const CliRun again2 = run("run " + p("l/o.json") + " --out-dir " + p("l2"));
  ASSERT_EQ(again2.status, 0) << again2.output;
  EXPECT_EQ(file_bytes(p("l/o.bin")), file_bytes(p("l2/o.bin")));
  const CliRun half = run("rain" + in + "--rate 25 --lidar " + p("scan.bin") + " --out " + p("half.exr"));
  EXPECT_NE(half.status, 0);
  EXPECT_NE(half.output.find("--lidar-out"), std::string::npos) << half.output;
  const CliRun bad = run("rain" + in + "--rate 25 --wind 3 --out " + p("bad.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--wind"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("bad.exr")));
}

// A frame of a sequence from the command line: the record holds it, `brume run` repeats it bit for
// bit, and --lidar rains on the scan at the same frame (brume lidar rain's bytes with the same
// --frame, --wind and --ego-speed). Bad sequences are refused naming the flag, nothing written.
TEST_F(CameraRainCli, FramesOfASequence) {
  const Scene s = scene(96, 64, 12);
  write_image(p("in.exr"), s.rgb, WriteOptions{});
  write_image(p("range.exr"), s.range, WriteOptions{});
  std::vector<float> pts;
  for (int i = 0; i < 1500; ++i) {
    const double a = 0.004 * i, r = 3.0 + 0.02 * i;
    pts.insert(pts.end(), {static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)), -1.0f, 0.3f});
  }
  {
    std::ofstream f(p("scan.bin"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  }
  fs::create_directories(p("first"));
  const std::string in = " --image " + p("in.exr") + " --range " + p("range.exr") + " --fx 80 ";
  const std::string seq = "--rate 50 --rain-seed 9 --wind 0,2,0 --ego-speed 10 ";
  const CliRun r = run("rain" + in + seq + "--frame 2 --lidar " + p("scan.bin") + " --lidar-out " + p("first/o.bin") +
                       " --out " + p("first/o.exr") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["job"]["rain"]["frame"], 2);
  EXPECT_EQ(rec["rain"]["frame"], 2);
  EXPECT_DOUBLE_EQ(rec["rain"]["time_s"].get<double>(), 0.2);
  EXPECT_EQ(rec["lidar_rain"]["frame"], 2);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.exr"), p("again/o.exr"));
  EXPECT_EQ(file_bytes(p("first/o.bin")), file_bytes(p("again/o.bin")));
  const CliRun alone = run("lidar rain --points " + p("scan.bin") + " --rate 50 --seed 9 --wind 0,2,0 --ego-speed 10 "
                           "--frame 2 --out " + p("alone.bin"));
  ASSERT_EQ(alone.status, 0) << alone.output;
  EXPECT_EQ(file_bytes(p("first/o.bin")), file_bytes(p("alone.bin")));
  const CliRun zero = run("rain" + in + seq + "--out " + p("zero.exr"));
  ASSERT_EQ(zero.status, 0) << zero.output;
  EXPECT_NE(file_bytes(p("zero.exr")), file_bytes(p("first/o.exr")));
  // Bad sequences.
  {
    std::ofstream g(p("poses.txt"));
    for (int k = 0; k < 3; ++k) g << "1 0 0 0 0 1 0 0 0 0 1 " << k << "\n";
    std::ofstream c(p("calib.txt"));
    c << "P2: 80 0 47.5 0 0 80 31.5 0 0 0 1 0\nR0_rect: 1 0 0 0 1 0 0 0 1\nTr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";
  }
  const auto refused = [&](const std::string& flags, std::initializer_list<const char*> words) {
    const CliRun b = run("rain" + in + "--rate 25 " + flags + " --out " + p("bad.exr"));
    EXPECT_NE(b.status, 0) << flags;
    for (const char* w : words) EXPECT_NE(b.output.find(w), std::string::npos) << flags << ": " << b.output;
    EXPECT_FALSE(fs::exists(p("bad.exr"))) << flags;
  };
  // A poses file: the record hashes it, and brume run repeats the frame (and refuses an edited file).
  fs::create_directories(p("posed"));
  const CliRun posed = run("rain" + in + "--rate 25 --rain-seed 2 --poses " + p("poses.txt") + " --kitti-calib " +
                           p("calib.txt") + " --frame 1 --out " + p("posed/o.exr") + " --record " + p("posed/o.json"));
  ASSERT_EQ(posed.status, 0) << posed.output;
  EXPECT_EQ(read_json(p("posed/o.json"))["rain"]["pose_files"]["poses"]["path"], p("poses.txt"));
  const CliRun posed_again = run("run " + p("posed/o.json") + " --out-dir " + p("posed2"));
  ASSERT_EQ(posed_again.status, 0) << posed_again.output;
  expect_same_pixels(p("posed/o.exr"), p("posed2/o.exr"));
  {
    std::ofstream g(p("poses.txt"), std::ios::app);
    g << "1 0 0 0 0 1 0 0 0 0 1 3\n";
  }
  const CliRun edited = run("run " + p("posed/o.json") + " --out-dir " + p("posed3"));
  EXPECT_NE(edited.status, 0);
  EXPECT_NE(edited.output.find("poses.txt"), std::string::npos) << edited.output;
  refused("--poses " + p("poses.txt") + " --frame 1", {"--poses", "--kitti-calib", "camera 2"});
  refused("--poses " + p("poses.txt") + " --kitti-calib " + p("calib.txt") + " --ego-speed 5 --frame 1",
          {"--ego-speed 5", "--poses", "give one of them"});
  refused("--poses " + p("poses.txt") + " --kitti-calib " + p("calib.txt") + " --frame 7",
          {"--poses", "4 poses", "--frame 7", "line 8"});
}

// KITTI object 000001 (image and Velodyne scan), 25 mm/h: runs, draws streaks, changes the image,
// and `brume run` repeats it bit for bit.
TEST_F(CameraRainCli, KittiFrame) {
  const std::string k = "kitti_object_000001";
  if (!have_data(k + "/velodyne/000001.bin")) GTEST_SKIP() << data_absent(k + "/velodyne/000001.bin");
  const std::string K = data_path(k);
  fs::create_directories(p("first"));
  const CliRun r = run("rain --image " + K + "/image_2/000001.png --velodyne " + K + "/velodyne/000001.bin --kitti-calib " +
                       K + "/calib/000001.txt --rate 25 --out " + p("first/o.png") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_GT(rec["rain"]["drops_drawn"].get<std::size_t>(), 100u);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.png"), p("again/o.png"));
}

}  // namespace rain_camera_tests
