// brume — the camera and its pose (see brume/camera.hpp for the frames).
#include "brume/camera.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "core/math_constants.hpp"
#include "core/text.hpp"

namespace brume {

namespace {
// A view matrix's last row must be (0, 0, 0, 1) this closely: it is exact in
// any rigid matrix, so more than rounding means a projection or a typo.
constexpr double kLastRowTol = 1e-6;
// Its upper 3x3 must satisfy |R R^T - I| <= this entrywise: loose enough for
// matrices printed with ~5 significant digits, tight enough to refuse any
// scale or shear that would distort heights (1e-4 of 100 m is 1 cm).
constexpr double kOrthoTol = 1e-4;

std::string pose_num(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec3 add(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Vec3 sub(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3 scale(const Vec3& a, double s) { return {a.x * s, a.y * s, a.z * s}; }

// Right-handed rotations (anticlockwise seen from the tip of the axis).
Mat3 rot_x(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 r;
  r.m[1][1] = c, r.m[1][2] = -s, r.m[2][1] = s, r.m[2][2] = c;
  return r;
}
Mat3 rot_y(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 r;
  r.m[0][0] = c, r.m[0][2] = s, r.m[2][0] = -s, r.m[2][2] = c;
  return r;
}
Mat3 rot_z(double a) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 r;
  r.m[0][0] = c, r.m[0][1] = -s, r.m[1][0] = s, r.m[1][1] = c;
  return r;
}

double det(const Mat3& a) {
  const auto& m = a.m;
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

// The nearest rotation to an almost orthonormal R (the orthogonal polar
// factor), by Newton-Schulz: R <- R (3I - R^T R) / 2 converges quadratically
// while |R^T R - I| < 1, so a 1e-4 input reaches double rounding in 3 steps.
// Rays then stay unit and heights are not scaled by the file's rounding.
Mat3 orthonormalise(Mat3 r) {
  for (int it = 0; it < 6; ++it) {
    const Mat3 g = r.transposed() * r;
    Mat3 h;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) h.m[i][j] = 0.5 * ((i == j ? 3.0 : 0.0) - g.m[i][j]);
    r = r * h;
  }
  return r;
}

double normalise_yaw(double deg) {
  double y = std::fmod(deg, 360.0);
  if (y < 0.0) y += 360.0;
  return y >= 360.0 ? 0.0 : y;  // -1e-17 + 360 rounds to 360
}
double normalise_roll(double deg) {
  double r = std::fmod(deg, 360.0);
  if (r > 180.0) r -= 360.0;
  if (r <= -180.0) r += 360.0;
  return r;
}

std::string row_string(const double* row, int n) {
  std::ostringstream s;
  s.precision(10);
  s << '(';
  for (int c = 0; c < n; ++c) s << (c ? " " : "") << row[c];
  s << ')';
  return s.str();
}

// cv = diag(1, -1, -1) eye: the columns of world_from_cv are R's with the
// second and third negated.
Mat3 cv_rotation(const Mat3& world_from_eye) {
  Mat3 r = world_from_eye;
  for (int i = 0; i < 3; ++i) r.m[i][1] = -r.m[i][1], r.m[i][2] = -r.m[i][2];
  return r;
}
}  // namespace

// ---- small linear algebra ------------------------------------------------------

Vec3 Mat3::operator*(const Vec3& v) const {
  return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
          m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
}
Mat3 Mat3::operator*(const Mat3& b) const {
  Mat3 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = m[i][0] * b.m[0][j] + m[i][1] * b.m[1][j] + m[i][2] * b.m[2][j];
  return r;
}
Mat3 Mat3::transposed() const {
  Mat3 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = m[j][i];
  return r;
}
Vec3 RigidTransform::apply(const Vec3& p) const { return add(rotation * p, translation); }
Mat4 RigidTransform::matrix() const {
  Mat4 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = rotation.m[i][j];
  r.m[0][3] = translation.x, r.m[1][3] = translation.y, r.m[2][3] = translation.z;
  return r;
}

// ---- intrinsics -------------------------------------------------------------------

Intrinsics intrinsics_from_fov(int width, int height, double fov_x_deg, double fov_y_deg) {
  auto check = [](double f, const char* flag) {
    if (!std::isnan(f) && !(f > 0.0 && f < 180.0))
      throw Error(std::string(flag) + " " + text::g(f) + " degrees is not a field of view; use (0, 180)");
  };
  check(fov_x_deg, "--fov-x");
  check(fov_y_deg, "--fov-y");
  if (std::isnan(fov_x_deg) && std::isnan(fov_y_deg)) throw Error("give --fov-x or --fov-y (degrees) or --fx/--fy (pixels)");
  Intrinsics k;
  if (!std::isnan(fov_x_deg)) k.fx = 0.5 * width / std::tan(0.5 * fov_x_deg * kPi / 180.0);
  if (!std::isnan(fov_y_deg)) k.fy = 0.5 * height / std::tan(0.5 * fov_y_deg * kPi / 180.0);
  if (k.fx == 0.0) k.fx = k.fy;
  if (k.fy == 0.0) k.fy = k.fx;
  return k;
}

Intrinsics resolve(const Intrinsics& k, int width, int height) {
  Intrinsics r = k;
  if (r.fy == 0.0) r.fy = r.fx;
  if (r.fx == 0.0) r.fx = r.fy;
  text::require_positive(r.fx, "--fx");
  text::require_positive(r.fy, "--fy");
  if (std::isnan(r.cx)) r.cx = (width - 1) / 2.0;
  if (std::isnan(r.cy)) r.cy = (height - 1) / 2.0;
  if (!std::isfinite(r.cx) || !std::isfinite(r.cy)) throw Error("--cx/--cy must be finite pixel coordinates");
  return r;
}

// ---- projection kinds -----------------------------------------------------------

std::string to_string(Projection p) {
  switch (p) {
    case Projection::pinhole: return "pinhole";
    case Projection::fisheye: return "fisheye";
    case Projection::equirectangular: return "equirectangular";
  }
  return "?";
}

Projection parse_projection(const std::string& s) {
  if (s == "pinhole") return Projection::pinhole;
  if (s == "fisheye") return Projection::fisheye;
  if (s == "equirectangular") return Projection::equirectangular;
  throw Error("--projection '" + s + "' is not a projection; use pinhole, fisheye or equirectangular (the last two "
              "are sky projections: brume sky)");
}

// ---- yaw, pitch, roll ---------------------------------------------------------------

Mat3 rotation_from_ypr(double yaw_deg, double pitch_deg, double roll_deg) {
  // Compass azimuth is clockwise from above, a right-handed turn about +y anticlockwise: hence -yaw.
  return rot_y(-yaw_deg * kDeg) * rot_x(pitch_deg * kDeg) * rot_z(roll_deg * kDeg);
}

YawPitchRoll ypr_from_rotation(const Mat3& r) {
  // Optical axis f = R (0, 0, -1) = (sin yaw cos pitch, sin pitch, -cos yaw cos pitch).
  const Vec3 f{-r.m[0][2], -r.m[1][2], -r.m[2][2]};
  const double horiz = std::hypot(f.x, f.z);
  YawPitchRoll a;
  a.pitch_deg = std::atan2(f.y, horiz) / kDeg;
  double yaw;
  if (horiz > 1e-9) {
    yaw = std::atan2(f.x, -f.z);
  } else {
    // Axis vertical: yaw and roll turn about one axis; with roll 0 the right
    // vector R (1, 0, 0) is (cos yaw, 0, sin yaw).
    yaw = std::atan2(r.m[2][0], r.m[0][0]);
  }
  // Roll from what is left once yaw and pitch are undone: R_roll = R_pitch^T R_yaw^T R.
  // Well conditioned even near the vertical, where a small yaw error turns into roll.
  const Mat3 rr = rot_x(-a.pitch_deg * kDeg) * rot_y(yaw) * r;
  a.roll_deg = horiz > 1e-9 ? normalise_roll(std::atan2(rr.m[1][0], rr.m[0][0]) / kDeg) : 0.0;
  a.yaw_deg = normalise_yaw(yaw / kDeg);
  return a;
}

// ---- the camera -------------------------------------------------------------------------

Vec3 Camera::pixel_ray_cv(double u, double v) const {
  if (projection != Projection::pinhole)
    throw Error("the " + to_string(projection) + " projection is not a Camera's (sky images map through SkyGeometry, brume/sky.hpp); only pinhole cameras have rays");
  return {(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0};
}

RigidTransform Camera::world_from_camera() const { return {cv_rotation(orientation), position_m}; }

Vec3 Camera::world_ray(double u, double v) const {
  const Vec3 c = pixel_ray_cv(u, v);
  return scale(cv_rotation(orientation) * c, 1.0 / std::sqrt(dot(c, c)));
}

Vec3 Camera::world_point(double u, double v, double range_m) const {
  return add(position_m, scale(world_ray(u, v), range_m));
}

double Camera::height_of(double u, double v, double range_m) const { return world_point(u, v, range_m).y; }

std::optional<std::array<double, 2>> Camera::pixel_of(const Vec3& world) const {
  if (projection != Projection::pinhole)
    throw Error("the " + to_string(projection) + " projection is not a Camera's (sky images map through SkyGeometry, brume/sky.hpp); only pinhole cameras project");
  const Vec3 c = cv_rotation(orientation).transposed() * sub(world, position_m);
  if (!(c.z > 0.0)) return std::nullopt;
  return std::array<double, 2>{k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy};
}

void Camera::require_height(const std::string& who) const {
  if (!height_known())
    throw Error(who + " needs the camera's height above the ground: give --camera-height METRES, or the whole pose "
                      "with --view-matrix FILE");
}

Mat4 Camera::view_matrix() const {
  require_height("the view matrix");
  // x_eye = R^T (x_world - C).
  const Mat3 rt = orientation.transposed();
  return RigidTransform{rt, scale(rt * position_m, -1.0)}.matrix();
}

Camera Camera::from_view_matrix(const Mat4& m, const Intrinsics& k, int width, int height, const std::string& what) {
  validate_view_matrix(m, what);
  Camera c = make_camera(k, width, height);
  Mat3 rt;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) rt.m[i][j] = m.m[i][j];
  c.orientation = orthonormalise(rt).transposed();
  // C = -R t.
  c.position_m = scale(c.orientation * Vec3{m.m[0][3], m.m[1][3], m.m[2][3]}, -1.0);
  return c;
}

Camera camera_from_intrinsics(const Intrinsics& k, int width, int height) { return make_camera(k, width, height); }

Camera camera_from_fov(int width, int height, double fov_x_deg, double fov_y_deg) {
  return make_camera(intrinsics_from_fov(width, height, fov_x_deg, fov_y_deg), width, height);
}

// ---- view matrix files -----------------------------------------------------------------------

void validate_view_matrix(const Mat4& m, const std::string& what) {
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(m.m[r][c]))
        throw Error(what + ": row " + std::to_string(r + 1) + ", column " + std::to_string(c + 1) + " is " +
                    pose_num(m.m[r][c]) + "; every entry of a view matrix must be a finite number");
  for (int c = 0; c < 4; ++c)
    if (std::abs(m.m[3][c] - (c == 3 ? 1.0 : 0.0)) > kLastRowTol)
      throw Error(what + ": row 4 is " + row_string(m.m[3], 4) + "; it must be (0 0 0 1) within 1e-6. A view matrix "
                  "is a rotation and a translation (x_eye = M x_world); a projection matrix is not one");
  Mat3 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.m[i][j] = m.m[i][j];
  const Mat3 g = r * r.transposed();  // row i . row j
  int wi = 0, wj = 0;
  double worst = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = i; j < 3; ++j) {
      const double e = std::abs(g.m[i][j] - (i == j ? 1.0 : 0.0));
      if (!(e <= worst)) worst = e, wi = i, wj = j;
    }
  if (worst > kOrthoTol) {
    const std::string why =
        wi == wj ? "row " + std::to_string(wi + 1) + " " + row_string(m.m[wi], 3) + " of the upper 3x3 has length " +
                       pose_num(std::sqrt(g.m[wi][wi]))
                 : "rows " + std::to_string(wi + 1) + " " + row_string(m.m[wi], 3) + " and " + std::to_string(wj + 1) +
                       " " + row_string(m.m[wj], 3) + " of the upper 3x3 have dot product " + pose_num(g.m[wi][wj]);
    throw Error(what + ": " + why + "; the upper 3x3 must be a rotation, orthonormal within 1e-4 (unit rows, "
                "perpendicular): no scale or shear. Remove any model scale from the matrix");
  }
  if (det(r) < 0.0)
    throw Error(what + ": the upper 3x3 has determinant " + pose_num(det(r)) + ", a mirror; a view matrix's rotation "
                "has determinant +1 (right-handed, OpenGL). Check for a flipped axis (left-handed / D3D convention)");
}

Mat4 read_view_matrix(const std::string& path) {
  const std::string what = "--view-matrix '" + path + "'";
  // A regular file of a few lines (brume/io.hpp; 1 MiB: four rows of four numbers and comments).
  std::istringstream in(read_input_file(path, "--view-matrix", {1u << 20, "a view matrix is four rows of four numbers"}));
  Mat4 m;
  int rows = 0, line_no = 0;
  std::string line;
  while (std::getline(in, line)) {
    ++line_no;
    line = line.substr(0, line.find('#'));
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream s(line);
    std::string tok;
    int n = 0;
    double vals[4] = {};
    while (s >> tok) {
      if (rows == 4)
        throw Error(what + ", line " + std::to_string(line_no) + ": a fifth row; the file holds exactly four rows "
                    "of four numbers (x_eye = M x_world)");
      char* end = nullptr;
      errno = 0;
      const double v = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0')
        throw Error(what + ", line " + std::to_string(line_no) + " (row " + std::to_string(rows + 1) + "): '" + tok +
                    "' is not a number; each row holds four numbers separated by spaces or commas");
      if (n == 4)
        throw Error(what + ", line " + std::to_string(line_no) + " (row " + std::to_string(rows + 1) +
                    ") has more than four numbers; each row holds exactly four");
      vals[n++] = v;
    }
    if (n == 0) continue;  // blank or comment
    if (n != 4)
      throw Error(what + ", line " + std::to_string(line_no) + " (row " + std::to_string(rows + 1) + ") has " +
                  std::to_string(n) + " number" + (n == 1 ? "" : "s") + "; each row holds exactly four");
    for (int c = 0; c < 4; ++c) m.m[rows][c] = vals[c];
    ++rows;
  }
  if (rows != 4)
    throw Error(what + " has " + std::to_string(rows) + " row" + (rows == 1 ? "" : "s") +
                "; a view matrix file holds four rows of four numbers (x_eye = M x_world, translation in the fourth "
                "column, last row 0 0 0 1)");
  validate_view_matrix(m, what);
  return m;
}

// ---- the pose from the command line ----------------------------------------------------------

Camera make_camera(const Intrinsics& k, int width, int height, const CameraPose& p, Projection projection) {
  if (width <= 0 || height <= 0)
    throw Error("the camera's image size " + std::to_string(width) + "x" + std::to_string(height) +
                " is not allowed: both must be > 0 pixels");
  if (projection != Projection::pinhole)
    throw Error("--projection " + to_string(projection) + " is a sky projection (brume sky: SkyGeometry in "
                "brume/sky.hpp), not a camera for RGB-D images; use pinhole");
  Camera c;
  c.k = resolve(k, width, height);
  c.width = width, c.height = height;
  c.projection = projection;

  if (!p.view_matrix_file.empty()) {
    std::string clash;
    if (p.yaw_deg != 0.0) clash = "--yaw " + pose_num(p.yaw_deg);
    else if (p.pitch_deg != 0.0) clash = "--pitch " + pose_num(p.pitch_deg);
    else if (p.roll_deg != 0.0) clash = "--roll " + pose_num(p.roll_deg);
    else if (!std::isnan(p.height_m)) clash = "--camera-height " + pose_num(p.height_m);
    else if (p.x_m != 0.0 || p.z_m != 0.0) clash = "a camera x/z position";
    if (!clash.empty())
      throw Error("--view-matrix '" + p.view_matrix_file + "' gives the whole pose, but " + clash +
                  " was given too; use one or the other");
    Camera v = Camera::from_view_matrix(read_view_matrix(p.view_matrix_file), c.k, width, height,
                                        "--view-matrix '" + p.view_matrix_file + "'");
    v.projection = projection;
    v.view_matrix_file = p.view_matrix_file;  // an input: its record hashes it (camera_record)
    return v;
  }

  if (!std::isfinite(p.yaw_deg))
    throw Error("--yaw " + pose_num(p.yaw_deg) + " is not allowed: it must be a finite number of degrees (compass azimuth "
                "of the optical axis, clockwise from north; taken modulo 360)");
  if (!(p.pitch_deg >= -90.0 && p.pitch_deg <= 90.0))
    throw Error("--pitch " + pose_num(p.pitch_deg) + " is not allowed: it must be in [-90, 90] degrees (elevation of the "
                "optical axis, > 0 up); to look back over the top, turn --yaw by 180 and --roll by 180 instead");
  if (!(p.roll_deg > -180.0 && p.roll_deg <= 180.0))
    throw Error("--roll " + pose_num(p.roll_deg) + " is not allowed: it must be in (-180, 180] degrees (> 0 turns the "
                "image content clockwise); -180 is written 180");
  if (std::isinf(p.height_m))
    throw Error("--camera-height " + pose_num(p.height_m) + " is not allowed: it must be a finite number of metres above "
                "the ground plane");
  if (!std::isfinite(p.x_m) || !std::isfinite(p.z_m))
    throw Error("the camera position x " + pose_num(p.x_m) + ", z " + pose_num(p.z_m) + " m is not allowed: both must be finite");
  c.orientation = rotation_from_ypr(p.yaw_deg, p.pitch_deg, p.roll_deg);
  c.position_m = {p.x_m, p.height_m, p.z_m};
  return c;
}

nlohmann::json camera_record(const Camera& c) {
  YawPitchRoll a = c.ypr();
  // -0.0 + 0.0 is +0.0: a level pose's angles come out of atan2 as -0, which
  // a record should not show.
  a.yaw_deg += 0.0, a.pitch_deg += 0.0, a.roll_deg += 0.0;
  auto finite_or_null = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json j = {{"projection", to_string(c.projection)},
          {"width_px", c.width},
          {"height_px", c.height},
          {"fx_px", c.k.fx},
          {"fy_px", c.k.fy},
          {"cx_px", c.k.cx},
          {"cy_px", c.k.cy},
          {"yaw_deg", a.yaw_deg},
          {"pitch_deg", a.pitch_deg},
          {"roll_deg", a.roll_deg},
          {"position_m", {c.position_m.x, finite_or_null(c.position_m.y), c.position_m.z}},
          {"frames", "cv: x right, y down, z forward; world: x east, y up, z south; yaw clockwise from north"}};
  // The pose's file is an input: brume run checks its hash.
  if (!c.view_matrix_file.empty())
    j["view_matrix"] = {{"path", c.view_matrix_file}, {"sha256", sha256_file(c.view_matrix_file)}};
  return j;
}

const ParamTable<CameraPose>& camera_pose_param_table() {
  static const ParamTable<CameraPose> t = [] {
    ParamTable<CameraPose> d("camera");
    d.real("yaw", &CameraPose::yaw_deg, "deg", Range::any(),
           "compass azimuth of the optical axis, clockwise from north seen from above (taken modulo 360)")
        .real("pitch", &CameraPose::pitch_deg, "deg", Range::closed(-90.0, 90.0), "elevation of the optical axis, > 0 looking up")
        .real("roll", &CameraPose::roll_deg, "deg", Range::left_open(-180.0, 180.0),
              "rotation about the optical axis, > 0 turns the image content clockwise")
        .real_or_unset("camera-height", &CameraPose::height_m, "m", Range::any(),
                       "height of the camera centre above the ground plane (world y)", NAN, "unknown")
        .real("camera-x", &CameraPose::x_m, "m", Range::any(), "camera centre east of the world origin")
        .real("camera-z", &CameraPose::z_m, "m", Range::any(), "camera centre south of the world origin")
        .text("view-matrix", &CameraPose::view_matrix_file,
              "the whole pose as a 4x4 OpenGL view matrix file (four rows of four numbers, x_eye = M x_world)")
        .reads_file("", 0, 5);
    return d;
  }();
  return t;
}

}  // namespace brume
