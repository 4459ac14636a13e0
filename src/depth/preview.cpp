// brume — false-colour pictures of range maps, for inspection.
#include <algorithm>
#include <cmath>

#include "brume/depth.hpp"
#include "brume/io.hpp"

namespace brume {

// False colour of log range (near = warm, far = cool); unknown (sky) = black.
Image range_preview(const Image& range) {
  float lo = INFINITY, hi = 0.0f;
  for (float r : range.data)
    if (std::isfinite(r) && r > 0.0f) lo = std::min(lo, r), hi = std::max(hi, r);
  Image out(range.width, range.height, 3);
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    const float r = range.data[i];
    if (!(std::isfinite(r) && r > 0.0f)) continue;
    float t = hi > lo ? std::log(r / lo) / std::log(hi / lo) : 0.0f;
    // A short perceptual ramp: dark red -> orange -> yellow -> cyan -> blue.
    const float k[5][3] = {{0.5f, 0.0f, 0.05f}, {0.95f, 0.4f, 0.05f}, {0.95f, 0.9f, 0.3f},
                           {0.3f, 0.8f, 0.9f}, {0.1f, 0.2f, 0.7f}};
    float s = t * 4.0f;
    int j = std::min(3, static_cast<int>(s));
    float u = s - j;
    for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = srgb_to_linear(k[j][c] + u * (k[j + 1][c] - k[j][c]));
  }
  return out;
}

}  // namespace brume
