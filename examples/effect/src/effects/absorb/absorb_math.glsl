// brume — per-pixel maths of `brume absorb`, the example effect
// (examples/effect/README.md): a purely absorbing medium between the camera
// and the scene.
//
// Written once in the common subset of C++ and GLSL ES 3.00 (float scalars,
// explicit float literals): the CPU path includes it through
// src/shared/prelude_cpp.h, and a GPU pass that declares this topic embeds the
// same text.
//
// Beer-Lambert with no in-scattering (Hansard eq. 1 with kappa_s = 0): a
// surface at range R [m] seen through a medium of absorption coefficient
// kappa_a [1/m] keeps T = exp(-kappa_a R) of its radiance and gains nothing
// (no airlight).
BRUME_FN float brume_absorb_transmittance(float kappa_a_per_m, float range_m) {
  return exp(-kappa_a_per_m * range_m);
}
