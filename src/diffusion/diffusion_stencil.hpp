// brume — the one update formula of every diffusion stencil (internal).
//
// brume_diffusion_update is defined once, in src/diffusion/diffusion_math.glsl,
// in the common subset of C++ and GLSL: the GPU's diffuse pass calls the same
// text with vec4/float, and on the CPU it is a template over the vector and
// weight types, so the reference (double), the fast path (float, four-float
// vectors) and the f16 rows (eight-float AVX vectors) all evaluate that one
// expression in that one order and agree bit for bit where their inputs agree.
#pragma once

#include "shared/prelude_cpp.h"

namespace brume::cpu {

using brume::shared::brume_diffusion_update;

}  // namespace brume::cpu
