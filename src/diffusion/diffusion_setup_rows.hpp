// brume — the per-pixel set-up of the fast path's invariant schemes
// (internal), written once and compiled for every SIMD target by
// diffusion_fast_kernels.cpp, whose options it needs (-fno-math-errno,
// -ffp-contract=off: cmake/brume_engine.cmake).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstring>

#include "diffusion/diffusion_setup_math.hpp"

namespace brume::cpu {

// The per-pixel set-up of the invariant schemes, vectorised (eight floats a
// step; diffusion_setup_math.hpp): the rates ln(sigma / sigma0) / N of eq.
// 18 (brume_invariant_rate's operations with its log), and a space-variant
// map's growth e^rho and variance ratio (brume_step_variance_ratio's;
// setup_math::growth_and_ratio8). The
// last < 8 values go through the same vector code, padded. Always inlined
// into the reference rows' and every SIMD target's set-up
// (diffusion_fast_kernels.cpp: RowKernels::rates and ::growth; same
// operations, same bits).
namespace setup {
using setup_math::v8f;
// Whole vectors by fixed-size copies (one vector load or store); only the
// last < 8 values go through a padded copy (a variable-length copy into a
// vector on the stack defeats store-to-load forwarding: 4.9 ns a value
// instead of 1.2 when every vector went that way).
__attribute__((always_inline)) inline v8f load8(const float* p, std::size_t m, float pad) {
  v8f v;
  if (m == 8) {
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  float t[8];
  for (std::size_t j = 0; j < 8; ++j) t[j] = j < m ? p[j] : pad;
  std::memcpy(&v, t, sizeof v);
  return v;
}
__attribute__((always_inline)) inline void store8(float* p, v8f v, std::size_t m) {
  if (m == 8) {
    std::memcpy(p, &v, sizeof v);
    return;
  }
  float t[8];
  std::memcpy(t, &v, sizeof v);
  for (std::size_t j = 0; j < m; ++j) p[j] = t[j];
}
__attribute__((always_inline)) inline void rates_body(const float* s, float* rho, std::size_t n, float s0, float Nf) {
  for (std::size_t i = 0; i < n; i += 8) {
    const std::size_t m = std::min<std::size_t>(8, n - i);
    store8(rho + i, setup_math::logf8(load8(s + i, m, s0) / s0) / Nf, m);
  }
}
__attribute__((always_inline)) inline void growth_body(const float* rho, float* g, float* vr, std::size_t n) {
  for (std::size_t i = 0; i < n; i += 8) {
    const std::size_t m = std::min<std::size_t>(8, n - i);
    v8f gv, rv;
    setup_math::growth_and_ratio8(load8(rho + i, m, 0.0f), gv, rv);
    store8(g + i, gv, m);
    store8(vr + i, rv, m);
  }
}
}  // namespace setup
}  // namespace brume::cpu
