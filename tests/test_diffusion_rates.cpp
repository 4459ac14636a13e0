// Diffusion engine, issue #9 item 4: the per-edge conductance input (depth of
// field), the per-pixel rate input, and any channel count. Closed forms
// (variance 2 w N, conservation, leak-free edges), the fast path against the
// double-precision reference, the sigma path as "rates, then the rate path"
// bit for bit, channel groups against independent runs, and the error paths.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>

#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "diffusion/diffusion_setup_math.hpp"
#include "shared/prelude_cpp.h"
#include "engine_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

// A deterministic value in [0, 1) from a pixel and a seed (no <random>
// distribution, whose output is implementation-defined).
float hash01(int x, int y, int seed) {
  std::uint32_t h = static_cast<std::uint32_t>(x) * 73856093u ^ static_cast<std::uint32_t>(y) * 19349663u ^
                    static_cast<std::uint32_t>(seed) * 83492791u;
  h ^= h >> 13, h *= 0x5bd1e995u, h ^= h >> 15;
  return static_cast<float>(h & 0xffffffu) / 16777216.0f;
}

// A textured C-channel image in [0, 1].
Image texture(int w, int h, int C) {
  Image f(w, h, C);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < C; ++c)
        f.at(x, y, c) = c % 3 == 0   ? 0.5f + 0.5f * std::sin(0.9f * x + c) * std::cos(0.7f * y)
                        : c % 3 == 1 ? (((x / 3 + y / 5 + c) % 2) ? 0.9f : 0.1f)
                                     : hash01(x, y, c);
  return f;
}

// Edge weights in [0, 1/4] that vary from edge to edge (a depth-of-field map
// with sharp and blurred parts), some exactly 0.
Image weight_map(int w, int h, int seed) {
  Image m(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float v = hash01(x, y, seed);
      m.at(x, y) = v < 0.15f ? 0.0f : 0.25f * v;
    }
  return m;
}


DiffusionParams rate_params(Scheme s, Precision p = Precision::f32) {
  DiffusionParams d;
  d.scheme = s;
  d.precision = p;
  return d;
}

Exec reference_exec() {
  Exec e;
  e.path = Path::reference;
  return e;
}

// Channels [c0, c0 + n) of f as an n-channel image, and back.
Image channels(const Image& f, int c0, int n) {
  Image g(f.width, f.height, n);
  for (std::size_t i = 0; i < f.pixels(); ++i)
    for (int c = 0; c < n; ++c) g.data[i * n + c] = f.data[i * f.channels + c0 + c];
  return g;
}

double channel_sum(const Image& f, int c) {
  double s = 0.0;
  for (std::size_t i = 0; i < f.pixels(); ++i) s += f.data[i * f.channels + c];
  return s;
}


}  // namespace

// ---- Conductance path: closed forms ------------------------------------------

TEST(DiffusionConductance, ImpulseSpreadsToVarianceTwoWN) {
  // Each explicit step with a constant edge weight w adds exactly 2w to the
  // per-axis variance of a distribution (its discrete kernel has second
  // moment 2w and mean 0), so N steps give 2wN while no mass reaches the
  // border. Tolerance 1e-4 relative: float rounding of ~4000 values over 100 steps.
  for (float g : {0.4f, 0.8f, 1.0f}) {
    const float w = 0.25f * g;
    const int N = 100, n = 81;
    Image f(n, n, 1, 0.0f);
    f.at(n / 2, n / 2) = 1.0f;
    diffuse_conductance(f, Image(n, n, 1, w), Image(n, n, 1, w), N);
    double m = 0, vx = 0, vy = 0;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double v = f.at(x, y);
        m += v, vx += v * (x - n / 2) * (x - n / 2), vy += v * (y - n / 2) * (y - n / 2);
      }
    EXPECT_NEAR(vx / m / (2.0 * w * N), 1.0, 1e-4) << "g " << g;
    EXPECT_NEAR(vy / m / (2.0 * w * N), 1.0, 1e-4) << "g " << g;
  }
}

TEST(DiffusionConductance, ConstantWeightIsAGaussianOfVarianceTwoWN) {
  // Constant w = g/4 against a true Gaussian convolution of sigma^2 = 2wN
  // (double, same mirror boundary), on the smooth channel of the texture
  // (see the next test for why not on pixel noise at w = 1/4). The explicit
  // kernel is a lattice heat kernel, not a sampled Gaussian: the discrete
  // step's fourth moment differs from a Gaussian's by an amount growing with
  // w, which leaves (measured) 5e-6 RMS at g = 0.6 and 2e-5 at g = 1 on this
  // smooth image at sigma ~ 4.5, largest (< 4e-4) at the corners, where the
  // mirror puts a kink in the sine; 6e-5 RMS / 1e-3 max leave room, while
  // half the iterations (the wrong variance) misses by ~1.7e-3 RMS.
  for (float g : {0.6f, 1.0f}) {
    const float w = 0.25f * g;
    const int N = static_cast<int>(std::lround(20.0 / (2.0 * w)));  // sigma^2 = 20
    Image f = channels(texture(96, 80, 1), 0, 1);
    const Image ref = gaussian_reference(f, std::sqrt(2.0 * w * N));
    Image fast = f, wrong = f;
    diffuse_conductance(fast, Image(96, 80, 1, w), Image(96, 80, 1, w), N);
    const Diff d = compare(fast, ref);
    RecordProperty("rms_g" + std::to_string(g), std::to_string(d.rms));
    EXPECT_LE(d.rms, 6e-5) << "g " << g << ": " << d;
    EXPECT_LE(d.max_abs, 1e-3) << "g " << g << ": " << d;
    diffuse_conductance(wrong, Image(96, 80, 1, w), Image(96, 80, 1, w), N / 2);
    const Diff dw = compare(wrong, ref);
    EXPECT_GT(dw.rms, 1e-3) << "g " << g << ": " << dw;
  }
}

TEST(DiffusionConductance, CheckerboardDecaysBy1Minus8WPerStep) {
  // Von Neumann analysis of the explicit step: the mode (-1)^(x+y) is
  // multiplied by 1 - 8w. At the stability limit w = 1/4 it is not damped at
  // all (it flips sign), so pixel-scale noise survives any number of steps:
  // depth of field wants g < 1 (w < 1/4) where it must smooth noise, as the
  // invariant-exact scheme's default rho_max 0.2 does. Interior pixels after
  // one step, tolerance: float rounding of w (1e-7) times 8 neighbours.
  for (float w : {0.25f, 0.2f, 0.1f}) {
    Image f(16, 16, 1);
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) f.at(x, y) = (x + y) % 2 ? -0.5f : 0.5f;
    Image g = f;
    diffuse_conductance(g, Image(16, 16, 1, w), Image(16, 16, 1, w), 1);
    for (int y = 1; y < 15; ++y)
      for (int x = 1; x < 15; ++x)
        ASSERT_NEAR(g.at(x, y), (1.0 - 8.0 * w) * f.at(x, y), 1e-6) << "w " << w << " (" << x << ", " << y << ")";
  }
}

TEST(DiffusionConductance, MassIsConservedForAnyWeights) {
  // The flux w (F_n - F) is antisymmetric across each edge, whatever the
  // weights. Reference (double, each value rounded to float once at the
  // end, 6e-8 relative, random in sign): 1e-8 relative. Fast (float): rounding of
  // ~5000 values in [0, 1] over 60 steps, 1e-5 relative.
  const Image wx = weight_map(71, 67, 1), wy = weight_map(71, 67, 2);
  for (const bool ref : {false, true}) {
    Image f = texture(71, 67, 5);
    Image g = f;
    diffuse_conductance(g, wx, wy, 60, Precision::f32, ref ? reference_exec() : Exec{});
    for (int c = 0; c < 5; ++c)
      EXPECT_NEAR(channel_sum(g, c) / channel_sum(f, c), 1.0, ref ? 1e-8 : 1e-5) << (ref ? "reference" : "fast")
                                                                               << " channel " << c;
  }
}

TEST(DiffusionConductance, PixelWithFourZeroEdgesNeverChanges) {
  // F(x) += sum w (F_n - F(x)) with every w = 0 adds exact zeros: the pixel
  // keeps its bits, fast and reference, f32 and f16 (the value is already
  // binary16 here, so rounding keeps it too).
  Image wx = weight_map(40, 30, 3), wy = weight_map(40, 30, 4);
  const int px = 17, py = 11;
  wx.at(px - 1, py) = wx.at(px, py) = 0.0f;
  wy.at(px, py - 1) = wy.at(px, py) = 0.0f;
  Image f = texture(40, 30, 4);
  for (int c = 0; c < 4; ++c) f.at(px, py, c) = 0.375f + 0.125f * c;  // binary16-exact
  for (const bool ref : {false, true})
    for (Precision p : {Precision::f32, Precision::f16}) {
      Image g = f;
      diffuse_conductance(g, wx, wy, 50, p, ref ? reference_exec() : Exec{});
      for (int c = 0; c < 4; ++c) EXPECT_EQ(g.at(px, py, c), f.at(px, py, c)) << (ref ? "reference " : "fast ") << to_string(p);
      // Its neighbours did change (the test is not vacuous).
      EXPECT_NE(g.at(px + 1, py, 0), f.at(px + 1, py, 0));
    }
}

TEST(DiffusionConductance, ZeroEdgeBetweenRegionsIsLeakFree) {
  // w = 0 on every edge between columns 31 and 32: the regions exchange
  // nothing at all. Two images that differ only on the left give the right
  // region bit for bit the same, and a right region of zeros stays zero.
  const int W = 64, H = 40;
  Image wx(W, H, 1, 0.25f), wy(W, H, 1, 0.25f);
  for (int y = 0; y < H; ++y) wx.at(31, y) = 0.0f;
  Image a = texture(W, H, 4), b = a;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < 32; ++x)
      for (int c = 0; c < 4; ++c) b.at(x, y, c) = 1.0f - a.at(x, y, c);
  for (int y = 0; y < H; ++y)
    for (int x = 32; x < W; ++x) a.at(x, y, 0) = b.at(x, y, 0) = 0.0f;
  for (const bool ref : {false, true}) {
    Image ga = a, gb = b;
    const Exec ex = ref ? reference_exec() : Exec{};
    diffuse_conductance(ga, wx, wy, 200, Precision::f32, ex);
    diffuse_conductance(gb, wx, wy, 200, Precision::f32, ex);
    for (int y = 0; y < H; ++y)
      for (int x = 32; x < W; ++x) {
        ASSERT_EQ(ga.at(x, y, 0), 0.0f) << "(" << x << ", " << y << ")";
        for (int c = 1; c < 4; ++c) ASSERT_EQ(ga.at(x, y, c), gb.at(x, y, c)) << "(" << x << ", " << y << ")";
      }
    EXPECT_NE(ga.at(30, 20, 1), gb.at(30, 20, 1));  // the left sides did diffuse differently
  }
}

TEST(DiffusionConductance, FastMatchesReference) {
  // Varying weights, 6 channels (two groups of four in the fast path), f32
  // and f16. f32: float rounding of values in [0, 1] over 80 steps, a few ulp
  // each, 2e-5. f16: both round to binary16 every step, but a value near a
  // rounding boundary can round differently, one half-ulp (2^-12 near 1) per
  // step at worst; isolated pixels, RMS far below.
  const Image wx = weight_map(73, 51, 5), wy = weight_map(73, 51, 6);
  struct Case {
    Precision p;
    double max_tol, rms_tol;
  };
  for (const Case c : {Case{Precision::f32, 2e-5, 2e-6}, Case{Precision::f16, 1e-2, 5e-4}}) {
    Image f = texture(73, 51, 6);
    Image fast = f, ref = f;
    diffuse_conductance(fast, wx, wy, 80, c.p);
    diffuse_conductance(ref, wx, wy, 80, c.p, reference_exec());
    const Diff d = compare(fast, ref);
    EXPECT_LE(d.max_abs, c.max_tol) << to_string(c.p) << ": " << d;
    EXPECT_LE(d.rms, c.rms_tol) << to_string(c.p) << ": " << d;
  }
}

TEST(DiffusionConductance, StandardSchemeIsTheConductanceOfItsEdgeRates) {
  // The standard scheme with rate map rho and edge rate `mode` is exactly
  // the conductance path with w = brume_edge_rate(rho_a, rho_b, mode) per
  // edge: same stencil, same order, so the same bits.
  const int W = 61, H = 47, N = 60;  // rates up to (5^2 - 1)/120 = 0.2
  const Image sigma = ramp_map(W, H, 1.0, 5.0);
  Image rho(W, H, 1);
  for (std::size_t i = 0; i < rho.data.size(); ++i)
    rho.data[i] = shared::brume_standard_rate(sigma.data[i], 1.0f, static_cast<float>(N));
  for (EdgeRate e : {EdgeRate::mean, EdgeRate::min, EdgeRate::harmonic}) {
    Image wx(W, H, 1, 0.0f), wy(W, H, 1, 0.0f);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        if (x + 1 < W) wx.at(x, y) = shared::brume_edge_rate(rho.at(x, y), rho.at(x + 1, y), static_cast<int>(e));
        if (y + 1 < H) wy.at(x, y) = shared::brume_edge_rate(rho.at(x, y), rho.at(x, y + 1), static_cast<int>(e));
      }
    Image a = texture(W, H, 4), b = a;
    DiffusionParams dp = rate_params(Scheme::standard);
    dp.edge_rate = e;
    diffuse_rates(a, rho, N, dp);
    diffuse_conductance(b, wx, wy, N);
    EXPECT_EQ(a.data, b.data) << to_string(e);
  }
}

// ---- Rate path ------------------------------------------------------------------

TEST(DiffusionRates, RatesFromSigmaGiveTheSigmaPathBitForBit) {
  // The sigma path is "rho from sigma (eq. 13 / 18, the shared float
  // formulas; eq. 18's ln that of diffusion_setup_math.hpp), then the rate
  // path": the same rate map given directly must
  // give the same bits, every scheme, f32 and f16, varying and constant maps.
  // The reference computes its rates from sigma in double, so there the two
  // differ by the float rounding of rho (< 1e-7 relative): 1e-6.
  const int W = 73, H = 51;
  for (Scheme s : {Scheme::standard, Scheme::invariant, Scheme::invariant_exact})
    for (Precision p : {Precision::f32, Precision::f16})
      for (bool uniform : {false, true}) {
        const double smax = 6.0;
        const Image sigma = uniform ? Image(W, H, 1, 6.0f) : ramp_map(W, H, 1.0, smax);
        const DiffusionParams dp = rate_params(s, p);
        const int N = plan_diffusion(dp, smax).iterations;
        Image rho(W, H, 1);
        for (std::size_t i = 0; i < rho.data.size(); ++i)
          rho.data[i] = s == Scheme::standard
                            ? shared::brume_standard_rate(sigma.data[i], 1.0f, static_cast<float>(N))
                            : cpu::setup_math::logf1(sigma.data[i] / 1.0f) / static_cast<float>(N);  // the fast path's rate
        Image a = texture(W, H, 4), b = a;
        diffuse(a, sigma, smax, dp);
        const DiffusionPlan plan = diffuse_rates(b, rho, N, dp);
        EXPECT_EQ(plan.iterations, N);
        EXPECT_EQ(a.data, b.data) << to_string(s) << " " << to_string(p) << (uniform ? " uniform" : "");
        if (p == Precision::f32) {
          Image ra = texture(W, H, 4), rb = ra;
          diffuse(ra, sigma, smax, dp, reference_exec());
          diffuse_rates(rb, rho, N, dp, reference_exec());
          EXPECT_LE(compare(ra, rb).max_abs, 1e-6) << "reference " << to_string(s);
        }
      }
}

TEST(DiffusionRates, FastMatchesReferenceOnAnArbitraryRateMap) {
  // A rate map not derived from any sigma (rates in [0, 1/4] with zeros),
  // every scheme and edge rate; tolerances as DiffusionFastPath (f32): float
  // rounding over 12-30 iterations and the fast path's running product for
  // sigma_k (relative drift < 1e-6).
  const Image rho = weight_map(67, 53, 9);
  for (Scheme s : {Scheme::standard, Scheme::invariant, Scheme::invariant_exact})
    for (EdgeRate e : {EdgeRate::mean, EdgeRate::min, EdgeRate::harmonic}) {
      DiffusionParams dp = rate_params(s);
      dp.edge_rate = e;
      const int N = s == Scheme::standard ? 30 : 12;
      Image fast = texture(67, 53, 4), ref = fast;
      diffuse_rates(fast, rho, N, dp);
      diffuse_rates(ref, rho, N, dp, reference_exec());
      const Diff d = compare(fast, ref);
      EXPECT_LE(d.max_abs, 2e-5) << to_string(s) << " " << to_string(e) << ": " << d;
      EXPECT_LE(d.rms, 2e-6) << to_string(s) << " " << to_string(e) << ": " << d;
    }
}

TEST(DiffusionRates, PlanReportsTheScaleReached) {
  // Standard: sigma^2 = s0^2 + 2 N rho; invariant: sigma = s0 e^{N rho}.
  Image f(8, 8, 4, 0.5f), rho(8, 8, 1, 0.1f);
  rho.at(3, 3) = 0.2f;
  const DiffusionPlan a = diffuse_rates(f, rho, 50, rate_params(Scheme::standard));
  EXPECT_EQ(a.iterations, 50);
  EXPECT_NEAR(a.rho_max, 0.2, 1e-7);
  EXPECT_NEAR(a.sigma_max, std::sqrt(1.0 + 2.0 * 50 * 0.2), 1e-5);
  const DiffusionPlan b = diffuse_rates(f, rho, 10, rate_params(Scheme::invariant_exact));
  EXPECT_NEAR(b.sigma_max, std::exp(10 * 0.2), 1e-4);
}

// ---- Any channel count ---------------------------------------------------------

TEST(DiffusionChannels, SixChannelsEqualIndependentFourAndTwoChannelRuns) {
  // One sigma (or rate, or weight) map for all channels; the channels are
  // independent, so a 6-channel run is a 4-channel and a 2-channel run, bit
  // for bit, on every input and both precisions.
  const int W = 59, H = 43;
  const Image sigma = ramp_map(W, H, 1.0, 7.0), wx = weight_map(W, H, 11), wy = weight_map(W, H, 12);
  const Image rho = weight_map(W, H, 13);
  const Image f = texture(W, H, 6);
  for (Precision p : {Precision::f32, Precision::f16}) {
    struct Run {
      const char* name;
      std::function<void(Image&)> fn;
    };
    const Run runs[] = {
        {"sigma invariant-exact", [&](Image& g) { diffuse(g, sigma, 7.0, rate_params(Scheme::invariant_exact, p)); }},
        {"sigma standard", [&](Image& g) { diffuse(g, sigma, 7.0, rate_params(Scheme::standard, p)); }},
        {"rates invariant", [&](Image& g) { diffuse_rates(g, rho, 9, rate_params(Scheme::invariant, p)); }},
        {"conductance", [&](Image& g) { diffuse_conductance(g, wx, wy, 25, p); }},
    };
    for (const Run& r : runs) {
      Image all = f, lo = channels(f, 0, 4), hi = channels(f, 4, 2);
      r.fn(all);
      r.fn(lo);
      r.fn(hi);
      EXPECT_EQ(channels(all, 0, 4).data, lo.data) << r.name << " " << to_string(p);
      EXPECT_EQ(channels(all, 4, 2).data, hi.data) << r.name << " " << to_string(p);
    }
  }
}

TEST(DiffusionChannels, OneChannelIsChannelZeroOfAFourChannelRun) {
  const int W = 52, H = 38;
  const Image sigma = ramp_map(W, H, 1.0, 6.0), f = texture(W, H, 4);
  for (Scheme s : {Scheme::standard, Scheme::invariant_exact}) {
    Image four = f, one = channels(f, 0, 1);
    diffuse(four, sigma, 6.0, rate_params(s));
    diffuse(one, sigma, 6.0, rate_params(s));
    EXPECT_EQ(one.data, channels(four, 0, 1).data) << to_string(s);
    EXPECT_NE(one.data, channels(f, 0, 1).data) << to_string(s);  // it did blur
  }
}

TEST(DiffusionChannels, SixChannelFastMatchesReference) {
  // The reference runs all six channels in one pass, the fast path in groups
  // of four: tolerances as DiffusionFastPath (f32).
  const Image sigma = ramp_map(61, 45, 1.0, 6.0);
  for (Scheme s : {Scheme::standard, Scheme::invariant_exact}) {
    Image fast = texture(61, 45, 6), ref = fast;
    diffuse(fast, sigma, 6.0, rate_params(s));
    diffuse(ref, sigma, 6.0, rate_params(s), reference_exec());
    const Diff d = compare(fast, ref);
    EXPECT_LE(d.max_abs, 2e-5) << to_string(s) << ": " << d;
    EXPECT_LE(d.rms, 2e-6) << to_string(s) << ": " << d;
  }
}

// ---- Input checks ----------------------------------------------------------------

TEST(DiffusionRatesErrors, BadInputsNameTheMapThePixelAndTheValue) {
  auto has = [](const std::string& msg, const std::string& part) {
    return msg.find(part) != std::string::npos;
  };
  Image f(8, 6, 3, 0.5f);
  const Image ok(8, 6, 1, 0.1f);
  const DiffusionParams dp = rate_params(Scheme::standard);

  // Size mismatch, for each map.
  std::string m = error_of([&] { diffuse_rates(f, Image(7, 6, 1, 0.1f), 5, dp); });
  EXPECT_TRUE(has(m, "rate map 7x6") && has(m, "8x6")) << m;
  m = error_of([&] { diffuse_conductance(f, Image(8, 5, 1, 0.1f), ok, 5); });
  EXPECT_TRUE(has(m, "conductance map wx 8x5")) << m;
  m = error_of([&] { diffuse_conductance(f, ok, Image(8, 6, 2, 0.1f), 5); });
  EXPECT_TRUE(has(m, "conductance map wy") && has(m, "2 channels")) << m;

  // Negative and NaN rates, weights above 1/4: the map, the pixel, the value.
  Image neg = ok;
  neg.at(5, 2) = -0.01f;
  m = error_of([&] { diffuse_rates(f, neg, 5, dp); });
  EXPECT_TRUE(has(m, "rate map pixel (5, 2)") && has(m, "-0.01") && has(m, "[0, 0.25]")) << m;
  Image nan = ok;
  nan.at(0, 4) = NAN;
  m = error_of([&] { diffuse_rates(f, nan, 5, rate_params(Scheme::invariant_exact)); });
  EXPECT_TRUE(has(m, "rate map pixel (0, 4)") && has(m, "nan")) << m;
  Image big = ok;
  big.at(7, 5) = 0.3f;  // the unused last column/row is still checked
  m = error_of([&] { diffuse_conductance(f, big, ok, 5); });
  EXPECT_TRUE(has(m, "conductance map wx pixel (7, 5)") && has(m, "0.3")) << m;
  m = error_of([&] { diffuse_conductance(f, ok, big, 5); });
  EXPECT_TRUE(has(m, "conductance map wy pixel (7, 5)")) << m;
  m = error_of([&] { diffuse_conductance(f, ok, nan, 5); });
  EXPECT_TRUE(has(m, "conductance map wy pixel (0, 4)")) << m;

  // Zero channels, negative iteration counts.
  Image none(8, 6, 0);
  m = error_of([&] { diffuse_conductance(none, ok, ok, 5); });
  EXPECT_TRUE(has(m, "at least one channel") && has(m, "0 channels")) << m;
  m = error_of([&] { diffuse(none, Image(8, 6, 1, 2.0f), 2.0, dp); });
  EXPECT_TRUE(has(m, "at least one channel")) << m;
  m = error_of([&] { diffuse_rates(f, ok, -1, dp); });
  EXPECT_TRUE(has(m, "iteration count -1")) << m;

  // Invariant offsets that would run off any image.
  m = error_of([&] { diffuse_rates(f, Image(8, 6, 1, 0.25f), 100, rate_params(Scheme::invariant)); });
  EXPECT_TRUE(has(m, "1e6 px")) << m;

  // The GPU's check keeps its 4-channel contract.
  m = error_of([&] { validate_diffusion(f, Image(8, 6, 1, 2.0f), 2.0, dp); });
  EXPECT_TRUE(has(m, "4-channel") && has(m, "3 channels")) << m;

  // Nothing was touched by the refused calls.
  for (float v : f.data) ASSERT_EQ(v, 0.5f);
}
