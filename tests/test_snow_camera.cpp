// Snow on a camera's image (brume/snow.hpp, issue #58's camera part): no flake drawn behind a
// nearer surface, drawn + analytic transmittance against e^{−σ_cam·r}, rate 0 giving the image
// back bit for bit, the flakes' light from the sky and the ground, and `brume snow` with `brume
// run` of its record and --lidar against `brume lidar snow`.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/snow.hpp"
#include "effects/snow/snow_internal.hpp"
#include "streak_scene.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace snow_camera_tests {

CameraSnowParams params(double rate, std::uint64_t seed) {
  CameraSnowParams p;
  p.flakes.rate_mm_h = rate;
  p.seed = seed;
  return p;
}


// A wall at 2 m (planar depth) over the left half hides every flake behind it: there the image is
// at most as covered as the same seed's flakes drawn up to z_split = 2.02 m (a splat's footprint
// reaches the neighbouring pixel, whose ray meets the wall up to 0.2 % farther), and as covered
// as those drawn up to 2 m within 1 % (the softness in front of the wall). Every flake is drawn
// (ε = 0), so the thresholds do not depend on z_split.
TEST(CameraSnow, NoFlakeIsDrawnBehindNearerDepth) {
  const int W = 200, H = 150;
  Flat wall = flat(W, H, 300.0, 1.0f, 1000.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) {
      const double a = (x - wall.k.cx) / 300.0, b = (y - wall.k.cy) / 300.0;
      wall.range.at(x, y) = static_cast<float>(2.0 * std::sqrt(1 + a * a + b * b));
    }
  const Flat far = flat(W, H, 300.0, 1.0f, 1000.0);
  CameraSnowParams p = params(1.0, 5);
  p.epsilon = 0.0, p.z_split_m = 8.0;
  const std::array<float, 3> black{0, 0, 0};
  CameraSnowStats st;
  const Image with = render_camera_snow(scene_of(wall, false, black), p, two_threads(), &st);
  EXPECT_GT(st.flakes_drawn, 1000u);
  const Image open = render_camera_snow(scene_of(far, false, black), p, two_threads());
  p.z_split_m = 2.0;
  const Image near = render_camera_snow(scene_of(far, false, black), p, two_threads());
  p.z_split_m = 2.02;
  const Image slack = render_camera_snow(scene_of(far, false, black), p, two_threads());
  double a_with = 0.0, a_near = 0.0, a_open = 0.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) {
      const double aw = 1.0 - with.at(x, y, 0);
      ASSERT_LE(aw, 1.0 - slack.at(x, y, 0) + 1e-6) << x << "," << y;
      a_with += aw, a_near += 1.0 - near.at(x, y, 0), a_open += 1.0 - open.at(x, y, 0);
    }
  EXPECT_GT(a_near, 0.0);
  EXPECT_NEAR(a_with / a_near, 1.0, 0.01);
  EXPECT_GT(a_open, 1.2 * a_near);  // the flakes beyond 2 m are many: the wall hides something
  for (int y = 0; y < H; ++y)
    for (int x = W / 2 + 8; x < W; ++x) ASSERT_EQ(with.at(x, y, 0), open.at(x, y, 0)) << x << "," << y;
}

// Drawn + analytic transmittance is e^{−σ_cam·r} in expectation (a Poisson field: E[Π(1 − α)] =
// e^{−E Σα}): a white scene at range r, black flakes, no airlight; the image's mean over 2 seeds
// within 1 % at r = 10 m (mostly drawn) and 60 m (mostly analytic), at the default thinning
// (measured: within 1e−4 over 4 seeds at 240x120).
TEST(CameraSnow, DrawnAndAnalyticTransmittanceIsBeerLambert) {
  const int W = 160, H = 80;
  for (double r : {10.0, 60.0}) {
    Flat fl = flat(W, H, 250.0, 1.0f, r);
    double mean = 0.0;
    CameraSnowStats st;
    for (std::uint64_t seed = 1; seed <= 2; ++seed) {
      const Image out = render_camera_snow(scene_of(fl, true, std::array<float, 3>{0, 0, 0}), params(2.0, seed),
                                           two_threads(), &st);
      double s = 0.0;
      for (int i = 0; i < W * H; ++i) s += out.data[3 * static_cast<std::size_t>(i)];
      mean += s / (W * H) / 2.0;
    }
    const double expect = std::exp(-st.sigma_cam * r);
    EXPECT_NEAR(st.sigma_cam, 1.64 / 2.0 * snow_sizes(params(2.0, 0).flakes).extinction_per_m(2.0), 1e-15);
    EXPECT_LT(expect, 0.98);  // the test can fail: the snow takes a visible share
    std::printf("r = %g m: mean %.5f, e^-sigma r %.5f (%zu flakes drawn in the last)\n", r, mean, expect,
                st.flakes_drawn);
    EXPECT_NEAR(mean / expect, 1.0, 0.01) << "r = " << r;
  }
}

// Rate 0: the image back bit for bit (no haze); the flakes' radiance is albedo·(L_sky + L_ground)/2
// of the image's sky (unknown range) and bottom quarter.
TEST(CameraSnow, RateZeroGivesTheImageBackAndFlakesAreLitBySkyAndGround) {
  const Scene sc = scene(96, 64, 12);
  Flat f = flat(96, 64, 80.0, 0.5f, 10.0);
  f.rgb = sc.rgb, f.range = sc.range;
  {
    CameraRainScene s = scene_of(f, true);
    s.airlight = {0.7f, 0.7f, 0.8f};
    const Image out = render_camera_snow(s, params(0.0, 1), two_threads());
    ASSERT_EQ(out.data.size(), f.rgb.data.size());
    for (std::size_t i = 0; i < out.data.size(); ++i) ASSERT_EQ(out.data[i], f.rgb.data[i]) << i;
    CameraSnowStats st;
    (void)render_camera_snow(s, params(1.0, 1), two_threads(), &st);
    double sky[3] = {0, 0, 0}, ground[3] = {0, 0, 0};
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 96; ++x)
        for (int c = 0; c < 3; ++c) {
          if (y < 12) sky[c] += f.rgb.at(x, y, c) / (96.0 * 12);
          if (y >= 48) ground[c] += f.rgb.at(x, y, c) / (96.0 * 16);
        }
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(st.sky[c], sky[c], 1e-9);
      EXPECT_NEAR(st.ground[c], ground[c], 1e-9);
    }
    EXPECT_GT(st.flakes_drawn, 0u);
  }
}

TEST(CameraSnow, BadParametersAreRefused) {
  CameraSnowParams p;
  EXPECT_NE(error_of([&] { validate_camera_snow(p); }).find("--rate"), std::string::npos);
  p.flakes.rate_mm_h = 1.0;
  p.wind = "1,2";
  EXPECT_NE(error_of([&] { validate_camera_snow(p); }).find("--wind"), std::string::npos);
  p.wind = "0,0,0";
  p.f_number = 2.8;
  EXPECT_NE(error_of([&] { validate_camera_snow(p); }).find("--focus-distance"), std::string::npos);
  p.f_number.reset();
  p.z_split_m = 0.1;
  EXPECT_NE(error_of([&] { validate_camera_snow(p); }).find("--z-split"), std::string::npos);
  EXPECT_NE(error_of([&] { camera_snow_param_table().set_text(p, "albedo", "1.5"); }).find("--albedo"),
            std::string::npos);
}

class CameraSnowCli : public ScratchDirTest {};

// `brume snow` from files, `brume run` of its record (the same image bit for bit), rate 0 (the
// image back), --lidar (the scan `brume lidar snow` writes with --seed the --snow-seed).
TEST_F(CameraSnowCli, RunsAndBrumeRunRepeatsIt) {
  const Scene s = scene(96, 64, 12);
  write_image(p("in.exr"), s.rgb, WriteOptions{});
  write_image(p("range.exr"), s.range, WriteOptions{});
  fs::create_directories(p("first"));
  const std::string in = " --image " + p("in.exr") + " --range " + p("range.exr") + " --fx 80 ";
  const CliRun r = run("snow" + in + "--rate 2 --snow-seed 4 --wind 0,2,0 --ego-speed 10 --visibility 300 --out " +
                       p("first/o.exr") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["command"], "snow");
  EXPECT_EQ(rec["job"]["snow"]["snow-seed"], 4);
  EXPECT_GT(rec["snow"]["flakes_drawn"].get<std::size_t>(), 0u);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.exr"), p("again/o.exr"));
  const CliRun zero = run("snow" + in + "--rate 0 --out " + p("zero.exr"));
  ASSERT_EQ(zero.status, 0) << zero.output;
  const Image z = read_color(p("zero.exr"));
  ASSERT_EQ(z.data.size(), s.rgb.data.size());
  for (std::size_t i = 0; i < z.data.size(); ++i) ASSERT_EQ(z.data[i], s.rgb.data[i]) << i;
  std::vector<float> pts;
  for (int i = 0; i < 2000; ++i) {
    const double a = 0.003 * i, rr = 3.0 + 0.02 * i;
    pts.insert(pts.end(), {static_cast<float>(rr * std::cos(a)), static_cast<float>(rr * std::sin(a)), -1.0f,
                           static_cast<float>((i % 7) / 7.0)});
  }
  {
    std::ofstream f(p("scan.bin"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  }
  fs::create_directories(p("l"));
  const CliRun both = run("snow" + in + "--rate 2 --snow-seed 9 --lidar " + p("scan.bin") + " --lidar-out " +
                          p("l/o.bin") + " --out " + p("l/o.exr") + " --record " + p("l/o.json"));
  ASSERT_EQ(both.status, 0) << both.output;
  const CliRun alone = run("lidar snow --points " + p("scan.bin") + " --rate 2 --seed 9 --out " + p("alone.bin"));
  ASSERT_EQ(alone.status, 0) << alone.output;
  EXPECT_EQ(file_bytes(p("l/o.bin")), file_bytes(p("alone.bin")));
  EXPECT_TRUE(read_json(p("l/o.json")).contains("lidar_snow"));
  const CliRun again2 = run("run " + p("l/o.json") + " --out-dir " + p("l2"));
  ASSERT_EQ(again2.status, 0) << again2.output;
  EXPECT_EQ(file_bytes(p("l/o.bin")), file_bytes(p("l2/o.bin")));
  const CliRun bad = run("snow" + in + "--rate 2 --lidar " + p("scan.bin") + " --out " + p("bad.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--lidar-out"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("bad.exr")));
}

// ---- frames of a sequence -------------------------------------------------------------------

// Frame 0 is today's image bit for bit (the fingerprint of main's library, fbf627f, for this scene,
// wind and ego speed); frames 1 and 2 are other images, the same on one thread and two.
TEST(CameraSnowFrames, FrameZeroIsTodaysAndFramesDifferAndRepeat) {
  const Flat fl = flat(96, 64, 60.0, 0.3f, 40.0);
  CameraSnowParams p = params(2.0, 5);
  p.wind = "1,-2,0.5", p.ego_speed_m_s = 8.0, p.z_split_m = 8.0;
  EXPECT_EQ(fingerprint(render_camera_snow(scene_of(fl, true), p, two_threads())), 0xbd15f61b90e58943ull);
  const auto h = frame_fingerprints([&](std::uint64_t k, const Exec& e) {
    p.frame = k;
    return render_camera_snow(scene_of(fl, true), p, e);
  });
  EXPECT_EQ(h[0], 0xbd15f61b90e58943ull);
  EXPECT_NE(h[1], 0u);
  EXPECT_NE(h[1], h[0]);
  EXPECT_NE(h[2], h[1]);
}

// At frame 3 (0.3 s: no flake reaches its layer's edge) every flake drawn is one of frame 0's moved
// by the wind and the one fall speed, (w_x, w_y, w_z − v_t)·t, less the camera's s·t (within 1e-9 m:
// the closed form's rounding), wherever frame 0's is in the picture (a pixel inside, from z_near,
// above the thinning's D_t).
TEST(CameraSnowFrames, FlakesFallAtOneSpeedBetweenFrames) {
  const Flat fl = flat(64, 48, 60.0, 0.3f, 1000.0);
  CameraSnowParams p = params(2.0, 3);
  p.wind = "0.5,1,0.2", p.ego_speed_m_s = 4.0, p.z_split_m = 5.0, p.flakes.fall_speed_m_s = 1.5;
  const auto drawn = [&](std::uint64_t frame) {
    p.frame = frame;
    StreakSlabs slabs;
    (void)render_camera_snow_drawn(scene_of(fl, false, {1, 1, 1}), p, two_threads(), nullptr, nullptr, &slabs);
    std::vector<std::array<double, 4>> out;  // x, y, z (the field's axes at the camera), D [mm]
    for (const std::vector<Streak>& slab : slabs)
      for (const Streak& k : slab)
        out.push_back({k.c[2], -k.c[0], -k.c[1], std::sqrt(k.area / (3.14159265358979323846 / 4.0 * 3600.0)) * 1e3});
    return out;
  };
  const auto f0 = drawn(0), f3 = drawn(3);
  const double t = 0.3;
  const double m[3] = {0.5 * t - 4.0 * t, 1.0 * t, (0.2 - 1.5) * t};
  std::size_t checked = 0;
  for (const auto& a : f3) {
    const double q[3] = {a[0] - m[0], a[1] - m[1], a[2] - m[2]};  // where frame 0 had it
    if (!(q[0] >= p.z_near_m && q[0] < p.z_split_m)) continue;
    const double u = 60.0 * -q[1] / q[0] + fl.k.cx, v = 60.0 * -q[2] / q[0] + fl.k.cy;
    if (!(u >= 0.5 && u <= 62.5 && v >= 0.5 && v <= 46.5)) continue;
    bool found = false, thinned = true;
    for (const auto& b : f0) {
      if (std::abs(b[0] - q[0]) <= 1e-9 && std::abs(b[1] - q[1]) <= 1e-9 && std::abs(b[2] - q[2]) <= 1e-9) {
        found = true;
        EXPECT_NEAR(b[3], a[3], 1e-9 * a[3]);
      }
    }
    // A flake frame 0 did not draw must be one its thinning drops: D_t is non-decreasing in depth, so
    // no flake frame 0 drew as far or farther may be as small or smaller.
    if (!found)
      for (const auto& b : f0)
        if (b[0] >= q[0] && b[3] <= a[3]) thinned = false;
    EXPECT_TRUE(found || thinned) << "a flake at " << a[0] << ", " << a[1] << ", " << a[2] << " (D " << a[3]
                                  << " mm) is not frame 0's moved";
    checked += found;
  }
  EXPECT_GT(checked, 30u);
}

// The command line: a frame's record repeats bit for bit; the scan's snow has no frames yet.
TEST_F(CameraSnowCli, FramesOfASequence) {
  const Scene s = scene(96, 64, 12);
  write_image(p("in.exr"), s.rgb, WriteOptions{});
  write_image(p("range.exr"), s.range, WriteOptions{});
  fs::create_directories(p("first"));
  const std::string in = " --image " + p("in.exr") + " --range " + p("range.exr") + " --fx 80 ";
  const CliRun r = run("snow" + in + "--rate 2 --snow-seed 4 --wind 0,2,0 --ego-speed 10 --frame 3 --out " +
                       p("first/o.exr") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["job"]["snow"]["frame"], 3);
  EXPECT_EQ(rec["snow"]["frame"], 3);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.exr"), p("again/o.exr"));
  const std::vector<float> pts = {5.0f, 0.0f, -1.0f, 0.3f, 6.0f, 1.0f, -1.0f, 0.3f};
  {
    std::ofstream f(p("scan.bin"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  }
  // The scan at the same frame: brume lidar snow's --frame (its flakes drawn afresh per beam), with
  // the camera's seed.
  const CliRun with_scan = run("snow" + in + "--rate 2 --snow-seed 4 --frame 1 --lidar " + p("scan.bin") +
                               " --lidar-out " + p("b.bin") + " --out " + p("b.exr"));
  ASSERT_EQ(with_scan.status, 0) << with_scan.output;
  const CliRun alone = run("lidar snow --points " + p("scan.bin") + " --rate 2 --seed 4 --frame 1 --out " + p("c.bin"));
  ASSERT_EQ(alone.status, 0) << alone.output;
  EXPECT_EQ(file_bytes(p("b.bin")), file_bytes(p("c.bin")));
}

}  // namespace snow_camera_tests
