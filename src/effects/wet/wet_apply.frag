// The wet ground's pass (brume/wet.hpp; the CPU's render_wet, src/effects/wet/wet.cpp): per
// pixel the ground test (its 3-D point within uTolerance of the plane, or the mask), the
// darkening K_eff and the mirror f R_F(theta) L, L what the pixel's ray mirrored about the
// plane's normal sees: marched through the range map one pixel of its image's major axis a step
// (the CPU skips the blocks its min-depth pyramids clear, which holds the same samples), a hit
// where it passes a pixel's planar depth by more than the margin (bisected to 1/64 step) and by
// less than the thickness; at its vanishing point the pixel there; leaving the frame, uSky.
// Off the ground the pixel as it came.
// The march is the CPU's in a form that float keeps: along the mirrored ray X = P + t D,
// w = 1/Z and the image point are linear in the step s, u = (x, y) - s (a_u, a_v)/m,
// w = 1/P_z - s D_z/m, a = (f_x (P_x D_z - D_x P_z), f_y (P_y D_z - D_y P_z)), m = max |a|: the
// CPU's u_inf + w c_u with u_inf and c_u ~ 1/D_z, which cancel in float at grazing rays.
// uMarch (WetMarch): 0 blocks, every pixel a sample; 1 above-ground, once the ray is higher above
// the plane than uTolerance (from its lift point w_lift on, the CPU's rule) a sample on one of the
// plane's own pixels (known range, its ray going down, |h + r dn| <= uTolerance: the ground test)
// reads as +inf: tested per sample from the range (the CPU's second depth map, without an upload).
// Topics: wet_math.
uniform highp sampler2D uImage;  // linear RGB
uniform highp sampler2D uRange;  // metres along the ray (-1 = unknown)
uniform highp sampler2D uMask;   // .r: the ground where > 1/2, with uMasked
uniform int uMasked;             // 1: the mask gives the ground, 0: the plane's test
uniform vec4 uK;                 // fx, fy, cx, cy [px]
uniform vec3 uNormal;            // the plane's normal (world +y) in the camera's cv frame
uniform float uHeight;           // the camera above the plane [m]
uniform float uTolerance;        // [m]
uniform float uKEff;             // K_eff
uniform float uWetted;           // f
uniform float uWaterIndex;       // n
uniform vec3 uSky;               // what a ray leaving the frame sees (linear RGB)
uniform float uFrontK;           // 1 + the hit margin
uniform float uThickK;           // 1 + the hit margin + the thickness
uniform int uMaxSteps;           // the march's steps at most
uniform int uMarch;              // 0 blocks, 1 above-ground (WetMarch)
layout(location = 0) out vec4 oColor;
layout(location = 1) out vec4 oInfo;  // r: 1 on the ground; g: 1 hit, 2 the vanishing point's pixel, 3 left the frame; ba: the pixel L came from

ivec2 frame_size() { return textureSize(uRange, 0); }

bool inside(vec2 q) {
  vec2 s = vec2(frame_size());
  return q.x > -0.5 && q.x < s.x - 0.5 && q.y > -0.5 && q.y < s.y - 0.5;
}

// The planar depth of pixel q (range / |ray|), +inf where the range is unknown.
float planar_depth(ivec2 q) {
  float r = texelFetch(uRange, q, 0).r;
  if (!(r > 0.0)) return uintBitsToFloat(0x7F800000u);
  vec2 xy = (vec2(q) - uK.zw) / uK.xy;
  return r / sqrt(xy.x * xy.x + xy.y * xy.y + 1.0);
}

// Pixel q's unit ray (cv) and 1/|ray|.
vec3 pixel_ray(ivec2 q, out float inv) {
  vec2 xy = (vec2(q) - uK.zw) / uK.xy;
  inv = 1.0 / sqrt(xy.x * xy.x + xy.y * xy.y + 1.0);
  return vec3(xy, 1.0) * inv;
}

// The plane's test of a pixel of planar depth z (finite): its ray goes down and its 3-D point lies
// within the tolerance of the plane (render_wet's expressions, in float).
bool on_plane(float z, float inv, float dn) { return dn < 0.0 && abs(uHeight + z / inv * dn) <= uTolerance; }

// The nearest pixel's planar depth at an image point inside the frame (halves away from 0); with
// `lifted`, +inf on the plane's own pixels.
float depth_at(vec2 q, bool lifted) {
  ivec2 i = ivec2(floor(q + 0.5));
  float z = planar_depth(i);
  if (lifted && !isinf(z)) {
    float inv;
    vec3 d = pixel_ray(i, inv);
    if (on_plane(z, inv, dot(d, uNormal))) return uintBitsToFloat(0x7F800000u);
  }
  return z;
}

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 c = texelFetch(uImage, p, 0).rgb;
  oColor = vec4(c, 1.0);
  oInfo = vec4(0.0);
  if (!(texelFetch(uRange, p, 0).r > 0.0)) return;
  float z0 = planar_depth(p);
  float inv;
  vec3 d = pixel_ray(p, inv);  // the unit ray (cv)
  float dn = dot(d, uNormal);
  if (!(dn < 0.0)) return;  // a ray that cannot meet the ground from above
  float r0 = z0 / inv;
  bool ground = uMasked == 1 ? texelFetch(uMask, p, 0).r > 0.5 : on_plane(z0, inv, dn);
  if (!ground) return;

  vec3 P = r0 * d;
  vec3 D = d - 2.0 * dn * uNormal;
  vec2 a = vec2(uK.x * (P.x * D.z - D.x * P.z), uK.y * (P.y * D.z - D.y * P.z));
  float m = max(max(abs(a.x), abs(a.y)), 1e-30);
  vec2 step_uv = -a / m;
  float step_w = -D.z / m;
  float w0 = 1.0 / P.z;
  vec2 p0 = vec2(p);
  // above-ground: the lift point, where the ray's height above the plane, h + r0 dn + t (-dn),
  // reaches the tolerance (lifted from the start when it is there already; never when the ray
  // turns behind the camera first).
  bool lifted = false, can_lift = false;
  float w_lift = 0.0;
  if (uMarch == 1) {
    float t_lift = (uTolerance - (uHeight + r0 * dn)) / -dn;
    float z_lift = P.z + max(t_lift, 0.0) * D.z;
    if (t_lift <= 0.0) {
      lifted = true;
    } else if (z_lift > 0.0) {
      can_lift = true;
      w_lift = 1.0 / z_lift;
    }
  }
  int end = 3;
  vec2 h = vec2(0.0);
  bool front = true;  // the ray's last point lay in front of the depth map
  for (int s = 1; s <= uMaxSteps; ++s) {
    float wc = w0 + float(s - 1) * step_w;
    if (D.z > 0.0 && wc * m < 0.5 * D.z) {  // within half a pixel of its vanishing point
      end = 2;
      break;
    }
    if (can_lift && !lifted && (D.z > 0.0 ? wc <= w_lift : wc >= w_lift)) lifted = true;
    float w1 = w0 + float(s) * step_w;
    vec2 q = p0 + float(s) * step_uv;
    if (!(w1 > 0.0) || !inside(q)) break;  // leaves the frame (or turns behind the camera)
    bool behind = 1.0 / w1 > depth_at(q, lifted) * uFrontK;
    if (behind && front) {
      float lo = float(s - 1), hi = float(s);  // bisection to the crossing: within 1/64 of a step
      for (int b = 0; b < 6; ++b) {
        float mid = 0.5 * (lo + hi);
        vec2 mq = p0 + mid * step_uv;
        if (inside(mq) && 1.0 / (w0 + mid * step_w) > depth_at(mq, lifted) * uFrontK) hi = mid;
        else lo = mid;
      }
      h = p0 + hi * step_uv;
      if (!inside(h)) h = q;
      if (1.0 / (w0 + hi * step_w) <= depth_at(h, lifted) * uThickK) {  // within the surfaces' thickness: a hit
        end = 1;
        break;
      }
    }
    front = !behind;
    if (s == uMaxSteps) end = 2;
  }
  if (end == 2) {
    vec2 vp = vec2(uK.x * D.x / D.z + uK.z, uK.y * D.y / D.z + uK.w);
    if (D.z > 0.0 && inside(vp)) h = vp;
    else end = 3;
  }
  vec3 L = end == 3 ? uSky : texelFetch(uImage, ivec2(floor(h + 0.5)), 0).rgb;
  float mirror = uWetted * brume_wet_fresnel(-dn, uWaterIndex);
  oColor = vec4(uKEff * c + mirror * L, 1.0);
  oInfo = vec4(1.0, float(end), end == 3 ? vec2(-1.0) : floor(h + 0.5));
}
