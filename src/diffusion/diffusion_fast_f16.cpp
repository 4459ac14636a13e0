// brume — binary16 storage for the constant-scale diffusion path (x86-64 with
// F16C). Its functions are compiled for AVX2 and F16C (the target pragma
// below) and only entered after a run-time check, so the rest of the library
// keeps running on any x86-64.
//
// Why a pragma after the includes rather than -mavx2 -mf16c for the file
// (as until 2026-12-03): the headers' inline functions (mirror, eq11,
// StoreF32, std::vector's members, ...) are then compiled for the baseline
// here too. With the flags, a build that does not inline them (GCC 12 at
// -O0 and -Og: 151 and 20 such functions; clang 14 at -O0) emitted AVX2
// copies of them as weak symbols (eq11, StoreF32's load and store, the
// stencil update), and the linker may keep that copy for every caller in the
// library: an illegal instruction on an x86-64 without AVX2. Functions
// defined after the pragma get the target (lambdas and OpenMP bodies
// included); the header templates instantiated here keep the baseline, and
// could then only call StoreF16's loads and stores, not inline them -- so
// uniform_border_pixel, the one such template in a loop here, is always
// inlined (into the AVX2 row), and the row writes the stencil update's
// expression itself (below). Same bits and time as before (f16 constant
// sigma 25, 1600x1120, 2 threads, Zen 4, six rounds alternated: 36.5 and
// 36.7 ms median). The test
// build_f16_kernels_leave_shared_code_at_baseline
// (tests/check_target_isolation.sh) checks the weak symbols.
//
// Hansard §5.3 measures RGBA16F about twice as fast as RGBA32F on a GPU; the
// same holds here because the constant-scale iteration is memory-bound: F is
// read and written as 8 bytes per pixel instead of 16. The arithmetic is the
// float path's, term by term, and every stored value is rounded to nearest
// binary16 exactly as round_to_half does, so the result is bit-identical to
// the float-storage f16 path. The schedule is the float path's too: the
// groups of iterations that share a pass (diffusion_fusion.hpp), planned by
// the caller with 2-byte values.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>

#include "diffusion/half.hpp"
#include "diffusion/diffusion_fusion.hpp"
#include "diffusion/diffusion_rows.hpp"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>

#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx2,f16c"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx2,f16c")
#endif

namespace brume::cpu {
namespace {

struct StoreF16 {
  using T = std::uint16_t;
  static v4 load(const std::uint16_t* p) {
    __m128 f = _mm_cvtph_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)));
    v4 v;
    std::memcpy(&v, &f, sizeof v);
    return v;
  }
  static void store(std::uint16_t* p, v4 v) {
    __m128 f;
    std::memcpy(&f, &v, sizeof f);
    _mm_storel_epi64(reinterpret_cast<__m128i*>(p), _mm_cvtps_ph(f, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC));
  }
};

inline __m256 ld8(const std::uint16_t* p) {
  return _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
}

// uniform_row_body of diffusion_fast_kernels.cpp on binary16 storage, 8
// floats (two RGBA pixels) per step, same operation order.
void row_interior_f16(const std::uint16_t* s, const std::uint16_t* u0, const std::uint16_t* u1,
                      const std::uint16_t* d0, const std::uint16_t* d1, std::uint16_t* o, std::size_t begin,
                      std::size_t end, std::ptrdiff_t n4, float fr, float w) {
  const __m256 vf = _mm256_set1_ps(fr), vw = _mm256_set1_ps(w);
  auto lerp = [&](__m256 a, __m256 b) { return _mm256_add_ps(a, _mm256_mul_ps(vf, _mm256_sub_ps(b, a))); };
  std::size_t i = begin;
  for (; i + 8 <= end; i += 8) {
    const __m256 fc = ld8(s + i);
    const __m256 l = lerp(ld8(s + i - n4), ld8(s + i - n4 - 4));
    const __m256 r = lerp(ld8(s + i + n4), ld8(s + i + n4 + 4));
    const __m256 u = lerp(ld8(u0 + i), ld8(u1 + i));
    const __m256 d = lerp(ld8(d0 + i), ld8(d1 + i));
    // brume_diffusion_update's expression, term by term (as the AVX2 and
    // AVX-512 rows of diffusion_fast_kernels.cpp write it): the shared
    // template, instantiated outside the target pragma, would take 256-bit
    // vectors across a baseline call, which clang refuses (it changes the ABI).
    const __m256 acc = fc + vw * (l - fc) + vw * (r - fc) + vw * (u - fc) + vw * (d - fc);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(o + i), _mm256_cvtps_ph(acc, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC));
  }
  for (; i < end; i += 4) {  // (end - begin) is a multiple of 4: one pixel at a time
    const v4 fc = StoreF16::load(s + i);
    const v4 a = StoreF16::load(s + i - n4), b = StoreF16::load(s + i + n4);
    const v4 l = a + fr * (StoreF16::load(s + i - n4 - 4) - a);
    const v4 r = b + fr * (StoreF16::load(s + i + n4 + 4) - b);
    const v4 c = StoreF16::load(u0 + i), e = StoreF16::load(d0 + i);
    const v4 u = c + fr * (StoreF16::load(u1 + i) - c);
    const v4 d = e + fr * (StoreF16::load(d1 + i) - e);
    StoreF16::store(o + i, brume_diffusion_update(fc, l, r, u, d, w, w, w, w));
  }
}

}  // namespace

bool uniform_iterations_f16(float* f, int W, int H, const std::vector<UniformStep>& steps,
                            const std::vector<FusedGroup>& groups, int threads, std::uint16_t* a, std::uint16_t* b,
                            std::uint16_t* ring) {
  static const bool supported = __builtin_cpu_supports("avx2") && cpu_has_f16c();
  if (!supported) return false;
  const std::size_t Ws = static_cast<std::size_t>(W);
  // F arrives rounded to binary16 already, so this conversion is exact.
#pragma omp parallel for num_threads(threads) schedule(static)
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
  const std::uint16_t* res = uniform_iterations_fused(a, b, W, H, steps, groups, threads, ring, row);
#pragma omp parallel for num_threads(threads) schedule(static)
  for (int y = 0; y < H; ++y)
    for (std::size_t i = y * Ws * 4; i < (y + 1) * Ws * 4; i += 4) StoreF32::store(f + i, StoreF16::load(res + i));
  return true;
}

}  // namespace brume::cpu

#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif

#else  // not x86-64: the float-storage path rounds to binary16 instead

namespace brume::cpu {
bool uniform_iterations_f16(float*, int, int, const std::vector<UniformStep>&, const std::vector<FusedGroup>&, int,
                            std::uint16_t*, std::uint16_t*, std::uint16_t*) {
  return false;
}
}  // namespace brume::cpu

#endif
