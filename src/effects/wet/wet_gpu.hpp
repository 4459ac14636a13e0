// brume — the camera's wet ground on the GPU (brume/wet.hpp): render_wet's per-pixel pass as one
// fragment shader (wet_apply.frag: the ground test, the darkening, the Fresnel mirror with its
// march through the range map). Internal.
#pragma once

#include "brume/gpu_context.hpp"
#include "brume/wet.hpp"

namespace brume {

// The scene's checks render_wet makes (sizes, the mask's, the camera's height without a mask).
void check_wet_scene(const WetScene& s);

// The march that runs for the scene: its own, but blocks where above_ground cannot (no camera
// height: the plane's pixels are unknown, the ground is a mask's).
WetMarch wet_march_that_runs(const WetScene& s);

// render_wet's contract on the GPU: the same scene checks, the same image up to float rounding
// (the march in float: at grazing rays a mirrored ray may take a neighbouring pixel), the
// ground map, the counts and the march that ran (both marches, wet_march_that_runs); the pass's times in `timing` (its pass in composite_ms).
Image render_wet_gpu(GpuContext& ctx, const WetScene& s, const WetFilm& w, WetStats* stats, Image* ground,
                     GpuTiming& timing);

}  // namespace brume
