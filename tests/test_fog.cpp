// Layered fog (brume/fog.hpp): the float per-pixel path against closed forms
// and a double-precision quadrature, the level-ray limit, the sky rule,
// constant fog = haze, a sampled table converging to its profile, rotation
// about the vertical, depth buffers against a range, the blur, the backends,
// bad inputs, and the command line (errors leave nothing; brume run repeats).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/gpu.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "core/simd.hpp"
#include "effects/fog/fog_fast.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

Intrinsics fog_k(double f = 60.0) {
  Intrinsics k;
  k.fx = k.fy = f;
  return k;
}

FogParams exp_params(double height, double pitch = 0.0) {
  FogParams p;
  p.profile = HeightProfile::exponential;
  p.density_per_m = 0.02;
  p.falloff_per_m = 0.05;
  p.base_height_m = 3.0;
  p.camera.height_m = height;
  p.camera.pitch_deg = pitch;
  p.airlight = Rgb{0.7f, 0.75f, 0.8f};
  return p;
}

// A ground plane y = 0 seen from the camera, by independent arithmetic: the
// ray of pixel (u, v) hits it at l = h / -d_y; rays that would meet it
// beyond `wall` metres (or never) see a wall at that range instead.
Image ground_plane(const Camera& c, double wall = 400.0) {
  Image r(c.width, c.height, 1);
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      const Vec3 d = c.world_ray(u, v);
      const double l = d.y < 0.0 ? c.position_m.y / -d.y : INFINITY;
      r.at(u, v) = static_cast<float>(std::min(l, wall));
    }
  return r;
}

Image flat_rgb(int w, int h, float v = 0.3f) { return Image(w, h, 3, v); }

// F of the exponential in double: l (D(y_f) - D(y_c)) / (y_f - y_c), with
// D(y) = -(D0/B) exp(-B (y - Y0)); expm1 keeps it exact near level.
double exp_reference(const FogParams& p, double yc, double l, double dy_unit) {
  const double dy = l * dy_unit, B = p.falloff_per_m;
  const double dc = p.density_per_m * std::exp(-B * (yc - p.base_height_m));
  if (dy == 0.0) return l * dc;
  return l * dc * (-std::expm1(-B * dy)) / (B * dy);
}

// Mean density over [y0, y0 + dy] by composite Gauss-Legendre (3 points on
// 4000 panels, double): an independent oracle for every profile.
double mean_quadrature(const FogDensity& d, double dy) {
  if (dy == 0.0) return d.at(0.0);
  const int n = 4000;
  const double x[3] = {-std::sqrt(0.6), 0.0, std::sqrt(0.6)}, w[3] = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
  double s = 0.0;
  for (int i = 0; i < n; ++i) {
    const double a = dy * i / n, b = dy * (i + 1) / n;
    for (int k = 0; k < 3; ++k) s += w[k] * d.at(0.5 * (a + b) + 0.5 * (b - a) * x[k]) * 0.5;
  }
  return s / n;
}

struct Applied {
  FogAnalysis a;
  FogResult r;
};
Applied apply(const Image& rgb, const Image& range, const FogParams& p, const Camera& c, const Exec& e = {}) {
  Applied o;
  o.a = analyse_fog(rgb, range, range, c, p);
  o.r = apply_fog(rgb, range, p, o.a, e);
  return o;
}

}  // namespace

// ---- the per-pixel maths ----------------------------------------------------------------

TEST(Fog, ExponentialMatchesClosedFormOnAGroundPlane) {
  // Looking down (pitch -20), level (0) and up (+25) from 10 m: every pixel's
  // F against the double closed form. Tolerance 2e-5 relative: the float path
  // (exp, the series below 0.05 e-foldings) against double arithmetic.
  for (double pitch : {-20.0, 0.0, 25.0}) {
    SCOPED_TRACE("pitch " + std::to_string(pitch));
    const FogParams p = exp_params(10.0, pitch);
    const Camera c = make_camera(fog_k(), 81, 61, p.camera);
    const Image range = ground_plane(c);
    const Applied o = apply(flat_rgb(81, 61), range, p, c);
    double worst = 0.0;
    int down = 0, up = 0;
    for (int v = 0; v < 61; ++v)
      for (int u = 0; u < 81; ++u) {
        const double dy = c.world_ray(u, v).y;
        (dy < 0 ? down : up)++;
        const double ref = exp_reference(p, 10.0, range.at(u, v), dy);
        ASSERT_GT(ref, 0.0);
        worst = std::max(worst, std::abs(o.r.optical_depth.at(u, v) - ref) / ref);
      }
    EXPECT_LT(worst, 2e-5);
    EXPECT_GT(down, 81 * 2);  // every pose sees the ground
    if (pitch < 0) { EXPECT_GT(down, 81 * 45); }
    if (pitch > 0) { EXPECT_GT(up, 81 * 30); }
  }
}

TEST(Fog, VectorRowsMatchThePerPixelLoopAndTheClosedForm) {
  // The exponential profile without blur runs as vector rows (fog_fast.cpp:
  // one polynomial e^x for the mean instead of two libm expf). An odd width
  // (vector tails), looking down, level and up, sky of every kind (NaN, inf,
  // 0; climbing: closed form, else over the sky distance), and a camera
  // 1.8 km above the base height (delta(y_c) ~ 1e-41 /m: denormal in f32).
  //  - F against the per-pixel loop: 1e-6 relative + 1e-30 absolute (exp_f's
  //    1e-7 amplified <= 4.5x by the difference d_low - dc at |x| >= 0.25;
  //    6e-7 measured);
  //  - F against the double closed form: 2e-5 relative + 1e-30 absolute (the
  //    float ray and range, as the per-pixel loop's own test); from 1.8 km,
  //    1e-4: exponents of ~90 e-folds carry 90 x 6e-8 each in f32 (the
  //    per-pixel loop's too: the formulation's conditioning, not the rows');
  //  - transmission and colour against the double composite: 2e-6 absolute
  //    (from 1.8 km: 5e-5, f F times the relative error of F);
  //  - every SIMD target against the default one: exact.
  const int W = 203, H = 57;
  for (double height : {10.0, 1800.0})
    for (double pitch : {-20.0, 0.0, 25.0}) {
      SCOPED_TRACE("height " + std::to_string(height) + ", pitch " + std::to_string(pitch));
      FogParams p = exp_params(height, pitch);
      p.sky_distance_m = 900.0;
      const Camera c = make_camera(fog_k(), W, H, p.camera);
      Image range(W, H, 1);
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          const Vec3 d = c.world_ray(u, v);
          // the ground (from 10 m: or a wall at 700 m), and sky in a few columns and rows
          const double l = d.y < 0.0 ? std::min(height / -d.y, height > 100.0 ? 1e5 : 700.0) : 30.0 + 3.0 * u + v;
          float r = static_cast<float>(l);
          if (u % 17 == 3) r = NAN;
          if (u % 29 == 5) r = INFINITY;
          if (v % 13 == 7) r = 0.0f;
          range.at(u, v) = r;
        }
      Image rgb(W, H, 3);
      for (std::size_t i = 0; i < rgb.data.size(); ++i) rgb.data[i] = 0.05f + 0.9f * static_cast<float>(i % 97) / 97.0f;
      const FogAnalysis a = analyse_fog(rgb, range, range, c, p);
      FogResult vec, loop;
      apply_fog(rgb, range, p, a, vec);
      detail::apply_fog_rows(rgb, range, p, a, loop, Exec{}, false);
      // Every SIMD target the CPU runs (forced in turn: the baseline
      // fallback, SSE4, AVX2, AVX-512 on such a host) compiles the same row
      // and gives the same bits (exact equality: the same operations in the
      // same order, no contraction).
      for (std::int64_t t : simd::targets()) {
        simd::force_target(t);
        FogResult got;
        apply_fog(rgb, range, p, a, got);
        simd::force_target(0);
        EXPECT_EQ(got.optical_depth.data, vec.optical_depth.data) << simd::target_name(t);
        EXPECT_EQ(got.transmission.data, vec.transmission.data) << simd::target_name(t);
        EXPECT_EQ(got.rgb.data, vec.rgb.data) << simd::target_name(t);
      }
      const double B = p.falloff_per_m, dc = p.density_per_m * std::exp(-B * (height - p.base_height_m));
      double worst_loop = 0.0, worst_ref = 0.0, worst_f = 0.0, worst_c = 0.0, loop_ref = 0.0;
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          const float r = range.at(u, v);
          const bool sky = !(std::isfinite(r) && r != 0.0f);
          const double dy = c.world_ray(u, v).y;
          const double ref = !sky ? exp_reference(p, height, r, dy)
                             : dy > 0.0 ? dc / (B * dy)
                                        : exp_reference(p, height, 900.0, dy);
          const double F = vec.optical_depth.at(u, v);
          ASSERT_TRUE(std::isfinite(F) && F >= 0.0) << u << "," << v << ": " << F;
          worst_loop = std::max(worst_loop, std::abs(F - loop.optical_depth.at(u, v)) / (1e-6 * F + 1e-30));
          worst_ref = std::max(worst_ref, std::abs(F - ref) / (2e-5 * ref + 1e-30));
          loop_ref = std::max(loop_ref, std::abs(loop.optical_depth.at(u, v) - ref) / (2e-5 * ref + 1e-30));
          const double f = std::exp(-ref);
          worst_f = std::max(worst_f, std::abs(vec.transmission.at(u, v) - f));
          for (int k = 0; k < 3; ++k) {
            const double want = f * rgb.at(u, v, k) + (1.0 - f) * (*p.airlight)[k];
            worst_c = std::max(worst_c, std::abs(vec.rgb.at(u, v, k) - want));
          }
        }
      const double high = height > 100.0 ? 1.0 : 0.0;
      std::printf("  vector rows / loop: F %.2g x 1e-6; F vs double %.2g x 2e-5 (loop %.2g); f %.2g; colour %.2g\n",
                  worst_loop, worst_ref, loop_ref, worst_f, worst_c);
      EXPECT_LE(worst_loop, 1.0);
      EXPECT_LE(worst_ref, high ? 5.0 : 1.0);
      EXPECT_LT(worst_f, high ? 5e-5 : 2e-6);
      EXPECT_LT(worst_c, high ? 5e-5 : 2e-6);
    }
}

TEST(Fog, VectorRowsKeepTheLevelRayLimit) {
  // One pixel at the principal point, whose unit ray climbs exactly ray_y =
  // r2: height differences of 1e-6 m, 0 and -1e-6 m over l = 1 km give
  // F = l delta(y_c) to float precision (1e-6), as the per-pixel loop does.
  const float l = 1000.0f, rgb[3] = {0.2f, 0.4f, 0.6f};
  for (float dy : {1e-6f, 0.0f, -1e-6f, 1e-3f, -1e-3f}) {
    detail::FogExpFrame fr;
    float F = -1.0f, f = -1.0f, out[3] = {};
    fr.rgb = rgb, fr.range = &l, fr.out_rgb = out, fr.optical_depth = &F, fr.transmission = &f;
    fr.width = 1, fr.r2 = dy / l, fr.ifx = fr.ify = 0.01f;
    fr.d0 = 0.02f, fr.falloff = 0.05f, fr.exponent_c = -0.35f, fr.sky_distance = 500.0f;
    detail::fog_exponential_row(fr, 0);
    const double dc = 0.02 * std::exp(-0.35), B = 0.05;
    const double want = dy == 0.0f ? l * dc : l * dc * -std::expm1(-B * dy) / (B * dy);
    EXPECT_NEAR(F / want, 1.0, 1e-6) << "dy " << dy;
    EXPECT_NEAR(f, std::exp(-want), 1e-6);
  }
}

TEST(Fog, LevelRayLimitIsStableForEveryProfile) {
  // Height differences of 1e-6 m (and 0, and -1e-6: looking down) give
  // F = l delta(y_c) to float precision: the mean density never subtracts
  // antiderivatives. The camera sits inside the band and inside the ramp.
  std::vector<FogParams> ps(5);
  ps[0] = exp_params(120.0);
  ps[1].profile = HeightProfile::band, ps[1].band_center_m = 100.0, ps[1].band_half_width_m = 40.0;
  ps[2].profile = HeightProfile::ramp, ps[2].ramp_bottom_m = 50.0, ps[2].ramp_top_m = 200.0;
  ps[3].profile = HeightProfile::constant;
  ps[4] = ps[2];  // a table written as the ramp
  DensityTable t;
  t.height_m = {50.0, 200.0};
  t.density_per_m = {0.02, 0.0};
  for (std::size_t i = 0; i < ps.size(); ++i) {
    SCOPED_TRACE("profile " + std::to_string(i));
    const FogDensity d = fog_density(ps[i], i == 4 ? t : DensityTable{}, 120.0);
    const double dc = d.at(0.0);
    ASSERT_GT(dc, 0.0);
    const float l = 1000.0f;
    for (float dy : {1e-6f, 0.0f, -1e-6f}) {
      const float F = fog_optical_depth(d, l, dy / l, false, 1.0f);
      EXPECT_NEAR(F / (l * dc), 1.0, 1e-6) << "dy " << dy;
    }
    // And at 1e-3 .. 10 m, against the double quadrature (1e-5: float).
    for (float dy : {1e-3f, -0.37f, 10.0f, -10.0f}) {
      const double ref = l * mean_quadrature(d, dy);
      EXPECT_NEAR(fog_optical_depth(d, l, dy / l, false, 1.0f) / ref, 1.0, 1e-5) << "dy " << dy;
    }
  }
}

TEST(Fog, EveryProfileAgreesWithQuadratureLookingUpAndDown) {
  // Random rays crossing the band's and ramp's edges, from below, inside and
  // above: the float path against double quadrature, 2e-5 relative (float),
  // and the sign: F >= 0 whichever way the ray goes.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> yc(-20.0, 220.0), l(1.0, 2000.0), dyu(-1.0, 1.0);
  FogParams band, ramp, table;
  band.profile = HeightProfile::band, band.band_center_m = 100.0, band.band_half_width_m = 40.0;
  ramp.profile = HeightProfile::ramp, ramp.ramp_bottom_m = 50.0, ramp.ramp_top_m = 200.0;
  table.profile = HeightProfile::table;
  DensityTable t;
  t.height_m = {0.0, 30.0, 31.0, 150.0};
  t.density_per_m = {0.05, 0.01, 0.03, 0.0};
  for (int i = 0; i < 300; ++i) {
    const double y = yc(rng), len = l(rng), u = dyu(rng);
    for (const FogParams* p : {&band, &ramp, &table}) {
      const FogDensity d = fog_density(*p, p == &table ? t : DensityTable{}, y);
      const double ref = len * mean_quadrature(d, len * u);
      const float F = fog_optical_depth(d, static_cast<float>(len), static_cast<float>(u), false, 1.0f);
      ASSERT_GE(F, 0.0f);
      EXPECT_NEAR(F, ref, 2e-5 * ref + 1e-6) << "y_c " << y << " l " << len << " d_y " << u;
    }
  }
}

TEST(Fog, SkyIntegratesToInfinityWhereTheFogVanishes) {
  // Exponential looking up: F = delta(y_c) / (B d_y) (closed form);
  // band above the camera: the whole band's column mass / d_y =
  // D0 Wb / d_y; looking down into an exponential: the sky distance.
  FogParams p = exp_params(10.0);
  const FogDensity d = fog_density(p, {}, 10.0);
  const double dc = 0.02 * std::exp(-0.05 * 7.0);
  EXPECT_NEAR(fog_optical_depth(d, 0.0f, 0.25f, true, 500.0f), dc / (0.05 * 0.25), 1e-5 * dc / 0.0125);
  EXPECT_NEAR(fog_optical_depth(d, 0.0f, -0.25f, true, 500.0f), exp_reference(p, 10.0, 500.0, -0.25), 1e-4);
  FogParams b;
  b.profile = HeightProfile::band, b.band_center_m = 100.0, b.band_half_width_m = 40.0, b.density_per_m = 0.01;
  const FogDensity db = fog_density(b, {}, 10.0);  // camera below the band
  EXPECT_NEAR(fog_optical_depth(db, 0.0f, 0.5f, true, 500.0f), 0.01 * 40.0 / 0.5, 1e-5);
  EXPECT_EQ(fog_optical_depth(db, 0.0f, -0.5f, true, 500.0f), 0.0f);  // nothing below the camera
  FogParams c;
  c.profile = HeightProfile::constant, c.density_per_m = 0.001;
  EXPECT_NEAR(fog_optical_depth(fog_density(c, {}, 0.0), 0.0f, 0.5f, true, 700.0f), 0.7, 1e-6);
}

TEST(Fog, ConstantDensityEqualsHazeWithTheSameExtinction) {
  // Beer-Lambert on range both ways: fog's F = beta l against haze's
  // kappa' R' with kappa' = beta R_max and no blur. 2e-6: two float roundings.
  const Scene s = scene(64, 48, 0);
  FogParams f;
  f.profile = HeightProfile::constant;
  f.density_per_m = 0.0015;
  f.airlight = Rgb{0.6f, 0.65f, 0.7f};
  const Camera c = make_camera(fog_k(), 64, 48);
  const Applied o = apply(s.rgb, s.range, f, c);
  HazeParams h;
  h.kappa_a = 0.0015 * 1000.0, h.kappa_s = 0.0, h.lambda = 0.0;
  h.airlight = f.airlight;
  const HazeAnalysis ha = analyse_haze(s.rgb, s.range, h);
  const HazeResult hr = apply_haze(s.rgb, s.range, h, ha);
  const Diff df = compare(o.r.rgb, hr.rgb);
  EXPECT_LT(df.max_abs, 2e-6) << df;
}

TEST(Fog, TableSamplingTheExponentialConverges) {
  // Piecewise-linear interpolation error falls as 1/N^2: doubling the
  // samples divides the worst F error by about 4 (3..5), and 800 samples
  // are within 1e-4 relative of the exponential.
  const FogParams e = exp_params(10.0, -10.0);
  const Camera c = make_camera(fog_k(), 41, 31, e.camera);
  const Image range = ground_plane(c, 100.0);  // heights 0 .. 70 m
  const Applied ref = apply(flat_rgb(41, 31), range, e, c);
  auto err = [&](int n) {
    const std::string path = (fs::temp_directory_path() / ("brume_fog_table_" + std::to_string(::getpid()) + ".csv")).string();
    {
      std::ofstream o(path);
      o << "height_m,density_per_m\n";
      for (int i = 0; i <= n; ++i) {
        const double y = -10.0 + 90.0 * i / n;  // the scene spans heights 0 .. 70 m
        o.precision(17);
        o << y << "," << 0.02 * std::exp(-0.05 * (y - 3.0)) << "\n";
      }
    }
    FogParams t = e;
    t.profile = HeightProfile::table, t.table_file = path;
    t.density_per_m = FogParams{}.density_per_m, t.falloff_per_m = FogParams{}.falloff_per_m;
    t.base_height_m = 0.0;
    const Applied o = apply(flat_rgb(41, 31), range, t, c);
    fs::remove(path);
    double worst = 0.0;
    for (std::size_t i = 0; i < range.pixels(); ++i)
      worst = std::max(worst, std::abs(o.r.optical_depth.data[i] / ref.r.optical_depth.data[i] - 1.0));
    return worst;
  };
  const double e50 = err(50), e100 = err(100), e800 = err(800);
  EXPECT_GT(e50 / e100, 3.0);
  EXPECT_LT(e50 / e100, 5.0);
  EXPECT_LT(e800, 1e-4);
}

TEST(Fog, TurningAboutTheVerticalLeavesTheFogUnchanged) {
  // The same scene seen after a yaw turn: every pixel's ray keeps its
  // elevation, so its world height and F are unchanged (Zhou's point of the
  // Euclidean distance). A pitch change does change them (the test can fail).
  FogParams p = exp_params(10.0, -5.0);
  p.camera.roll_deg = 7.0;
  const Camera c0 = make_camera(fog_k(), 41, 31, p.camera);
  const Image range = ground_plane(c0);
  const Applied a0 = apply(flat_rgb(41, 31), range, p, c0);
  p.camera.yaw_deg = 73.0;
  const Applied a1 = apply(flat_rgb(41, 31), range, p, make_camera(fog_k(), 41, 31, p.camera));
  EXPECT_LT(compare(a0.r.optical_depth, a1.r.optical_depth).max_abs, 1e-6);
  p.camera.pitch_deg = -8.0;
  const Applied a2 = apply(flat_rgb(41, 31), range, p, make_camera(fog_k(), 41, 31, p.camera));
  EXPECT_GT(compare(a0.r.optical_depth, a2.r.optical_depth).max_abs, 1e-3);
}

TEST(Fog, CameraInsideABandOrBelowARampIsANormalCase) {
  // Inside the band a level ray sees delta(y_c) over its whole length;
  // below the ramp a level ray sees D0. Closed forms, float precision.
  FogParams b;
  b.profile = HeightProfile::band, b.band_center_m = 5.0, b.band_half_width_m = 20.0, b.density_per_m = 0.01;
  b.camera.height_m = 2.0;
  const double db = 0.005 * (1.0 + std::cos(M_PI * -3.0 / 20.0));
  const Camera c = make_camera(fog_k(), 41, 31, b.camera);
  const Image range(41, 31, 1, 250.0f);
  const Applied o = apply(flat_rgb(41, 31), range, b, c);
  EXPECT_NEAR(o.r.optical_depth.at(20, 15), 250.0 * db, 1e-5);
  FogParams r;
  r.profile = HeightProfile::ramp, r.ramp_bottom_m = 30.0, r.ramp_top_m = 60.0, r.density_per_m = 0.004;
  r.camera.height_m = 2.0;
  const Applied q = apply(flat_rgb(41, 31), range, r, make_camera(fog_k(), 41, 31, r.camera));
  EXPECT_NEAR(q.r.optical_depth.at(20, 15), 1.0, 1e-5);
}

TEST(Fog, BlurredTransmissionReachesOneWhereNoFogIsCrossed) {
  // A band 20 .. 40 m above the ground, a level camera at 2 m: the lower
  // rows (80 m away, below 18 m) cross no fog, so after the blur their
  // transmission is 1 (the diffusion keeps a constant, and rate-0 pixels
  // take no flux); the top rows (300 m away, climbing through the band) are
  // fogged and blurred.
  FogParams p;
  p.profile = HeightProfile::band, p.band_center_m = 30.0, p.band_half_width_m = 10.0, p.density_per_m = 0.02;
  p.camera.height_m = 2.0;
  p.lambda = 4.0;
  p.airlight = Rgb{0.8f, 0.8f, 0.8f};
  const Camera c = make_camera(fog_k(), 64, 48, p.camera);
  Image range(64, 48, 1, 80.0f);
  for (int v = 0; v < 12; ++v)
    for (int u = 0; u < 64; ++u) range.at(u, v) = 300.0f;
  const Scene s = scene(64, 48, 0);
  const Applied o = apply(s.rgb, range, p, c);
  EXPECT_GT(o.a.sigma_max, p.diffusion.sigma0 + 1.0);
  EXPECT_GT(o.a.plan.iterations, 0);
  for (int v = 30; v < 48; ++v)
    for (int u = 0; u < 64; ++u) ASSERT_NEAR(o.r.transmission.at(u, v), 1.0f, 1e-6f) << u << "," << v;
  EXPECT_LT(o.r.transmission.at(32, 2), 0.9f);
  EXPECT_GT(o.r.optical_depth.at(32, 2), 0.1f);
}

TEST(Fog, PreparationFillsHolesAndKeepsTheSkySky) {
  // --prepare auto: a small hole is filled from its boundary (50 m) and
  // fogged as scene; the top rows, identified as sky beyond the 8 px
  // horizon margin, integrate along their climbing rays (exponential:
  // delta(y_c) / (B d_y), closed form). With --prepare off the hole is sky too.
  FogParams p = exp_params(10.0, 10.0);
  DepthSource ds;
  ds.k = fog_k(40.0);
  const Camera c = make_camera(fog_k(40.0), 48, 32, p.camera);
  Image range(48, 32, 1, 50.0f);
  for (int v = 0; v < 14; ++v)
    for (int u = 0; u < 48; ++u) range.at(u, v) = NAN;
  range.at(30, 20) = range.at(31, 20) = range.at(30, 21) = range.at(31, 21) = NAN;
  const FogRun on = run_fog(flat_rgb(48, 32), range, ds, p, RangeStep{});
  const Image& F = on.result.optical_depth;
  EXPECT_NEAR(F.at(30, 20) / exp_reference(p, 10.0, 50.0, c.world_ray(30, 20).y), 1.0, 1e-5);
  const double dc = 0.02 * std::exp(-0.05 * 7.0), up = c.world_ray(10, 2).y;
  ASSERT_GT(up, 0.0);
  EXPECT_NEAR(F.at(10, 2) / (dc / (0.05 * up)), 1.0, 1e-5);
  RangeStep off;
  off.mode = PrepareMode::off;
  const FogRun no = run_fog(flat_rgb(48, 32), range, ds, p, off);
  const double hole_up = c.world_ray(30, 20).y;  // the hole's rays climb (pitch 10): a finite sky integral
  ASSERT_GT(hole_up, 0.0);
  EXPECT_NEAR(no.result.optical_depth.at(30, 20) / (dc / (0.05 * hole_up)), 1.0, 1e-5);
  EXPECT_GT(no.result.optical_depth.at(30, 20), 2.0f * F.at(30, 20));
}

// ---- bad inputs ---------------------------------------------------------------------------

TEST(Fog, BadInputsGiveClearErrors) {
  FogParams p;
  auto msg = [](const std::string& flag, const std::string& text) {
    FogParams q;
    return error_of([&] { fog_param_table().set_text(q, flag, text); });
  };
  EXPECT_NE(msg("density", "-0.1").find("--density"), std::string::npos);
  EXPECT_NE(msg("falloff", "-1").find("--falloff"), std::string::npos);
  p.profile = HeightProfile::ramp, p.ramp_bottom_m = 10.0, p.ramp_top_m = 5.0;
  EXPECT_NE(error_of([&] { validate_fog(p); }).find("--ramp-top"), std::string::npos);
  p = {};
  p.profile = HeightProfile::band;
  EXPECT_NE(error_of([&] { validate_fog(p, {"falloff"}); }).find("--falloff"), std::string::npos);
  p = {};
  EXPECT_NE(error_of([&] { validate_fog(p, {"albedo"}); }).find("--lambda"), std::string::npos);
  p.classic = ClassicFog::linear;
  EXPECT_NE(error_of([&] { validate_fog(p, {"profile"}); }).find("--classic"), std::string::npos);
  p = {};
  p.profile = HeightProfile::table;
  EXPECT_NE(error_of([&] { validate_fog(p); }).find("--table"), std::string::npos);

  const fs::path dir = fs::temp_directory_path() / ("brume_fog_bad_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto table_error = [&](const std::string& body) {
    const std::string path = (dir / "t.csv").string();
    std::ofstream(path) << body;
    return error_of([&] { read_density_table(path); });
  };
  EXPECT_NE(table_error("0,0.1\n10,0.2\n5,0.1\n").find("strictly increasing"), std::string::npos);
  EXPECT_NE(table_error("0,0.1\n0,0.2\n").find("strictly increasing"), std::string::npos);
  EXPECT_NE(table_error("0,nan\n").find("finite"), std::string::npos);
  EXPECT_NE(table_error("0,-0.1\n").find("negative"), std::string::npos);
  EXPECT_NE(table_error("height_m,density\n").find("no rows"), std::string::npos);
  EXPECT_NE(table_error("0,0.1\nten,0.2\n").find("line 2"), std::string::npos);

  // A view matrix with a scale is not a pose.
  const std::string vm = (dir / "scaled.txt").string();
  std::ofstream(vm) << "2 0 0 0\n0 2 0 0\n0 0 2 -5\n0 0 0 1\n";
  p = exp_params(0.0);
  p.camera.height_m = NAN;
  p.camera.view_matrix_file = vm;
  DepthSource ds;
  ds.k = fog_k();
  const std::string m = error_of([&] {
    run_fog(flat_rgb(8, 6), Image(8, 6, 1, 10.0f), ds, p, RangeStep{});
  });
  EXPECT_NE(m.find("--view-matrix"), std::string::npos) << m;
  // A height profile without a camera height.
  p.camera.view_matrix_file.clear();
  const std::string h = error_of([&] { run_fog(flat_rgb(8, 6), Image(8, 6, 1, 10.0f), ds, p, RangeStep{}); });
  EXPECT_NE(h.find("--camera-height"), std::string::npos) << h;
  fs::remove_all(dir);
}

// ---- backends -----------------------------------------------------------------------------

TEST(Fog, GpuMatchesCpu) {
  // Every profile, sky included, with and without the blur: the GPU pass
  // against the CPU, RMS <= 1e-3 (f32; transcendental functions differ in
  // the last bits between the GPU and libm, and the diffusion accumulates).
  BRUME_REQUIRE_GPU(ctx);
  const Scene s = scene(96, 64, 0);
  std::vector<FogParams> ps(6);
  ps[0] = exp_params(10.0, -5.0);
  ps[1] = ps[0], ps[1].lambda = 6.0;
  ps[2].profile = HeightProfile::band, ps[2].band_center_m = 12.0, ps[2].band_half_width_m = 8.0;
  ps[3].profile = HeightProfile::ramp, ps[3].ramp_bottom_m = 2.0, ps[3].ramp_top_m = 30.0;
  ps[4].classic = ClassicFog::exp2, ps[4].density_per_m = 0.004;
  ps[5] = ps[2], ps[5].lambda = 3.0, ps[5].albedo = 0.8;
  for (std::size_t i = 0; i < ps.size(); ++i) {
    SCOPED_TRACE("case " + std::to_string(i));
    FogParams& p = ps[i];
    if (p.classic == ClassicFog::none) p.camera.height_m = 10.0, p.camera.pitch_deg = -5.0;
    p.airlight = Rgb{0.7f, 0.72f, 0.75f};
    const Camera c = make_camera(fog_k(80.0), 96, 64, p.camera);
    Image range = ground_plane(c, 300.0);
    for (int v = 0; v < 10; ++v)
      for (int u = 0; u < 96; ++u) range.at(u, v) = NAN;  // sky
    const FogAnalysis a = analyse_fog(s.rgb, range, range, c, p);
    const FogResult cpu = apply_fog(s.rgb, range, p, a);
    GpuFog g(*ctx, s.rgb, range);
    const FogResult gpu = g.render(p, a);
    const Diff d = compare(cpu.rgb, gpu.rgb);
    EXPECT_LT(d.rms, 1e-3) << d;
    EXPECT_LT(compare(cpu.transmission, gpu.transmission).rms, 1e-3);
  }
}

TEST(Fog, GpuReadsTheDepthBufferAsTheCpuReadsTheRange) {
  // The fog pass sampling a renderer's window depth and linearising it itself
  // (depth_math.glsl) against the CPU's range path on the range the CPU
  // converts from the same buffer (load_depth: depth_buffer_to_z, z_to_range):
  // OpenGL, D3D and reversed-Z, finite and infinite far planes, the cleared
  // value and NaN as sky, with and without the blur. RMS <= 1e-3 (f32, as
  // GpuMatchesCpu); the optical depth to 1e-4 relative RMS (the linearisation
  // in highp, a few ulp, times dF/dl l / F <= a few).
  BRUME_REQUIRE_GPU(ctx);
  const int W = 96, H = 64;
  const Scene s = scene(W, H, 0);
  FogParams p = exp_params(10.0, -5.0);
  const Camera c = make_camera(fog_k(80.0), W, H, p.camera);
  const Image ground = ground_plane(c, 300.0);
  const double n = 0.5;
  int case_no = 0;
  for (auto conv : {DepthBufferConvention::opengl, DepthBufferConvention::d3d, DepthBufferConvention::reversed})
    for (double far : {2000.0, static_cast<double>(INFINITY)})
      for (double lambda : {0.0, 4.0}) {
        if (lambda > 0.0 && (++case_no % 2)) continue;  // the blur on half the cases: it only follows the pass
        SCOPED_TRACE("convention " + std::to_string(static_cast<int>(conv)) + ", far " + std::to_string(far) +
                     ", lambda " + std::to_string(lambda));
        p.lambda = lambda;
        const float clear = conv == DepthBufferConvention::reversed ? 0.0f : 1.0f;
        Image d(W, H, 1);
        for (int v = 0; v < H; ++v)
          for (int u = 0; u < W; ++u) {
            const Vec3 ray = c.pixel_ray_cv(u, v);
            const double z = ground.at(u, v) / std::sqrt(ray.x * ray.x + ray.y * ray.y + 1.0);
            d.at(u, v) = v < 8 ? clear : static_cast<float>(z_to_depth_buffer(z, conv, n, far));
          }
        d.at(5, 20) = NAN;  // an unknown stored value: sky too
        const Image range = z_to_range(depth_buffer_to_z(d, conv, n, far), c.k);
        const FogAnalysis a = analyse_fog(s.rgb, range, range, c, p);
        ASSERT_EQ(a.unknown_pixels, static_cast<std::size_t>(8 * W + 1));
        const FogResult cpu = apply_fog(s.rgb, range, p, a);
        GpuFog g(*ctx, s.rgb, d, conv, n, far);
        const FogResult gpu = g.render(p, a);
        EXPECT_LT(compare(cpu.rgb, gpu.rgb).rms, 1e-3) << compare(cpu.rgb, gpu.rgb);
        EXPECT_LT(compare(cpu.transmission, gpu.transmission).rms, 1e-3);
        double se = 0.0;
        for (std::size_t i = 0; i < cpu.optical_depth.pixels(); ++i) {
          const double e = gpu.optical_depth.data[i] / cpu.optical_depth.data[i] - 1.0;
          se += e * e;
        }
        EXPECT_LT(std::sqrt(se / cpu.optical_depth.pixels()), 1e-4);
      }
  // Out-of-range window depth is refused as by `depth convert`.
  Image bad(W, H, 1, 0.5f);
  bad.at(3, 4) = 1.5f;
  EXPECT_THROW(GpuFog(*ctx, s.rgb, bad, DepthBufferConvention::d3d, n, 100.0), Error);
}

TEST(Fog, DepthBuffersGiveTheFogOfTheRange) {
  // The same ground plane as a range map and as OpenGL, D3D and reversed-Z
  // depth buffers (window depth written here by the textbook formulas):
  // the fog's optical depth agrees to 1e-4 relative (a float32 depth buffer
  // resolves z to about z^2 eps / n).
  const fs::path dir = fs::temp_directory_path() / ("brume_fog_db_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const FogParams p = exp_params(10.0, -12.0);
  const Camera c = make_camera(fog_k(), 64, 48, p.camera);
  const Image range = ground_plane(c, 300.0);
  const double n = 0.5, f = 2000.0;
  WriteOptions data;
  data.is_color = false;
  write_image((dir / "range.exr").string(), range, data);
  write_image((dir / "rgb.exr").string(), flat_rgb(64, 48), WriteOptions{});
  auto optical = [&](const std::string& depth_flags) {
    const std::string out = (dir / "F.exr").string();
    const CliRun r = run("fog --image " + (dir / "rgb.exr").string() + " " + depth_flags +
                         " --fx 60 --camera-height 10 --pitch -12 --density 0.02 --falloff 0.05 --base-height 3 "
                         "--airlight 0.7,0.75,0.8 --out " + (dir / "o.exr").string() + " --optical-depth " + out);
    EXPECT_EQ(r.status, 0) << r.output;
    return read_scalar(out);
  };
  const Image ref = optical("--range " + (dir / "range.exr").string());
  for (const char* conv : {"opengl", "d3d", "reversed-z"}) {
    SCOPED_TRACE(conv);
    Image d(64, 48, 1);
    for (int v = 0; v < 48; ++v)
      for (int u = 0; u < 64; ++u) {
        const Vec3 ray = c.pixel_ray_cv(u, v);
        const double z = range.at(u, v) / std::sqrt(ray.x * ray.x + ray.y * ray.y + 1.0);
        double w;
        if (std::string(conv) == "opengl") w = 0.5 * (((f + n) - 2.0 * f * n / z) / (f - n) + 1.0);
        else if (std::string(conv) == "d3d") w = f * (z - n) / (z * (f - n));
        else w = n * (f - z) / (z * (f - n));
        d.at(u, v) = static_cast<float>(w);
      }
    write_image((dir / "depth.exr").string(), d, data);
    const Image F = optical("--depth-buffer " + (dir / "depth.exr").string() + " --near 0.5 --far 2000 --convention " +
                            conv);
    double worst = 0.0;
    for (std::size_t i = 0; i < F.pixels(); ++i) worst = std::max(worst, std::abs(F.data[i] / ref.data[i] - 1.0));
    EXPECT_LT(worst, 1e-4);
  }
  fs::remove_all(dir);
}

// ---- the command line ------------------------------------------------------------------------

class CliFog : public ScratchDirTest {
 protected:
  void SetUp() override {
    const Scene s = scene(40, 30, 6);
    WriteOptions data;
    data.is_color = false;
    write_image(p("img.exr"), s.rgb, WriteOptions{});
    write_image(p("range.exr"), s.range, data);
  }
  std::string base() const {
    return "fog --image " + p("img.exr") + " --range " + p("range.exr") + " --fov-y 50 --camera-height 20 --pitch 3";
  }
  std::size_t files() const {
    return static_cast<std::size_t>(std::distance(fs::directory_iterator(dir), fs::directory_iterator()));
  }
};

TEST_F(CliFog, ErrorsLeaveNothingBehind) {
  // Each bad run names the flag or file and writes no output, record or map.
  const std::vector<std::pair<std::string, std::string>> cases = {
      {" --density -1", "--density"},
      {" --profile band --falloff 0.1", "--falloff"},
      {" --albedo 0.5", "--lambda"},
      {" --profile table --table " + p("missing.csv"), "missing.csv"},
      {" --profile ramp --ramp-bottom 10 --ramp-top 5", "--ramp-top"},
      {" --classic linear --profile band", "--classic"},
  };
  for (const auto& [flags, needle] : cases) {
    SCOPED_TRACE(flags);
    const CliRun r = run(base() + flags + " --out " + p("o.png") + " --optical-depth " + p("F.exr") + " --record " +
                         p("r.json"));
    EXPECT_EQ(r.status, 2) << r.output;
    EXPECT_NE(r.output.find(needle), std::string::npos) << r.output;
    EXPECT_EQ(files(), 2u);  // the two inputs only
  }
  // A height profile without a camera height.
  const CliRun r = run("fog --image " + p("img.exr") + " --range " + p("range.exr") + " --fov-y 50 --out " + p("o.png"));
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("--camera-height"), std::string::npos) << r.output;
  EXPECT_EQ(files(), 2u);
}

TEST_F(CliFog, RunRepeatsTheRecord) {
  fs::create_directories(p("first"));
  const CliRun a = run(base() + " --profile band --band-center 30 --band-half-width 25 --density 0.01 --lambda 3 --out " +
                       p("first/o.exr") + " --optical-depth " + p("first/F.exr") + " --record " + p("first/a.json"));
  ASSERT_EQ(a.status, 0) << a.output;
  const nlohmann::json rec = read_json(p("first/a.json"));
  EXPECT_EQ(rec["command"], "fog");
  EXPECT_EQ(rec["job"]["fog"]["profile"], "band");
  EXPECT_EQ(rec["job"]["camera"]["camera-height"], 20.0);
  EXPECT_GT(rec["fog"]["derived"]["sigma_max_px"].get<double>(), 1.0);
  EXPECT_TRUE(rec["prepare"]["applied"].get<bool>());  // the top rows are sky
  const CliRun b = run("run " + p("first/a.json") + " --out-dir " + p("again"));
  ASSERT_EQ(b.status, 0) << b.output;
  expect_same_pixels(p("first/o.exr"), p("again/o.exr"));
  const Image f1 = read_scalar(p("first/F.exr")), f2 = read_scalar(p("again/F.exr"));
  ASSERT_EQ(f1.data.size(), f2.data.size());
  EXPECT_EQ(std::memcmp(f1.data.data(), f2.data.data(), f1.data.size() * sizeof(float)), 0);
}

TEST_F(CliFog, RunRefusesAChangedTableAndTheRecordShowsPlusZero) {
  {
    std::ofstream t(p("table.csv"));
    t << "height_m,density_per_m\n0,0.02\n40,0.005\n120,0\n";
  }
  const CliRun a = run(base() + " --profile table --table " + p("table.csv") + " --out " + p("o.exr") + " --record " +
                       p("a.json"));
  ASSERT_EQ(a.status, 0) << a.output;
  const nlohmann::json rec = read_json(p("a.json"));
  // A level-yaw pose records yaw +0 (atan2 gives -0), and the pitch as given.
  const double yaw = rec["fog"]["derived"]["camera"]["yaw_deg"].get<double>();
  EXPECT_EQ(yaw, 0.0);
  EXPECT_FALSE(std::signbit(yaw));
  EXPECT_NEAR(rec["fog"]["derived"]["camera"]["pitch_deg"].get<double>(), 3.0, 1e-9);
  EXPECT_EQ(rec["fog"]["derived"]["table"]["sha256"].get<std::string>().size(), 64u);
  ASSERT_EQ(run("run " + p("a.json") + " --out-dir " + p("again")).status, 0);
  {
    std::ofstream t(p("table.csv"), std::ios::app);
    t << "200,0\n";
  }
  const CliRun b = run("run " + p("a.json") + " --out-dir " + p("third"));
  EXPECT_NE(b.status, 0);
  EXPECT_NE(b.output.find("table.csv"), std::string::npos) << b.output;
  EXPECT_NE(b.output.find("SHA-256 differs"), std::string::npos) << b.output;
  EXPECT_FALSE(fs::exists(p("third/o.exr")));
}

TEST_F(CliFog, GpuDepthBufferRunsTheDepthPassWhenUnprepared) {
  // `brume fog --backend gpu --depth-buffer ... --prepare off` hands the
  // window depth to the fog pass (the record says so, and names the pass's
  // time fog_pass_ms); the result equals the CPU's on the same flags (RMS
  // 1e-3, f32). With --prepare auto and sky present, the CPU prepares the range.
  BRUME_REQUIRE_GPU(ctx);
  const Image range = read_scalar(p("range.exr"));
  const Intrinsics k = intrinsics_from_fov(range.width, range.height, NAN, 50.0);
  const Image z = range_to_z(range, k);
  Image d(range.width, range.height, 1);
  for (std::size_t i = 0; i < d.pixels(); ++i)
    d.data[i] = std::isfinite(z.data[i]) && z.data[i] > 0.0f
                    ? static_cast<float>(z_to_depth_buffer(z.data[i], DepthBufferConvention::reversed, 0.5, 3000.0))
                    : 0.0f;
  WriteOptions data;
  data.is_color = false;
  write_image(p("depth.exr"), d, data);
  const std::string flags = "fog --image " + p("img.exr") + " --depth-buffer " + p("depth.exr") +
                            " --near 0.5 --far 3000 --convention reversed-z --fov-y 50 --camera-height 20 --pitch 3 "
                            "--airlight 0.7,0.72,0.75 --prepare off";
  const CliRun g = run(flags + " --backend gpu --timing --out " + p("g.exr") + " --record " + p("g.json"));
  ASSERT_EQ(g.status, 0) << g.output;
  const CliRun c = run(flags + " --backend cpu --out " + p("c.exr"));
  ASSERT_EQ(c.status, 0) << c.output;
  const nlohmann::json rec = read_json(p("g.json"));
  EXPECT_EQ(rec["execution"]["gpu_depth_input"].get<std::string>().rfind("window depth", 0), 0u) << rec["execution"];
  EXPECT_TRUE(rec["execution"]["timing"].contains("fog_pass_ms")) << rec["execution"]["timing"];
  EXPECT_FALSE(rec["execution"]["timing"].contains("premultiply_ms"));
  EXPECT_NE(g.output.find("fog_pass_ms"), std::string::npos) << g.output;
  EXPECT_LT(compare(read_color(p("c.exr")), read_color(p("g.exr"))).rms, 1e-3);
  const CliRun h = run("fog --image " + p("img.exr") + " --depth-buffer " + p("depth.exr") +
                       " --near 0.5 --far 3000 --convention reversed-z --fov-y 50 --camera-height 20 --pitch 3 "
                       "--backend gpu --out " + p("h.exr") + " --record " + p("h.json"));
  ASSERT_EQ(h.status, 0) << h.output;
  EXPECT_EQ(read_json(p("h.json"))["execution"]["gpu_depth_input"], "range from the CPU");
}
