// brume — procedural RGB-D demo scene.
//
// A pinhole camera 1.6 m above a flat ground plane (y = 0) looks along +z,
// tilted 5 degrees down, with a 55 degree vertical field of view; the horizon
// sits at about 42 % of the image height. World units are metres: x points
// right, y up, z forward, the camera centre is at (0, 1.6, 0). Contents, by
// range from the camera:
//   ~4 m        a red/white checkered ball (r = 0.5 m) left of the path
//   3-120 m     a straight paved path (two-tone 0.5 m slabs, kerbs) heading
//               4 degrees left, with a white post-and-rail fence on its right
//   ~10 m       a black/white checkered 1 m cube behind the fence
//   ~13 m       a tree (trunk and leafy crown) on the left; another at ~28 m
//   ~35 m       a two-storey house with windows and a tiled gable roof
//   ~80 m       an apartment block, with a taller office block at ~110 m
//   ~165-220 m  a tree line; beyond ~110 m the mown lawn turns into fields
//   ~300-650 m  rolling hills covered in fields, hedgerows and woods
//   ~750-1250 m forested mountains with meadows and rocky tops
//   sky         pale horizon to deep-blue zenith with soft clouds; range NaN
// Lighting is Lambertian: a warm sun behind the camera's left shoulder with
// hard shadows, plus a hemispherical sky/ground ambient term; no aerial
// perspective (adding that is the library's job).
//
// Anti-aliasing: every pixel's centre ray is traced first; pixels at object,
// depth or shadow edges, on sharp patterns (checkers, windows, tiles, distant
// paving) or near the thin fence are then supersampled on a 3x3 grid, the
// centre subsample being that first ray. Ground textures and all noise are
// also box-filtered analytically over the sample footprint, so regular
// patterns fade to their mean instead of aliasing in the distance. Colours are
// averaged; the range is always that of the pixel-centre ray, so depth edges
// stay sharp. Output colour is linear light in [0,1]; range is the distance in
// metres from the camera centre along the pixel's ray.
//
// Deterministic: IEEE double arithmetic with no libm calls other than sqrt
// (correctly rounded), integer-hash noise and independent work per pixel, so
// the result depends neither on the thread count nor on the machine (given
// the project's strict ISO mode, i.e. no FMA contraction).
#include "brume/demo_scene.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace brume {
namespace {

// ---------------------------------------------------------------- vectors --

struct V3 {
  double x, y, z;
};
inline V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 operator*(V3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
inline V3 operator*(double s, V3 a) { return a * s; }
inline V3 mul(V3 a, V3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
inline double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 normalize(V3 a) { return a * (1.0 / std::sqrt(dot(a, a))); }
inline V3 mix(V3 a, V3 b, double t) { return a + (b - a) * t; }
inline double clamp01(double v) { return std::min(1.0, std::max(0.0, v)); }
inline double smoothstep(double e0, double e1, double x) {
  double t = clamp01((x - e0) / (e1 - e0));
  return t * t * (3.0 - 2.0 * t);
}

constexpr double kInf = 1e30;
constexpr double kEps = 1e-7;

// ------------------------------------------------------- hashing / noise --

inline std::uint32_t mix32(std::uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  x ^= x >> 16;
  return x;
}
inline std::uint32_t hash2(std::int32_t x, std::int32_t y, std::uint32_t seed) {
  return mix32(static_cast<std::uint32_t>(x) * 0x8da6b343U ^
               static_cast<std::uint32_t>(y) * 0xd8163841U ^ seed * 0x9e3779b9U);
}
inline std::uint32_t hash3(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
  return mix32(static_cast<std::uint32_t>(x) * 0x8da6b343U ^
               static_cast<std::uint32_t>(y) * 0xd8163841U ^
               static_cast<std::uint32_t>(z) * 0xcb1ab31fU ^ seed * 0x9e3779b9U);
}
inline double unit(std::uint32_t h) { return static_cast<double>(h >> 8) * (1.0 / 16777216.0); }

// floor() for |v| < 2^62 by truncation (baseline x86-64 has no rounding
// instruction, and this is on the hot path of every texture).
inline double fast_floor(double v) {
  double t = static_cast<double>(static_cast<std::int64_t>(v));
  return t > v ? t - 1.0 : t;
}

// Lattice coordinate, kept far from int overflow.
inline std::int32_t cell(double v, double& frac) {
  v = std::min(1e8, std::max(-1e8, v));
  double f = fast_floor(v);
  frac = v - f;
  return static_cast<std::int32_t>(f);
}

// Lattice values for 2-D value noise: a 256 x 256 tile of integer-hashed
// values, built once and never modified (the hashes are cheap, but four per
// lookup dominate the render time).
constexpr int kNoiseSize = 256;
const std::vector<float>& noise_lattice() {
  static const std::vector<float> lattice = [] {
    std::vector<float> v(static_cast<std::size_t>(kNoiseSize) * kNoiseSize);
    for (int y = 0; y < kNoiseSize; ++y)
      for (int x = 0; x < kNoiseSize; ++x)
        v[static_cast<std::size_t>(y) * kNoiseSize + x] =
            static_cast<float>(unit(hash2(x, y, 0x5eedU)));
    return v;
  }();
  return lattice;
}

// Smooth value noise in [0,1]; `seed` selects a different offset into the
// (256-periodic) lattice.
double vnoise2(double x, double y, std::uint32_t seed) {
  const float* lat = noise_lattice().data();
  const std::uint32_t hs = mix32(seed * 0x9e3779b9U + 0x632be5abU);
  double fx, fy;
  const std::uint32_t ix = static_cast<std::uint32_t>(cell(x, fx)) + hs;
  const std::uint32_t iy = static_cast<std::uint32_t>(cell(y, fy)) + (hs >> 8);
  const std::uint32_t m = kNoiseSize - 1;
  const float* r0 = lat + static_cast<std::size_t>(iy & m) * kNoiseSize;
  const float* r1 = lat + static_cast<std::size_t>((iy + 1) & m) * kNoiseSize;
  const double a = r0[ix & m], b = r0[(ix + 1) & m], c = r1[ix & m], d = r1[(ix + 1) & m];
  const double ux = fx * fx * (3.0 - 2.0 * fx), uy = fy * fy * (3.0 - 2.0 * fy);
  const double ab = a + (b - a) * ux;
  return ab + ((c + (d - c) * ux) - ab) * uy;
}

double vnoise3(V3 p, std::uint32_t seed) {
  double fx, fy, fz;
  std::int32_t ix = cell(p.x, fx), iy = cell(p.y, fy), iz = cell(p.z, fz);
  double ux = fx * fx * (3.0 - 2.0 * fx), uy = fy * fy * (3.0 - 2.0 * fy),
         uz = fz * fz * (3.0 - 2.0 * fz);
  double v[2];
  for (int k = 0; k < 2; ++k) {
    double a = unit(hash3(ix, iy, iz + k, seed)), b = unit(hash3(ix + 1, iy, iz + k, seed));
    double c = unit(hash3(ix, iy + 1, iz + k, seed)), d = unit(hash3(ix + 1, iy + 1, iz + k, seed));
    double ab = a + (b - a) * ux, cd = c + (d - c) * ux;
    v[k] = ab + (cd - ab) * uy;
  }
  return v[0] + (v[1] - v[0]) * uz;
}

// Octave weight for a pattern of frequency f (cycles per unit) seen through a
// box filter of width w units: 1 when well resolved, 0 when it would alias.
inline double octave_fade(double f, double w) { return clamp01((0.5 - f * w) * 4.0); }

// Fractal value noise in [0,1] (mean 0.5), octaves fading out with the filter
// footprint w (in units of the base frequency); `gain` is the amplitude ratio
// between successive octaves.
double fbm2(double x, double y, int octaves, double w, std::uint32_t seed, double gain = 0.5) {
  double sum = 0.0, amp = 0.5, norm = 0.0, f = 1.0;
  for (int i = 0; i < octaves; ++i) {
    double fade = octave_fade(f, w);
    if (fade <= 0.0) break;
    sum += amp * fade * (vnoise2(x * f, y * f, seed + 17U * i) - 0.5);
    norm += amp;
    amp *= gain;
    f *= 2.03;
  }
  return norm > 0.0 ? 0.5 + sum / norm : 0.5;
}

double fbm3(V3 p, int octaves, double w, std::uint32_t seed) {
  double sum = 0.0, amp = 0.5, norm = 0.0, f = 1.0;
  for (int i = 0; i < octaves; ++i) {
    double fade = octave_fade(f, w);
    if (fade <= 0.0) break;
    sum += amp * fade * (vnoise3(p * f, seed + 31U * i) - 0.5);
    norm += amp;
    amp *= 0.5;
    f *= 2.01;
  }
  return norm > 0.0 ? 0.5 + sum / norm : 0.5;
}

// Box-filtered periodic pulse: the fraction of [x - w/2, x + w/2] in which
// frac(x) < duty (w in units of the period).
inline double pulse_integral(double x, double duty) {
  double f = fast_floor(x);
  return f * duty + std::min(x - f, duty);
}
inline double filtered_pulse(double x, double duty, double w) {
  if (w < 1e-6) return (x - fast_floor(x)) < duty ? 1.0 : 0.0;
  if (w > 1e4) return duty;
  return (pulse_integral(x + 0.5 * w, duty) - pulse_integral(x - 0.5 * w, duty)) / w;
}
// Filtered lines of width `width` centred on integer multiples of `period`.
inline double filtered_lines(double x, double period, double width, double w) {
  return filtered_pulse(x / period + 0.5 * width / period, width / period, w / period);
}
// Filtered step: 1 where x < edge.
inline double filtered_below(double x, double edge, double w) {
  if (w < 1e-9) return x < edge ? 1.0 : 0.0;
  return clamp01((edge - x) / w + 0.5);
}

// ----------------------------------------------------------------- scene --

enum Mat : int {
  kNone = -1,
  kGround,
  kBall,
  kCube,
  kTrunk,
  kCrown,
  kFence,
  kHouseWall,
  kRoof,
  kChimney,
  kBlockA,
  kBlockB,
  kTreeLine,
  kHill,
  kMountain,
};

// Objects for culling (bit positions in object masks).
enum Obj : int {
  kObjBall,
  kObjCube,
  kObjTree0,
  kObjTree1,
  kObjFence,
  kObjHouse,
  kObjBlockA,
  kObjBlockB,
  kObjTreeLine,
  kObjCount
};

struct Ray {
  V3 o, d, inv;
};
inline Ray make_ray(V3 o, V3 d) {
  auto iv = [](double v) { return 1.0 / (std::fabs(v) < 1e-30 ? (v < 0 ? -1e-30 : 1e-30) : v); };
  return {o, d, {iv(d.x), iv(d.y), iv(d.z)}};
}

struct Hit {
  double t = kInf;
  int mat = kNone;
  V3 n{0, 1, 0};
  int id = 0;
  bool thin = false;        // the ray crossed the fence's bounds beyond thin_from
  double thin_from = kInf;  // (input) distance beyond which the fence is thin on screen
};

struct Sphere {
  V3 c;
  double r;
};
struct Box {
  V3 lo, hi;
};
struct Ellipsoid {
  V3 c, r;
  int mat;
  V3 inv_r{};          // 1 / r, filled in by make_scene
  double slope = 0.0;  // bound on (y - camera height) / z over the ellipsoid
};
struct Poly {  // convex: dot(n[i], p) <= d[i]
  std::array<V3, 7> n;
  std::array<double, 7> d;
  int count;
};
struct Tree {
  double x, z, trunk_r, trunk_h;
  std::array<Sphere, 7> crown;
  Box bounds;
};

constexpr double kCamHeight = 1.6;
constexpr double kFovYDeg = 55.0;
// Trigonometry of the 5 degree downward pitch and the half field of view,
// as literals so that no libm rounding differences can enter.
constexpr double kSinPitch = 0.08715574274765817;    // sin(5 deg)
constexpr double kCosPitch = 0.9961946980917455;     // cos(5 deg)
constexpr double kTanHalfFovY = 0.5205670505517462;  // tan(27.5 deg)

// Sun direction (towards the sun), behind the camera's left shoulder.
constexpr V3 kSunRaw{-0.50, 0.62, -0.60};

// Path: a straight paved strip from (1.2, 0, 0), heading 4 degrees left.
constexpr double kPathX0 = 1.2;
constexpr double kPathSin = -0.0697565;  // sin(-4 deg)
constexpr double kPathCos = 0.9975641;   // cos(-4 deg)
constexpr double kPathHalf = 1.7;        // paving half-width
constexpr double kKerbHalf = 1.95;       // paving + kerb
// Fence in path-local coordinates (s along, r across to the right).
constexpr double kFencePostR0 = 2.44, kFencePostR1 = 2.56, kFencePostHalf = 0.06;
constexpr double kFenceRailR0 = 2.38, kFenceRailR1 = 2.44;
constexpr double kFenceTop = 1.16, kFenceSpacing = 2.5, kFenceStart = 1.0, kFenceLength = 120.0;
constexpr double kRail0Lo = 0.46, kRail0Hi = 0.56, kRail1Lo = 0.92, kRail1Hi = 1.02;

constexpr Sphere kBallS{{-1.7, 0.5, 3.9}, 0.5};
constexpr Box kCubeB{{4.4, 0.0, 8.2}, {5.4, 1.0, 9.2}};
constexpr Box kChimneyB{{-13.2, 0.0, 35.4}, {-12.4, 9.3, 36.2}};
constexpr Box kBlockAB{{14.0, 0.0, 76.0}, {32.0, 15.0, 86.0}};
constexpr Box kBlockBB{{36.0, 0.0, 98.0}, {50.0, 24.0, 110.0}};
constexpr Box kHouseBounds{{-19.5, 0.0, 30.4}, {-10.5, 9.4, 38.6}};

// House: walls x in [-19,-11], z in [31,38], eaves at 5.5 m, ridge (along x)
// at 8.3 m over z = 34.5. Roof slopes have normals (0, 3.5, -/+2.8).
constexpr double kHouseX0 = -19.0, kHouseX1 = -11.0, kHouseZ0 = 31.0, kHouseZ1 = 38.0;
constexpr double kEave = 5.5, kRidgeZ = 34.5;

// Fence bounds in path-local coordinates {s, y, r}.
inline Box fence_local_bounds() {
  return {{kFenceStart, 0.0, kFenceRailR0}, {kFenceLength + 0.1, kFenceTop, kFencePostR1}};
}

struct Scene {
  V3 sun;
  V3 path_s, path_r;  // path-local axes (world)
  Poly house_body, roof_front, roof_back;
  std::array<Tree, 2> trees;
  std::vector<Sphere> tree_line;  // sorted by centre x
  double tree_line_rmax;
  Box tree_line_bounds;
  std::array<Ellipsoid, 12> hills;
  std::array<Box, kObjCount> bounds;         // world bounds of each object
  std::array<Box, kObjCount> shadow_bounds;  // points the object may shade
  Box fence_shadow_local;                    // the same for the fence, path-local {s, y, r}
};

Poly make_house_body() {
  const V3 nf{0.0, 3.5, -2.8}, nb{0.0, 3.5, 2.8};
  Poly p{};
  p.n = {V3{-1, 0, 0}, V3{1, 0, 0}, V3{0, 0, -1}, V3{0, 0, 1}, V3{0, -1, 0}, nf, nb};
  p.d = {-kHouseX0,
         kHouseX1,
         -kHouseZ0,
         kHouseZ1,
         0.0,
         dot(nf, V3{0, kEave, kHouseZ0}),
         dot(nb, V3{0, kEave, kHouseZ1})};
  p.count = 7;
  return p;
}

// One roof slope: a 0.22 m thick slab over the body's slope, overhanging by
// 0.45 m at the eave and 0.4 m at the gables.
Poly make_roof(bool front) {
  const V3 n = front ? V3{0.0, 3.5, -2.8} : V3{0.0, 3.5, 2.8};
  const double len = std::sqrt(dot(n, n));
  const double d0 = dot(n, V3{0, kEave, front ? kHouseZ0 : kHouseZ1});
  Poly p{};
  p.n = {n, n * -1.0, V3{-1, 0, 0}, V3{1, 0, 0}, V3{0, 0, -1}, V3{0, 0, 1}, V3{0, 1, 0}};
  p.d = {d0 + 0.22 * len,
         -(d0 - 0.01 * len),
         -(kHouseX0 - 0.4),
         kHouseX1 + 0.4,
         front ? -(kHouseZ0 - 0.45) : -kRidgeZ,
         front ? kRidgeZ : kHouseZ1 + 0.45,
         kInf};
  p.count = 6;
  return p;
}

Tree make_tree(double x, double z, double scale, std::uint32_t seed) {
  Tree t{};
  t.x = x;
  t.z = z;
  t.trunk_r = 0.2 * scale;
  t.trunk_h = 3.4 * scale;
  // Crown: a large central ball and six smaller ones around it {x, y, z, r}.
  const double offs[7][4] = {{0.0, 4.0, 0.0, 1.65},  {1.15, 3.5, -0.3, 1.1}, {-1.1, 3.6, 0.4, 1.15},
                             {0.3, 3.3, -1.0, 1.05}, {-0.4, 3.5, 1.0, 1.1},  {0.5, 5.0, 0.2, 1.05},
                             {-0.6, 4.9, -0.4, 1.0}};
  double lox = x, hix = x, hiy = t.trunk_h, loz = z, hiz = z;
  for (int i = 0; i < 7; ++i) {
    double jx = (unit(hash2(i, 1, seed)) - 0.5) * 0.4, jz = (unit(hash2(i, 2, seed)) - 0.5) * 0.4;
    Sphere s{{x + (offs[i][0] + jx) * scale, offs[i][1] * scale, z + (offs[i][2] + jz) * scale},
             offs[i][3] * scale};
    t.crown[static_cast<std::size_t>(i)] = s;
    lox = std::min(lox, s.c.x - s.r);
    hix = std::max(hix, s.c.x + s.r);
    loz = std::min(loz, s.c.z - s.r);
    hiz = std::max(hiz, s.c.z + s.r);
    hiy = std::max(hiy, s.c.y + s.r);
  }
  lox = std::min(lox, x - t.trunk_r);
  hix = std::max(hix, x + t.trunk_r);
  t.bounds = {{lox, 0.0, loz}, {hix, hiy, hiz}};
  return t;
}

Scene make_scene() {
  Scene s{};
  s.sun = normalize(kSunRaw);
  s.path_s = {kPathSin, 0.0, kPathCos};
  s.path_r = {kPathCos, 0.0, -kPathSin};
  s.house_body = make_house_body();
  s.roof_front = make_roof(true);
  s.roof_back = make_roof(false);
  s.trees = {make_tree(-2.9, 13.0, 0.85, 11U), make_tree(14.0, 24.0, 1.15, 23U)};

  // Tree line: two staggered rows of overlapping round crowns between
  // z = 170 and 215, with a few gaps and an opening for the path.
  double lo_x = kInf, hi_x = -kInf, hi_y = 0.0, lo_z = kInf, hi_z = -kInf;
  s.tree_line_rmax = 0.0;
  for (int row = 0; row < 2; ++row) {
    for (int k = 0; k < 62; ++k) {
      std::uint32_t seed = 7U + 13U * static_cast<std::uint32_t>(row);
      double x = -185.0 + 6.0 * k + 3.0 * row + (unit(hash2(k, 0, seed)) - 0.5) * 4.0;
      double z = 176.0 + 22.0 * row + (unit(hash2(k, 1, seed)) - 0.5) * 10.0;
      double r = 3.8 + unit(hash2(k, 2, seed)) * 3.2;
      double path_x = kPathX0 + z * kPathSin / kPathCos;
      if (std::fabs(x - path_x) < 8.0 + r) continue;  // keep the path open
      double gap = vnoise2(x / 40.0, 3.0 * row, 8U);
      if (gap < 0.3) continue;
      r *= 0.7 + 0.5 * gap;
      Sphere sp{{x, r * 0.8 + 1.0, z}, r};
      s.tree_line.push_back(sp);
      s.tree_line_rmax = std::max(s.tree_line_rmax, r);
      lo_x = std::min(lo_x, x - r);
      hi_x = std::max(hi_x, x + r);
      hi_y = std::max(hi_y, sp.c.y + r);
      lo_z = std::min(lo_z, z - r);
      hi_z = std::max(hi_z, z + r);
    }
  }
  std::sort(s.tree_line.begin(), s.tree_line.end(),
            [](const Sphere& a, const Sphere& b) { return a.c.x < b.c.x; });
  s.tree_line_bounds = {{lo_x, 0.0, lo_z}, {hi_x, hi_y, hi_z}};

  // Object bounds, and the region each object can cast a shadow into: its
  // bounds swept away from the sun down to the ground.
  Box fence{{kInf, kInf, kInf}, {-kInf, -kInf, -kInf}};
  const Box fl = fence_local_bounds();
  for (int c = 0; c < 8; ++c) {
    double ls = (c & 1) ? fl.hi.x : fl.lo.x, ly = (c & 2) ? fl.hi.y : fl.lo.y,
           lr = (c & 4) ? fl.hi.z : fl.lo.z;
    V3 w = V3{kPathX0, ly, 0.0} + s.path_s * ls + s.path_r * lr;
    fence.lo = {std::min(fence.lo.x, w.x), std::min(fence.lo.y, w.y), std::min(fence.lo.z, w.z)};
    fence.hi = {std::max(fence.hi.x, w.x), std::max(fence.hi.y, w.y), std::max(fence.hi.z, w.z)};
  }
  const V3 br{kBallS.r, kBallS.r, kBallS.r};
  s.bounds = {Box{kBallS.c - br, kBallS.c + br},
              kCubeB,
              s.trees[0].bounds,
              s.trees[1].bounds,
              fence,
              kHouseBounds,
              kBlockAB,
              kBlockBB,
              s.tree_line_bounds};
  {
    const V3 sun_local{dot(s.sun, s.path_s), s.sun.y, dot(s.sun, s.path_r)};
    const V3 sweep = sun_local * (-(fl.hi.y + 0.01) / s.sun.y);
    const V3 m{0.01, 0.01, 0.01};
    s.fence_shadow_local = {
        V3{std::min(fl.lo.x, fl.lo.x + sweep.x), -1.0, std::min(fl.lo.z, fl.lo.z + sweep.z)} - m,
        V3{std::max(fl.hi.x, fl.hi.x + sweep.x), fl.hi.y, std::max(fl.hi.z, fl.hi.z + sweep.z)} +
            m};
  }
  for (int i = 0; i < kObjCount; ++i) {
    const Box& b = s.bounds[static_cast<std::size_t>(i)];
    const V3 sweep = s.sun * (-(b.hi.y + 0.01) / s.sun.y);
    const V3 m{0.01, 0.01, 0.01};
    s.shadow_bounds[static_cast<std::size_t>(i)] = {
        V3{std::min(b.lo.x, b.lo.x + sweep.x), -1.0, std::min(b.lo.z, b.lo.z + sweep.z)} - m,
        V3{std::max(b.hi.x, b.hi.x + sweep.x), b.hi.y, std::max(b.hi.z, b.hi.z + sweep.z)} + m};
  }

  // Hills 300-650 m away (tops 75-120 m), mountains 750-1400 m away.
  s.hills = {Ellipsoid{{-430.0, -70.0, 520.0}, {400.0, 165.0, 230.0}, kHill},
             Ellipsoid{{-60.0, -110.0, 600.0}, {260.0, 200.0, 200.0}, kHill},
             Ellipsoid{{260.0, -95.0, 450.0}, {330.0, 170.0, 170.0}, kHill},
             Ellipsoid{{720.0, -60.0, 620.0}, {380.0, 180.0, 250.0}, kHill},
             Ellipsoid{{-900.0, -470.0, 1100.0}, {900.0, 650.0, 350.0}, kMountain},
             Ellipsoid{{-150.0, -480.0, 1250.0}, {700.0, 700.0, 380.0}, kMountain},
             Ellipsoid{{600.0, -440.0, 1050.0}, {650.0, 640.0, 330.0}, kMountain},
             Ellipsoid{{1300.0, -420.0, 1200.0}, {800.0, 600.0, 380.0}, kMountain},
             Ellipsoid{{0.0, -980.0, 1900.0}, {3000.0, 1150.0, 500.0}, kMountain},
             Ellipsoid{{-520.0, -330.0, 1000.0}, {300.0, 580.0, 230.0}, kMountain},
             Ellipsoid{{230.0, -370.0, 1120.0}, {340.0, 630.0, 240.0}, kMountain},
             Ellipsoid{{950.0, -320.0, 1000.0}, {280.0, 530.0, 200.0}, kMountain}};
  for (Ellipsoid& e : s.hills) {
    e.inv_r = {1.0 / e.r.x, 1.0 / e.r.y, 1.0 / e.r.z};
    e.slope = (e.c.y + e.r.y - kCamHeight) / (e.c.z - e.r.z);
  }
  return s;
}

// ------------------------------------------------------------ intersectors --

inline bool hit_sphere(const Ray& r, const Sphere& s, double tmax, double& t) {
  V3 oc = r.o - s.c;
  double b = dot(oc, r.d);
  double c = dot(oc, oc) - s.r * s.r;
  double h = b * b - c;
  if (h < 0.0) return false;
  double t0 = -b - std::sqrt(h);
  if (t0 <= kEps || t0 >= tmax) return false;
  t = t0;
  return true;
}

inline bool hit_ellipsoid(const Ray& r, const Ellipsoid& e, double tmax, double& t) {
  V3 oc = mul(r.o - e.c, e.inv_r), dd = mul(r.d, e.inv_r);
  double a = dot(dd, dd), b = dot(oc, dd), c = dot(oc, oc) - 1.0;
  double h = b * b - a * c;
  if (h < 0.0) return false;
  double t0 = (-b - std::sqrt(h)) / a;
  if (t0 <= kEps || t0 >= tmax) return false;
  t = t0;
  return true;
}

// Slab test; returns the entry distance and the axis (0..2) of the entry face.
inline bool hit_box(const Ray& r, const Box& b, double tmax, double& t, int& axis) {
  double tx0 = (b.lo.x - r.o.x) * r.inv.x, tx1 = (b.hi.x - r.o.x) * r.inv.x;
  double ty0 = (b.lo.y - r.o.y) * r.inv.y, ty1 = (b.hi.y - r.o.y) * r.inv.y;
  double tz0 = (b.lo.z - r.o.z) * r.inv.z, tz1 = (b.hi.z - r.o.z) * r.inv.z;
  double nx = std::min(tx0, tx1), ny = std::min(ty0, ty1), nz = std::min(tz0, tz1);
  double tn = std::max(nx, std::max(ny, nz));
  double tf = std::min(std::max(tx0, tx1), std::min(std::max(ty0, ty1), std::max(tz0, tz1)));
  if (tn > tf || tf <= kEps || tn >= tmax) return false;
  if (tn <= kEps) return false;  // origin inside: not a visible surface
  t = tn;
  axis = tn == nx ? 0 : (tn == ny ? 1 : 2);
  return true;
}
// Box overlap of the ray segment (0, tmax) — used for bounding volumes.
inline bool overlaps_box(const Ray& r, const Box& b, double tmax, double& tn_out, double& tf_out) {
  double tx0 = (b.lo.x - r.o.x) * r.inv.x, tx1 = (b.hi.x - r.o.x) * r.inv.x;
  double ty0 = (b.lo.y - r.o.y) * r.inv.y, ty1 = (b.hi.y - r.o.y) * r.inv.y;
  double tz0 = (b.lo.z - r.o.z) * r.inv.z, tz1 = (b.hi.z - r.o.z) * r.inv.z;
  double tn = std::max(std::min(tx0, tx1), std::max(std::min(ty0, ty1), std::min(tz0, tz1)));
  double tf = std::min(std::max(tx0, tx1), std::min(std::max(ty0, ty1), std::max(tz0, tz1)));
  tn = std::max(tn, 0.0);
  tf = std::min(tf, tmax);
  tn_out = tn;
  tf_out = tf;
  return tn <= tf;
}
inline V3 box_normal(const Ray& r, int axis) {
  if (axis == 0) return {r.d.x > 0 ? -1.0 : 1.0, 0, 0};
  if (axis == 1) return {0, r.d.y > 0 ? -1.0 : 1.0, 0};
  return {0, 0, r.d.z > 0 ? -1.0 : 1.0};
}

inline bool hit_poly(const Ray& r, const Poly& p, double tmax, double& t, int& face) {
  double tn = -kInf, tf = tmax;
  int f = -1;
  for (int i = 0; i < p.count; ++i) {
    const V3& n = p.n[static_cast<std::size_t>(i)];
    double denom = dot(n, r.d);
    double num = p.d[static_cast<std::size_t>(i)] - dot(n, r.o);
    if (std::fabs(denom) < 1e-14) {
      if (num < 0.0) return false;
      continue;
    }
    double tt = num / denom;
    if (denom < 0.0) {
      if (tt > tn) {
        tn = tt;
        f = i;
      }
    } else if (tt < tf) {
      tf = tt;
    }
    if (tn > tf) return false;
  }
  if (f < 0 || tn <= kEps || tn >= tmax) return false;
  t = tn;
  face = f;
  return true;
}

inline bool hit_cylinder_y(const Ray& r, double cx, double cz, double rad, double y1, double tmax,
                           double& t) {
  double ox = r.o.x - cx, oz = r.o.z - cz;
  double a = r.d.x * r.d.x + r.d.z * r.d.z;
  if (a < 1e-14) return false;
  double b = ox * r.d.x + oz * r.d.z;
  double c = ox * ox + oz * oz - rad * rad;
  double h = b * b - a * c;
  if (h < 0.0) return false;
  double t0 = (-b - std::sqrt(h)) / a;
  if (t0 <= kEps || t0 >= tmax) return false;
  double y = r.o.y + t0 * r.d.y;
  if (y < 0.0 || y > y1) return false;
  t = t0;
  return true;
}

// ------------------------------------------------------------ scene query --

// Fence, intersected in path-local coordinates (s, y, r) where it is a set of
// axis-aligned boxes. Local vectors are stored as V3{s, y, r}.
bool hit_fence(const Scene& sc, const Ray& wr, double tmax, Hit& hit) {
  V3 o = wr.o - V3{kPathX0, 0, 0};
  Ray r = make_ray(V3{dot(o, sc.path_s), o.y, dot(o, sc.path_r)},
                   V3{dot(wr.d, sc.path_s), wr.d.y, dot(wr.d, sc.path_r)});
  double tn, tf;
  const Box all = fence_local_bounds();
  if (!overlaps_box(r, all, tmax, tn, tf)) return false;
  if (tf > hit.thin_from) hit.thin = true;
  bool found = false;
  double best = tmax, t;
  int axis, best_axis = 0;
  const Box rails[2] = {
      {{kFenceStart, kRail0Lo, kFenceRailR0}, {kFenceLength, kRail0Hi, kFenceRailR1}},
      {{kFenceStart, kRail1Lo, kFenceRailR0}, {kFenceLength, kRail1Hi, kFenceRailR1}}};
  for (const Box& b : rails) {
    if (hit_box(r, b, best, t, axis)) {
      best = t;
      best_axis = axis;
      found = true;
    }
  }
  double s0 = r.o.x + tn * r.d.x, s1 = r.o.x + tf * r.d.x;
  if (s0 > s1) std::swap(s0, s1);
  int k0 = std::max(1, static_cast<int>(std::floor((s0 - kFencePostHalf) / kFenceSpacing)));
  int k1 = std::min(static_cast<int>(kFenceLength / kFenceSpacing),
                    static_cast<int>(std::ceil((s1 + kFencePostHalf) / kFenceSpacing)));
  for (int k = k0; k <= k1; ++k) {
    double sk = k * kFenceSpacing;
    Box b{{sk - kFencePostHalf, 0.0, kFencePostR0}, {sk + kFencePostHalf, kFenceTop, kFencePostR1}};
    if (hit_box(r, b, best, t, axis)) {
      best = t;
      best_axis = axis;
      found = true;
    }
  }
  if (!found) return false;
  V3 ln = box_normal(r, best_axis);  // {s, y, r}
  hit.t = best;
  hit.mat = kFence;
  hit.id = 0;
  hit.n = sc.path_s * ln.x + V3{0, ln.y, 0} + sc.path_r * ln.z;
  return true;
}

// Closest hit among the objects (everything except the ground, hills and
// mountains) whose bit is set in `mask`. With `any` set it returns at the
// first hit found (shadow rays).
bool hit_objects(const Scene& sc, const Ray& r, double tmax, Hit& hit, bool any,
                 std::uint32_t mask) {
  bool found = false;
  double t, tn, tf;
  int axis;
  auto take = [&](double tt, int mat, V3 n, int id) {
    tmax = tt;
    hit.t = tt;
    hit.mat = mat;
    hit.n = n;
    hit.id = id;
    found = true;
  };
  auto on = [mask](int obj) { return (mask >> obj) & 1U; };
  if (on(kObjBall) && hit_sphere(r, kBallS, tmax, t)) {
    take(t, kBall, (r.o + r.d * t - kBallS.c) * (1.0 / kBallS.r), 0);
    if (any) return true;
  }
  if (on(kObjCube) && hit_box(r, kCubeB, tmax, t, axis)) {
    take(t, kCube, box_normal(r, axis), axis);
    if (any) return true;
  }
  for (int i = 0; i < 2; ++i) {
    const Tree& tr = sc.trees[static_cast<std::size_t>(i)];
    if (!on(kObjTree0 + i) || !overlaps_box(r, tr.bounds, tmax, tn, tf)) continue;
    if (hit_cylinder_y(r, tr.x, tr.z, tr.trunk_r, tr.trunk_h, tmax, t)) {
      V3 p = r.o + r.d * t;
      take(t, kTrunk, normalize(V3{p.x - tr.x, 0.0, p.z - tr.z}), i);
      if (any) return true;
    }
    for (int k = 0; k < static_cast<int>(tr.crown.size()); ++k) {
      const Sphere& s = tr.crown[static_cast<std::size_t>(k)];
      if (hit_sphere(r, s, tmax, t)) {
        take(t, kCrown, (r.o + r.d * t - s.c) * (1.0 / s.r), 8 * i + k);
        if (any) return true;
      }
    }
  }
  if (on(kObjFence) && hit_fence(sc, r, tmax, hit)) {
    tmax = hit.t;
    found = true;
    if (any) return true;
  }
  if (on(kObjHouse) && overlaps_box(r, kHouseBounds, tmax, tn, tf)) {
    int face;
    if (hit_poly(r, sc.house_body, tmax, t, face)) {
      take(t, kHouseWall, normalize(sc.house_body.n[static_cast<std::size_t>(face)]), face);
      if (any) return true;
    }
    if (hit_poly(r, sc.roof_front, tmax, t, face)) {
      take(t, kRoof, normalize(sc.roof_front.n[static_cast<std::size_t>(face)]), face);
      if (any) return true;
    }
    if (hit_poly(r, sc.roof_back, tmax, t, face)) {
      take(t, kRoof, normalize(sc.roof_back.n[static_cast<std::size_t>(face)]), 10 + face);
      if (any) return true;
    }
    if (hit_box(r, kChimneyB, tmax, t, axis)) {
      take(t, kChimney, box_normal(r, axis), axis);
      if (any) return true;
    }
  }
  if (on(kObjBlockA) && hit_box(r, kBlockAB, tmax, t, axis)) {
    take(t, kBlockA, box_normal(r, axis), axis);
    if (any) return true;
  }
  if (on(kObjBlockB) && hit_box(r, kBlockBB, tmax, t, axis)) {
    take(t, kBlockB, box_normal(r, axis), axis);
    if (any) return true;
  }
  if (on(kObjTreeLine) && overlaps_box(r, sc.tree_line_bounds, tmax, tn, tf)) {
    // Only crowns whose x range meets the ray's x range inside the bounds.
    double x0 = r.o.x + tn * r.d.x, x1 = r.o.x + tf * r.d.x;
    if (x0 > x1) std::swap(x0, x1);
    auto first = std::lower_bound(sc.tree_line.begin(), sc.tree_line.end(), x0 - sc.tree_line_rmax,
                                  [](const Sphere& s, double v) { return s.c.x < v; });
    for (auto it = first; it != sc.tree_line.end() && it->c.x <= x1 + sc.tree_line_rmax; ++it) {
      const std::size_t i = static_cast<std::size_t>(it - sc.tree_line.begin());
      const Sphere& s = *it;
      if (hit_sphere(r, s, tmax, t)) {
        take(t, kTreeLine, (r.o + r.d * t - s.c) * (1.0 / s.r), static_cast<int>(i));
        if (any) return true;
      }
    }
  }
  return found;
}

// Primary ray: `mask` selects the objects whose screen bounds contain the sample.
Hit trace(const Scene& sc, const Ray& r, double thin_from, std::uint32_t mask) {
  Hit hit;
  hit.thin_from = thin_from;
  double tmax = kInf;
  if (r.d.y < 0.0) {
    hit.t = -r.o.y / r.d.y;
    hit.mat = kGround;
    hit.n = {0, 1, 0};
    tmax = hit.t;
  }
  hit_objects(sc, r, tmax, hit, false, mask);
  // Hills and mountains lie beyond 190 m and low above the horizon (the
  // slope bounds assume the ray starts at the camera).
  if (hit.t > 190.0 && r.d.y < 0.3) {
    double t;
    for (const Ellipsoid& e : sc.hills) {
      if (r.d.y > e.slope * r.d.z) continue;
      if (hit_ellipsoid(r, e, hit.t, t)) {
        hit.t = t;
        hit.mat = e.mat;
        V3 p = r.o + r.d * t - e.c;
        hit.n = normalize(V3{p.x / (e.r.x * e.r.x), p.y / (e.r.y * e.r.y), p.z / (e.r.z * e.r.z)});
      }
    }
  }
  return hit;
}

inline bool inside(const Box& b, V3 p) {
  return p.x >= b.lo.x && p.x <= b.hi.x && p.y >= b.lo.y && p.y <= b.hi.y && p.z >= b.lo.z &&
         p.z <= b.hi.z;
}

bool in_shadow(const Scene& sc, V3 p, V3 n) {
  std::uint32_t mask = 0;
  for (int i = 0; i < kObjCount; ++i)
    if (inside(sc.shadow_bounds[static_cast<std::size_t>(i)], p)) mask |= 1U << i;
  if (mask & (1U << kObjFence)) {  // the fence's world box is loose: refine along the path
    V3 q = p - V3{kPathX0, 0.0, 0.0};
    if (!inside(sc.fence_shadow_local, V3{dot(q, sc.path_s), q.y, dot(q, sc.path_r)}))
      mask &= ~(1U << kObjFence);
  }
  if (mask == 0) return false;
  Ray r = make_ray(p + n * 2e-4, sc.sun);
  Hit h;
  return hit_objects(sc, r, kInf, h, true, mask);
}

// ---------------------------------------------------------------- shading --

constexpr V3 kSkyHorizon{0.60, 0.72, 0.86};
constexpr V3 kSkyZenith{0.09, 0.22, 0.58};
constexpr V3 kSunColour{1.55, 1.45, 1.28};
constexpr V3 kSkyAmbient{0.30, 0.36, 0.46};
constexpr V3 kGroundAmbient{0.10, 0.11, 0.07};

V3 sky_colour(const V3& d, double pix) {
  double e = std::max(0.0, d.y);
  double k = std::sqrt(std::min(1.0, e * 2.4));
  V3 c = mix(kSkyHorizon, kSkyZenith, k);
  // Soft cumulus on a cloud deck 1.5 km up; filtered by footprint.
  if (d.y > 0.004) {
    double t = 1500.0 / d.y;
    double fx = d.x * t, fz = d.z * t;
    double w = t * pix / d.y / 900.0;  // footprint in noise units
    double n = fbm2(fx / 900.0 + 3.1, fz / 900.0 - 7.7, 5, w, 99U);
    double cover = smoothstep(0.52, 0.72, n) * smoothstep(0.004, 0.06, d.y);
    double shade = 0.80 + 0.25 * smoothstep(0.55, 0.8, n);
    c = mix(c, V3{0.86, 0.87, 0.90} * shade, cover * 0.9);
  }
  return c;
}

// Field patchwork (far ground and hills). Returns albedo.
V3 fields_albedo(double x, double z, double w) {
  constexpr V3 kCrops[6] = {{0.085, 0.17, 0.040}, {0.17, 0.25, 0.060},  {0.36, 0.29, 0.11},
                            {0.20, 0.13, 0.070},  {0.060, 0.12, 0.035}, {0.26, 0.24, 0.08}};
  // Warp the grid so fields are not perfectly aligned.
  double wx = x + 18.0 * (vnoise2(x / 140.0, z / 140.0, 5U) - 0.5);
  double wz = z + 18.0 * (vnoise2(x / 140.0 + 9.0, z / 140.0, 6U) - 0.5);
  double cx = wx / 72.0, cz = wz / 46.0;
  double fr;
  std::int32_t iz = cell(cz, fr);
  double fxr;
  std::int32_t ix = cell(cx + 0.37 * iz, fxr);
  std::uint32_t h = hash2(ix, iz, 77U);
  V3 crop = kCrops[h % 6U];
  double var = 0.85 + 0.3 * unit(mix32(h));
  double tex = fbm2(x / 9.0, z / 9.0, 4, w / 9.0, 12U);
  V3 c = crop * (var * (0.8 + 0.4 * tex));
  if (h % 6U == 3U) {  // ploughed: furrows
    c = c * (0.75 + 0.5 * filtered_pulse(wx / 1.6, 0.5, w / 1.6));
  }
  // Hedgerows along field borders.
  double hedge = std::max(filtered_lines(wz, 46.0, 2.5, w),
                          filtered_lines(wx + 0.37 * iz * 72.0, 72.0, 2.5, w));
  c = mix(c, V3{0.035, 0.07, 0.025}, hedge);
  // Woods.
  double wood = smoothstep(0.6, 0.66, fbm2(x / 180.0, z / 180.0, 3, w / 180.0, 41U));
  c = mix(c, V3{0.035, 0.075, 0.028} * (0.7 + 0.6 * tex), wood);
  return c;
}

// Ground albedo at (x, z) with footprint derivatives (world x/z per
// subsample along the two screen axes).
// `pattern` is set where the paving is small enough on screen that its edges
// are worth supersampling on top of the analytic filtering.
V3 ground_albedo(const Scene& sc, double x, double z, double dxu, double dzu, double dxv,
                 double dzv, bool& pattern) {
  const double s = (x - kPathX0) * sc.path_s.x + z * sc.path_s.z;
  const double r = (x - kPathX0) * sc.path_r.x + z * sc.path_r.z;
  const double ws = std::fabs(dxu * sc.path_s.x + dzu * sc.path_s.z) +
                    std::fabs(dxv * sc.path_s.x + dzv * sc.path_s.z);
  const double wr = std::fabs(dxu * sc.path_r.x + dzu * sc.path_r.z) +
                    std::fabs(dxv * sc.path_r.x + dzv * sc.path_r.z);
  const double wx = std::fabs(dxu) + std::fabs(dxv), wz = std::fabs(dzu) + std::fabs(dzv);
  const double wiso = std::sqrt(wx * wz);  // isotropic footprint for noise
  const double wmax = std::max(wx, wz);

  // Lawn: mown stripes along the path, fine grass noise, dry/dirt patches.
  V3 grass{0.0, 0.0, 0.0};
  double far = z < 70.0 ? 0.0
               : z > 175.0
                   ? 1.0
                   : smoothstep(95.0, 150.0, z + 40.0 * (vnoise2(x / 60.0, z / 60.0, 3U) - 0.5));
  if (far < 1.0) {
    double n = fbm2(x / 2.5, z / 2.5, 3, wiso / 2.5, 1U);
    double dry = smoothstep(0.55, 0.75, vnoise2(x / 7.0, z / 7.0, 2U) * 0.7 + n * 0.3);
    V3 g = mix(V3{0.07, 0.15, 0.030}, V3{0.12, 0.20, 0.045}, n);
    g = mix(g, V3{0.20, 0.17, 0.08}, dry * 0.45);
    double blade = fbm2(x / 0.22, z / 0.22, 5, wiso / 0.22, 9U, 0.75);
    g = g * (0.7 + 0.6 * blade);
    double stripe = filtered_pulse(r / 2.2, 0.5, wr / 2.2);
    g = g * (0.86 + 0.28 * stripe);
    grass = g;
  }
  if (far > 0.0) grass = mix(grass, fields_albedo(x, z, wmax), far);

  double paving = filtered_below(std::fabs(r), kPathHalf, wr);
  double kerb = filtered_below(std::fabs(r), kKerbHalf, wr) - paving;
  if (paving <= 0.0 && kerb <= 0.0) return grass;
  const double ts = 0.5, tr = 2.0 * kPathHalf / 8.0;
  pattern = std::max(ws / ts, wr / tr) > 0.15;

  // Paving: two-tone 0.5 m x 0.425 m slabs in a checker, dark joints.
  const double rs = r + kPathHalf;
  double sgs = 1.0 - 2.0 * filtered_pulse(s / ts, 0.5, ws / ts);
  double sgr = 1.0 - 2.0 * filtered_pulse(rs / tr, 0.5, wr / tr);
  double check = 0.5 - 0.5 * sgs * sgr;
  double ps, pr;
  std::int32_t is = cell(s / ts, ps), ir = cell(rs / tr, pr);
  double tile_fade = clamp01(1.4 - std::max(ws / ts, wr / tr) * 2.0);
  double tile_var = 1.0 + 0.25 * tile_fade * (unit(hash2(is, ir, 4U)) - 0.5);
  double stain = fbm2(s / 0.8, r / 0.8, 3, wiso / 0.8, 8U);
  V3 slab =
      mix(V3{0.40, 0.38, 0.35}, V3{0.13, 0.12, 0.115}, check) * tile_var * (0.8 + 0.4 * stain);
  double joint = std::max(filtered_lines(s, ts, 0.035, ws), filtered_lines(rs, tr, 0.035, wr));
  V3 pave = mix(slab, V3{0.035, 0.033, 0.03}, joint);

  // Kerb stones: light, 0.9 m long.
  double kj = filtered_lines(s, 0.9, 0.03, ws);
  V3 kerb_c = mix(V3{0.50, 0.49, 0.46} * (0.85 + 0.3 * stain), V3{0.06, 0.06, 0.055}, kj);

  return grass * (1.0 - paving - kerb) + pave * paving + kerb_c * kerb;
}

// Windows on a wall. a = horizontal wall coordinate, y = height (metres).
// Returns glass/frame albedo blended over `wall`, or wall.
// `pattern` is set within `margin` metres of a window.
V3 windows(V3 wall, double a, double y, double cell_w, double win_w, double floor_h, double sill,
           double win_h, int floors, std::uint32_t seed, double margin, bool& pattern) {
  if (y < -margin) return wall;
  double fa, fy;
  std::int32_t ia = cell(a / cell_w, fa);
  std::int32_t iy = cell(y / floor_h, fy);
  if (iy >= floors + 1) return wall;
  double la = fa * cell_w - 0.5 * (cell_w - win_w);  // 0..win_w inside the window
  double ly = fy * floor_h - sill;                   // 0..win_h inside
  const double frame = 0.09;
  const double ext = frame + margin;
  if (la < -ext || la > win_w + ext || ly < -ext || ly > win_h + ext) return wall;
  // Near an edge of the frame, the glass or the mullion/transom?
  auto near = [margin](double v, double e) { return std::fabs(v - e) < margin; };
  if (near(la, -frame) || near(la, 0.0) || near(la, win_w) || near(la, win_w + frame) ||
      near(la, 0.5 * win_w - 0.04) || near(la, 0.5 * win_w + 0.04) || near(ly, -frame) ||
      near(ly, 0.0) || near(ly, win_h) || near(ly, win_h + frame) ||
      near(ly, 0.62 * win_h - 0.04) || near(ly, 0.62 * win_h + 0.04))
    pattern = true;
  if (iy >= floors || y < 0.0) return wall;
  if (la < -frame || la > win_w + frame || ly < -frame || ly > win_h + frame) return wall;
  if (la < 0.0 || la > win_w || ly < 0.0 || ly > win_h) return {0.70, 0.70, 0.68};  // frame
  // Mullion and transom.
  if (std::fabs(la - 0.5 * win_w) < 0.04 || std::fabs(ly - 0.62 * win_h) < 0.04)
    return {0.70, 0.70, 0.68};
  std::uint32_t h = hash2(ia, iy, seed);
  double v = unit(h);
  V3 glass{0.030, 0.045, 0.060};
  if (v > 0.75) glass = V3{0.18, 0.14, 0.10};  // curtains
  // A sky reflection gradient on the upper panes.
  glass = glass + V3{0.05, 0.07, 0.10} * clamp01(ly / win_h);
  return glass;
}

struct Surface {
  V3 albedo;
  double ao = 1.0;       // ambient occlusion / self-shadowing factor
  bool pattern = false;  // has sharp, unfiltered texture: supersample it
};

// Ground-contact occlusion from a sphere (centre c, radius r) at point p.
// Faded to exactly zero beyond four radii.
inline double sphere_occlusion(V3 p, V3 n, V3 c, double r) {
  V3 d = c - p;
  double l2 = dot(d, d);
  double k = r * r / l2;
  if (k < 1.0 / 16.0) return 1.0;
  double cos_t = std::max(0.0, dot(n, d) / std::sqrt(l2));
  return 1.0 - cos_t * std::min(1.0, (k - 1.0 / 16.0) * (16.0 / 15.0));
}

Surface shade_surface(const Scene& sc, const Ray& ray, const Hit& h, V3 p, double foot, double dxu,
                      double dzu, double dxv, double dzv) {
  Surface s{{0.5, 0.5, 0.5}, 1.0};
  switch (h.mat) {
    case kGround: {
      s.albedo = ground_albedo(sc, p.x, p.z, dxu, dzu, dxv, dzv, s.pattern);
      if (p.z < 30.0) {
        s.ao = sphere_occlusion(p, h.n, kBallS.c, kBallS.r) *
               sphere_occlusion(p, h.n, V3{4.9, 0.45, 8.7}, 0.62);
        for (const Tree& t : sc.trees)
          s.ao *= sphere_occlusion(p, h.n, V3{t.x, 0.3, t.z}, t.trunk_r * 1.6);
      }
      break;
    }
    case kBall: {
      // Checkered ball, tilted: 8 gores x 4 latitude bands.
      constexpr double c1 = 0.9396926, s1 = 0.3420201;  // 20 deg about z
      constexpr double c2 = 0.9063078, s2 = 0.4226183;  // 25 deg about x
      V3 n = h.n;
      V3 a{c1 * n.x - s1 * n.y, s1 * n.x + c1 * n.y, n.z};
      V3 b{a.x, c2 * a.y - s2 * a.z, s2 * a.y + c2 * a.z};
      int parity = (b.x > 0.0) ^ (b.z > 0.0) ^ (std::fabs(b.x) > std::fabs(b.z));
      int band = (b.y > -0.5) + (b.y > 0.0) + (b.y > 0.5);
      parity ^= band & 1;
      // Supersample near the checker's edges only.
      const double m = 1.5 * foot / kBallS.r;
      s.pattern = std::fabs(b.x) < m || std::fabs(b.z) < m ||
                  std::fabs(std::fabs(b.x) - std::fabs(b.z)) < 1.5 * m ||
                  std::fabs(b.y + 0.5) < m || std::fabs(b.y) < m || std::fabs(b.y - 0.5) < m;
      s.albedo = parity ? V3{0.70, 0.05, 0.035} : V3{0.78, 0.77, 0.74};
      break;
    }
    case kCube: {
      // 4 x 4 black/white checker on every face.
      double u, v;
      if (h.id == 0) {
        u = p.z - kCubeB.lo.z;
        v = p.y;
      } else if (h.id == 1) {
        u = p.x - kCubeB.lo.x;
        v = p.z - kCubeB.lo.z;
      } else {
        u = p.x - kCubeB.lo.x;
        v = p.y;
      }
      double fu, fv;
      std::int32_t iu = cell(u * 4.0, fu), iv = cell(v * 4.0, fv);
      s.albedo = ((iu + iv) & 1) ? V3{0.035, 0.035, 0.035} : V3{0.76, 0.76, 0.74};
      const double m = 1.5 * foot * 4.0;
      s.pattern = fu < m || fu > 1.0 - m || fv < m || fv > 1.0 - m;
      break;
    }
    case kTrunk: {
      double n = fbm2((h.n.x + 2.0 * h.n.z) * 2.0, p.y * 1.5, 4, foot * 1.5, 51U);
      s.albedo = V3{0.13, 0.09, 0.06} * (0.6 + 0.8 * n);
      break;
    }
    case kCrown:
    case kTreeLine: {
      bool near = h.mat == kCrown;
      double freq = near ? 2.6 : 0.55;
      double n = fbm3(p * freq, 5, foot * freq, near ? 61U : 62U);
      double leaf = smoothstep(0.25, 0.75, n);
      V3 base = near ? V3{0.045, 0.12, 0.025} : V3{0.035, 0.085, 0.025};
      V3 tip = near ? V3{0.14, 0.24, 0.05} : V3{0.09, 0.16, 0.04};
      s.albedo = mix(base, tip, leaf);
      // Gaps between leaf clumps are darker (self-shadowing), and the crown
      // underside gets less light.
      s.ao = (0.45 + 0.55 * leaf) * (0.65 + 0.35 * clamp01(0.5 + 0.5 * h.n.y));
      break;
    }
    case kFence: {
      s.albedo = V3{0.72, 0.71, 0.68} * (0.9 + 0.2 * vnoise2(p.x * 3.0, p.y * 3.0 + p.z, 71U));
      break;
    }
    case kHouseWall: {
      const double m = 1.5 * foot;
      V3 wall =
          V3{0.62, 0.50, 0.36} * (0.92 + 0.16 * fbm2(p.x * 0.8 + p.z, p.y * 0.8, 3, foot, 81U));
      if (h.id == 2) {  // front (faces the camera): door between two windows
        double a = p.x - kHouseX0;
        if (std::fabs(a - 4.0) < 0.43 + m && p.y < 2.3 + m) s.pattern = true;
        if (std::fabs(a - 4.0) < 0.43 && p.y < 2.3) {
          bool frame = std::fabs(a - 4.0) > 0.35 || p.y > 2.21;
          s.albedo = frame ? V3{0.70, 0.70, 0.68} : V3{0.17, 0.065, 0.035};
        } else {
          s.albedo = windows(wall, a, p.y, 2.0, 0.9, 2.75, 0.85, 1.35, 2, 91U, m, s.pattern);
        }
      } else if (h.id == 1 || h.id == 0) {  // gable ends
        s.albedo = windows(wall, p.z - kHouseZ0 - 0.5, p.y, 3.0, 1.0, 2.75, 0.85, 1.35, 2, 92U, m,
                           s.pattern);
        if (p.y > kEave - m)
          s.albedo = windows(p.y > kEave ? wall : s.albedo, p.z - kHouseZ0 - 2.5, p.y - 5.9, 2.0,
                             0.8, 3.0, 0.0, 1.0, 1, 93U, m, s.pattern);
      } else {
        s.albedo = wall;
      }
      // Plinth.
      if (p.y < 0.35) s.albedo = V3{0.22, 0.20, 0.18};
      if (std::fabs(p.y - 0.35) < m) s.pattern = true;
      break;
    }
    case kRoof: {
      s.pattern = true;
      // Rows of tiles up the slope, staggered vertical joints.
      double slope_u = h.id < 10 ? (p.z - (kHouseZ0 - 0.45)) : ((kHouseZ1 + 0.45) - p.z);
      double row = slope_u / 0.26;
      double fr;
      std::int32_t ir = cell(row, fr);
      double along = p.x / 0.3 + 0.5 * (ir & 1);
      double fa;
      cell(along, fa);
      double shade = 0.75 + 0.45 * fr;  // each tile row darkens towards its lower edge
      if (fa < 0.08) shade *= 0.55;
      std::uint32_t hh = hash2(static_cast<std::int32_t>(std::floor(along)), ir, 97U);
      s.albedo = V3{0.36, 0.095, 0.055} * shade * (0.85 + 0.3 * unit(hh));
      if ((h.id % 10) != 0) s.albedo = V3{0.30, 0.09, 0.05};  // edges of the slab
      break;
    }
    case kChimney: {
      s.pattern = true;
      double fr, fa;
      std::int32_t ir = cell(p.y / 0.075, fr);
      cell((p.x + p.z) / 0.24 + 0.5 * (ir & 1), fa);
      s.albedo = (fr < 0.15 || fa < 0.06) ? V3{0.45, 0.43, 0.40} : V3{0.30, 0.10, 0.06};
      break;
    }
    case kBlockA: {
      const double m = 1.5 * foot;
      V3 wall = V3{0.58, 0.55, 0.50} * (0.93 + 0.14 * fbm2(p.x + p.z, p.y, 3, foot, 101U));
      double a = h.id == 0 ? p.z - kBlockAB.lo.z : p.x - kBlockAB.lo.x;
      if (h.id == 1) {
        s.albedo = wall;
      } else {
        // Floor slabs as darker bands, windows 1.6 m wide every 3 m.
        double fy;
        cell(p.y / 3.0, fy);
        if (fy > 0.94) wall = wall * 0.7;
        if (std::fabs(fy - 0.94) * 3.0 < m || (1.0 - fy) * 3.0 < m || fy * 3.0 < m)
          s.pattern = true;
        s.albedo = windows(wall, a - 0.2, p.y, 3.0, 1.6, 3.0, 0.9, 1.5, 5, 103U, m, s.pattern);
      }
      break;
    }
    case kBlockB: {
      const double m = 1.5 * foot;
      V3 wall{0.30, 0.34, 0.40};
      double a = h.id == 0 ? p.z - kBlockBB.lo.z : p.x - kBlockBB.lo.x;
      if (h.id == 1) {
        s.albedo = wall;
      } else {
        double fy, fa;
        std::int32_t iy = cell(p.y / 3.0, fy);
        std::int32_t ia = cell(a / 1.5, fa);
        s.pattern = std::fabs(fy - 0.3) * 3.0 < m || std::fabs(fy - 0.85) * 3.0 < m ||
                    (fa < 0.05 + m / 1.5 || fa > 1.0 - m / 1.5);
        if (fy > 0.3 && fy < 0.85 && iy < 8 && fa > 0.05) {  // ribbon windows
          double v = unit(hash2(ia, iy, 107U));
          s.albedo = V3{0.06, 0.08, 0.11} + V3{0.06, 0.08, 0.10} * v;
        } else {
          s.albedo = wall * (fy <= 0.3 || fy >= 0.85 ? 1.0 : 0.5);
        }
      }
      break;
    }
    case kHill: {
      s.albedo = fields_albedo(p.x, p.z, foot);
      break;
    }
    case kMountain: {
      // Forest low down, then alpine meadow, then bare rock near the tops;
      // the boundaries wander with the noise.
      double n = fbm3(p * (1.0 / 60.0), 6, foot / 60.0, 121U);
      double streak = fbm2(p.x / 25.0, p.y / 90.0, 4, foot / 25.0, 123U);
      double e = p.y + 120.0 * (n - 0.5);
      V3 forest = V3{0.040, 0.075, 0.035} * (0.7 + 0.6 * n);
      V3 meadow = V3{0.14, 0.17, 0.07} * (0.75 + 0.5 * n);
      V3 rock = V3{0.20, 0.18, 0.16} * (0.6 + 0.8 * streak);
      s.albedo = mix(forest, meadow, smoothstep(110.0, 160.0, e));
      s.albedo = mix(s.albedo, rock, smoothstep(195.0, 245.0, e + 80.0 * (streak - 0.5)));
      break;
    }
    default:
      break;
  }
  (void)ray;
  return s;
}

struct Shaded {
  V3 colour;
  bool shadowed;  // sunlit side of the surface, but the sun is blocked
  bool pattern;
};

Shaded shade(const Scene& sc, const Ray& ray, const Hit& h, double pix, V3 du, V3 dv) {
  V3 p = ray.o + ray.d * h.t;
  V3 n = h.n;
  if (dot(n, ray.d) > 0.0) n = n * -1.0;
  double foot = h.t * pix / std::max(0.2, std::fabs(dot(n, ray.d)));
  double dxu = 0, dzu = 0, dxv = 0, dzv = 0;
  if (h.mat == kGround) {
    // Ray differentials on the plane y = 0: P = o - d * o.y / d.y, so
    // dP = (dd * d.y - d * dd.y) * (-o.y) / d.y^2 for a direction change dd
    // (du, dv: change per sample step across / down the image).
    double dy = ray.d.y;
    double k = -ray.o.y / (dy * dy);
    dxu = (du.x * dy - ray.d.x * du.y) * k;
    dzu = (du.z * dy - ray.d.z * du.y) * k;
    dxv = (dv.x * dy - ray.d.x * dv.y) * k;
    dzv = (dv.z * dy - ray.d.z * dv.y) * k;
  }
  Surface s = shade_surface(sc, ray, h, p, foot, dxu, dzu, dxv, dzv);
  double ndl = dot(n, sc.sun);
  V3 light = mix(kGroundAmbient, kSkyAmbient, 0.5 + 0.5 * n.y) * s.ao;
  bool shadowed = false;
  if (ndl > 0.0) {
    // Nothing can shade the hills and mountains.
    shadowed = h.mat != kHill && h.mat != kMountain && in_shadow(sc, p, n);
    if (!shadowed) light = light + kSunColour * ndl;
  }
  if (h.mat == kCrown || h.mat == kTreeLine) light = light * (0.6 + 0.4 * s.ao);
  return {mul(s.albedo, light), shadowed, s.pattern};
}

struct Camera {
  V3 origin, fwd, up, right;
  double th;      // tan(fov_y / 2)
  double aspect;  // width / height
  int width, height;
  // Screen-space bounds of each object, in pixels: {x0, y0, x1, y1}.
  std::array<std::array<double, 4>, kObjCount> rects;

  // Image position (pixels) of world point q; false if behind the camera.
  bool project(V3 q, double& px, double& py) const {
    V3 v = q - origin;
    double depth = dot(v, fwd);
    if (depth < 1e-3) return false;
    px = (dot(v, right) / (depth * th * aspect) + 1.0) * 0.5 * width;
    py = (1.0 - dot(v, up) / (depth * th)) * 0.5 * height;
    return true;
  }
  void set_rects(const Scene& sc) {
    for (int i = 0; i < kObjCount; ++i) {
      const Box& b = sc.bounds[static_cast<std::size_t>(i)];
      auto& r = rects[static_cast<std::size_t>(i)];
      r = {kInf, kInf, -kInf, -kInf};
      for (int c = 0; c < 8; ++c) {
        V3 q{(c & 1) ? b.hi.x : b.lo.x, (c & 2) ? b.hi.y : b.lo.y, (c & 4) ? b.hi.z : b.lo.z};
        double px, py;
        if (!project(q, px, py)) {
          r = {-kInf, -kInf, kInf, kInf};  // straddles the camera plane: never culled
          break;
        }
        r = {std::min(r[0], px), std::min(r[1], py), std::max(r[2], px), std::max(r[3], py)};
      }
      // A pixel of margin for rounding and the subsample spread.
      r = {r[0] - 1.0, r[1] - 1.0, r[2] + 1.0, r[3] + 1.0};
    }
  }
  std::uint32_t mask_at(double px, double py) const {
    std::uint32_t m = 0;
    for (int i = 0; i < kObjCount; ++i) {
      const auto& r = rects[static_cast<std::size_t>(i)];
      if (px >= r[0] && px <= r[2] && py >= r[1] && py <= r[3]) m |= 1U << i;
    }
    return m;
  }
};

struct Sample {
  V3 colour;
  float range;   // NaN for sky
  int key;       // surface identity (material and object), -1 for sky
  bool thin;     // the ray passed through a region of sub-pixel structures
  bool pattern;  // the surface has sharp texture detail
};

// One ray through image position (px, py) (pixels, (0,0) = top-left
// corner). `spacing` is the distance to the neighbouring samples in pixels:
// textures are box-filtered over that footprint.
Sample render_sample(const Scene& sc, const Camera& cam, double px, double py, double spacing) {
  const double sx = (2.0 * px / cam.width - 1.0) * cam.th * cam.aspect;
  const double sy = (1.0 - 2.0 * py / cam.height) * cam.th;
  const V3 dir = cam.fwd + cam.right * sx + cam.up * sy;
  const double inv_len = 1.0 / std::sqrt(dot(dir, dir));
  const V3 d = dir * inv_len;
  const Ray ray = make_ray(cam.origin, d);
  const double pix = 2.0 * cam.th / cam.height * spacing;  // sample spacing, radians
  // Rails are 0.1 m tall: thinner than about two pixels beyond this range.
  const Hit h = trace(sc, ray, 0.1 / (2.0 * pix / spacing), cam.mask_at(px, py));
  Sample smp;
  smp.thin = h.thin;
  smp.pattern = false;
  if (h.mat == kNone) {
    smp.colour = sky_colour(d, pix);
    smp.range = std::numeric_limits<float>::quiet_NaN();
    smp.key = -1;
    return smp;
  }
  // Direction change per sample step. Its component along d does not move
  // the hit point on a plane, so the normalisation's derivative is omitted.
  const V3 du = cam.right * (2.0 * cam.th * cam.aspect / cam.width * spacing * inv_len);
  const V3 dv = cam.up * (-2.0 * cam.th / cam.height * spacing * inv_len);
  const Shaded sh = shade(sc, ray, h, pix, du, dv);
  smp.colour = sh.colour;
  smp.pattern = sh.pattern;
  smp.range = static_cast<float>(h.t);
  smp.key = (h.mat * 4096 + h.id) * 2 + (sh.shadowed ? 1 : 0);
  return smp;
}

}  // namespace

DemoScene render_demo_scene(int width, int height) {
  DemoScene out;
  out.fov_y_deg = kFovYDeg;
  if (width <= 0 || height <= 0) return out;
  out.rgb = Image(width, height, 3, 0.0f);
  out.range = Image(width, height, 1, std::numeric_limits<float>::quiet_NaN());

  const Scene sc = make_scene();
  Camera cam;
  cam.origin = {0.0, kCamHeight, 0.0};
  cam.fwd = {0.0, -kSinPitch, kCosPitch};
  cam.up = {0.0, kCosPitch, kSinPitch};
  cam.right = {1.0, 0.0, 0.0};
  cam.th = kTanHalfFovY;
  cam.aspect = static_cast<double>(width) / height;
  cam.width = width;
  cam.height = height;
  cam.set_rects(sc);

  // Pass 1: the pixel-centre ray of every pixel, textures filtered over the
  // whole pixel. This fixes the range image.
  const std::size_t n = out.rgb.pixels();
  std::vector<int> key(n);
  std::vector<unsigned char> flags(n);  // 1: thin structures near, 2: patterned
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Sample s = render_sample(sc, cam, x + 0.5, y + 0.5, 1.0);
      const std::size_t i = static_cast<std::size_t>(y) * width + x;
      float* c = out.rgb.row(y) + 3 * x;
      c[0] = static_cast<float>(s.colour.x);
      c[1] = static_cast<float>(s.colour.y);
      c[2] = static_cast<float>(s.colour.z);
      out.range.data[i] = s.range;
      key[i] = s.key;
      flags[i] = static_cast<unsigned char>((s.thin ? 1 : 0) | (s.pattern ? 2 : 0));
    }
  }

  // Pass 2: 3x3 supersampling wherever the pixel or a neighbour sees another
  // surface or shadow state (object, depth and shadow edges), where the
  // surface has sharp texture (checkers, windows, tiles, distant paving) and
  // where thin fence parts may fall between pixel centres. Smooth textures
  // (noise, stripes, paving up close, fields) are box-filtered analytically
  // and need no extra samples. The centre subsample is the pass-1 sample; the
  // other eight are filtered over a third of a pixel, so that the average
  // covers the same pixel area as a single sample.
  constexpr int kSS = 3;
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * width + x;
      bool need = flags[i] != 0;
      for (int dy = -1; dy <= 1 && !need; ++dy) {
        for (int dx = -1; dx <= 1 && !need; ++dx) {
          int xx = std::clamp(x + dx, 0, width - 1), yy = std::clamp(y + dy, 0, height - 1);
          if (key[static_cast<std::size_t>(yy) * width + xx] != key[i]) need = true;
        }
      }
      float* c = out.rgb.row(y) + 3 * x;
      if (need) {
        V3 acc{c[0], c[1], c[2]};
        for (int j = 0; j < kSS; ++j) {
          for (int k = 0; k < kSS; ++k) {
            if (j == kSS / 2 && k == kSS / 2) continue;
            acc =
                acc +
                render_sample(sc, cam, x + (k + 0.5) / kSS, y + (j + 0.5) / kSS, 1.0 / kSS).colour;
          }
        }
        acc = acc * (1.0 / (kSS * kSS));
        c[0] = static_cast<float>(acc.x);
        c[1] = static_cast<float>(acc.y);
        c[2] = static_cast<float>(acc.z);
      }
      for (int ch = 0; ch < 3; ++ch) c[ch] = static_cast<float>(clamp01(c[ch]));
    }
  }
  return out;
}


DemoScene render_demo_scene_thin_lens(int width, int height, double focus_distance_m, double coc_infinity_px,
                                      int samples) {
  DemoScene out;
  out.fov_y_deg = kFovYDeg;
  if (width <= 0 || height <= 0 || samples <= 0) return out;
  out.rgb = Image(width, height, 3, 0.0f);
  const Scene sc = make_scene();
  Camera cam;
  cam.origin = {0.0, kCamHeight, 0.0};
  cam.fwd = {0.0, -kSinPitch, kCosPitch};
  cam.up = {0.0, kCosPitch, kSinPitch};
  cam.right = {1.0, 0.0, 0.0};
  cam.th = kTanHalfFovY;
  cam.aspect = static_cast<double>(width) / height;
  cam.width = width;
  cam.height = height;
  // A lens ray leaves the pinhole's screen-space bounds: every object is a candidate.
  const std::uint32_t all = 0xFFFFFFFFu;
  // Focal length in pixels, and the aperture diameter (m) whose image of a
  // point at infinity is coc_infinity_px wide: a point at planar depth Z
  // images to a disc of A f |Z - Zf| / (Z Zf) px, which tends to A f / Zf.
  const double f_px = 0.5 * height / cam.th;
  const double aperture = coc_infinity_px * focus_distance_m / f_px;
  const double pix = 2.0 * cam.th / cam.height;  // one pixel, radians
  const double golden = 0.6180339887498949, plastic1 = 0.7548776662466927, plastic2 = 0.5698402909980532;
#pragma omp parallel for schedule(dynamic, 2)
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      V3 acc{0.0, 0.0, 0.0};
      const double jitter = unit(hash2(x, y, 91u));
      for (int s = 0; s < samples; ++s) {
        // Pixel position: a rank-1 lattice (Fibonacci-like); lens point: the
        // R2 sequence, Cartesian-scrambled per pixel, mapped to the disc by
        // equal-area polar mapping.
        const double u = (s + 0.5) / samples, v = std::fmod(s * golden + jitter, 1.0);
        const double a = std::fmod(s * plastic1 + jitter, 1.0), b = std::fmod(s * plastic2 + 0.5 * jitter, 1.0);
        const double px = x + u, py = y + v;
        const double sx = (2.0 * px / cam.width - 1.0) * cam.th * cam.aspect;
        const double sy = (1.0 - 2.0 * py / cam.height) * cam.th;
        const V3 dir = cam.fwd + cam.right * sx + cam.up * sy;  // forward component 1: planar depth
        const V3 focus = cam.origin + dir * focus_distance_m;
        const double r = 0.5 * aperture * std::sqrt(a), phi = 2.0 * 3.141592653589793 * b;
        const V3 o = cam.origin + cam.right * (r * std::cos(phi)) + cam.up * (r * std::sin(phi));
        const V3 d = normalize(focus - o);
        const Ray ray = make_ray(o, d);
        const Hit h = trace(sc, ray, 0.1 / (2.0 * pix), all);
        if (h.mat == kNone) {
          acc = acc + sky_colour(d, pix);
          continue;
        }
        const double inv_len = 1.0 / std::sqrt(dot(dir, dir));
        const V3 du = cam.right * (2.0 * cam.th * cam.aspect / cam.width * inv_len);
        const V3 dv = cam.up * (-2.0 * cam.th / cam.height * inv_len);
        acc = acc + shade(sc, ray, h, pix, du, dv).colour;
      }
      acc = acc * (1.0 / samples);
      float* c = out.rgb.row(y) + 3 * x;
      c[0] = static_cast<float>(clamp01(acc.x));
      c[1] = static_cast<float>(clamp01(acc.y));
      c[2] = static_cast<float>(clamp01(acc.z));
    }
  }
  return out;
}

}  // namespace brume
