// The composition of media (brume/medium.hpp): extinctions add, particle
// echoes are the union of the media's, each attenuated by the others, and a
// particle medium is analytic beyond its sampled range only -- checked
// against closed forms with an analytic medium and the stub particle medium
// (tests/media_stub/).
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/medium.hpp"
#include "media_stub/stub_medium.hpp"

using namespace brume;
using namespace brume::test;

namespace medium_tests {

constexpr double kRel = 1e-6;  // float32 outputs of double formulas

TEST(Medium, ExtinctionsAddAndNoOpticalDepthIsCountedTwice) {
  const StubMedium haze(0.01, 0.0);                                      // analytic everywhere
  const StubMedium rain(0.03, 10.0, {{{5.0, 0.0, 0.0}, 0.1, 0.0, {}}});  // particles within 10 m
  const MediumRay axis{{0, 0, 0}, {1, 0, 0}};
  EXPECT_DOUBLE_EQ(haze.optical_depth(axis, 40.0), 0.01 * 40.0);
  EXPECT_DOUBLE_EQ(rain.optical_depth(axis, 40.0), 0.03 * 30.0);  // σ over [r_s, r] only
  EXPECT_DOUBLE_EQ(rain.optical_depth(axis, 8.0), 0.0);
  const std::vector<float> in = {0.0f, 40.0f, 0.0f, 100.0f, 8.0f, 0.0f, 0.0f, 100.0f};
  std::vector<float> out(in.size());
  const ScanRun run = scan_through_media({&haze, &rain}, in.data(), out.data(), 2);
  EXPECT_EQ(run.echoes, 0u);  // the particle's echo (0) never beats a target
  const double far = 100.0 * std::exp(-2.0 * (0.01 * 40.0 + 0.03 * 30.0));
  EXPECT_NEAR(out[3], far, far * kRel);
  // Point 1 (8 m along x) passes the particle at 5 m: no echo, but the
  // particle is what the medium is within r_s (no analytic optical depth).
  const double near = 100.0 * std::exp(-2.0 * 0.01 * 8.0);
  EXPECT_NEAR(out[7], near, near * kRel);
}

TEST(Medium, EchoesAreTheUnionAttenuatedByTheOtherMedia) {
  const StubMedium haze(0.01, 0.0);
  const StubMedium weak(0.0, 50.0, {{{5.0, 0.0, 0.0}, 0.1, 30.0, {}}});
  const StubMedium strong(0.0, 50.0, {{{12.0, 0.0, 0.0}, 0.1, 60.0, {}}});
  const std::vector<float> in = {40.0f, 0.0f, 0.0f, 50.0f};
  std::vector<float> out(in.size());
  for (const auto& media :
       {std::vector<const Medium*>{&haze, &weak, &strong}, std::vector<const Medium*>{&strong, &haze, &weak}}) {
    const ScanRun run = scan_through_media(media, in.data(), out.data(), 1);
    EXPECT_EQ(run.echoes, 1u);
    // 60·e^{−2·0.01·12} = 47.2 beats 30·e^{−0.1} = 27.1 and the target's 50·e^{−0.8} = 22.5.
    const double echo = 60.0 * std::exp(-2.0 * 0.01 * 12.0);
    EXPECT_NEAR(out[0], 12.0, 12.0 * kRel);
    EXPECT_NEAR(out[3], echo, echo * kRel);
  }
  // Ties go to the target: an echo equal to the target's return leaves the point.
  const StubMedium tie(0.0, 50.0, {{{5.0, 0.0, 0.0}, 0.1, 50.0, {}}});
  scan_through_media({&tie}, in.data(), out.data(), 1);
  EXPECT_EQ(out[0], 40.0f);
  EXPECT_EQ(out[3], 50.0f);
}

TEST(Medium, ImageThroughAnAnalyticAndAParticleMedium) {
  Camera cam;
  cam.k = {9.0, 9.0, 4.0, 4.0};
  cam.width = cam.height = 9;
  cam.position_m = {0.0, 0.0, 0.0};
  const std::array<float, 3> airlight = {1.0f, 1.0f, 1.0f};
  const StubMedium haze(0.01, 0.0);
  const StubMedium rain(0.03, 10.0, {{{0.0, 0.0, -5.0}, 0.05, 0.0, {0.5f, 0.5f, 0.5f}}});
  const Image rgb(9, 9, 3, 0.0f), range(9, 9, 1, 20.0f);
  const Image out = image_through_media({&haze, &rain}, rgb, range, cam, airlight);
  const double t = std::exp(-(0.01 * 20.0 + 0.03 * 10.0));
  EXPECT_NEAR(out.at(0, 8, 1), 1.0 - t, (1.0 - t) * kRel);
  // The particle at 5 m seen through 5 m of haze.
  const double tp = std::exp(-0.01 * 5.0);
  const double centre = tp * 0.5 + (1.0 - tp);
  EXPECT_NEAR(out.at(4, 4, 1), centre, centre * kRel);
  // Unknown range is the effect's sky rule: left as it is.
  Image sky = range;
  sky.at(2, 2) = NAN;
  EXPECT_EQ(image_through_media({&haze}, rgb, sky, cam, airlight).at(2, 2, 0), 0.0f);
}

// A particle that claims to cover more than its pixel is a broken medium:
// refused, naming the pixel and the value, never clamped.
TEST(Medium, ACoverageOutsideZeroOneIsRefused) {
  class Broken final : public Medium {
   public:
    double extinction_per_m() const override { return 0.0; }
    double sampled_range_m() const override { return 10.0; }
    void particles(const MediumRay&, double, double, std::vector<Particle>& out) const override {
      out.push_back({5.0, 0.0, 1.5, {1.0f, 1.0f, 1.0f}});
    }
    nlohmann::json scan_record(const ScanRun&) const override { return nlohmann::json::object(); }
  };
  Camera cam;
  cam.k = {2.0, 2.0, 1.0, 1.0};
  cam.width = cam.height = 2;
  const Broken b;
  try {
    image_through_media({&b}, Image(2, 2, 3, 0.0f), Image(2, 2, 1, 20.0f), cam, {1.0f, 1.0f, 1.0f});
    FAIL() << "a coverage of 1.5 was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("covers 1.5 of it"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("pixel (0, 0)"), std::string::npos) << e.what();
  }
}

TEST(Medium, ScanArraysOfAnotherShapeAreRefused) {
  const Image bad(3, 2, 1);
  std::vector<float> buffer;
  EXPECT_THROW(scan_points(ConstImageView(bad), "points", buffer), Error);
}

}  // namespace medium_tests
