// The procedural demo scene (tools/demo_scene): determinism across runs and
// thread counts, and the geometric facts its header documents.
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstring>

#include "brume/demo_scene.hpp"

using namespace brume;

namespace {

bool same_bits(const Image& a, const Image& b) {
  return a.width == b.width && a.height == b.height && a.channels == b.channels &&
         std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)) == 0;  // NaN-safe
}

DemoScene render_with_threads(int w, int h, int threads) {
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  DemoScene s = render_demo_scene(w, h);
  omp_set_num_threads(before);
  return s;
}

}  // namespace

TEST(DemoScene, BitIdenticalAcrossRunsAndThreadCounts) {
  // The header promises the same output on any thread count: work is per
  // pixel with no shared accumulation, so even one differing bit is a bug.
  const DemoScene a = render_with_threads(160, 112, 1);
  const DemoScene b = render_with_threads(160, 112, 1);
  const DemoScene c = render_with_threads(160, 112, 4);
  EXPECT_TRUE(same_bits(a.rgb, b.rgb));
  EXPECT_TRUE(same_bits(a.range, b.range));
  EXPECT_TRUE(same_bits(a.rgb, c.rgb));
  EXPECT_TRUE(same_bits(a.range, c.range));
}

TEST(DemoScene, SizesChannelsAndEmptyForNonPositiveSizes) {
  const DemoScene s = render_demo_scene(96, 64);
  EXPECT_EQ(s.fov_y_deg, 55.0);
  EXPECT_EQ(s.rgb.width, 96);
  EXPECT_EQ(s.rgb.height, 64);
  EXPECT_EQ(s.rgb.channels, 3);
  EXPECT_EQ(s.range.width, 96);
  EXPECT_EQ(s.range.height, 64);
  EXPECT_EQ(s.range.channels, 1);
  EXPECT_TRUE(render_demo_scene(0, 10).rgb.empty());
  EXPECT_TRUE(render_demo_scene(10, -1).range.empty());
}

TEST(DemoScene, ColoursLinearInUnitRangeAndRangesDocumented) {
  const int W = 240, H = 168;
  const DemoScene s = render_demo_scene(W, H);
  int sky = 0;
  double rmin = INFINITY, rmax = -INFINITY;
  double sky_b_minus_r = 0.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      for (int c = 0; c < 3; ++c) {
        const float v = s.rgb.at(x, y, c);
        ASSERT_TRUE(std::isfinite(v) && v >= 0.0f && v <= 1.0f) << x << "," << y << "," << c << ": " << v;
      }
      const float r = s.range.at(x, y);
      if (std::isnan(r)) {
        ++sky;
        sky_b_minus_r += s.rgb.at(x, y, 2) - s.rgb.at(x, y, 0);
        continue;
      }
      ASSERT_TRUE(std::isfinite(r)) << x << "," << y;
      rmin = std::min(rmin, double(r));
      rmax = std::max(rmax, double(r));
    }
  // Sky (NaN range) fills the top: the top row looks 22.5 degrees above the
  // horizon, over every object; the bottom row sees only ground.
  for (int x = 0; x < W; ++x) {
    EXPECT_TRUE(std::isnan(s.range.at(x, 0))) << x;
    EXPECT_FALSE(std::isnan(s.range.at(x, H - 1))) << x;
  }
  EXPECT_GT(sky, W * H / 10);
  EXPECT_GT(sky_b_minus_r / sky, 0.1);  // a blue sky: blue well above red on average
  // Documented span: the ground at the bottom edge (~3 m) to the mountains
  // (about 1.25 km); the ball at 3.9 m is not the nearest surface.
  EXPECT_GT(rmin, 2.9);
  EXPECT_LT(rmin, 3.2);
  EXPECT_GT(rmax, 1000.0);
  EXPECT_LT(rmax, 2000.0);
}

TEST(DemoScene, GroundRangeMatchesThePinholeClosedForm) {
  // Bottom-centre pixel: a ray into the flat ground (y = 0) from 1.6 m up.
  // Camera pitched 5 degrees down, tan(fov_y/2) = tan(27.5 deg); ray
  // d = fwd + v tan(27.5) up + u tan(27.5) aspect right with v = 1 - 2 py / H.
  // Range = 1.6 |d| / (-d_y). Tolerance 1e-5 relative: float storage of a
  // double computation (eps 6e-8) plus the scene's intersection epsilon.
  const int W = 160, H = 112;
  const DemoScene s = render_demo_scene(W, H);
  const double kPi = 3.14159265358979323846;
  const double p = 5.0 * kPi / 180.0, th = std::tan(27.5 * kPi / 180.0), aspect = double(W) / H;
  for (int x : {W / 2 - 1, W / 2 + 3}) {
    const int y = H - 1;
    const double u = 2.0 * (x + 0.5) / W - 1.0, v = 1.0 - 2.0 * (y + 0.5) / H;
    // fwd = (0, -sin p, cos p), up = (0, cos p, sin p), right = (1, 0, 0).
    const double dx = u * th * aspect, dy = -std::sin(p) + v * th * std::cos(p),
                 dz = std::cos(p) + v * th * std::sin(p);
    const double expect = 1.6 * std::sqrt(dx * dx + dy * dy + dz * dz) / -dy;
    EXPECT_NEAR(s.range.at(x, y), expect, 1e-5 * expect) << "pixel " << x << "," << y;
  }
}
