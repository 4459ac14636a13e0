// brume — the fast CPU schedule of layered fog: the exponential profile
// without blur, one row at a time as vector code (fog_fast.hpp).
//
// What it computes is fog_math.glsl's brume_fog_along / brume_fog_sky /
// brume_fog_composite for kind 0 in f32: the ray's world-up component in the
// same operations (the row's terms hoisted), the mean density as below with
// ONE exponential instead of two, and f = e^-F. It is written branch-free so
// that GCC vectorises the row: both sides of each choice are computed and
// selected, sky pixels included. e^x is AttenuationTable::exp_f (relative
// error <= 1e-7 against double exp over [-87, 88], flushing to 0 below,
// tests/test_aerial_spectral.cpp) instead of libm's expf. F agrees with the
// per-pixel loop to 1e-6 relative (6e-7 measured) and with the double closed
// form as the loop does (2e-5; tests/test_fog.cpp, VectorRows...), and the
// Delta y -> 0 limit is a series, as stable as the loop's (tested at 1e-6 m).
//
// Schedule: per pixel one sqrt, two divisions (the ray, F = N / D) and two
// polynomial exps, where the per-pixel loop spent a sqrt, two divisions
// and three libm expf calls. The row is one loop of scalar C++ that the
// compiler vectorises (`omp simd`), compiled by Highway's foreach_target.h
// for every target of core/simd.hpp (the baseline: SSE2, 4 lanes; SSE4;
// AVX2, 8 lanes; AVX-512, 16) and chosen at run time by
// HWY_DYNAMIC_DISPATCH: the same source, one compilation per instruction
// set. With -ffp-contract=off on this file (CMakeLists.txt: the AVX2 and
// AVX-512 targets have FMA) and no reassociation, every target gives the
// same bits (test: FogVectorRows.EveryTargetGivesTheSameBits).
// bench/bench_fog.cpp times it against the per-pixel loop, interleaved.
#include "core/simd.hpp"  // first: the targets

#ifndef BRUME_FOG_FAST_SHARED
#define BRUME_FOG_FAST_SHARED
#include <cmath>
#include <limits>

#include "brume/aerial.hpp"
#include "effects/fog/fog_fast.hpp"
#endif

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "effects/fog/fog_fast.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace brume::detail {
namespace HWY_NAMESPACE {

namespace {

// e^x for x <= 0 through exp_f, whose domain is |x| < 2.9e6: below -100 it
// is 0 in f32 either way (exp_f(-100) == 0, tested).
inline float exp_neg(float x) { return AttenuationTable::exp_f(x < -100.0f ? -100.0f : x); }
// e^x for any x: above 100 it is inf in f32 either way (exp_f(100) == inf).
inline float exp_any(float x) {
  x = x < -100.0f ? -100.0f : x;
  return AttenuationTable::exp_f(x > 100.0f ? 100.0f : x);
}

}  // namespace

// This target's row (exported below).
void FogExponentialRow(const FogExpFrame& fr, int v) {
  const int W = fr.width;
  const std::size_t row = static_cast<std::size_t>(v) * static_cast<std::size_t>(W);
  const float* __restrict in = fr.rgb + 3 * row;
  const float* __restrict range = fr.range + row;
  float* __restrict out = fr.out_rgb + 3 * row;
  float* __restrict Fo = fr.optical_depth + row;
  float* __restrict fo = fr.transmission + row;
  // brume_fog_ray_y, with the row's terms hoisted (same operations, same bits):
  // ray_y = ((r0 x + r1 y) + r2) / sqrt((x x + y y) + 1).
  const float y = (static_cast<float>(v) - fr.cy) * fr.ify;
  const float r1y = fr.r1 * y, yy = y * y, r0 = fr.r0, r2 = fr.r2, cx = fr.cx, ifx = fr.ifx;
  const float d0 = fr.d0, B = fr.falloff, ec = fr.exponent_c, sky_l = fr.sky_distance;
  // delta(y_c), with libm as the scalar path; flushed to 0 below the normal
  // range as exp_f flushes d_low (e^-87.3 and less give 0), so that
  // d_low - dc is never negative (a camera ~90 e-folding heights above the
  // fog: F ~ 1e-38 l instead of 0, f = 1 either way).
  const float dc_libm = d0 * std::exp(ec);
  const float dc = dc_libm < std::numeric_limits<float>::min() ? 0.0f : dc_libm;
  // Sky rays climbing above this integrate to infinity in closed form (B > 0: all that climb).
  const float climb = B > 0.0f ? 0.0f : INFINITY;
  const float a0 = fr.airlight[0], a1 = fr.airlight[1], a2 = fr.airlight[2];
  constexpr float kInf = INFINITY;
#pragma omp simd
  for (int u = 0; u < W; ++u) {
    const float x = (static_cast<float>(u) - cx) * ifx;
    const float ry = (r0 * x + r1y + r2) / std::sqrt(x * x + yy + 1.0f);
    const float r = range[u];
    const bool known = std::abs(r) < kInf && r != 0.0f;  // finite and non-zero; NaN is not
    const float l = known ? r : sky_l;
    // The mean density over [0, dy] with ONE exponential: with x = B dy and
    // dc = delta(y_c) = D0 e^ec,
    //   climbing (x >= 0):  mean = dc (1 - e^-x) / x,            t = e^-x
    //   descending (x < 0): mean = (D0 e^(ec + |x|) - dc) / |x|,   t = e^(ec + |x|)
    // (the scalar path's delta(y_low) g(|x|) multiplied out: e^ec is the
    // frame's constant). The differences are of the lower end's density and
    // the camera's, d_low - d_high >= (1 - e^-0.25) d_low: below |x| = 0.25
    // the series d_low g(|x|) replaces them (to x^6; next term x^7/8! < 2e-9),
    // so the difference loses at most ~5 ulp. d_low overflows only when the
    // density itself does; dc underflowing means the fog at the camera
    // height is below 1e-38 /m, where f = 1 in f32 either way (dc is then 0).
    const float xb = B * (l * ry);
    const bool climbs = xb >= 0.0f;
    const float ax = std::abs(xb);
    const float t = exp_any(climbs ? -ax : ec + ax);
    const float d_low = climbs ? dc : d0 * t;
    const float diff = climbs ? dc * (1.0f - t) : d_low - dc;
    const float s4 = 1.0f / 120.0f - ax * (1.0f / 720.0f - ax * (1.0f / 5040.0f));
    const float series = 1.0f - ax * (1.0f / 2.0f - ax * (1.0f / 6.0f - ax * (1.0f / 24.0f - ax * s4)));
    const bool near_level = ax < 0.25f;
    // F = N / D, one division: the ray's l diff / |x| (or l d_low g), or a
    // climbing sky ray's closed form dc / (B ray_y) (brume_fog_exp_sky).
    const float N_ray = l * (near_level ? d_low * series : diff), D_ray = near_level ? 1.0f : ax;
    const float N_sky = ry > climb ? dc : N_ray, D_sky = ry > climb ? B * ry : D_ray;
    const float N = known ? N_ray : N_sky;
    const float D = known ? D_ray : D_sky;
    const bool infinite = fr.sky_infinite && !known && !(ry > climb);  // diverging, across an unbounded medium
    const float F = infinite ? kInf : N / D;
    const float f = exp_neg(-F);
    Fo[u] = F;
    fo[u] = f;
    const float* c = in + 3 * u;
    float* o = out + 3 * u;
    o[0] = f * c[0] + (1.0f - f) * a0;  // brume_fog_composite
    o[1] = f * c[1] + (1.0f - f) * a1;
    o[2] = f * c[2] + (1.0f - f) * a2;
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace brume::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace brume::detail {
HWY_EXPORT(FogExponentialRow);

void fog_exponential_row(const FogExpFrame& fr, int v) { HWY_DYNAMIC_DISPATCH(FogExponentialRow)(fr, v); }
}  // namespace brume::detail
#endif  // HWY_ONCE
