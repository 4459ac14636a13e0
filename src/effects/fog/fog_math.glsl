// brume — per-pixel maths of layered fog (Zhou, Chen, Smith; docs/fog.md),
// in the common subset of C++ and GLSL ES 3.00 (see haze_math.glsl).
//
// The height profile's optical depth along a ray is the media layer's
// (src/media/height_profile.glsl: camera-relative heights u = y - y_c, the
// mean density over the ray's climb, positive whether the ray climbs or
// descends -- the paper's l/|dy| form changes sign looking down); this file
// adds classic OpenGL fog, sky rays, the horizon margin's blend, the blur's
// scale and the composite.

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
// The fog of one frame: its height profile, camera-relative (brume::FogDensity
// on the CPU; uniforms on the GPU; height_profile.glsl), whose kind 3 is
// classic linear and 4 classic exp2 (then the profile's d0 is exp2's density).
struct BrumeFog {
  BrumeProfile profile;
  float fog_start, fog_end;        // classic linear
};

// Optical depth over l metres along a ray whose unit direction climbs at ray_y.
BRUME_FN float brume_fog_along(BRUME_IN(BrumeFog) f, float l, float ray_y) {
  if (f.profile.kind == 3) return -log(brume_fog_classic_linear(f.fog_start, f.fog_end, l));  // +inf beyond the end
  if (f.profile.kind == 4) return brume_fog_classic_exp2(f.profile.d0, l);
  return brume_profile_along(f.profile, l, ray_y);
}

// +inf, the optical depth of a sky ray across an unbounded medium.
BRUME_FN float brume_fog_infinity() { return uintBitsToFloat(0x7F800000u); }

// A sky ray: integrated to infinity where the density vanishes along it
// (exponential climbing with B > 0: delta(y_c) / (B d_y); band: to its far
// edge; piecewise: to its last (first) knot when the density there is 0),
// else, where the integral diverges, over sky_distance metres or, for
// sky_distance < 0, to infinity: F = +inf (f = 0, the sky is the fog colour).
BRUME_FN float brume_fog_sky(BRUME_IN(BrumeFog) f, float ray_y, float sky_distance) {
  if (f.profile.kind == 0) {
    if (f.profile.d0 == 0.0f) return 0.0f;
    if (ray_y > 0.0f && f.profile.falloff > 0.0f)
      return brume_profile_exp_sky(f.profile.d0, f.profile.falloff, f.profile.exponent_c, ray_y);
  } else if (f.profile.kind == 1) {
    if (ray_y != 0.0f) {
      float h = ray_y > 0.0f ? max(f.profile.band_half_width - f.profile.band_offset, 0.0f)
                             : min(-f.profile.band_half_width - f.profile.band_offset, 0.0f);
      if (h == 0.0f) return 0.0f;
      return brume_profile_mean(f.profile, h) * (h / ray_y);
    }
    if (brume_profile_mean(f.profile, 0.0f) == 0.0f) return 0.0f;
  } else if (f.profile.kind == 2) {
    if (ray_y > 0.0f && f.profile.kd[f.profile.n - 1] == 0.0f) {
      float h = max(f.profile.ku[f.profile.n - 1], 0.0f);
      return h == 0.0f ? 0.0f : brume_profile_piecewise_integral(f.profile, 0.0f, h) / ray_y;
    }
    if (ray_y < 0.0f && f.profile.kd[0] == 0.0f) {
      float h = min(f.profile.ku[0], 0.0f);
      return h == 0.0f ? 0.0f : brume_profile_piecewise_integral(f.profile, h, 0.0f) / -ray_y;
    }
    if (ray_y == 0.0f && brume_profile_mean(f.profile, 0.0f) == 0.0f) return 0.0f;
  }
  if (sky_distance < 0.0f) return f.profile.kind == 4 && f.profile.d0 == 0.0f ? 0.0f : brume_fog_infinity();
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
