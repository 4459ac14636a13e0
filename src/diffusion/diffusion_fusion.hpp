// brume — temporal blocking of the diffusion iterations: the invariant
// schemes, constant-scale and space-variant, and the conductance stencil
// (standard scheme, radius one row) (internal; issue #16).
//
// Every iteration of the invariant schemes reads the whole image and writes
// the whole image: at 1600x1120 RGBA float, 17 iterations move ~1 GB. When
// the image does not stay in the last-level cache that traffic, not the
// arithmetic, sets the time (the Intel host of docs/performance.md: 100 of 134 ms
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
#include <cstring>
#include <utility>
#include <vector>

#include "core/schedule.hpp"
#include "diffusion/diffusion_kernels.hpp"
#include "diffusion/diffusion_rows.hpp"

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

// The groups of N iterations with these radii on a W x H image with
// `threads` bands; `elem_bytes` per channel value (4: float, 2: binary16).
inline std::vector<FusedGroup> plan_fusion(const Radii& radii, int W, int H, int threads, std::size_t elem_bytes,
                                           int channels = 4) {
  const FusionLimits lim = diffusion_fusion_limits();
  const int N = static_cast<int>(radii.size());
  const std::size_t row_bytes = static_cast<std::size_t>(W) * static_cast<std::size_t>(channels) * elem_bytes;
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

// A pass is done in place: the image it reads is the image it writes, so
// the fast path needs no second image-sized buffer (the ping-pong partner
// it had until 2026-12-03: 28.7 MB at 1600x1120, first touched by every
// run, and out of the last-level cache together with the image). Two
// things make that safe.
//  - Within a band, the wavefront reads level 0 (the image) at step v only
//    in rows v -+ r_1, and later steps read rows >= v + 1 - r_1; the group's
//    last level writes row v - lag_m at step v. A row goes to the image once
//    no later step reads its old value: directly when lag_m >= r_1, else
//    through a ring of r_1 - lag_m + 1 rows (the delay) from which row
//    v - r_1 is written at the end of step v.
//  - The rows of the neighbouring bands that level 1 reads (at most the
//    group's halo, r_1 + ... + r_m rows, on each side) are copied before any
//    thread writes (a barrier), and read from the copies.
// Where some group's copies and delay would exceed half the image (offsets
// large against the bands: many threads, or a short image), the schedule
// runs as before instead, each pass from one image into a partner image
// (plan_scratch); the partner is allocated only then.

// What a group's rows are: the radius r_j of the iteration that writes level
// j, its halo E_j (levels j + 1 .. m read E_j more rows on each side), the
// lag of level j behind level 1.
struct GroupShape {
  std::vector<int> r, E, lag;
  GroupShape(const int* radii, int m) : r(m + 1), E(m + 1), lag(m + 1) {
    for (int j = 1; j <= m; ++j) r[j] = radii[j - 1];
    E[m] = 0;
    for (int j = m - 1; j >= 1; --j) E[j] = E[j + 1] + r[j + 1];
    lag[1] = 0;
    for (int j = 2; j <= m; ++j) lag[j] = lag[j - 1] + r[j];
  }
  int halo() const { return E[1] + r[1]; }  // r_1 + ... + r_m
  // Rows of delay the in-place last level needs (0: it writes directly).
  int delay() const { return lag.back() >= r[1] ? 0 : r[1] - lag.back() + 1; }
};

// Output rows [Y0, Y1) of a group of m >= 1 iterations with radii
// radii[0 .. m) into the whole image B (level m). Level 0 is read through
// `level0` (the image A, or, in place, B's own rows and copies of the
// neighbouring bands'). rs: values per row (W x the channels). ring:
// fused_ring_rows(radii, m) rows, this thread's own. delay: null when B is
// not level 0 (rows are written directly), else GroupShape::delay() rows
// (or null when that is 0).
// row(j, y, in, out): iteration j of the group writes row y of level j + 1
// to `out`, reading level j through in(q), which returns row q (any q within
// y -+ radii[j], already mirrored into the image).
template <class T, class LevelRow>
void fused_group_band(const RowSource<T>& level0, T* B, std::size_t rs, int H, const int* radii, int m, int Y0,
                      int Y1, T* ring, T* delay, LevelRow&& row) {
  const GroupShape g(radii, m);
  // Levels 1..m: rows [lo, hi]; levels 1..m-1: ring capacity and base.
  std::vector<int> lo(m + 1), hi(m + 1), cap(m + 1, 0);
  std::vector<T*> base(m + 1, nullptr);
  T* p = ring;
  for (int j = 1; j <= m; ++j) {
    lo[j] = std::max(0, Y0 - g.E[j]);
    hi[j] = std::min(H - 1, Y1 - 1 + g.E[j]);
    if (j < m) {
      cap[j] = 2 * g.r[j + 1] + 1;
      base[j] = p;
      p += static_cast<std::size_t>(cap[j]) * rs;
    }
  }
  const int C = delay ? g.delay() : 0;  // delay rows (0: direct writes)
  int v0 = lo[1], v1 = hi[1];
  for (int j = 2; j <= m; ++j) v0 = std::min(v0, lo[j] + g.lag[j]), v1 = std::max(v1, hi[j] + g.lag[j]);
  auto flush = [&](int y) {
    std::memcpy(B + static_cast<std::size_t>(y) * rs, delay + static_cast<std::size_t>(y % C) * rs, rs * sizeof(T));
  };
  for (int v = v0; v <= v1; ++v) {
    for (int j = 1; j <= m; ++j) {
      const int y = v - g.lag[j];
      if (y < lo[j] || y > hi[j]) continue;
      // Level j - 1 (0: level0; else its ring), row y of level j (m: B, or
      // the delay).
      const RowSource<T> in = j == 1 ? level0 : RowSource<T>{base[j - 1], rs, cap[j - 1]};
      T* out = j < m   ? base[j] + static_cast<std::size_t>(y % cap[j]) * rs
               : C > 0 ? delay + static_cast<std::size_t>(y % C) * rs
                       : B + static_cast<std::size_t>(y) * rs;
      row(j - 1, y, in, out);
    }
    // Row v - r_1 is read by no later step: its new value goes in.
    if (C > 0 && v - g.r[1] >= Y0 && v - g.r[1] < Y1) flush(v - g.r[1]);
  }
  if (C > 0)
    for (int y = std::max(Y0, v1 - g.r[1] + 1); y < Y1; ++y) flush(y);
}

// Rows of the neighbouring bands that one thread copies at most, for a
// group of this halo (none when one thread's band is the whole image).
inline std::size_t band_copy_rows(int halo, int H, int threads) {
  return threads > 1 ? 2 * static_cast<std::size_t>(std::min(H, halo)) : 0;
}

// Per-thread scratch of a schedule, in rows (W x the channels values): the rings of
// the largest group, the copies of neighbouring bands' rows and the delay
// of the largest in-place group; and whether some group runs ping-pong.
struct ScratchPlan {
  std::size_t ring_rows = 0, copy_rows = 0;  // copy_rows: copies and delay of one group
  std::vector<char> in_place;                // per group
  bool partner = false;
  std::size_t rows_per_thread() const { return ring_rows + copy_rows; }
};
inline ScratchPlan plan_scratch(const Radii& radii, const std::vector<FusedGroup>& groups, int H, int threads) {
  ScratchPlan s;
  for (const FusedGroup& fg : groups) {
    const int* r = &radii[static_cast<std::size_t>(fg.k0)];
    const GroupShape g(r, fg.m);
    s.ring_rows = std::max(s.ring_rows, fused_ring_rows(r, fg.m));
    // One thread's band is the image: nothing to copy. Else each thread
    // copies up to the halo on each side. In place while every thread's
    // copies and delay together stay within half the image (so that the
    // extra heap stays below the partner's; a copy costs a fraction of an
    // iteration's row).
    const std::size_t halo = band_copy_rows(g.halo(), H, threads);
    const std::size_t delay = static_cast<std::size_t>(g.delay());
    const bool ip = (halo + delay) * static_cast<std::size_t>(threads) * 2 <= static_cast<std::size_t>(H);
    s.in_place.push_back(ip);
    if (ip) {
      s.copy_rows = std::max(s.copy_rows, halo + delay);
    } else {
      s.partner = true;
    }
  }
  // Once a partner is needed, every group uses it: the copies would only
  // add to its heap (many threads: 16 at 1600 x 1120 would keep 2.2x the
  // image instead of the ping-pong schedule's 1.3x + rings).
  if (s.partner) {
    std::fill(s.in_place.begin(), s.in_place.end(), 0);
    s.copy_rows = 0;
  }
  return s;
}

// N iterations of F in `img` (W x H x channels, 4 but for the constant
// scale's 3-channel rows), grouped by plan_fusion, each
// group in place or, where plan_scratch says so, from img into `partner`
// (then the two swap); returns the buffer holding the result (img unless a
// ping-pong group left it in partner). scratch: fusion_scratch_values(...)
// values; partner: an image's values where plan_scratch(...).partner, else
// unused (may be null). row(k, y, in, out): iteration k writes row y to
// `out`, reading the previous level through in(q) (see fused_group_band).
// Called from inside OpenMP parallel regions (omp_get_thread_num() names
// the calling thread's scratch). Each thread's band of a fused group
// overlaps its neighbours' by the group's halo, so rows there are computed
// twice, from the same inputs, with the same bits; every row of every level
// is computed by the same row function from the same input rows as one
// pass per iteration from one image into another, whatever the thread
// count, band, group or buffer (tests: DiffusionFusion.*).
template <class T, class LevelRow>
T* iterations_fused(T* img, T* partner, int W, int H, const Radii& radii, const std::vector<FusedGroup>& groups,
                    int threads, T* scratch, LevelRow row, int channels = 4) {
  const std::size_t rs = static_cast<std::size_t>(W) * static_cast<std::size_t>(channels);  // values per row
  const ScratchPlan plan = plan_scratch(radii, groups, H, threads);
  const std::size_t per_thread = plan.rows_per_thread() * rs;
  // Level 0's row table of each thread (in-place groups).
  std::vector<const T*> tables(static_cast<std::size_t>(threads) * static_cast<std::size_t>(H));
  T* cur = img;
  T* other = partner;
  for (std::size_t gi = 0; gi < groups.size(); ++gi) {
    const FusedGroup& fg = groups[gi];
    const int* radii_g = &radii[static_cast<std::size_t>(fg.k0)];
    const bool in_place = plan.in_place[gi];
    if (!in_place && fg.m == 1) {
      const RowSource<T> in{cur, rs, 0};
#pragma omp parallel for num_threads(threads) schedule(dynamic, kRowChunk)
      for (int y = 0; y < H; ++y) row(fg.k0, y, in, other + y * rs);
      std::swap(cur, other);
      continue;
    }
    const int halo = GroupShape(radii_g, fg.m).halo();
#pragma omp parallel num_threads(threads)
    {
      const int t = omp_get_thread_num(), nt = omp_get_num_threads();
      const int Y0 = static_cast<int>(static_cast<long long>(H) * t / nt);
      const int Y1 = static_cast<int>(static_cast<long long>(H) * (t + 1) / nt);
      T* ring = scratch + static_cast<std::size_t>(t) * per_thread;
      T* copies = ring + plan.ring_rows * rs;  // then the delay
      auto level_row = [&](int j, int y, const RowSource<T>& in, T* out) { row(fg.k0 + j, y, in, out); };
      if (!in_place) {
        if (Y0 < Y1)
          fused_group_band(RowSource<T>{cur, rs, 0}, other, rs, H, radii_g, fg.m, Y0, Y1, ring,
                           static_cast<T*>(nullptr), level_row);
      } else {
        // Level 1 reads rows [a, b); those of the neighbouring bands are
        // copied before any thread writes its own.
        const T** table = tables.data() + static_cast<std::size_t>(t) * static_cast<std::size_t>(H);
        const int a = std::max(0, Y0 - halo), b = std::min(H, Y1 + halo);
        if (Y0 < Y1) {
          T* c = copies;
          for (int q = a; q < b; ++q) {
            if (q >= Y0 && q < Y1) {
              table[q] = cur + static_cast<std::size_t>(q) * rs;
            } else {
              std::memcpy(c, cur + static_cast<std::size_t>(q) * rs, rs * sizeof(T));
              table[q] = c;
              c += rs;
            }
          }
        }
#pragma omp barrier
        if (Y0 < Y1)
          fused_group_band(RowSource<T>{cur, rs, 0, table}, cur, rs, H, radii_g, fg.m, Y0, Y1, ring,
                           copies + band_copy_rows(halo, H, threads) * rs, level_row);
      }
    }
    if (!in_place) std::swap(cur, other);
  }
  return cur;
}

// Values of scratch that iterations_fused needs.
inline std::size_t fusion_scratch_values(const Radii& radii, const std::vector<FusedGroup>& groups, int W, int H,
                                         int threads, int channels = 4) {
  return plan_scratch(radii, groups, H, threads).rows_per_thread() * static_cast<std::size_t>(W) *
         static_cast<std::size_t>(channels) * static_cast<std::size_t>(threads);
}
// Whether iterations_fused needs its partner image.
inline bool fusion_needs_partner(const Radii& radii, const std::vector<FusedGroup>& groups, int H, int threads) {
  return plan_scratch(radii, groups, H, threads).partner;
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
T* uniform_iterations_fused(T* img, T* partner, int W, int H, const std::vector<UniformStep>& st,
                            const std::vector<FusedGroup>& groups, int threads, T* scratch, Row5 row5,
                            int channels = 4) {
  return iterations_fused(img, partner, W, H, uniform_radii(st), groups, threads, scratch,
                          [&](int k, int y, const RowSource<T>& in, T* out) {
                            const UniformStep& s = st[static_cast<std::size_t>(k)];
                            const int n = s.n;
                            row5(in(y), in(mirror(y - n, H)), in(mirror(y - n - 1, H)), in(mirror(y + n, H)),
                                 in(mirror(y + n + 1, H)), out, s);
                          },
                          channels);
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
