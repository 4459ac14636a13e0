// brume — temporal blocking of the diffusion iterations of the invariant
// schemes, constant-scale and space-variant (internal; issue #16).
//
// Every iteration of the invariant schemes reads the whole image and writes
// the whole image: at 1600x1120 RGBA float, 17 iterations move ~1 GB. When
// the image does not stay in the last-level cache that traffic, not the
// arithmetic, sets the time (the Intel host of README "Speed": 100 of 134 ms
// were the memory floor). Temporal blocking runs several iterations per pass
// over the image: a group of m consecutive iterations reads the image once
// (level 0) and writes it once (level m); the m - 1 levels between live in
// small ring buffers of rows that stay in the core's cache.
//
// The schedule is a wavefront over rows. Iteration j of a group (level j)
// computes row y from rows y, y -+ n_j and y -+ (n_j + 1) of level j - 1,
// mirrored at the image's edges (n_j: the constant offset's integer part, or
// on a space-variant map any pixel's, at most the bound general_radii gives):
// all within y -+ r_j, r_j = n_j + 1 (a single
// reflection moves a row by at most n_j; a tap reflected twice means
// r_j > H, and then every row is within reach). So level j can compute row y
// as soon as level j - 1 has row min(H - 1, y + r_j), and level j - 1 must
// still hold row y - r_j: a ring of 2 r_j + 1 rows. Level j runs
// lag_j = r_2 + ... + r_j rows behind level 1; each "time" step computes one
// row of every level, in level order.
//
// Threads take contiguous bands of the output rows and run their own
// wavefront with their own rings; a band's level j covers the band widened
// by E_j = r_{j+1} + ... + r_m rows on each side (clipped to the image), so
// neighbouring bands recompute a few rows each (overlapped tiling) and no
// thread waits for another within a group. Every row of every level is
// computed by the same row function from the same input rows as the
// unblocked schedule, so the result is bit for bit the same, whatever the
// thread count, band or group (tests: DiffusionFusion.*).
//
// Which iterations to fuse (FusionLimits, diffusion_kernels.hpp):
// consecutive ones while the group's total halo r_1 + ... + r_m stays within
// halo_rows and its rings within ring_bytes per thread (about the core's L2);
// and a thread's band must be band_halos halos tall, or the recomputation at
// the band's edges eats the saving. Late iterations, whose offsets outgrow
// that, run alone as before.
#pragma once

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "cpu/diffusion_kernels.hpp"
#include "cpu/diffusion_rows.hpp"

namespace brume::cpu {

// Internal linkage: diffusion_fast_f16.cpp compiles this header with -mavx2,
// and an inline function with external linkage compiled there could be the
// copy the linker keeps for every caller, AVX2 instructions and all, on a CPU
// without them.
namespace {

// Radii of a schedule: iteration k reads rows within y -+ radii[k] of the
// row it writes (its largest integer offset n, plus 1).
using Radii = std::vector<int>;

// Rows of ring that a group's levels 1 .. m-1 need (level j, read by
// iteration j of the group: 2 radius + 1).
inline std::size_t fused_ring_rows(const int* radii, int m) {
  std::size_t rows = 0;
  for (int j = 1; j < m; ++j) rows += 2 * static_cast<std::size_t>(radii[j]) + 1;
  return rows;
}

// Rows of ring per thread that the largest group of a plan needs (a pass
// alone needs none).
inline std::size_t max_ring_rows(const Radii& radii, const std::vector<FusedGroup>& groups) {
  std::size_t rows = 0;
  for (const FusedGroup& g : groups) rows = std::max(rows, fused_ring_rows(&radii[static_cast<std::size_t>(g.k0)], g.m));
  return rows;
}

// The groups of N iterations with these radii on a W x H image with
// `threads` bands; `elem_bytes` per channel value (4: float, 2: binary16).
inline std::vector<FusedGroup> plan_fusion(const Radii& radii, int W, int H, int threads, std::size_t elem_bytes) {
  const FusionLimits lim = diffusion_fusion_limits();
  const int N = static_cast<int>(radii.size());
  const std::size_t row_bytes = static_cast<std::size_t>(W) * 4 * elem_bytes;
  const int band = H / std::max(1, threads);
  std::vector<FusedGroup> groups;
  for (int k = 0; k < N;) {
    int m = 1, halo = radii[static_cast<std::size_t>(k)];
    while (k + m < N) {
      const int h = halo + radii[static_cast<std::size_t>(k + m)];
      if (h > lim.halo_rows || static_cast<long long>(lim.band_halos) * h > band) break;
      if (static_cast<long long>(fused_ring_rows(&radii[static_cast<std::size_t>(k)], m + 1) * row_bytes) >
          lim.ring_bytes)
        break;
      halo = h;
      ++m;
    }
    groups.push_back({k, m});
    k += m;
  }
  return groups;
}

// Output rows [Y0, Y1) of a group of m >= 2 iterations with radii
// radii[0 .. m), from the whole image A (level 0) into the whole image B
// (level m); ring: fused_ring_rows(radii, m) rows of W x 4 values, this
// thread's own. row(j, y, in, out): iteration j of the group writes row y of
// level j + 1 to `out`, reading level j through in(q), which returns row q
// (any q within y -+ radii[j], already mirrored into the image).
template <class T, class LevelRow>
void fused_group_band(const T* A, T* B, int W, int H, const int* radii, int m, int Y0, int Y1, T* ring,
                      LevelRow&& row) {
  const std::size_t rs = static_cast<std::size_t>(W) * 4;  // values per row
  // Levels 1..m: radius r (of the iteration that writes it), halo E, rows
  // [lo, hi], lag; levels 1..m-1: ring capacity and base.
  std::vector<int> r(m + 1), E(m + 1), lo(m + 1), hi(m + 1), lag(m + 1), cap(m + 1, 0);
  std::vector<T*> base(m + 1, nullptr);
  for (int j = 1; j <= m; ++j) r[j] = radii[j - 1];
  E[m] = 0;
  for (int j = m - 1; j >= 1; --j) E[j] = E[j + 1] + r[j + 1];
  lag[1] = 0;
  for (int j = 2; j <= m; ++j) lag[j] = lag[j - 1] + r[j];
  T* p = ring;
  for (int j = 1; j <= m; ++j) {
    lo[j] = std::max(0, Y0 - E[j]);
    hi[j] = std::min(H - 1, Y1 - 1 + E[j]);
    if (j < m) {
      cap[j] = 2 * r[j + 1] + 1;
      base[j] = p;
      p += static_cast<std::size_t>(cap[j]) * rs;
    }
  }
  int v0 = lo[1], v1 = hi[1];
  for (int j = 2; j <= m; ++j) v0 = std::min(v0, lo[j] + lag[j]), v1 = std::max(v1, hi[j] + lag[j]);
  for (int v = v0; v <= v1; ++v)
    for (int j = 1; j <= m; ++j) {
      const int y = v - lag[j];
      if (y < lo[j] || y > hi[j]) continue;
      // Level j - 1 (0: A; else its ring), row y of level j (m: B).
      const RowSource<T> in = j == 1 ? RowSource<T>{A, rs, 0} : RowSource<T>{base[j - 1], rs, cap[j - 1]};
      T* out = j == m ? B + static_cast<std::size_t>(y) * rs : base[j] + static_cast<std::size_t>(y % cap[j]) * rs;
      row(j - 1, y, in, out);
    }
}

// N iterations of F from `src`, ping-ponging with `dst` (both W x H x 4),
// grouped by plan_fusion; returns the buffer holding the result. ring: at
// least fusion_ring_values(...) values. row(k, y, in, out): iteration k
// writes row y to `out`, reading the previous level through in(q) (see
// fused_group_band). Called from inside OpenMP parallel regions
// (omp_get_thread_num() names the calling thread's scratch). Each thread's
// band of a fused group overlaps its neighbours' by the group's halo, so
// rows there are computed twice, from the same inputs, with the same bits.
template <class T, class LevelRow>
T* iterations_fused(T* src, T* dst, int W, int H, const Radii& radii, const std::vector<FusedGroup>& groups,
                    int threads, T* ring, LevelRow row) {
  const std::size_t rs = static_cast<std::size_t>(W) * 4;
  const std::size_t ring_rows = max_ring_rows(radii, groups);
  for (const FusedGroup& g : groups) {
    if (g.m == 1) {
      const RowSource<T> in{src, rs, 0};
#pragma omp parallel for num_threads(threads) schedule(static)
      for (int y = 0; y < H; ++y) row(g.k0, y, in, dst + y * rs);
    } else {
#pragma omp parallel num_threads(threads)
      {
        const int t = omp_get_thread_num(), nt = omp_get_num_threads();
        const int Y0 = static_cast<int>(static_cast<long long>(H) * t / nt);
        const int Y1 = static_cast<int>(static_cast<long long>(H) * (t + 1) / nt);
        if (Y0 < Y1)
          fused_group_band(src, dst, W, H, &radii[static_cast<std::size_t>(g.k0)], g.m, Y0, Y1,
                           ring + t * ring_rows * rs, [&](int j, int y, const RowSource<T>& in, T* out) {
                             row(g.k0 + j, y, in, out);
                           });
      }
    }
    std::swap(src, dst);
  }
  return src;
}

// Values of ring that iterations_fused needs.
inline std::size_t fusion_ring_values(const Radii& radii, const std::vector<FusedGroup>& groups, int W,
                                      int threads) {
  return max_ring_rows(radii, groups) * static_cast<std::size_t>(W) * 4 * static_cast<std::size_t>(threads);
}

// The radii of constant-scale steps: n + 1.
inline Radii uniform_radii(const std::vector<UniformStep>& st) {
  Radii r(st.size());
  for (std::size_t k = 0; k < st.size(); ++k) r[k] = st[k].n + 1;
  return r;
}

// The radii of the space-variant invariant schemes: per iteration, a bound
// on the largest integer offset n over the image, plus 1, plus one row of
// slack. The offset grows with the rate (sigma_k = s0 e^{k rho} and the
// exact scheme's variance ratio both increase with rho), so the largest rate
// bounds it; computed in double with a relative margin of 1e-4 (+1e-6 per
// iteration) for the float running product, e^{rho} and the ratio, which
// differ from the double values by a few ulps: a bound, never an estimate.
inline Radii general_radii(const float* rho, std::size_t np, int N, float s0, bool exact) {
  const float rmax = largest_nonnegative(rho, np);  // the rates are finite and >= 0
  const double x = 2.0 * static_cast<double>(rmax);
  const double vr = exact ? (x < 1e-12 ? 1.0 : std::expm1(x) / x) : 1.0;
  const double g = std::exp(static_cast<double>(rmax));
  Radii r(static_cast<std::size_t>(N));
  double s = s0;
  for (int k = 0; k < N; ++k) {
    const double margin = 1.0 + 1e-4 + 1e-6 * k;
    // exact: n = floor(sqrt(m)), m = sigma_k^2 vr (brume_offset_for_moment);
    // published: n = floor(sigma_k).
    const double bound = exact ? std::sqrt(s * s * vr) * margin * margin : s * margin;
    r[static_cast<std::size_t>(k)] = static_cast<int>(std::floor(bound)) + 2;
    s *= g;
  }
  return r;
}

// Constant-scale iterations: one row from its centre row and the rows at
// -n, -(n+1), +n, +(n+1) of the step, mirrored. row5(s, u0, u1, d0, d1, o, step).
template <class T, class Row5>
T* uniform_iterations_fused(T* src, T* dst, int W, int H, const std::vector<UniformStep>& st,
                            const std::vector<FusedGroup>& groups, int threads, T* ring, Row5 row5) {
  return iterations_fused(src, dst, W, H, uniform_radii(st), groups, threads, ring,
                          [&](int k, int y, const RowSource<T>& in, T* out) {
                            const UniformStep& s = st[static_cast<std::size_t>(k)];
                            const int n = s.n;
                            row5(in(y), in(mirror(y - n, H)), in(mirror(y - n - 1, H)), in(mirror(y + n, H)),
                                 in(mirror(y + n + 1, H)), out, s);
                          });
}

// The steps of N constant-scale iterations: sigma_k as the running product
// sigma_{k+1} = sigma_k e^{rho}, the same float sequence as every path.
inline std::vector<UniformStep> uniform_steps(int N, float s0, float rho, bool exact, int edge_mode) {
  std::vector<UniformStep> st(static_cast<std::size_t>(N));
  const float growth = setup_math::expf1(rho);  // as the space-variant path's growth
  float sig = s0;
  for (int k = 0; k < N; ++k) {
    st[static_cast<std::size_t>(k)] = uniform_step(sig, rho, exact, edge_mode);
    sig *= growth;
  }
  return st;
}

}  // namespace
}  // namespace brume::cpu
