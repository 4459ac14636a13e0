// brume — the row kernels of the fast CPU diffusion path: one row of one
// iteration of eq. 11 (with eq. 12's edge weights), written once with
// Highway and compiled for every SIMD target (core/simd.hpp: the baseline
// fallback, SSE4, AVX2, AVX-512 on x86-64; NEON on aarch64, untested yet),
// beside the plain C++ reference rows every target is tested against; and
// the pick of the rows (row_kernels). The schedule that runs them over rows, iterations and
// threads is diffusion_fast.cpp; the per-pixel formulas they share with it
// and with the binary16 rows are diffusion_rows.hpp.
//
//  - F is interleaved RGBA float, so a pixel is four lanes -- or, for an RGB
//    image in f32, interleaved RGB (rows of three values a pixel: the
//    constant row is a loop over values, and the space-variant run kernels
//    have RGB forms: Run<3>);
//  - a constant rate makes every offset and weight of an iteration equal,
//    and the interior of each row is then a contiguous 5-tap loop over floats
//    (UniformRow). It performs the same arithmetic in the same order as the
//    general path, so it gives the same bits;
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
//    (standard_row_body, vectorised by the compiler for each target).
// Every target evaluates the same elementwise operations in the same order
// as the reference rows (ISO C++ and Highway's Mul, Add, Sub, Div: no
// reassociation, no contraction -- -ffp-contract=off on this file in
// cmake/brume_engine.cmake, as the AVX2 and AVX-512 targets enable FMA), so all give
// the same bits (test: DiffusionSimd).
//
// Layout (Highway's): the part before HWY_BEFORE_NAMESPACE is compiled once
// for the baseline (the reference rows and what every target shares, always
// inlined into the targets' rows); hwy/foreach_target.h includes this file
// again for each target, compiling the namespace HWY_NAMESPACE (N_AVX2, ...)
// with that target's instruction set; the HWY_ONCE part exports each
// target's table of rows (HWY_EXPORT) and picks one at run time.
#include "core/simd.hpp"  // first: the targets

#ifndef BRUME_DIFFUSION_FAST_KERNELS_SHARED
#define BRUME_DIFFUSION_FAST_KERNELS_SHARED
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <vector>

#include "diffusion/diffusion_rows.hpp"
#include "diffusion/diffusion_setup_rows.hpp"

namespace brume::cpu {
namespace {

// The reference rows (plain C++, compiled for the baseline; diffusion level 0,
// and the scalar tails of the targets' rows).

// Interior of a row when every pixel has the same offset h = n + fr and the
// same rate w (so every eq. 12 weight is w): a contiguous loop over floats.
// px: values per pixel (4, or 3 for RGB without alpha), n4 = n px: the loop
// is the same for any channel count.
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
void uniform_row_generic(BRUME_UNIFORM_ROW_ARGS) { uniform_row_body(s, u0, u1, d0, d1, o, begin, end, n4, px, fr, w); }

// Eq. 12 weights of the pixels [xa, xb) of a run that shares the integer
// offset n, with every tap inside the image: the rate samples are then
// contiguous loads. Same arithmetic as update_pixel.
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
// and the rows y -+ n, y -+ (n+1) are contiguous across the run.
struct RunArgs {
  const float *s, *u0, *u1, *d0, *d1;  // rows y, y -+ n, y -+ (n+1) of F
  float* o;                            // row y of the output
  const float* fr;                     // per pixel of the row
  float *wl, *wr, *wu, *wd;            // per pixel of the row (scratch)
};
// The rate map's rows y, y -+ n, y -+ (n+1) of a run (its eq. 12 weights).
struct RateRows {
  const float *c, *u0, *u1, *d0, *d1;
};
// A run's weights and update.
using RunKernel = void (*)(const RunArgs&, const RateRows&, int edge_mode, int xa, int xb, int n);

// One RGBA pixel per 128-bit vector (eq11: the interpolation, then the stencil update).
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

// The same run on RGB rows (three values a pixel, no fourth channel to
// carry: the space-variant blur of an RGB image in f32). Value by value,
// eq11's operations in eq11's order (the interpolation, then
// brume_diffusion_update), with the pixel's fraction and weights: each value
// gets the bits the same channel of an RGBA pixel gets (test:
// DiffusionChannels.RgbRowsGiveTheRgbaBits).
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

// A run's weights (run_weights, into the scratch rows) and then its update,
// pixel by pixel: the reference run kernels, and the last pixels of the
// targets' runs (kRgb: RGB rows).
template <bool kRgb>
__attribute__((always_inline)) inline void run_reference(const RunArgs& a, const RateRows& q, int edge_mode, int xa,
                                                         int xb, int n) {
  switch (edge_mode) {
    case 1: run_weights<1>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, xa, xb, n); break;
    case 2: run_weights<2>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, xa, xb, n); break;
    default: run_weights<0>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, xa, xb, n); break;
  }
  if constexpr (kRgb)
    run_update_rgb_values(a, xa, xb, n);
  else
    run_update_v4(a, xa, xb, n);
}
void run_generic(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb, int n) {
  run_reference<false>(a, q, edge_mode, xa, xb, n);
}
void run_rgb_generic(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb, int n) {
  run_reference<true>(a, q, edge_mode, xa, xb, n);
}

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
// The product is taken by `product` (sigma_products: the reference's
// sixteen pixels per GCC vector; each target's SigmaProducts: its own
// vectors), into an L1-sized chunk, then the chunk's offsets.
typedef float v16f __attribute__((vector_size(64)));
// s[0 .. c) = s0 g[0 .. c)^k, each lane's k multiplies in order (the
// reference: sixteen pixels per vector, four vectors at once, kept in
// registers through the k multiplies).
__attribute__((always_inline)) inline void sigma_products(float* __restrict s, const float* __restrict g, int c,
                                                          float s0, int k) {
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
}
template <bool kExact, class Product>
__attribute__((always_inline)) inline void row_offsets(float* __restrict h, int* __restrict n, float* __restrict fr,
                                                       float s0, int k, const float* __restrict growth,
                                                       const float* __restrict vr, int W, Product&& product) {
  constexpr int kChunk = 256;
  alignas(64) float s[kChunk];
  for (int x0 = 0; x0 < W; x0 += kChunk) {
    const int c = std::min(kChunk, W - x0);
    product(s, growth + x0, c, s0, k);
    for (int x = 0; x < c; ++x) {
      const float hx = kExact ? sh::brume_offset_for_moment(s[x] * s[x] * vr[x0 + x]) : s[x];
      h[x0 + x] = hx;
      n[x0 + x] = static_cast<int>(hx);
      fr[x0 + x] = hx - static_cast<float>(n[x0 + x]);
    }
  }
}

// First index e > x with n[e] != n[x] (or W): blocks of 16 compared without
// an early exit, then one at a time (the reference; the targets compare a
// vector of offsets with one instruction, RunEnd; all return the same index).
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

// One row of the general invariant scheme: offsets from sigma_k (and, for the
// exact variant, the variance ratio), then the update. A space-variant map
// varies slowly almost everywhere, so the row splits into long runs of
// pixels whose offsets share their integer part; inside the image those are
// updated by contiguous vector loops, and only pixels whose taps need the
// mirror (near the borders) go through the general per-pixel update_pixel.
// Both evaluate the same formulas in the same order (ISO C++, no
// reassociation or contraction), so the split does not change results.
// Written once (always inlined) into the reference row (run_generic,
// run_end_generic) and each target's (Run, RunEndOf); the
// offset loops widen with them.
// F's rows come through a RowSource (the whole image, or a fused group's
// ring) and row y of the result goes to orow.
// C: values a pixel, 4 (RGBA) or 3 (RGB rows, with the RGB run kernels).
template <int C, class Product>
__attribute__((always_inline)) inline void general_row_body(const RowSource<float>& in, float* orow, const float* rho,
                                                            float s0, int k, const float* growth, const float* vr,
                                                            bool exact, int edge_mode, int W, int H, int y,
                                                            RowScratch& t, RunKernel run, RunEnd run_end,
                                                            Product&& product) {
  float* h = t.h.data();
  if (exact)
    row_offsets<true>(h, t.n.data(), t.fr.data(), s0, k, growth, vr, W, product);
  else
    row_offsets<false>(h, t.n.data(), t.fr.data(), s0, k, growth, vr, W, product);
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

// One row of the conductance stencil (the standard scheme once its edge
// rates are formed): wr[x] couples x and x+1 (0 at the last column: zero
// flux), wd couples rows. Written once as plain C++; each target's copy
// (StandardRow) is this loop vectorised by the compiler for that target.
#define BRUME_STANDARD_ROW_ARGS                                                                        \
  const float *__restrict s, const float *__restrict up, const float *__restrict dn,                  \
      const float *__restrict wr, const float *__restrict wd_up, const float *__restrict wd, float *__restrict o, \
      int W
#define BRUME_STANDARD_ROW_CALL standard_row_body(s, up, dn, wr, wd_up, wd, o, W)
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
void standard_row_generic(BRUME_STANDARD_ROW_ARGS) { BRUME_STANDARD_ROW_CALL; }

#define BRUME_GENERAL_ROW_ARGS                                                                              \
  const RowSource<float> &in, float *orow, const float *rho, float s0, int k, const float *growth,            \
      const float *vr, bool exact, int edge_mode, int W, int H, int y, RowScratch &t
#define BRUME_GENERAL_ROW_CALL(C, upd, end, prod) \
  general_row_body<C>(in, orow, rho, s0, k, growth, vr, exact, edge_mode, W, H, y, t, upd, end, prod)
void general_row_generic(BRUME_GENERAL_ROW_ARGS) {
  BRUME_GENERAL_ROW_CALL(4, run_generic, run_end_generic, sigma_products);
}
void general_rgb_row_generic(BRUME_GENERAL_ROW_ARGS) {
  BRUME_GENERAL_ROW_CALL(3, run_rgb_generic, run_end_generic, sigma_products);
}
void rates_generic(const float* s, float* rho, std::size_t n, float s0, float Nf) {
  setup::rates_body(s, rho, n, s0, Nf);
}
void growth_generic(const float* rho, float* g, float* vr, std::size_t n) { setup::growth_body(rho, g, vr, n); }

}  // namespace
}  // namespace brume::cpu
#endif  // BRUME_DIFFUSION_FAST_KERNELS_SHARED

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "diffusion/diffusion_fast_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace brume::cpu {
namespace HWY_NAMESPACE {
namespace {
namespace hn = hwy::HWY_NAMESPACE;

// The prelude's min(a, b) = b < a ? b : a and max(a, b) = a < b ? b : a
// (src/shared/prelude_cpp.h), lane by lane. x86's minps(b, a) is b < a ? b : a
// and maxps(b, a) is b > a ? b : a, the same for every input (NaN and signed
// zeros included); elsewhere (NEON's fmin, EMU128) the comparison and select.
#undef BRUME_HWY_X86_MINMAX
#if HWY_TARGET == HWY_SSE4 || HWY_TARGET == HWY_SSSE3 || HWY_TARGET == HWY_AVX2 || HWY_TARGET == HWY_AVX3 || \
    HWY_TARGET == HWY_AVX3_DL
#define BRUME_HWY_X86_MINMAX 1
#endif
// kMax false: min(a, b); true: max(a, b).
template <bool kMax, class V>
HWY_INLINE V AsPrelude(V a, V b) {
#ifdef BRUME_HWY_X86_MINMAX
  return kMax ? hn::Max(b, a) : hn::Min(b, a);
#else
  return kMax ? hn::IfThenElse(hn::Lt(a, b), b, a) : hn::IfThenElse(hn::Lt(b, a), b, a);
#endif
}
// Masked tails (the last pixels of a run in the vector loop, under a lane
// mask) where a masked load and store never touch the lanes outside the
// mask: AVX-512's. Elsewhere the last pixels take the reference loop.
#undef BRUME_HWY_MASKED_TAIL
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
#define BRUME_HWY_MASKED_TAIL 1
#endif

// brume_diffusion_update's expression (diffusion_math.glsl), term by term
// in its order: the shared template, instantiated outside the target, cannot
// take this target's vectors. Highway's named operations throughout, not
// C++ operators, which SVE's sizeless vectors do not have (GCC 12):
// fc + wl (l - fc) + wr (r - fc) + wu (u - fc) + wd (d - fc).
template <class V>
HWY_INLINE V Stencil(V fc, V l, V r, V u, V d, V wl, V wr, V wu, V wd) {
  const V a = hn::Add(fc, hn::Mul(wl, hn::Sub(l, fc)));
  const V b = hn::Add(a, hn::Mul(wr, hn::Sub(r, fc)));
  const V c = hn::Add(b, hn::Mul(wu, hn::Sub(u, fc)));
  return hn::Add(c, hn::Mul(wd, hn::Sub(d, fc)));
}
// r0 + f (r1 - r0): mix, sub then mul then add.
template <class V>
HWY_INLINE V Lerp(V r0, V r1, V f) {
  return hn::Add(r0, hn::Mul(f, hn::Sub(r1, r0)));
}

// uniform_row_body with vectors of at most eight floats (the lanes are
// values, whatever the channel count), the remainder by the reference loop.
// Why not sixteen on AVX-512: taps at offsets of n RGBA pixels (16 n bytes)
// make three in four 64-byte loads straddle two cache lines (one in four at
// 32 bytes); measured 1.3x slower on a Zen 3-era AMD EPYC, the same time on
// Zen 5 (docs/performance.md).
void UniformRow(BRUME_UNIFORM_ROW_ARGS) {
  const hn::CappedTag<float, 8> d;
  const std::size_t N = hn::Lanes(d);
  const auto vf = hn::Set(d, fr), vw = hn::Set(d, w);
  std::size_t i = begin;
  for (; i + N <= end; i += N) {
    const auto fc = hn::LoadU(d, s + i);
    const auto l = Lerp(hn::LoadU(d, s + i - n4), hn::LoadU(d, s + i - n4 - px), vf);
    const auto r = Lerp(hn::LoadU(d, s + i + n4), hn::LoadU(d, s + i + n4 + px), vf);
    const auto u = Lerp(hn::LoadU(d, u0 + i), hn::LoadU(d, u1 + i), vf);
    const auto dd = Lerp(hn::LoadU(d, d0 + i), hn::LoadU(d, d1 + i), vf);
    hn::StoreU(Stencil(fc, l, r, u, dd, vw, vw, vw, vw), d, o + i);
  }
  uniform_row_body(s, u0, u1, d0, d1, o, i, end, n4, px, fr, w);
}

// brume_tap_rate and brume_edge_rate lane by lane, operation for operation.
template <int kMode, class D, class V = hn::Vec<D>>
HWY_INLINE V Tap(D d, V r0, V r1, V f) {
  if constexpr (kMode == 0) return Lerp(r0, r1, f);
  return hn::IfThenElse(hn::Gt(f, hn::Zero(d)), AsPrelude<false>(r0, r1), r0);
}
template <int kMode, class D, class V = hn::Vec<D>>
HWY_INLINE V Edge(D d, V rc, V rn) {
  if constexpr (kMode == 1) return AsPrelude<false>(rc, rn);
  if constexpr (kMode == 2)  // 2 rc rn / max(rc + rn, 1e-30)
    return hn::Div(hn::Mul(hn::Mul(hn::Set(d, 2.0f), rc), rn), AsPrelude<true>(hn::Add(rc, rn), hn::Set(d, 1.0e-30f)));
  return hn::Mul(hn::Set(d, 0.5f), hn::Add(rc, rn));
}
// One direction's eq. 12 weights of Lanes(d) pixels: centre rates rc, the
// rates of the tap's two texels (contiguous across the run), fractions f.
template <int kMode, class D, class V = hn::Vec<D>>
HWY_INLINE V Weight(D d, V rc, V r0, V r1, V f) {
  return Edge<kMode>(d, rc, Tap<kMode>(d, r0, r1, f));
}

// A run of pixels of C values (4: RGBA, 3: RGB rows): N = Lanes(d) pixels'
// fractions and eq. 12 weights in registers (the rate taps are contiguous
// loads, as in run_weights), then their C N values, C vectors, each lane
// taking its pixel's fraction and weights by one table look-up of those
// registers (lane l of vector j: pixel (j N + l) / C; for RGBA the
// broadcast of a pixel's values over its four lanes, for RGB rows the same
// with no lane spent on an alpha). The weights make no round trip through
// the scratch rows, whose 4 x W floats, with the offsets and F's rows,
// outgrew L1 at W = 1600. Value by value these are eq11's operations in
// eq11's order (run_update_v4, run_update_rgb_values). On AVX-512 the last
// < N pixels take the same code under masks (masked-off lanes are neither
// loaded nor stored, so short runs -- a real haze map splits its rows into
// many -- stay vectorised); elsewhere the reference loop.
template <int kMode, int C>
void RunMode(const RunArgs& a, const RateRows& q, int xa, int xb, int n) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  const std::ptrdiff_t nC = static_cast<std::ptrdiff_t>(n) * C;
  HWY_ALIGN std::int32_t idx[C][HWY_MAX_BYTES / sizeof(float)];
  for (int j = 0; j < C; ++j)
    for (int l = 0; l < N; ++l) idx[j][l] = (j * N + l) / C;
  const hn::RebindToSigned<decltype(d)> di;
#if HWY_HAVE_SCALABLE
  // SVE's vectors are sizeless, never an array's elements: vector j's
  // indices are loaded where they are used.
  auto lanes_of = [&](int j) { return hn::IndicesFromVec(d, hn::Load(di, idx[j])); };
#else
  using Idx = decltype(hn::IndicesFromVec(d, hn::Load(di, idx[0])));
  Idx lanes[C];
  for (int j = 0; j < C; ++j) lanes[j] = hn::IndicesFromVec(d, hn::Load(di, idx[j]));
  auto lanes_of = [&](int j) { return lanes[j]; };
#endif
  // The rows in locals: read through `a` and `q`, every pointer was loaded
  // again after each store (the compiler cannot tell that a store to the
  // output row leaves them unchanged), 18 extra loads per vector of pixels.
  const float *const fs = a.s, *const fu0 = a.u0, *const fu1 = a.u1, *const fd0 = a.d0, *const fd1 = a.d1;
  float* const fo = a.o;
  const float* const fra = a.fr;
  const float *const qc = q.c, *const qu0 = q.u0, *const qu1 = q.u1, *const qd0 = q.d0, *const qd1 = q.d1;
  // Vector j of the pixels from x: values vm of it (all: full vectors).
  auto update = [&](int x, int j, auto fN, auto wlN, auto wrN, auto wuN, auto wdN, auto load, auto store) {
    const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * C + static_cast<std::ptrdiff_t>(j) * N;
    const auto f = hn::TableLookupLanes(fN, lanes_of(j));
    const auto fc = load(fs + i);
    const auto l = Lerp(load(fs + i - nC), load(fs + i - nC - C), f);
    const auto r = Lerp(load(fs + i + nC), load(fs + i + nC + C), f);
    const auto u = Lerp(load(fu0 + i), load(fu1 + i), f);
    const auto dd = Lerp(load(fd0 + i), load(fd1 + i), f);
    store(Stencil(fc, l, r, u, dd, hn::TableLookupLanes(wlN, lanes_of(j)), hn::TableLookupLanes(wrN, lanes_of(j)),
                  hn::TableLookupLanes(wuN, lanes_of(j)), hn::TableLookupLanes(wdN, lanes_of(j))),
          fo + i);
  };
  int x = xa;
  for (; x + N <= xb; x += N) {
    auto load = [&](const float* p) { return hn::LoadU(d, p); };
    auto store = [&](hn::Vec<decltype(d)> v, float* p) { hn::StoreU(v, d, p); };
    const auto fN = load(fra + x), rc = load(qc + x);
    const auto wlN = Weight<kMode>(d, rc, load(qc + x - n), load(qc + x - n - 1), fN);
    const auto wrN = Weight<kMode>(d, rc, load(qc + x + n), load(qc + x + n + 1), fN);
    const auto wuN = Weight<kMode>(d, rc, load(qu0 + x), load(qu1 + x), fN);
    const auto wdN = Weight<kMode>(d, rc, load(qd0 + x), load(qd1 + x), fN);
    for (int j = 0; j < C; ++j) update(x, j, fN, wlN, wrN, wuN, wdN, load, store);
  }
  if (x >= xb) return;
#ifdef BRUME_HWY_MASKED_TAIL
  const int m = xb - x;  // pixels
  const auto pm = hn::FirstN(d, static_cast<std::size_t>(m));
  auto pload = [&](const float* p) { return hn::MaskedLoad(pm, d, p); };
  const auto fN = pload(fra + x), rc = pload(qc + x);
  const auto wlN = Weight<kMode>(d, rc, pload(qc + x - n), pload(qc + x - n - 1), fN);
  const auto wrN = Weight<kMode>(d, rc, pload(qc + x + n), pload(qc + x + n + 1), fN);
  const auto wuN = Weight<kMode>(d, rc, pload(qu0 + x), pload(qu1 + x), fN);
  const auto wdN = Weight<kMode>(d, rc, pload(qd0 + x), pload(qd1 + x), fN);
  for (int j = 0; j < C; ++j) {
    const int values = C * m - N * j;  // of this vector
    if (values <= 0) break;
    const auto vm = hn::FirstN(d, static_cast<std::size_t>(std::min(values, N)));
    auto load = [&](const float* p) { return hn::MaskedLoad(vm, d, p); };
    auto store = [&](hn::Vec<decltype(d)> v, float* p) { hn::BlendedStore(v, vm, d, p); };
    update(x, j, fN, wlN, wrN, wuN, wdN, load, store);
  }
#else
  run_weights<kMode>(q.c, q.u0, q.u1, q.d0, q.d1, a.fr, a.wl, a.wr, a.wu, a.wd, x, xb, n);
  if constexpr (C == 4)
    run_update_v4(a, x, xb, n);
  else
    run_update_rgb_values(a, x, xb, n);
#endif
}

template <int C>
void Run(const RunArgs& a, const RateRows& q, int edge_mode, int xa, int xb, int n) {
  switch (edge_mode) {
    case 1: RunMode<1, C>(a, q, xa, xb, n); break;
    case 2: RunMode<2, C>(a, q, xa, xb, n); break;
    default: RunMode<0, C>(a, q, xa, xb, n); break;
  }
}

// run_end_generic a vector of offsets at a time (called once per run, not inlined).
int RunEndOf(const int* __restrict n, int x, int W) {
  const hn::ScalableTag<std::int32_t> d;
  const int N = static_cast<int>(hn::Lanes(d));
  const auto v = hn::Set(d, n[x]);
  int e = x + 1;
  for (; e + N <= W; e += N) {
    const intptr_t first = hn::FindFirstTrue(d, hn::Ne(hn::LoadU(d, n + e), v));
    if (first >= 0) return e + static_cast<int>(first);
  }
  while (e < W && n[e] == n[x]) ++e;
  return e;
}

void StandardRow(BRUME_STANDARD_ROW_ARGS) { BRUME_STANDARD_ROW_CALL; }
// sigma_products on this target's vectors: each lane's k multiplies in the
// same order, so the same bits. Four chains at once hide the multiply's
// latency. (The reference's sixteen-float GCC vectors, inlined here, were
// split by GCC for AVX2 into halves passed through the stack and general
// registers: 72 % of the AVX2 row's own time, measured.)
HWY_INLINE void SigmaProducts(float* HWY_RESTRICT s, const float* HWY_RESTRICT g, int c, float s0, int k) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  const auto s0v = hn::Set(d, s0);
  int b = 0;
  for (; b + 4 * N <= c; b += 4 * N) {
    const auto g0 = hn::LoadU(d, g + b), g1 = hn::LoadU(d, g + b + N), g2 = hn::LoadU(d, g + b + 2 * N),
               g3 = hn::LoadU(d, g + b + 3 * N);
    auto p0 = s0v, p1 = s0v, p2 = s0v, p3 = s0v;
    for (int i = 0; i < k; ++i) p0 = hn::Mul(p0, g0), p1 = hn::Mul(p1, g1), p2 = hn::Mul(p2, g2), p3 = hn::Mul(p3, g3);
    hn::StoreU(p0, d, s + b);
    hn::StoreU(p1, d, s + b + N);
    hn::StoreU(p2, d, s + b + 2 * N);
    hn::StoreU(p3, d, s + b + 3 * N);
  }
  for (; b + N <= c; b += N) {
    const auto g0 = hn::LoadU(d, g + b);
    auto p0 = s0v;
    for (int i = 0; i < k; ++i) p0 = hn::Mul(p0, g0);
    hn::StoreU(p0, d, s + b);
  }
  for (; b < c; ++b) {
    float sb = s0;
    for (int i = 0; i < k; ++i) sb = sb * g[b];
    s[b] = sb;
  }
}
void GeneralRow(BRUME_GENERAL_ROW_ARGS) { BRUME_GENERAL_ROW_CALL(4, Run<4>, RunEndOf, SigmaProducts); }
void GeneralRgbRow(BRUME_GENERAL_ROW_ARGS) { BRUME_GENERAL_ROW_CALL(3, Run<3>, RunEndOf, SigmaProducts); }
// The set-up's eight-float vector code (GCC's vector extension), compiled
// for this target.
void Rates(const float* s, float* rho, std::size_t n, float s0, float Nf) { setup::rates_body(s, rho, n, s0, Nf); }
void Growth(const float* rho, float* g, float* vr, std::size_t n) { setup::growth_body(rho, g, vr, n); }

}  // namespace

// This target's rows (exported below).
RowKernels Kernels() { return {UniformRow, GeneralRow, StandardRow, GeneralRgbRow, Rates, Growth}; }

}  // namespace HWY_NAMESPACE
}  // namespace brume::cpu
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace brume::cpu {
HWY_EXPORT(Kernels);

namespace {
std::atomic<int> g_simd_limit{-1};
int simd_available() {
  const std::int64_t t = hwy::SupportedTargets() & HWY_TARGETS;
  if (t & (HWY_AVX3 | HWY_AVX3_DL)) return 2;
  if (t & HWY_AVX2) return 1;
  return 0;
}
}  // namespace

// The reference rows and set-up (level 0).
const RowKernels kReference{uniform_row_generic,     general_row_generic, standard_row_generic,
                            general_rgb_row_generic, rates_generic,       growth_generic};

RowKernels row_kernels() {
  // Level 0 (set_diffusion_simd_limit(0)): the reference rows. Otherwise the
  // best target the CPU runs, without the 512-bit ones at level 1. The
  // constant-scale rows are at most eight floats wide on every target
  // (UniformRow); the space-variant rows gain from 512 bits (160 against
  // 175 ms on a Zen 3-era EPYC): their per-pixel offsets and weights are
  // arithmetic-bound.
  if (g_simd_limit.load(std::memory_order_relaxed) == 0) return kReference;
  std::int64_t t = hwy::SupportedTargets() & HWY_TARGETS;
  if (diffusion_simd_level() < 2) t &= ~static_cast<std::int64_t>(HWY_AVX3 | HWY_AVX3_DL);
  if (t == 0) return kReference;
  hwy::ChosenTarget chosen;  // the table entry of the best of t (the lowest bit)
  chosen.Update(t & -t);
  return HWY_DISPATCH_TABLE(Kernels)[chosen.GetIndex()]();
}

int diffusion_simd_level() {
  const int limit = g_simd_limit.load(std::memory_order_relaxed);
  return limit < 0 ? simd_available() : std::min(limit, simd_available());
}
void set_diffusion_simd_limit(int level) { g_simd_limit.store(level, std::memory_order_relaxed); }

}  // namespace brume::cpu
#endif  // HWY_ONCE
