// brume — the file form every scan effect shares (brume lidar rain, brume
// lidar wet): the output paths checked before any work, the KITTI scan read,
// the effect run on its points, then the points that return (input order),
// one label byte per input point and the record written together (OutputSet:
// nothing partial on an error).
#pragma once

#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

#include "brume/pipeline.hpp"  // RunContext, job_record

namespace brume {

struct ScanFiles {
  std::string points, out, labels, record;  // --points, --out, --labels, --record
};
// `run(in, out, n, labels, what)` fills out's first 4 (n - lost) floats and
// the n labels, puts the effect's record block(s) into `blocks` and returns
// the number of points lost. `command` names the record ("lidar rain").
nlohmann::json run_scan_file_job(
    const std::string& command, const RunContext& ctx, const nlohmann::json& job, const ScanFiles& files,
    const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*, const std::string&,
                                    nlohmann::json& blocks)>& run);

}  // namespace brume
