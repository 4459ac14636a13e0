// brume — the one update formula of every diffusion stencil (internal).
//
// Every scheme of the engine is one explicit step of the same conservative
// stencil (Hansard eq. 11; Bertalmio et al.'s I <- I + 1/4 div^-(g grad^+ I)):
//
//   F'(x) = F(x) + w_l (F_l - F(x)) + w_r (F_r - F(x)) + w_u (F_u - F(x)) + w_d (F_d - F(x))
//
// where F_l .. F_d are the four neighbour samples (unit offsets for the
// standard scheme and the per-edge conductance, interpolated at +-h_k for the
// invariant schemes) and w_l .. w_d the weights on the four edges. Written
// as a difference against the centre (never as (1 - sum w) F + sum w F_n) so
// that a pixel whose four weights are 0 is returned bit for bit, and a
// constant image stays constant whatever the weights.
//
// The body is in the common subset of C++ and GLSL ES 3.20; only the
// signature is a C++ template so that the reference (double), the fast path
// (float, and four-channel float vectors) and the f16 rows (eight-float AVX
// vectors) all evaluate this one expression, in this one order (l, r, u, d;
// left to right, no contraction under ISO C++), and so agree bit for bit
// where their inputs agree. The GLSL twin for src/shared/ is
//   BRUME_FN vec4 brume_diffusion_update(vec4 fc, vec4 l, vec4 r, vec4 u, vec4 d,
//                                        float wl, float wr, float wu, float wd)
// with the same body (left to the lead: src/shared/ is being split).
#pragma once

namespace brume::cpu {

template <class V, class S>
inline V brume_diffusion_update(V fc, V l, V r, V u, V d, S wl, S wr, S wu, S wd) {
  return fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc);
}

}  // namespace brume::cpu
