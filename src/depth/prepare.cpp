// brume — range-map preparation (Hansard 2018, section 4.1).
//
// Physics. The haze model attenuates each pixel by exp(-kappa R) and blends it
// with the airlight, so every pixel needs a finite range R. Scanner and stereo
// maps have holes (dropped returns, occlusions) and no range at all for the
// sky. The sky has no "correct" range: it is composed with the airlight
// anyway, so any large value works, provided the horizon does not get a hard
// edge. The paper therefore (a) fills small holes with a plausible constant,
// (b) gives the sky a constant S_max > R_max and (c) mattes a band of width mu
// at the horizon by solving Laplace's equation there, tapering smoothly from
// the observed ranges into S_max. Observed values are never altered.
//
// Algorithm (rules in include/brume/prepare.hpp):
//  1. Unknown = NaN, +-inf or 0; negative finite values are refused. Unknown
//     pixels are labelled into 8-connected components (OpenCV
//     connectedComponentsWithStats). A component is SKY if it touches row 0 and
//     has area >= sky_min_fraction * N, or has area >= sky_large_fraction * N;
//     every other component is a HOLE.
//  2. Hole filling: the boundary of a hole is the set of known pixels 4-adjacent
//     to it (each pixel counted once). Candidates c are boundary values (all
//     distinct ones when there are at most ransac_iterations boundary pixels,
//     else ransac_iterations draws from a std::mt19937_64 seeded from `seed`
//     and the hole's position, so results do not depend on label order or
//     thread count). Score(c) = sum_b rho((R_b - c) / s), rho = Tukey biweight
//     (k = 4.685), s = 1.4826 MAD of the boundary values (MAD = 0 falls back
//     to 1e-6 |median|). The smallest score wins (first one on ties) and fills
//     the whole hole, so the value lies within [min, max] of the boundary.
//  3. Sky pixels get S_max = s_max_factor * R_max (rounded to float, forced
//     strictly above R_max).
//  4. Margin: sky pixels whose exact Euclidean distance to the scene (known +
//     filled pixels; cv::distanceTransform DIST_L2 / DIST_MASK_PRECISE) is
//     <= mu. On the margin we solve the 4-neighbour discrete Laplace equation
//        sum_{q in N4(p)} (S_q - S_p) = 0,
//     with Dirichlet values S = R at scene neighbours and S = S_max at sky
//     neighbours outside the margin. A neighbour outside the image is the
//     pixel itself (half-sample mirror, zero flux), so its term vanishes.
//     The system A u = b (A = diag(d_p) - adjacency, d_p = in-image neighbour
//     count) is symmetric and irreducibly diagonally dominant on every margin
//     component (each one reaches a scene pixel), hence SPD. It is solved in
//     double by conjugate gradients (no preconditioner: diag(A) is 4 except at
//     the border) from a distance-weighted blend of the nearest scene value
//     and S_max, until max|r| <= residual_tol * S_max / 4, where r = b - A u is
//     exactly the discrete Laplacian. Rounding the solution to float adds at
//     most 8 * 2^-24 S_max = 4.8e-7 S_max to the Laplacian, so the float output
//     meets residual_tol (which must be >= 1e-6); the residual reported is the
//     one measured on the float output. The sky weight w solves the same
//     system with 0 at scene neighbours and 1 at sky neighbours outside the
//     margin (b = the count of those), by the same CG from the same strip
//     start, to max|r| <= residual_tol / 4. One boundary differs: above the
//     top row lies sky (w = 1 there, a Dirichlet neighbour, where the range
//     has its mirror), because the sky goes on above the frame -- a sky
//     strip narrower than mu, all of it margin, would otherwise have no sky
//     side and weigh 0. It is written clamped to [0, 1]
//     (the maximum principle keeps it there up to the tolerance), 1 on the
//     sky beyond the margin. CG iterations grow like mu (condition
//     number ~ mu^2); Jacobi sweeps roughly like mu^1.5..2. Measured on the
//     1600x1120 benchmark scene for mu = 4/8/16/32: CG 46/75/130/241
//     iterations, Jacobi 273/767/2321/6845 sweeps to the same residual; the
//     paper's fixed 2 mu sweeps stop at max|Lap| = 0.18..0.02 S_max. Dot
//     products use fixed blocks summed in order, so the result is the same
//     for every thread count.
//
// Cost (bench/bench_prepare.cpp, 1600x1120, 2 threads): labelling, EDT and the
// per-pixel passes are O(N), ~30 ms; CG on the 67k margin pixels ~25 ms.
#include "brume/prepare.hpp"

#include <omp.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "core/text.hpp"

#include "brume_opencv.hpp"
#include "core/schedule.hpp"
#include "depth/sky_check.hpp"

namespace brume {

const ParamTable<PrepareParams>& prepare_param_table() {
  static const ParamTable<PrepareParams> t = [] {
    ParamTable<PrepareParams> d("prepare");
    d.real("sky-margin", &PrepareParams::sky_margin_px, "px", Range::at_least(0.0),
           "width mu of the matted horizon between scene and sky; 0 disables the margin")
        .real("s-max-factor", &PrepareParams::s_max_factor, "1", Range::left_open(1.0, 1e6),
              "sky range S_max = factor * R_max; must exceed 1 so the sky lies beyond the scene")
        .real("min-coverage", &PrepareParams::min_coverage, "1", Range::closed(0.0, 1.0),
              "refuse maps whose known pixels cover less than this fraction (a projected lidar scan)")
        .real("sky-min-fraction", &PrepareParams::sky_min_fraction, "1", Range::closed(0.0, 1.0),
              "area fraction a top-touching unknown region needs to count as sky")
        .real("sky-large-fraction", &PrepareParams::sky_large_fraction, "1", Range::closed(0.0, 1.0),
              "area fraction an unknown region anywhere needs to count as sky")
        .real("residual-tol", &PrepareParams::residual_tol, "1", Range::closed(1e-6, 0.1),
              "the margin solve stops at max |discrete Laplacian| <= tol * S_max (below 1e-6 a float32 "
              "output cannot hold it)")
        .integer("ransac-iterations", &PrepareParams::ransac_iterations, "1", Range::closed(1, 1e6),
                 "candidate fill values tried per hole")
        .count("seed", &PrepareParams::seed, "1", Range::at_least(0.0),
               "seed of the hole-filling RANSAC (results are deterministic for a seed)");
    return d;
  }();
  return t;
}

namespace {

constexpr double kTukey = 4.685;            // 95% efficiency at the normal
constexpr double kMadToSigma = 1.482602218;  // 1 / Phi^-1(3/4)

inline bool is_unknown(float r) { return !std::isfinite(r) || r == 0.0f; }

// Every parameter through its declaration (brume/pipeline.hpp): messages name
// the flag (--sky-margin), the value, the allowed range and the meaning.
void validate(const PrepareParams& p) { prepare_param_table().validate(p); }

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

inline double tukey_rho(double u) {
  constexpr double c2_6 = kTukey * kTukey / 6.0;
  const double a = std::abs(u);
  if (a >= kTukey) return c2_6;
  const double t = 1.0 - (u / kTukey) * (u / kTukey);
  return c2_6 * (1.0 - t * t * t);
}

// RANSAC fill value of one hole from its (sorted) boundary values.
float ransac_fill(std::vector<float>& bv, int iterations, std::uint64_t seed) {
  assert(!bv.empty());
  std::sort(bv.begin(), bv.end());
  const std::size_t n = bv.size();
  const double median = n % 2 ? bv[n / 2] : 0.5 * (static_cast<double>(bv[n / 2 - 1]) + bv[n / 2]);
  std::vector<double> dev(n);
  for (std::size_t i = 0; i < n; ++i) dev[i] = std::abs(bv[i] - median);
  std::nth_element(dev.begin(), dev.begin() + n / 2, dev.end());
  double s = kMadToSigma * dev[n / 2];
  if (!(s > 0.0)) s = std::max(1e-6 * std::abs(median), 1e-30);
  const double inv_s = 1.0 / s;

  // Score of candidate c: only boundary values within k s of c contribute less
  // than the constant k^2/6, and bv is sorted, so sum over that window only.
  auto score = [&](float c) {
    const double half = kTukey * s;
    auto lo = std::lower_bound(bv.begin(), bv.end(), static_cast<float>(c - half));
    auto hi = std::upper_bound(lo, bv.end(), static_cast<float>(c + half));
    double sum = static_cast<double>(n - static_cast<std::size_t>(hi - lo)) * (kTukey * kTukey / 6.0);
    for (auto it = lo; it != hi; ++it) sum += tukey_rho((static_cast<double>(*it) - c) * inv_s);
    return sum;
  };

  float best = bv[0];
  double best_score = std::numeric_limits<double>::infinity();
  auto consider = [&](float c) {
    const double sc = score(c);
    if (sc < best_score) best_score = sc, best = c;
  };
  if (n <= static_cast<std::size_t>(iterations)) {
    for (std::size_t i = 0; i < n; ++i)
      if (i == 0 || bv[i] != bv[i - 1]) consider(bv[i]);
  } else {
    std::mt19937_64 rng(seed);
    for (int it = 0; it < iterations; ++it) consider(bv[rng() % n]);
  }
  return best;
}

// The margin system A u = b: A = diag(d) - adjacency, d = in-image neighbour
// count (2..4), b = sum of the Dirichlet neighbours' values.
struct MarginSystem {
  std::size_t n = 0;
  std::vector<std::size_t> pix;  // pixel index of each unknown
  std::vector<int> nb;           // 4 neighbour unknowns per row; n = none (indexes a zero entry)
  std::vector<double> diag, b;
};

// The solver works on fixed blocks of unknowns; per-block partial sums are
// added in block order, so results do not depend on the thread count.
constexpr std::size_t kBlock = 4096;

// Conjugate gradients on A u = b until max |b - A u| <= target; returns the
// iteration count. No preconditioner: diag(A) is 4 except at the image border,
// so Jacobi scaling does not change the iteration count (measured).
int solve_cg(const MarginSystem& s, std::vector<double>& u, double target, int nt) {
  const std::size_t n = s.n;
  const std::size_t nblk = (n + kBlock - 1) / kBlock;
  const int* nb = s.nb.data();
  const double* diag = s.diag.data();
  // Index n holds 0 in every vector read through a neighbour index.
  std::vector<double> r(n), q(n), p(n + 1, 0.0);
  u.resize(n + 1);
  u[n] = 0.0;
  std::vector<double> part(nblk), part2(nblk);
  const bool par = n > 16384;
  auto ordered = [](const std::vector<double>& v) {
    double a = 0.0;
    for (double x : v) a += x;
    return a;
  };
  auto ordered_max = [](const std::vector<double>& v) {
    double a = 0.0;
    for (double x : v) a = std::max(a, x);
    return a;
  };
  // r = b - A u, p = r; returns max |r| and r.r.
  auto restart = [&] {
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (par)
    for (std::size_t k = 0; k < nblk; ++k) {
      double m = 0.0, rr = 0.0;
      const std::size_t e = std::min(n, (k + 1) * kBlock);
      for (std::size_t i = k * kBlock; i < e; ++i) {
        const int* c = nb + 4 * i;
        const double ri = s.b[i] - (diag[i] * u[i] - u[c[0]] - u[c[1]] - u[c[2]] - u[c[3]]);
        r[i] = p[i] = ri;
        rr += ri * ri;
        m = std::max(m, std::abs(ri));
      }
      part[k] = m;
      part2[k] = rr;
    }
    return std::pair(ordered_max(part), ordered(part2));
  };

  int iters = 0;
  const int cap = static_cast<int>(std::min<std::size_t>(n + 1000, 1000000));
  for (int attempt = 0; attempt < 4 && iters < cap; ++attempt) {
    auto [rmax, rr] = restart();
    if (rmax <= target) break;
    while (rmax > target && iters < cap) {
      // q = A p, p.q
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (par)
      for (std::size_t k = 0; k < nblk; ++k) {
        double a = 0.0;
        const std::size_t e = std::min(n, (k + 1) * kBlock);
#pragma omp simd reduction(+ : a)
        for (std::size_t i = k * kBlock; i < e; ++i) {
          const int* c = nb + 4 * i;
          const double qi = diag[i] * p[i] - p[c[0]] - p[c[1]] - p[c[2]] - p[c[3]];
          q[i] = qi;
          a += p[i] * qi;
        }
        part[k] = a;
      }
      const double pq = ordered(part);
      if (!(pq > 0.0)) break;
      const double alpha = rr / pq;
      // u += alpha p, r -= alpha q, r.r, max |r|
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (par)
      for (std::size_t k = 0; k < nblk; ++k) {
        // Two interleaved accumulators (even/odd i) for the sum and the max:
        // shorter dependency chains, fixed order. (No `omp simd` here: clang
        // cannot vectorise a floating-point max reduction without fast-math.)
        double a[2] = {0.0, 0.0}, m[2] = {0.0, 0.0};
        const std::size_t e = std::min(n, (k + 1) * kBlock);
        for (std::size_t i = k * kBlock; i < e; ++i) {
          u[i] += alpha * p[i];
          const double ri = r[i] - alpha * q[i];
          r[i] = ri;
          a[i & 1] += ri * ri;
          m[i & 1] = std::max(m[i & 1], std::abs(ri));
        }
        part[k] = a[0] + a[1];
        part2[k] = std::max(m[0], m[1]);
      }
      const double rr_new = ordered(part);
      rmax = ordered_max(part2);
      const double beta = rr_new / rr;
      rr = rr_new;
      // p = r + beta p
#pragma omp parallel for num_threads(nt) schedule(dynamic, kBlock) if (par)
      for (std::size_t i = 0; i < n; ++i) p[i] = r[i] + beta * p[i];
      ++iters;
    }
    // The loop stops on the recursive residual; the next restart() checks the
    // true one and continues from there if rounding made them differ.
  }
  u.resize(n);
  return iters;
}

// max |b - A v| over the margin, v the float values written to `out`.
double float_residual(const MarginSystem& s, const float* out, int nt) {
  double worst = 0.0;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk) reduction(max : worst)
  for (std::size_t i = 0; i < s.n; ++i) {
    double a = s.b[i] - s.diag[i] * static_cast<double>(out[s.pix[i]]);
    for (int k = 0; k < 4; ++k) {
      const std::size_t j = static_cast<std::size_t>(s.nb[4 * i + k]);
      if (j < s.n) a += out[s.pix[j]];
    }
    worst = std::max(worst, std::abs(a));
  }
  return worst;
}

}  // namespace

PrepareResult prepare_range(DenseImageRef range, const PrepareParams& p, int threads, bool sky_weight) {
  validate(p);
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  if (range.empty() || range.width <= 0 || range.height <= 0)
    throw Error("prepare: the range map is empty (" + range.size_string() +
                "); pass a range map with at least one pixel.");
  if (range.channels != 1)
    throw Error("prepare: the range map has " + std::to_string(range.channels) +
                " channels; it must have exactly 1 (range in metres). Read a single channel (e.g. read_scalar with "
                "channel \"Z\") or split the channels first.");
  assert(range.data.size() == range.pixels());
  if (range.pixels() >= static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw Error("prepare: the range map is " + range.size_string() + " = " + std::to_string(range.pixels()) +
                " pixels; at most 2^31 - 2 are supported (labels are 32-bit). Prepare it in tiles or downsample it.");

  const int W = range.width, H = range.height;
  const std::size_t N = range.pixels();
  const float* in = range.data.data();

  // --- 1. classify ---------------------------------------------------------
  cv::Mat unknown(H, W, CV_8U);
  std::size_t known = 0, negatives = 0, first_neg = N;
  float rmax = 0.0f;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk) reduction(+ : known, negatives) reduction(min : first_neg) \
    reduction(max : rmax)
  for (int y = 0; y < H; ++y) {
    unsigned char* u = unknown.ptr<unsigned char>(y);
    const float* r = in + static_cast<std::size_t>(y) * W;
    for (int x = 0; x < W; ++x) {
      const float v = r[x];
      const bool unk = is_unknown(v);
      u[x] = unk ? 255 : 0;
      if (unk) continue;
      if (v < 0.0f) {
        ++negatives;
        first_neg = std::min(first_neg, static_cast<std::size_t>(y) * W + x);
        continue;
      }
      ++known;
      rmax = std::max(rmax, v);
    }
  }
  if (negatives) {
    const int fx = static_cast<int>(first_neg % W), fy = static_cast<int>(first_neg / W);
    throw Error("prepare: the range map has " + std::to_string(negatives) + " negative value(s), the first " +
                text::g(in[first_neg]) + " m at pixel (" + std::to_string(fx) + ", " + std::to_string(fy) +
                "); range must be > 0 where known, with NaN, inf or 0 marking unknown pixels. Fix the conversion "
                "that produced the map (e.g. a disparity offset or sign), set invalid pixels to NaN, or, if the file "
                "marks unknown pixels with a negative value such as -1, give it as --unknown-value -1.");
  }
  PrepareResult res;
  res.known_fraction = static_cast<double>(known) / static_cast<double>(N);
  if (known == 0 || res.known_fraction < p.min_coverage) {
    std::ostringstream m;
    char pct[32];
    std::snprintf(pct, sizeof pct, "%.2f%%", 100.0 * res.known_fraction);
    m << "prepare: the range map (" << range.size_string() << ") has known values at only " << known << " of " << N
      << " pixels, i.e. it covers " << pct << " of the pixels, below --min-coverage " << text::g(p.min_coverage) << " (" << text::g(100.0 * p.min_coverage)
      << "%). This looks like a sparse map (e.g. a projected lidar scan); prepare fills holes and sky in dense "
         "maps only and would invent most of this one. Densify/complete the depth first (depth completion, "
         "stereo, a mesh render), or run the effect with --prepare off.";
    throw Error(m.str());
  }
  res.range_max_m = rmax;
  float smax = static_cast<float>(p.s_max_factor * static_cast<double>(rmax));
  if (!(smax > rmax)) smax = std::nextafter(rmax, std::numeric_limits<float>::infinity());
  if (!std::isfinite(smax))
    throw Error("prepare: S_max = --s-max-factor * R_max = " + text::g(p.s_max_factor) + " * " + text::g(rmax) +
                " m overflows float; the map's largest range is implausible (check its units) or --s-max-factor is "
                "too large (lower it).");
  res.s_max_m = smax;

  res.range = range.to_image();  // the output starts as the measured range (its own buffer)
  res.sky_mask = Image(W, H, 1, 0.0f);
  res.hole_mask = Image(W, H, 1, 0.0f);
  res.margin_mask = Image(W, H, 1, 0.0f);
  if (sky_weight) res.sky_weight = Image(W, H, 1, 0.0f);
  if (known == N) return res;  // nothing to fill

  cv::Mat labels, stats, centroids;
  const int ncomp = cv::connectedComponentsWithStats(unknown, labels, stats, centroids, 8, CV_32S);
  unknown.release();

  // Sky / hole decision per component (label 0 = known pixels).
  std::vector<int> hole_id(ncomp, -1);  // >= 0: hole index; -1: known; -2: sky
  std::vector<std::uint64_t> hole_seed;
  int sky_left = W, sky_top = H, sky_right = -1, sky_bottom = -1;
  const double dN = static_cast<double>(N);
  for (int l = 1; l < ncomp; ++l) {
    const int* st = stats.ptr<int>(l);
    const double area = st[cv::CC_STAT_AREA];
    const bool top = st[cv::CC_STAT_TOP] == 0;
    const bool sky = prepare_takes_as_sky(top, area, dN, p);
    if (sky) {
      hole_id[l] = -2;
      res.sky_pixels += static_cast<std::size_t>(area);
      sky_left = std::min(sky_left, st[cv::CC_STAT_LEFT]);
      sky_top = std::min(sky_top, st[cv::CC_STAT_TOP]);
      sky_right = std::max(sky_right, st[cv::CC_STAT_LEFT] + st[cv::CC_STAT_WIDTH] - 1);
      sky_bottom = std::max(sky_bottom, st[cv::CC_STAT_TOP] + st[cv::CC_STAT_HEIGHT] - 1);
    } else {
      hole_id[l] = static_cast<int>(hole_seed.size());
      res.hole_pixels += static_cast<std::size_t>(area);
      // Seed from the hole's geometry, not its label: OpenCV's parallel
      // labelling need not number components in raster order.
      std::uint64_t h = splitmix64(p.seed);
      for (int k : {cv::CC_STAT_LEFT, cv::CC_STAT_TOP, cv::CC_STAT_WIDTH, cv::CC_STAT_HEIGHT, cv::CC_STAT_AREA})
        h = splitmix64(h ^ static_cast<std::uint64_t>(st[k]));
      hole_seed.push_back(h);
    }
  }
  const int nholes = static_cast<int>(hole_seed.size());
  res.holes = static_cast<std::size_t>(nholes);

  // --- 2. holes: boundary values, RANSAC --------------------------------------
  // Boundary of a hole = known pixels 4-adjacent to it, each counted once.
  // Small holes: scan each hole's bounding box grown by one pixel (in
  // parallel over holes). If those boxes add up to more than the image (long
  // diagonal holes), one scan of the whole image instead.
  std::vector<float> fill(nholes, 0.0f);
  if (nholes > 0) {
    std::vector<int> hole_label(nholes);
    double box_area = 0.0;
    for (int l = 1; l < ncomp; ++l)
      if (hole_id[l] >= 0) {
        hole_label[hole_id[l]] = l;
        const int* st = stats.ptr<int>(l);
        box_area += (st[cv::CC_STAT_WIDTH] + 2.0) * (st[cv::CC_STAT_HEIGHT] + 2.0);
      }
    // Known pixel (x, y) borders hole label l?
    auto borders = [&](int x, int y, int l) {
      return (x > 0 && labels.ptr<int>(y)[x - 1] == l) || (x + 1 < W && labels.ptr<int>(y)[x + 1] == l) ||
             (y > 0 && labels.ptr<int>(y - 1)[x] == l) || (y + 1 < H && labels.ptr<int>(y + 1)[x] == l);
    };
    std::vector<std::vector<float>> bnd(nholes);
    if (box_area <= dN) {
#pragma omp parallel for num_threads(nt) schedule(dynamic, 8)
      for (int h = 0; h < nholes; ++h) {
        const int l = hole_label[h];
        const int* st = stats.ptr<int>(l);
        const int bx0 = std::max(0, st[cv::CC_STAT_LEFT] - 1), by0 = std::max(0, st[cv::CC_STAT_TOP] - 1);
        const int bx1 = std::min(W - 1, st[cv::CC_STAT_LEFT] + st[cv::CC_STAT_WIDTH]);
        const int by1 = std::min(H - 1, st[cv::CC_STAT_TOP] + st[cv::CC_STAT_HEIGHT]);
        for (int y = by0; y <= by1; ++y) {
          const int* L = labels.ptr<int>(y);
          for (int x = bx0; x <= bx1; ++x)
            if (L[x] == 0 && borders(x, y, l)) bnd[h].push_back(in[static_cast<std::size_t>(y) * W + x]);
        }
        fill[h] = ransac_fill(bnd[h], p.ransac_iterations, hole_seed[h]);
      }
    } else {
      for (int y = 0; y < H; ++y) {
        const int* L = labels.ptr<int>(y);
        for (int x = 0; x < W; ++x) {
          if (L[x] != 0) continue;
          int c[4], nc = 0;  // distinct holes this known pixel borders
          const int nl[4] = {x > 0 ? L[x - 1] : 0, x + 1 < W ? L[x + 1] : 0, y > 0 ? labels.ptr<int>(y - 1)[x] : 0,
                             y + 1 < H ? labels.ptr<int>(y + 1)[x] : 0};
          for (int l : nl) {
            if (l <= 0 || hole_id[l] < 0 || std::find(c, c + nc, hole_id[l]) != c + nc) continue;
            c[nc++] = hole_id[l];
          }
          for (int k = 0; k < nc; ++k) bnd[c[k]].push_back(in[static_cast<std::size_t>(y) * W + x]);
        }
      }
#pragma omp parallel for num_threads(nt) schedule(dynamic, 8)
      for (int h = 0; h < nholes; ++h) fill[h] = ransac_fill(bnd[h], p.ransac_iterations, hole_seed[h]);
    }
  }

  // --- 3. fill holes and sky ---------------------------------------------------
  {
    float* out = res.range.data.data();
    float* skym = res.sky_mask.data.data();
    float* holem = res.hole_mask.data.data();
    float* skyw = sky_weight ? res.sky_weight.data.data() : nullptr;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y) {
      const int* L = labels.ptr<int>(y);
      const std::size_t o = static_cast<std::size_t>(y) * W;
      for (int x = 0; x < W; ++x) {
        if (!L[x]) continue;
        const int h = hole_id[L[x]];
        if (h >= 0) {
          out[o + x] = fill[h];
          holem[o + x] = 1.0f;
        } else {
          out[o + x] = smax;
          skym[o + x] = 1.0f;
          if (skyw) skyw[o + x] = 1.0f;
        }
      }
    }
  }
  const double mu = p.sky_margin_px;
  if (res.sky_pixels == 0 || mu < 1.0) return res;

  // --- 4. margin: exact EDT on the sky's bounding box grown by one pixel ----
  // (on a monotone pixel path from a sky pixel to its nearest scene pixel, the
  // first non-sky pixel is a scene pixel at least as close, and it borders
  // the sky, so it lies in that box).
  const int x0 = std::max(0, sky_left - 1), y0 = std::max(0, sky_top - 1);
  const int x1 = std::min(W - 1, sky_right + 1), y1 = std::min(H - 1, sky_bottom + 1);
  const int cw = x1 - x0 + 1, ch = y1 - y0 + 1;
  cv::Mat skycrop(ch, cw, CV_8U), dist;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < ch; ++y) {
    const float* s = res.sky_mask.row(y + y0) + x0;
    unsigned char* d = skycrop.ptr<unsigned char>(y);
    for (int x = 0; x < cw; ++x) d[x] = s[x] != 0.0f ? 255 : 0;
  }
  cv::distanceTransform(skycrop, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  skycrop.release();

  // Number the margin pixels in raster order; reuse `labels` as the index map
  // (-1 = not a margin pixel) inside the box. The EDT gives sqrt(k) for an
  // integer squared distance k; d <= mu is decided on k, free of float rounding.
  const double mu2 = mu * mu;
  const double mu_lo = mu - 1e-3, mu_hi = mu + 1e-3;
  auto in_margin = [=](float d) {
    if (!(d > 0.0f) || d > mu_hi) return false;
    return d < mu_lo || static_cast<double>(std::llround(double(d) * d)) <= mu2;
  };
  std::vector<std::size_t> row_count(ch + 1, 0);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < ch; ++y) {
    const float* d = dist.ptr<float>(y);
    std::size_t c = 0;
    for (int x = 0; x < cw; ++x) c += in_margin(d[x]);
    row_count[y + 1] = c;
  }
  for (int y = 0; y < ch; ++y) row_count[y + 1] += row_count[y];
  const std::size_t n = row_count[ch];
  res.margin_pixels = n;
  if (n == 0) return res;

  MarginSystem sys;
  sys.n = n;
  sys.pix.resize(n);
  std::vector<float> mdist(n);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < ch; ++y) {
    const float* d = dist.ptr<float>(y);
    int* L = labels.ptr<int>(y + y0) + x0;
    std::size_t k = row_count[y];
    for (int x = 0; x < cw; ++x) {
      if (in_margin(d[x])) {
        L[x] = static_cast<int>(k);
        sys.pix[k] = static_cast<std::size_t>(y + y0) * W + (x + x0);
        mdist[k] = d[x];
        ++k;
      } else {
        L[x] = -1;
      }
    }
  }
  dist.release();

  // Assemble A and b; record each unknown's scene neighbours for the start.
  sys.nb.assign(4 * n, static_cast<int>(n));
  sys.diag.assign(n, 0.0);
  sys.b.assign(n, 0.0);
  std::vector<double> scene_sum(n, 0.0);
  std::vector<unsigned char> scene_cnt(n, 0), sky_cnt(n, 0), top_row(n, 0);
  {
    const float* out = res.range.data.data();
    const float* skym = res.sky_mask.data.data();
    float* mm = res.margin_mask.data.data();
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk)
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t pi = sys.pix[i];
      mm[pi] = 1.0f;
      const int x = static_cast<int>(pi % W), y = static_cast<int>(pi / W);
      top_row[i] = y == 0;
      const int nx[4] = {x - 1, x + 1, x, x};
      const int ny[4] = {y, y, y - 1, y + 1};
      for (int k = 0; k < 4; ++k) {
        if (nx[k] < 0 || nx[k] >= W || ny[k] < 0 || ny[k] >= H) continue;  // mirror: no flux
        sys.diag[i] += 1.0;
        const std::size_t q = static_cast<std::size_t>(ny[k]) * W + nx[k];
        // Every in-image neighbour of a margin pixel lies in the box, where
        // `labels` now holds margin indices.
        assert(nx[k] >= x0 && nx[k] <= x1 && ny[k] >= y0 && ny[k] <= y1);
        const int j = labels.ptr<int>(ny[k])[nx[k]];
        if (j >= 0) {
          sys.nb[4 * i + k] = j;
        } else {
          sys.b[i] += out[q];
          if (skym[q] == 0.0f) scene_sum[i] += out[q], ++scene_cnt[i];
          else ++sky_cnt[i];
        }
      }
    }
  }

  // Start: breadth-first nearest scene value v, then v + (S_max - v) t with
  // t = distance / (floor(mu) + 1), the exact solution across a straight strip.
  std::vector<double> u(n), w(n);
  {
    std::vector<double> v(n, smax);
    std::vector<unsigned char> seen(n, 0);
    std::vector<std::size_t> queue;
    queue.reserve(n);
    for (std::size_t i = 0; i < n; ++i)
      if (scene_cnt[i]) v[i] = scene_sum[i] / scene_cnt[i], seen[i] = 1, queue.push_back(i);
    for (std::size_t h = 0; h < queue.size(); ++h) {
      const std::size_t i = queue[h];
      for (int k = 0; k < 4; ++k) {
        const std::size_t j = static_cast<std::size_t>(sys.nb[4 * i + k]);
        if (j < n && !seen[j]) seen[j] = 1, v[j] = v[i], queue.push_back(j);
      }
    }
    const double span = std::floor(mu) + 1.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double t = std::min(1.0, mdist[i] / span);
      u[i] = v[i] + (smax - v[i]) * t;
      w[i] = t;
    }
  }

  res.solver_iterations = solve_cg(sys, u, 0.25 * p.residual_tol * smax, nt);

  // Write back in float and measure the residual actually delivered.
  float* out = res.range.data.data();
  for (std::size_t i = 0; i < n; ++i) out[sys.pix[i]] = static_cast<float>(u[i]);
  res.margin_residual = float_residual(sys, out, nt) / smax;

  // The sky weight: the same operator, 0 on the scene side, 1 on the sky's
  // and above the frame.
  if (!sky_weight) return res;
  for (std::size_t i = 0; i < n; ++i) sys.b[i] = sky_cnt[i] + top_row[i], sys.diag[i] += top_row[i];
  res.weight_iterations = solve_cg(sys, w, 0.25 * p.residual_tol, nt);
  float* skyw = res.sky_weight.data.data();
  for (std::size_t i = 0; i < n; ++i) skyw[sys.pix[i]] = static_cast<float>(std::clamp(w[i], 0.0, 1.0));
  res.weight_residual = float_residual(sys, skyw, nt);
  return res;
}

PreparedSkyCheck check_prepared_sky(ConstImageView range, const PrepareParams& p) {
  PreparedSkyCheck out;
  const int W = range.width(), H = range.height();
  if (W <= 0 || H <= 0) return out;
  const std::size_t N = static_cast<std::size_t>(W) * static_cast<std::size_t>(H);
  out.pixels = N;
  cv::Mat unknown(H, W, CV_8U);
  std::vector<int> first_known(static_cast<std::size_t>(W), H);  // each column's topmost known row
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const bool known = !is_unknown(range.at(x, y));
      unknown.data[static_cast<std::size_t>(y) * W + x] = known ? 0 : 1;
      if (known && y < first_known[static_cast<std::size_t>(x)]) first_known[static_cast<std::size_t>(x)] = y;
    }
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(unknown, labels, stats, centroids, 8, CV_32S);
  std::vector<std::uint8_t> sky(static_cast<std::size_t>(n), 0);
  for (int l = 1; l < n; ++l) {
    const int* st = stats.ptr<int>(l);
    sky[static_cast<std::size_t>(l)] =
        prepare_takes_as_sky(st[cv::CC_STAT_TOP] == 0, st[cv::CC_STAT_AREA], static_cast<double>(N), p) ? 1 : 0;
  }
  for (int y = 0; y < H; ++y) {
    const int* L = labels.ptr<int>(y);
    for (int x = 0; x < W; ++x) {
      if (!sky[static_cast<std::size_t>(L[x])]) continue;
      ++out.sky;
      if (y > first_known[static_cast<std::size_t>(x)]) ++out.under;
    }
  }
  return out;
}

}  // namespace brume
