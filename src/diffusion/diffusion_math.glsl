// brume — per-pixel maths of the diffusion engine (Hansard §3, eq. 11-18):
// the rates, the edge rate and the neighbour offsets of the stencil.
//
// Written once in the common subset of C++ and GLSL ES 3.00 (float scalars,
// no pointers, explicit float literals; the one template, the stencil update
// below, is spelled with macros that are empty in GLSL): the CPU backend
// includes it through prelude_cpp.h and the GPU backend embeds the same text
// in the shaders of the passes that declare this topic, so both backends
// share the maths and differ only in the schedule.
//
// Scales in pixels, rates per iteration, N the iteration count.

// Per-pixel rate of the standard scheme (eq. 13): rho = (sigma^2 - s0^2)/(2N).
BRUME_FN float brume_standard_rate(float sigma, float sigma0, float iterations) {
  return (sigma * sigma - sigma0 * sigma0) / (2.0f * iterations);
}

// Per-pixel rate of the invariant schemes (eq. 18): rho = ln(sigma/s0)/N.
BRUME_FN float brume_invariant_rate(float sigma, float sigma0, float iterations) {
  return log(sigma / sigma0) / iterations;
}

// Rate on the edge between a pixel (rate rho_c) and its neighbour sample
// (rate rho_n): the coefficient of the flux F(x+u) - F(x) in eq. 11.
//   mode 0, mean (eq. 12, the paper): (rho_c + rho_n) / 2. A near pixel with
//     rate 0 still receives half its far neighbour's rate, so a blurred
//     background leaks into the edge of a sharp foreground object.
//   mode 1, min: min(rho_c, rho_n). No flux into or out of a pixel whose
//     rate is 0: the sharp side stays sharp and unmixed.
//   mode 2, harmonic: 2 rho_c rho_n / (rho_c + rho_n), the series
//     conductance of finite-volume schemes for heterogeneous media; 0 when
//     either rate is 0, close to the mean where the rates vary smoothly.
// All three equal rho where rho_c = rho_n, so a constant target scale gives
// the same Gaussian whatever the mode.
// (Harmonic: the denominator is kept >= 1e-30 so that two zero rates give 0
// without a branch; any sum above that is used as is.)
BRUME_FN float brume_edge_rate(float rho_c, float rho_n, int mode) {
  if (mode == 1) return min(rho_c, rho_n);
  if (mode == 2) return 2.0f * rho_c * rho_n / max(rho_c + rho_n, 1.0e-30f);
  return 0.5f * (rho_c + rho_n);
}

// Rate of a neighbour sample that linear interpolation takes from two texels,
// r0 with weight 1 - f and r1 with weight f (the invariant schemes' taps at
// +-h_k), before brume_edge_rate pairs it with the centre's rate.
//   mode 0, mean (the paper): the interpolated rate, mix(r0, r1, f).
//   modes 1 and 2, min and harmonic: the smaller rate of the texels the tap
//     reads (r0 alone when f = 0). A tap straddling a depth edge blends a
//     sharp texel (rate 0) into F's sample; with the interpolated rate it
//     still carried a non-zero weight, so the sharp object's colour reached
//     the blurred side as thin streaks at the offsets h_k (1.1-2.8 % in
//     `brume study diffusion`'s leakage scene). With the smaller texel rate
//     such a tap carries nothing, as the standard scheme's unit taps do.
//     Where the two rates are equal (a constant target scale) it is that
//     rate, so the Gaussian is unchanged; where they vary smoothly it departs
//     from the interpolation by at most |r1 - r0|, one texel's change.
BRUME_FN float brume_tap_rate(float r0, float r1, float f, int mode) {
  if (mode == 0) return r0 + f * (r1 - r0);
  return f > 0.0f ? min(r0, r1) : r0;
}

// (e^{2 rho} - 1) / (2 rho) with its limit 1 at rho -> 0: the factor by which
// the exact step variance sigma_k^2 (e^{2 rho} - 1) exceeds the published
// scheme's 2 rho sigma_k^2. The series is used below 1e-3, where the direct
// form loses digits to cancellation (error < 1e-9 there).
BRUME_FN float brume_step_variance_ratio(float rho) {
  float x = 2.0f * rho;
  if (x < 1.0e-3f) return 1.0f + x * (0.5f + x / 6.0f);
  return (exp(x) - 1.0f) / x;
}

// Offset h whose linearly interpolated two-tap sample has second moment m:
// h^2 + f(1 - f) = m with f = frac(h). The left side is the piecewise-linear
// interpolation of h^2 between integers, so with n = floor(sqrt(m)) the
// solution is h = (m + n(n + 1)) / (2n + 1). Exact for every m >= 0.
// (floor(sqrt(m)) is written as a truncating conversion, equal for m >= 0,
// so that the CPU loop over a row vectorises without SSE4.1's round.)
BRUME_FN float brume_offset_for_moment(float m) {
  float n = float(int(sqrt(m)));
  return (m + n * (n + 1.0f)) / (2.0f * n + 1.0f);
}

// Neighbour offset at iteration k for a pixel whose current scale is sigma_k
// and whose rate is rho. Published scheme (eq. 18): h = sigma_k. Exact
// variant: h such that 2 rho (h^2 + f(1-f)) = sigma_k^2 (e^{2 rho} - 1).
BRUME_FN float brume_invariant_offset(float sigma_k, float rho, bool exact) {
  if (!exact) return sigma_k;
  return brume_offset_for_moment(sigma_k * sigma_k * brume_step_variance_ratio(rho));
}

// The one update of every diffusion stencil (Hansard eq. 11; Bertalmio et
// al.'s I <- I + 1/4 div^-(g grad^+ I) with per-edge conductance):
//   F' = F + w_l (F_l - F) + w_r (F_r - F) + w_u (F_u - F) + w_d (F_d - F)
// F_l .. F_d the four neighbour samples (unit offsets, or interpolated at
// +-h_k for the invariant schemes), w_l .. w_d the weights on the four edges.
// Written as differences against the centre (never (1 - sum w) F + sum w F_n)
// so that a pixel whose four weights are 0 comes back bit for bit and a
// constant image stays constant. Evaluated left to right (l, r, u, d) with
// no contraction, so every path that feeds it equal inputs agrees bit for
// bit. brume_vec/brume_weight are vec4/float in GLSL; in C++ they are
// template parameters (float, double, four- and eight-float vectors), so the
// reference, fast and f16 paths evaluate this very expression.
BRUME_STENCIL_FN brume_vec brume_diffusion_update(brume_vec fc, brume_vec l, brume_vec r, brume_vec u, brume_vec d,
                                                  brume_weight wl, brume_weight wr, brume_weight wu, brume_weight wd) {
  return fc + wl * (l - fc) + wr * (r - fc) + wu * (u - fc) + wd * (d - fc);
}
