// Inserting a virtual object with aerial perspective (include/brume/insert.hpp):
// the scene as its own object reproduces `brume aerial`, the depth test, Gamma
// for the object's own range against independent double arithmetic with a
// closed-form table, alpha edges, the blur's coverage, and the errors.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "brume/insert.hpp"
#include "effects/aerial/insert/insert_job.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

constexpr double kBeta[3] = {1.0e-3, 2.0e-3, 3.0e-3};  // [1/m] per channel

AttenuationTable exp_table(double s_max) {
  return AttenuationTable::from_function(
      [](double s) { return std::array<double, 3>{std::exp(-kBeta[0] * s), std::exp(-kBeta[1] * s),
                                                   std::exp(-kBeta[2] * s)}; },
      s_max);
}


// An opaque object covering the whole frame: (E, 1).
Image opaque(const Image& rgb) {
  Image o(rgb.width, rgb.height, 4, 1.0f);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) o.data[i * 4 + c] = rgb.data[i * 3 + c];
  return o;
}

AerialParams given_airlight() {
  AerialParams p;
  p.airlight = Rgb{0.7f, 0.75f, 0.8f};
  return p;
}

RangeStep prepare_off() {
  RangeStep r;
  r.mode = PrepareMode::off;
  return r;
}

double insert_max_diff(const Image& a, const Image& b, const Image& range) {
  double m = 0.0;
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    if (!std::isfinite(range.data[i])) continue;
    for (int c = 0; c < 3; ++c)
      m = std::max(m, std::abs(static_cast<double>(a.data[i * 3 + c]) - b.data[i * 3 + c]));
  }
  return m;
}

}  // namespace

TEST(Insert, SceneAsItsOwnObjectReproducesAerial) {
  // The clean scene as an opaque object at its own range covers every known
  // pixel (ties go to the object), whatever the photo is; its layer is then
  // Gamma E + (1 - Gamma) Iinf, aerial's render. Same table (same R_max), the
  // same f32 operations per pixel except the "+ 0 x photo" of the composite:
  // equal up to FMA contraction, 1e-6 on values <= 1. Default (spectral) sensitivity.
  const Scene clean = scene(40, 30, 5, 7), other = scene(40, 30, 5, 99);
  const AerialParams p = given_airlight();
  const AerialRun ref = run_aerial(clean.rgb, clean.range, p, prepare_off());
  const InsertRun ins = insert_object(other.rgb, clean.range, opaque(clean.rgb), clean.range, p, prepare_off());
  EXPECT_EQ(ins.analysis.visible_pixels, 40u * 25u);
  EXPECT_EQ(ins.analysis.hidden_pixels, 0u);
  EXPECT_LT(insert_max_diff(ins.result.rgb, ref.result.rgb, clean.range), 1e-6);
  // Sky (object absent): the photo itself.
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 40; ++x)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(ins.result.rgb.at(x, y, c), other.rgb.at(x, y, c));
}

TEST(Insert, SceneAsItsOwnObjectReproducesAerialWithTheBlur) {
  // With --lambda and no sky: the object covers the whole frame, so its seven
  // channels diffuse with aerial's sigma map; channels 0..5 are aerial's six
  // and the coverage stays 1 up to the stencil's f32 rounding (a few ulp per
  // iteration): 1e-5.
  const Scene clean = scene(40, 30, 0, 11), other = scene(40, 30, 0, 12);
  AerialParams p = given_airlight();
  p.atmosphere.turbidity = 8.0;
  p.lambda = 6.0;
  const AerialRun ref = run_aerial(clean.rgb, clean.range, p, prepare_off());
  ASSERT_GT(ref.analysis.plan.iterations, 3);
  const InsertRun ins = insert_object(other.rgb, clean.range, opaque(clean.rgb), clean.range, p, prepare_off());
  EXPECT_EQ(ins.analysis.aerial.plan.iterations, ref.analysis.plan.iterations);
  EXPECT_LT(compare(ins.result.rgb, ref.result.rgb).max_abs, 1e-5);
  // ... and the blur really changed the render (the test can fail).
  AerialParams sharp = p;
  sharp.lambda = 0.0;
  const AerialRun plain = run_aerial(clean.rgb, clean.range, sharp, prepare_off());
  EXPECT_GT(compare(ins.result.rgb, plain.result.rgb).max_abs, 1e-2);
}

TEST(Insert, ObjectBehindASceneSurfaceIsHidden) {
  // Scene at 100 m with sky on top; the object: a block at 200 m (behind the
  // scene, hidden), a block at 50 m (in front), one over the sky.
  const int W = 32, H = 24;
  Scene s = scene(W, H, 4, 3);
  for (std::size_t i = 4 * W; i < s.range.pixels(); ++i) s.range.data[i] = 100.0f;
  Image obj(W, H, 4, 0.0f), orange(W, H, 1, NAN);
  auto block = [&](int x0, int y0, int x1, int y1, float r) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        obj.at(x, y, 0) = 0.9f, obj.at(x, y, 1) = 0.2f, obj.at(x, y, 2) = 0.1f, obj.at(x, y, 3) = 1.0f;
        orange.at(x, y) = r;
      }
  };
  block(4, 8, 12, 20, 200.0f);   // behind: hidden
  block(16, 8, 24, 20, 50.0f);   // in front: visible
  block(10, 0, 20, 3, 5000.0f);  // over the sky: visible
  for (double lambda : {0.0, 8.0}) {
    AerialParams p = given_airlight();
    p.lambda = lambda;
    const InsertRun r = insert_object(s.rgb, s.range, obj, orange, p);
    EXPECT_EQ(r.analysis.hidden_pixels, 8u * 12u);
    EXPECT_EQ(r.analysis.visible_pixels, 8u * 12u + 10u * 3u);
    std::size_t changed = 0;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const bool visible = (x >= 16 && x < 24 && y >= 8 && y < 20) || (x >= 10 && x < 20 && y < 3);
        bool same = true;
        for (int c = 0; c < 3; ++c) {
          const float o = r.result.rgb.at(x, y, c), q = s.rgb.at(x, y, c);
          same = same && std::memcmp(&o, &q, sizeof o) == 0;
        }
        if (!visible) {
          ASSERT_TRUE(same) << "lambda " << lambda << " pixel (" << x << ", " << y << ") changed";
        }
        changed += same ? 0 : 1;
      }
    EXPECT_EQ(changed, 8u * 12u + 10u * 3u) << "lambda " << lambda;  // every visible pixel took the object
  }
}

TEST(Insert, ObjectInFrontGetsGammaForItsOwnRange) {
  // Independent double arithmetic with a closed-form table Gamma_c = e^{-beta_c s}
  // in camera-RGB space: out = alpha (E Gamma + A (1 - Gamma)) + (1 - alpha) P
  // at s = R_o distance_scale. ln Gamma is linear in s, so the table is exact up
  // to f32 storage of ln Gamma (~1e-6 relative): 2e-6 on values <= 1.
  const int W = 24, H = 16;
  Scene s = scene(W, H, 0, 5);  // scene 10 .. 1000 m
  Image obj(W, H, 4, 0.0f), orange(W, H, 1, NAN);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> col(0.0f, 1.0f), al(0.05f, 1.0f);
  for (int y = 2; y < 14; ++y)
    for (int x = 3; x < 20; ++x) {
      const float a = (x % 3 == 0) ? 1.0f : al(rng);
      for (int c = 0; c < 3; ++c) obj.at(x, y, c) = a * col(rng);  // premultiplied
      obj.at(x, y, 3) = a;
      orange.at(x, y) = 0.5f * s.range.at(x, y);  // always in front of the scene
    }
  AerialParams p = given_airlight();
  p.distance_scale = 3.0;
  InsertAnalysis a = analyse_insert(s.rgb, s.range, obj, orange, p);
  a.aerial.sensitivity.space = SensitivitySpace::camera_rgb;
  a.aerial.gamma = exp_table(a.aerial.range_max_m * p.distance_scale);
  const InsertResult r = apply_insert(s.rgb, s.range, obj, orange, p, a);
  double worst = 0.0;
  for (int y = 2; y < 14; ++y)
    for (int x = 3; x < 20; ++x) {
      const double alpha = obj.at(x, y, 3);
      for (int c = 0; c < 3; ++c) {
        const double g = std::exp(-kBeta[c] * orange.at(x, y) * 3.0);
        const double want = obj.at(x, y, c) * g + alpha * (*p.airlight)[c] * (1.0 - g) + (1.0 - alpha) * s.rgb.at(x, y, c);
        worst = std::max(worst, std::abs(r.rgb.at(x, y, c) - want));
      }
      ASSERT_EQ(r.coverage.at(x, y), obj.at(x, y, 3));
    }
  EXPECT_LT(worst, 2e-6);
}

TEST(Insert, HalfTransparentEdgeIsHalfObjectHalfPhoto) {
  // An alpha = 0.5 pixel: 0.5 x the attenuated object + 0.5 x the photo, per
  // channel; with Gamma from the closed-form table (2e-6 as above).
  const int W = 8, H = 8;
  Scene s = scene(W, H, 0, 9);
  Image obj(W, H, 4, 0.0f), orange(W, H, 1, NAN);
  const float E[3] = {0.9f, 0.4f, 0.1f};
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < 4; ++x) {
      const float a = x == 3 ? 0.5f : 1.0f;  // the edge column is half covered
      for (int c = 0; c < 3; ++c) obj.at(x, y, c) = a * E[c];
      obj.at(x, y, 3) = a;
      orange.at(x, y) = 5.0f;
    }
  AerialParams p = given_airlight();
  InsertAnalysis a = analyse_insert(s.rgb, s.range, obj, orange, p);
  a.aerial.sensitivity.space = SensitivitySpace::camera_rgb;
  a.aerial.gamma = exp_table(a.aerial.range_max_m);
  const InsertResult r = apply_insert(s.rgb, s.range, obj, orange, p, a);
  for (int y = 0; y < H; ++y)
    for (int c = 0; c < 3; ++c) {
      const double g = std::exp(-kBeta[c] * 5.0);
      const double attenuated = E[c] * g + (*p.airlight)[c] * (1.0 - g);
      EXPECT_NEAR(r.rgb.at(3, y, c), 0.5 * attenuated + 0.5 * s.rgb.at(3, y, c), 2e-6);
      EXPECT_NEAR(r.rgb.at(2, y, c), attenuated, 2e-6);
      EXPECT_EQ(r.rgb.at(4, y, c), s.rgb.at(4, y, c));
    }
}

TEST(Insert, BlurUsesTheBlurredCoverageForThePhoto) {
  // An opaque object of one colour E at one range in front of a photo of one
  // colour P. Its seven channels diffuse linearly: F = (Gamma E D, Gamma D, D),
  // D the blurred coverage, so every visible pixel must be
  //   out = D L + (1 - D) P,  L = Gamma E + (1 - Gamma) Iinf,
  // with L the unblurred object layer (the lambda = 0 run's interior pixel).
  // Composing the photo under the unblurred alpha (1 there) would give D L,
  // a dark fringe; the edge pixels really have D < 0.9. f32 stencil: 1e-5.
  const int W = 40, H = 30;
  const float P[3] = {0.1f, 0.6f, 0.3f};
  Image photo(W, H, 3), range(W, H, 1, 1000.0f), obj(W, H, 4, 0.0f), orange(W, H, 1, NAN);
  for (std::size_t i = 0; i < photo.pixels(); ++i)
    for (int c = 0; c < 3; ++c) photo.data[i * 3 + c] = P[c];
  for (int y = 8; y < 22; ++y)
    for (int x = 10; x < 30; ++x) {
      obj.at(x, y, 0) = 0.95f, obj.at(x, y, 1) = 0.2f, obj.at(x, y, 2) = 0.05f, obj.at(x, y, 3) = 1.0f;
      orange.at(x, y) = 900.0f;
    }
  AerialParams p = given_airlight();
  p.atmosphere.turbidity = 10.0;
  const InsertRun sharp = insert_object(photo, range, obj, orange, p);
  const float L[3] = {sharp.result.rgb.at(20, 15, 0), sharp.result.rgb.at(20, 15, 1), sharp.result.rgb.at(20, 15, 2)};
  p.lambda = 10.0;
  const InsertRun r = insert_object(photo, range, obj, orange, p);
  ASSERT_GT(r.analysis.aerial.plan.iterations, 3);
  EXPECT_LT(r.result.coverage.at(10, 15), 0.9f);  // the blur softened the edge
  double worst = 0.0;
  for (int y = 8; y < 22; ++y)
    for (int x = 10; x < 30; ++x) {
      const double d = r.result.coverage.at(x, y);
      for (int c = 0; c < 3; ++c)
        worst = std::max(worst, std::abs(r.result.rgb.at(x, y, c) - (d * L[c] + (1.0 - d) * P[c])));
    }
  EXPECT_LT(worst, 1e-5);
}

TEST(Insert, BadInputsNameWhatIsWrong) {
  const Scene s = scene(16, 12, 0, 1);
  const Image obj = opaque(s.rgb);
  const AerialParams p = given_airlight();
  auto message = [](auto&& f) {
    try {
      f();
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const Image small(8, 12, 4, 1.0f);
  EXPECT_NE(message([&] { insert_object(s.rgb, s.range, small, s.range, p); }).find("8x12"), std::string::npos);
  // Coverage without a range is absent, counted, the photo kept bit for bit.
  const Image no_range(16, 12, 1, NAN);
  const InsertRun absent = insert_object(s.rgb, s.range, obj, no_range, p);
  EXPECT_EQ(absent.analysis.coverage_without_range_pixels, 16u * 12u);
  EXPECT_EQ(absent.analysis.visible_pixels, 0u);
  EXPECT_EQ(std::memcmp(absent.result.rgb.data.data(), s.rgb.data.data(), s.rgb.data.size() * sizeof(float)), 0);
  Image negative = s.range;
  negative.at(3, 4) = -2.0f;
  EXPECT_NE(message([&] { insert_object(s.rgb, s.range, obj, negative, p); }).find("(3, 4)"), std::string::npos);
  AerialParams rm = p;
  rm.remove = true;
  EXPECT_NE(message([&] { insert_object(s.rgb, s.range, obj, s.range, rm); }).find("--remove"), std::string::npos);
  AerialParams t = p;
  t.atmosphere.turbidity = 30.0;
  EXPECT_NE(message([&] { insert_object(s.rgb, s.range, obj, s.range, t); }).find("--turbidity"), std::string::npos);
  Exec gpu;
  gpu.backend = Backend::gpu;
  EXPECT_NE(message([&] { insert_object(s.rgb, s.range, obj, s.range, p, {}, gpu); }).find("--backend cpu"),
            std::string::npos);
}

TEST(Insert, DeclarationOffersAerialsRenderFlagsOnly) {
  const auto& t = insert_job_table();
  for (const char* n : {"image", "range", "object", "object-range", "object-depth-scale", "turbidity", "altitude",
                        "sensitivity", "airlight", "distance-scale", "lambda", "sigma0", "scheme", "prepare", "out",
                        "record", "coverage", "scale-map"})
    EXPECT_NE(t.find(n), nullptr) << n;
  for (const char* n : {"from-turbidity", "from-airlight", "remove", "gamma-floor", "attenuation"})
    EXPECT_EQ(t.find(n), nullptr) << n;
  // A job survives its own record.
  InsertJob j;
  j.aerial.atmosphere.turbidity = 7.5;
  j.aerial.lambda = 2.0;
  j.object.object = "o.exr";
  j.object.object_depth_scale = 0.001;
  InsertJob back;
  t.from_json(back, t.to_json(j), "test");
  EXPECT_EQ(t.to_json(back), t.to_json(j));
}
