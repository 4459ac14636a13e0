// brume — `brume aerial coefficients` as a job from files to files -- its
// table and run: the command's half of the part, whose public header
// (brume/aerial_coefficients.hpp) declares the tables' functions. Private to
// the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("aerial coefficients")->run).
#pragma once

#include <string>

#include "brume/aerial_coefficients.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct CoefficientsJob {
  Atmosphere atmosphere;
  std::string sensitivity = "default";      // default | FILE.csv | DATABASE.txt#CAMERA NAME
  std::string distances = "100,1000,10000";  // [m] comma-separated, each finite and >= 0
  std::string out;                           // CSV of Gamma per distance (required)
  std::string spectrum;                      // CSV of beta_R, beta_M per wavelength (optional)
};
const ParamTable<CoefficientsJob>& coefficients_job_table();

// Checks everything, then writes --out (and --spectrum) together or not at all.
// Returns a summary: {"aerial coefficients": {turbidity, altitude_m,
// sensitivity: {source, sha256, space}, columns, rows}}.
nlohmann::json run_coefficients_job(const CoefficientsJob& job, const RunContext& ctx = {});

}  // namespace brume
