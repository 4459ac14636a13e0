// Pass 1 of the aerial passes (include/brume/aerial.hpp): Gamma from the
// table(s) with the CPU's interpolation in ln Gamma (AttenuationTable::at:
// texelFetch at texel centres, never the sampler's filtering), the transfer
// rho and clean radiance E' of the mode, and the six premultiplied channels
// as two targets F0 = (rho E', rho_r), F1 = (rho_g, rho_b, 0, 0); remove
// writes its result in F0.rgb. aux.r = sigma for the rate pass.
// Inputs: uImage (linear sRGB in .rgb), uRange (metres; -1 = unknown, set on
// upload), uTable / uTableFrom (ln Gamma per channel in .rgb, N x 1); with
// uSlant = 1 (--path slant) instead uSlantDh (per pixel dh = s slope +
// offset: slope in .r, offset in .g) and uSlantTable / uSlantTableFrom (ln
// Gamma over the equivalent distances (s_R, s_M), nr x nm, bilinear in ln
// Gamma as SlantAttenuationTable::log_at). Level: those three are bound to
// any texture and never read.
// Topics: haze_math, aerial_math.
uniform highp sampler2D uImage;
uniform highp sampler2D uRange;
uniform highp sampler2D uTable;
uniform highp sampler2D uTableFrom;
uniform highp sampler2D uSlantDh;
uniform highp sampler2D uSlantTable;
uniform highp sampler2D uSlantTableFrom;
uniform int uSlant;               // 1: --path slant
uniform vec2 uInvScaleHeight;     // 1 / H_R, 1 / H_M (m^-1)
uniform vec2 uSlantInvStep;       // 1 / the grid's steps in s_R, s_M (m^-1)
uniform int uSlantNr, uSlantNm;   // the grid's nodes in s_R and s_M (>= 2 each)
uniform float uStep, uStepFrom;  // m per table sample
uniform int uLast, uLastFrom;    // last sample index (>= 1)
uniform float uDistanceScale;    // s = R x this
uniform float uFar;              // m, R_max x distance scale: unknown range
uniform float uInvRangeMax;
uniform float uSigma0, uSigmaMax;
uniform int uMode;               // 0 render, 1 re-render, 2 remove
uniform int uXyz;                // 1: work in XYZ (M diag(Gamma) M^-1)
uniform vec3 uA, uA1;            // Iinf (Iinf2), Iinf1, in the working space
uniform float uFloor;            // gamma_floor
layout(location = 0) out vec4 oF0;
layout(location = 1) out vec4 oF1;
layout(location = 2) out vec4 oAux;

vec3 gamma_at(highp sampler2D tab, float s, float step, int last) {
  if (!(s > 0.0)) return vec3(1.0);
  float t = s / step;
  int i = t >= float(last) ? last - 1 : int(t);
  float f = t - float(i);
  vec3 a = texelFetch(tab, ivec2(i, 0), 0).rgb;
  vec3 b = texelFetch(tab, ivec2(i + 1, 0), 0).rgb;
  return exp(a + f * (b - a));
}

// (1 - e^-x) / x, the flat-Earth exponential atmosphere's mean density along
// a path that climbs x scale heights (the CPU's slant_factor, -expm1(-x)/x):
// its series near 0, where 1 - e^-x would lose float's digits (below |x| =
// 0.05 the next term, x^5/720, is < 5e-10).
float slant_factor(float x) {
  if (abs(x) < 0.05) return 1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x / 120.0)));
  return (1.0 - exp(-x)) / x;
}

// ln Gamma at grid position (tr, tm): SlantAttenuationTable::log_at (edges
// clamped, NaN to 0), texelFetch at the four nodes.
vec3 slant_log_at(highp sampler2D tab, float tr, float tm) {
  float lr = float(uSlantNr - 1), lm = float(uSlantNm - 1);
  tr = min(max(tr, 0.0), lr);
  tm = min(max(tm, 0.0), lm);
  int i = min(int(tr), uSlantNr - 2), j = min(int(tm), uSlantNm - 2);
  float fr = tr - float(i), fm = tm - float(j);
  vec3 a = texelFetch(tab, ivec2(i, j), 0).rgb, b = texelFetch(tab, ivec2(i + 1, j), 0).rgb;
  vec3 c = texelFetch(tab, ivec2(i, j + 1), 0).rgb, d = texelFetch(tab, ivec2(i + 1, j + 1), 0).rgb;
  vec3 lo = a + fr * (b - a), hi = c + fr * (d - c);
  return lo + fm * (hi - lo);
}

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 e = texelFetch(uImage, p, 0).rgb;
  if (uXyz == 1)
    e = vec3(brume_srgb_to_x(e.r, e.g, e.b), brume_srgb_to_y(e.r, e.g, e.b), brume_srgb_to_z(e.r, e.g, e.b));
  float r = texelFetch(uRange, p, 0).r;
  bool known = r > 0.0;
  float s = known ? r * uDistanceScale : uFar;
  float sigma = brume_target_scale(known ? r * uInvRangeMax : 1.0, uSigma0, uSigmaMax);
  vec3 g, g1;
  if (uSlant == 1) {
    vec2 k = texelFetch(uSlantDh, p, 0).rg;
    float dh = s * k.r + k.g;
    if (isnan(dh) || isinf(dh)) dh = 0.0;
    vec2 t = s * vec2(slant_factor(dh * uInvScaleHeight.x), slant_factor(dh * uInvScaleHeight.y)) * uSlantInvStep;
    g = exp(slant_log_at(uSlantTable, t.x, t.y));
    if (uMode == 1) g1 = exp(slant_log_at(uSlantTableFrom, t.x, t.y));
  } else {
    g = gamma_at(uTable, s, uStep, uLast);
    if (uMode == 1) g1 = gamma_at(uTableFrom, s, uStepFrom, uLastFrom);
  }
  vec3 rho = g;
  vec3 f;
  if (uMode == 1) {
    rho = vec3(brume_aerial_rerender_rho(g.r, g1.r, uFloor), brume_aerial_rerender_rho(g.g, g1.g, uFloor),
               brume_aerial_rerender_rho(g.b, g1.b, uFloor));
    vec3 ep = vec3(brume_aerial_rerender_radiance(e.r, uA.r, uA1.r), brume_aerial_rerender_radiance(e.g, uA.g, uA1.g),
                   brume_aerial_rerender_radiance(e.b, uA.b, uA1.b));
    f = rho * ep;
  } else if (uMode == 2) {
    f = vec3(brume_aerial_remove(e.r, g.r, uA.r, uFloor), brume_aerial_remove(e.g, g.g, uA.g, uFloor),
             brume_aerial_remove(e.b, g.b, uA.b, uFloor));
  } else {
    f = rho * e;
  }
  oF0 = vec4(f, rho.r);
  oF1 = vec4(rho.g, rho.b, 0.0, 0.0);
  oAux = vec4(sigma, 0.0, 0.0, 1.0);
}
