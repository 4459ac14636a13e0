// The layered-fog pass (Zhou, Chen, Smith; brume/fog.hpp): each pixel's
// world-up ray component from the camera, its optical depth F along the
// ray (sky: to infinity or over the sky distance), f = exp(-F), and either
// the composite C = f C_scene + (1 - f) C_fog (no blur) or the premultiplied
// F0 = f (C, 1) for haze's diffusion passes, with the blur scale sigma.
// Inputs: uImage (linear RGB), uRange: with uDepthBuffer == 0, metres along
// the ray (-1 = unknown = sky, set on upload because GLSL compilers may fold
// isnan() away); with uDepthBuffer == 1, a renderer's window depth in [0, 1]
// (the depth texture itself), linearised here by the CPU conversion's
// expression (depth_math.glsl), the cleared value uDepthLinear.z being sky.
// uSkyWeight (with uSkyBlend == 1): the preparation's sky weight; a known
// pixel of weight > 0 is the horizon margin (brume_fog_pixel).
// Topics: haze_math, height_profile, fog_math, depth_math.
uniform highp sampler2D uImage;
uniform highp sampler2D uRange;
uniform vec3 uRayRow;          // second row of world_from_cv
uniform vec4 uK;               // cx, cy, 1/fx, 1/fy
uniform int uKind;             // BrumeProfile.kind (fog: 3, 4 classic)
uniform vec3 uExp;             // d0, falloff, exponent_c
uniform vec2 uBand;            // offset, half-width
uniform vec2 uClassic;         // fog start, end
uniform int uKnots;
uniform float uKnotU[BRUME_PROFILE_MAX_KNOTS];
uniform float uKnotD[BRUME_PROFILE_MAX_KNOTS];
uniform float uSkyDistance;    // m, diverging sky rays (< 0: infinity, F = +inf)
uniform float uSkyBlurDistance;  // m, the sky's blur distance
uniform highp sampler2D uSkyWeight;
uniform int uSkyBlend;         // 1: blend the horizon margin by uSkyWeight
uniform vec3 uAirlight;        // linear RGB
uniform int uBlur;             // 1: premultiplied output for the diffusion passes
uniform vec4 uScale;           // sigma0, lambda, albedo, 1 / R_max
uniform float uSigmaMax;       // px, the analysis' bound (the rate pass needs sigma <= it)
uniform int uDepthBuffer;      // 0: uRange is range; 1: uRange is window depth
uniform vec3 uDepthLinear;     // a, b [1/m] (1/z = (1 - d) a + d b: (1/n, 1/f), reversed-z (1/f, 1/n)), clear value
layout(location = 0) out vec4 oColor;  // no blur: (C, f); blur: f (C, 1)
layout(location = 1) out vec4 oAux;    // r: sigma, g: f, b: F

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 c = texelFetch(uImage, p, 0).rgb;
  float r = texelFetch(uRange, p, 0).r;
  if (uDepthBuffer == 1) {
    float x = (float(p.x) - uK.x) * uK.z;
    float y = (float(p.y) - uK.y) * uK.w;
    r = r == uDepthLinear.z ? -1.0 : brume_depth_buffer_range(r, uDepthLinear.x, uDepthLinear.y, x, y);
  }
  bool sky = !(r > 0.0);
  BrumeFog fog;
  fog.profile.kind = uKind;
  fog.profile.d0 = uExp.x;
  fog.profile.falloff = uExp.y;
  fog.profile.exponent_c = uExp.z;
  fog.profile.band_offset = uBand.x;
  fog.profile.band_half_width = uBand.y;
  fog.fog_start = uClassic.x;
  fog.fog_end = uClassic.y;
  fog.profile.n = uKnots;
  for (int i = 0; i < BRUME_PROFILE_MAX_KNOTS; ++i) {
    fog.profile.ku[i] = uKnotU[i];
    fog.profile.kd[i] = uKnotD[i];
  }
  float ry = brume_fog_ray_y(uRayRow.x, uRayRow.y, uRayRow.z, uK.x, uK.y, uK.z, uK.w, float(p.x), float(p.y));
  float w = uSkyBlend == 1 ? texelFetch(uSkyWeight, p, 0).r : 0.0;
  float F = brume_fog_pixel(fog, r, ry, sky, uSkyDistance, w);
  float f = exp(-F);
  float sigma = 0.0;
  if (uBlur == 1) {
    float l = sky ? uSkyBlurDistance : r;
    float Fb = sky || w > 0.0 ? brume_fog_along(fog, l, ry) : F;
    sigma = min(brume_fog_scale(uScale.x, uScale.y, uScale.z, Fb, l * uScale.w), uSigmaMax);
    oColor = vec4(f * c, f);
  } else {
    oColor = vec4(brume_fog_composite(c.r, f, uAirlight.r), brume_fog_composite(c.g, f, uAirlight.g),
                  brume_fog_composite(c.b, f, uAirlight.b), f);
  }
  oAux = vec4(sigma, f, F, 1.0);
}
