// brume — the fast CPU schedule of layered fog (internal): the exponential
// profile without blur, a renderer's per-frame case (issue #12's benchmark),
// one image row at a time as vector code. The algorithm is
// src/effects/fog/fog_math.glsl's with the mean density multiplied out (one
// exponential per pixel, not two) and e^x from AttenuationTable::exp_f
// (brume/aerial.hpp: f32 polynomial, relative error <= 1e-7, vectorisable)
// instead of libm's expf; fog_fast.cpp states the resulting bound.
#pragma once

#include <cstddef>

#include "brume/fog.hpp"

namespace brume::detail {

struct FogExpFrame {
  const float* rgb = nullptr;    // W x H x 3, linear
  const float* range = nullptr;  // W x H [m]; unknown (NaN, inf, 0) is sky
  float* out_rgb = nullptr;      // W x H x 3 (may not alias rgb)
  float* optical_depth = nullptr;
  float* transmission = nullptr;
  int width = 0;
  // brume_fog_ray_y's constants: second row of world_from_cv, cx, cy, 1/fx, 1/fy
  float r0 = 0, r1 = 0, r2 = 0, cx = 0, cy = 0, ifx = 0, ify = 0;
  // the density (FogDensity, exponential, d0 > 0) and the sky
  float d0 = 0, falloff = 0, exponent_c = 0;
  float sky_distance = 0;  // [m] diverging sky rays (looking level or down, or B = 0)
  bool sky_infinite = false;  // diverging sky rays: F = +inf instead
  float airlight[3] = {0, 0, 0};
};

// Row v of the frame: optical depth, transmission and composite.
void fog_exponential_row(const FogExpFrame& fr, int v);

// apply_fog itself; vector_rows = false forces the per-pixel loop (every
// profile; the vector rows' peer in tests/test_fog.cpp and bench/bench_fog.cpp).
void apply_fog_rows(DenseImageRef rgb, DenseImageRef range, const FogParams& p, const FogAnalysis& a, FogResult& out,
                    const Exec& exec, bool vector_rows, DenseImageRef sky_weight = {});

}  // namespace brume::detail
