// Pass 1 of the haze passes (Hansard §4.2): transmission (eq. 1), target
// scale (eq. 7) and the premultiplied RGBA F0 = tau (E, 1) (eq. 2). The
// diffusion rates are made from the scale by the rate pass (diffusion_rates.frag).
// Inputs: uImage (RGB in .rgb, linear), uRange (metres in .r; -1 = unknown, set
// on upload because GLSL compilers may fold isnan() away).
// Topics: haze_math.
uniform highp sampler2D uImage;
uniform highp sampler2D uRange;
uniform float uInvRangeMax;   // 1 / R_max
uniform float uKappa;         // kappa_a' + kappa_s' (normalised)
uniform float uSigma0;        // px
uniform float uSigmaMax;      // px
uniform int uNaive;           // 1: F0 = (E, tau) (the naive composite's blur input)
uniform highp sampler2D uSkyWeight;  // the preparation's sky weight (.r), with uSkyBlend
uniform int uSkyBlend;        // 1: the sky lies beyond the medium (brume_sky_blend with uSkyTau)
uniform float uSkyTau;        // the sky's own transmission (0: at infinity)
layout(location = 0) out vec4 oF;
layout(location = 1) out vec4 oAux;  // r: sigma, g: tau0 (an RG32F target)

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 e = texelFetch(uImage, p, 0).rgb;
  float r = texelFetch(uRange, p, 0).r;
  bool known = r > 0.0;  // the upload maps NaN, inf and 0 (unknown) to -1
  float rn = known ? r * uInvRangeMax : 1.0;  // unknown -> R_max (the CPU rule)
  float tau = brume_transmission(uKappa, rn);
  if (uSkyBlend == 1) tau = brume_sky_blend(tau, uSkyTau, texelFetch(uSkyWeight, p, 0).r);
  float sigma = brume_target_scale(rn, uSigma0, uSigmaMax);
  oF = uNaive == 1 ? vec4(e, tau) : vec4(tau * e, tau);
  oAux = vec4(sigma, tau, 0.0, 1.0);
}
