// brume — per-pixel maths of depth of field (Bertalmio et al. eq. 1-2).
//
// Written once in the common subset of C++ and GLSL ES 3.00 (float scalars,
// no pointers, explicit float literals), like haze_math. The GPU passes of
// depth of field are the engine's own (rates from sigma, diffusion): the
// scale map is formed on the host, so no pass embeds this topic yet.
//
// Units: depths in metres (planar, along the optical axis), CoC diameters and
// scales in pixels.

// Thin-lens circle of confusion (eq. 1-2): c = alpha |Z - Zf| / Z, alpha the
// diameter at Z -> infinity, alpha = F^2 / (n (Zf - F)) converted to pixels.
// Z > 0; the caller takes unknown depth as infinitely far (c = alpha).
BRUME_FN float brume_coc(float alpha_px, float z, float zf) {
  return alpha_px * max(z - zf, zf - z) / z;
}

// Target scale of the diffusion for a CoC of diameter c on an input of inner
// scale sigma0: the Gaussian with the disc's second moment has sigma = c/4
// (a uniform disc of radius r has per-axis variance r^2/4 = c^2/16), added in
// variance to sigma0, then capped at `limit` (--coc-limit) so that a stray
// near pixel cannot set the iteration count.
BRUME_FN float brume_dof_scale(float coc_px, float sigma0, float limit) {
  float s = sqrt(sigma0 * sigma0 + 0.0625f * coc_px * coc_px);
  return min(s, limit);
}
