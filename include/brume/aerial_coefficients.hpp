// brume — `brume aerial coefficients`: the spectral model of aerial
// perspective (brume/aerial.hpp) as tables a user can check and plot:
//   --out       distance_m,gamma_r,gamma_g,gamma_b   Gamma_c(s) at the given distances
//               (gamma_x,gamma_y,gamma_z for the default sensitivity, whose
//               channels are CIE X, Y, Z)
//   --spectrum  wavelength_nm,beta_rayleigh_per_m,beta_mie_per_m   380..780 nm at 1 nm
// Gamma is the spectral integral itself (attenuation_direct), not the table a
// render interpolates.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/aerial.hpp"
#include "brume/params.hpp"

namespace brume {

// --turbidity and --altitude: the atmosphere block, for every aerial command.
const ParamTable<Atmosphere>& atmosphere_param_table();

// --distances text -> metres; throws brume::Error naming --distances and the item.
std::vector<double> parse_distances(const std::string& text);

// The two CSV texts (no files touched): what run_coefficients_job writes.
std::string attenuation_csv(const Atmosphere& a, const SpectralSensitivity& q, const std::vector<double>& distances_m);
std::string spectrum_csv(const Atmosphere& a);

}  // namespace brume
