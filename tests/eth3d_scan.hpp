// brume tests and benchmarks — ETH3D two-view frames with a KITTI-like scan
// simulated from their laser ground truth (issue 52): the scan-only
// completion's "above the scan" test (tests/test_complete.cpp) and its
// fusion with the second view (tests/test_fuse.cpp, bench/bench_complete.cpp)
// take the same scan. No test helpers here: the bench includes it too.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <utility>

#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/io.hpp"

namespace brume::eth3d {

// ETH3D two-view with a KITTI-like scan simulated from its laser ground
// truth: 48 full rows (every pixel with a ground-truth value) spread evenly
// over the lower 60 % of the frame, nothing above (issue 52).
struct SimulatedScan {
  Image rgb, truth, sparse;
  Intrinsics k;
  int top = 0;  // first row of the lower 60 %
};
// `dir`: the scene's folder (im0.png, disp0.pfm, calib.txt), ending in '/'.
inline SimulatedScan kitti_like_scan(const std::string& dir) {
  SimulatedScan e;
  DepthSource s;
  s.disparity = dir + "disp0.pfm";
  s.calib = dir + "calib.txt";
  LoadedDepth ld = load_depth(s);
  e.truth = std::move(ld.range);
  e.k = *ld.camera;
  e.rgb = read_color(dir + "im0.png");
  const int H = e.truth.height;
  e.top = static_cast<int>(std::ceil(0.4 * H));
  e.sparse = Image(e.truth.width, H, 1, NAN);
  for (int i = 0; i < 48; ++i) {
    const int y = e.top + static_cast<int>(std::lround(i * (H - 1 - e.top) / 47.0));
    for (int x = 0; x < e.truth.width; ++x) e.sparse.at(x, y) = e.truth.at(x, y);
  }
  return e;
}

// Share of the ground-truth pixels of rows [y0, y1) off by more than 10 %
// (a pixel left unknown counts as off).
inline double share_off(const Image& est, const Image& truth, int y0, int y1, std::size_t* n_out = nullptr) {
  std::size_t n = 0, off = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = 0; x < truth.width; ++x) {
      const float t = truth.at(x, y), v = est.at(x, y);
      if (!std::isfinite(t)) continue;
      ++n;
      off += (std::isfinite(v) && std::abs(v - t) <= 0.1f * t) ? 0 : 1;
    }
  if (n_out) *n_out = n;
  return n ? static_cast<double>(off) / static_cast<double>(n) : 0.0;
}

}  // namespace brume::eth3d
