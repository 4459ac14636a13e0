// brume — the check every scan effect makes of its input points before any
// work (lidar rain, lidar snow): finite coordinates and intensities >= 0.
#pragma once

#include <cstddef>
#include <string>

namespace brume {

// Refuses (brume::Error naming `what` and the point) a non-finite value or a
// negative intensity among n points of 4 floats.
void check_scan_points(const float* points, std::size_t n, const std::string& what);

}  // namespace brume
