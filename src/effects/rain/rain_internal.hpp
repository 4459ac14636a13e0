// brume — rain's internal entry points for tests and benchmarks (not installed).
#pragma once

#include <cstddef>
#include <memory>

#include "brume/rain.hpp"
#include "effects/rain/streaks.hpp"

namespace brume {

// How a scan's drop echoes are searched (the same echoes, bit for bit):
//   by_beam: each beam's cone cells enumerated (RainField::cone_cells) and
//            their drops tested, about 20 µs a beam at 2 mrad;
//   by_cell: each cell the cones can cross drawn once, its drops tested
//            against the beams binned by direction: a cost that grows with
//            the volume the cones sweep, ~0.3 s for a KITTI scan;
//   chosen:  by_cell for scans of kLidarRainByCellBeams points or more, else by_beam
//            (lidar_rain, lidar_rain_as_medium);
//   general: the pass of a field that is not the scan's frame as hashed (a calibration, a pose,
//            a frame K > 0), which a scan in its own frame at frame 0 must repeat too.
// A field that is not the scan's frame as hashed always takes the general pass.
enum class LidarRainSearch { chosen, by_beam, by_cell, general };
constexpr std::size_t kLidarRainByCellBeams = 16384;
std::unique_ptr<Medium> lidar_rain_as_medium_searching(const LidarRainParams& p, LidarRainSearch search);

// render_camera_rain with the streaks it drew (slab by slab, before the splat) in `drawn` (may be
// null): the tests compare them with the scan's field.
Image render_camera_rain_drawn(const CameraRainScene& s, const CameraRainParams& p, const Exec& exec,
                               CameraRainStats* stats, Image* transmission, StreakSlabs* drawn);

}  // namespace brume
