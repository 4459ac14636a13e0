// Lets the per-pixel maths in src/shared/*.glsl compile as C++.
// GLSL ES 3.20 has float scalars, exp/sqrt/floor/clamp/mix built in and
// passes by value; this prelude gives C++ the same vocabulary, so the same
// source text is compiled by the CPU backend and embedded in the shaders.
// C++ sees every topic at once (brume::shared::...); a GPU pass declares the
// topics it needs (src/gpu/context.hpp, PassSpec). A new topic file is added
// here, to BRUME_SHADERS in CMakeLists.txt and to the topic table in
// src/gpu/context.cpp.
#pragma once
#include <cmath>

namespace brume::shared {
#define BRUME_FN inline
// The stencil update takes any vector and weight type on the CPU (see diffusion_math.glsl).
#define BRUME_STENCIL_FN template <class brume_vec, class brume_weight> inline
using std::acos;
// A struct argument: by const reference in C++, by value (`in`) in GLSL.
#define BRUME_IN(T) const T&
using std::abs;
using std::cos;
using std::exp;
using std::floor;
using std::log;
using std::sin;
using std::sqrt;
using std::tan;
inline float clamp(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
inline float min(float a, float b) { return b < a ? b : a; }
inline float max(float a, float b) { return a < b ? b : a; }
inline float mix(float a, float b, float t) { return a + t * (b - a); }
// GLSL's two-argument atan(y, x) is C's atan2.
inline float atan(float y, float x) { return std::atan2(y, x); }
#include "shared/diffusion_math.glsl"
#include "shared/haze_math.glsl"
#include "shared/aerial_math.glsl"
#include "shared/sky_math.glsl"
// The CPU holds density tables of up to 1024 rows (the GPU 32).
#define BRUME_FOG_MAX_KNOTS 1024
#include "shared/fog_math.glsl"
#include "shared/depth_math.glsl"
#include "shared/dof_math.glsl"
#undef BRUME_FN
#undef BRUME_STENCIL_FN
#undef BRUME_IN
}  // namespace brume::shared
