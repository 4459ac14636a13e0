// Last aerial pass: out_c = F_c + (1 - F_{3+c}) A_c (Hansard eq. 4 per
// channel), back to linear sRGB from XYZ, remove's result as it is; sky
// pixels (uSky, or unknown in uRange) keep the input colour and rho = 1.
// Topics: haze_math, aerial_math.
uniform highp sampler2D uF0;
uniform highp sampler2D uF1;
uniform highp sampler2D uImage;
uniform highp sampler2D uRange;
uniform highp sampler2D uSky;  // .r = 1: unknown in the measured range
uniform vec3 uA;
uniform int uMode;
uniform int uXyz;
layout(location = 0) out vec4 oColor;
layout(location = 1) out vec4 oAtt;

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  if (texelFetch(uSky, p, 0).r > 0.5 || !(texelFetch(uRange, p, 0).r > 0.0)) {
    oColor = vec4(texelFetch(uImage, p, 0).rgb, 1.0);
    oAtt = vec4(1.0);
    return;
  }
  vec4 f0 = texelFetch(uF0, p, 0);
  vec4 f1 = texelFetch(uF1, p, 0);
  vec3 rho = vec3(f0.a, f1.r, f1.g);
  vec3 o = uMode == 2 ? f0.rgb
                      : vec3(brume_composite_premultiplied(f0.r, rho.r, uA.r),
                             brume_composite_premultiplied(f0.g, rho.g, uA.g),
                             brume_composite_premultiplied(f0.b, rho.b, uA.b));
  if (uXyz == 1)
    o = vec3(brume_xyz_to_r(o.x, o.y, o.z), brume_xyz_to_g(o.x, o.y, o.z), brume_xyz_to_b(o.x, o.y, o.z));
  oColor = vec4(o, 1.0);
  oAtt = vec4(rho, 1.0);
}
