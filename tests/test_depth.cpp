// Depth conversions against closed forms and real data: z <-> range at the
// image corners, depth-buffer round trips for every convention, the
// Middlebury / ETH3D disparity formula and its unknowns, the KITTI lidar
// projection against the dataset's own object labels, and the error paths.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/prepare.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

TEST(Depth, ZToRangeAtTheCorners) {
  // range = z sqrt(1 + ((u-cx)/fx)^2 + ((v-cy)/fy)^2); exact up to float rounding (1e-6 relative).
  Intrinsics k;
  k.fx = 500, k.fy = 480, k.cx = 319.5, k.cy = 239.5;
  Image z(640, 480, 1, 10.0f);
  Image r = z_to_range(z, k);
  const int us[] = {0, 639, 0, 639}, vs[] = {0, 0, 479, 479};
  for (int i = 0; i < 4; ++i) {
    const double a = (us[i] - 319.5) / 500.0, b = (vs[i] - 239.5) / 480.0;
    EXPECT_NEAR(r.at(us[i], vs[i]), 10.0 * std::sqrt(1 + a * a + b * b), 1e-5);
  }
  EXPECT_NEAR(r.at(320, 240), 10.0 * std::sqrt(1 + std::pow(0.5 / 500, 2) + std::pow(0.5 / 480, 2)), 1e-5);
  Image back = range_to_z(r, k);
  for (float v : back.data) ASSERT_NEAR(v, 10.0f, 1e-5);
  // The default principal point is the image centre ((W-1)/2, (H-1)/2).
  Intrinsics d;
  d.fx = 500;
  Image r2 = z_to_range(z, d);
  EXPECT_FLOAT_EQ(r2.at(0, 0), r2.at(639, 479));
}

TEST(Depth, FieldOfViewSpansTheImage) {
  // 90 degrees across 200 px: the edge ray is at 45 degrees, fx = 100.
  Intrinsics k = intrinsics_from_fov(200, 100, 90.0, NAN);
  EXPECT_NEAR(k.fx, 100.0, 1e-9);
  EXPECT_NEAR(k.fy, 100.0, 1e-9);
  EXPECT_THROW(intrinsics_from_fov(200, 100, 180.0, NAN), Error);
}

TEST(Depth, DepthBufferRoundTripsEveryConvention) {
  // Encode a known z with each convention, decode, compare (double precision:
  // 1e-9 relative). Plus the closed-form anchors of each convention.
  for (auto c : {DepthBufferConvention::opengl, DepthBufferConvention::d3d, DepthBufferConvention::reversed})
    for (double far : {100.0, static_cast<double>(INFINITY)})
      for (double z : {0.5, 1.0, 3.7, 42.0, 99.0}) {
        const double d = z_to_depth_buffer(z, c, 0.5, far);
        EXPECT_GE(d, 0.0);
        EXPECT_LE(d, 1.0);
        EXPECT_NEAR(depth_buffer_to_z(d, c, 0.5, far) / z, 1.0, 1e-9) << int(c) << " far " << far << " z " << z;
      }
  // OpenGL: d = 0 -> z_ndc = -1 -> z = near; d = 1/2 -> z_ndc = 0 -> 2fn/(f+n) (Zhou eq. 3-5).
  EXPECT_NEAR(depth_buffer_to_z(0.0, DepthBufferConvention::opengl, 1.0, 100.0), 1.0, 1e-12);
  EXPECT_NEAR(depth_buffer_to_z(0.5, DepthBufferConvention::opengl, 1.0, 100.0), 200.0 / 101.0, 1e-12);
  EXPECT_NEAR(depth_buffer_to_z(0.0, DepthBufferConvention::d3d, 1.0, 100.0), 1.0, 1e-12);
  EXPECT_NEAR(depth_buffer_to_z(1.0, DepthBufferConvention::reversed, 1.0, 100.0), 1.0, 1e-12);
  EXPECT_NEAR(depth_buffer_to_z(0.0, DepthBufferConvention::reversed, 1.0, 100.0), 100.0, 1e-9);
  // The cleared value is background: unknown.
  Image buf(2, 1, 1);
  buf.data = {1.0f, 0.25f};
  Image z = depth_buffer_to_z(buf, DepthBufferConvention::opengl, 0.1, 50.0);
  EXPECT_TRUE(std::isnan(z.data[0]));
  EXPECT_TRUE(std::isfinite(z.data[1]));
  buf.data = {0.0f, 0.25f};
  EXPECT_TRUE(std::isnan(depth_buffer_to_z(buf, DepthBufferConvention::reversed, 0.1, 50.0).data[0]));
  EXPECT_THROW(depth_buffer_to_z(buf, DepthBufferConvention::opengl, 5.0, 5.0), Error);   // near >= far
  EXPECT_THROW(depth_buffer_to_z(buf, DepthBufferConvention::opengl, -1.0, 5.0), Error);  // near <= 0
}

TEST(Depth, DepthBufferImageFormIsTheDoubleFormulaToAFewUlp) {
  // The image conversion (and the GPU fog pass) evaluate 1/z = (1 - d) a + d b
  // in f32 (src/depth/depth_math.glsl); the double textbook formula for the
  // same stored d is the reference. Bound 4e-7 relative (~3 ulp: a and b
  // rounded to f32, two products, a sum and the reciprocal, no cancellation:
  // both terms >= 0), over d in (0, 1) densely and near both planes.
  for (auto c : {DepthBufferConvention::opengl, DepthBufferConvention::d3d, DepthBufferConvention::reversed})
    for (double far : {2000.0, 60.0, static_cast<double>(INFINITY)}) {
      const double n = 0.3;
      const DepthBufferLinear lin = depth_buffer_linear(c, n, far);
      Image buf(4001, 1, 1);
      for (int i = 0; i < buf.width; ++i) {
        const double t = (i + 0.5) / buf.width;  // also within 1e-6 of each plane
        buf.data[i] = static_cast<float>(i < 3 ? 1e-6 * (i + 1) : i > buf.width - 4 ? 1.0 - 1e-6 * (buf.width - i) : t);
      }
      const Image z = depth_buffer_to_z(buf, c, n, far);
      double worst = 0.0;
      for (int i = 0; i < buf.width; ++i) {
        const float d = buf.data[i];
        if (d == lin.clear) continue;
        const double want = depth_buffer_to_z(static_cast<double>(d), c, n, far);
        worst = std::max(worst, std::abs(z.data[i] / want - 1.0));
      }
      EXPECT_LT(worst, 4e-7) << int(c) << " far " << far;
    }
  EXPECT_THROW(depth_buffer_linear(DepthBufferConvention::d3d, 1.0, 0.5), Error);  // far < near
}

TEST(Depth, DisparityFormulaAndUnknowns) {
  // Z = f B / (d + doffs); inf, NaN and d + doffs <= 0 are unknown.
  Image d(5, 1, 1);
  d.data = {10.0f, 2.5f, INFINITY, 0.0f, -3.0f};
  Image z = disparity_to_z(d, 500.0, 0.1, 0.0);
  EXPECT_NEAR(z.data[0], 5.0, 1e-6);
  EXPECT_NEAR(z.data[1], 20.0, 1e-5);
  EXPECT_TRUE(std::isnan(z.data[2]));
  EXPECT_TRUE(std::isnan(z.data[3]));
  EXPECT_TRUE(std::isnan(z.data[4]));
  Image z2 = disparity_to_z(d, 500.0, 0.1, 4.0);  // doffs shifts the zero
  EXPECT_NEAR(z2.data[3], 12.5, 1e-5);
  EXPECT_NEAR(z2.data[4], 50.0, 1e-4);
  EXPECT_THROW(disparity_to_z(d, 0.0, 0.1, 0.0), Error);
  EXPECT_THROW(disparity_to_z(d, 500.0, -0.1, 0.0), Error);
}

TEST(Depth, CalibErrors) {
  fs::path dir = fs::temp_directory_path() / ("brume_calib_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "nobase.txt") << "cam0=[500 0 10; 0 500 10; 0 0 1]\ndoffs=0\n";
  std::ofstream(dir / "zerof.txt") << "cam0=[0 0 10; 0 0 10; 0 0 1]\nbaseline=100\n";
  std::ofstream(dir / "short.txt") << "cam0=[500 0 10]\nbaseline=100\n";
  for (const char* f : {"nobase.txt", "zerof.txt", "short.txt"}) {
    try {
      read_stereo_calib((dir / f).string());
      ADD_FAILURE() << f << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << e.what();
    }
  }
  fs::remove_all(dir);
}

TEST(Depth, Eth3dPlaygroundConverts) {
  const std::string rel = "eth3d_two_view/playground_1l/";
  BRUME_REQUIRE_DATA(rel + "disp0.pfm");
  StereoCalib c = read_stereo_calib(data_path(rel + "calib.txt"));
  EXPECT_DOUBLE_EQ(c.f_px, 542.019);
  EXPECT_NEAR(c.baseline_m, 0.0595549, 1e-12);
  DepthSource s;
  s.disparity = data_path(rel + "disp0.pfm");
  s.calib = data_path(rel + "calib.txt");
  LoadedDepth ld = load_depth(s);
  // SOURCES.md: 49.6 % valid, depth 1.61-15.2 m (range a little longer off-axis).
  std::size_t known = 0;
  float lo = 1e9f, hi = 0.0f;
  for (float r : ld.range.data)
    if (std::isfinite(r)) ++known, lo = std::min(lo, r), hi = std::max(hi, r);
  EXPECT_NEAR(static_cast<double>(known) / ld.range.pixels(), 0.496, 0.005);
  EXPECT_GT(lo, 1.55f);
  EXPECT_LT(hi, 18.0f);
  // One pixel by the formula, independently.
  Image disp = read_scalar(data_path(rel + "disp0.pfm"));
  for (std::size_t i = 0; i < disp.data.size(); i += 997)
    if (std::isfinite(disp.data[i]) && disp.data[i] > 0) {
      const int u = static_cast<int>(i % disp.width), v = static_cast<int>(i / disp.width);
      const double z = 542.019 * 0.0595549 / disp.data[i];
      const double a = (u - 541.836) / 542.019, b = (v - 255.198) / 542.019;
      // 1e-4 relative: the library works in float (7 significant digits) and
      // the calib values above are rounded to 6; the formula itself is exact.
      EXPECT_NEAR(ld.range.data[i], z * std::sqrt(1 + a * a + b * b), 1e-4 * z);
    }
}

TEST(Depth, Middlebury2005DisparityPng) {
  // The flags of test_util.hpp's middlebury2005() against SOURCES.md's
  // formula Z[mm] = 160 * 3740 / (I + dmin), evaluated here directly.
  const std::string rel = "middlebury2005_thirdsize/Art/";
  BRUME_REQUIRE_DATA(rel + "disp1.png");
  double dmin = 0;
  std::ifstream(data_path(rel + "dmin.txt")) >> dmin;
  Image range = load_depth(middlebury2005("Art")).range;
  Image I = read_scalar(data_path(rel + "disp1.png"));
  Intrinsics k;
  k.fx = 3740.0 / 3.0;
  Image zmap = range_to_z(range, k);
  for (std::size_t i = 0; i < I.data.size(); i += 101) {
    if (I.data[i] == 0) {
      EXPECT_TRUE(std::isnan(range.data[i]));
      continue;
    }
    // 2e-5 m: float rounding of z (<= 3 m, ulp 2.4e-7) through the disparity
    // scale and offset, a few ulp; the formula is the one in SOURCES.md.
    EXPECT_NEAR(zmap.data[i], 0.160 * 3740.0 / (I.data[i] + dmin), 2e-5);
  }
}

TEST(Depth, KittiScanProjectsOntoTheLabelledObjects) {
  // The projected scan covers a few percent of the image (SOURCES.md: 18 630
  // points in view, no returns above row 122), and the lidar depth inside the
  // labelled truck and car boxes agrees with the labels' camera-frame z
  // (location z is the box centre; the visible rear face is up to l/2 nearer).
  const std::string rel = "kitti_object_000001/";
  BRUME_REQUIRE_DATA(rel + "velodyne/000001.bin");
  KittiCalib c = read_kitti_calib(data_path(rel + "calib/000001.txt"));
  LidarImage li = project_velodyne(data_path(rel + "velodyne/000001.bin"), c, 1242, 375);
  EXPECT_EQ(li.points, 120268u);
  // SOURCES.md counted 18 630 in view with its own projection; the count is
  // deterministic here, the slack covers points on the image border that a
  // different rounding of the pixel centre keeps or drops (~0.5 %).
  EXPECT_NEAR(static_cast<double>(li.points_in_view), 18630.0, 100.0);
  EXPECT_GT(li.coverage, 0.02);
  EXPECT_LT(li.coverage, 0.06);
  for (int v = 0; v < 115; ++v)  // rows above 122 per SOURCES.md, with a margin for pixel rounding
    for (int u = 0; u < 1242; ++u) ASSERT_TRUE(std::isnan(li.range.at(u, v))) << u << "," << v;
  struct Box {
    double l, t, r, b, z, len;
  };
  for (Box box : {Box{599.41, 156.40, 629.75, 189.25, 69.44, 12.34}, Box{387.63, 181.54, 423.81, 203.12, 58.49, 3.69}}) {
    std::vector<float> zs;
    for (int v = static_cast<int>(box.t) + 2; v < box.b - 2; ++v)
      for (int u = static_cast<int>(box.l) + 2; u < box.r - 2; ++u)
        if (std::isfinite(li.z.at(u, v))) zs.push_back(li.z.at(u, v));
    ASSERT_GT(zs.size(), 5u);
    std::nth_element(zs.begin(), zs.begin() + zs.size() / 2, zs.end());
    const double med = zs[zs.size() / 2];
    EXPECT_GT(med, box.z - box.len / 2 - 1.5) << "box at z " << box.z;
    EXPECT_LT(med, box.z + 0.5) << "box at z " << box.z;
  }
  // Truncated scan files are refused.
  fs::path cut = fs::temp_directory_path() / ("brume_cut_" + std::to_string(::getpid()) + ".bin");
  std::ofstream(cut, std::ios::binary) << "0123456789";
  EXPECT_THROW(project_velodyne(cut.string(), c, 1242, 375), Error);
  fs::remove(cut);
}

TEST(Depth, SourceErrors) {
  DepthSource none;
  EXPECT_THROW(load_depth(none), Error);
  DepthSource two;
  two.range = "a.exr";
  two.z = "b.exr";
  EXPECT_THROW(load_depth(two), Error);
  const std::string rel = "eth3d_two_view/playground_1l/";
  BRUME_REQUIRE_DATA(rel + "disp0.pfm");
  DepthSource s;
  s.disparity = data_path(rel + "disp0.pfm");
  s.calib = data_path(rel + "calib.txt");
  try {
    load_depth(s, 640, 480);  // the image it should belong to has another size
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("941x490"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("640x480"), std::string::npos) << e.what();
  }
  DepthSource z;
  z.z = data_path(rel + "disp0.pfm");  // planar z without intrinsics
  EXPECT_THROW(load_depth(z), Error);
}

TEST(Depth, PrepareRefusesTheSparseKittiScan) {
  // A projected Velodyne scan covers ~4 % of the pixels: prepare must refuse
  // it with a message that says so and what to do, not "fill" it.
  const std::string rel = "kitti_object_000001/";
  BRUME_REQUIRE_DATA(rel + "velodyne/000001.bin");
  DepthSource s;
  s.velodyne = data_path(rel + "velodyne/000001.bin");
  s.kitti_calib = data_path(rel + "calib/000001.txt");
  s.like = data_path(rel + "image_2/000001.png");
  LoadedDepth ld = load_depth(s);
  EXPECT_NEAR(ld.record["coverage"].get<double>(), 0.04, 0.01);
  try {
    prepare_range(ld.range);
    FAIL() << "sparse scan accepted";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("3.99%"), std::string::npos) << m;
    EXPECT_NE(m.find("--prepare off"), std::string::npos) << m;
  }
}

TEST(Depth, UnknownValueMarksStoredSentinels) {
  // A GeoPose3K-like range map: -1 marks the sky. Stored values equal to
  // --unknown-value become NaN before any scaling; other negatives are refused
  // with a message that names the file, the value and the flag that fixes it.
  const fs::path dir = fs::temp_directory_path() / ("brume_test_unknown_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "r.exr").string();
  Image r(6, 4, 1, 250.0f);
  for (int x = 0; x < 6; ++x) r.at(x, 0) = -1.0f;  // sky row
  WriteOptions data;
  data.is_color = false;
  write_image(path, r, data);

  DepthSource s;
  s.range = path;
  try {
    load_depth(s);
    ADD_FAILURE() << "a negative range was accepted";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(path), std::string::npos) << m;
    EXPECT_NE(m.find("--unknown-value -1"), std::string::npos) << m;
    EXPECT_NE(m.find("(0, 0)"), std::string::npos) << m;
  }
  s.unknown_value = -1.0;
  s.depth_scale = 2.0;  // compared in file units: -1 still matches, not -1 / 2 or -1 * 2
  LoadedDepth d = load_depth(s);
  for (int x = 0; x < 6; ++x) EXPECT_TRUE(std::isnan(d.range.at(x, 0)));
  EXPECT_EQ(d.range.at(0, 1), 500.0f);  // 250 stored x 2 m per unit
  EXPECT_EQ(d.record["unknown_value"], -1.0);
  EXPECT_EQ(d.record["unknown_value_pixels"], 6);
  EXPECT_EQ(d.record["unknown_pixels"], 6);
  // A sentinel that matches nothing leaves the negatives refused, and says so.
  s.unknown_value = -2.0;
  try {
    load_depth(s);
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--unknown-value -2"), std::string::npos) << e.what();
  }
  // A lidar scan has no stored grid: the flag is refused, not ignored.
  DepthSource v;
  v.velodyne = (dir / "scan.bin").string();
  v.unknown_value = -1.0;
  try {
    load_depth(v, 10, 10);
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--velodyne"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}
