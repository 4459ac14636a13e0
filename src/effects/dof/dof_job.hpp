// brume — `brume dof` as a job from files to files -- its table, map outputs and run: the command's
// half of the family, whose public header (brume/dof.hpp) declares the parameters and the
// functions. Private to the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("dof")->run).
#pragma once

#include "brume/dof.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct DofJob {
  InputFiles input;
  RangeStep prepare;
  DofParams dof;
  SceneScale scene;    // --scene-scale: the lengths for a reference frame (brume/pipeline.hpp)
  OutputFiles output;  // maps: scale-map
};
const std::vector<MapOutput>& dof_map_outputs();
const ParamTable<DofJob>& dof_job_table();
nlohmann::json run_dof_job(const DofJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
