// brume — `brume insert` as a job from files to files -- its table, map outputs and run: the
// command's half of the family, whose public header (brume/insert.hpp) declares the parameters and
// the functions. Private to the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("insert")->run).
#pragma once

#include "brume/insert.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct InsertJob {
  InputFiles input;     // the photo and its depth (any depth source)
  InsertObject object;  // the object and its range
  RangeStep prepare;
  AerialParams aerial;  // insert_aerial_param_table()'s subset
  OutputFiles output;   // maps: coverage, scale-map
};
const std::vector<MapOutput>& insert_map_outputs();
const ParamTable<InsertJob>& insert_job_table();
nlohmann::json run_insert_job(const InsertJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
