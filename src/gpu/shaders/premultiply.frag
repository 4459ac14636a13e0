// Pass 1 of N + 2 (Hansard §4.2): transmission (eq. 1), target scale (eq. 7)
// and the premultiplied RGBA F0 = tau (E, 1) (eq. 2); also the per-pixel
// diffusion rate (eq. 13 / 18) for the diffusion passes.
// Inputs: uImage (RGB in .rgb, linear), uRange (metres in .r; -1 = unknown, set
// on upload because GLSL compilers may fold isnan() away).
uniform highp sampler2D uImage;
uniform highp sampler2D uRange;
uniform float uInvRangeMax;   // 1 / R_max
uniform float uKappa;         // kappa_a' + kappa_s' (normalised)
uniform float uSigma0;        // px
uniform float uSigmaMax;      // px
uniform float uIterations;    // N
uniform int uScheme;          // 0 standard, 1 invariant, 2 invariant-exact
uniform int uNaive;           // 1: F0 = (E, tau) (the naive composite's blur input)
layout(location = 0) out vec4 oF;
layout(location = 1) out vec4 oAux;  // r: rate rho, g: sigma, b: tau0

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 e = texelFetch(uImage, p, 0).rgb;
  float r = texelFetch(uRange, p, 0).r;
  bool known = r > 0.0;  // the upload maps NaN, inf and 0 (unknown) to -1
  float rn = known ? r * uInvRangeMax : 1.0;  // unknown -> R_max (the CPU rule)
  float tau = brume_transmission(uKappa, rn);
  float sigma = brume_target_scale(rn, uSigma0, uSigmaMax);
  float rho = uIterations > 0.0 ? (uScheme == 0 ? brume_standard_rate(sigma, uSigma0, uIterations)
                                                : brume_invariant_rate(sigma, uSigma0, uIterations))
                                : 0.0;
  oF = uNaive == 1 ? vec4(e, tau) : vec4(tau * e, tau);
  oAux = vec4(rho, sigma, tau, 0.0);
}
