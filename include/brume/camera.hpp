// brume — the camera: intrinsics, image size, projection and pose, with the
// frame conventions every effect shares (layered fog needs the world height
// of each pixel, the sky model its world direction, depth of field its ray).
//
// Frames (fixed here once for all effects):
//
//  * pixel (u, v): column u, row v, 0-based, row 0 at the top, pixel centres
//    at integers (OpenCV, Middlebury, KITTI; see brume/depth.hpp).
//  * camera "cv" frame (OpenCV): x right, y down, z forward. Pixel (u, v) has
//    the ray ((u - cx)/fx, (v - cy)/fy, 1), whose z component is 1 so that a
//    point at planar depth z is z times it, and range = z |ray|.
//  * OpenGL eye frame: x right, y up, the camera looking down -z;
//    eye = diag(1, -1, -1) cv (the same axes, y and z flipped).
//  * world: right-handed, x east, y up, z south (so -z is north, as in
//    OpenGL). The ground plane is y = 0 and heights are y.
//
// Orientation. R = world_from_eye = R_yaw R_pitch R_roll with
//    R_yaw   = rotation about world +y by -yaw   (yaw: compass azimuth of the
//              optical axis, degrees clockwise from north seen from above;
//              a right-handed turn about +y is anticlockwise from above),
//    R_pitch = rotation about eye +x by +pitch (pitch > 0 raises the axis),
//    R_roll  = rotation about eye +z by +roll.
// R = identity is a level camera looking north with image-up = world up and
// image-right = east. The optical axis is R (0, 0, -1)
//    = (sin yaw cos pitch, sin pitch, -cos yaw cos pitch)
// (east, up, south components). Roll > 0 turns the image CONTENT clockwise:
// a right-handed turn about +z (which points backwards) is anticlockwise for
// someone behind the camera looking where it looks, so the camera's right
// edge rises (image-right at roll 90 points world UP) and the world, seen
// in the picture, turns the other way -- clockwise (the sky moves from the
// top of the picture to its right edge). This is the opposite of the
// aviation sign (bank right = right wing down).
//
// Position: the camera centre C in world metres, C = (x, height, z).
// View matrix (OpenGL): x_eye = M x_world for column vectors, M = [R^T | -R^T C;
// 0 0 0 1], translation in the fourth column, the eye looking down -z.
//
// A Camera is a pinhole camera: its rays, projections and poses are the
// pinhole's. Fisheye (looking up, equidistant) and equirectangular images are
// sky images: their pixel <-> direction maps are SkyGeometry's
// (brume/sky.hpp: sky_geometry, direction_of_pixel, pixel_of_direction), which
// uses a Camera only for --projection pinhole. A Camera built with another
// projection is refused (make_camera) and names SkyGeometry.
#pragma once

#include <array>
#include <cmath>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace brume {

// A pinhole camera's intrinsics in pixels (the pixel convention of brume/depth.hpp).
struct Intrinsics {
  double fx = 0.0, fy = 0.0;  // [px] focal lengths, > 0
  double cx = NAN, cy = NAN;  // [px] principal point; NaN = the image centre
};

// From fields of view in degrees (edge to edge); give one or both (square
// pixels assumed for the missing one). Throws brume::Error on bad values.
Intrinsics intrinsics_from_fov(int width, int height, double fov_x_deg, double fov_y_deg);

// Validated copy with the principal point filled in for a width x height image.
Intrinsics resolve(const Intrinsics& k, int width, int height);

struct Vec3 {
  double x = 0.0, y = 0.0, z = 0.0;
};

// Row-major 3x3: m[row][column], acting on column vectors.
struct Mat3 {
  double m[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // identity
  Vec3 operator*(const Vec3& v) const;
  Mat3 operator*(const Mat3& b) const;
  Mat3 transposed() const;
};

// Row-major 4x4: m[row][column], acting on column vectors (x' = M x).
struct Mat4 {
  double m[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
};

// A rotation followed by a translation: x_to = rotation x_from + translation.
struct RigidTransform {
  Mat3 rotation;
  Vec3 translation;
  Vec3 apply(const Vec3& p) const;
  Mat4 matrix() const;
};

// OpenGL eye frame from the cv frame and back (the same map: diag(1, -1, -1)).
inline Vec3 eye_from_cv(const Vec3& c) { return {c.x, -c.y, -c.z}; }
inline Vec3 cv_from_eye(const Vec3& e) { return {e.x, -e.y, -e.z}; }

enum class Projection { pinhole, fisheye, equirectangular };
std::string to_string(Projection p);
// "pinhole" | "fisheye" | "equirectangular"; anything else throws naming --projection.
// (Only pinhole makes a Camera; the other two are the sky projections of SkyGeometry.)
Projection parse_projection(const std::string& s);

// Angles of the convention above, in degrees.
struct YawPitchRoll {
  double yaw_deg = 0.0;    // [0, 360)
  double pitch_deg = 0.0;  // [-90, 90]
  double roll_deg = 0.0;   // (-180, 180]
};
// R = R_yaw R_pitch R_roll (world_from_eye). Any finite angles.
Mat3 rotation_from_ypr(double yaw_deg, double pitch_deg, double roll_deg);
// The inverse of rotation_from_ypr for a proper rotation, angles normalised
// to the ranges above. At pitch +-90 (optical axis vertical) yaw and roll turn
// about the same axis; the whole turn is then reported as yaw, with roll 0.
YawPitchRoll ypr_from_rotation(const Mat3& world_from_eye);

struct Camera {
  Intrinsics k;                              // [px] resolved: fx, fy > 0, cx, cy finite
  int width = 0, height = 0;                 // [px] image size
  Projection projection = Projection::pinhole;
  Mat3 orientation;                          // world_from_eye (R above); identity = level, looking north
  Vec3 position_m{0.0, NAN, 0.0};            // [m] camera centre in world; y = height (NaN: not known)
  std::string view_matrix_file;              // the --view-matrix file the pose was read from ("" if none)

  // ((u - cx)/fx, (v - cy)/fy, 1) in the cv frame (not unit: z = 1).
  Vec3 pixel_ray_cv(double u, double v) const;
  // world_from_cv: rotation R diag(1, -1, -1) and the camera centre.
  RigidTransform world_from_camera() const;
  // Unit direction of pixel (u, v)'s ray in the world.
  Vec3 world_ray(double u, double v) const;
  // The world point at range_m metres along pixel (u, v)'s ray.
  Vec3 world_point(double u, double v, double range_m) const;
  // Its height y above the ground plane [m] (needs a known camera height).
  double height_of(double u, double v, double range_m) const;
  // The pixel (u, v) where a world point projects; nullopt when it is not in
  // front of the camera (z_cv <= 0). Pixels outside the image are returned.
  std::optional<std::array<double, 2>> pixel_of(const Vec3& world) const;

  YawPitchRoll ypr() const { return ypr_from_rotation(orientation); }
  bool height_known() const { return std::isfinite(position_m.y); }
  // Throws, naming `who` and the flags that give a height, when it is unknown.
  void require_height(const std::string& who) const;

  // OpenGL view matrix x_eye = M x_world (needs a known position).
  Mat4 view_matrix() const;
  // A camera posed by a view matrix; M is validated as read_view_matrix does
  // (`what` names it in errors).
  static Camera from_view_matrix(const Mat4& view_from_world, const Intrinsics& k, int width, int height,
                                 const std::string& what = "--view-matrix");
};

// A level camera looking north from an unknown height, from fields of view in
// degrees (edge to edge; one may be NaN: square pixels), or from intrinsics.
Camera camera_from_fov(int width, int height, double fov_x_deg, double fov_y_deg = NAN);
Camera camera_from_intrinsics(const Intrinsics& k, int width, int height);

// Read a 4x4 OpenGL view matrix: four rows of four numbers separated by
// whitespace or commas, `#` starts a comment, blank lines are ignored.
// Validated: finite, last row (0, 0, 0, 1) within 1e-6, upper 3x3 orthonormal
// within 1e-4 with determinant +1 (a rotation: no scale, shear or mirror).
// Errors name the file, the row, the value and what is allowed.
Mat4 read_view_matrix(const std::string& path);
// The same checks on a matrix in memory; `what` names its source in errors.
void validate_view_matrix(const Mat4& m, const std::string& what);

// The pose as the command line gives it (flag names in brackets).
struct CameraPose {
  double yaw_deg = 0.0;      // [deg] --yaw: compass azimuth of the optical axis, clockwise from
                             //       north; any finite value, normalised to [0, 360)
  double pitch_deg = 0.0;    // [deg] --pitch: elevation of the optical axis, > 0 up; [-90, 90]
  double roll_deg = 0.0;     // [deg] --roll: > 0 turns the image content clockwise; (-180, 180]
  double height_m = NAN;     // [m]   --camera-height: y of the camera centre above the ground
                             //       plane; finite (negative = below the datum); NaN = not known
  double x_m = 0.0, z_m = 0.0;  // [m] camera centre east / south of the world origin; finite
  std::string view_matrix_file;  // --view-matrix: pose from a 4x4 view matrix file instead
                                 // (then yaw, pitch, roll, height, x, z must stay at their defaults)
};

// Validate the pose (brume::Error naming --yaw, --pitch, --roll,
// --camera-height, --view-matrix) and build the camera for a width x height
// image. Intrinsics are resolved (NaN cx/cy = the image centre). fisheye and
// equirectangular are refused: they map sky images, through SkyGeometry
// (brume/sky.hpp), not through a Camera.
template <class P>
class ParamTable;  // brume/params.hpp
// The camera's pose as parameters (conventions fixed once for every effect):
// --yaw, --pitch, --roll, --camera-height, --camera-x, --camera-z,
// --view-matrix. For the effects and media that need world heights or
// directions (height profiles, sky); an effect that does not use the pose
// does not bind it.
const ParamTable<CameraPose>& camera_pose_param_table();

Camera make_camera(const Intrinsics& k, int width, int height, const CameraPose& pose = {},
                   Projection projection = Projection::pinhole);

// What a parameter record holds about the camera: intrinsics, size,
// projection, yaw/pitch/roll, position (null when unknown).
nlohmann::json camera_record(const Camera& c);

}  // namespace brume
