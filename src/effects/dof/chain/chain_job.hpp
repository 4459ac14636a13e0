// brume — `brume haze` with --dof-... flags (haze+dof) as a job from files to files -- its table,
// map outputs and run: the command's half of the family, whose public header (brume/chain.hpp)
// declares the parameters and the functions. Private to the library (not installed): a program runs
// a job through the list of commands (brume/command.hpp: find_command("haze+dof")->run).
#pragma once

#include "brume/chain.hpp"
#include "brume/lidar_camera.hpp"
#include "brume/pipeline.hpp"
#include "effects/dof/dof_job.hpp"
#include "effects/haze/haze_job.hpp"

namespace brume {

struct HazeDofJob {
  InputFiles input;
  RangeStep prepare;
  HazeParams haze;
  DofParams dof;       // flags --dof-..., record block "dof"
  SceneScale scene;    // --scene-scale: both stages' lengths for a reference frame (brume/pipeline.hpp)
  OutputFiles output;  // maps: transmission, scale-map (haze's sigma), dof-scale-map (the DOF's sigma)
  CameraLidar lidar;   // --lidar IN.bin --lidar-out OUT.bin (brume/lidar_camera.hpp): haze's medium
};
const std::vector<MapOutput>& haze_dof_map_outputs();
const ParamTable<HazeDofJob>& haze_dof_job_table();

// Whether names set explicitly ask for the DOF stage: any "dof-" parameter
// (`brume haze` runs the chain when one is given, plain haze otherwise).
bool dof_stage_requested(const std::set<std::string>& given);
// The chain's haze part as a plain haze job (`brume haze` without --dof-...).
// Throws when the job carries a DOF setting, which plain haze would ignore.
HazeJob haze_part(const HazeDofJob& job, const std::set<std::string>& given = {});

// From files to files; the record's command is "haze+dof" (`brume run` repeats it).
nlohmann::json run_haze_dof_job(const HazeDofJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
