// Last haze pass (Hansard eq. 4): out = F.rgb + (1 - F.a) B with the blurred
// transmission F.a (premultiplied), or the naive tau0 E_blurred + (1 - tau0) B.
// Topics: haze_math.
uniform highp sampler2D uF;
uniform highp sampler2D uAux;  // .g = tau0
uniform vec3 uAirlight;        // linear RGB
uniform int uNaive;
layout(location = 0) out vec4 oColor;  // rgb: result, a: blurred transmission

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec4 f = texelFetch(uF, p, 0);
  vec3 c;
  if (uNaive == 1) {
    float t0 = texelFetch(uAux, p, 0).g;
    c = vec3(brume_composite_naive(f.r, t0, uAirlight.r), brume_composite_naive(f.g, t0, uAirlight.g),
             brume_composite_naive(f.b, t0, uAirlight.b));
  } else {
    c = vec3(brume_composite_premultiplied(f.r, f.a, uAirlight.r), brume_composite_premultiplied(f.g, f.a, uAirlight.g),
             brume_composite_premultiplied(f.b, f.a, uAirlight.b));
  }
  oColor = vec4(c, f.a);
}
