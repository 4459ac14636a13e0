// brume — depth sources and their conversion to range maps.
//
// Every effect works on a RANGE map: metres from the camera centre along each
// pixel's ray (not planar z: Beer-Lambert needs the distance light travels,
// and range makes the fog independent of the camera's rotation). Unknown is
// NaN. Every depth convention is converted explicitly from flags; nothing is
// guessed.
//
// Pixel convention (OpenCV, Middlebury, KITTI): pixel (u, v) -- column u, row
// v, 0-based, row 0 at the top -- is the point (u, v) in the coordinates of
// the principal point (cx, cy); its ray is ((u - cx)/fx, (v - cy)/fy, 1) and
// range = z |ray|. With only a field of view, the FOV spans the image from
// edge to edge (fx = (W/2) / tan(fov_x/2)) and the principal point is the
// image centre ((W-1)/2, (H-1)/2).
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "brume/camera.hpp"  // Intrinsics
#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

// The convention of every range map brume reads or makes: a pixel's range is
// known when it is finite and not zero; NaN, +-inf and 0 mark it unknown
// (a lidar hole, sky, no return).
inline bool known_range(float r) { return std::isfinite(r) && r != 0.0f; }

// ---- the camera in millimetres, as 3D software states it (Blender) ----------------
// A focal length F and a sensor [mm], the sensor fit and the lens shift, with
// Blender's meaning (BKE_camera_params_compute_viewplane), square pixels:
//   fit auto: the sensor WIDTH spans the image's larger side (the height of a
//     portrait image); horizontal: the width spans the image width; vertical:
//     the sensor HEIGHT spans the image height;
//   s = the side the fit spans [px] (auto: max(W, H); horizontal: W;
//     vertical: H), d = the sensor size on it [mm] (vertical: the height,
//     else the width);
//   fx = fy = F s / d  [px];
//   cx = (W - 1)/2 - shift_x s,  cy = (H - 1)/2 + shift_y s  [px]
// (the shift moves the frame, in units of s: a positive shift_x sees more to
// the right, so the principal point moves left; y up in Blender, down in the
// image). Checked against Blender 3.4's own projection (calc_matrix_camera)
// of the test renders (tests/renders/, docs/renderers.md).
enum class SensorFit { automatic, horizontal, vertical };
const EnumNames<SensorFit>& sensor_fit_names();
struct LensCamera {
  std::optional<double> focal_length_mm;   // [mm] F, > 0
  std::optional<double> sensor_width_mm;   // [mm] > 0 (fits auto, horizontal)
  std::optional<double> sensor_height_mm;  // [mm] > 0 (fit vertical)
  SensorFit sensor_fit = SensorFit::automatic;
  std::array<double, 2> lens_shift{0.0, 0.0};  // [1] Blender's shift_x, shift_y, in units of s
  bool given() const { return focal_length_mm || sensor_width_mm || sensor_height_mm || lens_shift[0] != 0.0 ||
                              lens_shift[1] != 0.0; }
};
// The side s the fit spans [px] and the sensor size d on it [mm]; throws
// brume::Error naming the flag that is missing or would be ignored.
struct LensScale {
  double side_px = 0.0, sensor_mm = 0.0;
  const char* sensor_flag = "--sensor-width";
};
LensScale lens_scale(const LensCamera& c, int width, int height);
// Pixels per millimetre on the sensor: s / d.
// The pixel intrinsics of the camera (above); throws when F or the sensor is missing.
Intrinsics lens_intrinsics(const LensCamera& c, int width, int height);

Image z_to_range(const Image& z, const Intrinsics& k);
Image range_to_z(const Image& range, const Intrinsics& k);

// ---- stereo disparity -------------------------------------------------------
// Z = f B / (d + doffs) with f in pixels and B in metres; d not finite or
// d + doffs <= 0 is unknown.
struct StereoCalib {
  double f_px = 0.0, cx = NAN, cy = NAN;  // cam0 of calib.txt
  double baseline_m = 0.0;                // calib.txt gives millimetres
  double doffs_px = 0.0;
  int width = 0, height = 0;              // 0 when absent
};
// Middlebury 2014 / ETH3D calib.txt: cam0=[f 0 cx; 0 f cy; 0 0 1], doffs, baseline (mm).
StereoCalib read_stereo_calib(const std::string& path);
// The camera of a --calib file: a Middlebury 2014 / ETH3D calib.txt (its
// cam0), or KITTI depth completion's intrinsics/*.txt: the 3x3 matrix K =
// [fx 0 cx; 0 fy cy; 0 0 1] as 9 numbers and nothing else (it has no
// baseline: it converts planar depth, not disparity, which refuses it).
Intrinsics read_calib_camera(const std::string& path);
Image disparity_to_z(const Image& disparity, double f_px, double baseline_m, double doffs_px);

// ---- rasteriser depth buffers ------------------------------------------------
// Window depth d in [0, 1] -> planar depth (Zhou eq. 3-5 for OpenGL):
//  opengl:   z_ndc = 2d - 1, z_e = -P34 / (z_ndc + P33), depth = -z_e
//            = 2 f n / ((f + n) - z_ndc (f - n))
//  d3d:      d = f (z - n) / (z (f - n))      ->  z = f n / (f - d (f - n))
//  reversed: d = 1 at near, 0 at far (D3D)    ->  z = f n / (n + d (f - n))
// With far = inf (infinite far plane): opengl z = 2n / (1 - z_ndc),
// d3d z = n / (1 - d), reversed z = n / d. The cleared value (1, or 0 for
// reversed) is background and becomes unknown.
enum class DepthBufferConvention { opengl, d3d, reversed };
DepthBufferConvention parse_depth_buffer_convention(const std::string& s);
double depth_buffer_to_z(double d, DepthBufferConvention c, double near_m, double far_m);
double z_to_depth_buffer(double z, DepthBufferConvention c, double near_m, double far_m);
// The image conversion evaluates, per pixel in f32, the form the GPU fog
// pass also evaluates (src/depth/depth_math.glsl): 1/z = (1 - d) a + d b,
// without the textbook forms' cancellation (a few ulp from the double
// depth_buffer_to_z above for the same stored d).
Image depth_buffer_to_z(const Image& d, DepthBufferConvention c, double near_m, double far_m);
// That form's constants, validated (near > 0, far > near or inf).
struct DepthBufferLinear {
  double a = 0.0, b = 0.0;  // [1/m] (1/near, 1/far), or (1/far, 1/near) for reversed-z; 1/inf = 0
  float clear = 1.0f;       // the cleared window depth, background = unknown: 1, or 0 for reversed-z
};
DepthBufferLinear depth_buffer_linear(DepthBufferConvention c, double near_m, double far_m);

// ---- monocular estimates ------------------------------------------------------
// Inverse depth (MiDaS-style, affine-invariant): z = 1 / (scale v + shift).
Image inverse_depth_to_z(const Image& v, double scale, double shift);
// Normalised depth v in [0, 1]: z = near + v (far - near).
Image normalized_depth_to_z(const Image& v, double near_m, double far_m);

// ---- lidar ----------------------------------------------------------------------
struct KittiCalib {
  double P2[12];  // 3x4 projection of camera 2 (rectified)
  double R0[9];   // rectifying rotation
  double Tr[12];  // velodyne -> camera 0
  double P3[12];  // 3x4 projection of camera 3 (the right colour camera), when the file has it
  bool has_p3 = false;
};
// Reads and checks a KITTI calibration (the one reader, for every command
// that takes --kitti-calib): each of P2, R0_rect and Tr_velo_to_cam exactly
// once (a repeated key is refused, not the last one kept), every number
// finite, R0_rect and Tr_velo_to_cam's 3x3 part rotations (orthonormal
// within 1e-3, determinant +1), P2's focal lengths > 0; P3, when present
// (the object benchmark's files have it: the stereo baseline), read the same
// way. Errors name --kitti-calib and the file.
KittiCalib read_kitti_calib(const std::string& path);

// ---- LiDAR scans: one reader, one validation, for every command that reads a scan ----
// A Velodyne HDL-64E sweep holds ~120 000 points; 10 M is a hundred sweeps,
// so more is not one scan (and 160 MB before any work).
constexpr std::uint64_t kMaxScanPoints = 10'000'000;
// The farthest point a scan may hold [m]: no LiDAR return is farther (KITTI's
// HDL-64E reaches 120 m, survey scanners ~6 km); a value such as 3e38 is a
// fill value or another unit, and past it a fog's optical depth overflows.
constexpr double kMaxScanRangeM = 10000.0;
// KITTI velodyne .bin: little-endian float32 x, y, z, reflectance per point.
// Throws an Error naming `what` when the size is not a multiple of 16 bytes
// or holds more than kMaxScanPoints points.
std::vector<float> parse_kitti_bin(const std::string& bytes, const std::string& what);
// The file `path` (named in errors as `flag` 'path'): a regular file of
// whole points, at most kMaxScanPoints, refused before it is read when its
// run's memory (bytes_per_point, the caller's working set per point: at least
// the 16 bytes read) exceeds what the process may still use (check_memory).
std::vector<float> read_kitti_bin(const std::string& path, const std::string& flag, double bytes_per_point = 16.0);
// n points' bytes as a KITTI velodyne .bin (the inverse of parse_kitti_bin;
// brume's supported hosts are little-endian, as the format).
std::string kitti_bin_bytes(const float* points, std::size_t n);
// An output scan's path (named in errors as `flag`): it must end in .bin and
// its folder be writable.
void check_kitti_bin_output(const std::string& path, const std::string& flag);
// Every point's x, y, z and intensity finite, the intensity >= 0, the point
// within kMaxScanRangeM of the sensor; else an Error naming `what` and the
// point. Every reader of a scan (file or array) checks it this way.
void validate_scan(const float* xyzi, std::size_t n, const std::string& what);

struct LidarImage {
  Image range;  // metres from camera 2's centre, NaN where no point lands
  Image z;      // planar depth in camera 2
  std::size_t points = 0, points_in_view = 0, pixels_hit = 0;
  double coverage = 0.0;  // pixels_hit / pixels
};
// Project a KITTI Velodyne scan (float32 x, y, z, reflectance per point)
// through P2 R0_rect Tr_velo_to_cam into a width x height sparse image, the
// nearest point winning where several land on one pixel.
LidarImage project_velodyne(const std::string& bin_path, const KittiCalib& calib, int width, int height);

// Linear RGB false colour of log range (near = dark red, far = blue); unknown
// pixels are black. For looking at range maps, not for measuring them.
Image range_preview(const Image& range);

}  // namespace brume
