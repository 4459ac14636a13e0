// brume — a medium whose extinction varies with height: a height profile
// δ(y) [1/m] of the extinction coefficient (the density), and its optical
// depth along a ray (issue #53; docs/architecture.md, "The media layer").
// Layered fog and the LiDAR fog's height-layered model both take it, so a
// camera frame and its scan see the same medium.
//
//   exponential  δ = D0 exp(-B (y - Y0))
//   band         δ = D0 (1 + cos(π (y - Yc) / Wb)) / 2 for |y - Yc| <= Wb, else 0
//   ramp         δ = D0 below y_b, linear to 0 at y_t, 0 above
//   constant     δ = D0
//   table        piecewise linear through (height, density) rows of a CSV,
//                integrated exactly, the end values held outside its heights
//
// A ray from height y_r climbing at d_y (its unit direction's world-up
// component) crosses the optical depth
//
//   F(l) = ∫_0^l δ(y_r + t d_y) dt = l · mean δ over [y_r, y_r + l d_y],
//
// evaluated in heights relative to y_r without forming differences of
// antiderivatives (src/media/height_profile.glsl), stable down to height
// differences of 1e-6 m, equal to l δ(y_r) for a level ray.
//
// Heights are those of brume/camera.hpp's world (y up). The flags keep fog's
// names and block ("fog": --profile, --density, ...) so that records and
// command lines stay as they were.
#pragma once

#include <cstddef>
#include <set>
#include <string>
#include <vector>

#include "brume/camera.hpp"
#include "brume/params.hpp"

namespace brume {

enum class HeightProfile { exponential, band, ramp, constant, table };
const EnumNames<HeightProfile>& height_profile_names();

// The profile and its fields.
struct HeightProfileParams {
  HeightProfile profile = HeightProfile::exponential;
  double density_per_m = 0.02;      // [1/m] D0, >= 0 (exponential: at the base height)
  double falloff_per_m = 0.05;      // [1/m] B, exponential height falloff, >= 0 (0 = constant)
  double base_height_m = 0.0;       // [m]   Y0, exponential: height where δ = D0; finite
  double band_center_m = 0.0;       // [m]   Yc, band centre; finite
  double band_half_width_m = 20.0;  // [m]   Wb, band half-width, > 0
  double ramp_bottom_m = 0.0;       // [m]   y_b: δ = D0 below; finite
  double ramp_top_m = 50.0;         // [m]   y_t: δ = 0 above, > ramp_bottom_m
  std::string table_file;           // CSV rows "height_m,density_per_m" (profile table)
};
// Block "fog": --profile, --density, --falloff, --base-height, --band-center,
// --band-half-width, --ramp-bottom, --ramp-top, --table.
const ParamTable<HeightProfileParams>& height_profile_param_table();
// The combinations a run would silently ignore (a field the profile does not
// use), --ramp-top above --ramp-bottom, --table with --profile table.
// `given`: names set explicitly.
void validate_height_profile(const HeightProfileParams& p, const std::set<std::string>& given = {});

// A profile placed in the world by the pose of a camera (--camera-height,
// --pitch, --roll, ...: the camera effects' pose): what a camera effect's
// job hands a LiDAR scan (CommandDef::height_medium) and what the LiDAR
// fog's height-layered model holds.
struct HeightMedium : HeightProfileParams {
  CameraPose camera;
};
// Block "fog" then block "camera": the profile's flags and the pose's.
const ParamTable<HeightMedium>& height_medium_param_table();
// Its ranges, validate_height_profile, and no pose where the profile does
// not depend on height (constant).
void validate_height_medium(const HeightMedium& m);

// A density table (--profile table): heights strictly increasing, densities
// finite and >= 0. Errors name the file, the line and the fix.
struct DensityTable {
  std::vector<double> height_m, density_per_m;
  std::string path, sha256;
};
DensityTable read_density_table(const std::string& path);
// The record's "inputs" key of a --table file.
constexpr const char* kDensityTableInput = "fog_table";

// The density as per-ray code sees it, relative to a reference height y_r
// (the camera's, the scan's origin): heights u = y - y_r, so that no ray
// forms a difference of large heights.
struct HeightDensity {
  HeightProfile profile = HeightProfile::constant;
  double d0 = 0.0;             // [1/m]
  double falloff = 0.0;        // [1/m] exponential B
  double exponent_c = 0.0;     // exponential: -B (y_r - Y0), δ(y_r) = D0 exp(exponent_c)
  double band_offset = 0.0;    // band: y_r - Yc
  double band_half_width = 1.0;
  std::vector<double> knot_u, knot_density;  // ramp, constant, table: piecewise linear in u = y - y_r
  // δ at height u above the reference (for tests and the record).
  double at(double u) const;
  // The per-ray code's kind (BrumeProfile.kind, src/media/height_profile.glsl):
  // 0 exponential, 1 band, 2 piecewise linear.
  int kind() const;
};
// `table`: the profile table's rows (read_density_table), else unused.
HeightDensity height_density(const HeightProfileParams& p, const DensityTable& table, double reference_height_m);

// Optical depths of n rays at once (float, the per-ray code): out[i] along
// range_m[i] metres of a ray from the reference height climbing at ray_y[i].
// A table of more rows than the code holds (1024) is refused.
void height_optical_depths(const HeightDensity& d, const float* range_m, const float* ray_y, float* out,
                           std::size_t n);
// The largest density at heights u in [u0, u1] above the reference height
// (exactly: the ends, the band's centre, the knots inside).
double height_density_max(const HeightDensity& d, double u0, double u1);

}  // namespace brume
