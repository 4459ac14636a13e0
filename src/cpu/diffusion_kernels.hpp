// brume — CPU schedules of the diffusion schemes (internal).
//
// The algorithm is stated in include/brume/diffusion.hpp and the per-pixel
// formulas in src/shared/haze_math.glsl; this header declares the two CPU
// schedules of it: a plain double-precision reference and the fast float path.
#pragma once

#include "brume/diffusion.hpp"

namespace brume::cpu {

// Half-sample mirror of an index into [0, n): ... 2 1 0 | 0 1 2 ... n-1 | n-1 ...
inline int mirror(int i, int n) {
  if (i >= 0 && i < n) return i;
  const int period = 2 * n;
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - 1 - i;
}

// Both take a validated F (4 channels), sigma map, plan and parameters.
void diffuse_reference(Image& f, const Image& sigma, const DiffusionPlan& plan,
                       const DiffusionParams& p);
void diffuse_fast(Image& f, const Image& sigma, const DiffusionPlan& plan,
                  const DiffusionParams& p, int threads);

// Round n floats to the nearest IEEE binary16 value (ties to even), in place.
void round_to_half(float* v, std::size_t n);

}  // namespace brume::cpu
