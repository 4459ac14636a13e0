// brume — the row kernels of the fast CPU diffusion path: one row of one
// iteration of eq. 11 (with eq. 12's edge weights), each compiled at three
// vector widths, and the pick of a width (row_kernels). The schedule that
// runs them over rows, iterations and threads is diffusion_fast.cpp; the
// per-pixel formulas they share with it and with the binary16 rows are
// diffusion_rows.hpp.
//
//  - F is interleaved RGBA float, so a pixel is one 128-bit vector and the
//    channel loops vectorise -- or, for an RGB image in f32, interleaved RGB
//    (rows of three values a pixel: the constant row is a loop over values,
//    and the space-variant run kernels have RGB forms, run_rgb_*);
//  - a constant rate makes every offset and weight of an iteration equal,
//    and the interior of each row is then a contiguous 5-tap loop over floats
//    that the compiler vectorises (uniform_row; AVX2 clone). It performs the
//    same arithmetic in the same order as the general path, so it gives the
//    same bits;
//  - a space-variant scale splits each row into runs of pixels whose offsets
//    share their integer part; inside the image a run's rate samples, edge
//    weights and taps are contiguous, so they are computed by vector loops
//    (about 1.9x faster than per-pixel gathers on a haze map), and only the
//    pixels whose taps need the mirror take the per-pixel path
//    (general_row_body). The row's offsets come from sigma_k formed as a
//    running product sigma_0 e^{rho} ... e^{rho} (multiplies instead of an
//    exp per pixel and iteration; relative drift < 1e-6 after 13 steps,
//    covered by the fast-vs-reference test), per row and chunk from the
//    growth map rather than kept in a map (row_offsets);
//  - the conductance stencil (the standard scheme once its edge weights are
//    formed; also the public per-edge path) is a row of fixed weights
//    (standard_row).
// Every width evaluates the same elementwise operations in the same order
// (ISO C++, no reassociation, no contraction: -ffp-contract=off on this file
// in CMakeLists.txt), so all give the same bits (test: DiffusionSimd).
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <vector>

#include "diffusion/diffusion_rows.hpp"

#if defined(__x86_64__)
#include <immintrin.h>
#endif

// GCC 12's AVX-512 intrinsics pass _mm512_undefined_ps() (`__m512 __Y = __Y;`)
// as the unused pass-through of their unmasked forms (_mm512_permutexvar_ps,
// _mm512_min_ps, _mm512_broadcast_f32x4), and -Wmaybe-uninitialized reports
// it once per inlining of the row kernels: a false positive (no lane of it
// is ever read), silenced for the row kernels only (push ... pop below).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

namespace brume::cpu {

namespace {

// Interior of a row when every pixel has the same offset h = n + fr and the
// same rate w (so every eq. 12 weight is w): a contiguous loop over floats,
// compiled for 128-bit vectors and for AVX2 (the same elementwise operations
// in the same order in each, hence the same bits; why not AVX-512: row_kernels).
// px: values per pixel (4, or 3 for RGB without alpha), n4 = n px: the
// loop is the same for any channel count.
#define BRUME_UNIFORM_ROW_ARGS                                                                      \
  const float *__restrict s, const float *__restrict u0, const float *__restrict u1,               \
      const float *__restrict d0, const float *__restrict d1, float *__restrict o, std::size_t begin, \
      std::size_t end, std::ptrdiff_t n4, std::ptrdiff_t px, float fr, float w
__attribute__((always_inline)) inline void uniform_row_body(BRUME_UNIFORM_ROW_ARGS) {
  for (std::size_t i = begin; i < end; ++i) {
    const float fc = s[i];
    const float l = s[i - n4] + fr * (s[i - n4 - px] - s[i - n4]);
    const float r = s[i + n4] + fr * (s[i + n4 + px] - s[i + n4]);
    const float u = u0[i] + fr * (u1[i] - u0[i]);
    const float d = d0[i] + fr * (d1[i] - d0[i]);
    o[i] = brume_diffusion_update(fc, l, r, u, d, w, w, w, w);
  }
}
#define BRUME_UNIFORM_ROW_CALL uniform_row_body(s, u0, u1, d0, d1, o, begin, end, n4, px, fr, w)
void uniform_row_generic(BRUME_UNIFORM_ROW_ARGS) { BRUME_UNIFORM_ROW_CALL; }
#if defined(__x86_64__)
__attribute__((target("avx2"))) void uniform_row_avx2(BRUME_UNIFORM_ROW_ARGS) { BRUME_UNIFORM_ROW_CALL; }
#endif
#undef BRUME_UNIFORM_ROW_CALL
#undef BRUME_UNIFORM_ROW_ARGS

// Eq. 12 weights of the pixels [xa, xb) of a run that shares the integer
// offset n, with every tap inside the image: the rate samples are then
// contiguous loads, and the loop vectorises. Same arithmetic as update_pixel.
template <int kMode>
__attribute__((always_inline)) inline void run_weights(const float* __restrict rrow, const float* __restrict ru0,
                                                       const float* __restrict ru1, const float* __restrict rd0,
                                                       const float* __restrict rd1, const float* __restrict fr,
                                                       float* __restrict wl, float* __restrict wr,
                                                       float* __restrict wu, float* __restrict wd, int xa, int xb,
                                                       int n) {
  for (int x = xa; x < xb; ++x) {
    const float rc = rrow[x], f = fr[x];
    wl[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[x - n], rrow[x - n - 1], f, kMode), kMode);
    wr[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[x + n], rrow[x + n + 1], f, kMode), kMode);
    wu[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(ru0[x], ru1[x], f, kMode), kMode);
    wd[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(rd0[x], rd1[x], f, kMode), kMode);
  }
}

// Eq. 11 for the pixels [xa, xb) of such a run: the taps x -+ n, x -+ (n+1)
// and the rows y -+ n, y -+ (n+1) are contiguous across the run. Three
// widths of the same arithmetic: one pixel per 128-bit vector (any CPU), two
// per AVX2 vector, four per AVX-512 vector. The wide ones broadcast each
// pixel's fraction and weights over its four lanes and then evaluate, lane
// by lane, exactly eq11's operations in eq11's order (sub, mul, add for the
// interpolation; brume_diffusion_update for the stencil; no contraction in
// ISO mode), so the three give the same bits (test: DiffusionSimd).
struct RunArgs {
  const float *s, *u0, *u1, *d0, *d1;  // rows y, y -+ n, y -+ (n+1) of F
  float* o;                            // row y of the output
  const float* fr;                     // per pixel of the row
  float *wl, *wr, *wu, *wd;            // per pixel of the row (scratch)
};
using RunUpdate = void (*)(const RunArgs&, int xa, int xb, int n);
// The rate map's rows y, y -+ n, y -+ (n+1) of a run (its eq. 12 weights).
struct RateRows {
  const float *c, *u0, *u1, *d0, *d1;
};
// A run's weights and update (three widths below).
using RunKernel = void (*)(const RunArgs&, const RateRows&, int edge_mode, int xa, int xb, int n);

inline void run_update_v4(const RunArgs& a, int xa, int xb, int n) {
  const std::ptrdiff_t n4 = static_cast<std::ptrdiff_t>(n) * 4;
  auto ld = [](const float* p) { return StoreF32::load(p); };
  for (int x = xa; x < xb; ++x) {
    const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * 4;
    StoreF32::store(a.o + i, eq11(ld(a.s + i), ld(a.s + i - n4), ld(a.s + i - n4 - 4), ld(a.s + i + n4),
                                  ld(a.s + i + n4 + 4), ld(a.u0 + i), ld(a.u1 + i), ld(a.d0 + i), ld(a.d1 + i),
                                  a.fr[x], a.wl[x], a.wr[x], a.wu[x], a.wd[x]));
  }
}

void run_update_generic(const RunArgs& a, int xa, int xb, int n) { run_update_v4(a, xa, xb, n); }

// A run's weights (run_weights, into the scratch rows) and then its update:
// the run kernel of the 128-bit and AVX2 rows (the AVX-512 rows fuse the two,
// run_fused_avx512).
template <RunUpdate kUpdate>
__attribute__((always_inline)) inline void weights_then_update(const RunArgs& a, const RateRows& q, int edge_mode,
                                                               int xa, int xb, int n) {
  switch (edge_mode) {
    case 1: run_weights<1>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, xa, xb, n); break;
    case 2: run_weights<2>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, xa, xb, n); break;
    default: run_weights<0>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, xa, xb, n); break;
  }
  kUpdate(a, xa, xb, n);
}
void run_generic(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb, int n) {
  weights_then_update<run_update_generic>(a, q, edge_mode, xa, xb, n);
}

// The same run on RGB rows (three values a pixel, no fourth channel to
// carry: the space-variant blur of an RGB image in f32). Value by value,
// eq11's operations in eq11's order (the interpolation, then
// brume_diffusion_update), with the pixel's fraction and weights: each value
// gets the bits the same channel of an RGBA pixel gets (test:
// DiffusionChannels.RgbRowsGiveTheRgbaBits). One value at a time here and for
// the last pixels of the wider kernels.
inline void run_update_rgb_values(const RunArgs& a, int xa, int xb, int n) {
  const std::ptrdiff_t n3 = static_cast<std::ptrdiff_t>(n) * 3;
  for (int x = xa; x < xb; ++x) {
    const std::ptrdiff_t i0 = static_cast<std::ptrdiff_t>(x) * 3;
    const float f = a.fr[x], wl = a.wl[x], wr = a.wr[x], wu = a.wu[x], wd = a.wd[x];
    for (std::ptrdiff_t i = i0; i < i0 + 3; ++i) {
      const float fc = a.s[i];
      const float l = a.s[i - n3] + f * (a.s[i - n3 - 3] - a.s[i - n3]);
      const float r = a.s[i + n3] + f * (a.s[i + n3 + 3] - a.s[i + n3]);
      const float u = a.u0[i] + f * (a.u1[i] - a.u0[i]);
      const float d = a.d0[i] + f * (a.d1[i] - a.d0[i]);
      a.o[i] = brume_diffusion_update(fc, l, r, u, d, wl, wr, wu, wd);
    }
  }
}
void run_rgb_generic(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb, int n) {
  weights_then_update<run_update_rgb_values>(a, q, edge_mode, xa, xb, n);
}

#if defined(__x86_64__)
// (Lambdas would not inherit the target attribute: helpers instead.)
#define BRUME_AVX2 __attribute__((target("avx2"), always_inline)) inline
#define BRUME_AVX512 __attribute__((target("avx512f"), always_inline)) inline
// Two consecutive per-pixel values, each over its pixel's four lanes.
BRUME_AVX2 __m256 bc2(const float* p) {
  const __m256i idx = _mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1);
  return _mm256_permutevar8x32_ps(_mm256_castps128_ps256(_mm_castpd_ps(_mm_load_sd(reinterpret_cast<const double*>(p)))),
                                  idx);
}
BRUME_AVX2 __m256 lerp2(__m256 p0, __m256 p1, __m256 f) { return p0 + f * (p1 - p0); }
// Four consecutive per-pixel values, each over its pixel's four lanes.
BRUME_AVX512 __m512 bc4(const float* p) {
  const __m512i idx = _mm512_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3);
  return _mm512_permutexvar_ps(idx, _mm512_broadcast_f32x4(_mm_loadu_ps(p)));
}
BRUME_AVX512 __m512 lerp4(__m512 p0, __m512 p1, __m512 f) { return p0 + f * (p1 - p0); }

__attribute__((target("avx2"))) void run_update_avx2(const RunArgs& a, int xa, int xb, int n) {
  const std::ptrdiff_t n4 = static_cast<std::ptrdiff_t>(n) * 4;
  int x = xa;
  for (; x + 2 <= xb; x += 2) {
    const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * 4;
    const __m256 f = bc2(a.fr + x);
    const __m256 fc = _mm256_loadu_ps(a.s + i);
    const __m256 l = lerp2(_mm256_loadu_ps(a.s + i - n4), _mm256_loadu_ps(a.s + i - n4 - 4), f);
    const __m256 r = lerp2(_mm256_loadu_ps(a.s + i + n4), _mm256_loadu_ps(a.s + i + n4 + 4), f);
    const __m256 u = lerp2(_mm256_loadu_ps(a.u0 + i), _mm256_loadu_ps(a.u1 + i), f);
    const __m256 d = lerp2(_mm256_loadu_ps(a.d0 + i), _mm256_loadu_ps(a.d1 + i), f);
    const __m256 wl = bc2(a.wl + x), wr = bc2(a.wr + x), wu = bc2(a.wu + x), wd = bc2(a.wd + x);
    _mm256_storeu_ps(a.o + i, fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc));
  }
  run_update_v4(a, x, xb, n);
}

__attribute__((target("avx2"))) void run_avx2(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb,
                                              int n) {
  weights_then_update<run_update_avx2>(a, q, edge_mode, xa, xb, n);
}

__attribute__((target("avx512f"))) void run_update_avx512(const RunArgs& a, int xa, int xb, int n) {
  const std::ptrdiff_t n4 = static_cast<std::ptrdiff_t>(n) * 4;
  int x = xa;
  for (; x + 4 <= xb; x += 4) {
    const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * 4;
    const __m512 f = bc4(a.fr + x);
    const __m512 fc = _mm512_loadu_ps(a.s + i);
    const __m512 l = lerp4(_mm512_loadu_ps(a.s + i - n4), _mm512_loadu_ps(a.s + i - n4 - 4), f);
    const __m512 r = lerp4(_mm512_loadu_ps(a.s + i + n4), _mm512_loadu_ps(a.s + i + n4 + 4), f);
    const __m512 u = lerp4(_mm512_loadu_ps(a.u0 + i), _mm512_loadu_ps(a.u1 + i), f);
    const __m512 d = lerp4(_mm512_loadu_ps(a.d0 + i), _mm512_loadu_ps(a.d1 + i), f);
    const __m512 wl = bc4(a.wl + x), wr = bc4(a.wr + x), wu = bc4(a.wu + x), wd = bc4(a.wd + x);
    _mm512_storeu_ps(a.o + i, fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc));
  }
  run_update_v4(a, x, xb, n);
}

// The AVX-512 run: sixteen pixels' eq. 12 weights in four registers (the
// rate taps are contiguous loads, as in run_weights), then their update four
// pixels at a time, each pixel's fraction and weights permuted over its four
// lanes from those registers -- no round trip of the weights through the
// scratch rows, whose 4 x W floats, with the offsets and F's rows, outgrew
// L1 at W = 1600. tap16 and edge16 are brume_tap_rate and brume_edge_rate
// lane by lane, operation for operation (min(a, b) is b < a ? b : a, which
// is _mm512_min_ps(b, a); max(a, b) is a < b ? b : a, _mm512_max_ps(a, b) for
// the finite values here), so the weights, and the pixels, keep their bits
// (test: DiffusionSimd). The last < 16 pixels take run_weights and
// run_update_avx512.
template <int kMode>
BRUME_AVX512 __m512 tap16(__m512 r0, __m512 r1, __m512 f) {
  if constexpr (kMode == 0) return r0 + f * (r1 - r0);
  return _mm512_mask_blend_ps(_mm512_cmp_ps_mask(f, _mm512_setzero_ps(), _CMP_GT_OQ), r0, _mm512_min_ps(r1, r0));
}
template <int kMode>
BRUME_AVX512 __m512 edge16(__m512 rc, __m512 rn) {
  if constexpr (kMode == 1) return _mm512_min_ps(rn, rc);
  if constexpr (kMode == 2) return _mm512_set1_ps(2.0f) * rc * rn / _mm512_max_ps(rc + rn, _mm512_set1_ps(1.0e-30f));
  return _mm512_set1_ps(0.5f) * (rc + rn);
}
// One direction's weights of sixteen pixels: centre rates rc, the tap's
// two texels' rates at r0 and r1, fractions f.
template <int kMode>
BRUME_AVX512 __m512 weight16(__m512 rc, const float* r0, const float* r1, __m512 f) {
  return edge16<kMode>(rc, tap16<kMode>(_mm512_loadu_ps(r0), _mm512_loadu_ps(r1), f));
}
template <int kMode>
__attribute__((target("avx512f"))) void run_fused_avx512_mode(const RunArgs& a, const RateRows& q, int xa, int xb,
                                                              int n) {
  const std::ptrdiff_t n4 = static_cast<std::ptrdiff_t>(n) * 4;
  const __m512i lanes[4] = {_mm512_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3),
                            _mm512_setr_epi32(4, 4, 4, 4, 5, 5, 5, 5, 6, 6, 6, 6, 7, 7, 7, 7),
                            _mm512_setr_epi32(8, 8, 8, 8, 9, 9, 9, 9, 10, 10, 10, 10, 11, 11, 11, 11),
                            _mm512_setr_epi32(12, 12, 12, 12, 13, 13, 13, 13, 14, 14, 14, 14, 15, 15, 15, 15)};
  int x = xa;
  for (; x + 16 <= xb; x += 16) {
    const __m512 f16 = _mm512_loadu_ps(a.fr + x), rc = _mm512_loadu_ps(q.c + x);
    const __m512 wl16 = weight16<kMode>(rc, q.c + x - n, q.c + x - n - 1, f16);
    const __m512 wr16 = weight16<kMode>(rc, q.c + x + n, q.c + x + n + 1, f16);
    const __m512 wu16 = weight16<kMode>(rc, q.u0 + x, q.u1 + x, f16);
    const __m512 wd16 = weight16<kMode>(rc, q.d0 + x, q.d1 + x, f16);
    for (int j = 0; j < 4; ++j) {
      const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x + 4 * j) * 4;
      const __m512 f = _mm512_permutexvar_ps(lanes[j], f16);
      const __m512 fc = _mm512_loadu_ps(a.s + i);
      const __m512 l = lerp4(_mm512_loadu_ps(a.s + i - n4), _mm512_loadu_ps(a.s + i - n4 - 4), f);
      const __m512 r = lerp4(_mm512_loadu_ps(a.s + i + n4), _mm512_loadu_ps(a.s + i + n4 + 4), f);
      const __m512 u = lerp4(_mm512_loadu_ps(a.u0 + i), _mm512_loadu_ps(a.u1 + i), f);
      const __m512 d = lerp4(_mm512_loadu_ps(a.d0 + i), _mm512_loadu_ps(a.d1 + i), f);
      const __m512 wl = _mm512_permutexvar_ps(lanes[j], wl16), wr = _mm512_permutexvar_ps(lanes[j], wr16);
      const __m512 wu = _mm512_permutexvar_ps(lanes[j], wu16), wd = _mm512_permutexvar_ps(lanes[j], wd16);
      _mm512_storeu_ps(a.o + i, fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc));
    }
  }
  if (x < xb) {
    run_weights<kMode>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, x, xb, n);
    run_update_avx512(a, x, xb, n);
  }
}
__attribute__((target("avx512f"))) void run_fused_avx512(const RunArgs& a, const RateRows& q, int edge_mode, int xa,
                                                         int xb, int n) {
  switch (edge_mode) {
    case 1: run_fused_avx512_mode<1>(a, q, xa, xb, n); break;
    case 2: run_fused_avx512_mode<2>(a, q, xa, xb, n); break;
    default: run_fused_avx512_mode<0>(a, q, xa, xb, n); break;
  }
}

// RGB rows (run_update_rgb_values' arithmetic) at AVX2 width: eight pixels
// are 24 values, three 256-bit vectors, and each value lane takes its
// pixel's fraction and weights by one permute of the eight pixels' values
// (pixel (8 j + l) / 3 for lane l of vector j): the broadcast that the RGBA
// rows do over four lanes, with no lane spent on an alpha.
__attribute__((target("avx2"))) void run_update_rgb_avx2(const RunArgs& a, int xa, int xb, int n) {
  const std::ptrdiff_t n3 = static_cast<std::ptrdiff_t>(n) * 3;
  const __m256i lanes[3] = {_mm256_setr_epi32(0, 0, 0, 1, 1, 1, 2, 2), _mm256_setr_epi32(2, 3, 3, 3, 4, 4, 4, 5),
                            _mm256_setr_epi32(5, 5, 6, 6, 6, 7, 7, 7)};
  int x = xa;
  for (; x + 8 <= xb; x += 8) {
    const __m256 f8 = _mm256_loadu_ps(a.fr + x);
    const __m256 wl8 = _mm256_loadu_ps(a.wl + x), wr8 = _mm256_loadu_ps(a.wr + x);
    const __m256 wu8 = _mm256_loadu_ps(a.wu + x), wd8 = _mm256_loadu_ps(a.wd + x);
    for (int j = 0; j < 3; ++j) {
      const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * 3 + 8 * j;
      const __m256 f = _mm256_permutevar8x32_ps(f8, lanes[j]);
      const __m256 fc = _mm256_loadu_ps(a.s + i);
      const __m256 l = lerp2(_mm256_loadu_ps(a.s + i - n3), _mm256_loadu_ps(a.s + i - n3 - 3), f);
      const __m256 r = lerp2(_mm256_loadu_ps(a.s + i + n3), _mm256_loadu_ps(a.s + i + n3 + 3), f);
      const __m256 u = lerp2(_mm256_loadu_ps(a.u0 + i), _mm256_loadu_ps(a.u1 + i), f);
      const __m256 d = lerp2(_mm256_loadu_ps(a.d0 + i), _mm256_loadu_ps(a.d1 + i), f);
      const __m256 wl = _mm256_permutevar8x32_ps(wl8, lanes[j]), wr = _mm256_permutevar8x32_ps(wr8, lanes[j]);
      const __m256 wu = _mm256_permutevar8x32_ps(wu8, lanes[j]), wd = _mm256_permutevar8x32_ps(wd8, lanes[j]);
      _mm256_storeu_ps(a.o + i, fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc));
    }
  }
  run_update_rgb_values(a, x, xb, n);
}
__attribute__((target("avx2"))) void run_rgb_avx2(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb,
                                                  int n) {
  weights_then_update<run_update_rgb_avx2>(a, q, edge_mode, xa, xb, n);
}

// RGB rows at AVX-512 width, the weights in registers as run_fused_avx512:
// sixteen pixels' fractions and eq. 12 weights (weight16), then their 48
// values as three 512-bit vectors, lane l of vector j taking pixel
// (16 j + l) / 3's by one permute. The last < 16 pixels of a run take the
// same code under masks (masked-off lanes are neither loaded nor stored), so
// short runs -- a real haze map splits its rows into many -- stay vectorised.
// Masked forms of weight16 and lerp4 (lanes outside the mask read as 0).
template <int kMode>
BRUME_AVX512 __m512 weight16m(__mmask16 m, __m512 rc, const float* r0, const float* r1, __m512 f) {
  return edge16<kMode>(rc, tap16<kMode>(_mm512_maskz_loadu_ps(m, r0), _mm512_maskz_loadu_ps(m, r1), f));
}
BRUME_AVX512 __m512 lerp4m(__mmask16 m, const float* p0, const float* p1, __m512 f) {
  return lerp4(_mm512_maskz_loadu_ps(m, p0), _mm512_maskz_loadu_ps(m, p1), f);
}
template <int kMode>
__attribute__((target("avx512f"))) void run_rgb_avx512_mode(const RunArgs& a, const RateRows& q, int xa, int xb,
                                                            int n) {
  const std::ptrdiff_t n3 = static_cast<std::ptrdiff_t>(n) * 3;
  const __m512i lanes[3] = {_mm512_setr_epi32(0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5),
                            _mm512_setr_epi32(5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 9, 9, 9, 10, 10),
                            _mm512_setr_epi32(10, 11, 11, 11, 12, 12, 12, 13, 13, 13, 14, 14, 14, 15, 15, 15)};
  for (int x = xa; x < xb; x += 16) {
    const int m = std::min(16, xb - x);                             // pixels
    const __mmask16 pm = static_cast<__mmask16>((1u << m) - 1u);    // their lanes
    const __m512 f16 = _mm512_maskz_loadu_ps(pm, a.fr + x), rc = _mm512_maskz_loadu_ps(pm, q.c + x);
    const __m512 wl16 = weight16m<kMode>(pm, rc, q.c + x - n, q.c + x - n - 1, f16);
    const __m512 wr16 = weight16m<kMode>(pm, rc, q.c + x + n, q.c + x + n + 1, f16);
    const __m512 wu16 = weight16m<kMode>(pm, rc, q.u0 + x, q.u1 + x, f16);
    const __m512 wd16 = weight16m<kMode>(pm, rc, q.d0 + x, q.d1 + x, f16);
    for (int j = 0; j < 3; ++j) {
      const int values = 3 * m - 16 * j;  // of this vector
      if (values <= 0) break;
      const __mmask16 vm = static_cast<__mmask16>(values >= 16 ? 0xffffu : (1u << values) - 1u);
      const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * 3 + 16 * j;
      const __m512 f = _mm512_permutexvar_ps(lanes[j], f16);
      const __m512 fc = _mm512_maskz_loadu_ps(vm, a.s + i);
      const __m512 l = lerp4m(vm, a.s + i - n3, a.s + i - n3 - 3, f);
      const __m512 r = lerp4m(vm, a.s + i + n3, a.s + i + n3 + 3, f);
      const __m512 u = lerp4m(vm, a.u0 + i, a.u1 + i, f);
      const __m512 d = lerp4m(vm, a.d0 + i, a.d1 + i, f);
      const __m512 wl = _mm512_permutexvar_ps(lanes[j], wl16), wr = _mm512_permutexvar_ps(lanes[j], wr16);
      const __m512 wu = _mm512_permutexvar_ps(lanes[j], wu16), wd = _mm512_permutexvar_ps(lanes[j], wd16);
      _mm512_mask_storeu_ps(a.o + i, vm, fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc));
    }
  }
}
__attribute__((target("avx512f"))) void run_rgb_avx512(const RunArgs& a, const RateRows& q, int edge_mode, int xa,
                                                       int xb, int n) {
  switch (edge_mode) {
    case 1: run_rgb_avx512_mode<1>(a, q, xa, xb, n); break;
    case 2: run_rgb_avx512_mode<2>(a, q, xa, xb, n); break;
    default: run_rgb_avx512_mode<0>(a, q, xa, xb, n); break;
  }
}
#undef BRUME_AVX2
#undef BRUME_AVX512
#endif

// Offsets of a row at iteration k, their integer and fractional parts. The
// row's sigma_k is the running product sigma_0 e^rho e^rho ... (k factors
// growth = e^rho, in that order: the same float sequence as every path),
// formed here in L1-sized chunks rather than kept in a W x H map between
// iterations: k multiplies a pixel (at most N - 1, vectorised, in L1) take
// the place of reading and writing the map (a quarter of the RGBA image,
// streamed twice per iteration), the map's heap is saved, and a fused
// group's levels need no sigma of their own. The
// exact scheme's offset needs the variance ratio vr; the published one is
// sigma_k itself.
// The product is taken sixteen pixels per vector (GCC's vector extension: a
// zmm register in the AVX-512 row, four xmm in the generic one), four
// vectors at once, kept in registers through the k multiplies; written as k
// passes over the chunk, as before, each pass loaded and stored it again
// (GCC does not interchange the loops), and one vector at a time waits on
// each multiply's latency.
typedef float v16f __attribute__((vector_size(64)));
template <bool kExact>
__attribute__((always_inline)) inline void row_offsets(float* __restrict h, int* __restrict n, float* __restrict fr,
                                                       float s0, int k, const float* __restrict growth,
                                                       const float* __restrict vr, int W) {
  constexpr int kChunk = 256;
  float s[kChunk];
  for (int x0 = 0; x0 < W; x0 += kChunk) {
    const int c = std::min(kChunk, W - x0);
    const float* __restrict g = growth + x0;
    const v16f s0v = v16f{} + s0;  // s0 in every lane (0 + s0 is s0)
    int b = 0;
    for (; b + 64 <= c; b += 64) {  // four independent chains hide the multiply's latency
      v16f g0, g1, g2, g3;
      std::memcpy(&g0, g + b, sizeof g0);
      std::memcpy(&g1, g + b + 16, sizeof g1);
      std::memcpy(&g2, g + b + 32, sizeof g2);
      std::memcpy(&g3, g + b + 48, sizeof g3);
      v16f p0 = s0v, p1 = s0v, p2 = s0v, p3 = s0v;
      for (int i = 0; i < k; ++i) p0 = p0 * g0, p1 = p1 * g1, p2 = p2 * g2, p3 = p3 * g3;
      std::memcpy(s + b, &p0, sizeof p0);
      std::memcpy(s + b + 16, &p1, sizeof p1);
      std::memcpy(s + b + 32, &p2, sizeof p2);
      std::memcpy(s + b + 48, &p3, sizeof p3);
    }
    for (; b + 16 <= c; b += 16) {
      v16f g0;
      std::memcpy(&g0, g + b, sizeof g0);
      v16f p0 = s0v;
      for (int i = 0; i < k; ++i) p0 = p0 * g0;
      std::memcpy(s + b, &p0, sizeof p0);
    }
    for (; b < c; ++b) {
      float sb = s0;
      for (int i = 0; i < k; ++i) sb = sb * g[b];
      s[b] = sb;
    }
    for (int x = 0; x < c; ++x) {
      const float hx = kExact ? sh::brume_offset_for_moment(s[x] * s[x] * vr[x0 + x]) : s[x];
      h[x0 + x] = hx;
      n[x0 + x] = static_cast<int>(hx);
      fr[x0 + x] = hx - static_cast<float>(n[x0 + x]);
    }
  }
}

// First index e > x with n[e] != n[x] (or W): blocks of 16 compared without
// an early exit, then one at a time. GCC 12 compiles the block compare to 16
// scalar compares (8.6 % of the AVX-512 row in a profile), so the AVX2 and
// AVX-512 rows compare 8 or 16 lanes with one instruction (run_end_avx2,
// run_end_avx512; called once per run, not inlined); all three return the
// same index.
int run_end_generic(const int* __restrict n, int x, int W) {
  const int v = n[x];
  int e = x + 1;
  while (e + 16 <= W) {
    int differ = 0;
    for (int j = 0; j < 16; ++j) differ |= n[e + j] != v;
    if (differ) break;
    e += 16;
  }
  while (e < W && n[e] == v) ++e;
  return e;
}
using RunEnd = int (*)(const int* __restrict, int, int);
#if defined(__x86_64__)
__attribute__((target("avx2"))) int run_end_avx2(const int* __restrict n, int x, int W) {
  const __m256i v = _mm256_set1_epi32(n[x]);
  int e = x + 1;
  for (; e + 8 <= W; e += 8) {
    const __m256i eq = _mm256_cmpeq_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(n + e)), v);
    const unsigned differ = ~static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(eq))) & 0xffu;
    if (differ) return e + __builtin_ctz(differ);
  }
  while (e < W && n[e] == n[x]) ++e;
  return e;
}
__attribute__((target("avx512f"))) int run_end_avx512(const int* __restrict n, int x, int W) {
  const __m512i v = _mm512_set1_epi32(n[x]);
  int e = x + 1;
  for (; e + 16 <= W; e += 16) {
    const __mmask16 differ = _mm512_cmpneq_epi32_mask(_mm512_loadu_si512(n + e), v);
    if (differ) return e + __builtin_ctz(static_cast<unsigned>(differ));
  }
  while (e < W && n[e] == n[x]) ++e;
  return e;
}
#endif

// One row of the general invariant scheme: offsets from sigma_k (and, for the
// exact variant, the variance ratio), then the update. A space-variant map
// varies slowly almost everywhere, so the row splits into long runs of
// pixels whose offsets share their integer part; inside the image those are
// updated by contiguous vector loops, and only pixels whose taps need the
// mirror (near the borders) go through the general per-pixel update_pixel.
// Both evaluate the same formulas in the same order (ISO C++, no
// reassociation or contraction), so the split does not change results.
// Written once (always inlined) and compiled three times below, for the
// three widths of the run kernel (weights and update: run_generic, run_avx2,
// run_fused_avx512); the offset loops widen with them.
// F's rows come through a RowSource (the whole image, or a fused group's
// ring) and row y of the result goes to orow.
// C: values a pixel, 4 (RGBA) or 3 (RGB rows, with the RGB run kernels).
template <int C>
__attribute__((always_inline)) inline void general_row_body(const RowSource<float>& in, float* orow, const float* rho,
                                                            float s0, int k, const float* growth, const float* vr,
                                                            bool exact, int edge_mode, int W, int H, int y,
                                                            RowScratch& t, RunKernel run, RunEnd run_end) {
  float* h = t.h.data();
  if (exact)
    row_offsets<true>(h, t.n.data(), t.fr.data(), s0, k, growth, vr, W);
  else
    row_offsets<false>(h, t.n.data(), t.fr.data(), s0, k, growth, vr, W);
  const std::size_t Ws = static_cast<std::size_t>(W);
  for (int x = 0; x < W;) {
    const int n = t.n[x];
    const int e = run_end(t.n.data(), x, W);
    // Columns of the run whose horizontal taps stay inside the row. The
    // vertical taps are whole rows for the whole run (one n), mirrored when
    // they fall outside the image -- as update_pixel mirrors them (mirror is
    // the identity inside), so rows near the top and bottom take the vector
    // loops too, with the same bits (on a haze map those rows have the
    // largest offsets: up to 2 x 24 of 1120 rows went pixel by pixel).
    int a = std::max(x, n + 1), b = std::min(e, W - n - 1);
    if (a >= b) a = b = e;
    const std::size_t yu0 = static_cast<std::size_t>(mirror(y - n, H)), yu1 = static_cast<std::size_t>(mirror(y - n - 1, H));
    const std::size_t yd0 = static_cast<std::size_t>(mirror(y + n, H)), yd1 = static_cast<std::size_t>(mirror(y + n + 1, H));
    const float* rrow = rho + y * Ws;
    const RateRows q{rrow, rho + yu0 * Ws, rho + yu1 * Ws, rho + yd0 * Ws, rho + yd1 * Ws};
    const RunArgs args{in(y),        in(static_cast<int>(yu0)), in(static_cast<int>(yu1)), in(static_cast<int>(yd0)),
                       in(static_cast<int>(yd1)), orow,         t.fr.data(),              t.wl.data(),
                       t.wr.data(),  t.wu.data(),               t.wd.data()};
    // The columns [p, qe) whose horizontal taps (x -+ n, x -+ (n+1)) leave
    // the row: F's row and the rate row at the taps' columns p - n - 1 ..
    // qe + n, mirrored, are copied side by side, and the same run kernel
    // reads them through pointers shifted so that column c is copy entry
    // c - (p - n - 1) (formed as integers: the shifted base itself may lie
    // outside the copy, every access lands inside). Every tap and rate
    // sample is then the value pixel_from_rows reads at the mirrored index,
    // and the kernel evaluates its formulas in its order: the same bits
    // (test: DiffusionSimd.OneIterationIsThePerPixelFormula, offsets up to
    // several row widths), four to sixteen pixels a vector instead of one with
    // per-tap mirroring (the border columns, up to 2 (n + 1) a row, took 5 %
    // of a space-variant blur at sigma 25 one pixel at a time, and more in
    // the top band, whose offsets are the largest). A segment whose copy
    // would exceed the row by far (an offset of several row widths) keeps
    // the per-pixel path.
    auto border = [&](int p, int qe) {
      if (p >= qe) return;
      const std::size_t len = static_cast<std::size_t>(qe - p) + 2 * static_cast<std::size_t>(n) + 2;
      if (len > 2 * Ws + 64) {
        for (int i = p; i < qe; ++i) {
          if constexpr (C == 4)
            pixel_from_rows<false>(in, orow, rho, 0.0f, W, H, i, y, h[i], edge_mode);
          else
            pixel_values_from_rows(in, orow, rho, W, H, i, y, h[i], edge_mode, C);
        }
        return;
      }
      if (t.rpad.size() < len) t.fpad.resize(C * len), t.rpad.resize(len);
      const float* s = args.s;
      for (std::size_t j = 0; j < len; ++j) {
        const int col = mirror(p - n - 1 + static_cast<int>(j), W);
        std::memcpy(t.fpad.data() + C * j, s + static_cast<std::size_t>(col) * C, C * sizeof(float));
        t.rpad[j] = rrow[col];
      }
      const std::ptrdiff_t shift = static_cast<std::ptrdiff_t>(n) + 1 - p;  // column c -> entry c + shift
      auto shifted = [](const float* base, std::ptrdiff_t values) {
        return reinterpret_cast<const float*>(reinterpret_cast<std::uintptr_t>(base) +
                                              static_cast<std::uintptr_t>(values * static_cast<std::ptrdiff_t>(sizeof(float))));
      };
      RunArgs pa = args;
      pa.s = shifted(t.fpad.data(), shift * C);
      RateRows pq = q;
      pq.c = shifted(t.rpad.data(), shift);
      run(pa, pq, edge_mode, p, qe, n);
    };
    border(x, a);
    if (a < b) run(args, q, edge_mode, a, b, n);
    border(std::max(b, a), e);
    x = e;
  }
}

#define BRUME_GENERAL_ROW_ARGS                                                                              \
  const RowSource<float> &in, float *orow, const float *rho, float s0, int k, const float *growth,            \
      const float *vr, bool exact, int edge_mode, int W, int H, int y, RowScratch &t
#define BRUME_GENERAL_ROW_CALL(C, upd, end) \
  general_row_body<C>(in, orow, rho, s0, k, growth, vr, exact, edge_mode, W, H, y, t, upd, end)
void general_row_generic(BRUME_GENERAL_ROW_ARGS) { BRUME_GENERAL_ROW_CALL(4, run_generic, run_end_generic); }
void general_rgb_row_generic(BRUME_GENERAL_ROW_ARGS) { BRUME_GENERAL_ROW_CALL(3, run_rgb_generic, run_end_generic); }
#if defined(__x86_64__)
__attribute__((target("avx2"))) void general_row_avx2(BRUME_GENERAL_ROW_ARGS) {
  BRUME_GENERAL_ROW_CALL(4, run_avx2, run_end_avx2);
}
__attribute__((target("avx2"))) void general_rgb_row_avx2(BRUME_GENERAL_ROW_ARGS) {
  BRUME_GENERAL_ROW_CALL(3, run_rgb_avx2, run_end_avx2);
}
__attribute__((target("avx512f"))) void general_row_avx512(BRUME_GENERAL_ROW_ARGS) {
  BRUME_GENERAL_ROW_CALL(4, run_fused_avx512, run_end_avx512);
}
__attribute__((target("avx512f"))) void general_rgb_row_avx512(BRUME_GENERAL_ROW_ARGS) {
  BRUME_GENERAL_ROW_CALL(3, run_rgb_avx512, run_end_avx512);
}
#endif
#undef BRUME_GENERAL_ROW_CALL
#undef BRUME_GENERAL_ROW_ARGS
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// One row of the conductance stencil (the standard scheme once its edge
// rates are formed): wr[x] couples x and x+1 (0 at the last column: zero
// flux), wd couples rows. Three widths, as uniform_row.
#define BRUME_STANDARD_ROW_ARGS                                                                        \
  const float *__restrict s, const float *__restrict up, const float *__restrict dn,                  \
      const float *__restrict wr, const float *__restrict wd_up, const float *__restrict wd, float *__restrict o, \
      int W
__attribute__((always_inline)) inline void standard_row_body(BRUME_STANDARD_ROW_ARGS) {
  for (int x = 0; x < W; ++x) {
    const float wl = x > 0 ? wr[x - 1] : 0.0f;
    const int xl = x > 0 ? x - 1 : 0, xr = x < W - 1 ? x + 1 : x;
    const float a = wl, b = wr[x], c = wd_up[x], e = wd[x];
    for (int ch = 0; ch < 4; ++ch)
      o[x * 4 + ch] = brume_diffusion_update(s[x * 4 + ch], s[xl * 4 + ch], s[xr * 4 + ch], up[x * 4 + ch],
                                             dn[x * 4 + ch], a, b, c, e);
  }
}
#define BRUME_STANDARD_ROW_CALL standard_row_body(s, up, dn, wr, wd_up, wd, o, W)
void standard_row_generic(BRUME_STANDARD_ROW_ARGS) { BRUME_STANDARD_ROW_CALL; }
#if defined(__x86_64__)
__attribute__((target("avx2"))) void standard_row_avx2(BRUME_STANDARD_ROW_ARGS) { BRUME_STANDARD_ROW_CALL; }
__attribute__((target("avx512f"))) void standard_row_avx512(BRUME_STANDARD_ROW_ARGS) { BRUME_STANDARD_ROW_CALL; }
#endif
#undef BRUME_STANDARD_ROW_CALL
#undef BRUME_STANDARD_ROW_ARGS

std::atomic<int> g_simd_limit{-1};
int simd_available() {
#if defined(__x86_64__)
  static const int level = __builtin_cpu_supports("avx512f") ? 2 : __builtin_cpu_supports("avx2") ? 1 : 0;
  return level;
#else
  return 0;
#endif
}

}  // namespace

RowKernels row_kernels() {
  switch (diffusion_simd_level()) {
#if defined(__x86_64__)
    // The constant-scale rows stay at AVX2 on AVX-512 hosts: measured on an
    // AMD EPYC (Zen, 2 cores, 1600x1120, sigma 25) they take 1.3x longer with
    // 512-bit vectors (73-78 ms against 100-108 ms of CPU time per blur),
    // presumably because taps at offsets of n RGBA pixels (16n bytes) make
    // three in four 64-byte loads straddle two cache lines (one in four at 32
    // bytes). The space-variant rows gain from 512 bits (160 against 175 ms):
    // their per-pixel offsets and weights are arithmetic-bound. On Zen 5
    // (AMD EPYC family 26), with the workspace rows cache-line aligned, the
    // constant rows took the same time at either width (-3..+3 %, 2026-12-02).
    case 2: return {uniform_row_avx2, general_row_avx512, standard_row_avx512, general_rgb_row_avx512};
    case 1: return {uniform_row_avx2, general_row_avx2, standard_row_avx2, general_rgb_row_avx2};
#endif
    default: return {uniform_row_generic, general_row_generic, standard_row_generic, general_rgb_row_generic};
  }
}

int diffusion_simd_level() {
  const int limit = g_simd_limit.load(std::memory_order_relaxed);
  return limit < 0 ? simd_available() : std::min(limit, simd_available());
}
void set_diffusion_simd_limit(int level) { g_simd_limit.store(level, std::memory_order_relaxed); }

}  // namespace brume::cpu
