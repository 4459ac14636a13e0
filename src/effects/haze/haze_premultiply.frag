// Pass 1 of the haze passes (Hansard §4.2): transmission (eq. 1), target
// scale (eq. 7) and the premultiplied RGBA F0 = tau (E, 1) (eq. 2). The
// diffusion rates are made from the scale by the rate pass (diffusion_rates.frag).
// Inputs: uImage (RGB in .rgb, linear), uRange (metres in .r; -1 = unknown, set
// on upload because GLSL compilers may fold isnan() away).
// With uParticles 1 (rain's and snow's camera pass, src/effects/rain/rain_gpu.cpp) the
// transmission is instead that of haze's sigma and the particles' analytic part along the
// pixel's ray (brume_particles_optical_depth), the sky's (uSkyTau) where the range is unknown.
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
uniform highp sampler2D uParticleSteps;  // uParticles 1: step i (texel i % 64, i / 64) = (G at its start, sigma_drawn, its start [m])
uniform int uParticles;       // 1: haze's sigma and falling particles' analytic part (metres), 0: haze alone
uniform vec4 uRay;            // uParticles 1: fx, fy, cx, cy [px]
uniform vec4 uParticleDepth;  // uParticles 1: sigma_haze, sigma_particles [1/m], step dz, z_split [m]
uniform int uParticleStepCount;  // uParticles 1: the table's steps (i = 1 .. count)
layout(location = 0) out vec4 oF;
layout(location = 1) out vec4 oAux;  // r: sigma, g: tau0 (an RG32F target)

// The particles' and haze's transmission along pixel p's ray to range r [m] (brume/rain.hpp).
float particles_transmission(ivec2 p, float r) {
  vec2 xy = (vec2(p) - uRay.zw) / uRay.xy;
  float cos_theta = 1.0 / sqrt(xy.x * xy.x + xy.y * xy.y + 1.0);
  float z = min(r * cos_theta, uParticleDepth.w);
  vec3 s = vec3(0.0);
  if (z > 0.0) {
    int i = clamp(int(ceil(z / uParticleDepth.z)), 1, uParticleStepCount);
    s = texelFetch(uParticleSteps, ivec2(i % 64, i / 64), 0).rgb;
  }
  float tau = brume_particles_optical_depth(uParticleDepth.y, r, cos_theta, s.r, s.g, s.b, z);
  return exp(-(uParticleDepth.x * r + tau));
}

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 e = texelFetch(uImage, p, 0).rgb;
  float r = texelFetch(uRange, p, 0).r;
  bool known = r > 0.0;  // the upload maps NaN, inf and 0 (unknown) to -1
  float rn = known ? r * uInvRangeMax : 1.0;  // unknown -> R_max (the CPU rule)
  float tau;
  if (uParticles == 1)
    tau = known ? particles_transmission(p, r) : uSkyTau;  // the sky lies beyond the unbounded media
  else
    tau = brume_transmission(uKappa, rn);
  if (uSkyBlend == 1) tau = brume_sky_blend(tau, uSkyTau, texelFetch(uSkyWeight, p, 0).r);
  float sigma = brume_target_scale(rn, uSigma0, uSigmaMax);
  oF = uNaive == 1 ? vec4(e, tau) : vec4(tau * e, tau);
  oAux = vec4(sigma, tau, 0.0, 1.0);
}
