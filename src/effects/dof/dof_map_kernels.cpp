// brume — the depth-of-field scale map's row kernels (dof_map.hpp): the CoC
// pass and the foreground rule's Gaussian, band values and maxima, written
// once with Highway and compiled for every SIMD target of core/simd.hpp (the
// baseline fallback: SSE2, 4 lanes; SSE4; AVX2, 8 lanes; AVX-512, 16), the
// CPU choosing at run time (HWY_DYNAMIC_DISPATCH). The schedule that runs
// them (which rows, which columns) is dof_map.cpp, beside the scalar loops
// they reproduce.
//
// Every kernel performs the scalar loop's IEEE operations in its order, lane
// by lane: Highway's Div and Sqrt are correctly rounded as the scalar
// divss/sqrtss are, the selects spell prelude_cpp.h's min and max (b < a ? b
// : a), and -ffp-contract=off on this file (CMakeLists.txt) keeps AVX2's and
// AVX-512's FMA from fusing a product into a sum. This file never reads
// errno (-fno-math-errno), so its square roots are the instruction (the
// argument s0^2 + (c/4)^2 is never negative: errno was never set). The one
// libm call, log2f for the band of a scale, is replaced where its floor is
// decided by the float's exponent alone (DofCocRowK below), and called as
// the reference calls it elsewhere. Test: DofScaleMap.VectorRowsGiveTheReferenceBits.
#include "core/simd.hpp"  // first: the targets

#ifndef BRUME_DOF_MAP_KERNELS_SHARED
#define BRUME_DOF_MAP_KERNELS_SHARED
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "effects/dof/dof_map.hpp"
#endif

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "effects/dof/dof_map_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace brume::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

namespace {

// The band of a scale where the exponent does not decide it: the
// reference's expression (dof_map.cpp, near_field_raise).
int band_by_log2(float s) { return std::max(0, static_cast<int>(std::floor(std::log2(s)))); }

}  // namespace

// The CoC pass (dof_map.cpp's per-pixel loop and near_field_raise's band
// loop) over one row. The band floor(log2 s), at least 0: s = 2^e (1 + f),
// f the mantissa's fraction, log2 s = e + log2(1 + f). For e < 0 the floor is
// negative or 0 whatever log2f rounds to, so the band is 0. For 0 <= e <= 127
// and 2^-14 <= f <= 1 - 2^-14, log2 s lies at least 4.4e-5 from the integers
// e and e + 1, more than five of log2f's ulps there (<= 2^-17 below 128):
// any log2f within a few ulps floors to e. The rest (f within 2^-14 of an
// octave's edge: exact powers of two, a cap such as --coc-limit 16; e = 128:
// an infinite scale) call log2f as the reference does.
void DofCocRowK(const DofCocRow& r, DofCocStats& st) {
  const hn::ScalableTag<float> d;
  const hn::RebindToSigned<decltype(d)> di;
  const hn::Rebind<std::int8_t, decltype(d)> d8;
  const int N = static_cast<int>(hn::Lanes(d)), W = r.width;
  constexpr int kMax = HWY_MAX_BYTES / sizeof(float);
  const auto alpha = hn::Set(d, r.alpha), zf = hn::Set(d, r.zf), s0 = hn::Set(d, r.s0), limit = hn::Set(d, r.limit);
  const auto s0s0 = hn::Set(d, r.s0 * r.s0), quarter2 = hn::Set(d, 0.0625f), zero = hn::Zero(d);
  const auto inf = hn::Set(d, INFINITY);
  const auto exp_bias = hn::Set(di, 127), mant_bits = hn::Set(di, 0x7FFFFF), izero = hn::Zero(di);
  const auto f_lo = hn::Set(di, 1 << 9), f_hi = hn::Set(di, (1 << 23) - (1 << 9)), none = hn::Set(di, -1);
  auto zmin = inf, zmax = zero;
  auto jmin = hn::Set(di, INT_MAX), jmax = none;
  long unknown = 0, near = 0, capped = 0;
  int lo = -1, last = -1;
  for (int x = 0; x < W; x += N) {
    const int n = std::min(N, W - x);
    const auto valid = hn::FirstN(d, static_cast<std::size_t>(n));
    // The row's last vector through a copy (Highway's masked loads and
    // stores read and write whole vectors on SSE2/SSE4): lanes past the row
    // read 0 (unknown) and are left out of every count.
    alignas(HWY_MAX_BYTES) float zt[kMax] = {};
    if (n < N) std::memcpy(zt, r.z + x, static_cast<std::size_t>(n) * sizeof(float));
    const auto z = n == N ? hn::LoadU(d, r.z + x) : hn::Load(d, zt);
    const auto finite = hn::Lt(hn::Abs(z), inf);  // std::isfinite: NaN compares false
    const auto known = hn::And(finite, hn::Gt(z, zero));
    // brume_coc: alpha max(z - zf, zf - z) / z; unknown depth: alpha.
    const auto dp = hn::Sub(z, zf), dn = hn::Sub(zf, z);
    const auto c = hn::IfThenElse(known, hn::Div(hn::Mul(alpha, hn::IfThenElse(hn::Lt(dp, dn), dn, dp)), z), alpha);
    // brume_dof_scale: sqrt(s0 s0 + 0.0625 c c), then min(s, limit).
    const auto s = hn::Sqrt(hn::Add(s0s0, hn::Mul(hn::Mul(quarter2, c), c)));
    const auto sigma = hn::IfThenElse(hn::Lt(limit, s), limit, s);
    unknown += static_cast<long>(hn::CountTrue(d, hn::AndNot(known, valid)));
    near += static_cast<long>(hn::CountTrue(d, hn::And(known, hn::Lt(z, zf))));
    capped += static_cast<long>(hn::CountTrue(d, hn::And(valid, hn::Gt(s, limit))));
    zmin = hn::Min(zmin, hn::IfThenElse(known, z, inf));
    zmax = hn::Max(zmax, hn::IfThenElse(known, z, zero));
    if (n == N) {
      hn::StoreU(sigma, d, r.sigma + x);
    } else {
      hn::Store(sigma, d, zt);
      std::memcpy(r.sigma + x, zt, static_cast<std::size_t>(n) * sizeof(float));
    }
    // The band: finite depth nearer than zf, sigma above s0.
    const auto member = hn::And(valid, hn::And(hn::And(finite, hn::Lt(z, zf)), hn::Gt(sigma, s0)));
    const auto bits = hn::BitCast(di, sigma);
    const auto e = hn::Sub(hn::ShiftRight<23>(bits), exp_bias);
    const auto f = hn::And(bits, mant_bits);
    const auto imember = hn::RebindMask(di, member);
    auto j = hn::IfThenElse(imember, hn::Max(e, izero), none);
    const auto by_libm =
        hn::And(imember, hn::And(hn::Gt(e, none), hn::Or(hn::Lt(f, f_lo), hn::Gt(f, f_hi))));
    alignas(HWY_MAX_BYTES) std::int32_t jl[kMax];
    alignas(HWY_MAX_BYTES) std::int8_t bl[kMax];
    if (!hn::AllFalse(di, by_libm)) {
      alignas(HWY_MAX_BYTES) float sl[kMax];
      alignas(HWY_MAX_BYTES) std::int32_t ml[kMax];
      hn::Store(sigma, d, sl);
      hn::Store(j, di, jl);
      hn::Store(hn::VecFromMask(di, by_libm), di, ml);
      for (int l = 0; l < n; ++l) {
        if (ml[l]) jl[l] = band_by_log2(sl[l]);
        bl[l] = static_cast<signed char>(jl[l]);  // the reference's cast (> 127 only for an infinite scale)
      }
      j = hn::Load(di, jl);
      std::memcpy(r.band + x, bl, static_cast<std::size_t>(n));
    } else if (n == N) {
      hn::StoreU(hn::DemoteTo(d8, j), d8, r.band + x);
    } else {
      hn::Store(hn::DemoteTo(d8, j), d8, bl);
      std::memcpy(r.band + x, bl, static_cast<std::size_t>(n));
    }
    jmin = hn::Min(jmin, hn::IfThenElse(imember, j, hn::Set(di, INT_MAX)));
    jmax = hn::Max(jmax, j);
    if (!hn::AllFalse(d, member)) {
      if (lo < 0) lo = x + static_cast<int>(hn::FindFirstTrue(d, member));
      last = x;
    }
  }
  st.unknown = unknown;
  st.near = near;
  st.capped = capped;
  st.zmin = hn::GetLane(hn::MinOfLanes(d, zmin));
  st.zmax = hn::GetLane(hn::MaxOfLanes(d, zmax));
  st.jmin = hn::GetLane(hn::MinOfLanes(di, jmin));
  st.jmax = hn::GetLane(hn::MaxOfLanes(di, jmax));
  st.lo = st.hi = 0;
  if (lo >= 0) {
    int hi = std::min(W, last + N);
    while (r.band[hi - 1] < 0 && hi - 1 > lo) --hi;
    st.lo = lo;
    st.hi = hi;
  }
}

void DofBlurRowK(const float* s, const float* k, int taps, float* out, int x0, int x1) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  int x = x0;
  // Four vectors at a time (independent sums: the latency of one add hidden
  // by the others), then one, then the rest one value at a time (Highway's
  // masked loads and stores read and write whole vectors on SSE2/SSE4).
  for (; x + 4 * N <= x1; x += 4 * N) {
    auto a0 = hn::Zero(d), a1 = hn::Zero(d), a2 = hn::Zero(d), a3 = hn::Zero(d);
    for (int i = 0; i < taps; ++i) {
      const auto w = hn::Set(d, k[i]);
      const float* p = s + x + i;
      a0 = hn::Add(a0, hn::Mul(w, hn::LoadU(d, p)));
      a1 = hn::Add(a1, hn::Mul(w, hn::LoadU(d, p + N)));
      a2 = hn::Add(a2, hn::Mul(w, hn::LoadU(d, p + 2 * N)));
      a3 = hn::Add(a3, hn::Mul(w, hn::LoadU(d, p + 3 * N)));
    }
    hn::StoreU(a0, d, out + x);
    hn::StoreU(a1, d, out + x + N);
    hn::StoreU(a2, d, out + x + 2 * N);
    hn::StoreU(a3, d, out + x + 3 * N);
  }
  for (; x + N <= x1; x += N) {
    auto a = hn::Zero(d);
    for (int i = 0; i < taps; ++i) a = hn::Add(a, hn::Mul(hn::Set(d, k[i]), hn::LoadU(d, s + x + i)));
    hn::StoreU(a, d, out + x);
  }
  for (; x < x1; ++x) {
    float a = 0.0f;
    for (int i = 0; i < taps; ++i) a = a + k[i] * s[x + i];
    out[x] = a;
  }
}

void DofBlurColsK(const float* const* rows, const float* k, int taps, float* out, int x0, int x1) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  int x = x0;
  for (; x + 2 * N <= x1; x += 2 * N) {
    auto a0 = hn::Zero(d), a1 = hn::Zero(d);
    for (int i = 0; i < taps; ++i) {
      const auto w = hn::Set(d, k[i]);
      a0 = hn::Add(a0, hn::Mul(w, hn::LoadU(d, rows[i] + x)));
      a1 = hn::Add(a1, hn::Mul(w, hn::LoadU(d, rows[i] + x + N)));
    }
    hn::StoreU(a0, d, out + x);
    hn::StoreU(a1, d, out + x + N);
  }
  for (; x + N <= x1; x += N) {
    auto a = hn::Zero(d);
    for (int i = 0; i < taps; ++i) a = hn::Add(a, hn::Mul(hn::Set(d, k[i]), hn::LoadU(d, rows[i] + x)));
    hn::StoreU(a, d, out + x);
  }
  for (; x < x1; ++x) {
    float a = 0.0f;
    for (int i = 0; i < taps; ++i) a = a + k[i] * rows[i][x];
    out[x] = a;
  }
}

int DofBandValuesK(const signed char* band, const float* sigma, int j, float s0, float* out, int n) {
  const hn::ScalableTag<float> d;
  const hn::RebindToSigned<decltype(d)> di;
  const hn::Rebind<std::int8_t, decltype(d)> d8;
  const int N = static_cast<int>(hn::Lanes(d));
  const auto vj = hn::Set(di, j);
  const auto v0 = hn::Set(d, s0);
  std::size_t members = 0;
  int x = 0;
  for (; x + N <= n; x += N) {
    const auto b = hn::PromoteTo(di, hn::LoadU(d8, reinterpret_cast<const std::int8_t*>(band) + x));
    const auto in = hn::RebindMask(d, hn::Eq(b, vj));
    hn::StoreU(hn::IfThenElse(in, hn::LoadU(d, sigma + x), v0), d, out + x);
    members += hn::CountTrue(d, in);
  }
  for (; x < n; ++x) {
    const bool in = band[x] == j;
    out[x] = in ? sigma[x] : s0;
    members += in;
  }
  return static_cast<int>(members);
}

void DofMaxRowK(float* v, const float* r, int n) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  int x = 0;
  for (; x + N <= n; x += N) {
    const auto a = hn::LoadU(d, v + x), b = hn::LoadU(d, r + x);
    hn::StoreU(hn::IfThenElse(hn::Lt(a, b), b, a), d, v + x);
  }
  for (; x < n; ++x) v[x] = v[x] < r[x] ? r[x] : v[x];
}

void DofMaxLerpK(float* v, const float* t, const float* b, float a, int n) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  const auto va = hn::Set(d, a);
  int x = 0;
  for (; x + N <= n; x += N) {
    const auto tt = hn::LoadU(d, t + x);
    const auto u = hn::Add(tt, hn::Mul(va, hn::Sub(hn::LoadU(d, b + x), tt)));
    const auto w = hn::LoadU(d, v + x);
    hn::StoreU(hn::IfThenElse(hn::Lt(w, u), u, w), d, v + x);
  }
  for (; x < n; ++x) {
    const float u = t[x] + a * (b[x] - t[x]);
    v[x] = v[x] < u ? u : v[x];
  }
}

void DofCapRowK(float* v, float limit, int n) {
  const hn::ScalableTag<float> d;
  const int N = static_cast<int>(hn::Lanes(d));
  const auto l = hn::Set(d, limit);
  int x = 0;
  for (; x + N <= n; x += N) {
    const auto a = hn::LoadU(d, v + x);
    hn::StoreU(hn::IfThenElse(hn::Lt(a, l), a, l), d, v + x);  // std::min(limit, v): v < limit ? v : limit
  }
  for (; x < n; ++x) v[x] = v[x] < limit ? v[x] : limit;
}

}  // namespace HWY_NAMESPACE
}  // namespace brume::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace brume::detail {
HWY_EXPORT(DofCocRowK);
HWY_EXPORT(DofBlurRowK);
HWY_EXPORT(DofBlurColsK);
HWY_EXPORT(DofBandValuesK);
HWY_EXPORT(DofMaxRowK);
HWY_EXPORT(DofMaxLerpK);
HWY_EXPORT(DofCapRowK);

void dof_coc_row(const DofCocRow& r, DofCocStats& s) { HWY_DYNAMIC_DISPATCH(DofCocRowK)(r, s); }
void dof_blur_row(const float* s, const float* k, int taps, float* out, int x0, int x1) {
  HWY_DYNAMIC_DISPATCH(DofBlurRowK)(s, k, taps, out, x0, x1);
}
void dof_blur_cols(const float* const* rows, const float* k, int taps, float* out, int x0, int x1) {
  HWY_DYNAMIC_DISPATCH(DofBlurColsK)(rows, k, taps, out, x0, x1);
}
int dof_band_values(const signed char* band, const float* sigma, int j, float s0, float* out, int n) {
  return HWY_DYNAMIC_DISPATCH(DofBandValuesK)(band, sigma, j, s0, out, n);
}
void dof_max_row(float* v, const float* r, int n) { HWY_DYNAMIC_DISPATCH(DofMaxRowK)(v, r, n); }
void dof_max_lerp(float* v, const float* t, const float* b, float a, int n) {
  HWY_DYNAMIC_DISPATCH(DofMaxLerpK)(v, t, b, a, n);
}
void dof_cap_row(float* v, float limit, int n) { HWY_DYNAMIC_DISPATCH(DofCapRowK)(v, limit, n); }
}  // namespace brume::detail
#endif  // HWY_ONCE
