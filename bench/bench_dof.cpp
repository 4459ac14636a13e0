// brume benchmark — `brume dof` as the library runs it (apply_dof: scale map
// from the CoC, foreground rule, diffusion) on the demo scene at 1024x768,
// CoC up to sigma = 20 px, the default invariant-exact scheme against the
// paper's eq. 16 (`bertalmio`, N = 2 sigma^2 = 798 iterations) and its
// symmetric form (`standard`), same image, same run, interleaved rounds (one
// warm-up round first) so that a busy host slows all alike; each figure is
// the median (min..max) of its rounds. Issue #55's target (item 6): default
// >= 30x faster than bertalmio (issue #13's was 15x).
//
// Usage: brume_bench_dof [ROUNDS] [map|map-reference|invariant-exact|bertalmio|standard|leaky]   (one part alone, below)
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/dof.hpp"
#include "effects/dof/dof_map.hpp"

using namespace brume;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::max(1, std::atoi(argv[1])) : 3;
  const int W = 1024, H = 768;
  const DemoScene s = render_demo_scene(W, H);
  // Planar depth from the demo's range: fy from its vertical field of view.
  Intrinsics k;
  k.fy = k.fx = 0.5 * H / std::tan(0.5 * s.fov_y_deg * M_PI / 180.0);
  k = resolve(k, W, H);
  const Image z = planar_depth(s.range, k);

  DofParams p;
  p.focus_distance_m = 6.0;  // the ball; the far field tends to alpha
  // sigma_max = 20 px at infinity: c = alpha, (alpha/4)^2 = 20^2 - 1.
  p.coc_infinity_px = 4.0 * std::sqrt(399.0);
  p.coc_limit_px = 20.0;  // near pixels (Z < Zf/2) would exceed it: capped at 20 px

  // One part alone, for a profiler or for CPU-time differencing on a busy
  // host (`time` of ROUNDS = 1 and 11: the difference / 10 is one call's CPU
  // time, start-up and the scene render cancel): the scale map (on the
  // vector rows; map-reference: the scalar loops they replace, the same
  // bits), or a scheme's whole apply.
  const std::string only = argc > 2 ? argv[2] : "";
  if (!only.empty()) {
    const bool reference = only == "map-reference", map = only == "map" || reference;
    if (!map) p.scheme = parse_enum(dof_scheme_names(), only, "brume_bench_dof PART");
    std::vector<double> tm;
    for (int r = 0; r <= rounds; ++r) {
      DofAnalysis a;
      const auto t0 = Clock::now();
      if (map) detail::dof_scale_map_rows(z, p, a, Exec{}, !reference);
      else apply_dof(s.rgb, z, p, a);
      if (r > 0) tm.push_back(ms_since(t0));
    }
    const bench::Spread m = bench::spread(tm);
    std::printf("%s: %.1f ms (%.1f..%.1f)\n", only.c_str(), m.median, m.lo, m.hi);
    return 0;
  }
  const DofScheme schemes[] = {DofScheme::invariant_exact, DofScheme::bertalmio, DofScheme::standard};
  std::vector<double> t[3], tmap;
  int iters[3] = {0, 0, 0};
  for (int r = 0; r <= rounds; ++r)
    for (int i = 0; i < 3; ++i) {
      p.scheme = schemes[i];
      DofAnalysis a;
      const auto t0 = Clock::now();
      const DofResult out = apply_dof(s.rgb, z, p, a);
      const double ms = ms_since(t0);
      iters[i] = a.plan.iterations;
      if (r > 0) t[i].push_back(ms);  // round 0 is the warm-up
      if (out.rgb.data.empty()) return 1;
      if (i == 0 && r > 0) {  // the scale map alone (CoC, cap, foreground rule), shared by every scheme
        const auto t1 = Clock::now();
        dof_scale_map(z, p, a);
        tmap.push_back(ms_since(t1));
      }
    }
  std::printf("brume_bench_dof: %dx%d demo scene, sigma_max 20 px, %s, %d threads, %d rounds (median, min..max)\n", W,
              H, bench::cpu_name().c_str(), omp_get_max_threads(), rounds);
  const bench::Spread d = bench::spread(t[0]), m = bench::spread(tmap);
  std::printf("  scale map (CoC, cap, foreground rule): %.1f ms (%.1f..%.1f), in every scheme's time\n", m.median, m.lo,
              m.hi);
  for (int i = 0; i < 3; ++i) {
    const bench::Spread x = bench::spread(t[i]);
    std::printf("  %-16s %5d iterations  %9.1f ms (%.1f..%.1f)  %6.1fx the default's time\n",
                to_string(schemes[i]).c_str(), iters[i], x.median, x.lo, x.hi, x.median / d.median);
  }
  return 0;
}
