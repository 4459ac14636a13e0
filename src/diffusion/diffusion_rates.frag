// The per-pixel diffusion rate from the target scale: rho = (sigma^2 -
// sigma0^2)/(2N) (eq. 13, standard) or ln(sigma/sigma0)/N (eq. 18,
// invariant schemes). The GPU's one place for rates: haze feeds it the sigma
// its premultiply pass wrote, diffuse_gpu an uploaded scale map, a renderer
// its own texture. With N = 0 no diffusion pass runs; the rate is 0 rather
// than a division by zero.
// Topics: diffusion_math.
uniform highp sampler2D uSigma;  // .r = sigma(x), px
uniform float uSigma0;      // px
uniform float uIterations;  // N
uniform int uScheme;        // 0 standard, 1 invariant, 2 invariant-exact
layout(location = 0) out vec4 oRate;  // .r = rho (an R32F target keeps .r only)

void main() {
  float sigma = texelFetch(uSigma, ivec2(gl_FragCoord.xy), 0).r;
  float rho = uIterations > 0.0 ? (uScheme == 0 ? brume_standard_rate(sigma, uSigma0, uIterations)
                                                : brume_invariant_rate(sigma, uSigma0, uIterations))
                                : 0.0;
  oRate = vec4(rho, 0.0, 0.0, 1.0);
}
