// The stub particle medium fogs a scan and an image through the medium
// interface (issue #53), checked against closed forms: Beer–Lambert beyond
// the sampled range, explicit particles within it.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "brume/medium.hpp"
#include "stub_medium.hpp"

using namespace brume;
using namespace brume::test;

namespace media_stub_tests {

// Float32 outputs of double formulas: 1e-6 relative is a few float ulps.
constexpr double kRel = 1e-6;

constexpr double kSigma = 0.02;    // [1/m]
constexpr double kSampled = 10.0;  // [m]

TEST(MediaStub, ScanBeerLambertBeyondTheSampledRangeAndEchoesWithin) {
  const StubMedium stub(kSigma, kSampled, {{{5.0, 0.0, 0.0}, 0.1, 80.0, {}}});
  const std::vector<float> in = {
      20.0f, 0.0f,  0.0f, 100.0f,  // through the particle at 5 m: its echo 80 beats 100·e^{−2σ(20−10)} = 67.0
      20.0f, 0.0f,  0.0f, 200.0f,  // the same beam, a brighter target: 200·e^{−0.4} = 134 beats the echo
      0.0f,  30.0f, 0.0f, 100.0f,  // no particle: Beer–Lambert over the analytic 20 m
      0.0f,  0.0f,  8.0f, 100.0f,  // within the sampled range and no particle: unchanged
      3.0f,  0.0f,  0.0f, 1.0f,    // the particle is behind the target: hidden, unchanged
  };
  std::vector<float> out(in.size());
  const ScanRun run = scan_through_media({&stub}, in.data(), out.data(), 5);
  EXPECT_EQ(run.points, 5u);
  EXPECT_EQ(run.echoes, 1u);
  // Point 0 moved to the particle's range along its beam, with the echo's intensity.
  EXPECT_NEAR(out[0], 5.0, 5.0 * kRel);
  EXPECT_EQ(out[1], 0.0f);
  EXPECT_EQ(out[2], 0.0f);
  EXPECT_NEAR(out[3], 80.0, 80.0 * kRel);
  const double hard = 200.0 * std::exp(-2.0 * kSigma * (20.0 - kSampled));
  EXPECT_EQ(out[4], 20.0f);
  EXPECT_NEAR(out[7], hard, hard * kRel);
  const double clear = 100.0 * std::exp(-2.0 * kSigma * (30.0 - kSampled));
  EXPECT_EQ(out[9], 30.0f);
  EXPECT_NEAR(out[11], clear, clear * kRel);
  EXPECT_EQ(out[15], 100.0f);
  EXPECT_EQ(out[16], 3.0f);
  EXPECT_EQ(out[19], 1.0f);
  const nlohmann::json block = stub.scan_record(run);
  EXPECT_EQ(block["medium"], "stub");
  EXPECT_EQ(block["echo_points"], 1);
}

// A 9x9 pinhole camera at the origin looking north (−z), the centre pixel's
// ray on the axis.
Camera axis_camera() {
  Camera cam;
  cam.k = {9.0, 9.0, 4.0, 4.0};
  cam.width = cam.height = 9;
  cam.position_m = {0.0, 0.0, 0.0};
  return cam;
}

TEST(MediaStub, ImageBeerLambertAndAParticleOverTheScene) {
  const Camera cam = axis_camera();
  const std::array<float, 3> airlight = {0.8f, 0.9f, 1.0f};
  const std::array<float, 3> drop = {0.3f, 0.2f, 0.1f};
  const StubMedium stub(kSigma, kSampled, {{{0.0, 0.0, -5.0}, 0.05, 0.0, drop}});
  Image rgb(9, 9, 3, 0.25f), range(9, 9, 1, 20.0f);
  range.at(4, 0) = 7.0f;  // within the sampled range: no analytic medium
  Image out = image_through_media({&stub}, rgb, range, cam, airlight);
  const double t = std::exp(-kSigma * (20.0 - kSampled));  // Beer–Lambert beyond r_s
  for (int k = 0; k < 3; ++k) {
    const double fogged = t * 0.25 + (1.0 - t) * airlight[k];
    EXPECT_NEAR(out.at(0, 0, k), fogged, fogged * kRel);
    EXPECT_NEAR(out.at(5, 4, k), fogged, fogged * kRel);    // 6.3° off the axis: misses the particle (0.55 m at 5 m)
    EXPECT_NEAR(out.at(4, 4, k), drop[k], drop[k] * kRel);  // the particle at 5 m covers it; no medium before it
    EXPECT_EQ(out.at(4, 0, k), 0.25f);
  }
  // A scene nearer than the particle hides it (the depth test).
  range.at(4, 4) = 3.0f;
  out = image_through_media({&stub}, rgb, range, cam, airlight);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(out.at(4, 4, k), 0.25f);
}

}  // namespace media_stub_tests
