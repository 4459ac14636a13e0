// brume — per-pixel maths of the haze effect (Hansard eq. 1, 4, 7).
//
// Written once in the common subset of C++ and GLSL ES 3.00 (float scalars,
// no pointers, no templates, explicit float literals): the CPU backend
// includes it through prelude_cpp.h and the GPU backend embeds the same text
// in the shaders of the passes that declare this topic, so both backends
// share the maths and differ only in the schedule.
//
// Units: ranges normalised by R_max (R' = R / R_max), coefficients
// normalised the other way (kappa' = kappa R_max), scales in pixels.

// Beer-Lambert transmission (Hansard eq. 1): tau = exp(-(kappa_a + kappa_s) R).
BRUME_FN float brume_transmission(float kappa_total_norm, float range_norm) {
  return exp(-kappa_total_norm * range_norm);
}

// Largest blur scale (Hansard eq. 7): sigma_max = sigma0 + lambda sqrt(kappa_s').
BRUME_FN float brume_sigma_max(float sigma0, float lambda, float kappa_s_norm) {
  return sigma0 + lambda * sqrt(kappa_s_norm);
}

// Target scale (Hansard eq. 7), the R^{3/2} law that approximates Premoze's
// multiple-scattering blur (eq. 5-6). R' is clamped to [0, 1] here: points
// beyond R_max (sky) get sigma_max, never more.
BRUME_FN float brume_target_scale(float range_norm, float sigma0, float sigma_max) {
  float r = clamp(range_norm, 0.0f, 1.0f);
  return sigma0 + r * sqrt(r) * (sigma_max - sigma0);
}

// Premultiplied composite with airlight (Hansard eq. 4), one channel:
// out = F + (1 - alpha) B, alpha the *blurred* transmission.
BRUME_FN float brume_composite_premultiplied(float f, float alpha, float airlight) {
  return f + (1.0f - alpha) * airlight;
}

// The naive, non-premultiplied composite the paper warns against (ghost
// edges): out = tau0 E_blurred + (1 - tau0) B with the unblurred tau0.
BRUME_FN float brume_composite_naive(float e_blurred, float tau0, float airlight) {
  return tau0 * e_blurred + (1.0f - tau0) * airlight;
}

// The sky in physical units (brume/haze.hpp, "The sky"): a pixel of the
// preparation's sky weight w (0 on the scene, 1 on the sky beyond the
// horizon margin, harmonic across the margin) takes the transmission
// (1 - w) tau_scene + w tau_sky, tau_scene that of its prepared range and
// tau_sky the sky's own (0 at infinity, exp(-beta M) at --sky-distance M).
// The ends are exact: w <= 0 keeps tau_scene, w >= 1 gives tau_sky.
BRUME_FN float brume_sky_blend(float tau_scene, float tau_sky, float w) {
  if (w <= 0.0f) return tau_scene;
  if (w >= 1.0f) return tau_sky;
  return (1.0f - w) * tau_scene + w * tau_sky;
}

// A medium drawn in part as particles (rain's drops, snow's flakes; brume/rain.hpp, "Extinction
// counted once"): what the camera's particles do not draw is analytic, its optical depth to range r
// along a ray whose cos theta = z/r is sigma r - G(min(r cos theta, z_split)) / cos theta, never
// below 0, with G(z) = g_start + sigma_drawn (z - z_start) on z's step of the tabulated, piecewise
// linear G (z_start the step's start, g_start = G there, sigma_drawn the drawn particles' optical
// depth per metre on it). Ranges in metres, coefficients per metre.
BRUME_FN float brume_particles_optical_depth(float sigma, float r, float cos_theta, float g_start, float sigma_drawn,
                                             float z_start, float z) {
  float g = g_start + sigma_drawn * max(0.0f, z - z_start);
  return max(0.0f, sigma * r - g / cos_theta);
}
