// brume — `brume depth convert` and `brume depth prepare` as library calls
// with declared parameters and re-runnable records (brume/pipeline.hpp).
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
  std::string out;    // prepared range, float file
  std::string masks;  // directory for sky.png, holes.png, margin.png, prepared-preview.png
  std::string record;
};
const ParamTable<DepthPrepareJob>& depth_prepare_job_table();
nlohmann::json run_depth_prepare_job(const DepthPrepareJob& job, const RunContext& ctx = {});

}  // namespace brume
