// brume — Preetham sky per-pixel maths (C++ and GLSL ES 3.00 at once).
//
// Preetham, Shirley, Smits, "A Practical Analytic Model for Daylight",
// SIGGRAPH 1999, Appendix A.2 (the table below is the paper's, 4 decimals;
// Morales 2014 eq. 1.7-1.8 repeats the Y row). For each of Y, x, y:
//   F(theta, gamma) = (1 + A e^{B / cos theta}) (1 + C e^{D gamma} + E cos^2 gamma)   (Perez 1993)
//   value(theta, gamma) = value_zenith F(theta, gamma) / F(0, theta_s)
// with theta the view zenith angle, gamma the angle between view and sun,
// theta_s the sun's zenith angle, all in radians; A..E linear in turbidity T:
//          A                  B                  C                  D                  E
//   Y   0.1787T-1.4630   -0.3554T+0.4275   -0.0227T+5.3251    0.1206T-2.5771   -0.0670T+0.3703
//   x  -0.0193T-0.2592   -0.0665T+0.0008   -0.0004T+0.2125   -0.0641T-0.8989   -0.0033T+0.0452
//   y  -0.0167T-0.2608   -0.0950T+0.0092   -0.0079T+0.2102   -0.0441T-1.6537   -0.0109T+0.0529
// Zenith luminance [kcd/m^2] and chromaticity (Preetham A.2):
//   chi = (4/9 - T/120)(pi - 2 theta_s),  Y_z = (4.0453T - 4.9710) tan chi - 0.2155T + 2.4192
//   x_z = [T^2 T 1] Mx [theta_s^3 theta_s^2 theta_s 1]^T, y_z likewise with My (below).
// Valid for T in [1.7, 20]: below T ~ 1.65 the gradation term 1 + A e^B of Y
// turns negative (brume/sky.hpp).
// The split F = theta_term * gamma_term lets a renderer evaluate the theta
// term once per row of an equirectangular image.

// 1 + A e^{B / cos theta}. cos theta is floored at 1e-4 (a named singular
// case, not a clamp of data): at the horizon B / cos theta -> -inf and the
// term -> 1; with B <= -0.0657 (T >= 1) e^{B/1e-4} is 0 in float already.
BRUME_FN float brume_perez_theta(float a, float b, float cos_theta) {
  return 1.0f + a * exp(b / max(cos_theta, 1e-4f));
}
// 1 + C e^{D gamma} + E cos^2 gamma.
BRUME_FN float brume_perez_gamma(float c, float d, float e, float gamma, float cos_gamma) {
  return 1.0f + c * exp(d * gamma) + e * cos_gamma * cos_gamma;
}

// The three rows of coefficients (k = 0..4 for A..E), linear in T.
BRUME_FN float brume_perez_coef_Y(int k, float t) {
  if (k == 0) return 0.1787f * t - 1.4630f;
  if (k == 1) return -0.3554f * t + 0.4275f;
  if (k == 2) return -0.0227f * t + 5.3251f;
  if (k == 3) return 0.1206f * t - 2.5771f;
  return -0.0670f * t + 0.3703f;
}
BRUME_FN float brume_perez_coef_x(int k, float t) {
  if (k == 0) return -0.0193f * t - 0.2592f;
  if (k == 1) return -0.0665f * t + 0.0008f;
  if (k == 2) return -0.0004f * t + 0.2125f;
  if (k == 3) return -0.0641f * t - 0.8989f;
  return -0.0033f * t + 0.0452f;
}
BRUME_FN float brume_perez_coef_y(int k, float t) {
  if (k == 0) return -0.0167f * t - 0.2608f;
  if (k == 1) return -0.0950f * t + 0.0092f;
  if (k == 2) return -0.0079f * t + 0.2102f;
  if (k == 3) return -0.0441f * t - 1.6537f;
  return -0.0109f * t + 0.0529f;
}

// Zenith luminance Y_z [kcd/m^2] (Preetham A.2).
BRUME_FN float brume_sky_zenith_Y(float t, float theta_s) {
  float chi = (4.0f / 9.0f - t / 120.0f) * (3.14159265f - 2.0f * theta_s);
  return (4.0453f * t - 4.9710f) * tan(chi) - 0.2155f * t + 2.4192f;
}
// Zenith chromaticity x_z, y_z (Preetham A.2, the matrices Mx, My row by row).
BRUME_FN float brume_sky_zenith_x(float t, float theta_s) {
  float s2 = theta_s * theta_s, s3 = s2 * theta_s;
  return t * t * (0.00166f * s3 - 0.00375f * s2 + 0.00209f * theta_s) +
         t * (-0.02903f * s3 + 0.06377f * s2 - 0.03202f * theta_s + 0.00394f) +
         (0.11693f * s3 - 0.21196f * s2 + 0.06052f * theta_s + 0.25886f);
}
BRUME_FN float brume_sky_zenith_y(float t, float theta_s) {
  float s2 = theta_s * theta_s, s3 = s2 * theta_s;
  return t * t * (0.00275f * s3 - 0.00610f * s2 + 0.00317f * theta_s) +
         t * (-0.04214f * s3 + 0.08970f * s2 - 0.04153f * theta_s + 0.00516f) +
         (0.15346f * s3 - 0.26756f * s2 + 0.06670f * theta_s + 0.26688f);
}

// Angle between the view (theta, phi) and the sun (theta_s, phi_s) from
// cos gamma = sin theta sin theta_s cos(phi - phi_s) + cos theta cos theta_s,
// clamped to [-1, 1] against rounding before acos.
BRUME_FN float brume_sky_cos_gamma(float sin_theta, float cos_theta, float sin_theta_s, float cos_theta_s,
                                   float cos_dphi) {
  return clamp(sin_theta * sin_theta_s * cos_dphi + cos_theta * cos_theta_s, -1.0f, 1.0f);
}

// ---- pixel -> direction, the projections of brume/sky.hpp in float ----------------------
// The GPU pass maps each fragment to its view direction with these (the CPU
// renderer keeps its double-precision direction_of_pixel, so its output is
// unchanged; tests/test_sky.cpp holds the two to each other). Angles are
// radians here; azimuths are not wrapped: only cos(phi - phi_s) is used.
//
// Fisheye (looking up, equidistant): offset (du, dv) = (u - cx, v - cy) from
// the zenith pixel; beyond r > radius there is no direction (the caller tests
// brume_sky_fisheye_r against the radius). theta = (pi/2) r / radius.
BRUME_FN float brume_sky_fisheye_r(float du, float dv) { return sqrt(du * du + dv * dv); }
BRUME_FN float brume_sky_fisheye_theta(float r, float radius) { return 1.57079633f * r / radius; }
// Compass azimuth: north at the image's up direction, east on the LEFT (seen
// from below), so phi = atan2(-du, -dv) + offset; at the centre itself the
// azimuth is undefined and irrelevant (sin theta = 0), taken as the offset.
BRUME_FN float brume_sky_fisheye_phi(float du, float dv, float offset) {
  return (du == 0.0f && dv == 0.0f) ? offset : atan(-du, -dv) + offset;
}
// Equirectangular: row 0 at the zenith, theta = pi (v + 0.5) / H; column u
// at phi = 2 pi (u + 0.5) / W - pi + offset (increasing to the right seen from inside).
// ((v + 0.5) / H first: the middle row of an odd height is then exactly pi/2, the horizon, as on the CPU.)
BRUME_FN float brume_sky_equirect_theta(float v, float height) { return 3.14159265f * ((v + 0.5f) / height); }
BRUME_FN float brume_sky_equirect_phi(float u, float width, float offset) {
  return 6.28318531f * (u + 0.5f) / width - 3.14159265f + offset;
}
// Pinhole: the ray d = (east, up, south) of a pixel (any length; the host
// folds intrinsics and orientation into one world_from_pixel matrix): its
// cos and sin of the zenith angle and its compass azimuth atan2(east, north).
BRUME_FN float brume_sky_ray_cos_theta(float dx, float dy, float dz) {
  return dy / sqrt(dx * dx + dy * dy + dz * dz);
}
BRUME_FN float brume_sky_ray_sin_theta(float dx, float dy, float dz) {
  return sqrt(dx * dx + dz * dz) / sqrt(dx * dx + dy * dy + dz * dz);
}
BRUME_FN float brume_sky_ray_phi(float dx, float dz) { return (dx == 0.0f && dz == 0.0f) ? 0.0f : atan(dx, -dz); }

// Below the horizon: the CPU renderer's test on the float zenith angle (the
// horizon itself, theta = pi/2 exactly, is sky).
BRUME_FN bool brume_sky_below_horizon(float theta) { return theta > 0.5f * 3.14159265f; }

// One channel of the sky in one direction: the per-image normalisation
// `scale` = value_zenith / F(0, theta_s) times the Perez F of the view, with
// gamma from its cosine (acos of a cosine clamped to [-1, 1]).
BRUME_FN float brume_sky_channel(float scale, float theta_term, float c, float d, float e, float cos_gamma) {
  return scale * theta_term * brume_perez_gamma(c, d, e, acos(cos_gamma), cos_gamma);
}
