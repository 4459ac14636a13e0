// brume — per-pixel maths of layered fog (Zhou, Chen, Smith; docs/fog.md),
// in the common subset of C++ and GLSL ES 3.00 (see haze_math.glsl).
//
// Heights are camera-relative, u = y - y_c: the ray from the camera to a
// pixel covers u in [0, dy] with dy = l d_y (l the range, d_y the unit ray's
// world-up component). Every function returns the MEAN density over that
// interval, (D(y_c + dy) - D(y_c)) / dy, in a form that never subtracts two
// antiderivative values: the optical depth is F = l * mean, positive whether
// the ray climbs or descends (the paper's l/|dy| form changes sign looking
// down), and equal to l delta(y_c) in the level limit dy -> 0, with relative
// error O(float eps) down to |dy| = 1e-6 m (tests/test_fog.cpp).

// g(x) = (1 - exp(-x)) / x for x >= 0, the exponential's mean over a climb
// of x e-foldings. Below x = 0.05 the series to x^4 (next term x^5/720 <
// 5e-10) replaces the quotient, whose cancellation costs eps/x (1e-6 there).
BRUME_FN float brume_fog_expm1_ratio(float x) {
  if (x < 0.05f) return 1.0f - x * (0.5f - x * (1.0f / 6.0f - x * (1.0f / 24.0f - x * (1.0f / 120.0f))));
  return (1.0f - exp(-x)) / x;
}

// Exponential density delta = D0 exp(-B (y - Y0)), exponent_c = -B (y_c - Y0):
// mean = delta(y_low) g(B |dy|), taken from the LOWER end (the densest), so
// that g <= 1 and the product overflows only when the density itself does.
BRUME_FN float brume_fog_exp_mean(float d0, float falloff, float exponent_c, float dy) {
  if (d0 == 0.0f) return 0.0f;
  float x = falloff * dy;
  float e = exponent_c - min(x, 0.0f);  // exponent at the lower end of [0, dy]
  return d0 * exp(e) * brume_fog_expm1_ratio(abs(x));
}

// sin(x) / x, series below |x| = 0.05 (next term x^6/5040 < 4e-12).
BRUME_FN float brume_fog_sinc(float x) {
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
BRUME_FN float brume_fog_band_mean(float d0, float offset, float half_width, float dy) {
  float a = offset;
  float b = offset + dy;
  float lo = min(a, b);
  float hi = max(a, b);
  float k = 1.5707963267948966f / half_width;
  if (lo >= -half_width && hi <= half_width) {
    return 0.5f * d0 * (1.0f + cos(k * (a + b)) * brume_fog_sinc(k * dy));
  }
  float s0 = clamp(lo, -half_width, half_width);
  float s1 = clamp(hi, -half_width, half_width);
  float h = s1 - s0;
  if (h <= 0.0f) return 0.0f;
  // Part of the interval outside the band: |dy| >= h > 0, and the density
  // vanishes at the band's edges, so the clamped difference is accurate.
  return 0.5f * d0 * (h / abs(dy)) * (1.0f + cos(k * (s0 + s1)) * brume_fog_sinc(k * h));
}

// The integral of a linear piece (a, da) - (b, db), a < b, over [lo, hi]
// (lo <= hi, camera-relative heights): overlap length times the density at
// the overlap's midpoint (exact for a linear function). Held ends are pieces
// with da == db reaching +-1e30 m. Lengths are differences of the interval's
// own ends and the knots, never of large absolute heights.
BRUME_FN float brume_fog_piece_integral(float a, float b, float da, float db, float lo, float hi) {
  float p = max(lo, a);
  float q = min(hi, b);
  if (q <= p) return 0.0f;
  float t = clamp((0.5f * (p + q) - a) / (b - a), 0.0f, 1.0f);
  return (q - p) * mix(da, db, t);
}

// Sky: the exponential integrated from the camera to infinity along a ray
// climbing at ray_y > 0 (finite only then, with B > 0): delta(y_c) / (B ray_y).
BRUME_FN float brume_fog_exp_sky(float d0, float falloff, float exponent_c, float ray_y) {
  return d0 * exp(exponent_c) / (falloff * ray_y);
}

// Classic OpenGL fog on the range l (transmission f, not optical depth).
BRUME_FN float brume_fog_classic_linear(float start, float end, float l) {
  return clamp((end - l) / (end - start), 0.0f, 1.0f);
}
BRUME_FN float brume_fog_classic_exp2(float d0, float l) {
  float x = d0 * l;
  return x * x;  // optical depth; f = exp(-(D0 l)^2)
}

// Scattering blur scale [px]: sigma = sigma0 + lambda sqrt(omega F) l / R_max,
// haze's sigma0 + lambda sqrt(kappa_s') R'^{3/2} at constant density.
BRUME_FN float brume_fog_scale(float sigma0, float lambda, float albedo, float optical_depth, float range_norm) {
  return sigma0 + lambda * sqrt(max(albedo * optical_depth, 0.0f)) * range_norm;
}

// Zhou eq. 1 without blur: C = f C_scene + (1 - f) C_fog, one channel.
BRUME_FN float brume_fog_composite(float c, float f, float fog) { return f * c + (1.0f - f) * fog; }

// ---- the whole ray ------------------------------------------------------------------
// The density of one frame, camera-relative (brume::FogDensity on the CPU;
// uniforms on the GPU). kind: 0 exponential, 1 band, 2 piecewise linear
// (ramp, constant, table: n knots ku with densities kd, ends held),
// 3 classic linear, 4 classic exp2.
#ifndef BRUME_FOG_MAX_KNOTS
#define BRUME_FOG_MAX_KNOTS 32  // the GPU's uniform arrays; the CPU sets its own
#endif
struct BrumeFog {
  int kind;
  float d0, falloff, exponent_c;   // exponential (d0 also band, exp2)
  float band_offset, band_half_width;
  float fog_start, fog_end;        // classic linear
  int n;
  float ku[BRUME_FOG_MAX_KNOTS];
  float kd[BRUME_FOG_MAX_KNOTS];
};

// Integral of the piecewise-linear density over [lo, hi]; held ends reach +-1e30 m.
BRUME_FN float brume_fog_piecewise_integral(BRUME_IN(BrumeFog) f, float lo, float hi) {
  float s = brume_fog_piece_integral(-1e30f, f.ku[0], f.kd[0], f.kd[0], lo, hi);
  for (int j = 0; j + 1 < f.n; ++j) s += brume_fog_piece_integral(f.ku[j], f.ku[j + 1], f.kd[j], f.kd[j + 1], lo, hi);
  s += brume_fog_piece_integral(f.ku[f.n - 1], 1e30f, f.kd[f.n - 1], f.kd[f.n - 1], lo, hi);
  return s;
}

// Mean density over the camera-relative height interval [0, dy]. A level
// ray (dy == 0) of a piecewise profile takes the mean over [0, 1e-20 m]:
// the limit delta(y_c), exactly.
BRUME_FN float brume_fog_mean(BRUME_IN(BrumeFog) f, float dy) {
  if (f.kind == 0) return brume_fog_exp_mean(f.d0, f.falloff, f.exponent_c, dy);
  if (f.kind == 1) return brume_fog_band_mean(f.d0, f.band_offset, f.band_half_width, dy);
  float lo = min(dy, 0.0f);
  float hi = dy == 0.0f ? 1e-20f : max(dy, 0.0f);
  return brume_fog_piecewise_integral(f, lo, hi) / (hi - lo);
}

// Optical depth over l metres along a ray whose unit direction climbs at ray_y.
BRUME_FN float brume_fog_along(BRUME_IN(BrumeFog) f, float l, float ray_y) {
  if (f.kind == 3) return -log(brume_fog_classic_linear(f.fog_start, f.fog_end, l));  // +inf beyond the end
  if (f.kind == 4) return brume_fog_classic_exp2(f.d0, l);
  return l * brume_fog_mean(f, l * ray_y);
}

// +inf, the optical depth of a sky ray across an unbounded medium.
BRUME_FN float brume_fog_infinity() { return uintBitsToFloat(0x7F800000u); }

// A sky ray: integrated to infinity where the density vanishes along it
// (exponential climbing with B > 0: delta(y_c) / (B d_y); band: to its far
// edge; piecewise: to its last (first) knot when the density there is 0),
// else, where the integral diverges, over sky_distance metres or, for
// sky_distance < 0, to infinity: F = +inf (f = 0, the sky is the fog colour).
BRUME_FN float brume_fog_sky(BRUME_IN(BrumeFog) f, float ray_y, float sky_distance) {
  if (f.kind == 0) {
    if (f.d0 == 0.0f) return 0.0f;
    if (ray_y > 0.0f && f.falloff > 0.0f) return brume_fog_exp_sky(f.d0, f.falloff, f.exponent_c, ray_y);
  } else if (f.kind == 1) {
    if (ray_y != 0.0f) {
      float h = ray_y > 0.0f ? max(f.band_half_width - f.band_offset, 0.0f)
                             : min(-f.band_half_width - f.band_offset, 0.0f);
      if (h == 0.0f) return 0.0f;
      return brume_fog_mean(f, h) * (h / ray_y);
    }
    if (brume_fog_mean(f, 0.0f) == 0.0f) return 0.0f;
  } else if (f.kind == 2) {
    if (ray_y > 0.0f && f.kd[f.n - 1] == 0.0f) {
      float h = max(f.ku[f.n - 1], 0.0f);
      return h == 0.0f ? 0.0f : brume_fog_piecewise_integral(f, 0.0f, h) / ray_y;
    }
    if (ray_y < 0.0f && f.kd[0] == 0.0f) {
      float h = min(f.ku[0], 0.0f);
      return h == 0.0f ? 0.0f : brume_fog_piecewise_integral(f, h, 0.0f) / -ray_y;
    }
    if (ray_y == 0.0f && brume_fog_mean(f, 0.0f) == 0.0f) return 0.0f;
  }
  if (sky_distance < 0.0f) return f.kind == 4 && f.d0 == 0.0f ? 0.0f : brume_fog_infinity();
  return brume_fog_along(f, sky_distance, ray_y);
}

// The optical depth of a pixel: a sky pixel's (brume_fog_sky), a scene
// pixel's along its range l, or, across the horizon margin (sky weight
// 0 < w < 1, l the margin's harmonic range), -ln of the blend of the two
// transmissions (brume_sky_blend, haze_math).
BRUME_FN float brume_fog_pixel(BRUME_IN(BrumeFog) f, float l, float ray_y, bool sky, float sky_distance, float w) {
  if (sky) return brume_fog_sky(f, ray_y, sky_distance);
  float F = brume_fog_along(f, l, ray_y);
  if (w <= 0.0f) return F;
  return -log(brume_sky_blend(exp(-F), exp(-brume_fog_sky(f, ray_y, sky_distance)), w));
}

// The world-up component of pixel (u, v)'s unit ray: r . ((u - cx)/fx, (v - cy)/fy, 1) / |.|,
// r the second row of world_from_cv; k = (cx, cy, 1/fx, 1/fy).
BRUME_FN float brume_fog_ray_y(float r0, float r1, float r2, float cx, float cy, float ifx, float ify, float u, float v) {
  float x = (u - cx) * ifx;
  float y = (v - cy) * ify;
  return (r0 * x + r1 * y + r2) / sqrt(x * x + y * y + 1.0f);
}
