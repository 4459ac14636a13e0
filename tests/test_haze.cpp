// Haze effect: closed forms (no medium, absorption only, Koschmieder
// visibility), the airlight estimate, fast against reference, and real data.
#include <cmath>
#include <fstream>

#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/haze.hpp"
#include "brume/prepare.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

Image test_rgb(int w, int h) {
  Image im(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        im.at(x, y, c) = static_cast<float>(((x * (3 + c) + y * 7) % 23) / 22.0);
  return im;
}

Image test_range(int w, int h, double near_m, double far_m) {
  Image r(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) r.at(x, y) = static_cast<float>(near_m + (far_m - near_m) * (h - 1 - y) / (h - 1.0));
  return r;
}

// Middlebury 2005 third-size scene -> linear RGB and range in metres (the
// conversion itself is tested in test_depth.cpp).
bool load_middlebury(const std::string& scene, Image& rgb, Image& range) {
  const std::string view = "middlebury2005_thirdsize/" + scene + "/view1.png";
  if (!have_data(view)) return false;
  rgb = read_color(data_path(view));
  range = load_depth(middlebury2005(scene), rgb.width, rgb.height).range;
  return true;
}

// Mean squared forward-difference gradient, or 4-neighbour Laplacian, of
// luminance over the pixels whose mask is set.
double energy(const Image& im, const std::vector<char>& mask, bool laplacian) {
  auto Y = [&](int x, int y) { return 0.2126 * im.at(x, y, 0) + 0.7152 * im.at(x, y, 1) + 0.0722 * im.at(x, y, 2); };
  double s = 0;
  std::size_t n = 0;
  for (int y = 1; y < im.height - 1; ++y)
    for (int x = 1; x < im.width - 1; ++x) {
      if (!mask[static_cast<std::size_t>(y) * im.width + x]) continue;
      if (laplacian) {
        double l = Y(x - 1, y) + Y(x + 1, y) + Y(x, y - 1) + Y(x, y + 1) - 4 * Y(x, y);
        s += l * l;
      } else {
        double gx = Y(x + 1, y) - Y(x, y), gy = Y(x, y + 1) - Y(x, y);
        s += gx * gx + gy * gy;
      }
      ++n;
    }
  return s / std::max<std::size_t>(n, 1);
}

}  // namespace

TEST(Haze, NoMediumReturnsTheInput) {
  // kappa_a = kappa_s = 0: tau = 1, sigma_max = sigma0 (no iterations), and
  // eq. 4 adds (1 - 1) B = 0. Bit-exact.
  Image rgb = test_rgb(40, 30), range = test_range(40, 30, 1, 50);
  HazeParams p;
  p.kappa_a = p.kappa_s = 0.0;
  HazeAnalysis a = analyse_haze(rgb, range, p);
  EXPECT_EQ(a.plan.iterations, 0);
  HazeResult r = apply_haze(rgb, range, p, a);
  EXPECT_EQ(r.rgb.data, rgb.data);
  for (float t : r.transmission.data) EXPECT_EQ(t, 1.0f);
}

TEST(Haze, AbsorptionOnlyIsBeerLambertWithoutBlur) {
  // kappa_s = 0: no blur (sigma_max = sigma0), out = E tau + (1 - tau) B with
  // tau = exp(-kappa_a R / R_max), eq. 1 and 4, evaluated here in double.
  // Tolerance 1e-6: float exp and two float products on values <= 1.
  Image rgb = test_rgb(40, 30), range = test_range(40, 30, 2, 80);
  HazeParams p;
  p.kappa_a = 1.3;
  p.kappa_s = 0.0;
  p.airlight = Rgb{0.7f, 0.75f, 0.8f};
  HazeAnalysis a = analyse_haze(rgb, range, p);
  EXPECT_DOUBLE_EQ(a.range_max_m, 80.0);
  HazeResult r = apply_haze(rgb, range, p, a);
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    const double tau = std::exp(-1.3 * range.data[i] / 80.0);
    EXPECT_NEAR(r.transmission.data[i], tau, 1e-6);
    for (int c = 0; c < 3; ++c)
      ASSERT_NEAR(r.rgb.data[i * 3 + c], rgb.data[i * 3 + c] * tau + (1 - tau) * (*p.airlight)[c], 1e-6);
  }
}

TEST(Haze, VisibilityIsTheTwoPercentContrastDistance) {
  // Koschmieder: at R = V the transmission is exp(-3.912) = 0.0200. With
  // lambda = 0 there is no blur, so the pixel at 1000 m shows it directly.
  Image rgb = test_rgb(16, 16), range = test_range(16, 16, 100, 1000);
  HazeParams p;
  p.visibility_m = 1000.0;
  p.albedo = 0.8;
  p.lambda = 0.0;
  HazeAnalysis a = analyse_haze(rgb, range, p);
  EXPECT_NEAR(a.extinction_per_m, 3.912e-3, 1e-12);
  EXPECT_NEAR(a.kappa_s / (a.kappa_a + a.kappa_s), 0.8, 1e-12);
  HazeResult r = apply_haze(rgb, range, p, a);
  EXPECT_NEAR(r.transmission.at(0, 0), 0.0200, 1e-4);  // top row is 1000 m
  EXPECT_NEAR(r.transmission.at(0, 15), std::exp(-0.3912), 1e-6);
}

TEST(Haze, AirlightAutoIsTheSkyMedian) {
  Image rgb = test_rgb(50, 40), range = test_range(50, 40, 1, 20);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 50; ++x) {
      range.at(x, y) = NAN;  // sky
      rgb.at(x, y, 0) = 0.6f, rgb.at(x, y, 1) = 0.7f, rgb.at(x, y, 2) = 0.9f;
    }
  HazeAnalysis a = analyse_haze(rgb, range, HazeParams{});
  EXPECT_EQ(a.unknown_pixels, 400u);
  EXPECT_FLOAT_EQ(a.airlight[0], 0.6f);
  EXPECT_FLOAT_EQ(a.airlight[2], 0.9f);
  EXPECT_FLOAT_EQ(a.range_max_m, range.at(0, 8));  // the top known row; unknown pixels do not count
}

TEST(Haze, BadInputsAreErrors) {
  Image rgb = test_rgb(10, 10), range = test_range(10, 12, 1, 5);
  try {
    analyse_haze(rgb, range, HazeParams{});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("10x12"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("10x10"), std::string::npos) << e.what();
  }
  Image r2 = test_range(10, 10, 1, 5);
  r2.at(3, 4) = -2.0f;
  EXPECT_THROW(analyse_haze(rgb, r2, HazeParams{}), Error);
  HazeParams p;
  p.kappa_s = -0.1;
  EXPECT_THROW(analyse_haze(rgb, test_range(10, 10, 1, 5), p), Error);
  p.kappa_s = NAN;
  EXPECT_THROW(analyse_haze(rgb, test_range(10, 10, 1, 5), p), Error);
}

TEST(Haze, FastPathMatchesReferenceOnRealData) {
  Image rgb, range;
  BRUME_REQUIRE_DATA("middlebury2005_thirdsize/Moebius/view1.png");
  ASSERT_TRUE(load_middlebury("Moebius", rgb, range));
  HazeParams p;
  p.kappa_s = 1.0;
  p.lambda = 6.0;
  HazeAnalysis a = analyse_haze(rgb, range, p);
  Exec ref;
  ref.path = Path::reference;
  HazeResult fast = apply_haze(rgb, range, p, a), slow = apply_haze(rgb, range, p, a, ref);
  // Same tolerance reasoning as DiffusionFastPath: float vs double rounding.
  Diff d = compare(fast.rgb, slow.rgb);
  EXPECT_LE(d.max_abs, 2e-5) << d;
}

TEST(Haze, RealSceneKeepsNearSharpAndBlursFar) {
  // Middlebury 2005 Dolls (1.4-2.9 m). sigma grows as R'^{3/2}: with
  // kappa_s' = 1 and lambda = 2 (sigma_max = 3 px) the nearest fifth of the
  // scene (R' <= 0.55) gets sigma <= 1.8 px and the farthest fifth
  // (R' >= 0.73) sigma >= 2.25 px. The energy of the luminance gradient and
  // Laplacian kept in each band (after / before, divided by the band's mean
  // tau^2 so that only blur is measured, not the loss of contrast) must be
  // ordered accordingly. Measured: gradient 0.27 vs 0.10 (2.7x), Laplacian
  // 0.054 vs 0.0074 (7.3x); the bounds leave margin for other platforms' libm.
  Image rgb, range;
  BRUME_REQUIRE_DATA("middlebury2005_thirdsize/Dolls/view1.png");
  ASSERT_TRUE(load_middlebury("Dolls", rgb, range));
  HazeParams p;
  p.kappa_s = 1.0;
  p.lambda = 2.0;
  HazeAnalysis a = analyse_haze(rgb, range, p);
  HazeResult r = apply_haze(rgb, range, p, a);
  for (float t : r.transmission.data) {
    ASSERT_GE(t, 0.0f);
    ASSERT_LE(t, 1.0f);
  }
  for (float v : r.rgb.data) ASSERT_TRUE(std::isfinite(v));
  std::vector<float> known;
  for (float v : range.data)
    if (std::isfinite(v)) known.push_back(v);
  std::sort(known.begin(), known.end());
  const float q20 = known[known.size() / 5], q80 = known[known.size() * 4 / 5];
  std::vector<char> near(range.pixels()), far(range.pixels());
  double tn = 0, tf = 0;
  std::size_t nn = 0, nf = 0;
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    const float v = range.data[i];
    near[i] = std::isfinite(v) && v <= q20;
    far[i] = std::isfinite(v) && v >= q80;
    const double t = r.transmission.data[i];
    if (near[i]) tn += t * t, ++nn;
    if (far[i]) tf += t * t, ++nf;
  }
  for (bool lap : {false, true}) {
    const double keep_near = energy(r.rgb, near, lap) / energy(rgb, near, lap) / (tn / nn);
    const double keep_far = energy(r.rgb, far, lap) / energy(rgb, far, lap) / (tf / nf);
    RecordProperty(lap ? "laplacian_keep_near" : "gradient_keep_near", std::to_string(keep_near));
    RecordProperty(lap ? "laplacian_keep_far" : "gradient_keep_far", std::to_string(keep_far));
    EXPECT_GT(keep_near, (lap ? 4.0 : 2.0) * keep_far)
        << (lap ? "laplacian" : "gradient") << ": near " << keep_near << ", far " << keep_far;
    EXPECT_LT(keep_near, 1.0);  // haze never sharpens
  }
}

TEST(Haze, NaiveCompositeShowsGhostEdgesPremultipliedDoesNot) {
  // Hansard §2.1: far away, where the blur is large, a noisy range map makes
  // tau0 vary from pixel to pixel. The premultiplied composite blurs tau
  // together with the colour, so a uniform far surface stays smooth; the
  // naive composite multiplies the blurred colour by the sharp tau0 and
  // shows the range noise as a pattern ("ghost edges").
  const int n = 64;
  Image rgb(n, n, 3, 0.2f), range(n, n, 1);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) range.at(x, y) = ((x + y) % 2) ? 100.0f : 90.0f;
  HazeParams p;
  p.kappa_s = 2.0;
  p.lambda = 6.0;
  p.airlight = Rgb{0.9f, 0.9f, 0.9f};
  auto spread = [&](Composite c) {
    p.composite = c;
    HazeResult r = apply_haze(rgb, range, p, analyse_haze(rgb, range, p));
    float lo = 1e9f, hi = -1e9f;
    for (int y = 16; y < 48; ++y)
      for (int x = 16; x < 48; ++x) lo = std::min(lo, r.rgb.at(x, y, 0)), hi = std::max(hi, r.rgb.at(x, y, 0));
    return hi - lo;
  };
  const float premultiplied = spread(Composite::premultiplied), naive = spread(Composite::naive);
  EXPECT_LT(premultiplied, 1e-3f);
  EXPECT_GT(naive, 20.0f * premultiplied + 0.02f) << "naive " << naive << ", premultiplied " << premultiplied;
}

TEST(Haze, PreparedEth3dHasNoHardHorizon) {
  // ETH3D playground: laser ground truth, about half the pixels unknown
  // including the sky. Prepared with a horizon margin (mu = 8 px), the range
  // and the haze transmission change gradually where the scene meets the sky;
  // with the sky set to S_max right against the scene (mu = 0) they step.
  // Measured over every horizontally adjacent (scene, sky) pair: the mean
  // |step| of the prepared range relative to S_max - R, and the mean |step| of
  // the blurred transmission. Measured: range 0.029 vs 1.0; tau 0.0153 vs
  // 0.0305 (the diffusion itself already softens the hard version).
  const std::string rel = "eth3d_two_view/playground_1l/";
  BRUME_REQUIRE_DATA(rel + "disp0.pfm");
  Image rgb = read_color(data_path(rel + "im0.png"));
  DepthSource src;
  src.disparity = data_path(rel + "disp0.pfm");
  src.calib = data_path(rel + "calib.txt");
  Image range = load_depth(src, rgb.width, rgb.height).range;
  HazeParams p;
  p.kappa_s = 2.0;
  p.lambda = 4.0;
  HazeAnalysis a = analyse_haze(rgb, range, p);
  struct Steps {
    double range_rel, tau;
  };
  auto steps = [&](double mu) {
    PrepareParams pp;
    pp.sky_margin_px = mu;
    PrepareResult pr = prepare_range(range, pp);
    for (float v : pr.range.data) EXPECT_TRUE(std::isfinite(v) && v > 0);
    HazeResult r = apply_haze(rgb, pr.range, p, a);
    double sr = 0, st = 0;
    std::size_t n = 0;
    for (int y = 0; y < range.height; ++y)
      for (int x = 0; x + 1 < range.width; ++x) {
        const bool k0 = std::isfinite(range.at(x, y)), k1 = std::isfinite(range.at(x + 1, y));
        const bool sky0 = !k0 && pr.sky_mask.at(x, y) > 0.5f, sky1 = !k1 && pr.sky_mask.at(x + 1, y) > 0.5f;
        if (!((k0 && sky1) || (k1 && sky0))) continue;
        const float R = k0 ? range.at(x, y) : range.at(x + 1, y);
        sr += std::abs(pr.range.at(x + 1, y) - pr.range.at(x, y)) / (pr.s_max_m - R);
        st += std::abs(r.transmission.at(x + 1, y) - r.transmission.at(x, y));
        ++n;
      }
    EXPECT_GT(n, 100u);
    return Steps{sr / n, st / n};
  };
  const Steps matted = steps(8.0), hard = steps(0.0);
  RecordProperty("range_step_matted", std::to_string(matted.range_rel));
  RecordProperty("range_step_hard", std::to_string(hard.range_rel));
  RecordProperty("tau_step_matted", std::to_string(matted.tau));
  RecordProperty("tau_step_hard", std::to_string(hard.tau));
  EXPECT_NEAR(hard.range_rel, 1.0, 1e-6);  // without a margin the sky value sits right against the scene
  EXPECT_LT(matted.range_rel, 0.1) << "the Laplace margin must taper from the scene into the sky";
  EXPECT_LT(matted.tau, 0.7 * hard.tau) << "mean |d tau| across the horizon: matted " << matted.tau << ", hard " << hard.tau;
}
