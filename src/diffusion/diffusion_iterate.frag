// One diffusion iteration (Hansard eq. 11-12 with eq. 13 or 17-18):
//   F <- F + sum_u rho(x,u) (F(x+u) - F(x)),  rho(x,u) = (rho(x+u) + rho(x)) / 2
// (or the min or harmonic mean of the two rates: brume_edge_rate)
// with unit offsets (standard) or offsets h_k(x) from sigma_k = sigma0 e^{k rho}
// (invariant, invariant-exact). Samples between texels are linear
// interpolations: in hardware (uHardware = 1, samplers set to LINEAR with
// MIRRORED_REPEAT, which is exactly the half-sample mirror boundary) or here
// in the shader with texelFetch (exact float weights).
// Topics: diffusion_math.
uniform highp sampler2D uF;      // F at iteration k
uniform highp sampler2D uRates;  // .r = rho(x) (gpu_diffusion_rates)
uniform int uK;                 // iteration index k
uniform int uScheme;            // 0 standard, 1 invariant, 2 invariant-exact
uniform float uSigma0;
uniform int uHardware;
uniform int uEdgeRate;          // 0 mean (eq. 12), 1 min, 2 harmonic
layout(location = 0) out vec4 oF;

// Half-sample mirror of an index into [0, n). GLSL's % is undefined for
// negative operands, so reflect negatives first (-1 -> 0, -2 -> 1, ...).
int mirror_index(int i, int n) {
  if (i >= 0 && i < n) return i;
  if (i < 0) i = -1 - i;
  int period = 2 * n;
  i = i % period;
  return i < n ? i : period - 1 - i;
}

// `tex` linearly interpolated at p + d * axis (d of either sign), with the
// half-sample mirror outside the image: one helper for F and for the rates.
vec4 sample_axis(highp sampler2D tex, ivec2 p, float d, ivec2 axis, ivec2 size) {
  if (uHardware == 1) return texture(tex, (vec2(p) + 0.5 + d * vec2(axis)) / vec2(size));
  float fl = floor(d);
  float fr = d - fl;
  int i0 = int(fl);
  ivec2 a = p + i0 * axis, b = p + (i0 + 1) * axis;
  a = ivec2(mirror_index(a.x, size.x), mirror_index(a.y, size.y));
  b = ivec2(mirror_index(b.x, size.x), mirror_index(b.y, size.y));
  vec4 va = texelFetch(tex, a, 0), vb = texelFetch(tex, b, 0);
  return va + fr * (vb - va);
}

// The rate of the tap at p + d * axis (brume_tap_rate): hardware or shader
// interpolation for the mean (as F), the texels' smaller rate for min and
// harmonic, read with texelFetch so that no filter blends them.
float rate_axis(ivec2 p, float d, ivec2 axis, ivec2 size) {
  if (uEdgeRate == 0) return sample_axis(uRates, p, d, axis, size).r;
  float fl = floor(d);
  float fr = d - fl;
  int i0 = int(fl);
  ivec2 a = p + i0 * axis, b = p + (i0 + 1) * axis;
  a = ivec2(mirror_index(a.x, size.x), mirror_index(a.y, size.y));
  b = ivec2(mirror_index(b.x, size.x), mirror_index(b.y, size.y));
  return brume_tap_rate(texelFetch(uRates, a, 0).r, texelFetch(uRates, b, 0).r, fr, uEdgeRate);
}

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  ivec2 size = textureSize(uF, 0);
  float rho = texelFetch(uRates, p, 0).r;
  float h = 1.0;
  if (uScheme != 0) h = brume_invariant_offset(uSigma0 * exp(float(uK) * rho), rho, uScheme == 2);
  vec4 fc = texelFetch(uF, p, 0);
  const ivec2 X = ivec2(1, 0), Y = ivec2(0, 1);
  vec4 l = sample_axis(uF, p, -h, X, size), r = sample_axis(uF, p, h, X, size);
  vec4 u = sample_axis(uF, p, -h, Y, size), d = sample_axis(uF, p, h, Y, size);
  float wl = brume_edge_rate(rho, rate_axis(p, -h, X, size), uEdgeRate);
  float wr = brume_edge_rate(rho, rate_axis(p, h, X, size), uEdgeRate);
  float wu = brume_edge_rate(rho, rate_axis(p, -h, Y, size), uEdgeRate);
  float wd = brume_edge_rate(rho, rate_axis(p, h, Y, size), uEdgeRate);
  oF = brume_diffusion_update(fc, l, r, u, d, wl, wr, wu, wd);
}
