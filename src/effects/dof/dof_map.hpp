// brume — the depth-of-field scale map's vector kernels (internal): the
// CoC pass and the foreground rule's Gaussian, band values and maxima, one
// row at a time, written once with Highway and compiled for every SIMD
// target (dof_map_kernels.cpp). Each performs the operations of the scalar
// loops in dof.cpp (the reference, detail::dof_scale_map_rows with vector =
// false) in the same order, lane by lane, so every target gives the same
// bits (tests/test_dof.cpp, DofScaleMap.VectorRowsGiveTheReferenceBits).
#pragma once

#include <cstddef>

#include "brume/dof.hpp"

namespace brume::detail {

// The CoC pass over one row: sigma = min(sqrt(s0^2 + (c/4)^2), limit) with
// c the thin-lens CoC (alpha for unknown depth: not finite or <= 0), and the
// foreground rule's band of each pixel: floor(log2 sigma) (at least 0) where
// the depth is finite and nearer than zf and sigma > s0, else -1.
struct DofCocRow {
  const float* z = nullptr;  // the row's planar depth [m]
  float* sigma = nullptr;    // out: the row's scale [px]
  signed char* band = nullptr;  // out: the row's band, -1 outside the near field's bands
  int width = 0;
  float alpha = 0, zf = 0, s0 = 0, limit = 0;
};
// What the row counted, and where its bands lie: members (band >= 0) only
// in columns [lo, hi) and in bands [jmin, jmax] (lo >= hi: none).
struct DofCocStats {
  long unknown = 0, near = 0, capped = 0;
  float zmin = 0, zmax = 0;  // over known depths (zmin = +inf, zmax = 0: none)
  int lo = 0, hi = 0, jmin = 0, jmax = -1;
};
void dof_coc_row(const DofCocRow& r, DofCocStats& s);

// out[x] = (((0 + k[0] s[x]) + k[1] s[x + 1]) + ...) + k[taps - 1] s[x + taps - 1]
// for x in [x0, x1): a sampled Gaussian along a padded row.
void dof_blur_row(const float* s, const float* k, int taps, float* out, int x0, int x1);
// The same down columns: out[x] = ((0 + k[0] rows[0][x]) + ...) for x in [x0, x1).
void dof_blur_cols(const float* const* rows, const float* k, int taps, float* out, int x0, int x1);
// out[x] = band[x] == j ? sigma[x] : s0 for x in [0, n); returns how many were band j.
int dof_band_values(const signed char* band, const float* sigma, int j, float s0, float* out, int n);
// v[x] = max(v[x], r[x]) (std::max's operand order), x in [0, n).
void dof_max_row(float* v, const float* r, int n);
// v[x] = max(v[x], t[x] + a (b[x] - t[x])): a bilinear read between two rows.
void dof_max_lerp(float* v, const float* t, const float* b, float a, int n);
// v[x] = min(limit, v[x]).
void dof_cap_row(float* v, float limit, int n);

// dof_scale_map itself; vector = false runs the scalar loops (the vector
// rows' reference, in tests/test_dof.cpp and bench/bench_dof.cpp). The map
// runs on one thread below parallel_pixels pixels (a test lowers it).
Image dof_scale_map_rows(const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec, bool vector,
                         std::size_t parallel_pixels = std::size_t{1} << 22);

}  // namespace brume::detail
