// brume — binary16 storage for the constant-scale diffusion path, and
// round_to_half, written once with Highway (core/simd.hpp) and compiled for
// every target; it stores
// binary16 only on the targets that convert float <-> binary16 in hardware
// with IEEE round-to-nearest-even (x86-64's F16C, part of Highway's AVX2
// and AVX-512 targets). On the others uniform_iterations_f16 returns false
// and the caller keeps binary16 values in float storage (round_to_half after
// every iteration), the bits this storage must match.
//
// Hansard §5.3 measures RGBA16F about twice as fast as RGBA32F on a GPU; the
// same holds here because the constant-scale iteration is memory-bound: F is
// read and written as 8 bytes per pixel instead of 16. The arithmetic is the
// float path's, term by term, and every stored value is rounded to nearest
// binary16 exactly as round_to_half does, so the result is bit-identical to
// the float-storage f16 path. The schedule is the float path's too: the
// groups of iterations that share a pass (diffusion_fusion.hpp), planned by
// the caller with 2-byte values.
//
// Target isolation: the headers' inline functions (mirror, eq11, StoreF32,
// std::vector's members, ...) are included before HWY_BEFORE_NAMESPACE and
// compiled for the baseline; only what is defined inside HWY_NAMESPACE
// (N_AVX2::..., N_AVX3::...) gets a target's instructions. The header
// templates instantiated here keep the baseline, and could then only call
// StoreF16's loads and stores, not inline them -- so uniform_border_pixel,
// the one such template in a loop here, is always inlined (into the
// target's row), and the row writes the stencil update's expression itself
// (below). tests/check_target_isolation.sh checks that no code outside a
// target's namespace holds AVX instructions, and no AVX2 code AVX-512 ones.
#include "core/simd.hpp"  // first: the targets

#ifndef BRUME_DIFFUSION_FAST_F16_SHARED
#define BRUME_DIFFUSION_FAST_F16_SHARED
#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

#include "core/schedule.hpp"
#include "diffusion/diffusion_fusion.hpp"
#include "diffusion/diffusion_rows.hpp"
#include "diffusion/half.hpp"
#endif

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "diffusion/diffusion_fast_f16.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace brume::cpu {
namespace HWY_NAMESPACE {
namespace {
namespace hn = hwy::HWY_NAMESPACE;

#undef BRUME_HWY_F16C
#if HWY_TARGET == HWY_AVX2 || HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
#define BRUME_HWY_F16C 1
#endif

#ifdef BRUME_HWY_F16C
// One RGBA pixel of binary16 bits as four floats (PromoteTo and DemoteTo:
// vcvtph2ps and vcvtps2ph, round to nearest even).
struct StoreF16 {
  using T = std::uint16_t;
  static v4 load(const std::uint16_t* p) {
    const hn::FixedTag<float, 4> d;
    const hn::Rebind<hwy::float16_t, decltype(d)> dh;
    HWY_ALIGN float f[4];
    hn::Store(hn::PromoteTo(d, hn::LoadU(dh, reinterpret_cast<const hwy::float16_t*>(p))), d, f);
    v4 v;
    std::memcpy(&v, f, sizeof v);
    return v;
  }
  static void store(std::uint16_t* p, v4 v) {
    const hn::FixedTag<float, 4> d;
    const hn::Rebind<hwy::float16_t, decltype(d)> dh;
    HWY_ALIGN float f[4];
    std::memcpy(f, &v, sizeof v);
    hn::StoreU(hn::DemoteTo(dh, hn::Load(d, f)), dh, reinterpret_cast<hwy::float16_t*>(p));
  }
};

// UniformRow of diffusion_fast_kernels.cpp on binary16 storage, at most 8
// floats (two RGBA pixels) a vector, same operation order.
void row_interior_f16(const std::uint16_t* s, const std::uint16_t* u0, const std::uint16_t* u1,
                      const std::uint16_t* d0, const std::uint16_t* d1, std::uint16_t* o, std::size_t begin,
                      std::size_t end, std::ptrdiff_t n4, float fr, float w) {
  const hn::CappedTag<float, 8> d;
  const hn::Rebind<hwy::float16_t, decltype(d)> dh;
  const std::size_t N = hn::Lanes(d);
  auto ld = [&](const std::uint16_t* p) { return hn::PromoteTo(d, hn::LoadU(dh, reinterpret_cast<const hwy::float16_t*>(p))); };
  const auto vf = hn::Set(d, fr), vw = hn::Set(d, w);
  auto lerp = [&](decltype(vf) a, decltype(vf) b) { return a + vf * (b - a); };
  std::size_t i = begin;
  for (; i + N <= end; i += N) {
    const auto fc = ld(s + i);
    const auto l = lerp(ld(s + i - n4), ld(s + i - n4 - 4));
    const auto r = lerp(ld(s + i + n4), ld(s + i + n4 + 4));
    const auto u = lerp(ld(u0 + i), ld(u1 + i));
    const auto dd = lerp(ld(d0 + i), ld(d1 + i));
    // brume_diffusion_update's expression, term by term (as
    // diffusion_fast_kernels.cpp's Stencil writes it): the shared template,
    // instantiated outside the target, cannot take this target's vectors.
    const auto acc = fc + vw * (l - fc) + vw * (r - fc) + vw * (u - fc) + vw * (dd - fc);
    hn::StoreU(hn::DemoteTo(dh, acc), dh, reinterpret_cast<hwy::float16_t*>(o + i));
  }
  for (; i < end; i += 4) {  // (end - begin) is a multiple of 4: one pixel at a time
    const v4 fc = StoreF16::load(s + i);
    const v4 a = StoreF16::load(s + i - n4), b = StoreF16::load(s + i + n4);
    const v4 l = a + fr * (StoreF16::load(s + i - n4 - 4) - a);
    const v4 r = b + fr * (StoreF16::load(s + i + n4 + 4) - b);
    const v4 c = StoreF16::load(u0 + i), e = StoreF16::load(d0 + i);
    const v4 u = c + fr * (StoreF16::load(u1 + i) - c);
    const v4 dd = e + fr * (StoreF16::load(d1 + i) - e);
    StoreF16::store(o + i, brume_diffusion_update(fc, l, r, u, dd, w, w, w, w));
  }
}
#endif  // BRUME_HWY_F16C

}  // namespace

// round_to_half on this target: eight values a vector where the target
// converts in hardware, else (and for the last < 8) the compiler's
// conversion through half_t (IEEE round to nearest even either way).
void RoundToHalf(float* v, std::size_t n) {
  std::size_t i = 0;
#ifdef BRUME_HWY_F16C
  const hn::CappedTag<float, 8> d;
  const hn::Rebind<hwy::float16_t, decltype(d)> dh;
  for (; i + hn::Lanes(d) <= n; i += hn::Lanes(d))
    hn::StoreU(hn::PromoteTo(d, hn::DemoteTo(dh, hn::LoadU(d, v + i))), d, v + i);
#endif
  for (; i < n; ++i) v[i] = static_cast<float>(static_cast<half_t>(v[i]));
}

// This target's binary16 iterations (exported below); false where it has no
// hardware conversion.
bool UniformIterationsF16(float* f, int W, int H, const std::vector<UniformStep>* steps,
                          const std::vector<FusedGroup>* groups, int threads, std::uint16_t* a, std::uint16_t* b,
                          std::uint16_t* ring) {
#ifdef BRUME_HWY_F16C
  const std::size_t Ws = static_cast<std::size_t>(W);
  // F arrives rounded to binary16 already, so this conversion is exact.
#pragma omp parallel for num_threads(threads) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (std::size_t i = y * Ws * 4; i < (y + 1) * Ws * 4; i += 4) StoreF16::store(a + i, StoreF32::load(f + i));
  // One row of one iteration, as diffusion_fast.cpp's float row: the vector
  // interior, then the mirrored border columns.
  auto row = [W](const std::uint16_t* s, const std::uint16_t* u0, const std::uint16_t* u1, const std::uint16_t* d0,
                 const std::uint16_t* d1, std::uint16_t* o, const UniformStep& st) {
    const int n = st.n;
    const int xa = std::min(n + 1, W), xb = std::max(W - n - 1, xa);
    row_interior_f16(s, u0, u1, d0, d1, o, static_cast<std::size_t>(xa) * 4, static_cast<std::size_t>(xb) * 4,
                     static_cast<std::ptrdiff_t>(n) * 4, st.fr, st.w);
    for (int x = 0; x < xa; ++x) uniform_border_pixel<StoreF16>(s, u0, u1, d0, d1, o, W, x, n, st.fr, st.w);
    for (int x = xb; x < W; ++x) uniform_border_pixel<StoreF16>(s, u0, u1, d0, d1, o, W, x, n, st.fr, st.w);
  };
  const std::uint16_t* res = uniform_iterations_fused(a, b, W, H, *steps, *groups, threads, ring, row);
#pragma omp parallel for num_threads(threads) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (std::size_t i = y * Ws * 4; i < (y + 1) * Ws * 4; i += 4) StoreF32::store(f + i, StoreF16::load(res + i));
  return true;
#else
  (void)f, (void)W, (void)H, (void)steps, (void)groups, (void)threads, (void)a, (void)b, (void)ring;
  return false;
#endif
}

}  // namespace HWY_NAMESPACE
}  // namespace brume::cpu
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace brume::cpu {
HWY_EXPORT(UniformIterationsF16);
HWY_EXPORT(RoundToHalf);

void round_to_half(float* v, std::size_t n) { HWY_DYNAMIC_DISPATCH(RoundToHalf)(v, n); }

bool uniform_iterations_f16(float* f, int W, int H, const std::vector<UniformStep>& steps,
                            const std::vector<FusedGroup>& groups, int threads, std::uint16_t* a, std::uint16_t* b,
                            std::uint16_t* ring) {
  return HWY_DYNAMIC_DISPATCH(UniformIterationsF16)(f, W, H, &steps, &groups, threads, a, b, ring);
}
}  // namespace brume::cpu
#endif  // HWY_ONCE
