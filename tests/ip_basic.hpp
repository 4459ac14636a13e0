// brume tests and benchmarks — IP-Basic (Ku, Harakeh & Waslander, "In
// defense of classical image processing: fast depth completion on the CPU",
// CRV 2018), its "fast" configuration, written here from the paper in plain
// loops (no OpenCV, so that it is independent of brume's pilot), and KITTI
// depth completion's four metrics. Used by tests/test_complete.cpp and
// bench/bench_complete.cpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <utility>
#include <vector>

#include "brume/depth.hpp"
#include "brume/image.hpp"

namespace brume::ip_basic {

// ---- Ku, Harakeh & Waslander 2018 (CRV), section III, written from the paper ----
// On the inverted depth D' = 100 - D (valid pixels only; 0 = empty), as the
// paper does: (1) dilate with a 5x5 diamond; (2) close with a 5x5 full kernel;
// (3) fill empty pixels from a 7x7 full dilation; (4) "extend to top" (left
// out: the held-out pixels all lie inside the scan); (5) fill empty pixels
// from a 31x31 full dilation; (6) 5x5 median on the valid pixels; (7) 5x5
// Gaussian blur on the valid pixels; invert back. Borders: only in-image
// pixels take part (the paper's OpenCV defaults do the same for dilation).
using Grid = std::vector<double>;

inline Grid dilate(const Grid& in, int W, int H, const std::vector<std::pair<int, int>>& offsets) {
  Grid out(in.size(), 0.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      double m = 0.0;
      for (auto [dx, dy] : offsets) {
        const int u = x + dx, v = y + dy;
        if (u >= 0 && v >= 0 && u < W && v < H) m = std::max(m, in[static_cast<std::size_t>(v) * W + u]);
      }
      out[static_cast<std::size_t>(y) * W + x] = m;
    }
  return out;
}
// A full k x k dilation (erosion with `erode`) as a row pass then a column pass.
inline Grid square(const Grid& in, int W, int H, int k, bool erode = false) {
  const int r = k / 2;
  Grid a(in.size()), b(in.size());
  auto pick = [erode](double p, double q) { return erode ? std::min(p, q) : std::max(p, q); };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      double m = in[static_cast<std::size_t>(y) * W + x];
      for (int d = -r; d <= r; ++d)
        if (x + d >= 0 && x + d < W) m = pick(m, in[static_cast<std::size_t>(y) * W + x + d]);
      a[static_cast<std::size_t>(y) * W + x] = m;
    }
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      double m = a[static_cast<std::size_t>(y) * W + x];
      for (int d = -r; d <= r; ++d)
        if (y + d >= 0 && y + d < H) m = pick(m, a[static_cast<std::size_t>(y + d) * W + x]);
      b[static_cast<std::size_t>(y) * W + x] = m;
    }
  return b;
}

inline Image ku_baseline(const Image& sparse) {
  const int W = sparse.width, H = sparse.height;
  const double kMax = 100.0;  // the paper's inversion constant (KITTI's ranges stay below it)
  Grid d(sparse.pixels());
  for (std::size_t i = 0; i < d.size(); ++i) d[i] = std::isfinite(sparse.data[i]) ? kMax - sparse.data[i] : 0.0;
  std::vector<std::pair<int, int>> diamond;
  for (int dy = -2; dy <= 2; ++dy)
    for (int dx = -2; dx <= 2; ++dx)
      if (std::abs(dx) + std::abs(dy) <= 2) diamond.emplace_back(dx, dy);
  d = dilate(d, W, H, diamond);
  d = square(square(d, W, H, 5), W, H, 5, true);  // closing
  for (int k : {7, 31}) {
    const Grid f = square(d, W, H, k);
    for (std::size_t i = 0; i < d.size(); ++i)
      if (d[i] < 0.1) d[i] = f[i];
  }
  Grid med = d;
  std::vector<double> win;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      if (d[i] < 0.1) continue;
      win.clear();
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          const int u = std::clamp(x + dx, 0, W - 1), v = std::clamp(y + dy, 0, H - 1);
          win.push_back(d[static_cast<std::size_t>(v) * W + u]);
        }
      std::nth_element(win.begin(), win.begin() + 12, win.end());
      med[i] = win[12];
    }
  // 5x5 Gaussian, sigma 1.1 px (OpenCV's for a 5-tap kernel with sigma 0, the paper's call).
  double g[5], gs = 0;
  for (int k = -2; k <= 2; ++k) gs += g[k + 2] = std::exp(-k * k / (2 * 1.1 * 1.1));
  for (double& v : g) v /= gs;
  Grid blur = med;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      if (med[i] < 0.1) continue;
      double s = 0;
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          const int u = std::clamp(x + dx, 0, W - 1), v = std::clamp(y + dy, 0, H - 1);
          s += g[dx + 2] * g[dy + 2] * med[static_cast<std::size_t>(v) * W + u];
        }
      blur[i] = s;
    }
  Image out(W, H, 1, NAN);
  for (std::size_t i = 0; i < blur.size(); ++i)
    if (blur[i] > 0.1) out.data[i] = static_cast<float>(kMax - blur[i]);
  return out;
}

// KITTI depth completion's metrics (Uhrig et al., "Sparsity invariant CNNs",
// 3DV 2017; the benchmark's devkit defines them on planar depth): MAE and
// RMSE of the depth [mm], iMAE and iRMSE of the inverse depth [1/km], over
// the pixels `at` where the truth is known; a pixel without an estimate is
// counted apart (`missing`), not in the means. Range maps are converted to
// planar depth with the camera k.
struct DcMetrics {
  double mae_mm = 0, rmse_mm = 0, imae_per_km = 0, irmse_per_km = 0;
  std::size_t n = 0, missing = 0;
};
inline DcMetrics dc_metrics(const Image& est_range, const Image& truth_range, const std::vector<std::size_t>& at,
                            const Intrinsics& k) {
  DcMetrics m;
  double a = 0, a2 = 0, ia = 0, ia2 = 0;
  for (std::size_t i : at) {
    const int x = static_cast<int>(i % est_range.width), y = static_cast<int>(i / est_range.width);
    const double u = (x - k.cx) / k.fx, v = (y - k.cy) / k.fy, s = std::sqrt(1.0 + u * u + v * v);
    const double t = truth_range.data[i] / s, e = est_range.data[i] / s;
    if (!std::isfinite(e) || e <= 0.0) {
      ++m.missing;
      continue;
    }
    const double d = (e - t) * 1e3, id = (1.0 / e - 1.0 / t) * 1e3;
    a += std::abs(d), a2 += d * d, ia += std::abs(id), ia2 += id * id, ++m.n;
  }
  if (m.n) {
    const double n = static_cast<double>(m.n);
    m.mae_mm = a / n, m.rmse_mm = std::sqrt(a2 / n), m.imae_per_km = ia / n, m.irmse_per_km = std::sqrt(ia2 / n);
  }
  return m;
}

// The held-out protocol of tests/test_complete.cpp and bench_complete
// (issue 52, item 3): 10 % of the returns `known` (pixel indices of `full`),
// drawn by std::shuffle with std::mt19937_64(seed), held out: `held`; those
// of them that `occluded` (occluded_returns of the full scan) does not mark:
// `kept`, the truth both methods are scored on; `sparse`: `full` without
// the held-out returns.
struct HeldOut {
  std::vector<std::size_t> held, kept;
  Image sparse;
};
inline HeldOut hold_out(const Image& full, const std::vector<std::size_t>& known,
                        const std::vector<std::uint8_t>& occluded, int seed) {
  std::vector<std::size_t> order = known;
  std::mt19937_64 rng(seed);
  std::shuffle(order.begin(), order.end(), rng);
  HeldOut h;
  h.held.assign(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(order.size() / 10));
  for (std::size_t i : h.held)
    if (!occluded[i]) h.kept.push_back(i);
  h.sparse = full;
  for (std::size_t i : h.held) h.sparse.data[i] = NAN;
  return h;
}

}  // namespace brume::ip_basic
