// brume — procedural RGB-D demo scene.
//
// A small ray-cast outdoor scene (paved path, fence, checkered ball and cube,
// trees, a house, apartment blocks, a tree line, hills and mountains under a
// blue sky; ranges from 3 m to about 1.25 km) with exact per-pixel range, used to
// demonstrate and test the haze effects without any external data. The camera
// is 1.6 m above the ground, pitched 5 degrees down, 55 degree vertical field
// of view. See tools/demo_scene/demo_scene.cpp for its layout and units.
//
// Not part of the installed library: the static library brume_demo_scene,
// linked by the CLI, the study, the tests and the benchmarks.
#pragma once

#include "brume/image.hpp"

namespace brume {

struct DemoScene {
  Image rgb;         // 3 channels, LINEAR light (not sRGB), values in [0,1]
  Image range;       // 1 channel, metres from the camera centre along each pixel's ray; NaN for sky
  double fov_y_deg;  // vertical field of view used
};

// Renders the scene at width x height; the horizontal field of view follows
// from the aspect ratio. Non-positive sizes give empty images. Deterministic:
// the same arguments give the same output on any machine and thread count.
DemoScene render_demo_scene(int width, int height);

// Ground truth for depth of field: the same scene through a thin lens (the
// pinhole's centre of projection spread over an aperture disc, every ray
// through its pixel's point on the plane at planar depth focus_distance_m),
// `samples` rays per pixel (pixel and aperture positions from low-discrepancy
// sequences). The aperture is chosen so that a point at infinity images to a
// disc of coc_infinity_px pixels (brume dof's --coc-infinity); a point at
// planar depth Z to alpha |Z - Zf| / Z, the thin-lens CoC of brume/dof.hpp.
// rgb only (range is left empty). Partial occlusion is included, which no
// post-process on the pinhole image can reproduce.
DemoScene render_demo_scene_thin_lens(int width, int height, double focus_distance_m, double coc_infinity_px,
                                      int samples);

}  // namespace brume
