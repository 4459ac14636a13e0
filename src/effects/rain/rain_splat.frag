// The falling particles' streaks splatted over the scene (the CPU's splat_streaks,
// src/effects/rain/streaks.cpp; brume/rain.hpp states the equations), a pixel per fragment: the
// pixel walks its tile's list of streaks (bin_streaks: far to near, ties in the enumeration's
// order) and, for each, the samples that have a tap on it in sample order, and takes each tap as
// the CPU does, I <- I + a (E - I), a = w * m/n * vis clamped to 1 (counted): the same updates in
// the same order as the CPU gives the pixel (per sample a pixel has at most one tap), in float.
// A streak i is uStreaks' texels 5i .. 5i + 4 (row-major, uStreakWidth a row):
//   0: P = c + u t0 [m], n (samples)       1: Q = u (t1 - t0)/n [m], rad
//   2: E' (linear RGB), m/n [px^2]         3: 1/(2 sigma^2) [px^-2], 1 for the Gaussian kernel
//   4: its columns and rows (u_lo, u_hi, v_lo, v_hi: they bound every pixel its samples touch),
//      read first: a pixel one beyond them skips the streak
// so that sample j (s = j + 1/2) is at X = P + s Q (the CPU's c + u (t0 + (t1 - t0) s/n)). Its
// image position u = fx X.x/X.z + cx (v likewise), its range r = |X|, its coverage m/n r/z^3 over
// the kernel's weight w: bilinear (taps at floor(u), floor(u) + 1) or a Gaussian about
// round(u) truncated at rad, normalised over its 2 rad + 1 taps per axis; hidden where the
// scene's range r_s is nearer: vis = clamp((r_s - r)/(uSoftness r), 0, 1) (unknown range: 1).
// Which samples: on the path's major image axis (monotone in s: a straight 3-D path's image) the
// samples within a tap's reach of the pixel plus one pixel, found by inverting the projection,
// widened by two samples; each is then tested exactly, so the window only skips samples with no
// tap on the pixel.
// Out: the pixel (rgb) and how many of its taps were clamped to 1 (a).
// Topics: none.
uniform highp sampler2D uImage;     // the scene through the analytic media (linear RGB)
uniform highp sampler2D uRange;     // metres along the ray (-1 = unknown)
uniform highp sampler2D uStreaks;   // 4 texels a streak (above)
uniform highp usampler2D uFirst;    // tile t's list starts at uFirst[t] and ends at uFirst[t + 1]
uniform highp usampler2D uList;     // the lists: indices of streaks
uniform vec4 uK;                    // fx, fy, cx, cy [px]
uniform ivec2 uTile;                // a tile's width and height [px]
uniform int uTilesX;                // tiles per row
uniform int uStreakWidth;           // uStreaks' width
uniform int uIndexWidth;            // uFirst's and uList's width
uniform float uSoftness;            // kRainDepthSoftness
out vec4 oColor;

vec4 streak_texel(int i, int q) {
  int t = 5 * i + q;
  return texelFetch(uStreaks, ivec2(t % uStreakWidth, t / uStreakWidth), 0);
}
uint index_at(highp usampler2D s, uint i) {
  int t = int(i);
  return texelFetch(s, ivec2(t % uIndexWidth, t / uIndexWidth), 0).r;
}
// lround: half away from zero.
int round_away(float x) { return x >= 0.0 ? int(floor(x + 0.5)) : -int(floor(0.5 - x)); }

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 o = texelFetch(uImage, p, 0).rgb;
  float rs = texelFetch(uRange, p, 0).r;
  bool sky = rs < 0.0;
  float clamped = 0.0;
  int tile = (p.y / uTile.y) * uTilesX + p.x / uTile.x;
  uint e0 = index_at(uFirst, uint(tile)), e1 = index_at(uFirst, uint(tile + 1));
  float fx = uK.x, fy = uK.y, cx = uK.z, cy = uK.w;
  for (uint e = e0; e < e1; ++e) {
    int i = int(index_at(uList, e));
    vec4 box = streak_texel(i, 4);
    if (float(p.x) < box.x - 1.0 || float(p.x) > box.y + 1.0 || float(p.y) < box.z - 1.0 || float(p.y) > box.w + 1.0)
      continue;
    vec4 t0 = streak_texel(i, 0), t1 = streak_texel(i, 1), t2 = streak_texel(i, 2), t3 = streak_texel(i, 3);
    vec3 P = t0.xyz, Q = t1.xyz;
    int n = int(t0.w), rad = int(t1.w);
    bool gauss = t3.y > 0.5;
    float inv = t3.x;
    int j0 = 0, j1 = n;
    if (n > 4) {
      vec3 A = P + 0.5 * Q, B = P + (float(n) - 0.5) * Q;
      float ua = fx * A.x / A.z + cx, ub = fx * B.x / B.z + cx;
      float va = fy * A.y / A.z + cy, vb = fy * B.y / B.z + cy;
      bool rows = abs(vb - va) >= abs(ub - ua);
      float f = rows ? fy : fx, c = rows ? cy : cx, at = rows ? float(p.y) : float(p.x);
      float a0 = rows ? va : ua, a1 = rows ? vb : ub, P1 = rows ? P.y : P.x, Q1 = rows ? Q.y : Q.x;
      float reach = gauss ? float(rad) + 0.5 : 1.0;
      float lo = max(at - reach - 1.0, min(a0, a1)), hi = min(at + reach + 1.0, max(a0, a1));
      if (lo > hi) continue;
      // s where the coordinate is R: f (P1 + Q1 s) = (R - c)(P.z + Q.z s).
      float sl = ((lo - c) * P.z - f * P1) / (f * Q1 - (lo - c) * Q.z);
      float sh = ((hi - c) * P.z - f * P1) / (f * Q1 - (hi - c) * Q.z);
      float s0 = clamp(min(sl, sh) - 0.5, -4.0, float(n) + 4.0), s1 = clamp(max(sl, sh) - 0.5, -4.0, float(n) + 4.0);
      j0 = max(0, int(floor(s0)) - 2);
      j1 = min(n, int(ceil(s1)) + 3);
    }
    vec3 E = t2.xyz;
    float m = t2.w;
    for (int j = j0; j < j1; ++j) {
      vec3 X = P + (float(j) + 0.5) * Q;
      float u = fx * X.x / X.z + cx, v = fy * X.y / X.z + cy;
      float w;
      if (!gauss) {
        float fu = floor(u), fv = floor(v);
        int x0 = int(fu), y0 = int(fv);
        if ((p.x != x0 && p.x != x0 + 1) || (p.y != y0 && p.y != y0 + 1)) continue;
        float ax = u - fu, ay = v - fv;
        w = (p.x == x0 ? 1.0 - ax : ax) * (p.y == y0 ? 1.0 - ay : ay);
      } else {
        int xc = round_away(u), yc = round_away(v);
        if (abs(p.x - xc) > rad || abs(p.y - yc) > rad) continue;
        float sx = 0.0, sy = 0.0, wx = 0.0, wy = 0.0;
        for (int q = -rad; q <= rad; ++q) {
          float dx = float(xc + q) - u, dy = float(yc + q) - v;
          float gx = exp(-(dx * dx) * inv), gy = exp(-(dy * dy) * inv);
          sx += gx, sy += gy;
          if (xc + q == p.x) wx = gx;
          if (yc + q == p.y) wy = gy;
        }
        w = wx * wy / (sx * sy);
      }
      if (!(w > 0.0)) continue;
      float r = sqrt(X.x * X.x + X.y * X.y + X.z * X.z);
      float a_sample = m * r / (X.z * X.z * X.z);
      float vis = sky ? 1.0 : min(1.0, max(0.0, (rs - r) * (1.0 / (uSoftness * r))));
      float a = w * a_sample * vis;
      if (!(a > 0.0)) continue;
      if (a > 1.0) {
        a = 1.0;
        clamped += 1.0;
      }
      o += a * (E - o);
    }
  }
  oColor = vec4(o, clamped);
}
