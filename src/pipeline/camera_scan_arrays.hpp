// brume — a camera effect's scan on arrays (brume.rain(..., lidar=points), brume.wet(...,
// lidar=points)): the frame's scan through the effect's scan model, its points and labels as the
// Result's lidar and lidar_labels (None for both without a scan), and the call's job marked with an
// empty lidar block (the scan's settings are the call's own keywords). Private to the library.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "brume/command.hpp"

namespace brume {

// The scan argument in[at], when given, through `run` (scan_array_result's: the points that return
// into out, one label per point, the count lost); its arrays into r. Whether there was a scan.
inline bool camera_scan_arrays(const std::vector<ArrayIn>& in, std::size_t at, const std::string& what,
                               ArrayResult& r,
                               const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*)>& run) {
  if (in.size() <= at || !in[at].present) {
    r.images["lidar"] = Image();  // None
    r.more["lidar_labels"] = nullptr;
    return false;
  }
  ArrayResult scan = scan_array_result(in[at].view, what, run);
  r.images["lidar"] = std::move(scan.images["points"]);
  r.bytes["lidar_labels"] = std::move(scan.bytes["labels"]);
  return true;
}

// The form's run, its job marked with an empty lidar block when in[at] was given.
inline void mark_scan_in_job(ArrayForm& a, std::size_t at) {
  a.run = [inner = a.run, at](const std::vector<ArrayIn>& in, const nlohmann::json& call, const Exec& e,
                              const std::set<std::string>& g) {
    ArrayResult r = inner(in, call, e, g);
    if (in.size() > at && in[at].present) r.job["lidar"] = nlohmann::json::object();
    return r;
  };
}

}  // namespace brume
