// brume — `brume absorb` (the example effect) as a job from files to files:
// the command's half of the family, private to the library; the public header
// (brume/absorb.hpp) declares the parameters and the in-memory run.
#pragma once

#include "brume/absorb.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct AbsorbJob {
  InputFiles input;    // --image and any depth source
  RangeStep prepare;   // completion and preparation of the range (brume/range_step.hpp)
  AbsorbParams absorb;
  OutputFiles output;  // --out, --record, the maps (transmission)
};
const std::vector<MapOutput>& absorb_map_outputs();
const ParamTable<AbsorbJob>& absorb_job_table();
// Returns the record it wrote (also embedded in the outputs).
nlohmann::json run_absorb_job(const AbsorbJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
