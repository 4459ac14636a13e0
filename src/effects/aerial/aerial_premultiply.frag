// Pass 1 of the aerial passes (include/brume/aerial.hpp): Gamma from the
// table(s) with the CPU's interpolation in ln Gamma (AttenuationTable::at:
// texelFetch at texel centres, never the sampler's filtering), the transfer
// rho and clean radiance E' of the mode, and the six premultiplied channels
// as two targets F0 = (rho E', rho_r), F1 = (rho_g, rho_b, 0, 0); remove
// writes its result in F0.rgb. aux.r = sigma for the rate pass.
// Inputs: uImage (linear sRGB in .rgb), uRange (metres; -1 = unknown, set on
// upload), uTable / uTableFrom (ln Gamma per channel in .rgb, N x 1).
// Topics: haze_math, aerial_math.
uniform highp sampler2D uImage;
uniform highp sampler2D uRange;
uniform highp sampler2D uTable;
uniform highp sampler2D uTableFrom;
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

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 e = texelFetch(uImage, p, 0).rgb;
  if (uXyz == 1)
    e = vec3(brume_srgb_to_x(e.r, e.g, e.b), brume_srgb_to_y(e.r, e.g, e.b), brume_srgb_to_z(e.r, e.g, e.b));
  float r = texelFetch(uRange, p, 0).r;
  bool known = r > 0.0;
  float s = known ? r * uDistanceScale : uFar;
  float sigma = brume_target_scale(known ? r * uInvRangeMax : 1.0, uSigma0, uSigmaMax);
  vec3 g = gamma_at(uTable, s, uStep, uLast);
  vec3 rho = g;
  vec3 f;
  if (uMode == 1) {
    vec3 g1 = gamma_at(uTableFrom, s, uStepFrom, uLastFrom);
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
