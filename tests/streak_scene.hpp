// The scenes the camera passes of falling particles are tested on (rain's and snow's:
// tests/test_rain_camera.cpp, tests/test_snow_camera.cpp): a flat grey scene at a constant
// range, its CameraRainScene, two threads.
#pragma once

#include <array>

#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/rain.hpp"

namespace brume::test {

// A flat grey scene at a constant range, seen by a camera of focal length f.
struct Flat {
  Image rgb, range;
  Intrinsics k;
};
inline Flat flat(int w, int h, double f, float grey, double range_m) {
  Flat s{Image(w, h, 3, grey), Image(w, h, 1, static_cast<float>(range_m)), {}};
  s.k.fx = s.k.fy = f;
  s.k.cx = (w - 1) / 2.0;
  s.k.cy = (h - 1) / 2.0;
  return s;
}
// Its scene for the renderer: `analytic` media or none, the particles' own radiance.
inline CameraRainScene scene_of(const Flat& f, bool analytic) {
  CameraRainScene s;
  s.rgb = f.rgb;
  s.range = f.range;
  s.k = f.k;
  s.analytic = analytic;
  return s;
}
// The same with the particles' radiance fixed to `e`.
inline CameraRainScene scene_of(const Flat& f, bool analytic, std::array<float, 3> e) {
  CameraRainScene s = scene_of(f, analytic);
  s.drop_radiance = e;
  return s;
}
inline Exec two_threads() {
  Exec e;
  e.threads = 2;
  return e;
}

}  // namespace brume::test
