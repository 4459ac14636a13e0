// brume — `brume blur` as a job from files to files -- its table and run: the
// command's half of the family, whose public header (brume/blur.hpp) declares
// the in-memory blur. Private to the library (not installed): a program runs a
// job through the list of commands (brume/command.hpp: find_command("blur")->run).
#pragma once

#include <optional>
#include <string>

#include "brume/blur.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct BlurJob {
  InputFiles input;              // image only
  std::optional<double> sigma;   // [px] constant target scale, >= sigma0; or:
  std::string scale_map;         // per-pixel target scale in px (1-channel float file)
  DiffusionParams diffusion;
  OutputFiles output;
};
const ParamTable<BlurJob>& blur_job_table();
nlohmann::json run_blur_job(const BlurJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
