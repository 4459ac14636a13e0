// brume — `brume sky render` and `brume sky fit` as jobs from files to files
// -- their tables and runs: the commands' half of the family, whose public
// header (brume/sky.hpp) declares the parameters and the functions. Private
// to the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("sky render")->run).
#pragma once

#include "brume/pipeline.hpp"
#include "brume/sky.hpp"

namespace brume {

struct SkyRenderJob {
  SkyRenderParams sky;
  OutputFiles output;
};
const ParamTable<SkyRenderJob>& sky_render_job_table();
nlohmann::json run_sky_render_job(const SkyRenderJob& job, const ExecOptions& exec, const RunContext& ctx = {});

struct SkyFitJob {
  std::string image;                      // --image (hdr, exr, png, jpg, tiff)
  std::string image_layer;                // --image-layer: its layer in a file with layers (brume/io.hpp)
  TransferFunction image_transfer = Transfer::automatic;  // --image-transfer
  std::string mask;                       // --mask: > 0.5 (or 128) marks usable sky
  SkyViewParams view;
  SunParams sun;
  SkyFitOptions fit;
  std::string out;                        // --out fit.json
  std::string plot;                       // --plot scatter.png
};
const ParamTable<SkyFitJob>& sky_fit_job_table();
// Runs the fit; writes --out (and --plot, drawn by `plot` when given: the
// library has no plotter) together, atomically. Returns the JSON written.
using SkyPlotter = Image (*)(const nlohmann::json& fit);
nlohmann::json run_sky_fit_job(const SkyFitJob& job, const RunContext& ctx = {}, SkyPlotter plot = nullptr);

}  // namespace brume
