// brume — the parameters of layered fog (the maths: brume/fog.hpp), in a
// header of their own: a height medium (brume/height_profile.hpp: the
// profile, its fields and the camera's pose) and the fog's look.
#pragma once

#include <optional>
#include <set>
#include <string>

#include "brume/camera.hpp"
#include "brume/diffusion.hpp"
#include "brume/height_profile.hpp"
#include "brume/params.hpp"
#include "brume/sky_rule.hpp"

namespace brume {

enum class ClassicFog { none, linear, exp2 };
const EnumNames<ClassicFog>& classic_fog_names();

// The height profile (--profile, --density, ... --table) and the camera's
// pose (--camera-height, --pitch, --roll, --yaw, --view-matrix, ...) are the
// HeightMedium's; the rest is the fog's.
struct FogParams : HeightMedium {
  ClassicFog classic = ClassicFog::none;  // classic OpenGL fog on range instead of a height profile
  double fog_start_m = 0.0;         // [m]   classic linear: f = 1 nearer than this, >= 0
  double fog_end_m = 1000.0;        // [m]   classic linear: f = 0 beyond this, > fog_start_m
  std::optional<double> sky_distance_m;  // [m] > 0; unset: infinity (blur: S_max = s-max-factor R_max)
  SkyRule sky_rule = SkyRule::automatic;  // s-max: the rule of records before schema 3
  std::optional<Rgb> airlight;      // linear RGB fog colour, >= 0; unset: estimated (estimate_airlight)
  double lambda = 0.0;              // [px] blur gain, >= 0 (0: no blur, Zhou's fog)
  double albedo = 1.0;              // [1] single-scattering albedo omega in sigma, [0, 1]
  DiffusionParams diffusion;        // scheme, precision, sigma0, rho_max, edge rate (with lambda > 0)
};

// The declaration of FogParams (diffusion and camera-pose blocks nested).
const ParamTable<FogParams>& fog_param_table();

// Range checks, and combinations a run would silently ignore (a density
// parameter the profile does not use, --profile with --classic, blur
// parameters with --lambda 0, a pose where no height is used, ...).
// `given`: names set explicitly.
void validate_fog(const FogParams& p, const std::set<std::string>& given = {});

}  // namespace brume
