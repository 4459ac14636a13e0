// brume — `brume haze` as a job from files to files -- its table, map outputs and run: the
// command's half of the family, whose public header (brume/haze.hpp) declares the parameters and
// the functions. Private to the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("haze")->run).
#pragma once

#include "brume/haze.hpp"
#include "brume/lidar_camera.hpp"
#include "brume/pipeline.hpp"

namespace brume {

// From files to files (the CLI's `brume haze` and `brume run`):
struct HazeJob {
  InputFiles input;
  RangeStep prepare;
  HazeParams haze;
  SceneScale scene;    // --scene-scale: the lengths for a reference frame (brume/pipeline.hpp)
  OutputFiles output;  // maps: transmission, scale-map
  CameraLidar lidar;   // --lidar IN.bin --lidar-out OUT.bin (brume/lidar_camera.hpp)
};
const std::vector<MapOutput>& haze_map_outputs();
const ParamTable<HazeJob>& haze_job_table();
// The command line's summary line of a haze record (stderr).
void print_haze_summary(const std::string& out, const nlohmann::json& record);
// Returns the record it wrote (also embedded in the outputs).
nlohmann::json run_haze_job(const HazeJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
