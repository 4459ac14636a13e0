// brume — e^x and ln x of the fast diffusion path's per-pixel set-up
// (internal): the rates ln(sigma / sigma0) / N of eq. 18, the growth e^rho
// of sigma_k, and the exact scheme's variance ratio (e^{2 rho} - 1)/(2 rho).
//
// Why not std::exp / std::log: on a space-variant map those are three
// calls into glibc per pixel (expf twice, logf once), ~4 ns each on the
// hosts measured (2026-12-03, Zen 4: 26 ms of a 125 ms one-thread blur of
// 1600 x 1120, a fifth of it), and scalar. Here each is evaluated in double
// precision, eight lanes per vector (GCC's vector extension: the width the
// caller's target gives it), to a relative error below 1e-15, and rounded
// once to float. That is the correctly rounded float unless the exact value
// lies within ~1e-15 of a midpoint between two floats; exhaustive runs
// (2026-12-03) found every float of [0, 0.5] (e^x) and [1, 1e6) (ln x)
// correctly rounded, and the tests check every float of [1, 2) and strides
// through the rest (DiffusionSetupMath.*). glibc's expf and logf
// are not always correctly rounded (their stated bounds are 0.502 and 0.82
// ulp), so a rate or growth can differ from the std:: one in its last bit
// where glibc's was the wrong neighbour; results stay within the tests'
// tolerances against the double-precision reference, and no longer depend on
// which libm variant (FMA or not) a host loads. Every lane, every width and
// the scalar form (lane 0 of a broadcast) evaluate the same IEEE double
// operations in the same order (no contraction: compiled where
// -ffp-contract=off holds, or without FMA), so they agree bit for bit.
// The integer steps on the doubles' bits use unsigned shifts and no
// comparison: AVX2 has no 64-bit arithmetic shift, and GCC 12 took the
// 64-byte vectors' shifts and double comparisons lane by lane through
// general registers (the AVX2 set-up took 4 ns a pixel; the same integers
// either way, checked for every float on 2026-12-06).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

namespace brume::cpu::setup_math {

typedef double v8d __attribute__((vector_size(64)));
typedef std::int64_t v8l __attribute__((vector_size(64)));
typedef std::uint64_t v8ul __attribute__((vector_size(64)));
typedef float v8f __attribute__((vector_size(32)));
typedef std::int32_t v8i __attribute__((vector_size(32)));

template <class To, class From>
__attribute__((always_inline)) inline To bits_as(From v) {
  static_assert(sizeof(To) == sizeof(From));
  To t;
  std::memcpy(&t, &v, sizeof t);
  return t;
}
// True when every lane of a comparison result is true (-1).
__attribute__((always_inline)) inline bool all_lanes(v8i ok) {
  std::uint64_t q[4];
  std::memcpy(q, &ok, sizeof q);
  return (q[0] & q[1] & q[2] & q[3]) == ~std::uint64_t{0};
}
// 1.5 * 2^52: adding it to a double of magnitude < 2^51 rounds that to an
// integer k and leaves k in the low bits (bits(t) - bits(shift) = k).
constexpr double kShift = 0x1.8p52;

// e^x for eight floats given as doubles, |x| <= 80 (callers route other
// lanes to std::exp). x = k ln 2 + r with k = round(x / ln 2), |r| <= ln 2 / 2;
// ln 2 split so that k ln2_hi is exact; e^r by its Taylor series to r^13
// (remainder < 0.347^14 / 14! < 1e-17, relative), Estrin form; 2^k by the
// exponent bits.
__attribute__((always_inline)) inline v8d exp_lanes(v8d x) {
  const v8d shift = v8d{} + kShift;
  const v8d t = x * 0x1.71547652b82fep0 + shift;
  const v8d kd = t - shift;
  const v8d r = (x - kd * 0x1.62e42fee00000p-1) - kd * 0x1.a39ef35793c76p-33;
  // Estrin's scheme (pairs, then r^2, r^4, r^8): a dependency chain of 6
  // operations instead of Horner's 26, so consecutive vectors overlap.
  const v8d r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
  const v8d q0 = 1.0 + r, q1 = 1.0 / 2 + r * (1.0 / 6), q2 = 1.0 / 24 + r * (1.0 / 120),
            q3 = 1.0 / 720 + r * (1.0 / 5040), q4 = 1.0 / 40320 + r * (1.0 / 362880),
            q5 = 1.0 / 3628800 + r * (1.0 / 39916800), q6 = 1.0 / 479001600 + r * (1.0 / 6227020800.0);
  const v8d p = (q0 + q1 * r2 + (q2 + q3 * r2) * r4) + ((q4 + q5 * r2) + q6 * r4) * r8;
  const v8l k = bits_as<v8l>(t) - bits_as<v8l>(shift);
  return p * bits_as<v8d>(bits_as<v8ul>(k + 1023) << 52);
}

// ln x for eight positive normal floats given as doubles: x = m 2^e with
// m in [sqrt(1/2), sqrt(2)); ln m = 2 atanh(s), s = (m - 1)/(m + 1), |s| <=
// 0.1716, by its series to s^23 (remainder < 0.1716^25 / 25 < 1e-20);
// ln x = e ln 2 + ln m. m - 1 is exact, so x near 1 keeps its relative
// accuracy, and x = 1 gives 0 exactly.
__attribute__((always_inline)) inline v8d log_lanes(v8d x) {
  const v8l bits = bits_as<v8l>(x);
  v8l e = bits_as<v8l>((bits_as<v8ul>(bits) >> 52) & 0x7ff) - 1023;
  v8l mb = (bits & 0x000fffffffffffffLL) | 0x3ff0000000000000LL;  // m in [1, 2)
  // 1 where m > sqrt 2 (halve m, bump e): the sign bit of bits(sqrt 2) -
  // bits(m), two positive doubles, whose bits order as their values.
  const v8l big = bits_as<v8l>(bits_as<v8ul>(bits_as<std::int64_t>(1.4142135623730951) - mb) >> 63);
  mb = mb - (big << 52);
  e = e + big;
  const v8d m = bits_as<v8d>(mb);
  const v8d s = (m - 1.0) / (m + 1.0), z = s * s;
  const v8d z2 = z * z, z4 = z2 * z2, z8 = z4 * z4;  // Estrin's scheme, as in exp_lanes
  const v8d q0 = 1.0 + z * (1.0 / 3), q1 = 1.0 / 5 + z * (1.0 / 7), q2 = 1.0 / 9 + z * (1.0 / 11),
            q3 = 1.0 / 13 + z * (1.0 / 15), q4 = 1.0 / 17 + z * (1.0 / 19), q5 = 1.0 / 21 + z * (1.0 / 23);
  const v8d p = (q0 + q1 * z2 + (q2 + q3 * z2) * z4) + (q4 + q5 * z2) * z8;
  const v8d lnm = (s + s) * p;
  const v8d shift = v8d{} + kShift;
  const v8d ed = bits_as<v8d>(bits_as<v8l>(shift) + e) - shift;  // e as a double (|e| < 2^51)
  return ed * 0x1.62e42fefa39efp-1 + lnm;
}

// Eight floats' e^x and ln x, rounded once to float. Lanes outside the
// ranges above (|x| > 80; for ln, x not a positive normal finite float) take
// std::exp / std::log: no rate or growth of a valid map reaches them.
__attribute__((always_inline)) inline v8f expf8(v8f x) {
  v8f y = __builtin_convertvector(exp_lanes(__builtin_convertvector(x, v8d)), v8f);
  if (!all_lanes((x <= 80.0f) & (x >= -80.0f)))
    for (int j = 0; j < 8; ++j)
      if (!(std::fabs(x[j]) <= 80.0f)) y[j] = std::exp(x[j]);
  return y;
}
__attribute__((always_inline)) inline v8f logf8(v8f x) {
  v8f y = __builtin_convertvector(log_lanes(__builtin_convertvector(x, v8d)), v8f);
  if (!all_lanes((x >= 0x1p-126f) & (x <= 0x1.fffffep127f)))
    for (int j = 0; j < 8; ++j)
      if (!(x[j] >= 0x1p-126f && x[j] <= 0x1.fffffep127f)) y[j] = std::log(x[j]);
  return y;
}

// The scalar forms: lane 0 of a broadcast, the same operations.
inline float expf1(float x) { return expf8(v8f{} + x)[0]; }
inline float logf1(float x) { return logf8(v8f{} + x)[0]; }

// The growth e^rho and brume_step_variance_ratio (src/diffusion/
// diffusion_math.glsl) of eight rates, from one double-precision e^rho:
// e^{2 rho} is its square in double (2 rho is exact in float, and the
// square errs by < 3e-16), rounded once to float -- expf8(2 rho) but for
// near-ties (none on [0, 0.25], checked exhaustively: the tests), at half
// the cost. The ratio is then the shared formula's float operations: its
// series below 2 rho = 1e-3, else (e^{2 rho} - 1)/(2 rho).
__attribute__((always_inline)) inline void growth_and_ratio8(v8f rho, v8f& growth, v8f& ratio) {
  const v8d e = exp_lanes(__builtin_convertvector(rho, v8d));
  v8f e2 = __builtin_convertvector(e * e, v8f);
  growth = __builtin_convertvector(e, v8f);
  if (!all_lanes((rho <= 40.0f) & (rho >= -40.0f)))
    for (int j = 0; j < 8; ++j)
      if (!(std::fabs(rho[j]) <= 40.0f)) growth[j] = std::exp(rho[j]), e2[j] = std::exp(2.0f * rho[j]);
  const v8f x = 2.0f * rho;
  const v8f series = 1.0f + x * (0.5f + x / 6.0f);
  const v8f direct = (e2 - 1.0f) / x;
  ratio = x < 1.0e-3f ? series : direct;
}
inline float variance_ratio1(float rho) {
  v8f g, r;
  growth_and_ratio8(v8f{} + rho, g, r);
  return r[0];
}

}  // namespace brume::cpu::setup_math
