// brume — the per-pixel update of the diffusion schemes, shared by the fast
// CPU translation units (internal). Written once, templated on how F is
// stored between iterations (float, or binary16 bits).
#pragma once

#include <cstdint>
#include <cstring>
#include <vector>

#include "diffusion/diffusion_kernels.hpp"
#include "diffusion/diffusion_setup_math.hpp"
#include "diffusion/diffusion_stencil.hpp"
#include "shared/prelude_cpp.h"

namespace brume::cpu {
namespace sh = brume::shared;

// Four floats (one RGBA pixel) as one vector: GCC/Clang vector extensions
// compile to SSE/AVX/NEON without intrinsics.
typedef float v4 __attribute__((vector_size(16)));

// Float storage of F between iterations (the f32 texture). The f16 storage
// (binary16 bits, the RGBA16F texture) lives in diffusion_fast_f16.cpp.
struct StoreF32 {
  using T = float;
  static v4 load(const float* p) {
    v4 v;
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  static void store(float* p, v4 v) { std::memcpy(p, &v, sizeof v); }
};

// Eq. 11 at one pixel from its taps: the centre fc and, per direction, the
// two texels (a0 at offset n, a1 at n + 1) that linear interpolation at
// fraction fr blends, with the four eq. 12 weights: the interpolation, then
// the shared stencil update (diffusion_stencil.hpp).
inline v4 eq11(v4 fc, v4 l0, v4 l1, v4 r0, v4 r1, v4 u0, v4 u1, v4 d0, v4 d1, float fr, float wl, float wr,
               float wu, float wd) {
  const v4 l = l0 + fr * (l1 - l0), r = r0 + fr * (r1 - r0);
  const v4 u = u0 + fr * (u1 - u0), d = d0 + fr * (d1 - d0);
  return brume_diffusion_update(fc, l, r, u, d, wl, wr, wu, wd);
}

// Where an iteration reads its rows: the whole image (cap 0: row q at
// base + q rs), a fused group's ring of cap rows (row q in slot q % cap), or
// a table of row pointers (a band of an image updated in place, whose
// neighbouring bands' rows are read from copies; diffusion_fusion.hpp).
// rs: values per row.
template <class T>
struct RowSource {
  const T* base;
  std::size_t rs;
  int cap;
  const T* const* table = nullptr;
  const T* operator()(int q) const {
    if (table) return table[q];
    return base + static_cast<std::size_t>(cap ? q % cap : q) * rs;
  }
};

// One pixel of the general scheme (any offsets, any rates): eq. 11-12.
// `h` is the pixel's neighbour offset; indices are mirrored only when a tap
// falls outside the image. kUniform: every rate is `w_all` (a constant target
// scale), so the eq. 12 weights need no look-up. The arithmetic, channel by
// channel, is the same as uniform_row_body's (diffusion_fast_kernels.cpp), so
// both give the same bits.
// F's rows come through `in` (the image or a fused group's ring) and the
// pixel goes to row `orow` of the result.
template <bool kUniform, class S = StoreF32>
inline void pixel_from_rows(const RowSource<typename S::T>& in, typename S::T* orow, const float* rho, float w_all,
                            int W, int H, int x, int y, float h, int edge_mode = 0) {
  const int n = static_cast<int>(h);
  const float fr = h - static_cast<float>(n);
  int xl0 = x - n, xl1 = x - n - 1, xr0 = x + n, xr1 = x + n + 1;
  int yu0 = y - n, yu1 = y - n - 1, yd0 = y + n, yd1 = y + n + 1;
  if (xl1 < 0 || xr1 >= W || yu1 < 0 || yd1 >= H) {
    xl0 = mirror(xl0, W), xl1 = mirror(xl1, W), xr0 = mirror(xr0, W), xr1 = mirror(xr1, W);
    yu0 = mirror(yu0, H), yu1 = mirror(yu1, H), yd0 = mirror(yd0, H), yd1 = mirror(yd1, H);
  }
  const std::size_t Ws = static_cast<std::size_t>(W);
  float wl = w_all, wr = w_all, wu = w_all, wd = w_all;
  if constexpr (!kUniform) {
    const float* rrow = rho + y * Ws;
    const float rc = rrow[x];
    wl = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[xl0], rrow[xl1], fr, edge_mode), edge_mode);
    wr = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[xr0], rrow[xr1], fr, edge_mode), edge_mode);
    wu = sh::brume_edge_rate(rc, sh::brume_tap_rate(rho[yu0 * Ws + x], rho[yu1 * Ws + x], fr, edge_mode), edge_mode);
    wd = sh::brume_edge_rate(rc, sh::brume_tap_rate(rho[yd0 * Ws + x], rho[yd1 * Ws + x], fr, edge_mode), edge_mode);
  }
  const typename S::T* srow = in(y);
  const std::size_t c = static_cast<std::size_t>(x) * 4;
  S::store(orow + c, eq11(S::load(srow + c), S::load(srow + xl0 * 4), S::load(srow + xl1 * 4),
                          S::load(srow + xr0 * 4), S::load(srow + xr1 * 4), S::load(in(yu0) + c),
                          S::load(in(yu1) + c), S::load(in(yd0) + c), S::load(in(yd1) + c), fr, wl, wr, wu, wd));
}

// The same pixel (space-variant, float storage) on rows of C values a pixel
// (the RGB rows): value by value, eq11's operations in eq11's order with the
// same taps and weights, hence each value's bits as in the RGBA pixel.
inline void pixel_values_from_rows(const RowSource<float>& in, float* orow, const float* rho, int W, int H, int x,
                                   int y, float h, int edge_mode, int C) {
  const int n = static_cast<int>(h);
  const float fr = h - static_cast<float>(n);
  const int xl0 = mirror(x - n, W), xl1 = mirror(x - n - 1, W), xr0 = mirror(x + n, W), xr1 = mirror(x + n + 1, W);
  const int yu0 = mirror(y - n, H), yu1 = mirror(y - n - 1, H), yd0 = mirror(y + n, H), yd1 = mirror(y + n + 1, H);
  const std::size_t Ws = static_cast<std::size_t>(W);
  const float* rrow = rho + y * Ws;
  const float rc = rrow[x];
  const float wl = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[xl0], rrow[xl1], fr, edge_mode), edge_mode);
  const float wr = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[xr0], rrow[xr1], fr, edge_mode), edge_mode);
  const float wu =
      sh::brume_edge_rate(rc, sh::brume_tap_rate(rho[yu0 * Ws + x], rho[yu1 * Ws + x], fr, edge_mode), edge_mode);
  const float wd =
      sh::brume_edge_rate(rc, sh::brume_tap_rate(rho[yd0 * Ws + x], rho[yd1 * Ws + x], fr, edge_mode), edge_mode);
  const float* s = in(y);
  const float *u0 = in(yu0), *u1 = in(yu1), *d0 = in(yd0), *d1 = in(yd1);
  const std::ptrdiff_t cC = static_cast<std::ptrdiff_t>(x) * C;
  for (int c = 0; c < C; ++c) {
    const std::ptrdiff_t i = cC + c;
    const float l = s[xl0 * C + c] + fr * (s[xl1 * C + c] - s[xl0 * C + c]);
    const float r = s[xr0 * C + c] + fr * (s[xr1 * C + c] - s[xr0 * C + c]);
    const float u = u0[i] + fr * (u1[i] - u0[i]), d = d0[i] + fr * (d1[i] - d0[i]);
    orow[i] = brume_diffusion_update(s[i], l, r, u, d, wl, wr, wu, wd);
  }
}

// The same pixel of whole images src -> dst.
template <bool kUniform, class S = StoreF32>
inline void update_pixel(const typename S::T* src, typename S::T* dst, const float* rho, float w_all, int W,
                         int H, int x, int y, float h, int edge_mode = 0) {
  const std::size_t rs = static_cast<std::size_t>(W) * 4;
  pixel_from_rows<kUniform, S>(RowSource<typename S::T>{src, rs, 0}, dst + static_cast<std::size_t>(y) * rs, rho,
                               w_all, W, H, x, y, h, edge_mode);
}

// One pixel of a constant-scale iteration (every weight w_all, offset h =
// n + fr) from row pointers: the centre row s and the rows at -n, -(n+1),
// +n, +(n+1), already mirrored; the column taps are mirrored here. Row
// pointers let the fused schedule (diffusion_fusion.hpp) feed rows from its
// rings. Same taps, same eq11, hence the same bits as update_pixel<true, S>
// (which mirrors every index once any falls outside; mirror is the identity
// inside). Always inlined: the binary16 row (diffusion_fast_f16.cpp) calls
// it from AVX2 + F16C code, and only once inlined there can its StoreF16
// loads and stores, compiled for that target, be inlined too.
template <class S = StoreF32>
__attribute__((always_inline)) inline void uniform_border_pixel(const typename S::T* s, const typename S::T* u0, const typename S::T* u1,
                                 const typename S::T* d0, const typename S::T* d1, typename S::T* o, int W, int x,
                                 int n, float fr, float w) {
  const std::ptrdiff_t c = static_cast<std::ptrdiff_t>(x) * 4;
  S::store(o + c, eq11(S::load(s + c), S::load(s + mirror(x - n, W) * 4), S::load(s + mirror(x - n - 1, W) * 4),
                       S::load(s + mirror(x + n, W) * 4), S::load(s + mirror(x + n + 1, W) * 4), S::load(u0 + c),
                       S::load(u1 + c), S::load(d0 + c), S::load(d1 + c), fr, w, w, w, w));
}

// A border pixel of a constant-scale row of C values a pixel (the 3-channel
// rows): uniform_border_pixel's taps and, value by value, eq11's operations
// in eq11's order (the interpolation, then brume_diffusion_update; no
// contraction where it is compiled: diffusion_fast.cpp), hence the bits a
// 4-channel row gives the same values.
inline void uniform_border_values(const float* s, const float* u0, const float* u1, const float* d0, const float* d1,
                                  float* o, int W, int x, int n, float fr, float w, int C) {
  const std::ptrdiff_t c0 = static_cast<std::ptrdiff_t>(x) * C;
  const std::ptrdiff_t l0 = static_cast<std::ptrdiff_t>(mirror(x - n, W)) * C,
                       l1 = static_cast<std::ptrdiff_t>(mirror(x - n - 1, W)) * C;
  const std::ptrdiff_t r0 = static_cast<std::ptrdiff_t>(mirror(x + n, W)) * C,
                       r1 = static_cast<std::ptrdiff_t>(mirror(x + n + 1, W)) * C;
  for (int c = 0; c < C; ++c) {
    const float l = s[l0 + c] + fr * (s[l1 + c] - s[l0 + c]), r = s[r0 + c] + fr * (s[r1 + c] - s[r0 + c]);
    const float u = u0[c0 + c] + fr * (u1[c0 + c] - u0[c0 + c]), d = d0[c0 + c] + fr * (d1[c0 + c] - d0[c0 + c]);
    o[c0 + c] = brume_diffusion_update(s[c0 + c], l, r, u, d, w, w, w, w);
  }
}

// Offset, interpolation fraction and eq. 12 weight of one iteration when the
// target scale is the same everywhere (every pixel has the same sigma_k).
struct UniformStep {
  float h, fr, w;
  int n;
};
// brume_invariant_offset with the fast path's variance ratio
// (diffusion_setup_math.hpp), as the space-variant rows form it.
inline float invariant_offset_fast(float sigma_k, float rho, bool exact) {
  return exact ? sh::brume_offset_for_moment(sigma_k * sigma_k * setup_math::variance_ratio1(rho)) : sigma_k;
}
inline UniformStep uniform_step(float sigma_k, float rho, bool exact, int edge_mode) {
  UniformStep st;
  st.h = invariant_offset_fast(sigma_k, rho, exact);
  st.n = static_cast<int>(st.h);
  st.fr = st.h - static_cast<float>(st.n);
  st.w = sh::brume_edge_rate(rho, sh::brume_tap_rate(rho, rho, st.fr, edge_mode), edge_mode);  // as update_pixel<false>
  return st;
}

// f16 storage of the constant-scale path on CPUs with F16C (x86-64): F is
// kept as binary16 bits between iterations, halving the memory traffic, with
// the same arithmetic and rounding as the float path + round_to_half, and the
// same schedule (steps and fused groups: diffusion_fusion.hpp, computed by
// the caller so that the per-target file compiles none of the planning).
// Returns false (and does nothing) where the chosen SIMD target has no
// hardware binary16 conversion (F16C: Highway's AVX2 and AVX-512 targets). a: a buffer of
// W x H x 4 binary16 values, b: another where fusion_needs_partner(...)
// (else null), ring: fusion_scratch_values(...) values (the workspace's),
// contents ignored.
// A run of consecutive iterations [k0, k0 + m) done in one pass.
struct FusedGroup {
  int k0, m;
};
bool uniform_iterations_f16(float* f, int W, int H, const std::vector<UniformStep>& steps,
                            const std::vector<FusedGroup>& groups, int threads, std::uint16_t* a, std::uint16_t* b,
                            std::uint16_t* ring);

// The row kernels of the float path (diffusion_fast_kernels.cpp): the
// reference rows (plain C++) and one Highway body compiled for every SIMD
// target (core/simd.hpp), all evaluating the same operations in the same
// order (the same bits). The schedule (diffusion_fast.cpp) picks the rows
// once per call (row_kernels) and calls them through these pointers, a row
// at a time.
//
// The interior of a constant-scale row, every pixel with the offset
// h = n + fr and the eq. 12 weight w: the values [begin, end) of row o from
// the rows s (y), u0, u1 (y -+ n, y -+ (n+1) above) and d0, d1 (below);
// px values a pixel (4, or 3 for RGB rows), n4 = n px. The border columns,
// whose taps are mirrored, are uniform_border_pixel's and
// uniform_border_values'.
using UniformRow = void (*)(const float* __restrict s, const float* __restrict u0, const float* __restrict u1,
                            const float* __restrict d0, const float* __restrict d1, float* __restrict o,
                            std::size_t begin, std::size_t end, std::ptrdiff_t n4, std::ptrdiff_t px, float fr,
                            float w);
// Per-thread scratch of the general (space-variant) row: offsets, their
// integer and fractional parts, and the four eq. 12 weights of each pixel.
struct RowScratch {
  std::vector<float> h, fr, wl, wr, wu, wd;
  std::vector<int> n;
  // The mirrored columns of a border segment (general_row_body): F's
  // values and the rates, grown on demand.
  std::vector<float> fpad, rpad;
  explicit RowScratch(int W) : h(W), fr(W), wl(W), wr(W), wu(W), wd(W), n(W) {}
};
// Row y of iteration k of the space-variant invariant schemes, into orow:
// F's rows from `in` (the image or a fused group's ring), the rate map rho
// (W x H), the row's growth e^rho and (exact scheme) variance ratio vr, s0
// the starting scale, t the calling thread's scratch.
using GeneralRow = void (*)(const RowSource<float>& in, float* orow, const float* rho, float s0, int k,
                            const float* growth, const float* vr, bool exact, int edge_mode, int W, int H, int y,
                            RowScratch& t);
// One row of the conductance stencil (the standard scheme once its edge
// rates are formed), RGBA: wr[x] couples x and x+1 (0 at the last column:
// zero flux), wd_up couples the row to the one above, wd to the one below;
// up and dn are those rows (clamped at the image's edges, where the weights
// are 0).
using StandardRow = void (*)(const float* __restrict s, const float* __restrict up, const float* __restrict dn,
                             const float* __restrict wr, const float* __restrict wd_up, const float* __restrict wd,
                             float* __restrict o, int W);
// The invariant schemes' per-pixel set-up (diffusion_setup_rows.hpp): n
// rates ln(s / s0) / N of the target scales s, and n rates' growth e^rho and
// variance ratio.
using RatesFn = void (*)(const float* s, float* rho, std::size_t n, float s0, float Nf);
using GrowthFn = void (*)(const float* rho, float* g, float* vr, std::size_t n);
// The widths of every row kernel, picked once per call.
struct RowKernels {
  UniformRow uniform;
  GeneralRow general;
  StandardRow standard;
  GeneralRow general_rgb;  // the space-variant row on RGB rows (three values a pixel)
  RatesFn rates;
  GrowthFn growth;
};
// The widths diffusion_simd_level() allows.
RowKernels row_kernels();

}  // namespace brume::cpu
