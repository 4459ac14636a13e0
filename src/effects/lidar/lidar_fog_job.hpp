// brume — `brume lidar fog` as a job from files to files: the command's half of
// the family, private to the library (not installed); the public header
// (brume/lidar_fog.hpp) declares the parameters and the functions. A program
// runs the job through the list of commands (brume/command.hpp:
// find_command("lidar fog")->run).
#pragma once

#include <string>

#include "brume/lidar_fog.hpp"

namespace brume {

struct LidarFogJob {
  std::string points;  // input .bin
  LidarFogParams fog;
  std::string out, record, soft_curve;
};
const ParamTable<LidarFogJob>& lidar_fog_job_table();

}  // namespace brume
