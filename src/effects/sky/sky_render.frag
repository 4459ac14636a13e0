// The Preetham sky, one fragment per pixel (include/brume/sky.hpp): the
// pixel's direction through the projection, the Perez distribution of Y, x, y
// with the per-image coefficients and normalisations the host computed with
// the same shared functions as the CPU renderer, xyY -> XYZ -> linear sRGB.
// The CPU tabulates the gamma term per image (a CPU schedule choice); here
// it is evaluated directly (acos, exp), the exact function the table samples.
// alpha = 0 marks "no sky" (outside the fisheye circle, or below the horizon
// without --ground): the host writes NaN there, because GLSL compilers may
// fold a NaN constant away.
// Topics: aerial_math, sky_math.
uniform int uProjection;      // 0 fisheye, 1 equirectangular, 2 pinhole
uniform vec2 uSize;           // W, H
uniform vec3 uFisheye;        // cx, cy, radius [px]
uniform float uOffset;        // azimuth offset [rad]
uniform vec3 uRay0;           // pinhole world_from_pixel rows: d = M (u, v, 1)
uniform vec3 uRay1;
uniform vec3 uRay2;
uniform float uCoef[15];      // Perez A..E of Y, x, y
uniform vec3 uScale;          // zenith value / F(0, theta_s) per channel (Y times the exposure)
uniform vec3 uSun;            // sin theta_s, cos theta_s, phi_s [rad]
uniform float uCosDisc;       // cos of the disc's radius; > 1 when no disc is drawn
uniform float uSunY;          // disc luminance
uniform vec4 uGround;         // linear RGB below the horizon, a = 1; a = 0: NaN
layout(location = 0) out vec4 oColor;

void main() {
  vec2 px = gl_FragCoord.xy - 0.5;  // pixel (u, v), rows not flipped
  float st, ct, phi;
  bool below;
  if (uProjection == 0) {
    float du = px.x - uFisheye.x, dv = px.y - uFisheye.y;
    float r = brume_sky_fisheye_r(du, dv);
    if (r > uFisheye.z) {
      oColor = vec4(0.0);
      return;
    }
    float th = brume_sky_fisheye_theta(r, uFisheye.z);
    below = brume_sky_below_horizon(th);
    st = sin(th);
    ct = cos(th);
    phi = brume_sky_fisheye_phi(du, dv, uOffset);
  } else if (uProjection == 1) {
    float th = brume_sky_equirect_theta(px.y, uSize.y);
    below = brume_sky_below_horizon(th);
    st = sin(th);
    ct = cos(th);
    phi = brume_sky_equirect_phi(px.x, uSize.x, uOffset);
  } else {
    vec3 q = vec3(px, 1.0);
    vec3 d = vec3(dot(uRay0, q), dot(uRay1, q), dot(uRay2, q));
    st = brume_sky_ray_sin_theta(d.x, d.y, d.z);
    ct = brume_sky_ray_cos_theta(d.x, d.y, d.z);
    phi = brume_sky_ray_phi(d.x, d.z);
    below = ct < 0.0;  // the CPU's float test differs only within ~1e-7 rad of the horizon
  }
  if (below) {
    oColor = uGround;
    return;
  }
  float cg = brume_sky_cos_gamma(st, ct, uSun.x, uSun.y, cos(phi - uSun.z));
  if (cg >= uCosDisc) {
    // The sun's own colour is not modelled: a white (D65, equal-energy in linear sRGB) disc, as the CPU.
    oColor = vec4(vec3(uSunY), 1.0);
    return;
  }
  float v[3];
  for (int c = 0; c < 3; ++c)
    v[c] = brume_sky_channel(uScale[c], brume_perez_theta(uCoef[5 * c], uCoef[5 * c + 1], ct), uCoef[5 * c + 2],
                             uCoef[5 * c + 3], uCoef[5 * c + 4], cg);
  float Y = v[0], xx = v[1], yy = v[2];
  float X = xx * Y / yy, Z = (1.0 - xx - yy) * Y / yy;
  oColor = vec4(brume_xyz_to_r(X, Y, Z), brume_xyz_to_g(X, Y, Z), brume_xyz_to_b(X, Y, Z), 1.0);
}
