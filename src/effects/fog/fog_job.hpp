// brume — `brume fog` as a job from files to files -- its table, map outputs and run: the command's
// half of the family, whose public header (brume/fog.hpp) declares the parameters and the
// functions. Private to the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("fog")->run).
#pragma once

#include "brume/fog.hpp"
#include "brume/lidar_camera.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct FogJob {
  InputFiles input;
  RangeStep prepare;
  FogParams fog;
  SceneScale scene;    // --scene-scale: the lengths for a reference frame (brume/pipeline.hpp)
  OutputFiles output;  // maps: optical-depth, transmission
  CameraLidar lidar;   // --lidar IN.bin --lidar-out OUT.bin (brume/lidar_camera.hpp)
};
const std::vector<MapOutput>& fog_map_outputs();
const ParamTable<FogJob>& fog_job_table();
nlohmann::json run_fog_job(const FogJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
