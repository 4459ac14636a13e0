// brume benchmark — range preparation (Hansard 4.1): prepare_range against a
// plain Jacobi iteration on the same horizon-margin problem.
//
// Input: a synthetic 1600x1120 range map: ground receding from 3 m to 80 m,
// boxes, an irregular skyline (sum of four sines), poles reaching high into
// the sky, objects floating in the sky (so the margin has inner rings) and
// 400 small holes marked NaN / inf / 0.
//
// Cases (one warm-up, then the median and spread of --runs timed runs):
//  * prepare_range, whole pipeline (labelling, RANSAC, EDT, CG margin solve);
//  * the two OpenCV calls it makes, alone, on the same masks, for scale;
//  * Jacobi on the margin problem prepare solved (same margin, same Dirichlet
//    data), started from S_max as in the paper, run until it reaches the
//    residual prepare delivered (capped at --jacobi-cap iterations), and its
//    residual after the paper's fixed 2 mu sweeps.
//
//   brume_bench_prepare [--runs N] [--threads N] [--jacobi-cap N] [--margin MU]
//
// Output: a Markdown table on stdout.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "brume/prepare.hpp"

#include "bench_util.hpp"
#include "brume_opencv.hpp"

using namespace brume;

namespace {

using Timing = brume::bench::Spread;

Timing measure(const std::function<void()>& fn, int runs) { return brume::bench::time_ms(fn, runs); }

std::string machine() { return brume::bench::cpu_name(); }

Image scene(int W, int H) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  Image r(W, H, 1);
  for (int x = 0; x < W; ++x) {
    const double u = x / static_cast<double>(W);
    double sky = 0.30 * H + 0.06 * H * std::sin(2 * std::numbers::pi * 1.3 * u) + 0.03 * H * std::sin(2 * std::numbers::pi * 7.1 * u + 1) +
                 0.015 * H * std::sin(2 * std::numbers::pi * 31.0 * u + 2) + 0.006 * H * std::sin(2 * std::numbers::pi * 97.0 * u);
    if (std::fmod(x, 173.0) < 9.0) sky = 0.08 * H;                   // poles reaching far up
    for (int y = 0; y < H; ++y) {
      const double t = (H - 1.0 - y) / (H - 1.0);                        // 0 bottom .. 1 top
      float v = static_cast<float>(3.0 + 77.0 * t * t + 0.002 * x);      // receding ground
      if (x % 400 > 150 && x % 400 < 260 && y > 0.55 * H && y < 0.8 * H) v = 12.0f + 0.001f * x;  // boxes
      if (y < sky) v = nan;
      r.at(x, y) = v;
    }
  }
  // Things in the sky: a few "birds" (known blobs), each ringed by margin.
  for (int k = 0; k < 6; ++k) {
    const int cx = 150 + 260 * k, cy = static_cast<int>(0.06 * H) + 13 * k;
    for (int y = cy - 4; y <= cy + 4; ++y)
      for (int x = cx - 10; x <= cx + 10; ++x)
        if (x >= 0 && x < W && y >= 0 && y < H && std::isnan(r.at(x, y))) r.at(x, y) = 70.0f;
  }
  // Small holes in the scene.
  std::mt19937 g(11);
  const float marks[3] = {nan, std::numeric_limits<float>::infinity(), 0.0f};
  for (int k = 0; k < 400; ++k) {
    const int cx = static_cast<int>(g() % W), cy = static_cast<int>(0.45 * H + g() % static_cast<unsigned>(0.55 * H));
    const int rad = 1 + static_cast<int>(g() % 7);
    for (int y = cy - rad; y <= cy + rad; ++y)
      for (int x = cx - rad; x <= cx + rad; ++x)
        if (x >= 0 && x < W && y >= 0 && y < H && (x - cx) * (x - cx) + (y - cy) * (y - cy) <= rad * rad)
          r.at(x, y) = marks[k % 3];
  }
  return r;
}

struct Jacobi {
  int iterations = 0;
  bool capped = false;
  double residual = 0.0;       // max |Laplacian| / S_max reached
  double residual_2mu = 0.0;   // after the paper's 2 mu sweeps
};

// Plain Jacobi on the margin of `res` (mirror at the border), from S_max,
// until max |Lap| <= target * S_max or `cap` iterations.
Jacobi jacobi(const PrepareResult& res, double target, int cap, int sweeps_2mu) {
  const int W = res.range.width, H = res.range.height;
  const std::size_t N = res.range.data.size();
  std::vector<double> g(res.range.data.begin(), res.range.data.end());
  g.push_back(0.0);  // g[N] = 0 stands in for a neighbour outside the image
  std::vector<std::size_t> pix;
  for (std::size_t i = 0; i < N; ++i)
    if (res.margin_mask.data[i] == 1.0f) pix.push_back(i), g[i] = res.s_max_m;
  const std::size_t n = pix.size();
  // Neighbour pixel indices and in-image neighbour counts, set up once. With
  // the mirror (zero flux) a neighbour outside the image adds no term.
  std::vector<std::size_t> nbr(4 * n);
  std::vector<double> deg(n), nu(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t p = pix[i];
    const int x = static_cast<int>(p % W), y = static_cast<int>(p / W);
    nbr[4 * i + 0] = x > 0 ? p - 1 : N;
    nbr[4 * i + 1] = x + 1 < W ? p + 1 : N;
    nbr[4 * i + 2] = y > 0 ? p - W : N;
    nbr[4 * i + 3] = y + 1 < H ? p + W : N;
    deg[i] = (x > 0) + (x + 1 < W) + (y > 0) + (y + 1 < H);
  }
  const double smax = res.s_max_m;
  Jacobi out;
  bool done = false;
  for (int it = 0;; ++it) {
    double worst = 0.0;
#pragma omp parallel for schedule(static) reduction(max : worst)
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t* q = &nbr[4 * i];
      const double gp = g[pix[i]];
      const double s = g[q[0]] + g[q[1]] + g[q[2]] + g[q[3]];
      worst = std::max(worst, std::abs(s - deg[i] * gp));
      nu[i] = s / deg[i];
    }
    if (it == sweeps_2mu) out.residual_2mu = worst / smax;
    if (!done && (worst <= target * smax || it >= cap)) {
      done = true;
      out.iterations = it;
      out.capped = worst > target * smax;
      out.residual = worst / smax;
    }
    if (done && it >= sweeps_2mu) return out;
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i) g[pix[i]] = nu[i];
  }
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 5, threads = 0, cap = 200000;
  double margin = PrepareParams{}.sky_margin_px;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", a.c_str());
        std::exit(2);
      }
      return std::atoi(argv[++i]);
    };
    if (a == "--runs") runs = std::max(1, next());
    else if (a == "--threads") threads = next();
    else if (a == "--jacobi-cap") cap = std::max(1, next());
    else if (a == "--margin") margin = std::max(0, next());
    else {
      std::fprintf(stderr, "usage: %s [--runs N] [--threads N] [--jacobi-cap N] [--margin MU]\n", argv[0]);
      return 2;
    }
  }
  if (threads > 0) omp_set_num_threads(threads), cv::setNumThreads(threads);
  const int nt = omp_get_max_threads();

  const int W = 1600, H = 1120;
  const Image in = scene(W, H);
  PrepareParams p;
  p.sky_margin_px = margin;
  PrepareResult res;
  const Timing tp = measure([&] { res = prepare_range(in, p); }, runs);

  // The two OpenCV calls alone, on the same masks.
  cv::Mat unk(H, W, CV_8U), sky(H, W, CV_8U), labels, stats, cent, dist;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float v = in.at(x, y);
      unk.at<unsigned char>(y, x) = (!std::isfinite(v) || v == 0.0f) ? 255 : 0;
      sky.at<unsigned char>(y, x) = res.sky_mask.at(x, y) == 1.0f ? 255 : 0;
    }
  const Timing tcc = measure([&] { cv::connectedComponentsWithStats(unk, labels, stats, cent, 8, CV_32S); }, runs);
  const Timing tdt = measure([&] { cv::distanceTransform(sky, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F); }, runs);

  const int sweeps = static_cast<int>(std::lround(2 * p.sky_margin_px));
  Jacobi jr;
  const double target = std::max(res.margin_residual, 1e-300);
  const Timing tj = measure([&] { jr = jacobi(res, target, cap, sweeps); }, std::min(runs, 3));

  auto ms = [](const Timing& t) {
    char b[96];
    std::snprintf(b, sizeof b, "%.1f (%.1f..%.1f)", t.median, t.lo, t.hi);
    return std::string(b);
  };
  std::printf("| machine | %s |\n|---|---|\n", machine().c_str());
  std::printf("| threads | %d (OpenMP; OpenCV %d) |\n", nt, cv::getNumThreads());
  std::printf("| size | %dx%d, known %.1f%%, %zu holes (%zu px), sky %zu px |\n", W, H, 100 * res.known_fraction,
              res.holes, res.hole_pixels, res.sky_pixels);
  std::printf("| margin | mu = %g px, %zu pixels |\n\n", p.sky_margin_px, res.margin_pixels);
  std::printf("| case | time [ms], median (min..max) | iterations | residual max|Lap|/S_max |\n|---|---|---|---|\n");
  std::printf("| prepare_range, whole (%d runs) | %s | %d CG | %.3g |\n", runs, ms(tp).c_str(), res.solver_iterations,
              res.margin_residual);
  std::printf("| of which cv::connectedComponentsWithStats (alone) | %s | | |\n", ms(tcc).c_str());
  std::printf("| of which cv::distanceTransform precise, full frame (alone) | %s | | |\n", ms(tdt).c_str());
  std::printf("| Jacobi from S_max to the same residual, margin solve only | %s | %d%s | %.3g |\n", ms(tj).c_str(),
              jr.iterations, jr.capped ? " (CAPPED)" : "", jr.residual);
  std::printf("| Jacobi, paper's 2 mu = %d sweeps | | %d | %.3g |\n", sweeps, sweeps, jr.residual_2mu);
  return 0;
}
