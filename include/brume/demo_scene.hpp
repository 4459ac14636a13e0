// brume — procedural RGB-D demo scene.
//
// A small ray-cast outdoor scene (paved path, fence, checkered ball and cube,
// trees, houses, a tree line, hills and mountains under a blue sky) with exact
// per-pixel range, used to demonstrate and test the haze effects without any
// external data. See src/effects/demo_scene.cpp for its layout and units.
#pragma once

#include "brume/image.hpp"

namespace brume {

struct DemoScene {
  Image rgb;         // 3 channels, LINEAR light (not sRGB), values in [0,1]
  Image range;       // 1 channel, metres from the camera centre along each pixel's ray; NaN for sky
  double fov_y_deg;  // vertical field of view used
};

// Renders the scene at width x height (both > 0). Deterministic: the same
// arguments give the same output on any machine and thread count.
DemoScene render_demo_scene(int width, int height);

}  // namespace brume
