// brume — snow's internal entry points for tests and benchmarks (not installed).
#pragma once

#include <cstddef>
#include <vector>

#include "brume/snow.hpp"
#include "effects/rain/streaks.hpp"

namespace brume {

// One beam of the footprint model (brume/snow.hpp), every share spelt out:
// the drawn flakes near to far, the share the undrawn (undetectable) flakes
// take in expectation, and the target's. The shares sum to 1 to rounding.
struct SnowBeamFlake {
  double range_m = 0, d_mm = 0, a = 0, share = 0, power = 0;  // power: ρ_f·share/r′² [1/m²]
};
struct SnowBeam {
  std::vector<SnowBeamFlake> flakes;
  double undrawn_share = 0, target_share = 1;
};
// The beams to n points (x, y, z, intensity each), as lidar_snow draws them (validated parameters).
std::vector<SnowBeam> lidar_snow_beams(const LidarSnowParams& p, const float* points, std::size_t n);

// render_camera_snow with the streaks it drew (slab by slab, before the splat) in `drawn` (may be null).
Image render_camera_snow_drawn(const CameraRainScene& s, const CameraSnowParams& p, const Exec& exec,
                               CameraSnowStats* stats, Image* transmission, StreakSlabs* drawn);

}  // namespace brume
