// Spectral aerial perspective (include/brume/aerial.hpp): render, re-render,
// remove and the per-channel scattering blur, against closed forms and
// independent double arithmetic. Gamma tables are built here from closed forms
// (Gamma_c = e^{-beta_c s}) with AttenuationTable::from_function, so these
// tests hold whatever the spectral integral gives.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

constexpr double kBeta1[3] = {1.0e-3, 2.0e-3, 3.0e-3};  // [1/m] per channel, a reddish-blue spread
constexpr double kBeta2[3] = {2.5e-3, 3.0e-3, 4.0e-3};

AttenuationTable exp_table(const double* beta, double s_max) {
  return AttenuationTable::from_function(
      [beta](double s) { return std::array<double, 3>{std::exp(-beta[0] * s), std::exp(-beta[1] * s),
                                                       std::exp(-beta[2] * s)}; },
      s_max);
}


// The analysis with the closed-form tables in place of the spectral ones.
AerialAnalysis analysis(const Scene& s, const AerialParams& p, const double* beta, const double* beta_from = nullptr) {
  AerialAnalysis a = analyse_aerial(s.rgb, s.range, p);
  // The closed forms are per channel of the image itself (camera-RGB space);
  // the default sensitivity is XYZ since the spectral branch landed, and the
  // XYZ path is tested on its own (XyzSpaceIsMDiagGammaMInverse).
  a.sensitivity.space = SensitivitySpace::camera_rgb;
  a.gamma = exp_table(beta, a.range_max_m * p.distance_scale);
  if (beta_from) a.gamma_from = exp_table(beta_from, a.range_max_m * p.distance_scale);
  return a;
}

AerialParams given_airlight(Rgb a) {
  AerialParams p;
  p.airlight = a;
  return p;
}

// Largest |a - b| over known-range pixels.
double max_diff_known(const Image& a, const Image& b, const Image& range) {
  double m = 0.0;
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    if (!std::isfinite(range.data[i])) continue;
    for (int c = 0; c < a.channels; ++c)
      m = std::max(m, std::abs(static_cast<double>(a.data[i * a.channels + c]) - b.data[i * b.channels + c]));
  }
  return m;
}

}  // namespace

TEST(Aerial, RenderIsTheTableLookUpOfEachPixel) {
  const Scene s = scene(40, 30, 0);
  const AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  const AerialAnalysis a = analysis(s, p, kBeta1);
  const AerialResult r = apply_aerial(s.rgb, s.range, p, a);
  ASSERT_EQ(a.sensitivity.space, SensitivitySpace::camera_rgb);  // set by analysis(); xyz is tested below
  // Independent double arithmetic: I = I0 e^{-beta s} + A (1 - e^{-beta s}).
  // ln Gamma is linear in s for one exponential, so the table interpolation is
  // exact up to f32 storage of ln Gamma (|ln G| <= 3: 3 ulp ~ 1e-6 relative):
  // 2e-6 absolute on values <= 1.
  double worst = 0.0, worst_g = 0.0;
  for (std::size_t i = 0; i < s.range.pixels(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double g = std::exp(-kBeta1[c] * s.range.data[i]);
      const double want = s.rgb.data[i * 3 + c] * g + (*p.airlight)[c] * (1.0 - g);
      worst = std::max(worst, std::abs(r.rgb.data[i * 3 + c] - want));
      worst_g = std::max(worst_g, std::abs(r.attenuation.data[i * 3 + c] - g));
    }
  EXPECT_LT(worst, 2e-6);
  EXPECT_LT(worst_g, 2e-6);
}

TEST(Aerial, ApplyLooksUpGammaExactlyAsAt) {
  // apply_aerial splits AttenuationTable::at (log_at per pixel, exp_f over a
  // row) for speed: the attenuation map must be at(R) bit for bit, in render
  // (Gamma) and in re-render (Gamma2 / max(Gamma1, floor), f32 division).
  const Scene s = scene(40, 30, 4);
  AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  const AerialAnalysis a = analysis(s, p, kBeta1);
  const AerialResult r = apply_aerial(s.rgb, s.range, p, a);
  p.from_turbidity = 3.0;
  const AerialAnalysis b = analysis(s, p, kBeta2, kBeta1);
  const AerialResult re = apply_aerial(s.rgb, s.range, p, b);
  for (std::size_t i = 0; i < s.range.pixels(); ++i) {
    if (!std::isfinite(s.range.data[i])) continue;
    const auto g = a.gamma.at(s.range.data[i]);
    const auto g2 = b.gamma.at(s.range.data[i]), g1 = b.gamma_from.at(s.range.data[i]);
    for (int c = 0; c < 3; ++c) {
      ASSERT_EQ(r.attenuation.data[i * 3 + c], g[c]) << "pixel " << i << " channel " << c;
      ASSERT_EQ(re.attenuation.data[i * 3 + c], g2[c] / std::max(g1[c], 1e-3f)) << "pixel " << i << " channel " << c;
    }
  }
}

TEST(Aerial, DistanceScaleMultipliesTheRange) {
  // A 1:100 model at 10 m is the landscape at 1 km.
  const Scene s = scene(16, 12, 0);
  AerialParams p = given_airlight({0.6f, 0.6f, 0.6f});
  p.distance_scale = 100.0;
  Scene big = s;
  for (float& v : big.range.data) v *= 100.0f;
  AerialParams p1 = p;
  p1.distance_scale = 1.0;
  const AerialAnalysis a = analysis(s, p, kBeta1), a1 = analysis(big, p1, kBeta1);
  const AerialResult r = apply_aerial(s.rgb, s.range, p, a), r1 = apply_aerial(big.rgb, big.range, p1, a1);
  // Same s on both sides up to f32 rounding of R x 100: 1e-6.
  EXPECT_LT(compare(r.rgb, r1.rgb).max_abs, 1e-6);
}

TEST(Aerial, RenderThenRemoveReturnsTheInput) {
  const Scene s = scene(40, 30, 5);
  AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  const AerialAnalysis a = analysis(s, p, kBeta1);
  const AerialResult r = apply_aerial(s.rgb, s.range, p, a);
  AerialParams q = p;
  q.remove = true;
  AerialAnalysis b = analysis(s, q, kBeta1);
  ASSERT_EQ(b.mode, AerialMode::remove);
  const AerialResult back = apply_aerial(r.rgb, s.range, q, b);
  // Gamma >= e^{-3} = 0.05 here (above the floor): the render's f32 rounding
  // (~6e-8 on values <= 1) is amplified by 1/Gamma <= 20: 4e-6.
  EXPECT_LT(max_diff_known(back.rgb, s.rgb, s.range), 4e-6);
  EXPECT_EQ(back.floored_pixels, 0u);
}

TEST(Aerial, RemoveFloorsGammaAndCountsIt) {
  Scene s = scene(8, 8, 0);
  AerialParams p = given_airlight({0.5f, 0.5f, 0.5f});
  p.remove = true;
  p.gamma_floor = 0.1;  // Gamma_b at 1000 m is e^{-3} = 0.0498 < 0.1
  const AerialAnalysis a = analysis(s, p, kBeta1);
  const AerialResult r = apply_aerial(s.rgb, s.range, p, a);
  const std::size_t i = static_cast<std::size_t>(7) * 8;  // (0, 7): R = 1000 m
  const double g = std::exp(-3.0);
  EXPECT_NEAR(r.rgb.data[i * 3 + 2], (s.rgb.data[i * 3 + 2] - 0.5 * (1.0 - g)) / 0.1, 1e-5);
  EXPECT_GE(r.floored_pixels, 1u);
}

TEST(Aerial, RerenderEqualsRenderingTheCleanImageAtT2) {
  const Scene s = scene(40, 30, 5);
  const AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  const AerialResult i1 = apply_aerial(s.rgb, s.range, p, analysis(s, p, kBeta1));
  const AerialResult i2 = apply_aerial(s.rgb, s.range, p, analysis(s, p, kBeta2));
  AerialParams q = p;
  q.from_turbidity = 3.0;  // the value only selects the mode here: the tables are the closed forms
  const AerialAnalysis a = analysis(s, q, kBeta2, kBeta1);
  ASSERT_EQ(a.mode, AerialMode::rerender);
  const AerialResult re = apply_aerial(i1.rgb, s.range, q, a);
  // Eq. 3.13 is exact for the model; f32 rounding of I1, amplified by
  // Gamma2/Gamma1 <= 1 (beta2 > beta1), and of the ratio: 4e-6.
  EXPECT_LT(max_diff_known(re.rgb, i2.rgb, s.range), 4e-6);
  // Attenuation map of a re-render: Gamma2 / Gamma1.
  const std::size_t k = static_cast<std::size_t>(29) * 40;
  EXPECT_NEAR(re.attenuation.data[k * 3], std::exp(-(kBeta2[0] - kBeta1[0]) * s.range.data[k]), 2e-6);
}

TEST(Aerial, RerenderWithANewHorizonScalesTheIllumination) {
  // With Iinf1 != Iinf2, eq. 3.13 equals rendering I0 Iinf2/Iinf1 at T2 with
  // Iinf2 (the scene's light scales with the horizon's).
  const Scene s = scene(24, 16, 0);
  const Rgb a1 = {0.6f, 0.65f, 0.7f}, a2 = {0.9f, 0.8f, 0.6f};
  const AerialParams p1 = given_airlight(a1);
  const AerialResult i1 = apply_aerial(s.rgb, s.range, p1, analysis(s, p1, kBeta1));
  Scene lit = s;
  for (std::size_t i = 0; i < s.rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) lit.rgb.data[i * 3 + c] *= a2[c] / a1[c];
  const AerialParams p2 = given_airlight(a2);
  const AerialResult want = apply_aerial(lit.rgb, s.range, p2, analysis(s, p2, kBeta2));
  AerialParams q = p2;
  q.from_turbidity = 3.0;
  q.from_airlight = a1;
  const AerialResult re = apply_aerial(i1.rgb, s.range, q, analysis(s, q, kBeta2, kBeta1));
  EXPECT_LT(max_diff_known(re.rgb, want.rgb, s.range), 4e-6);  // as above, gains <= 1.5: 4e-6
}

TEST(Aerial, BlurWithLambdaToZeroIsTheIdentityOnTheRender) {
  const Scene s = scene(40, 30, 0);
  AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  const AerialResult plain = apply_aerial(s.rgb, s.range, p, analysis(s, p, kBeta1));
  p.lambda = 1e-4;  // sigma_max - sigma0 = 1e-4 sqrt(kappa_s') px
  const AerialAnalysis a = analysis(s, p, kBeta1);
  ASSERT_GT(a.plan.iterations, 0);  // the diffusion really runs
  const AerialResult blurred = apply_aerial(s.rgb, s.range, p, a);
  // The extra variance is ~2 sigma0 dsigma ~ 4e-4 px^2: a contrast-1 edge
  // changes by < 1e-3 of its step; colours here are <= 1: 1e-3.
  EXPECT_LT(compare(blurred.rgb, plain.rgb).max_abs, 1e-3);
}

TEST(Aerial, SixChannelBlurKeepsAConstantImageConstant) {
  // Constant colour at one range: F is constant in all six channels, and the
  // diffusion keeps a constant constant; the result is the unblurred render.
  Image rgb(32, 24, 3), range(32, 24, 1, 400.0f);
  for (std::size_t i = 0; i < rgb.pixels(); ++i) rgb.data[i * 3] = 0.2f, rgb.data[i * 3 + 1] = 0.5f, rgb.data[i * 3 + 2] = 0.9f;
  AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  p.lambda = 20.0;
  const Scene s{rgb, range};
  const AerialAnalysis a = analysis(s, p, kBeta1);
  ASSERT_GT(a.plan.iterations, 3);
  const AerialResult r = apply_aerial(rgb, range, p, a);
  for (int c = 0; c < 3; ++c) {
    const double g = std::exp(-kBeta1[c] * 400.0);
    const double want = rgb.data[c] * g + (*p.airlight)[c] * (1.0 - g);
    for (std::size_t i = 0; i < rgb.pixels(); ++i) {
      // The stencil's weights sum to 1 in f32: a few ulp per iteration: 1e-5.
      ASSERT_NEAR(r.rgb.data[i * 3 + c], want, 1e-5) << "pixel " << i << " channel " << c;
      ASSERT_NEAR(r.attenuation.data[i * 3 + c], g, 1e-5);
    }
  }
}

TEST(Aerial, SkyPixelsAreUnchangedInEveryMode) {
  const Scene s = scene(40, 30, 6);
  for (int mode = 0; mode < 3; ++mode) {
    AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
    const double* from = nullptr;
    if (mode == 0) p.lambda = 10.0;  // the blur must not reach into the sky either
    if (mode == 1) p.from_turbidity = 2.0, from = kBeta1;
    if (mode == 2) p.remove = true;
    const AerialAnalysis a = analysis(s, p, kBeta2, from);
    // Both the measured range (unknown sky) and a prepared-like range where
    // the sky has a value: the analysis' sky mask keeps it unchanged.
    Image prepared = s.range;
    for (float& v : prepared.data)
      if (!std::isfinite(v)) v = 1250.0f;
    for (const Image* rng : {&s.range, static_cast<const Image*>(&prepared)}) {
      const AerialResult r = apply_aerial(s.rgb, *rng, p, a);
      for (int y = 0; y < 6; ++y)
        for (int x = 0; x < 40; ++x)
          for (int c = 0; c < 3; ++c)
            ASSERT_EQ(r.rgb.at(x, y, c), s.rgb.at(x, y, c)) << "mode " << mode << " (" << x << ", " << y << ")";
    }
  }
}

TEST(Aerial, XyzSpaceIsMDiagGammaMInverse) {
  // In XYZ sensitivity space the operator on linear sRGB is M diag(Gamma) M^-1;
  // with equal Gamma in X, Y, Z it must reduce to the plain render.
  const Scene s = scene(20, 10, 0);
  AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
  AerialAnalysis a = analysis(s, p, kBeta1);
  a.sensitivity.space = SensitivitySpace::xyz;
  const double grey[3] = {2e-3, 2e-3, 2e-3};
  a.gamma = exp_table(grey, 1000.0);
  const AerialResult r = apply_aerial(s.rgb, s.range, p, a);
  double worst = 0.0;
  for (std::size_t i = 0; i < s.range.pixels(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double g = std::exp(-2e-3 * s.range.data[i]);
      worst = std::max(worst, std::abs(r.rgb.data[i * 3 + c] - (s.rgb.data[i * 3 + c] * g + (*p.airlight)[c] * (1 - g))));
    }
  // M and M^-1 (7 decimals) compose to I within 1e-7; f32 matrix products on
  // values <= 1: 2e-6.
  EXPECT_LT(worst, 2e-6);
}

TEST(Aerial, AirlightEstimates) {
  // Sky >= 0.5 % of the frame: its per-channel median.
  Scene s = scene(40, 30, 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 40; ++x) s.rgb.at(x, y, 0) = 0.6f, s.rgb.at(x, y, 1) = 0.7f, s.rgb.at(x, y, 2) = 0.8f;
  AerialAnalysis a = analyse_aerial(s.rgb, s.range, AerialParams{});
  EXPECT_EQ(a.airlight, (std::array<float, 3>{0.6f, 0.7f, 0.8f}));
  EXPECT_NE(a.airlight_source.find("sky"), std::string::npos);
  // No sky: the brightest 10 % of the 1 % most distant pixels (here the 12
  // farthest of 1200, their brightest one) -> that pixel's colour.
  Scene n = scene(40, 30, 0);
  for (int k = 0; k < 12; ++k) n.range.at(k, 0) = 5000.0f + k, n.rgb.at(k, 0, 0) = n.rgb.at(k, 0, 1) = n.rgb.at(k, 0, 2) = 0.1f;
  n.rgb.at(3, 0, 0) = 0.9f, n.rgb.at(3, 0, 1) = 0.91f, n.rgb.at(3, 0, 2) = 0.92f;
  a = analyse_aerial(n.rgb, n.range, AerialParams{});
  EXPECT_EQ(a.airlight, (std::array<float, 3>{0.9f, 0.91f, 0.92f}));
}

TEST(Aerial, BadInputsNameTheFlag) {
  const Scene s = scene(8, 8, 0);
  auto message = [&](AerialParams p, const Image& range) {
    try {
      analyse_aerial(s.rgb, range, p);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  AerialParams p;
  p.atmosphere.turbidity = 25.0;
  EXPECT_NE(message(p, s.range).find("--turbidity"), std::string::npos) << message(p, s.range);
  p = {};
  p.atmosphere.turbidity = 0.5;
  EXPECT_NE(message(p, s.range).find("--turbidity"), std::string::npos);
  p = {};
  p.atmosphere.altitude_m = 9500.0;
  EXPECT_NE(message(p, s.range).find("--altitude"), std::string::npos) << message(p, s.range);
  p = {};
  p.atmosphere.altitude_m = -600.0;
  EXPECT_NE(message(p, s.range).find("--altitude"), std::string::npos);
  p = {};
  p.remove = true;
  p.from_turbidity = 2.0;
  const std::string m = message(p, s.range);
  EXPECT_NE(m.find("--remove"), std::string::npos) << m;
  EXPECT_NE(m.find("--from-turbidity"), std::string::npos) << m;
  p = {};
  p.from_airlight = Rgb{0.5f, 0.5f, 0.5f};
  EXPECT_NE(message(p, s.range).find("--from-horizon"), std::string::npos);
  p = {};
  p.remove = true;
  p.lambda = 5.0;
  EXPECT_NE(message(p, s.range).find("--lambda"), std::string::npos);
  p = {};
  p.gamma_floor = 0.0;
  EXPECT_NE(message(p, s.range).find("--gamma-floor"), std::string::npos);
  p = {};
  p.distance_scale = 0.0;
  EXPECT_NE(message(p, s.range).find("--distance-scale"), std::string::npos);
  p = {};
  p.from_turbidity = 2.0;
  p.from_airlight = Rgb{0.5f, 0.0f, 0.5f};
  EXPECT_NE(message(p, s.range).find("--from-airlight"), std::string::npos) << message(p, s.range);
  EXPECT_NE(message(AerialParams{}, Image(9, 8, 1, 5.0f)).find("does not match"), std::string::npos);
}

TEST(Aerial, DeclarationHasEveryFlag) {
  const auto& t = aerial_param_table();
  for (const char* n : {"turbidity", "altitude", "sensitivity", "airlight", "distance-scale", "from-turbidity",
                        "from-airlight", "remove", "gamma-floor", "lambda", "sigma0", "scheme", "precision",
                        "rho-max", "edge-rate"})
    EXPECT_NE(t.find(n), nullptr) << n;
  const auto& air = t.at("airlight").spec.aliases;
  EXPECT_NE(std::find(air.begin(), air.end(), "horizon"), air.end());
  EXPECT_NE(std::find(air.begin(), air.end(), "fog-color"), air.end());
  const auto& from = t.at("from-airlight").spec.aliases;
  EXPECT_NE(std::find(from.begin(), from.end(), "from-horizon"), from.end());
  // The record round-trips every field.
  AerialParams p;
  p.atmosphere = {7.5, 1200.0};
  p.from_turbidity = 3.0;
  p.from_airlight = Rgb{0.1f, 0.2f, 0.3f};
  p.lambda = 4.0;
  AerialParams q;
  t.from_json(q, t.to_json(p), "test");
  EXPECT_EQ(t.to_json(q), t.to_json(p));
}

// ---- GPU = CPU --------------------------------------------------------------------------

TEST(AerialGpu, MatchesTheCpuInEveryMode) {
  BRUME_REQUIRE_GPU(ctx);
  const Scene s = scene(64, 48, 8);
  Image prepared = s.range;
  for (float& v : prepared.data)
    if (!std::isfinite(v)) v = 1250.0f;
  for (int mode = 0; mode < 4; ++mode) {
    AerialParams p = given_airlight({0.7f, 0.75f, 0.8f});
    const double* from = nullptr;
    if (mode == 1) p.lambda = 12.0;
    if (mode == 2) p.from_turbidity = 2.0, from = kBeta1;
    if (mode == 3) p.remove = true;
    AerialAnalysis a = analysis(s, p, kBeta2, from);
    const AerialResult cpu = apply_aerial(s.rgb, prepared, p, a);
    GpuAerial g(*ctx, s.rgb, prepared);
    const AerialResult gpu = g.render(p, a);
    // f32 on both sides; the GPU's exp and division are not correctly
    // rounded (a few ulp) and remove amplifies by 1/Gamma <= 55: RMS 1e-3.
    const Diff d = compare(gpu.rgb, cpu.rgb), da = compare(gpu.attenuation, cpu.attenuation);
    EXPECT_LE(d.rms, 1e-3) << "mode " << mode << ": " << d;
    EXPECT_LE(da.rms, 1e-3) << "mode " << mode << ": " << da;
    EXPECT_EQ(gpu.floored_pixels, cpu.floored_pixels) << "mode " << mode;
    for (int x = 0; x < 64; ++x) ASSERT_EQ(gpu.rgb.at(x, 0, 1), s.rgb.at(x, 0, 1));  // sky kept exactly
  }
}

// ---- speed paths (issue #10): the fast forms must give the plain forms' numbers ----

TEST(Aerial, SkyMedianIsExactlyNthElement) {
  // The horizon estimate counts keys in a 16-bit histogram, then selects in
  // one bin. Reference: nth_element over every sky value (the code it
  // replaced), k = n/2. Cases that stress the bins: negatives (key order
  // reversed), many ties, a flat channel (every value in one bin), values
  // differing only below the top 16 bits, and an odd sky count.
  std::mt19937 rng(11);
  const int W = 97, H = 60, sky_rows = 31;  // 3007 sky pixels: odd
  Scene s = scene(W, H, sky_rows);
  std::uniform_real_distribution<float> wide(-1.0f, 2.0f);
  std::uniform_int_distribution<int> level(0, 4), fine(0, 4000);
  for (int y = 0; y < sky_rows; ++y)
    for (int x = 0; x < W; ++x) {
      s.rgb.at(x, y, 0) = wide(rng);                         // negatives and positives
      s.rgb.at(x, y, 1) = 0.25f * static_cast<float>(level(rng));  // five values, heavy ties
      s.rgb.at(x, y, 2) = 0.5f + 1e-6f * static_cast<float>(fine(rng));  // one 16-bit bin, distinct low bits
    }
  s.rgb.at(5, 3, 2) = 0.5f;  // and a few outside that bin
  s.rgb.at(6, 3, 2) = 0.9f;
  s.rgb.at(7, 3, 0) = -0.0f;
  const AerialAnalysis a = analyse_aerial(s.rgb, s.range, AerialParams{});
  ASSERT_NE(a.airlight_source.find("sky"), std::string::npos);
  for (int c = 0; c < 3; ++c) {
    std::vector<float> v;
    for (int y = 0; y < sky_rows; ++y)
      for (int x = 0; x < W; ++x) v.push_back(s.rgb.at(x, y, c));
    auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    EXPECT_EQ(a.airlight[c], *mid) << "channel " << c;
  }
}

TEST(Aerial, ReusedBuffersGiveTheSamePixels) {
  // apply_aerial into caller buffers (fresh, stale from another frame, wrong
  // size, in place) and analyse_aerial into a reused analysis must equal the
  // returning forms bit for bit, in every mode, with and without the blur.
  const Scene s = scene(64, 48, 6), other = scene(64, 48, 20, 3), small = scene(20, 10, 2, 5);
  auto same = [](const Image& x, const Image& y) {
    return x.width == y.width && x.height == y.height && x.channels == y.channels &&
           std::memcmp(x.data.data(), y.data.data(), x.data.size() * sizeof(float)) == 0;
  };
  std::vector<AerialParams> modes(5);
  modes[0].atmosphere.turbidity = 8.0;                               // render, XYZ
  modes[1].atmosphere.turbidity = 8.0, modes[1].from_turbidity = 2.0;  // re-render
  modes[2].atmosphere.turbidity = 4.0, modes[2].remove = true;        // remove
  modes[3].atmosphere.turbidity = 8.0, modes[3].lambda = 4.0;         // render with the blur
  modes[4].atmosphere.turbidity = 8.0, modes[4].airlight = Rgb{0.7f, 0.8f, 0.9f};
  for (std::size_t m = 0; m < modes.size(); ++m) {
    SCOPED_TRACE("mode " + std::to_string(m));
    const AerialParams& p = modes[m];
    const AerialAnalysis a = analyse_aerial(s.rgb, s.range, p);
    const AerialResult want = apply_aerial(s.rgb, s.range, p, a);

    AerialAnalysis reused = analyse_aerial(other.rgb, other.range, p);  // another frame's mask and horizon
    analyse_aerial(s.rgb, s.range, p, reused);
    EXPECT_TRUE(same(reused.sky, a.sky));
    EXPECT_EQ(reused.airlight, a.airlight);
    EXPECT_EQ(reused.airlight_source, a.airlight_source);
    EXPECT_EQ(reused.range_max_m, a.range_max_m);
    // The thread count given (Exec::threads) changes nothing: 1 and 3 threads
    // against the default team, the sky median and the Gamma tables included.
    for (int threads : {1, 3}) {
      const AerialAnalysis t = analyse_aerial(s.rgb, s.range, p, threads);
      EXPECT_TRUE(same(t.sky, a.sky)) << threads;
      EXPECT_EQ(t.airlight, a.airlight) << threads;
      EXPECT_EQ(t.gamma.log_gamma, a.gamma.log_gamma) << threads;
      EXPECT_EQ(t.gamma_from.log_gamma, a.gamma_from.log_gamma) << threads;
    }

    Image out = small.rgb, att(64, 48, 3, NAN), scale;  // wrong size; stale NaNs; empty
    const std::size_t floored = apply_aerial(s.rgb, s.range, p, reused, out, AerialMaps{&att, &scale});
    EXPECT_TRUE(same(out, want.rgb));
    EXPECT_TRUE(same(att, want.attenuation));
    EXPECT_TRUE(same(scale, want.scale));
    EXPECT_EQ(floored, want.floored_pixels);

    Image stale(64, 48, 3, NAN);  // image only, into a buffer holding garbage
    apply_aerial(s.rgb, s.range, p, a, stale);
    EXPECT_TRUE(same(stale, want.rgb));

    Image in_place = s.rgb;
    apply_aerial(in_place, s.range, p, a, in_place);
    EXPECT_TRUE(same(in_place, want.rgb));
  }
}

TEST(Aerial, ReusedBuffersMustNotAliasTheInputs) {
  const Scene s = scene(16, 12, 2);
  const AerialParams p;
  const AerialAnalysis a = analyse_aerial(s.rgb, s.range, p);
  Image rgb = s.rgb, range = s.range, out;
  EXPECT_NE(error_of([&] { apply_aerial(rgb, range, p, a, out, AerialMaps{&rgb, nullptr}); }).find("own Image"),
            std::string::npos);
  EXPECT_NE(error_of([&] { apply_aerial(rgb, range, p, a, range); }).find("own Image"), std::string::npos);
  // Untouched (compared as bits: the sky is NaN).
  EXPECT_EQ(std::memcmp(range.data.data(), s.range.data.data(), range.data.size() * sizeof(float)), 0);
}
