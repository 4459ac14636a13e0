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
//     component (each one reaches a scene pixel), hence SPD; it is solved in
//     double by Jacobi-preconditioned conjugate gradients from a distance-
//     weighted blend of the nearest scene value and S_max, until
//     max|r| <= residual_tol * S_max / 4 (r is exactly the discrete
//     Laplacian). Rounding the solution to float adds at most 8 * 2^-24 S_max
//     = 4.8e-7 S_max to the Laplacian, so the float output meets residual_tol
//     (>= 1e-6); the residual reported is measured on the float output.
//     Dot products use fixed blocks summed in order, so the result is the same
//     for every thread count.
#include "brume/prepare.hpp"

#include <omp.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "brume/error.hpp"

namespace brume {
namespace {

constexpr double kTukey = 4.685;            // 95% efficiency at the normal
constexpr double kMadToSigma = 1.482602218;  // 1 / Phi^-1(3/4)
constexpr double kMinResidualTol = 1e-6;     // float32 rounding floor, see header comment

inline bool is_unknown(float r) { return !std::isfinite(r) || r == 0.0f; }

std::string fmt(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

void check_param(const char* name, double v, double lo, double hi, bool lo_open, const char* meaning) {
  const bool ok = std::isfinite(v) && (lo_open ? v > lo : v >= lo) && v <= hi;
  if (ok) return;
  std::ostringstream m;
  m << "prepare: PrepareParams::" << name << " = " << fmt(v) << " is not allowed; it must be finite and "
    << (lo_open ? "> " : ">= ") << fmt(lo);
  if (std::isfinite(hi)) m << " and <= " << fmt(hi);
  m << " (" << meaning << "). Pass a value in that range (default: " << name << " = ";
  const PrepareParams d;
  const std::string n = name;
  if (n == "sky_margin_px") m << fmt(d.sky_margin_px);
  else if (n == "sky_min_fraction") m << fmt(d.sky_min_fraction);
  else if (n == "sky_large_fraction") m << fmt(d.sky_large_fraction);
  else if (n == "s_max_factor") m << fmt(d.s_max_factor);
  else if (n == "min_coverage") m << fmt(d.min_coverage);
  else if (n == "residual_tol") m << fmt(d.residual_tol);
  m << ").";
  throw Error(m.str());
}

void validate(const PrepareParams& p) {
  const double inf = std::numeric_limits<double>::infinity();
  check_param("sky_margin_px", p.sky_margin_px, 0.0, inf, false,
              "width in pixels of the matted horizon; 0 disables the margin");
  check_param("sky_min_fraction", p.sky_min_fraction, 0.0, 1.0, false,
              "fraction of the image a top-touching unknown region needs to count as sky");
  check_param("sky_large_fraction", p.sky_large_fraction, 0.0, 1.0, false,
              "fraction of the image an unknown region anywhere needs to count as sky");
  check_param("s_max_factor", p.s_max_factor, 1.0, 1e6, true, "S_max = s_max_factor * R_max must exceed R_max");
  check_param("min_coverage", p.min_coverage, 0.0, 1.0, false, "smallest fraction of pixels with a known range");
  check_param("residual_tol", p.residual_tol, kMinResidualTol, 0.1, false,
              "margin solve stops at max |discrete Laplacian| <= residual_tol * S_max; below 1e-6 the float32 "
              "output cannot hold it");
  if (p.ransac_iterations < 1 || p.ransac_iterations > 1000000)
    throw Error("prepare: PrepareParams::ransac_iterations = " + std::to_string(p.ransac_iterations) +
                " is not allowed; it must be between 1 and 1000000 (candidate fill values tried per hole). Pass a "
                "value in that range (default: 64).");
}

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

// Sum of f(i) for i in [0, n), in fixed blocks summed in order: the same bits
// for every thread count.
template <class F>
double det_sum(std::size_t n, F f) {
  constexpr std::size_t B = 2048;
  const std::size_t nb = (n + B - 1) / B;
  std::vector<double> part(nb, 0.0);
#pragma omp parallel for schedule(static) if (nb > 4)
  for (std::size_t k = 0; k < nb; ++k) {
    double a = 0.0;
    const std::size_t e = std::min(n, (k + 1) * B);
    for (std::size_t i = k * B; i < e; ++i) a += f(i);
    part[k] = a;
  }
  double s = 0.0;
  for (double v : part) s += v;
  return s;
}

struct MarginSystem {
  std::vector<std::size_t> pix;  // pixel index of each unknown
  std::vector<int> nb;           // 4 neighbour unknowns per row, -1 = none
  std::vector<double> diag, b;   // in-image neighbour count; sum of Dirichlet neighbours
};

// y = A x
void apply(const MarginSystem& s, const std::vector<double>& x, std::vector<double>& y) {
  const std::size_t n = s.pix.size();
#pragma omp parallel for schedule(static) if (n > 20000)
  for (std::size_t i = 0; i < n; ++i) {
    double a = s.diag[i] * x[i];
    const int* q = &s.nb[4 * i];
    for (int k = 0; k < 4; ++k)
      if (q[k] >= 0) a -= x[q[k]];
    y[i] = a;
  }
}

// Jacobi-preconditioned CG until max |b - A u| <= target. Returns iterations.
int solve_cg(const MarginSystem& s, std::vector<double>& u, double target) {
  const std::size_t n = s.pix.size();
  std::vector<double> r(n), z(n), p(n), q(n);
  auto residual = [&] {
    apply(s, u, q);
    double m = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      r[i] = s.b[i] - q[i];
      m = std::max(m, std::abs(r[i]));
    }
    return m;
  };
  int iters = 0;
  const int cap = static_cast<int>(std::min<std::size_t>(n + 1000, 1000000));
  for (int restart = 0; restart < 4 && iters < cap; ++restart) {
    double rmax = residual();
    if (rmax <= target) break;
    for (std::size_t i = 0; i < n; ++i) p[i] = z[i] = r[i] / s.diag[i];
    double rz = det_sum(n, [&](std::size_t i) { return r[i] * z[i]; });
    while (rmax > target && iters < cap) {
      apply(s, p, q);
      const double pq = det_sum(n, [&](std::size_t i) { return p[i] * q[i]; });
      if (!(pq > 0.0)) break;
      const double alpha = rz / pq;
      rmax = 0.0;
      for (std::size_t i = 0; i < n; ++i) {
        u[i] += alpha * p[i];
        r[i] -= alpha * q[i];
        z[i] = r[i] / s.diag[i];
        rmax = std::max(rmax, std::abs(r[i]));
      }
      const double rz_new = det_sum(n, [&](std::size_t i) { return r[i] * z[i]; });
      const double beta = rz_new / rz;
      rz = rz_new;
      for (std::size_t i = 0; i < n; ++i) p[i] = z[i] + beta * p[i];
      ++iters;
    }
    // The loop ends on the recursive residual; the restart check above
    // verifies it against the true one.
  }
  return iters;
}

}  // namespace

PrepareResult prepare_range(const Image& range, const PrepareParams& p) {
  validate(p);
  if (range.empty() || range.width <= 0 || range.height <= 0)
    throw Error("prepare: the range map is empty (" + range.size_string() +
                "); pass a range map with at least one pixel.");
  if (range.channels != 1)
    throw Error("prepare: the range map has " + std::to_string(range.channels) +
                " channels; it must have exactly 1 (range in metres). Read a single channel (e.g. read_scalar with "
                "channel \"Z\") or split the channels first.");
  assert(range.data.size() == range.pixels());

  const int W = range.width, H = range.height;
  const std::size_t N = range.pixels();
  const float* in = range.data.data();

  // --- 1. classify ---------------------------------------------------------
  cv::Mat unknown(H, W, CV_8U);
  std::size_t known = 0, negatives = 0, first_neg = N;
  float rmax = 0.0f;
#pragma omp parallel for schedule(static) reduction(+ : known, negatives) reduction(min : first_neg) \
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
                fmt(in[first_neg]) + " m at pixel (" + std::to_string(fx) + ", " + std::to_string(fy) +
                "); range must be > 0 where known, with NaN, inf or 0 marking unknown pixels. Fix the conversion "
                "that produced the map (e.g. a disparity offset or sign) or set invalid pixels to NaN.");
  }
  PrepareResult res;
  res.known_fraction = static_cast<double>(known) / static_cast<double>(N);
  if (known == 0 || res.known_fraction < p.min_coverage) {
    std::ostringstream m;
    char pct[32];
    std::snprintf(pct, sizeof pct, "%.2f%%", 100.0 * res.known_fraction);
    m << "prepare: the range map (" << range.size_string() << ") has known values at only " << known << " of " << N
      << " pixels, i.e. it covers " << pct << " of the pixels, below min_coverage = " << fmt(100.0 * p.min_coverage)
      << "%. This looks like a sparse map (e.g. a projected lidar scan); prepare fills holes and sky in dense "
         "maps only and would invent most of this one. Densify/complete the depth first (depth completion, "
         "stereo, a mesh render), or run the effect with --prepare off.";
    throw Error(m.str());
  }
  res.range_max_m = rmax;
  float smax = static_cast<float>(p.s_max_factor * static_cast<double>(rmax));
  if (!(smax > rmax)) smax = std::nextafter(rmax, std::numeric_limits<float>::infinity());
  if (!std::isfinite(smax))
    throw Error("prepare: S_max = s_max_factor * R_max = " + fmt(p.s_max_factor) + " * " + fmt(rmax) +
                " m overflows float; the map's largest range is implausible (check its units) or s_max_factor is "
                "too large (lower it).");
  res.s_max_m = smax;

  res.range = range;
  res.sky_mask = Image(W, H, 1, 0.0f);
  res.hole_mask = Image(W, H, 1, 0.0f);
  res.margin_mask = Image(W, H, 1, 0.0f);
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
    const bool sky = (top && area >= p.sky_min_fraction * dN) || area >= p.sky_large_fraction * dN;
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
  hole_id[0] = -1;
  const int nholes = static_cast<int>(hole_seed.size());
  res.holes = static_cast<std::size_t>(nholes);

  // --- 2. holes: boundary values, RANSAC --------------------------------------
  std::vector<float> fill(nholes, 0.0f);
  if (nholes > 0) {
    const int T = omp_get_max_threads();
    std::vector<std::vector<std::pair<int, float>>> part(T);
#pragma omp parallel num_threads(T)
    {
      auto& mine = part[omp_get_thread_num()];
#pragma omp for schedule(static)
      for (int y = 0; y < H; ++y) {
        const int* L = labels.ptr<int>(y);
        const int* Lu = y > 0 ? labels.ptr<int>(y - 1) : nullptr;
        const int* Ld = y + 1 < H ? labels.ptr<int>(y + 1) : nullptr;
        const float* r = in + static_cast<std::size_t>(y) * W;
        for (int x = 0; x < W; ++x) {
          if (L[x] != 0) continue;
          int c[4], nc = 0;
          auto add = [&](int l) {
            const int h = hole_id[l];
            if (h < 0) return;
            for (int k = 0; k < nc; ++k)
              if (c[k] == h) return;
            c[nc++] = h;
          };
          if (x > 0 && L[x - 1]) add(L[x - 1]);
          if (x + 1 < W && L[x + 1]) add(L[x + 1]);
          if (Lu && Lu[x]) add(Lu[x]);
          if (Ld && Ld[x]) add(Ld[x]);
          for (int k = 0; k < nc; ++k) mine.emplace_back(c[k], r[x]);
        }
      }
    }
    std::vector<std::vector<float>> bnd(nholes);
    for (auto& v : part)
      for (auto& [h, val] : v) bnd[h].push_back(val);
    part.clear();
#pragma omp parallel for schedule(dynamic, 16)
    for (int h = 0; h < nholes; ++h) fill[h] = ransac_fill(bnd[h], p.ransac_iterations, hole_seed[h]);
  }

  // --- 3. fill holes and sky ---------------------------------------------------
  {
    float* out = res.range.data.data();
    float* skym = res.sky_mask.data.data();
    float* holem = res.hole_mask.data.data();
#pragma omp parallel for schedule(static)
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
        }
      }
    }
  }
  const double mu = p.sky_margin_px;
  if (res.sky_pixels == 0 || mu < 1.0) return res;

  // --- 4. margin: exact EDT on the sky's bounding box grown by one pixel ----
  // (a sky pixel's nearest scene pixel is no farther than the first scene
  // pixel on a monotone path towards it, which lies in that box).
  const int x0 = std::max(0, sky_left - 1), y0 = std::max(0, sky_top - 1);
  const int x1 = std::min(W - 1, sky_right + 1), y1 = std::min(H - 1, sky_bottom + 1);
  const int cw = x1 - x0 + 1, ch = y1 - y0 + 1;
  cv::Mat skycrop(ch, cw, CV_8U), dist;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < ch; ++y) {
    const float* s = res.sky_mask.row(y + y0) + x0;
    unsigned char* d = skycrop.ptr<unsigned char>(y);
    for (int x = 0; x < cw; ++x) d[x] = s[x] != 0.0f ? 255 : 0;
  }
  cv::distanceTransform(skycrop, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  skycrop.release();

  // Number the margin pixels in raster order; reuse `labels` as the index map
  // (-1 = not a margin pixel) inside the box.
  std::vector<std::size_t> row_count(ch + 1, 0);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < ch; ++y) {
    const float* d = dist.ptr<float>(y);
    std::size_t c = 0;
    for (int x = 0; x < cw; ++x) c += d[x] > 0.0f && d[x] <= mu;
    row_count[y + 1] = c;
  }
  for (int y = 0; y < ch; ++y) row_count[y + 1] += row_count[y];
  const std::size_t n = row_count[ch];
  res.margin_pixels = n;
  if (n == 0) return res;

  MarginSystem sys;
  sys.pix.resize(n);
  std::vector<float> mdist(n);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < ch; ++y) {
    const float* d = dist.ptr<float>(y);
    int* L = labels.ptr<int>(y + y0) + x0;
    std::size_t k = row_count[y];
    for (int x = 0; x < cw; ++x) {
      if (d[x] > 0.0f && d[x] <= mu) {
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
  sys.nb.assign(4 * n, -1);
  sys.diag.assign(n, 0.0);
  sys.b.assign(n, 0.0);
  std::vector<double> scene_sum(n, 0.0);
  std::vector<unsigned char> scene_cnt(n, 0);
  {
    const float* out = res.range.data.data();
    const float* skym = res.sky_mask.data.data();
    float* mm = res.margin_mask.data.data();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t pi = sys.pix[i];
      mm[pi] = 1.0f;
      const int x = static_cast<int>(pi % W), y = static_cast<int>(pi / W);
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
        }
      }
    }
  }

  // Start: breadth-first nearest scene value v, then v + (S_max - v) t with
  // t = distance / (floor(mu) + 1), the exact solution across a straight strip.
  std::vector<double> u(n);
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
        const int j = sys.nb[4 * i + k];
        if (j >= 0 && !seen[j]) seen[j] = 1, v[j] = v[i], queue.push_back(j);
      }
    }
    const double span = std::floor(mu) + 1.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double t = std::min(1.0, mdist[i] / span);
      u[i] = v[i] + (smax - v[i]) * t;
    }
  }

  res.solver_iterations = solve_cg(sys, u, 0.25 * p.residual_tol * smax);

  // Write back in float and measure the residual actually delivered.
  float* out = res.range.data.data();
  for (std::size_t i = 0; i < n; ++i) out[sys.pix[i]] = static_cast<float>(u[i]);
  double worst = 0.0;
#pragma omp parallel for schedule(static) reduction(max : worst)
  for (std::size_t i = 0; i < n; ++i) {
    double a = -sys.diag[i] * out[sys.pix[i]] + sys.b[i];
    for (int k = 0; k < 4; ++k)
      if (sys.nb[4 * i + k] >= 0) a += out[sys.pix[sys.nb[4 * i + k]]];
    worst = std::max(worst, std::abs(a));
  }
  res.margin_residual = worst / smax;
  return res;
}

}  // namespace brume
