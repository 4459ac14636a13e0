// The demo scene as wet ground's camera tests and bench see it (tests/test_wet.cpp,
// tests/test_wet_gpu.cpp, bench/bench_wet.cpp):
// `brume demo`'s scene at W x H, the camera 1.6 m up and 5 deg down with the demo's vertical field
// of view, a ground tolerance of 2 cm, a blue-grey sky.
#pragma once

#include <cmath>

#include "brume/camera.hpp"
#include "brume/demo_scene.hpp"
#include "brume/wet.hpp"

namespace brume::test {

// `d` must outlive the scene (its images are viewed).
inline WetScene demo_wet_scene(const DemoScene& d, int W, int H) {
  CameraPose pose;
  pose.height_m = 1.6;
  pose.pitch_deg = -5.0;
  WetScene sc;
  sc.rgb = d.rgb;
  sc.range = d.range;
  sc.camera = make_camera(intrinsics_from_fov(W, H, NAN, d.fov_y_deg), W, H, pose);
  sc.ground_tolerance_m = 0.02;
  sc.sky = {0.55f, 0.65f, 0.8f};
  return sc;
}

}  // namespace brume::test
