// The camera against closed forms: where a level camera looks for each yaw,
// what pitch and roll do to the axis and to image-right, the pixel -> world
// -> pixel round trip, view matrices (pose -> M -> pose, the OpenGL eye
// flip), the height of a ray over the ground plane, the KITTI camera of
// depth_camera, and every rejected pose and view-matrix file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "brume/camera.hpp"
#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

Intrinsics test_k() {
  Intrinsics k;
  k.fx = 800.0, k.fy = 760.0, k.cx = 321.25, k.cy = 238.5;  // off-centre, non-square: catches swapped terms
  return k;
}

Camera posed(double yaw, double pitch, double roll, double height = 1.6, double x = 0.0, double z = 0.0) {
  CameraPose p;
  p.yaw_deg = yaw, p.pitch_deg = pitch, p.roll_deg = roll, p.height_m = height, p.x_m = x, p.z_m = z;
  return make_camera(test_k(), 640, 480, p);
}

// Rotation and sin/cos of degrees round each entry once or twice: 1e-14 is
// ~50 ulps at unit scale, far below any convention error (O(1)).
constexpr double kDir = 1e-14;

void expect_vec(const Vec3& a, const Vec3& b, double tol, const std::string& what) {
  EXPECT_NEAR(a.x, b.x, tol) << what;
  EXPECT_NEAR(a.y, b.y, tol) << what;
  EXPECT_NEAR(a.z, b.z, tol) << what;
}

Vec3 unit(Vec3 v) {
  const double n = std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
  return {v.x / n, v.y / n, v.z / n};
}


struct TempDir {
  fs::path dir = fs::temp_directory_path() / ("brume_camera_" + std::to_string(::getpid()));
  TempDir() { fs::create_directories(dir); }
  ~TempDir() { fs::remove_all(dir); }
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path p = dir / name;
    std::ofstream(p) << text;
    return p.string();
  }
};
}  // namespace

TEST(Camera, PrincipalPointRayIsTheOpticalAxis) {
  const Camera c = posed(37.0, -12.0, 25.0);
  const Vec3 cv = c.pixel_ray_cv(c.k.cx, c.k.cy);
  EXPECT_EQ(cv.x, 0.0);
  EXPECT_EQ(cv.y, 0.0);
  EXPECT_EQ(cv.z, 1.0);
  // Axis = (sin yaw cos pitch, sin pitch, -cos yaw cos pitch), independent of roll.
  const double y = 37.0 * kDeg, p = -12.0 * kDeg;
  expect_vec(c.world_ray(c.k.cx, c.k.cy), {std::sin(y) * std::cos(p), std::sin(p), -std::cos(y) * std::cos(p)}, kDir,
             "optical axis");
}

TEST(Camera, LevelCameraCompassDirections) {
  // World: x east, y up, z south. North = -z.
  const Vec3 north{0, 0, -1}, east{1, 0, 0}, south{0, 0, 1}, west{-1, 0, 0};
  const double yaws[] = {0, 90, 180, 270, 360, -90};
  const Vec3 want[] = {north, east, south, west, north, west};
  for (int i = 0; i < 6; ++i) {
    const Camera c = posed(yaws[i], 0, 0);
    expect_vec(c.world_ray(c.k.cx, c.k.cy), want[i], kDir, "yaw " + std::to_string(yaws[i]));
  }
  // Looking north, image-right is east and image-down is down: the pixel one
  // focal length right of the principal point sees north-east, 45 deg.
  const Camera c = posed(0, 0, 0);
  expect_vec(c.world_ray(c.k.cx + c.k.fx, c.k.cy), unit({1, 0, -1}), kDir, "image right");
  expect_vec(c.world_ray(c.k.cx, c.k.cy + c.k.fy), unit({0, -1, -1}), kDir, "image down");
  // Identity orientation, world_from_cv = diag(1, -1, -1).
  const RigidTransform t = c.world_from_camera();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_EQ(t.rotation.m[i][j], i != j ? 0.0 : i == 0 ? 1.0 : -1.0);
  EXPECT_EQ(t.translation.y, 1.6);
}

TEST(Camera, PitchRaisesTheAxis) {
  for (double yaw : {0.0, 123.0}) {
    const Camera c = posed(yaw, 30.0, 0.0);
    const Vec3 a = c.world_ray(c.k.cx, c.k.cy);
    EXPECT_NEAR(std::asin(a.y) / kDeg, 30.0, 1e-12) << "elevation at yaw " << yaw;
    EXPECT_NEAR(std::atan2(a.x, -a.z) / kDeg, yaw, 1e-12) << "azimuth unchanged by pitch";
  }
}

TEST(Camera, RollTurnsTheContentClockwise) {
  // On paper: R_roll = rotation about eye +z (pointing backwards) by +roll.
  // Image-right in eye space is (1, 0, 0); R_z(90) takes it to (0, 1, 0):
  // world UP for a level, north-looking camera. Image-up (0, 1, 0) goes to
  // (-1, 0, 0): west. So the sky (up) is imaged on the right edge and the
  // ground on the left: what was at the top moved to the right, a clockwise
  // turn of the content. Roll -90 mirrors this (image-right points down).
  const Camera c = posed(0, 0, 90);
  expect_vec(c.world_ray(c.k.cx + c.k.fx, c.k.cy), unit({0, 1, -1}), kDir, "roll 90: image-right points up");
  expect_vec(c.world_ray(c.k.cx, c.k.cy - c.k.fy), unit({-1, 0, -1}), kDir, "roll 90: image-up points west");
  const Camera m = posed(0, 0, -90);
  expect_vec(m.world_ray(m.k.cx + m.k.fx, m.k.cy), unit({0, -1, -1}), kDir, "roll -90: image-right points down");
  // A point above the horizon, straight ahead, lands right of centre on the
  // centre row with roll 90 (above centre with roll 0): clockwise by 90 deg.
  const Vec3 high{0.0, 1.6 + 10.0, -50.0};
  const auto level = posed(0, 0, 0).pixel_of(high), rolled = c.pixel_of(high);
  ASSERT_TRUE(level && rolled);
  EXPECT_NEAR((*level)[0], c.k.cx, 1e-9);
  EXPECT_LT((*level)[1], c.k.cy);  // above the centre (row 0 is the top)
  EXPECT_GT((*rolled)[0], c.k.cx);
  EXPECT_NEAR((*rolled)[1], c.k.cy, 1e-9);
}

TEST(Camera, PixelWorldPixelRoundTrip) {
  // Each step is a few double operations (~1e-16 relative) on world
  // coordinates of up to ~1e3 m, scaled by fx ~ 800 px: ~1e-10 px at worst.
  // 1e-9 px leaves margin, while any frame or sign error moves pixels by
  // whole pixels.
  const double poses[][6] = {{0, 0, 0, 1.6, 0, 0}, {37, -12, 25, 3, 10, -4}, {250, 60, -170, -2, 5, 7},
                             {359.5, -89, 180, 100, 0, 0}};
  for (const auto& p : poses) {
    const Camera c = posed(p[0], p[1], p[2], p[3], p[4], p[5]);
    for (double v = -40.0; v <= 520.0; v += 37.5)
      for (double u = -40.0; u <= 680.0; u += 41.25)
        for (double r : {0.5, 7.0, 1000.0}) {
          const Vec3 w = c.world_point(u, v, r);
          const Vec3 d{w.x - c.position_m.x, w.y - c.position_m.y, w.z - c.position_m.z};
          ASSERT_NEAR(std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z), r, 1e-12 * r) << "range along the ray";
          const auto px = c.pixel_of(w);
          ASSERT_TRUE(px);
          ASSERT_NEAR((*px)[0], u, 1e-9) << "yaw " << p[0] << " u " << u << " v " << v << " r " << r;
          ASSERT_NEAR((*px)[1], v, 1e-9) << "yaw " << p[0] << " u " << u << " v " << v << " r " << r;
        }
    // Behind the camera there is no pixel.
    const Vec3 a = c.world_ray(c.k.cx, c.k.cy);
    EXPECT_FALSE(c.pixel_of({c.position_m.x - a.x, c.position_m.y - a.y, c.position_m.z - a.z}));
  }
}

TEST(Camera, YawPitchRollRoundTripAndNormalisation) {
  for (double yaw = -720.0; yaw <= 720.0; yaw += 47.0)
    for (double pitch = -85.0; pitch <= 85.0; pitch += 17.0)
      for (double roll = -175.0; roll <= 180.0; roll += 35.0) {
        const YawPitchRoll a = ypr_from_rotation(rotation_from_ypr(yaw, pitch, roll));
        double want_yaw = std::fmod(yaw, 360.0);
        if (want_yaw < 0) want_yaw += 360.0;
        // atan2 of entries of a rotation built from sin/cos: ~1e-13 degrees.
        ASSERT_NEAR(a.yaw_deg, want_yaw, 1e-11) << yaw << " " << pitch << " " << roll;
        ASSERT_NEAR(a.pitch_deg, pitch, 1e-11);
        ASSERT_NEAR(a.roll_deg, roll, 1e-11);
      }
  EXPECT_NEAR(ypr_from_rotation(rotation_from_ypr(0, 0, -180)).roll_deg, 180.0, 1e-11);  // (-180, 180]
  // Axis vertical: yaw and roll are one turn; the reported pose (roll 0) is the same rotation.
  for (double pitch : {90.0, -90.0}) {
    const Mat3 r = rotation_from_ypr(10.0, pitch, 30.0);
    const YawPitchRoll a = ypr_from_rotation(r);
    EXPECT_EQ(a.roll_deg, 0.0);
    EXPECT_NEAR(a.pitch_deg, pitch, 1e-11);
    const Mat3 back = rotation_from_ypr(a.yaw_deg, a.pitch_deg, a.roll_deg);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(back.m[i][j], r.m[i][j], 1e-12) << "pitch " << pitch;
  }
}

TEST(Camera, ViewMatrixRoundTripAndEyeFlip) {
  const Camera c = posed(212.0, 17.0, -33.0, 4.5, -3.0, 12.0);
  const Mat4 m = c.view_matrix();
  EXPECT_EQ(m.m[3][0], 0.0);
  EXPECT_EQ(m.m[3][3], 1.0);
  const Camera b = Camera::from_view_matrix(m, test_k(), 640, 480);
  const YawPitchRoll a = b.ypr();
  EXPECT_NEAR(a.yaw_deg, 212.0, 1e-11);
  EXPECT_NEAR(a.pitch_deg, 17.0, 1e-11);
  EXPECT_NEAR(a.roll_deg, -33.0, 1e-11);
  expect_vec(b.position_m, {-3.0, 4.5, 12.0}, 1e-13, "camera centre");
  // x_eye = M x_world is the cv point with y and z negated: a point at planar
  // depth z along pixel (u, v) is z ((u-cx)/fx, (v-cy)/fy, 1) in cv, so
  // eye = (z (u-cx)/fx, -z (v-cy)/fy, -z): in front of the camera z_eye < 0.
  const double u = 100.0, v = 400.0, z = 25.0;
  const Vec3 ray = c.pixel_ray_cv(u, v);
  const double range = z * std::sqrt(ray.x * ray.x + ray.y * ray.y + 1.0);
  const Vec3 w = c.world_point(u, v, range);
  double e[3];
  for (int i = 0; i < 3; ++i) e[i] = m.m[i][0] * w.x + m.m[i][1] * w.y + m.m[i][2] * w.z + m.m[i][3];
  const Vec3 want = eye_from_cv({z * ray.x, z * ray.y, z});
  EXPECT_NEAR(e[0], want.x, 1e-12 * range);
  EXPECT_NEAR(e[1], want.y, 1e-12 * range);
  EXPECT_NEAR(e[2], want.z, 1e-12 * range);
  EXPECT_LT(e[2], 0.0);
  expect_vec(eye_from_cv({1, 2, 3}), {1, -2, -3}, 0.0, "flip");
  expect_vec(cv_from_eye(eye_from_cv({1, 2, 3})), {1, 2, 3}, 0.0, "flip twice");
  // No height, no view matrix.
  EXPECT_NE(error_of([] { (void)posed(0, 0, 0, NAN).view_matrix(); }).find("--camera-height"), std::string::npos);
}

TEST(Camera, HeightOverTheGroundPlane) {
  // Camera h above the ground, tilted down by t: the axis point at range r is
  // at h - r sin t; a pixel b = (v - cy)/fy below the centre looks down by
  // t + atan(b), and meets the ground (height 0) at r = h / sin(t + atan b).
  const double h = 1.6, t = 5.0;
  const Camera c = posed(73.0, -t, 0.0, h);
  for (double r : {1.0, 10.0, 18.0})
    EXPECT_NEAR(c.height_of(c.k.cx, c.k.cy, r), h - r * std::sin(t * kDeg), 1e-14 * (1 + r));
  const double v = c.k.cy + 150.0, down = t * kDeg + std::atan(150.0 / c.k.fy);
  // At u = cx the ray stays in the axis's vertical plane, so its depression is t + atan(b).
  EXPECT_NEAR(c.height_of(c.k.cx, v, 7.0), h - 7.0 * std::sin(down), 1e-13);
  EXPECT_NEAR(c.height_of(c.k.cx, v, h / std::sin(down)), 0.0, 1e-13);
  // An unknown height propagates (NaN), it is never taken as 0.
  EXPECT_TRUE(std::isnan(posed(0, -5, 0, NAN).height_of(10, 10, 5.0)));
  EXPECT_NE(error_of([] { posed(0, 0, 0, NAN).require_height("layered fog"); }).find("layered fog needs"),
            std::string::npos);
}

TEST(Camera, FromFieldOfViewAndIntrinsics) {
  const Camera c = camera_from_fov(640, 480, NAN, 60.0);
  EXPECT_NEAR(c.k.fy, 240.0 / std::tan(30.0 * kDeg), 1e-12);
  EXPECT_EQ(c.k.fx, c.k.fy);
  EXPECT_EQ(c.k.cx, 319.5);
  EXPECT_EQ(c.k.cy, 239.5);
  EXPECT_FALSE(c.height_known());
  // The top edge of the image (v = -0.5) is 30 deg above the axis.
  const Vec3 top = c.world_ray(c.k.cx, -0.5);
  EXPECT_NEAR(std::asin(top.y) / kDeg, 30.0, 1e-12);
  Intrinsics k;
  k.fx = 500;
  const Camera d = camera_from_intrinsics(k, 100, 50);
  EXPECT_EQ(d.k.fy, 500.0);
  EXPECT_EQ(d.k.cx, 49.5);
}

TEST(Camera, PoseErrorsNameTheFlag) {
  auto err = [](CameraPose p) { return error_of([&] { make_camera(test_k(), 640, 480, p); }); };
  CameraPose p;
  p.pitch_deg = 95;
  EXPECT_NE(err(p).find("--pitch 95"), std::string::npos) << err(p);
  EXPECT_NE(err(p).find("[-90, 90]"), std::string::npos);
  p = {};
  p.roll_deg = -180;
  EXPECT_NE(err(p).find("--roll -180"), std::string::npos) << err(p);
  p = {};
  p.yaw_deg = INFINITY;
  EXPECT_NE(err(p).find("--yaw inf"), std::string::npos) << err(p);
  p = {};
  p.height_m = -INFINITY;
  EXPECT_NE(err(p).find("--camera-height -inf"), std::string::npos) << err(p);
  p = {};
  p.pitch_deg = NAN;
  EXPECT_NE(err(p).find("--pitch nan"), std::string::npos) << err(p);
  p = {};
  p.view_matrix_file = "pose.txt", p.yaw_deg = 10;
  EXPECT_NE(err(p).find("--view-matrix 'pose.txt' gives the whole pose, but --yaw 10"), std::string::npos) << err(p);
  // Yaw is any finite angle (taken modulo 360).
  p = {};
  p.yaw_deg = -450;
  EXPECT_NEAR(make_camera(test_k(), 640, 480, p).ypr().yaw_deg, 270.0, 1e-11);
  // The sky projections are not cameras: refused, pointing to SkyGeometry.
  const std::string fe = error_of([] { make_camera(test_k(), 640, 480, {}, Projection::fisheye); });
  EXPECT_NE(fe.find("--projection fisheye is a sky projection"), std::string::npos) << fe;
  EXPECT_NE(fe.find("SkyGeometry"), std::string::npos) << fe;
  EXPECT_EQ(parse_projection("equirectangular"), Projection::equirectangular);
  EXPECT_NE(error_of([] { parse_projection("orthographic"); }).find("--projection 'orthographic'"), std::string::npos);
  EXPECT_NE(error_of([] { make_camera(test_k(), 0, 480); }).find("0x480"), std::string::npos);
}

TEST(Camera, ViewMatrixFiles) {
  TempDir t;
  // A good file: commas, comments, blank lines; a level camera looking east
  // (yaw 90) at C = (2, 1.5, -3). R = R_y(-90) has rows (0 0 -1), (0 1 0),
  // (1 0 0); M's upper 3x3 is R^T, its fourth column -R^T C = (3, -1.5, 2).
  const std::string good = t.write("good.txt",
                                   "# OpenGL view matrix\n"
                                   "0, 0, 1, 3   # row 1\n\n"
                                   "0 1 0 -1.5\n"
                                   "-1 0 0 2\n"
                                   "0 0 0 1\n");
  CameraPose p;
  p.view_matrix_file = good;
  const Camera c = make_camera(test_k(), 640, 480, p);
  expect_vec(c.position_m, {2.0, 1.5, -3.0}, 1e-15, "centre from file");
  expect_vec(c.world_ray(c.k.cx, c.k.cy), {1, 0, 0}, kDir, "looks east");
  EXPECT_NEAR(c.ypr().yaw_deg, 90.0, 1e-12);
  // Yaw 30 rounded to 5 digits (within 1e-4 of orthonormal): accepted, snapped
  // to a rotation. R^T = R_y(30): rows (cos 30, 0, sin 30), (0 1 0), (-sin 30, 0, cos 30).
  const std::string rounded = t.write("rounded.txt",
                                      "0.86603 0 0.5 0\n0 1 0 -1\n-0.5 0 0.86603 0\n0 0 0 1\n");
  Camera r = Camera::from_view_matrix(read_view_matrix(rounded), test_k(), 640, 480);
  const Vec3 a = r.world_ray(r.k.cx, r.k.cy);
  EXPECT_NEAR(a.x * a.x + a.y * a.y + a.z * a.z, 1.0, 1e-15) << "orthonormalised";
  EXPECT_NEAR(r.ypr().yaw_deg, 30.0, 1e-3);

  auto err = [&](const std::string& name, const std::string& text) {
    const std::string path = t.write(name, text);
    return error_of([&] { read_view_matrix(path); });
  };
  std::string e = err("word.txt", "1 0 0 0\n0 1 zero 0\n0 0 1 0\n0 0 0 1\n");
  EXPECT_NE(e.find("word.txt', line 2 (row 2): 'zero' is not a number"), std::string::npos) << e;
  e = err("three.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n");
  EXPECT_NE(e.find("three.txt' has 3 rows"), std::string::npos) << e;
  e = err("short.txt", "1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n");
  EXPECT_NE(e.find("short.txt', line 2 (row 2) has 3 numbers"), std::string::npos) << e;
  e = err("five.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n0 0 0 1\n");
  EXPECT_NE(e.find("five.txt', line 5: a fifth row"), std::string::npos) << e;
  e = err("scale.txt", "1 0 0 0\n0 2 0 0\n0 0 1 0\n0 0 0 1\n");
  EXPECT_NE(e.find("scale.txt': row 2 (0 2 0) of the upper 3x3 has length 2"), std::string::npos) << e;
  e = err("shear.txt", "1 0.1 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  EXPECT_NE(e.find("rows 1 (1 0.1 0) and 2 (0 1 0)"), std::string::npos) << e;
  e = err("persp.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 -1 0\n");
  EXPECT_NE(e.find("persp.txt': row 4 is (0 0 -1 0); it must be (0 0 0 1)"), std::string::npos) << e;
  e = err("nan.txt", "1 0 0 0\n0 1 0 nan\n0 0 1 0\n0 0 0 1\n");
  EXPECT_NE(e.find("nan.txt': row 2, column 4 is nan"), std::string::npos) << e;
  e = err("mirror.txt", "-1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  EXPECT_NE(e.find("mirror.txt': the upper 3x3 has determinant -1"), std::string::npos) << e;
  e = error_of([&] { read_view_matrix((t.dir / "absent.txt").string()); });
  EXPECT_NE(e.find("cannot read --view-matrix '"), std::string::npos) << e;
  EXPECT_NE(e.find("absent.txt': no such file"), std::string::npos) << e;
}

TEST(Camera, DepthCameraCoversKitti) {
  TempDir t;
  // A KITTI object calib with the dataset's usual camera-2 numbers: P2 = K [I | t].
  const std::string calib = t.write("calib.txt",
                                    "P0: 721.5377 0 609.5593 0 0 721.5377 172.854 0 0 0 1 0\n"
                                    "P2: 721.5377 0 609.5593 44.85728 0 721.5377 172.854 0.2163791 0 0 1 0.002745884\n"
                                    "R0_rect: 1 0 0 0 1 0 0 0 1\n"
                                    "Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n");
  DepthSource s;
  s.velodyne = "scan.bin";  // depth_camera reads only the calibration
  s.kitti_calib = calib;
  CameraPose pose;
  pose.height_m = 1.65;  // KITTI's camera height
  const Camera c = depth_camera(s, 1242, 375, pose);
  EXPECT_EQ(c.k.fx, 721.5377);
  EXPECT_EQ(c.k.fy, 721.5377);
  EXPECT_EQ(c.k.cx, 609.5593);
  EXPECT_EQ(c.k.cy, 172.854);
  EXPECT_EQ(c.position_m.y, 1.65);
  s.kitti_calib.clear();
  EXPECT_NE(error_of([&] { depth_camera(s, 1242, 375); }).find("--kitti-calib"), std::string::npos);
  // Other sources: the same intrinsics as depth_intrinsics.
  DepthSource z;
  z.z = "z.exr";
  z.fov_x_deg = 70.0;
  const Intrinsics k = depth_intrinsics(z, 640, 480);
  const Camera d = depth_camera(z, 640, 480);
  EXPECT_EQ(d.k.fx, k.fx);
  EXPECT_EQ(d.k.fy, k.fy);
  EXPECT_EQ(d.k.cx, k.cx);
  EXPECT_EQ(d.k.cy, k.cy);
  EXPECT_FALSE(d.height_known());
}
