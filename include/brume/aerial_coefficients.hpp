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
#include "brume/pipeline.hpp"

namespace brume {

// --turbidity and --altitude: the atmosphere block, for every aerial command.
const ParamTable<Atmosphere>& atmosphere_param_table();

struct CoefficientsJob {
  Atmosphere atmosphere;
  std::string sensitivity = "default";      // default | FILE.csv | DATABASE.txt#CAMERA NAME
  std::string distances = "100,1000,10000";  // [m] comma-separated, each finite and >= 0
  std::string out;                           // CSV of Gamma per distance (required)
  std::string spectrum;                      // CSV of beta_R, beta_M per wavelength (optional)
};
const ParamTable<CoefficientsJob>& coefficients_job_table();

// --distances text -> metres; throws brume::Error naming --distances and the item.
std::vector<double> parse_distances(const std::string& text);

// The two CSV texts (no files touched): what run_coefficients_job writes.
std::string attenuation_csv(const Atmosphere& a, const SpectralSensitivity& q, const std::vector<double>& distances_m);
std::string spectrum_csv(const Atmosphere& a);

// Checks everything, then writes --out (and --spectrum) together or not at all.
// Returns a summary: {"aerial coefficients": {turbidity, altitude_m,
// sensitivity: {source, sha256, space}, columns, rows}}.
nlohmann::json run_coefficients_job(const CoefficientsJob& job, const RunContext& ctx = {});

}  // namespace brume
