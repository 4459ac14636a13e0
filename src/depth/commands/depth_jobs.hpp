// brume — `brume depth convert`, `brume depth prepare` and `brume depth complete` as jobs from files
// to files with declared parameters and re-runnable records (brume/pipeline.hpp): the commands' half
// of depth, private to the library (not installed); a program runs a job through the list of
// commands (brume/command.hpp: find_command("depth prepare")->run).
#pragma once

#include <string>

#include "brume/depth_source.hpp"
#include "brume/pipeline.hpp"
#include "brume/prepare.hpp"

namespace brume {

struct DepthConvertJob {
  DepthSource depth;
  std::string kind = "range";  // range (metres along the ray) | z (planar depth)
  std::string out;             // float file
  std::string record;
};
const ParamTable<DepthConvertJob>& depth_convert_job_table();
nlohmann::json run_depth_convert_job(const DepthConvertJob& job, const RunContext& ctx = {});

struct DepthPrepareJob {
  DepthSource depth;
  PrepareParams prepare;
  CompleteMode complete = CompleteMode::automatic;  // as an effect's --complete (brume/pipeline.hpp)
  CompleteParams completion;
  std::string image;  // the colour image that guides the completion (and sizes a --velodyne scan)
  std::string image_layer;  // its layer in a file with layers (brume/io.hpp)
  std::string out;    // prepared range, float file
  std::string masks;  // directory for sky.png, holes.png, margin.png, prepared-preview.png
  std::string record;
};
const ParamTable<DepthPrepareJob>& depth_prepare_job_table();
nlohmann::json run_depth_prepare_job(const DepthPrepareJob& job, const RunContext& ctx = {});

// A sparse range map and its colour image -> a dense range map (brume/complete.hpp).
struct DepthCompleteJob {
  InputFiles input;         // --image and the depth source
  CompleteParams complete;
  std::string out;          // completed range, float file (NaN at the sky)
  std::string confidence;   // per-pixel confidence in [0, 1] (optional)
  std::string record;
};
const ParamTable<DepthCompleteJob>& depth_complete_job_table();
nlohmann::json run_depth_complete_job(const DepthCompleteJob& job, const ExecOptions& eo = {}, const RunContext& ctx = {});

}  // namespace brume
