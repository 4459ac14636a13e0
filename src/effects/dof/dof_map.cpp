// brume — depth of field's scale map (include/brume/dof.hpp): the CoC
// pass, the cap and the foreground rule (§3.4), as scalar loops (the
// reference) and on the vector rows of dof_map_kernels.cpp (the default,
// the same bits: dof_map.hpp).
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "core/schedule.hpp"
#include "core/text.hpp"
#include "effects/dof/dof_map.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;
namespace {
using namespace detail;

// Half-sample mirror (the diffusion engine's boundary): -1 -> 0, n -> n-1.
int mirror(int i, int n) {
  while (i < 0 || i >= n) i = i < 0 ? -1 - i : 2 * n - 1 - i;
  return i;
}

// Eight floats (GCC's vector extension; two SSE registers on the baseline).
typedef float BlurLanes __attribute__((vector_size(32)));

// A sampled Gaussian of standard deviation s px: radius ceil(4 s), weights
// normalised (truncation < 7e-5 of the mass).
std::vector<float> gaussian_weights(double s) {
  const int r = static_cast<int>(std::ceil(4.0 * s));
  std::vector<float> k(2 * r + 1);
  double sum = 0.0;
  for (int i = -r; i <= r; ++i) sum += std::exp(-0.5 * i * i / (s * s));
  for (int i = -r; i <= r; ++i) k[i + r] = static_cast<float>(std::exp(-0.5 * i * i / (s * s)) / sum);
  return k;
}

// In place: the sampled Gaussian, separable, mirrored borders; rows, then
// columns, in parallel.
void gaussian_blur(Image& img, double s, int nt) {
  const std::vector<float> k = gaussian_weights(s);
  const int W = img.width, H = img.height, r = static_cast<int>(k.size() / 2);
  Image tmp(W, H, 1);
#pragma omp parallel num_threads(nt)
  {
    std::vector<float> row(static_cast<std::size_t>(W + 2 * r));
    std::vector<const float*> taps(static_cast<std::size_t>(2 * r + 1));  // the column pass's rows
#pragma omp for schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y) {
      std::memcpy(row.data() + r, &img.at(0, y), static_cast<std::size_t>(W) * sizeof(float));
      for (int x = -r; x < 0; ++x) row[x + r] = img.at(mirror(x, W), y);
      for (int x = W; x < W + r; ++x) row[x + r] = img.at(mirror(x, W), y);
      float* o = &tmp.at(0, y);
      // Eight columns at a time, each lane the scalar loop's sum in its
      // order (GCC's vector extension: the same multiplies and adds, lane by
      // lane), then the rest one at a time.
      int x = 0;
      for (; x + 8 <= W; x += 8) {
        BlurLanes acc = {};
        for (int i = 0; i <= 2 * r; ++i) {
          BlurLanes v;
          std::memcpy(&v, &row[static_cast<std::size_t>(x + i)], sizeof v);
          acc += k[i] * v;
        }
        std::memcpy(o + x, &acc, sizeof acc);
      }
      for (; x < W; ++x) {
        float acc = 0.0f;
        for (int i = 0; i <= 2 * r; ++i) acc += k[i] * row[x + i];
        o[x] = acc;
      }
    }
#pragma omp for schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y) {
      float* o = &img.at(0, y);
      for (int i = -r; i <= r; ++i) taps[static_cast<std::size_t>(i + r)] = &tmp.at(0, mirror(y + i, H));
      // o = 0, then o += w_i src_i for i = -r .. r: eight columns at a time
      // kept in a register through the taps (the same operations in the
      // same order, lane by lane), then the rest.
      int x = 0;
      for (; x + 8 <= W; x += 8) {
        BlurLanes acc = {};
        for (int i = 0; i <= 2 * r; ++i) {
          BlurLanes v;
          std::memcpy(&v, taps[static_cast<std::size_t>(i)] + x, sizeof v);
          acc += k[i] * v;
        }
        std::memcpy(o + x, &acc, sizeof acc);
      }
      for (; x < W; ++x) {
        float acc = 0.0f;
        for (int i = 0; i <= 2 * r; ++i) acc += k[i] * taps[static_cast<std::size_t>(i)][x];
        o[x] = acc;
      }
    }
  }
}

// Bilinear reads of a coarse map at the pixel centres, clamped at the
// borders: the taps and weights of each column (and row) computed once.
struct Axis {
  std::vector<int> i0, i1;
  std::vector<float> a;
};
Axis axis(int n, int k, int coarse) {
  Axis t{std::vector<int>(n), std::vector<int>(n), std::vector<float>(n)};
  for (int x = 0; x < n; ++x) {
    const float f = std::clamp((x + 0.5f) / k - 0.5f, 0.0f, static_cast<float>(coarse - 1));
    t.i0[x] = static_cast<int>(f);
    t.i1[x] = std::min(t.i0[x] + 1, coarse - 1);
    t.a[x] = f - t.i0[x];
  }
  return t;
}
// A coarse row rc read along x at the W pixel centres.
void horiz_row(const float* rc, const Axis& ax, float* o, int W) {
  const int *x0 = ax.i0.data(), *x1 = ax.i1.data();
  const float* a = ax.a.data();
  for (int x = 0; x < W; ++x) o[x] = rc[x0[x]] + a[x] * (rc[x1[x]] - rc[x0[x]]);
}

// The coarse pixel (x, y) of band j at 1/k resolution: the mean of the k x
// k block's values (sigma at the band's members, s0 elsewhere; clipped at
// the borders), summed in double row by row; members counts the block's.
float block_average(const signed char* band, const Image& sigma, int k, int x, int y, int j, float s0, int& members) {
  const int W = sigma.width, H = sigma.height;
  double acc = 0.0;
  int n = 0;
  for (int yy = y * k; yy < std::min(H, (y + 1) * k); ++yy)
    for (int xx = x * k; xx < std::min(W, (x + 1) * k); ++xx) {
      const std::size_t i = static_cast<std::size_t>(yy) * W + xx;
      const bool in = band[i] == j;
      acc += in ? sigma.data[i] : s0;
      members += in;
      ++n;
    }
  return static_cast<float>(acc / n);
}

// §3.4's foreground rule (stated in dof.hpp): the near field's scale map is
// split into octave bands of sigma, [2^j, 2^{j+1}) px, band j (sigma0
// elsewhere) is blurred by a Gaussian of 2^j px, and every pixel takes the
// largest of its own sigma and the blurred bands, capped at the limit. Each
// near pixel so spreads by about its own scale, as its blur disc (radius c/2
// = 2 sigma) overlaps its neighbours. (One blur by the largest near sigma let
// a strongly blurred near ground raise an in-focus house 60 px above it,
// measured against the thin-lens render.)
//
// A blurred band is smooth, so it is formed at 1/k resolution, k =
// floor(2^j / 2) (>= 1): box-averaged down, blurred by s_c = sqrt((2^j/k)^2
// - 1/4) coarse px (a box-averaged coarse pixel is taken as sigma 0.5: the
// variance 2^{2j}/k^2 in all), read back bilinearly; it shapes a soft rim,
// not an image. The blur is a separable sampled Gaussian (s_c <= 1.94 coarse
// px: 17 taps), where it was the diffusion engine's invariant-exact scheme at
// that constant scale (a Gaussian to ~1e-3, tests/test_diffusion.cpp): the
// same map to within the engine's own accuracy (tests/test_dof.cpp bounds the
// difference against the definition), at a fraction of the cost (the engine
// ran a full-resolution 4-channel iteration per step for the bands j <= 1;
// 249 of the default's 455 ms at 1024 x 768, sigma up to 20 px).
void near_field_raise(const Image& z, float zf, float s0, float limit, Image& sigma, int nt) {
  const int W = z.width, H = z.height;
  const long np = static_cast<long>(z.pixels());
  std::vector<signed char> band(z.pixels(), -1);
  int top_band = -1;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk) reduction(max : top_band)
  for (long i = 0; i < np; ++i) {
    const float zi = z.data[static_cast<std::size_t>(i)], si = sigma.data[static_cast<std::size_t>(i)];
    if (std::isfinite(zi) && zi < zf && si > s0) {
      const int j = std::max(0, static_cast<int>(std::floor(std::log2(si))));
      band[static_cast<std::size_t>(i)] = static_cast<signed char>(j);
      top_band = std::max(top_band, j);
    }
  }
  // A blurred band, its axes, and (k > 1) its rows read bilinearly along x
  // at every pixel centre: horiz(x, cy) = the coarse row cy at column x,
  // formed once per coarse row rather than twice per pixel row.
  struct Coarse {
    Image map;
    Axis ax, ay;
    Image horiz;
  };
  std::vector<Coarse> bands;
  for (int j = 0; j <= top_band; ++j) {
    const float s_band = std::ldexp(1.0f, j);  // the band's lower edge: every member's sigma is >= it
    const int k = std::max(1, static_cast<int>(s_band / 2.0f));
    const int w = (W + k - 1) / k, h = (H + k - 1) / k;
    Image small(w, h, 1);
    int members = 0;
    if (k == 1) {
      // Each coarse pixel is one pixel: the average below is (0.0 + v) / 1,
      // v itself, so the band's values are taken as they are (a pass the
      // compiler vectorises instead of the blocks' nested loops).
      const std::size_t n = z.pixels();
      const signed char* b = band.data();
      const float* sg = sigma.data.data();
      float* out = small.data.data();
      for (std::size_t i = 0; i < n; ++i) {
        const bool in = b[i] == j;
        out[i] = in ? sg[i] : s0;
        members += in;
      }
    } else {
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk) reduction(+ : members)
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) small.at(x, y) = block_average(band.data(), sigma, k, x, y, j, s0, members);
    }
    if (members == 0) continue;
    const double s_small = std::max(1.0, static_cast<double>(s_band) / k);
    gaussian_blur(small, std::sqrt(s_small * s_small - 0.25), nt);
    Coarse c{std::move(small), axis(W, k, w), axis(H, k, h), Image()};
    if (k > 1) {
      c.horiz = Image(W, h, 1);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
      for (int cy = 0; cy < h; ++cy) {
        horiz_row(c.map.data.data() + static_cast<std::size_t>(cy) * w, c.ax, &c.horiz.at(0, cy), W);
      }
    }
    bands.push_back(std::move(c));
  }
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y) {
    float* v = &sigma.at(0, y);
    for (const Coarse& c : bands) {
      if (c.map.width == W && c.map.height == H) {
        // A full-resolution band (k = 1): every pixel's bilinear weights are
        // 0 (its centre is a coarse pixel's), so the read is the band's own
        // value, t + 0 (b - t) with t = r0[x] + 0 (r0[x + 1] - r0[x]), and
        // the values are positive and finite: r0[x] itself.
        const float* r = c.map.data.data() + static_cast<std::size_t>(y) * W;
        for (int x = 0; x < W; ++x) v[x] = std::max(v[x], r[x]);
        continue;
      }
      // t and b: the coarse rows above and below, read at x (horiz).
      const float* t = c.horiz.row(c.ay.i0[y]);
      const float* b = c.horiz.row(c.ay.i1[y]);
      const float ay = c.ay.a[y];
      for (int x = 0; x < W; ++x) v[x] = std::max(v[x], t[x] + ay * (b[x] - t[x]));
    }
    for (int x = 0; x < W; ++x) v[x] = std::min(limit, v[x]);
  }
}

// The scalar loops: the CoC pass and the foreground rule (the vector rows'
// reference).
void scalar_map(const Image& z, float alpha, float zf, float s0, float limit, Foreground foreground, DofAnalysis& a,
                Image& sigma, int nt) {
  const long np = static_cast<long>(z.pixels());
  long unknown = 0, near = 0, capped = 0;
  double zmin = INFINITY, zmax = 0.0;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk) reduction(+ : unknown, near, capped) \
    reduction(min : zmin) reduction(max : zmax)
  for (long i = 0; i < np; ++i) {
    const float zi = z.data[static_cast<std::size_t>(i)];
    const bool known = std::isfinite(zi) && zi > 0.0f;
    // Unknown depth is infinitely far (sky): c = alpha.
    const float c = known ? sh::brume_coc(alpha, zi, zf) : alpha;
    if (!known) {
      ++unknown;
    } else {
      zmin = std::min(zmin, static_cast<double>(zi));
      zmax = std::max(zmax, static_cast<double>(zi));
      if (zi < zf) ++near;
    }
    if (sh::brume_dof_scale(c, s0, INFINITY) > limit) ++capped;
    sigma.data[static_cast<std::size_t>(i)] = sh::brume_dof_scale(c, s0, limit);
  }
  a.unknown_pixels = static_cast<std::size_t>(unknown);
  a.near_pixels = static_cast<std::size_t>(near);
  a.capped_pixels = static_cast<std::size_t>(capped);
  a.z_min_m = std::isfinite(zmin) ? zmin : 0.0;
  a.z_max_m = zmax;

  if (foreground == Foreground::soft && a.near_pixels > 0) near_field_raise(z, zf, s0, limit, sigma, nt);
}

// ---- The vector rows' schedule (dof_map.hpp, dof_map_kernels.cpp) ----
//
// The same map as the scalar loops above, bit for bit, with less work:
//  - one pass per row forms sigma, the counts and each pixel's band, and
//    notes where the row's bands lie (columns [lo, hi), bands jmin..jmax);
//  - a band image is s0 but at its members, and the Gaussian of a run of s0
//    is one value (c1 along rows, c2 down columns: the same sums of the same
//    products in the same order): the blur computes only the rows and
//    columns within its radius of a member, the rest is that constant;
//  - the blur, the band's values and the maxima are the kernels' vector
//    rows (16 lanes on AVX-512 where the reference's blur runs 4).
// A member-free block of a coarse band averages to s0 exactly (the partial
// sums m s0 of a float's 24 significant bits are exact in double while m <=
// 2^29, and n s0 / n = s0), so a coarse band is averaged in the blocks of its
// members' spans only (every block where k^2 > 2^29, sigma >= 2^16 px).

// A band image's blurred rows: row y holds values other than the constant c
// only in [lo[y], hi[y]) (none where lo[y] >= hi[y]), in buf's row y.
struct SparseRows {
  int w = 0, h = 0;
  float c = 0.0f;
  std::vector<int> lo, hi;
  std::unique_ptr<float[]> buf;  // w x h, written only in rows that hold values
  bool holds(int y) const { return lo[static_cast<std::size_t>(y)] < hi[static_cast<std::size_t>(y)]; }
  float* row(int y) { return buf.get() + static_cast<std::size_t>(y) * w; }
  const float* row(int y) const { return buf.get() + static_cast<std::size_t>(y) * w; }
};

SparseRows sparse_rows(int w, int h, float c) {
  SparseRows s;
  s.w = w, s.h = h, s.c = c;
  s.lo.assign(static_cast<std::size_t>(h), 0);
  s.hi.assign(static_cast<std::size_t>(h), 0);
  s.buf.reset(new float[static_cast<std::size_t>(w) * h]);  // uninitialised: only rows that hold values are touched
  return s;
}

// gaussian_blur of a w x h band image whose row y is s0 outside [in_lo[y],
// in_hi[y]) (all s0 where in_lo[y] >= in_hi[y]); fill(y, row) writes a
// holding row's w values and returns its members. members: their sum; 0:
// nothing is blurred (the reference drops such a band).
template <class Fill>
SparseRows sparse_blur(int w, int h, float s0, const std::vector<float>& k, const std::vector<int>& in_lo,
                       const std::vector<int>& in_hi, Fill fill, long& members, int nt) {
  const int taps = static_cast<int>(k.size()), r = taps / 2;
  // The constants, by the kernels themselves (a row of s0, then columns of c1).
  const std::vector<float> s0s(static_cast<std::size_t>(taps), s0);
  float c1 = 0.0f, c2 = 0.0f;
  dof_blur_row(s0s.data(), k.data(), taps, &c1, 0, 1);
  const std::vector<float> c1row(static_cast<std::size_t>(std::max(w, taps)), c1);
  const std::vector<const float*> c1cols(static_cast<std::size_t>(taps), c1row.data());
  dof_blur_cols(c1cols.data(), k.data(), taps, &c2, 0, 1);
  // Rows: a holding row's sums within r of its span, c1 beyond (every tap
  // there reads s0, mirrored taps included: the span lies farther than r).
  SparseRows tmp = sparse_rows(w, h, c1);
  long m = 0;
#pragma omp parallel num_threads(nt) reduction(+ : m)
  {
    std::vector<float> pad(static_cast<std::size_t>(w + 2 * r));
#pragma omp for schedule(dynamic, kRowChunk)
    for (int y = 0; y < h; ++y) {
      const std::size_t yi = static_cast<std::size_t>(y);
      if (in_lo[yi] >= in_hi[yi]) continue;
      m += fill(y, pad.data() + r);
      for (int x = -r; x < 0; ++x) pad[static_cast<std::size_t>(x + r)] = pad[static_cast<std::size_t>(mirror(x, w) + r)];
      for (int x = w; x < w + r; ++x) pad[static_cast<std::size_t>(x + r)] = pad[static_cast<std::size_t>(mirror(x, w) + r)];
      const int a = std::max(0, in_lo[yi] - r), b = std::min(w, in_hi[yi] + r);
      float* o = tmp.row(y);
      std::fill(o, o + a, c1);
      dof_blur_row(pad.data(), k.data(), taps, o, a, b);
      std::fill(o + b, o + w, c1);
      tmp.lo[yi] = a;
      tmp.hi[yi] = b;
    }
  }
  members = m;
  if (m == 0) return {};
  // Columns: a row's sums over the union of the spans of the holding rows
  // its taps read (a row that holds none reads c1 there), c2 beyond.
  SparseRows out = sparse_rows(w, h, c2);
#pragma omp parallel num_threads(nt)
  {
    std::vector<const float*> rows(static_cast<std::size_t>(taps));
#pragma omp for schedule(dynamic, kRowChunk)
    for (int y = 0; y < h; ++y) {
      int a = w, b = 0;
      for (int i = 0; i < taps; ++i) {
        const int q = mirror(y + i - r, h);
        const bool holds = tmp.holds(q);
        rows[static_cast<std::size_t>(i)] = holds ? tmp.row(q) : c1row.data();
        if (holds) a = std::min(a, tmp.lo[static_cast<std::size_t>(q)]), b = std::max(b, tmp.hi[static_cast<std::size_t>(q)]);
      }
      if (a >= b) continue;
      dof_blur_cols(rows.data(), k.data(), taps, out.row(y), a, b);
      out.lo[static_cast<std::size_t>(y)] = a;
      out.hi[static_cast<std::size_t>(y)] = b;
    }
  }
  return out;
}

// The rows' notes from the CoC pass (DofCocStats): does row y hold members
// that may be of band j, and where.
bool may_hold(const DofCocStats& s, int j) { return s.lo < s.hi && s.jmin <= j && j <= s.jmax; }

// near_field_raise on the vector rows: band[] and rows[] from the CoC pass.
void near_field_raise_rows(float s0, float limit, Image& sigma, const signed char* band,
                           const std::vector<DofCocStats>& rows, int top_band, int nt) {
  const int W = sigma.width, H = sigma.height;
  struct Blurred {
    SparseRows map;
    bool full = false;       // the reference's full-resolution read (the map is W x H)
    Axis ay;                 // (coarse) the bilinear read down
    std::unique_ptr<float[]> horiz;  // (coarse) holding coarse rows read along x at every pixel centre
    std::vector<float> cx;           // W values c: a row that holds none (coarse: read along x)
    const float* hrow(int cy) const {
      return map.holds(cy) ? horiz.get() + static_cast<std::size_t>(cy) * cx.size() : cx.data();
    }
  };
  std::vector<Blurred> bands;
  for (int j = 0; j <= top_band; ++j) {
    const float s_band = std::ldexp(1.0f, j);
    const int k = std::max(1, static_cast<int>(s_band / 2.0f));
    const int w = (W + k - 1) / k, h = (H + k - 1) / k;
    const double s_small = std::max(1.0, static_cast<double>(s_band) / k);
    const std::vector<float> wk = gaussian_weights(std::sqrt(s_small * s_small - 0.25));
    // Where the band image may differ from s0: each coarse row's span of its pixel rows' members.
    std::vector<int> lo(static_cast<std::size_t>(h), 0), hi(static_cast<std::size_t>(h), 0);
    for (int cy = 0; cy < h; ++cy) {
      int a = w, b = 0;
      for (int yy = cy * k; yy < std::min(H, (cy + 1) * k); ++yy) {
        const DofCocStats& s = rows[static_cast<std::size_t>(yy)];
        if (may_hold(s, j)) a = std::min(a, s.lo / k), b = std::max(b, (s.hi - 1) / k + 1);
      }
      if (a < b) lo[static_cast<std::size_t>(cy)] = a, hi[static_cast<std::size_t>(cy)] = b;
      if (static_cast<double>(k) * k > 0x1p29) lo[static_cast<std::size_t>(cy)] = 0, hi[static_cast<std::size_t>(cy)] = w;
    }
    long members = 0;
    Blurred c;
    if (k == 1) {
      c.map = sparse_blur(w, h, s0, wk, lo, hi, [&](int y, float* o) {
        const std::size_t at = static_cast<std::size_t>(y) * W;
        return dof_band_values(band + at, sigma.data.data() + at, j, s0, o, W);
      }, members, nt);
    } else {
      // The reference's block average (double sums in its order) within the span, s0 beyond.
      c.map = sparse_blur(w, h, s0, wk, lo, hi, [&](int y, float* o) {
        std::fill(o, o + w, s0);
        int m = 0;
        for (int x = lo[static_cast<std::size_t>(y)]; x < hi[static_cast<std::size_t>(y)]; ++x)
          o[x] = block_average(band, sigma, k, x, y, j, s0, m);
        return m;
      }, members, nt);
    }
    if (members == 0) continue;
    c.full = w == W && h == H;
    c.cx.assign(static_cast<std::size_t>(W), c.map.c);  // (coarse: c + a (c - c) = c)
    if (!c.full) {
      const Axis ax = axis(W, k, w);
      c.ay = axis(H, k, h);
      c.horiz.reset(new float[static_cast<std::size_t>(W) * h]);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
      for (int cy = 0; cy < h; ++cy) {
        if (!c.map.holds(cy)) continue;
        float* rc = c.map.row(cy);
        std::fill(rc, rc + c.map.lo[static_cast<std::size_t>(cy)], c.map.c);
        std::fill(rc + c.map.hi[static_cast<std::size_t>(cy)], rc + w, c.map.c);
        horiz_row(rc, ax, c.horiz.get() + static_cast<std::size_t>(cy) * W, W);
      }
    }
    bands.push_back(std::move(c));
  }
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y) {
    float* v = sigma.row(y);
    for (const Blurred& c : bands) {
      if (c.full) {
        const SparseRows& m = c.map;
        if (!m.holds(y)) {
          dof_max_row(v, c.cx.data(), W);
          continue;
        }
        const int a = m.lo[static_cast<std::size_t>(y)], b = m.hi[static_cast<std::size_t>(y)];
        dof_max_row(v, c.cx.data(), a);
        dof_max_row(v + a, m.row(y) + a, b - a);
        dof_max_row(v + b, c.cx.data(), W - b);
        continue;
      }
      const std::size_t yi = static_cast<std::size_t>(y);
      dof_max_lerp(v, c.hrow(c.ay.i0[yi]), c.hrow(c.ay.i1[yi]), c.ay.a[yi], W);
    }
    dof_cap_row(v, limit, W);
  }
}

}  // namespace


Image detail::dof_scale_map_rows(const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec, bool vector,
                                 std::size_t parallel_pixels) {
  validate_dof(p);
  if (z.channels != 1) throw Error("the depth map must have one channel");
  const int W = z.width, H = z.height;
  a.alpha_px = coc_infinity_px(p, W, H);
  const float alpha = static_cast<float>(a.alpha_px), zf = static_cast<float>(*p.focus_distance_m);
  const float s0 = static_cast<float>(p.diffusion.sigma0), limit = static_cast<float>(p.coc_limit_px);
  Image sigma(W, H, 1);
  // The map's ~17 parallel regions are light (1-3 ms each at 1024x768), and
  // each ends when every thread has arrived: on a loaded host the second
  // thread's wait for a core cost more than it shares (1024x768, AMD EPYC
  // family 26, 2 vCPU, load average 6.5, 2026-12-06: 39-44 ms on one
  // thread, 155-264 ms on two; on a quiet host two threads took 21.6 ms,
  // 2026-12-01). brume_bench_dof ROUNDS map.
  // One thread below parallel_pixels (4 Mpx: dof_map.hpp), whatever the call's count.
  const int nt = z.pixels() < parallel_pixels ? 1 : exec.threads > 0 ? exec.threads : omp_get_max_threads();
  if (vector) {
    std::vector<DofCocStats> rows(static_cast<std::size_t>(H));
    std::unique_ptr<signed char[]> band(new signed char[z.pixels()]);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y) {
      DofCocRow r;
      r.z = z.row(y);
      r.sigma = sigma.row(y);
      r.band = band.get() + static_cast<std::size_t>(y) * W;
      r.width = W;
      r.alpha = alpha, r.zf = zf, r.s0 = s0, r.limit = limit;
      dof_coc_row(r, rows[static_cast<std::size_t>(y)]);
    }
    a.unknown_pixels = a.near_pixels = a.capped_pixels = 0;
    float zmin = INFINITY, zmax = 0.0f;
    int top_band = -1;
    for (const DofCocStats& s : rows) {
      a.unknown_pixels += static_cast<std::size_t>(s.unknown);
      a.near_pixels += static_cast<std::size_t>(s.near);
      a.capped_pixels += static_cast<std::size_t>(s.capped);
      zmin = std::min(zmin, s.zmin);
      zmax = std::max(zmax, s.zmax);
      top_band = std::max(top_band, s.jmax);
    }
    a.z_min_m = std::isfinite(zmin) ? zmin : 0.0;
    a.z_max_m = zmax;
    if (p.foreground == Foreground::soft && a.near_pixels > 0)
      near_field_raise_rows(s0, limit, sigma, band.get(), rows, top_band, nt);
  } else {
    scalar_map(z, alpha, zf, s0, limit, p.foreground, a, sigma, nt);
  }
  // The largest scale: every value is finite and at least s0 (no NaN), so
  // the order of the comparisons cannot change it: sixteen running maxima,
  // a loop that vectorises (one loop-carried max took ~1 ms at 1024 x 768).
  float m16[16];
  std::fill(m16, m16 + 16, s0);
  const std::size_t nv = sigma.data.size();
  const float* sv = sigma.data.data();
  std::size_t i16 = 0;
  for (; i16 + 16 <= nv; i16 += 16)
    for (int j = 0; j < 16; ++j) m16[j] = std::max(m16[j], sv[i16 + j]);
  float smax = s0;
  for (; i16 < nv; ++i16) smax = std::max(smax, sv[i16]);
  for (const float m : m16) smax = std::max(smax, m);
  a.sigma_max = smax;
  // Bounded where it is decided (brume/diffusion.hpp).
  a.plan = plan_diffusion(dof_diffusion_params(p), a.sigma_max, W, H,
                          "sqrt(sigma0^2 + (c/4)^2) at the most blurred pixel, c the circle of confusion (CoC at "
                          "infinity " + text::g(a.alpha_px) + " px: --coc-infinity, or --f-number, --focal-length and "
                          "--sensor-width; --focus-distance), capped by --coc-limit " + text::g(p.coc_limit_px) +
                          " px: lower --coc-limit or the CoC");
  return sigma;
}


Image dof_scale_map(const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec) {
  return detail::dof_scale_map_rows(z, p, a, exec, true);
}

}  // namespace brume
