// brume — the wet ground's per-pixel maths for its GPU pass (brume/wet.hpp; wet_apply.frag):
// Fresnel's unpolarised reflectance, air to water, in float. The CPU's camera, the LiDAR and the
// record use wet.cpp's fresnel_air_to in double; tests/test_wet_gpu.cpp holds this one to it.
//   cos theta_t = sqrt(1 - sin^2 theta / n^2),
//   r_s = (cos theta - n cos theta_t)/(cos theta + n cos theta_t),
//   r_p = (n cos theta - cos theta_t)/(n cos theta + cos theta_t),  R_F = (r_s^2 + r_p^2)/2.
BRUME_FN float brume_wet_fresnel(float cos_theta, float n) {
  float ci = clamp(cos_theta, 0.0f, 1.0f);
  float s2 = max(0.0f, 1.0f - ci * ci);
  float ct = sqrt(max(0.0f, 1.0f - s2 / (n * n)));
  float rs = (ci - n * ct) / (ci + n * ct);
  float rp = (n * ci - ct) / (n * ci + ct);
  return 0.5f * (rs * rs + rp * rp);
}
