// The scenes the camera passes of falling particles are tested on (rain's and snow's:
// tests/test_rain_camera.cpp, tests/test_snow_camera.cpp): a flat grey scene at a constant
// range, its CameraRainScene, two threads.
#pragma once

#include <array>
#include <cstdint>
#include <functional>

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

// FNV-1a over an image's floats: a bit-for-bit fingerprint (the frames' tests compare with main's).
inline std::uint64_t fingerprint(const Image& im) {
  std::uint64_t h = 1469598103934665603ull;
  const unsigned char* b = reinterpret_cast<const unsigned char*>(im.data.data());
  for (std::size_t i = 0; i < im.data.size() * sizeof(float); ++i) h = (h ^ b[i]) * 1099511628211ull;
  return h;
}
// The fingerprints of frames 0, 1 and 2 of `render(frame, exec)` on two threads; each must be the
// same on one thread (the moving pass's order does not depend on the threads), else 0.
inline std::array<std::uint64_t, 3> frame_fingerprints(const std::function<Image(std::uint64_t, const Exec&)>& render) {
  Exec one;
  one.threads = 1;
  std::array<std::uint64_t, 3> h{};
  for (std::uint64_t k = 0; k < 3; ++k) {
    h[k] = fingerprint(render(k, two_threads()));
    if (fingerprint(render(k, one)) != h[k]) h[k] = 0;
  }
  return h;
}

}  // namespace brume::test
