// brume — per-ray maths of a height profile of extinction (the density
// delta(y) [1/m], brume/height_profile.hpp), in the common subset of C++ and
// GLSL ES 3.00 (see haze_math.glsl): layered fog's pixels (fog_math.glsl)
// and the LiDAR fog's beams integrate it.
//
// Heights are relative to the ray's start, u = y - y_r: a ray of length l
// covers u in [0, dy] with dy = l d_y (d_y the unit ray's world-up
// component). Every function returns the MEAN density over that interval,
// (D(y_r + dy) - D(y_r)) / dy, in a form that never subtracts two
// antiderivative values: the optical depth is F = l * mean, positive whether
// the ray climbs or descends, and equal to l delta(y_r) in the level limit
// dy -> 0, with relative error O(float eps) down to |dy| = 1e-6 m
// (tests/test_fog.cpp).

// g(x) = (1 - exp(-x)) / x for x >= 0, the exponential's mean over a climb
// of x e-foldings. Below x = 0.05 the series to x^4 (next term x^5/720 <
// 5e-10) replaces the quotient, whose cancellation costs eps/x (1e-6 there).
BRUME_FN float brume_profile_expm1_ratio(float x) {
  if (x < 0.05f) return 1.0f - x * (0.5f - x * (1.0f / 6.0f - x * (1.0f / 24.0f - x * (1.0f / 120.0f))));
  return (1.0f - exp(-x)) / x;
}

// Exponential density delta = D0 exp(-B (y - Y0)), exponent_c = -B (y_c - Y0):
// mean = delta(y_low) g(B |dy|), taken from the LOWER end (the densest), so
// that g <= 1 and the product overflows only when the density itself does.
BRUME_FN float brume_profile_exp_mean(float d0, float falloff, float exponent_c, float dy) {
  if (d0 == 0.0f) return 0.0f;
  float x = falloff * dy;
  float e = exponent_c - min(x, 0.0f);  // exponent at the lower end of [0, dy]
  return d0 * exp(e) * brume_profile_expm1_ratio(abs(x));
}

// sin(x) / x, series below |x| = 0.05 (next term x^6/5040 < 4e-12).
BRUME_FN float brume_profile_sinc(float x) {
  if (abs(x) < 0.05f) {
    float x2 = x * x;
    return 1.0f - x2 * (1.0f / 6.0f - x2 * (1.0f / 120.0f));
  }
  return sin(x) / x;
}

// Zhou's sinusoidal band delta = D0 (1 + cos(pi s / W)) / 2, s = y - Yc in
// [-W, W], 0 outside; offset = y_c - Yc. Inside the band the difference of
// sines is written as a product (sin a - sin b = 2 cos((a+b)/2) sin((a-b)/2)),
// so mean = D0/2 (h/|dy|) (1 + cos(k (s0 + s1)) sinc(k h)), k = pi / (2W),
// with h the part of the interval inside the band (h = |dy| when both ends are inside).
BRUME_FN float brume_profile_band_mean(float d0, float offset, float half_width, float dy) {
  float a = offset;
  float b = offset + dy;
  float lo = min(a, b);
  float hi = max(a, b);
  float k = 1.5707963267948966f / half_width;
  if (lo >= -half_width && hi <= half_width) {
    return 0.5f * d0 * (1.0f + cos(k * (a + b)) * brume_profile_sinc(k * dy));
  }
  float s0 = clamp(lo, -half_width, half_width);
  float s1 = clamp(hi, -half_width, half_width);
  float h = s1 - s0;
  if (h <= 0.0f) return 0.0f;
  // Part of the interval outside the band: |dy| >= h > 0, and the density
  // vanishes at the band's edges, so the clamped difference is accurate.
  return 0.5f * d0 * (h / abs(dy)) * (1.0f + cos(k * (s0 + s1)) * brume_profile_sinc(k * h));
}

// The integral of a linear piece (a, da) - (b, db), a < b, over [lo, hi]
// (lo <= hi, camera-relative heights): overlap length times the density at
// the overlap's midpoint (exact for a linear function). Held ends are pieces
// with da == db reaching +-1e30 m. Lengths are differences of the interval's
// own ends and the knots, never of large absolute heights.
BRUME_FN float brume_profile_piece_integral(float a, float b, float da, float db, float lo, float hi) {
  float p = max(lo, a);
  float q = min(hi, b);
  if (q <= p) return 0.0f;
  float t = clamp((0.5f * (p + q) - a) / (b - a), 0.0f, 1.0f);
  return (q - p) * mix(da, db, t);
}

// Sky: the exponential integrated from the camera to infinity along a ray
// climbing at ray_y > 0 (finite only then, with B > 0): delta(y_c) / (B ray_y).
BRUME_FN float brume_profile_exp_sky(float d0, float falloff, float exponent_c, float ray_y) {
  return d0 * exp(exponent_c) / (falloff * ray_y);
}

// ---- the whole ray ------------------------------------------------------------------
// The density relative to the ray's start (brume::HeightDensity on the CPU;
// uniforms on the GPU). kind: 0 exponential, 1 band, 2 piecewise linear
// (ramp, constant, table: n knots ku with densities kd, ends held); an
// effect may give kinds of its own beyond 2 (fog's classic OpenGL fog) to
// rays it does not integrate here.
#ifndef BRUME_PROFILE_MAX_KNOTS
#define BRUME_PROFILE_MAX_KNOTS 32  // the GPU's uniform arrays; the CPU sets its own
#endif
struct BrumeProfile {
  int kind;
  float d0, falloff, exponent_c;   // exponential (d0 also band)
  float band_offset, band_half_width;
  int n;
  float ku[BRUME_PROFILE_MAX_KNOTS];
  float kd[BRUME_PROFILE_MAX_KNOTS];
};

// Integral of the piecewise-linear density over [lo, hi]; held ends reach +-1e30 m.
BRUME_FN float brume_profile_piecewise_integral(BRUME_IN(BrumeProfile) f, float lo, float hi) {
  float s = brume_profile_piece_integral(-1e30f, f.ku[0], f.kd[0], f.kd[0], lo, hi);
  for (int j = 0; j + 1 < f.n; ++j) s += brume_profile_piece_integral(f.ku[j], f.ku[j + 1], f.kd[j], f.kd[j + 1], lo, hi);
  s += brume_profile_piece_integral(f.ku[f.n - 1], 1e30f, f.kd[f.n - 1], f.kd[f.n - 1], lo, hi);
  return s;
}

// Mean density over the camera-relative height interval [0, dy]. A level
// ray (dy == 0) of a piecewise profile takes the mean over [0, 1e-20 m]:
// the limit delta(y_c), exactly.
BRUME_FN float brume_profile_mean(BRUME_IN(BrumeProfile) f, float dy) {
  if (f.kind == 0) return brume_profile_exp_mean(f.d0, f.falloff, f.exponent_c, dy);
  if (f.kind == 1) return brume_profile_band_mean(f.d0, f.band_offset, f.band_half_width, dy);
  float lo = min(dy, 0.0f);
  float hi = dy == 0.0f ? 1e-20f : max(dy, 0.0f);
  return brume_profile_piecewise_integral(f, lo, hi) / (hi - lo);
}


// Optical depth over l metres along a ray whose unit direction climbs at ray_y.
BRUME_FN float brume_profile_along(BRUME_IN(BrumeProfile) f, float l, float ray_y) {
  return l * brume_profile_mean(f, l * ray_y);
}
