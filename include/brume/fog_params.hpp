// brume — the parameters of layered fog (the maths: brume/fog.hpp), in a
// header of their own: the LiDAR's fog holds them (its height-layered model
// takes fog's profiles), and its public header should not need the whole of
// fog.hpp (which pulls in haze.hpp and the pipeline).
#pragma once

#include <optional>
#include <set>
#include <string>

#include "brume/camera.hpp"
#include "brume/diffusion.hpp"
#include "brume/params.hpp"
#include "brume/sky_rule.hpp"

namespace brume {

enum class FogProfile { exponential, band, ramp, constant, table };
const EnumNames<FogProfile>& fog_profile_names();
enum class ClassicFog { none, linear, exp2 };
const EnumNames<ClassicFog>& classic_fog_names();

struct FogParams {
  FogProfile profile = FogProfile::exponential;
  double density_per_m = 0.02;      // [1/m] D0, >= 0 (exponential: at the base height)
  double falloff_per_m = 0.05;      // [1/m] B, exponential height falloff, >= 0 (0 = constant)
  double base_height_m = 0.0;       // [m]   Y0, exponential: height where delta = D0; finite
  double band_center_m = 0.0;       // [m]   Yc, band centre; finite
  double band_half_width_m = 20.0;  // [m]   Wb, band half-width, > 0
  double ramp_bottom_m = 0.0;       // [m]   y_b: delta = D0 below; finite
  double ramp_top_m = 50.0;         // [m]   y_t: delta = 0 above, > ramp_bottom_m
  std::string table_file;           // CSV rows "height_m,density_per_m" (profile table)
  ClassicFog classic = ClassicFog::none;  // classic OpenGL fog on range instead of a height profile
  double fog_start_m = 0.0;         // [m]   classic linear: f = 1 nearer than this, >= 0
  double fog_end_m = 1000.0;        // [m]   classic linear: f = 0 beyond this, > fog_start_m
  std::optional<double> sky_distance_m;  // [m] > 0; unset: infinity (blur: S_max = s-max-factor R_max)
  SkyRule sky_rule = SkyRule::automatic;  // s-max: the rule of records before schema 3
  std::optional<Rgb> airlight;      // linear RGB fog colour, >= 0; unset: estimated (estimate_airlight)
  double lambda = 0.0;              // [px] blur gain, >= 0 (0: no blur, Zhou's fog)
  double albedo = 1.0;              // [1] single-scattering albedo omega in sigma, [0, 1]
  DiffusionParams diffusion;        // scheme, precision, sigma0, rho_max, edge rate (with lambda > 0)
  CameraPose camera;                // --camera-height, --pitch, --roll, --yaw, --view-matrix, ...
};

// The declaration of FogParams (diffusion and camera-pose blocks nested).
const ParamTable<FogParams>& fog_param_table();

// Range checks, and combinations a run would silently ignore (a density
// parameter the profile does not use, --profile with --classic, blur
// parameters with --lambda 0, a pose where no height is used, ...).
// `given`: names set explicitly.
void validate_fog(const FogParams& p, const std::set<std::string>& given = {});

}  // namespace brume
