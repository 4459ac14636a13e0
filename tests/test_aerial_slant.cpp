// The slant path of aerial perspective (issue #59, brume/aerial.hpp): the
// closed-form optical depth against a numerical integral of the exponential
// atmosphere along the ray, the spectral integral at two distances against the
// level one and against an independent fine integral, the 2-D table against
// the direct integral, and the render per pixel against the closed form from
// the camera's rays or a target-altitude map.
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "brume/gpu_aerial.hpp"
#include "flat_sensitivity.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

// int_0^s e^{-(t dh/s)/H} dt by composite Simpson in long double, 4000
// intervals: for the steepest case here (dh/H = 21.7 over the path) the rule's
// relative error is ~(dh/H/4000)^4/180 < 1e-11, far below the 1e-6 checked.
double numerical_level_distance(double s, double dh, double H) {
  const int n = 4000;
  const long double h = static_cast<long double>(s) / n, k = static_cast<long double>(dh) / s / H;
  long double sum = 0.0L;
  for (int i = 0; i <= n; ++i) {
    const long double w = (i == 0 || i == n) ? 1.0L : (i % 2 ? 4.0L : 2.0L);
    sum += w * std::exp(-k * (h * i));
  }
  return static_cast<double>(sum * h / 3.0L);
}

// The spectral integral with a flat sensitivity, independent of the
// library's quadrature: Simpson over 380-780 nm at 0.05 nm.
double flat_gamma_fine(const Atmosphere& a, double s_r, double s_m) {
  const int n = 8000;
  const double h = 400.0 / n;
  double sum = 0.0;
  for (int i = 0; i <= n; ++i) {
    const double l = 380.0 + i * h;
    const double tau = rayleigh_beta_per_m(l, a.altitude_m) * s_r + mie_beta_per_m(l, a.turbidity, a.altitude_m) * s_m;
    sum += ((i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0)) * std::exp(-tau);
  }
  return sum * h / 3.0 / 400.0;
}

// A frame of land from 300 m to 14 km, rising towards the top rows, sky above.
void slant_scene(Image& rgb, Image& range) {
  rgb = Image(64, 48, 3);
  range = Image(64, 48, 1);
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = y < 6 ? 0.8f : 0.05f + 0.01f * ((x + 2 * y + c) % 40);
      range.at(x, y) = y < 6 ? NAN : 300.0f + 13700.0f * std::pow((47.0f - y) / 41.0f, 2.0f) + 5.0f * (x % 7);
    }
}

}  // namespace

// The target: 1e-6 relative for elevations -10..60 deg, targets at or
// above -500 m, paths up to 30 km; exactly the level distance at dh = 0.
TEST(AerialSlant, OpticalDepthIsTheIntegralAlongTheRay) {
  double worst = 0.0;
  int cases = 0;
  for (double h0 : {-400.0, 0.0, 2910.0, 9000.0})
    for (int e = -10; e <= 60; e += 5)
      for (double s : {1.0, 120.0, 1500.0, 10000.0, 30000.0}) {
        const double dh = s * std::sin(e * M_PI / 180.0);
        if (h0 + dh < kSlantTargetMinAltitudeM) continue;
        const SlantDistances d = slant_distances(s, dh);
        for (const auto& [got, H] : {std::pair{d.rayleigh_m, kRayleighScaleHeightM}, std::pair{d.mie_m, kMieScaleHeightM}}) {
          const double want = numerical_level_distance(s, dh, H);
          worst = std::max(worst, std::abs(got - want) / want);
          ++cases;
        }
      }
  EXPECT_GT(cases, 300);
  EXPECT_LE(worst, 1e-6);
  // Level: the distance itself, bit for bit; near level expm1 keeps g exact
  // (1 - e^{-x} in double would lose ~1e-4 relative at x = 1e-12).
  EXPECT_EQ(slant_distances(2500.0, 0.0).rayleigh_m, 2500.0);
  EXPECT_EQ(slant_distances(2500.0, 0.0).mie_m, 2500.0);
  EXPECT_NEAR(slant_factor(1e-12), 1.0 - 5e-13, 1e-24);
  EXPECT_NEAR(slant_factor(-1e-9), 1.0 + 5e-10, 1e-20);
}

// At s_R = s_M = s the slant integral is the level one (the same sum; the exp
// of a sum against the sum of two products differs by rounding only), and
// against an independent 0.05 nm integral it holds to the quadrature's 1e-9.
TEST(AerialSlant, SpectralIntegralAtTwoDistances) {
  const SpectralSensitivity q = load_sensitivity("default");
  for (double t : {1.0, 2.0, 8.0, 20.0})
    for (double s : {0.0, 500.0, 4000.0, 16000.0}) {
      const Atmosphere a{t, 1500.0};
      const auto lv = attenuation_direct(a, q, s), sl = attenuation_slant_direct(a, q, s, s);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(sl[c], lv[c], 1e-14 * lv[c] + 1e-300) << t << " " << s;
    }
  for (double t : {1.0, 6.0, 20.0})
    for (auto [sr, sm] : {std::pair{3000.0, 800.0}, std::pair{16000.0, 5000.0}, std::pair{2000.0, 9000.0}}) {
      const Atmosphere a{t, 2910.0};
      const auto g = attenuation_slant_direct(a, flat_sensitivity(), sr, sm);
      EXPECT_NEAR(g[0], flat_gamma_fine(a, sr, sm), 1e-9) << t << " " << sr << " " << sm;
    }
  EXPECT_THROW(attenuation_slant_direct({2.0, 0.0}, flat_sensitivity(), -1.0, 10.0), Error);
}

// The 256 x 256 grid against the direct integral at random positions: ln
// Gamma is nearly linear in both distances (its curvature is the spectral
// variance of beta across a channel), so bilinear interpolation errs by
// ~dr^2 var(beta_M)/8; measured max 5.5e-7 at T 20 over 16 x 12 km (T 10:
// 1.4e-7, T 2: 3.0e-8; 2026-12-06), bounded here by 1e-6 absolute.
TEST(AerialSlant, TableMatchesTheDirectIntegral) {
  const SpectralSensitivity q = load_sensitivity("default");
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (double t : {1.0, 2.0, 10.0, 20.0}) {
    const Atmosphere a{t, 2910.0};
    const SlantAttenuationTable tab = slant_attenuation_table(a, q, 16000.0, 12000.0, kSlantSamples, kSlantSamples, 2);
    ASSERT_EQ(tab.log_gamma.size(), static_cast<std::size_t>(kSlantSamples) * kSlantSamples);
    EXPECT_EQ(tab.log_gamma[0], (std::array<float, 3>{0.0f, 0.0f, 0.0f}));
    double worst = 0.0;
    for (int k = 0; k < 400; ++k) {
      const double sr = 16000.0 * u(rng), sm = 12000.0 * u(rng);
      const auto want = attenuation_slant_direct(a, q, sr, sm);
      const auto l = tab.log_at(static_cast<float>(sr / tab.step_r_m), static_cast<float>(sm / tab.step_m_m));
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(std::exp(static_cast<double>(l[c])) - want[c]));
    }
    EXPECT_LE(worst, 1e-6) << "T " << t;
  }
  EXPECT_THROW(slant_attenuation_table({2.0, 0.0}, flat_sensitivity(), 0.0, 10.0), Error);
  EXPECT_THROW(slant_attenuation_table({2.0, 0.0}, flat_sensitivity(), 10.0, 10.0, 1, 4), Error);
}

// The render's attenuation per pixel equals the closed form from the camera's
// rays (h1 = h0 + s sin(elevation)) and, given as a map, from the target
// altitudes: the table's error at T 3 (between T 2's 3e-8 and T 10's 1.4e-7
// above) plus the f32 rounding of Gamma (6e-8) and of the cells: 5e-7
// (measured 7.9e-8).
TEST(AerialSlant, RenderFollowsTheClosedFormPerPixel) {
  Image rgb, range;
  slant_scene(rgb, range);
  AerialParams p;
  p.atmosphere = {3.0, 1200.0};
  p.airlight = Rgb{0.6f, 0.7f, 0.9f};
  p.path = AerialPath::slant;
  p.camera.pitch_deg = 4.0, p.camera.roll_deg = 7.0;
  const Camera cam = make_camera(Intrinsics{60.0, 60.0, NAN, NAN}, 64, 48, p.camera);
  AerialGeometry geo;
  geo.camera = cam;
  AerialAnalysis a;
  analyse_aerial(rgb, range, p, a, 2, &geo);
  const AerialResult r = apply_aerial(rgb, range, p, a);
  const SpectralSensitivity q = load_sensitivity("default");
  // The same targets as an altitude map: the second route.
  Image alt(64, 48, 1, NAN);
  double worst = 0.0, dh_span = 0.0;
  for (int y = 6; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      const double s = range.at(x, y), dh = s * cam.world_ray(x, y).y;
      alt.at(x, y) = static_cast<float>(p.atmosphere.altitude_m + dh);
      dh_span = std::max(dh_span, std::abs(dh));
      const SlantDistances d = slant_distances(s, dh);
      const auto want = attenuation_slant_direct(p.atmosphere, q, d.rayleigh_m, d.mie_m);
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(r.attenuation.at(x, y, c) - want[c]));
    }
  EXPECT_GT(dh_span, 500.0);  // the scene climbs: the test is not the level one
  EXPECT_LE(worst, 5e-7);
  // The level render differs there by far more than that.
  AerialParams lp = p;
  lp.path = AerialPath::level;
  lp.camera = {};
  const AerialResult lv = apply_aerial(rgb, range, lp, analyse_aerial(rgb, range, lp, 2));
  EXPECT_GT(std::abs(lv.attenuation.at(32, 8, 2) - r.attenuation.at(32, 8, 2)), 1e-3);

  AerialGeometry byfile;
  byfile.target_altitude = alt;
  AerialAnalysis b;
  p.camera = {};
  analyse_aerial(rgb, range, p, b, 2, &byfile);
  const AerialResult rb = apply_aerial(rgb, range, p, b);
  double worst_file = 0.0;
  for (int y = 6; y < 48; ++y)
    for (int x = 0; x < 64; ++x)
      for (int c = 0; c < 3; ++c)
        worst_file = std::max(worst_file, static_cast<double>(std::abs(rb.attenuation.at(x, y, c) - r.attenuation.at(x, y, c))));
  // The altitude map is f32 metres (~1e-4 m of dh) where the camera's route
  // keeps dh = s sin(elevation) in double: measured 1.8e-7 apart.
  EXPECT_LE(worst_file, 1e-6);
}

// The GPU's premultiply pass on the slant path: each pixel's dh and the 2-D
// table, in float. Its attenuation against the closed form and the spectral
// integral in double (the float GPU target, 1e-4), and every mode's
// pixels against the CPU's (RMS 1e-3, as the level path's GPU test: the
// GPU's exp is not correctly rounded and remove divides by Gamma).
TEST(AerialSlantGpu, FollowsTheClosedFormPerPixelAndTheCpu) {
  BRUME_REQUIRE_GPU(ctx);
  Image rgb, range;
  slant_scene(rgb, range);
  Image prepared = range;
  for (float& v : prepared.data)
    if (!std::isfinite(v)) v = 14100.0f;
  const SpectralSensitivity q = load_sensitivity("default");
  for (int mode = 0; mode < 4; ++mode) {
    AerialParams p;
    p.atmosphere = {3.0, 1200.0};
    p.airlight = Rgb{0.6f, 0.7f, 0.9f};
    p.path = AerialPath::slant;
    p.camera.pitch_deg = 4.0, p.camera.roll_deg = 7.0;
    if (mode == 1) p.lambda = 6.0;
    if (mode == 2) p.from_turbidity = 6.0, p.from_airlight = Rgb{0.5f, 0.6f, 0.8f};
    if (mode == 3) p.remove = true;
    AerialGeometry geo;
    geo.camera = make_camera(Intrinsics{60.0, 60.0, NAN, NAN}, 64, 48, p.camera);
    AerialAnalysis a;
    analyse_aerial(rgb, range, p, a, 2, &geo);
    const AerialResult cpu = apply_aerial(rgb, prepared, p, a);
    GpuAerial g(*ctx, rgb, prepared);
    const AerialResult gpu = g.render(p, a);
    const Diff d = compare(gpu.rgb, cpu.rgb), da = compare(gpu.attenuation, cpu.attenuation);
    EXPECT_LE(d.rms, 1e-3) << "mode " << mode << ": " << d;
    EXPECT_LE(da.rms, 1e-4) << "mode " << mode << ": " << da;
    EXPECT_EQ(gpu.floored_pixels, cpu.floored_pixels) << "mode " << mode;
    std::printf("slant GPU mode %d: pixels RMS %.3g max %.3g, attenuation RMS %.3g against the CPU\n", mode, d.rms,
                d.max_abs, da.rms);
    if (mode != 0) continue;
    double worst = 0.0;
    for (int y = 6; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        const double s = prepared.at(x, y), dh = s * geo.camera->world_ray(x, y).y;
        const SlantDistances sd = slant_distances(s, dh);
        const auto want = attenuation_slant_direct(p.atmosphere, q, sd.rayleigh_m, sd.mie_m);
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(gpu.attenuation.at(x, y, c) - want[c]) / want[c]);
      }
    std::printf("slant GPU: attenuation within %.3g (relative) of the closed form\n", worst);
    EXPECT_LE(worst, 1e-4) << "relative, against the closed form";
  }
}

TEST(AerialSlant, RefusesWhatItCannotVouchFor) {
  Image rgb, range;
  slant_scene(rgb, range);
  AerialParams p;
  p.airlight = Rgb{0.6f, 0.7f, 0.9f};
  p.path = AerialPath::slant;
  // No geometry.
  std::string e = error_of([&] { analyse_aerial(rgb, range, p, 1); });
  EXPECT_NE(e.find("--target-altitude"), std::string::npos) << e;
  EXPECT_NE(e.find("--pitch"), std::string::npos) << e;
  // A ray pointing down into the ground far below sea level.
  p.camera.pitch_deg = -40.0;
  AerialGeometry geo;
  geo.camera = make_camera(Intrinsics{60.0, 60.0, NAN, NAN}, 64, 48, p.camera);
  AerialAnalysis a;
  e = error_of([&] { analyse_aerial(rgb, range, p, a, 1, &geo); });
  EXPECT_NE(e.find("below the model's -500 m"), std::string::npos) << e;
  EXPECT_NE(e.find("pixel ("), std::string::npos) << e;
  // Beyond 30 km.
  p.camera = {};
  geo.camera = make_camera(Intrinsics{60.0, 60.0, NAN, NAN}, 64, 48, p.camera);
  Image far = range;
  far.at(10, 40) = 31000.0f;
  e = error_of([&] { analyse_aerial(rgb, far, p, a, 1, &geo); });
  EXPECT_NE(e.find("30000 m"), std::string::npos) << e;
  EXPECT_NE(e.find("pixel (10, 40)"), std::string::npos) << e;
  // A target-altitude map with a hole where the land is, or of another size.
  Image alt(64, 48, 1, 800.0f);
  alt.at(3, 20) = NAN;
  AerialGeometry byfile;
  byfile.target_altitude = alt;
  e = error_of([&] { analyse_aerial(rgb, range, p, a, 1, &byfile); });
  EXPECT_NE(e.find("no finite altitude at pixel (3, 20)"), std::string::npos) << e;
  Image small(32, 24, 1, 800.0f);
  byfile.target_altitude = small;
  e = error_of([&] { analyse_aerial(rgb, range, p, a, 1, &byfile); });
  EXPECT_NE(e.find("32x24"), std::string::npos) << e;
  // The pose without the slant path.
  AerialParams lv;
  lv.camera.pitch_deg = 3.0;
  e = error_of([&] { validate_aerial(lv); });
  EXPECT_NE(e.find("--pitch"), std::string::npos) << e;
  EXPECT_NE(e.find("--path slant"), std::string::npos) << e;
}

// --airlight horizon (issue #59 item 2) on a synthetic photo whose sky is a
// deep blue overhead and pale at the horizon: the colour just above the
// farthest skyline, not the sky's median; land the range map calls sky (a
// skyline two rows off) and a black stitch border are left out.
TEST(AerialHorizon, TakesTheSkyJustAboveTheFarSkyline) {
  const int W = 80, H = 60;
  Image rgb(W, H, 3), range(W, H, 1);
  const std::array<float, 3> zenith{0.02f, 0.15f, 0.6f}, horizon{0.12f, 0.45f, 0.85f}, rock{0.05f, 0.05f, 0.06f};
  for (int x = 0; x < W; ++x) {
    const bool far = x >= 40;                 // the right half: land at 12 km, its skyline at row 30
    const int sky_end = far ? 30 : 22;        // the left: 900 m, higher in the frame
    const int photo_land = far ? 25 : 22;     // the photo's rock starts 5 rows above the map's skyline (far half)
    for (int y = 0; y < H; ++y) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      range.data[i] = y < sky_end ? NAN : (far ? 12000.0f : 900.0f);
      std::array<float, 3> c = y >= photo_land ? rock : (y >= sky_end - 9 ? horizon : zenith);
      if (x >= 76) c = {0.0f, 0.0f, 0.0f};  // a stitch border: black, unknown range
      for (int k = 0; k < 3; ++k) rgb.data[3 * i + k] = c[k];
    }
  }
  nlohmann::json where;
  const std::array<float, 3> a = horizon_airlight(rgb, range, where);
  EXPECT_EQ(a, horizon);
  EXPECT_GT(where["pixels"].get<int>(), 16);
  EXPECT_EQ(where["rejected_darker_than_the_sky_above"].get<int>(), 2 * 36);  // rock rows 25-26 of 36 columns
  EXPECT_EQ(where["skyline_range_min_m"], 12000.0f);
  // The whole-sky median (auto) is the zenith's colour: far from it.
  AerialParams p;
  const AerialAnalysis med = analyse_aerial(rgb, range, p, 1);
  EXPECT_EQ(med.airlight, zenith);
  p.airlight_rule = "horizon";
  const AerialAnalysis hz = analyse_aerial(rgb, range, p, 1);
  EXPECT_EQ(hz.airlight, horizon);
  EXPECT_NE(hz.airlight_source.find("horizon"), std::string::npos);
  // No sky above the land: refused, with the fix.
  Image full(W, H, 1, 500.0f);
  const std::string e = error_of([&] { horizon_airlight(rgb, full, where); });
  EXPECT_NE(e.find("--airlight R,G,B"), std::string::npos) << e;
}
