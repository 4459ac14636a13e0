// brume — effects chained in one run: haze, then depth of field (the lens
// blurs what the air delivers; issue #13 item 5).
//
// One shape, no new flags by hand: the chain's job is haze's job (input and
// depth, preparation, haze with its diffusion block, outputs) with the whole
// depth-of-field block nested under the prefix "dof-" (ParamTable::nest with
// a prefix, as aerial's --sky-...): --dof-focus-distance, --dof-f-number,
// --dof-coc-infinity,
// --dof-coc-limit, --dof-scheme, --dof-foreground and the DOF stage's own
// diffusion flags (--dof-precision, --dof-sigma0, --dof-rho-max,
// --dof-edge-rate), and one more map output, --dof-scale-map. The record
// keeps them in the block "dof" (the batch mode's `dof.scheme`).
//
// The lens's focal length and sensor are the camera's, shared: the depth
// block's --focal-length and --sensor-width (--dof-focal-length and
// --dof-sensor-width, the chain's flags before schema 4, are their aliases).
// Shared, given once: the image, the depth source with its camera (the DOF
// stage's planar depth uses the depth flags' intrinsics, else the lens's,
// checked to agree within 1 % as in `brume dof`), the preparation (the range
// is prepared once and both stages run on it) and the output encoding.
// Not shared: every DOF parameter, --dof-sigma0 included. The DOF target
// sigma = sqrt(sigma0^2 + (c/4)^2) adds the variance (c/4)^2 whatever sigma0
// is (sigma0 moves only the cap and the plan), and keeping it the DOF's own
// makes the chain exactly `brume haze` then `brume dof` with the same
// values, which is what the tests hold it to.
//
// Data flow: the haze stage's linear RGB (before any encoding) is the DOF
// stage's input, in memory, at full float precision. On the GPU backend both
// stages run on one context; the hazy image is read back (haze needs its
// transmission and scale maps on the host anyway, and the DOF scale map is
// formed on the host from planar depth) and uploaded again as the DOF
// diffusion's RGBA input: one W x H RGBA32F readback and one upload, shown
// in --timing as the haze stage's readback_ms and the DOF stage's upload_ms.
#pragma once

#include <set>
#include <string>
#include <vector>

#include "brume/dof.hpp"
#include "brume/haze.hpp"

namespace brume {

// The prefix of the DOF stage's flags in a chain; its record block is "dof".
inline constexpr const char* kDofPrefix = "dof-";

struct HazeDofRun {
  HazeRun haze;           // haze.result.rgb: the hazy image the lens sees (linear RGB)
  DofRun dof;             // dof.result.rgb: the output (linear RGB)
  nlohmann::json record;  // {"haze", "dof", "prepare", "execution"}; execution.timing {"haze", "dof"}
};

// In memory, on views read in place. `measured_range`: metres along the ray; `k`: the intrinsics
// (resolved) for the DOF stage's planar depth. `given` holds the chain's
// names (the DOF's with their "dof-" prefix). Errors of the DOF stage name
// its flags with the prefix (--dof-focus-distance).
HazeDofRun run_haze_dof(ConstImageView rgb, ConstImageView measured_range, const Intrinsics& k, const HazeParams& haze,
                        const DofParams& dof, const RangeStep& prepare, const Exec& exec = {},
                        const std::set<std::string>& given = {});
// The Image form (an Image temporary cannot become a view).
inline HazeDofRun run_haze_dof(const Image& rgb, const Image& measured_range, const Intrinsics& k,
                               const HazeParams& haze, const DofParams& dof, const RangeStep& prepare,
                               const Exec& exec = {}, const std::set<std::string>& given = {}) {
  return run_haze_dof(ConstImageView(rgb), ConstImageView(measured_range), k, haze, dof, prepare, exec, given);
}

}  // namespace brume
