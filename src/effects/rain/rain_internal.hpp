// brume — rain's internal entry points for tests and benchmarks (not installed).
#pragma once

#include <memory>

#include "brume/rain.hpp"

namespace brume {

// Rain on a scan as lidar_rain_as_medium, but its echoes found beam by beam:
// each beam's cone cells enumerated (RainField::cone_cells) and their drops
// tested — the algorithm before the cell-major pass, which the pass repeats
// bit for bit (tests/test_rain.cpp, bench/bench_rain.cpp).
std::unique_ptr<Medium> lidar_rain_as_medium_by_beam(const LidarRainParams& p);

}  // namespace brume
