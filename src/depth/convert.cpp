// brume — depth conversions (see brume/depth.hpp for the conventions).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/math_constants.hpp"
#include "core/text.hpp"
#include "shared/prelude_cpp.h"

namespace brume {

namespace {
const float kUnknown = std::numeric_limits<float>::quiet_NaN();

std::string depth_num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
}  // namespace

namespace {
// A calibration is a few lines of numbers (KITTI's 1.6 kB, calib.txt's 158
// bytes); a file of more than 1 MiB is not one.
const InputLimit kCalibLimit{1u << 20, "a calibration is a few lines of numbers"};

// |M^T M - I| <= 1e-3 element-wise and det M > 0: a rotation, as KITTI's
// R0_rect and Tr_velo_to_cam are (to ~1e-7).
bool calib_is_rotation(const double m[3][3]) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double g = 0.0;
      for (int k = 0; k < 3; ++k) g += m[k][i] * m[k][j];
      if (!(std::abs(g - (i == j ? 1.0 : 0.0)) <= 1e-3)) return false;
    }
  const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
                     m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  return det > 0.0;
}
}  // namespace

const EnumNames<SensorFit>& sensor_fit_names() {
  static const EnumNames<SensorFit> n = {
      {SensorFit::automatic, "auto"}, {SensorFit::horizontal, "horizontal"}, {SensorFit::vertical, "vertical"}};
  return n;
}

LensScale lens_scale(const LensCamera& c, int width, int height) {
  const bool vertical = c.sensor_fit == SensorFit::vertical ||
                        (c.sensor_fit == SensorFit::automatic && height > width);
  LensScale l;
  l.side_px = vertical ? height : width;
  if (c.sensor_fit == SensorFit::vertical) {
    if (c.sensor_width_mm)
      throw Error("--sensor-width " + depth_num(*c.sensor_width_mm) + " mm is not used with --sensor-fit vertical, "
                  "where the sensor height spans the image height (Blender's meaning); drop --sensor-width, or use "
                  "--sensor-fit auto or horizontal");
    if (!c.sensor_height_mm)
      throw Error("--sensor-fit vertical needs --sensor-height MM (the sensor's height, which spans the image height)");
    l.sensor_mm = *c.sensor_height_mm;
    l.sensor_flag = "--sensor-height";
  } else {
    if (c.sensor_height_mm)
      throw Error("--sensor-height " + depth_num(*c.sensor_height_mm) + " mm is used only with --sensor-fit vertical; "
                  "with --sensor-fit " + enum_name(sensor_fit_names(), c.sensor_fit) + " the sensor width alone spans " +
                  (c.sensor_fit == SensorFit::automatic ? "the image's larger side" : "the image width") +
                  " (Blender's meaning): drop --sensor-height");
    if (!c.sensor_width_mm)
      throw Error("the camera in millimetres needs the sensor: --sensor-width MM (Blender: Camera > Sensor > Size; "
                  "36 for its default full-frame sensor)");
    l.sensor_mm = *c.sensor_width_mm;
  }
  return l;
}

Intrinsics lens_intrinsics(const LensCamera& c, int width, int height) {
  if (!c.focal_length_mm)
    throw Error("the camera in millimetres needs --focal-length MM (with --sensor-width MM" +
                std::string(c.lens_shift[0] != 0.0 || c.lens_shift[1] != 0.0 ? "; --lens-shift places the principal "
                                                                                 "point of that camera" : "") + ")");
  const LensScale l = lens_scale(c, width, height);
  Intrinsics k;
  k.fx = k.fy = *c.focal_length_mm * l.side_px / l.sensor_mm;
  if (c.lens_shift[0] != 0.0 || c.lens_shift[1] != 0.0) {
    k.cx = (width - 1) / 2.0 - c.lens_shift[0] * l.side_px;
    k.cy = (height - 1) / 2.0 + c.lens_shift[1] * l.side_px;
  }
  return resolve(k, width, height);
}

namespace {
Image scale_by_ray(const Image& in, const Intrinsics& k0, bool to_range) {
  if (in.channels != 1) throw Error("depth maps must have one channel");
  const Intrinsics k = resolve(k0, in.width, in.height);
  Image out(in.width, in.height, 1);
  // The ray's length factor sqrt(1 + a^2 + b^2), a = (u - cx)/fx and
  // b = (v - cy)/fy, with 1 + a^2 formed once per column and b^2 once per
  // row: the same double operations in the same order per pixel as
  // evaluating it whole, so the same bits, without two divides per pixel
  // (463 x 370, z to range and back: 1.59 -> 1.12 ms, AMD EPYC Zen 4; the
  // square root stays scalar: with errno it does not vectorise).
  const std::size_t W = static_cast<std::size_t>(in.width);
  std::vector<double> col(W);
  for (std::size_t u = 0; u < W; ++u) {
    const double a = (static_cast<double>(u) - k.cx) / k.fx;
    col[u] = 1.0 + a * a;
  }
  for (int v = 0; v < in.height; ++v) {
    const double b = (v - k.cy) / k.fy, bb = b * b;
    const float* src = in.data.data() + v * W;
    float* dst = out.data.data() + v * W;
    for (std::size_t u = 0; u < W; ++u) {
      const double ray = std::sqrt(col[u] + bb), x = src[u];
      dst[u] = static_cast<float>(to_range ? x * ray : x / ray);
    }
  }
  return out;
}
}  // namespace

Image z_to_range(const Image& z, const Intrinsics& k) { return scale_by_ray(z, k, true); }
Image range_to_z(const Image& range, const Intrinsics& k) { return scale_by_ray(range, k, false); }

namespace {
// KITTI depth completion's intrinsics/*.txt: 9 numbers, no key. Returns
// false when the text has any '=' (a calib.txt); throws for a keyless file
// that is not a camera matrix.
bool camera_matrix(const std::string& path, const std::string& text, std::array<double, 9>& K) {
  if (text.find('=') != std::string::npos) return false;
  std::istringstream in(text);
  std::vector<double> v;
  std::string tok;
  while (in >> tok) {
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || !std::isfinite(x))
      throw Error("--calib '" + path + "': '" + tok +
                  "' is not a number; --calib takes a Middlebury 2014 / ETH3D "
                  "calib.txt (cam0=, baseline= lines) or KITTI depth completion's intrinsics/*.txt (9 numbers: "
                  "fx 0 cx 0 fy cy 0 0 1)");
    if (v.size() == 9)
      throw Error("--calib '" + path +
                  "' holds more than 9 numbers and no '=' line; KITTI depth completion's "
                  "intrinsics/*.txt holds exactly the 3x3 matrix K (fx 0 cx 0 fy cy 0 0 1), a calib.txt has "
                  "cam0= and baseline= lines");
    v.push_back(x);
  }
  if (v.size() != 9)
    throw Error("--calib '" + path + "' holds " + std::to_string(v.size()) +
                " numbers and no '=' line; KITTI depth "
                "completion's intrinsics/*.txt holds the 3x3 matrix K as 9 numbers (fx 0 cx 0 fy cy 0 0 1), a "
                "calib.txt has cam0= and baseline= lines");
  std::copy(v.begin(), v.end(), K.begin());
  if (K[1] != 0.0 || K[3] != 0.0 || K[6] != 0.0 || K[7] != 0.0 || K[8] != 1.0)
    throw Error("--calib '" + path +
                "': the 9 numbers are not a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (row by "
                "row: entries 2, 4, 7 and 8 must be 0 and the last 1); give KITTI depth completion's "
                "intrinsics/*.txt as it is, or a calib.txt");
  text::require_positive(K[0], "--calib '" + path + "': focal length fx (K's first number)");
  text::require_positive(K[4], "--calib '" + path + "': focal length fy (K's fifth number)");
  return true;
}
}  // namespace

Intrinsics read_calib_camera(const std::string& path) {
  const std::string text = read_input_file(path, "--calib", kCalibLimit);
  std::array<double, 9> K{};
  Intrinsics k;
  if (camera_matrix(path, text, K)) {
    k.fx = K[0], k.fy = K[4], k.cx = K[2], k.cy = K[5];
    return k;
  }
  const StereoCalib c = read_stereo_calib(path);
  k.fx = k.fy = c.f_px;
  k.cx = c.cx, k.cy = c.cy;
  return k;
}

StereoCalib read_stereo_calib(const std::string& path) {
  const std::string text = read_input_file(path, "--calib", kCalibLimit);
  {
    std::array<double, 9> K{};
    if (camera_matrix(path, text, K))
      throw Error("--calib '" + path +
                  "' is a 3x3 camera matrix (KITTI depth completion's intrinsics/*.txt): it "
                  "gives the camera but no stereo baseline, which a disparity needs; give the pair's calib.txt "
                  "(Middlebury 2014 / ETH3D), or --fx and --baseline");
  }
  std::istringstream in(text);
  std::map<std::string, std::string> kv;
  std::map<std::string, int> at;  // the line of each key (from 1): a key given twice is refused
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    std::string key = line.substr(0, eq);
    key.erase(std::remove_if(key.begin(), key.end(), ::isspace), key.end());
    if (!at.emplace(key, lineno).second)
      throw Error("--calib '" + path + "': '" + key + "=' on line " + std::to_string(lineno) + " repeats line " +
                  std::to_string(at[key]) + "; a calib.txt gives each key once: remove one of them");
    kv[key] = line.substr(eq + 1);
  }
  for (const char* need : {"cam0", "baseline"})
    if (!kv.count(need))
      throw Error("--calib '" + path + "' has no '" + need +
                  "=' line; a Middlebury 2014 / ETH3D calib.txt has cam0=[f 0 cx; 0 f cy; 0 0 1], doffs=, baseline= (mm)");
  StereoCalib c;
  std::string m = kv["cam0"];
  std::replace_if(m.begin(), m.end(), [](char ch) { return ch == '[' || ch == ']' || ch == ';'; }, ' ');
  std::istringstream ms(m);
  std::array<double, 9> K{};
  for (double& v : K)
    if (!(ms >> v)) throw Error("--calib '" + path + "': cam0 must hold 9 numbers [f 0 cx; 0 f cy; 0 0 1]");
  c.f_px = K[0];
  c.cx = K[2];
  c.cy = K[5];
  // Both focal lengths (the conversion uses f = K[0]; a fy <= 0 says the
  // matrix is not [f 0 cx; 0 f cy; 0 0 1]).
  text::require_positive(K[4], "--calib '" + path + "': focal length fy in cam0");
  auto number = [&](const std::string& key, double def) {
    if (!kv.count(key)) return def;
    try {
      return std::stod(kv[key]);
    } catch (const std::exception&) {
      throw Error("--calib '" + path + "': '" + key + "=" + kv[key] + "' is not a number");
    }
  };
  c.baseline_m = number("baseline", 0.0) / 1000.0;
  c.doffs_px = number("doffs", 0.0);
  // Sizes are whole pixel counts; anything else (1e12, 3.5, nan) is refused
  // before the conversion to int, which would be undefined out of range
  // (UBSan; fuzz/corpus/stereo_calib/crlf_bigwidth.txt holds such a file).
  auto size = [&](const std::string& key) {
    const double v = number(key, 0);
    if (!(v >= 0.0 && v <= 1e9) || v != std::floor(v))
      throw Error("--calib '" + path + "': '" + key + "=" + kv[key] +
                  "' is not a pixel count; it must be a whole number from 0 to 1e9");
    return static_cast<int>(v);
  };
  c.width = size("width");
  c.height = size("height");
  text::require_positive(c.f_px, "--calib '" + path + "': focal length f in cam0");
  text::require_positive(c.baseline_m, "--calib '" + path + "': baseline");
  return c;
}

Image disparity_to_z(const Image& d, double f_px, double baseline_m, double doffs_px) {
  text::require_positive(f_px, "focal length (--fx) in pixels");
  text::require_positive(baseline_m, "--baseline in metres");
  if (!std::isfinite(doffs_px)) throw Error("--disparity-offset must be finite");
  Image z(d.width, d.height, 1);
  for (std::size_t i = 0; i < d.data.size(); ++i) {
    const double s = static_cast<double>(d.data[i]) + doffs_px;
    z.data[i] = std::isfinite(s) && s > 0.0 ? static_cast<float>(f_px * baseline_m / s) : kUnknown;
  }
  return z;
}

DepthBufferConvention parse_depth_buffer_convention(const std::string& s) {
  if (s == "opengl") return DepthBufferConvention::opengl;
  if (s == "d3d") return DepthBufferConvention::d3d;
  if (s == "reversed-z") return DepthBufferConvention::reversed;
  throw Error("--convention '" + s + "' is not a depth-buffer convention; use opengl, d3d or reversed-z");
}

double depth_buffer_to_z(double d, DepthBufferConvention c, double n, double f) {
  const bool inf = std::isinf(f);
  switch (c) {
    case DepthBufferConvention::opengl: {
      const double zn = 2.0 * d - 1.0;  // Zhou eq. 3
      if (inf) return 2.0 * n / (1.0 - zn);
      const double P33 = (f + n) / (n - f), P34 = -2.0 * f * n / (f - n);  // eq. 4
      return P34 / (zn + P33);  // depth = -z_e, z_e = -P34 / (z_ndc + P33) (eq. 5)
    }
    case DepthBufferConvention::d3d:
      return inf ? n / (1.0 - d) : f * n / (f - d * (f - n));
    case DepthBufferConvention::reversed:
      return inf ? n / d : f * n / (n + d * (f - n));
  }
  return NAN;
}

double z_to_depth_buffer(double z, DepthBufferConvention c, double n, double f) {
  const bool inf = std::isinf(f);
  switch (c) {
    case DepthBufferConvention::opengl: {
      const double zn = inf ? 1.0 - 2.0 * n / z : ((f + n) - 2.0 * f * n / z) / (f - n);
      return 0.5 * (zn + 1.0);
    }
    case DepthBufferConvention::d3d:
      return inf ? 1.0 - n / z : f * (z - n) / (z * (f - n));
    case DepthBufferConvention::reversed:
      return inf ? n / z : n * (f - z) / (z * (f - n));
  }
  return NAN;
}

DepthBufferLinear depth_buffer_linear(DepthBufferConvention c, double n, double f) {
  text::require_positive(n, "--near (metres)");
  if (!(f > n)) throw Error("--far " + depth_num(f) + " must be greater than --near " + depth_num(n) + " (use inf for an infinite far plane)");
  const double inv_n = 1.0 / n, inv_f = std::isinf(f) ? 0.0 : 1.0 / f;
  DepthBufferLinear l;
  const bool reversed = c == DepthBufferConvention::reversed;
  l.a = reversed ? inv_f : inv_n;
  l.b = reversed ? inv_n : inv_f;
  l.clear = reversed ? 0.0f : 1.0f;
  return l;
}

Image depth_buffer_to_z(const Image& d, DepthBufferConvention c, double n, double f) {
  const DepthBufferLinear lin = depth_buffer_linear(c, n, f);
  const float a = static_cast<float>(lin.a), b = static_cast<float>(lin.b);
  Image z(d.width, d.height, 1);
  for (std::size_t i = 0; i < d.data.size(); ++i) {
    const float v = d.data[i];
    if (!std::isfinite(v) || v == lin.clear) {
      z.data[i] = kUnknown;
      continue;
    }
    if (v < 0.0f || v > 1.0f) {
      throw Error("depth-buffer pixel (" + std::to_string(i % d.width) + ", " + std::to_string(i / d.width) +
                  ") is " + depth_num(v) + "; window depth must be in [0, 1] (for a 16/24-bit integer buffer give --scale 1/65535 or 1/16777215)");
    }
    z.data[i] = 1.0f / brume::shared::brume_depth_inverse_z(v, a, b);
  }
  return z;
}

Image inverse_depth_to_z(const Image& v, double scale, double shift) {
  if (!std::isfinite(scale) || scale == 0.0 || !std::isfinite(shift))
    throw Error("--inverse-scale and --inverse-shift must be finite and the scale non-zero (z = 1 / (scale v + shift))");
  Image z(v.width, v.height, 1);
  for (std::size_t i = 0; i < v.data.size(); ++i) {
    const double w = scale * v.data[i] + shift;
    z.data[i] = std::isfinite(w) && w > 0.0 ? static_cast<float>(1.0 / w) : kUnknown;
  }
  return z;
}

Image normalized_depth_to_z(const Image& v, double n, double f) {
  if (!(n >= 0.0) || !(f > n) || !std::isfinite(f))
    throw Error("--near " + depth_num(n) + " and --far " + depth_num(f) + ": need 0 <= near < far, finite (z = near + v (far - near))");
  Image z(v.width, v.height, 1);
  for (std::size_t i = 0; i < v.data.size(); ++i) {
    const float x = v.data[i];
    z.data[i] = std::isfinite(x) ? static_cast<float>(n + x * (f - n)) : kUnknown;
  }
  return z;
}

KittiCalib read_kitti_calib(const std::string& path) {
  const std::string what = "--kitti-calib '" + path + "'";
  std::istringstream in(read_input_file(path, "--kitti-calib", kCalibLimit));
  KittiCalib c{};
  // Where each matrix was given (line numbers from 1): a key given twice is
  // refused rather than the last one kept silently.
  std::map<std::string, int> seen;
  int got_p2 = 0, got_r0 = 0, got_tr = 0, got_p3 = 0, odometry_tr = 0;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    std::istringstream s(line);
    std::string key;
    s >> key;
    if (key.empty()) continue;
    // R_rect: and Tr_velo_cam: are the raw recordings' names of the same matrices; Tr: is the
    // odometry benchmark's (its calib.txt: P0-P3 and Tr, velodyne -> rectified camera 0).
    if (key == "Tr:") odometry_tr = lineno;
    const std::string canon = key == "R_rect:"                        ? "R0_rect:"
                              : key == "Tr_velo_cam:" || key == "Tr:" ? "Tr_velo_to_cam:"
                                                                      : key;
    if (!seen.emplace(canon, lineno).second)
      throw Error(what + ": '" + key + "' on line " + std::to_string(lineno) + " repeats " +
                  (canon == key ? "the key" : "'" + canon + "'") + " of line " + std::to_string(seen[canon]) +
                  "; a KITTI calibration gives each matrix once: remove one of them");
    auto read = [&](double* dst, int n, int& flag) {
      for (int i = 0; i < n; ++i)
        if (!(s >> dst[i]) || !std::isfinite(dst[i]))
          throw Error(what + ": '" + key + "' (line " + std::to_string(lineno) + ") needs " + std::to_string(n) +
                      " finite numbers");
      flag = lineno;
    };
    if (canon == "P2:") read(c.P2, 12, got_p2);
    else if (canon == "R0_rect:") read(c.R0, 9, got_r0);
    else if (canon == "Tr_velo_to_cam:") read(c.Tr, 12, got_tr);
    else if (canon == "P3:") read(c.P3, 12, got_p3);
  }
  c.has_p3 = got_p3 > 0;
  // The odometry benchmark's Tr maps into camera 0's rectified frame already: its R0_rect is I
  // (its readme: "Tr transforms a point from velodyne coordinates into the left rectified camera
  // coordinate system"). An R0_rect beside it is read as given.
  if (odometry_tr && !got_r0) {
    for (int i = 0; i < 9; ++i) c.R0[i] = i % 4 == 0 ? 1.0 : 0.0;
    got_r0 = odometry_tr;
  }
  if (!got_p2 || !got_r0 || !got_tr)
    throw Error(what + " lacks " + std::string(!got_p2 ? "P2: " : "") + (!got_r0 ? "R0_rect: " : "") +
                (!got_tr ? "Tr_velo_to_cam: " : "") +
                "(a KITTI object or raw calib file has all three; an odometry calib.txt has P0-P3 and Tr:)");
  double r0[3][3], tr[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r0[i][j] = c.R0[3 * i + j], tr[i][j] = c.Tr[4 * i + j];
  if (!calib_is_rotation(r0))
    throw Error(what + ": R0_rect (line " + std::to_string(got_r0) + ") is not a rotation (orthonormal within 1e-3, "
                "determinant +1); the file is not a KITTI calibration, or it is damaged");
  if (!calib_is_rotation(tr))
    throw Error(what + ": the 3x3 part of Tr_velo_to_cam (line " + std::to_string(got_tr) + ") is not a rotation "
                "(orthonormal within 1e-3, determinant +1); the file is not a KITTI calibration, or it is damaged");
  if (!(c.P2[0] > 0.0 && c.P2[5] > 0.0))
    throw Error(what + ": P2's focal lengths (fx " + depth_num(c.P2[0]) + ", fy " + depth_num(c.P2[5]) + " px, line " +
                std::to_string(got_p2) + ") must be > 0; the file is not a KITTI calibration, or it is damaged");
  return c;
}

LidarImage project_velodyne(const std::string& bin_path, const KittiCalib& c, int width, int height) {
  if (width <= 0 || height <= 0) throw Error("the lidar image size is not set; give --width/--height or --like IMAGE");
  // The one reader and validation of a scan (src/depth/scan.cpp): a regular
  // file of whole points, at most 10 M, every value finite.
  const std::vector<float> buf = read_kitti_bin(bin_path, "--velodyne");
  if (buf.empty())
    throw Error("--velodyne '" + bin_path + "' holds no points; a KITTI scan is float32 (x, y, z, reflectance) per "
                "point, 16 bytes each");
  validate_scan(buf.data(), buf.size() / 4, "--velodyne '" + bin_path + "'");
  // Camera 2's centre in rectified camera-0 coordinates: P2 = K [I | t], C = -t.
  const double* P = c.P2;
  const double fx = P[0], s = P[1], cx = P[2], fy = P[5], cy = P[6];
  const double tz = P[11];
  const double ty = (P[7] - cy * tz) / fy;
  const double tx = (P[3] - s * ty - cx * tz) / fx;
  // P2 fixes the image size the scan projects to only through the principal
  // point, near the centre of a KITTI image (609.6, 172.9 of 1242 x 375): one
  // outside the image's central half means an image of another size (a
  // resized or another camera's frame), on which every point would land in
  // the wrong place.
  if (cx < 0.25 * width || cx > 0.75 * width || cy < 0.25 * height || cy > 0.75 * height) {
    char pp[96];
    std::snprintf(pp, sizeof pp, "(%.1f, %.1f)", cx, cy);
    throw Error("--kitti-calib's principal point " + std::string(pp) + " px (P2) is not near the centre of the " +
                std::to_string(width) + "x" + std::to_string(height) +
                " image the scan is projected to: the image and the calibration do not belong together (KITTI's "
                "image_2 frames are about 1242x375; do not resize the image, or scale P2 with it)");
  }
  LidarImage out;
  out.range = Image(width, height, 1, kUnknown);
  out.z = Image(width, height, 1, kUnknown);
  out.points = buf.size() / 4;
  for (std::size_t i = 0; i < out.points; ++i) {
    const double X[3] = {buf[i * 4], buf[i * 4 + 1], buf[i * 4 + 2]};
    double cam[3], rect[3];
    for (int r = 0; r < 3; ++r) cam[r] = c.Tr[r * 4] * X[0] + c.Tr[r * 4 + 1] * X[1] + c.Tr[r * 4 + 2] * X[2] + c.Tr[r * 4 + 3];
    for (int r = 0; r < 3; ++r) rect[r] = c.R0[r * 3] * cam[0] + c.R0[r * 3 + 1] * cam[1] + c.R0[r * 3 + 2] * cam[2];
    const double pz = P[8] * rect[0] + P[9] * rect[1] + P[10] * rect[2] + P[11];
    if (!(pz > 0.0)) continue;  // behind camera 2
    const double u = (P[0] * rect[0] + P[1] * rect[1] + P[2] * rect[2] + P[3]) / pz;
    const double v = (P[4] * rect[0] + P[5] * rect[1] + P[6] * rect[2] + P[7]) / pz;
    const long iu = std::lround(u), iv = std::lround(v);  // pixel centres at integers
    if (iu < 0 || iv < 0 || iu >= width || iv >= height) continue;
    ++out.points_in_view;
    const double dx = rect[0] + tx, dy = rect[1] + ty, dz = rect[2] + tz;
    const float range = static_cast<float>(std::sqrt(dx * dx + dy * dy + dz * dz));
    float& cur = out.range.at(static_cast<int>(iu), static_cast<int>(iv));
    if (std::isnan(cur) || range < cur) {
      cur = range;
      out.z.at(static_cast<int>(iu), static_cast<int>(iv)) = static_cast<float>(dz);
    }
  }
  for (float r : out.range.data) out.pixels_hit += std::isfinite(r) ? 1 : 0;
  out.coverage = static_cast<double>(out.pixels_hit) / out.range.pixels();
  return out;
}

}  // namespace brume
