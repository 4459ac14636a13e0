// Rain on a camera's image (brume/rain.hpp, issue #56's camera part): σ_cam against the LiDAR's
// σ and Q_eff's fit, streak lengths and coverage against the drops of the field enumerated here
// (written again from the header's equations), the energy a rain adds against the exposure, its
// fluctuation's T^−½ law, the depth test, drawn + analytic transmittance against e^{−σr}, and
// `brume rain` with `brume run` of its record (KITTI 000001 when the data is present).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/rain.hpp"
#include "streak_scene.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace rain_camera_tests {

constexpr double kPi = 3.14159265358979323846;

CameraRainParams params(double rate, double exposure_s, std::uint64_t seed) {
  CameraRainParams p;
  p.drops.rate_mm_h = rate;
  p.exposure_s = exposure_s;
  p.seed = seed;
  return p;
}


// σ_cam is Q_eff/2 of the LiDAR's σ, bit for bit (the same ∫D²N), at the rates; Q_eff's
// default is the least-squares fit in ln V of 3.912/σ_cam to the visibility code's rain rows.
TEST(CameraRain, ExtinctionIsHalfQeffOfTheLidarsBitForBit) {
  for (double r : {1.0, 5.0, 25.0, 100.0})
    for (double q : {kCameraRainQEff, 1.0, 2.0}) {
      EXPECT_EQ(camera_rain_extinction_per_m(r, q), q / 2.0 * rain_extinction_per_m(r, kLidarRainQ)) << r << " " << q;
      // The recorded σ is the same double.
      const CameraRainParams p = [&] {
        CameraRainParams x = params(r, 1.0 / 60, 0);
        x.q_eff = q;
        return x;
      }();
      Intrinsics k;
      k.fx = k.fy = 500;
      k.cx = k.cy = 10;
      EXPECT_EQ(CameraRainOptics(p, k, 0.0).sigma_cam(), camera_rain_extinction_per_m(r, q));
    }
  // The fit, written again: ln Q = mean(ln(2·3.912/σ_lidar(R)) − ln V(R)).
  const double rows[4][2] = {{2.5, 5900.0}, {12.5, 2800.0}, {25.0, 1900.0}, {100.0, 770.0}};
  double s = 0.0;
  for (const auto& row : rows) {
    const double l = 4.1 * std::pow(row[0], -0.21), sigma = kPi * 8000.0 / (l * l * l) * 1e-6;
    s += std::log(2.0 * 3.912 / sigma) - std::log(row[1]);
  }
  EXPECT_NEAR(kCameraRainQEff, std::exp(s / 4.0), 0.005);
}

// ∫D²N between two diameters against Simpson's rule (20 000 intervals: 1e−12 relative).
TEST(CameraRain, PartialMomentIsTheIntegral) {
  for (double r : {1.0, 25.0, 100.0}) {
    const double l = 4.1 * std::pow(r, -0.21);
    const double a = 0.3, b = 6.0;
    const int m = 20000;
    const double h = (b - a) / m;
    double s = 0.0;
    for (int i = 0; i <= m; ++i) {
      const double d = a + i * h, f = d * d * 8000.0 * std::exp(-l * d);
      s += (i == 0 || i == m) ? f : (i % 2 ? 4 * f : 2 * f);
    }
    EXPECT_NEAR(rain_d2_between(r, a, b), s * h / 3.0, 1e-10 * s * h / 3.0);
  }
}

// Streak length and coverage on the drops of one cell layer (z in [4, 4.125) m), enumerated here
// from the field: each isolated streak is a vertical line of length fy·v(D)·T/z (the fall alone),
// measured as √(12·(var_v − 1/6)) of its coverage (a uniform segment's variance L²/12, plus the
// bilinear splat's 1/6), within 0.5 px; its coverage sums to (π/4)D²fx·fy·r/z³ within 1 %.
TEST(CameraRain, StreakLengthIsFallTimesExposureOverDepth) {
  const int W = 240, H = 240;
  const double f = 1000.0, T = 1.0 / 60;
  const Flat fl = flat(W, H, f, 1.0f, 1000.0);
  CameraRainParams p = params(25.0, T, 11);
  p.z_near_m = 4.0, p.z_split_m = 4.125, p.epsilon = 0.0, p.drops.drop_min_mm = 1.0;
  const Image out = render_camera_rain(scene_of(fl, false, {0, 0, 0}), p, two_threads());
  // Each thread owns a band of rows and the drops keep one order: the image is the same on one thread.
  Exec one;
  one.threads = 1;
  const Image single = render_camera_rain(scene_of(fl, false, {0, 0, 0}), p, one);
  ASSERT_EQ(std::memcmp(out.data.data(), single.data.data(), out.data.size() * sizeof(float)), 0);
  // The drops, written again: cv = (−y, −z, x) of the field's (x forward, y left, z up).
  const RainField field(25.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  struct D {
    double u, v, len, mass;
  };
  std::vector<D> drops;
  std::vector<RainDrop> cell;
  for (std::int64_t iy = -8; iy <= 8; ++iy)
    for (std::int64_t iz = -8; iz <= 8; ++iz) {
      cell.clear();
      field.cell_drops({32, iy, iz}, 0.0, cell);
      for (const RainDrop& d : cell) {
        const double x = -d.at.y, y = -d.at.z, z = d.at.x, r = std::sqrt(x * x + y * y + z * z);
        const double dm = d.d_mm * 1e-3;
        drops.push_back({f * x / z + fl.k.cx, f * y / z + fl.k.cy, f * atlas_terminal_velocity_m_per_s(d.d_mm) * T / z,
                         kPi / 4 * dm * dm * f * f * r / (z * z * z)});
      }
    }
  int checked = 0;
  for (std::size_t i = 0; i < drops.size(); ++i) {
    const D& d = drops[i];
    const int x0 = static_cast<int>(d.u) - 4, x1 = static_cast<int>(d.u) + 5;
    const int y0 = static_cast<int>(d.v - d.len / 2) - 4, y1 = static_cast<int>(d.v + d.len / 2) + 5;
    if (x0 < 0 || y0 < 0 || x1 >= W || y1 >= H) continue;
    bool alone = true;
    for (std::size_t j = 0; j < drops.size() && alone; ++j)
      if (j != i && std::abs(drops[j].u - d.u) < 10 && std::abs(drops[j].v - d.v) < (drops[j].len + d.len) / 2 + 10)
        alone = false;
    if (!alone) continue;
    double s = 0.0, sv = 0.0, svv = 0.0;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const double a = 1.0 - out.at(x, y, 0);  // one streak: 1 − (1 − α) = α
        s += a, sv += a * y, svv += a * y * y;
      }
    const double mean = sv / s, var = svv / s - mean * mean;
    EXPECT_NEAR(std::sqrt(12.0 * (var - 1.0 / 6.0)), d.len, 0.5) << "drop " << i;
    EXPECT_NEAR(s, d.mass, 0.01 * d.mass) << "drop " << i;  // a fall keeps r and z: the area is constant
    ++checked;
  }
  EXPECT_GE(checked, 5) << drops.size() << " drops";
}

// The energy the rain adds, Σ(I − I_bg), does not depend on T (mean of 8 seeds, within 1 %): the
// same drops (the seed's) for every T, falling from 2 to 10 m; only the drops whose streaks cross
// the frame's top and bottom differ.
TEST(CameraRain, EnergyIsIndependentOfExposure) {
  const int W = 320, H = 200;
  const Flat fl = flat(W, H, 500.0, 0.0f, 1000.0);
  const double ts[5] = {0.008, 0.016, 0.033, 0.066, 0.125};
  double energy[5] = {0, 0, 0, 0, 0};
  for (std::uint64_t seed = 1; seed <= 8; ++seed)
    for (int k = 0; k < 5; ++k) {
      CameraRainParams p = params(25.0, ts[k], seed);
      p.z_near_m = 2.0, p.z_split_m = 10.0, p.epsilon = 0.0, p.drops.drop_min_mm = 0.5;
      const Image out = render_camera_rain(scene_of(fl, false, {1, 1, 1}), p, two_threads());
      double s = 0.0;
      for (int i = 0; i < W * H; ++i) s += out.data[3 * static_cast<std::size_t>(i)];
      energy[k] += s / 8.0;
    }
  for (int k = 0; k < 5; ++k) EXPECT_NEAR(energy[k] / energy[2], 1.0, 0.01) << "T = " << ts[k];
}

// The fluctuation's standard deviation over a flat background goes as T^−½ (mean variance of 8
// seeds, within 5 %), for T in {8, 16, 33, 66, 125} ms: drops of 0.5 mm and more from 1 to 4 m,
// a wind of 20 m/s across the view (so that every streak is long against the splat: 40 px and
// more), every drop drawn (ε = 0).
TEST(CameraRain, FluctuationGoesAsTheInverseRootOfExposure) {
  const int W = 160, H = 120;
  const Flat fl = flat(W, H, 1000.0, 0.0f, 1000.0);
  const double ts[5] = {0.008, 0.016, 0.033, 0.066, 0.125};
  double var[5] = {0, 0, 0, 0, 0};
  for (std::uint64_t seed = 1; seed <= 8; ++seed)
    for (int k = 0; k < 5; ++k) {
      CameraRainParams p = params(25.0, ts[k], seed);
      p.z_near_m = 1.0, p.z_split_m = 4.0, p.epsilon = 0.0, p.drops.drop_min_mm = 0.5, p.wind = "0,20,0";
      const Image out = render_camera_rain(scene_of(fl, false, {1, 1, 1}), p, two_threads());
      double s = 0.0, ss = 0.0;
      for (int i = 0; i < W * H; ++i) {
        const double a = out.data[3 * static_cast<std::size_t>(i)];
        s += a, ss += a * a;
      }
      const double m = s / (W * H);
      var[k] += (ss / (W * H) - m * m) / 8.0;
    }
  for (int k = 0; k < 5; ++k)
    EXPECT_NEAR(std::sqrt(var[k] * ts[k]) / std::sqrt(var[2] * ts[2]), 1.0, 0.05) << "T = " << ts[k];
}

// A wall at 2 m (planar depth) over the left half hides every drop behind it: there the streaks
// are those of the same seed drawn up to z_split = 2 m. Tolerances: a splat's bilinear footprint
// reaches the neighbouring pixel, whose ray meets the wall up to 0.2 % farther here (the
// anti-aliasing at depth edges), so nothing beyond 2.02 m may show; the 1 % softness in front of
// the wall takes at most 1 % of the coverage.
TEST(CameraRain, AWallHidesTheDropsBehindIt) {
  const int W = 200, H = 150;
  Flat wall = flat(W, H, 300.0, 1.0f, 1000.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) {
      const double a = (x - wall.k.cx) / 300.0, b = (y - wall.k.cy) / 300.0;
      wall.range.at(x, y) = static_cast<float>(2.0 * std::sqrt(1 + a * a + b * b));
    }
  const Flat far = flat(W, H, 300.0, 1.0f, 1000.0);
  CameraRainParams p = params(100.0, 1.0 / 60, 5);
  p.epsilon = 0.0, p.drops.drop_min_mm = 0.3, p.z_split_m = 8.0;
  const Image with = render_camera_rain(scene_of(wall, false, {0, 0, 0}), p, two_threads());
  const Image open = render_camera_rain(scene_of(far, false, {0, 0, 0}), p, two_threads());
  p.z_split_m = 2.0;
  const Image near = render_camera_rain(scene_of(far, false, {0, 0, 0}), p, two_threads());
  p.z_split_m = 2.02;
  const Image slack = render_camera_rain(scene_of(far, false, {0, 0, 0}), p, two_threads());
  double a_with = 0.0, a_near = 0.0, a_open = 0.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) {
      const double aw = 1.0 - with.at(x, y, 0);
      EXPECT_LE(aw, 1.0 - slack.at(x, y, 0) + 1e-6) << x << "," << y;
      a_with += aw, a_near += 1.0 - near.at(x, y, 0), a_open += 1.0 - open.at(x, y, 0);
    }
  EXPECT_GT(a_near, 0.0);
  EXPECT_NEAR(a_with / a_near, 1.0, 0.01);
  EXPECT_GT(a_open, 1.2 * a_near);  // the drops beyond 2 m are many: the wall hides something
  // The right half (but for the splats at the edge) is the open scene's.
  for (int y = 0; y < H; ++y)
    for (int x = W / 2 + 8; x < W; ++x) ASSERT_EQ(with.at(x, y, 0), open.at(x, y, 0)) << x << "," << y;
}

// Drawn + analytic transmittance is e^{−σ_cam·r} in expectation: a white scene at range r, black
// drops, no airlight; the image's mean over 4 seeds within 1 % at r = 10, 50 and 200 m (z_split
// 20 m: 10 m is mostly drawn, 50 and 200 m mostly analytic), at the default thinning.
TEST(CameraRain, DrawnAndAnalyticTransmittanceIsBeerLambert) {
  const int W = 240, H = 120;
  for (double r : {10.0, 50.0, 200.0}) {
    Flat fl = flat(W, H, 250.0, 1.0f, r);
    double mean = 0.0;
    for (std::uint64_t seed = 1; seed <= 4; ++seed) {
      const CameraRainParams p = params(100.0, 1.0 / 60, seed);
      const Image out = render_camera_rain(scene_of(fl, true, {0, 0, 0}), p, two_threads());
      double s = 0.0;
      for (int i = 0; i < W * H; ++i) s += out.data[3 * static_cast<std::size_t>(i)];
      mean += s / (W * H) / 4.0;
    }
    const double expect = std::exp(-camera_rain_extinction_per_m(100.0) * r);
    EXPECT_NEAR(mean / expect, 1.0, 0.01) << "r = " << r;
  }
}

TEST(CameraRain, BadParametersAreRefused) {
  CameraRainParams p;
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--rate"), std::string::npos);
  p.drops.rate_mm_h = 5.0;
  p.wind = "1,2";
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--wind"), std::string::npos);
  p.wind = "1,x,3";
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--wind"), std::string::npos);
  p.wind = "0,0,0";
  p.f_number = 2.8;
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--focus-distance"), std::string::npos);
  p.f_number.reset();
  p.z_split_m = 0.1;
  EXPECT_NE(error_of([&] { validate_camera_rain(p); }).find("--z-split"), std::string::npos);
}

class CameraRainCli : public ScratchDirTest {};

// `brume rain` from files, and `brume run` of its record: the same image bit for bit. Rate 0
// without --visibility gives the image back.
TEST_F(CameraRainCli, RunsAndBrumeRunRepeatsIt) {
  const Scene s = scene(96, 64, 12);
  write_image(p("in.exr"), s.rgb, WriteOptions{});
  write_image(p("range.exr"), s.range, WriteOptions{});
  fs::create_directories(p("first"));
  const std::string in = " --image " + p("in.exr") + " --range " + p("range.exr") + " --fx 80 ";
  const CliRun r = run("rain" + in + "--rate 25 --rain-seed 4 --wind 0,2,0 --ego-speed 10 --visibility 300 --out " +
                       p("first/o.exr") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["command"], "rain");
  EXPECT_EQ(rec["job"]["rain"]["rain-seed"], 4);
  for (const char* k : {"seed", "z_split_m", "epsilon", "q_eff", "drop_min_mm", "drop_max_mm", "exposure_s"})
    EXPECT_TRUE(rec["rain"].contains(k)) << k;
  EXPECT_EQ(rec["rain"]["extinction_per_m"].get<double>(), camera_rain_extinction_per_m(25.0));
  EXPECT_GT(rec["rain"]["drops_drawn"].get<std::size_t>(), 0u);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.exr"), p("again/o.exr"));
  const CliRun zero = run("rain" + in + "--rate 0 --out " + p("zero.exr"));
  ASSERT_EQ(zero.status, 0) << zero.output;
  const Image z = read_color(p("zero.exr"));
  ASSERT_EQ(z.data.size(), s.rgb.data.size());
  for (std::size_t i = 0; i < z.data.size(); ++i) ASSERT_NEAR(z.data[i], s.rgb.data[i], 1e-6f) << i;
  // --mask: black on the left half keeps the image there.
  Image mask(96, 64, 1, 1.0f);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 48; ++x) mask.at(x, y) = 0.0f;
  write_image(p("mask.exr"), mask, WriteOptions{});
  const CliRun masked = run("rain" + in + "--rate 100 --mask " + p("mask.exr") + " --out " + p("masked.exr"));
  ASSERT_EQ(masked.status, 0) << masked.output;
  const Image m = read_color(p("masked.exr"));
  double changed = 0.0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 96; ++x)
      for (int c = 0; c < 3; ++c) {
        if (x < 48) ASSERT_EQ(m.at(x, y, c), s.rgb.at(x, y, c)) << x << "," << y;
        else changed += std::abs(m.at(x, y, c) - s.rgb.at(x, y, c));
      }
  EXPECT_GT(changed, 0.0);
  // --lidar: the scan through the same rain, as brume lidar rain writes it.
  std::vector<float> pts;
  for (int i = 0; i < 2000; ++i) {
    const double a = 0.003 * i, r = 3.0 + 0.02 * i;
    pts.insert(pts.end(), {static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)), -1.0f,
                           static_cast<float>((i % 7) / 7.0)});
  }
  {
    std::ofstream f(p("scan.bin"), std::ios::binary);
    f.write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  }
  fs::create_directories(p("l"));
  const CliRun both = run("rain" + in + "--rate 50 --rain-seed 9 --lidar " + p("scan.bin") + " --lidar-out " +
                          p("l/o.bin") + " --out " + p("l/o.exr") + " --record " + p("l/o.json"));
  ASSERT_EQ(both.status, 0) << both.output;
  const CliRun alone = run("lidar rain --points " + p("scan.bin") + " --rate 50 --seed 9 --out " + p("alone.bin"));
  ASSERT_EQ(alone.status, 0) << alone.output;
  EXPECT_EQ(file_bytes(p("l/o.bin")), file_bytes(p("alone.bin")));
  const CliRun again2 = run("run " + p("l/o.json") + " --out-dir " + p("l2"));
  ASSERT_EQ(again2.status, 0) << again2.output;
  EXPECT_EQ(file_bytes(p("l/o.bin")), file_bytes(p("l2/o.bin")));
  const CliRun half = run("rain" + in + "--rate 25 --lidar " + p("scan.bin") + " --out " + p("half.exr"));
  EXPECT_NE(half.status, 0);
  EXPECT_NE(half.output.find("--lidar-out"), std::string::npos) << half.output;
  const CliRun bad = run("rain" + in + "--rate 25 --wind 3 --out " + p("bad.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--wind"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("bad.exr")));
}

// KITTI object 000001 (image and Velodyne scan), 25 mm/h: runs, draws streaks, changes the image,
// and `brume run` repeats it bit for bit.
TEST_F(CameraRainCli, KittiFrame) {
  const std::string k = "kitti_object_000001";
  if (!have_data(k + "/velodyne/000001.bin")) GTEST_SKIP() << data_absent(k + "/velodyne/000001.bin");
  const std::string K = data_path(k);
  fs::create_directories(p("first"));
  const CliRun r = run("rain --image " + K + "/image_2/000001.png --velodyne " + K + "/velodyne/000001.bin --kitti-calib " +
                       K + "/calib/000001.txt --rate 25 --out " + p("first/o.png") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_GT(rec["rain"]["drops_drawn"].get<std::size_t>(), 100u);
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("first/o.png"), p("again/o.png"));
}

}  // namespace rain_camera_tests
