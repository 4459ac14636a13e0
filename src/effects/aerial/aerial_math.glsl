// brume — per-pixel maths of spectral aerial perspective (Morales eq. 3.11-3.13;
// include/brume/aerial.hpp states the model). Common subset of C++ and GLSL
// ES 3.00 (float scalars, explicit float literals): the CPU includes it through
// prelude_cpp.h, the GPU passes embed it (Topics: aerial_math).
//
// Every function works on one channel c of the sensitivity's space; Gamma is
// the table's value for the pixel's distance. The composite
// out = F + (1 - alpha) A is haze_math's brume_composite_premultiplied.

// Transfer factor rho of a re-render (eq. 3.13): Gamma2 / Gamma1, Gamma1
// floored at gamma_floor (a photo whose own haze left < floor of the scene's
// light carries no recoverable scene colour; the floor caps the gain 1/floor).
BRUME_FN float brume_aerial_rerender_rho(float gamma2, float gamma1, float gamma_floor) {
  return gamma2 / max(gamma1, gamma_floor);
}

// Clean radiance of a re-render, E' = I1 Iinf2 / Iinf1: eq. 3.13 scales the
// scene's illumination with the horizon (Iinf1 > 0, checked by the analysis).
BRUME_FN float brume_aerial_rerender_radiance(float i1, float airlight2, float airlight1) {
  return i1 * (airlight2 / airlight1);
}

// Remove (inverse of eq. 3.11): I0 = (I - Iinf (1 - Gamma)) / max(Gamma, floor).
// Below the floor the division would amplify the photo's noise by > 1/floor:
// the result is then an underestimate of I0's contrast, never an inf.
BRUME_FN float brume_aerial_remove(float i, float gamma, float airlight, float gamma_floor) {
  return (i - airlight * (1.0f - gamma)) / max(gamma, gamma_floor);
}

// Linear sRGB (D65) <-> CIE 1931 XYZ: IEC 61966-2-1's matrix M (4 decimals) and
// its exact inverse to 7 decimals (the standard's rounded inverse would leave a
// 1e-4 round-trip error; this one leaves f32 rounding):
// in XYZ sensitivity space the operator on linear sRGB is M diag(Gamma) M^-1.
BRUME_FN float brume_srgb_to_x(float r, float g, float b) { return 0.4124f * r + 0.3576f * g + 0.1805f * b; }
BRUME_FN float brume_srgb_to_y(float r, float g, float b) { return 0.2126f * r + 0.7152f * g + 0.0722f * b; }
BRUME_FN float brume_srgb_to_z(float r, float g, float b) { return 0.0193f * r + 0.1192f * g + 0.9505f * b; }
BRUME_FN float brume_xyz_to_r(float x, float y, float z) { return 3.2406255f * x - 1.5372080f * y - 0.4986286f * z; }
BRUME_FN float brume_xyz_to_g(float x, float y, float z) { return -0.9689307f * x + 1.8757561f * y + 0.0415175f * z; }
BRUME_FN float brume_xyz_to_b(float x, float y, float z) { return 0.0557101f * x - 0.2040211f * y + 1.0569959f * z; }
