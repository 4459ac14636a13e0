// brume benchmark — the haze pipeline on the GPU backend against the CPU
// backend, side by side on the same machine (issue #4).
//
// Full haze (premultiply, rates, N diffusion passes, composite: N + 3
// passes) on the built-in demo
// scene, sigma_max = 25 px (kappa_s' = 1, lambda = 24), schemes
// invariant-exact (f32, f16) and standard (f32, at sigma_max = 10 on software
// renderers, where 1248 passes would take minutes). GPU time: timer queries
// where the driver has them (checked against glFinish wall time), else wall
// time. "re-render" is a render after a parameter change on the same
// uploaded inputs. Median of --runs after a warm-up. Markdown on stdout.
//
//   brume_bench_gpu [--runs N] [--size WxH ...] [--threads N]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/gpu.hpp"
#include "brume/haze.hpp"

using namespace brume;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  int runs = 3, threads = 0;
  std::vector<std::pair<int, int>> sizes;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--runs" && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--size" && i + 1 < argc) {
      int w = 0, h = 0;
      if (std::sscanf(argv[++i], "%dx%d", &w, &h) == 2) sizes.emplace_back(w, h);
    } else {
      std::fprintf(stderr, "usage: %s [--runs N] [--size WxH ...] [--threads N]\n", argv[0]);
      return 2;
    }
  }
  if (sizes.empty()) sizes = {{1600, 1120}};
  GpuContext ctx;  // throws with the reason when there is none
  std::printf("# brume_bench_gpu\n\n- GPU: %s (%s, EGL %s platform)\n- runs: median of %d after a warm-up\n\n",
              ctx.info().renderer.c_str(), ctx.info().version.c_str(), ctx.info().platform.c_str(), runs);
  std::printf("| size | scheme | precision | sigma_max px | passes | GPU premultiply+diffusion+composite ms | per pass ms | re-render ms | timer | CPU backend ms |\n");
  std::printf("|---|---|---|---:|---:|---:|---:|---:|---|---:|\n");
  const bool software = ctx.info().software;
  for (auto [w, h] : sizes) {
    DemoScene scene = render_demo_scene(w, h);
    struct Case {
      Scheme s;
      Precision p;
      double lambda;
    };
    std::vector<Case> cases = {{Scheme::invariant_exact, Precision::f32, 24.0}, {Scheme::invariant_exact, Precision::f16, 24.0},
                               {Scheme::invariant, Precision::f32, 24.0},
                               {Scheme::standard, Precision::f32, software ? 9.0 : 24.0}};
    GpuHaze gh(ctx, scene.rgb, scene.range);
    for (const Case& c : cases) {
      HazeParams p;
      p.kappa_s = 1.0;
      p.lambda = c.lambda;
      p.diffusion.scheme = c.s;
      p.diffusion.precision = c.p;
      HazeAnalysis a = analyse_haze(scene.rgb, scene.range, p);
      std::vector<double> gpu_ms, rerender_ms, cpu_ms;
      bool timer = true;
      for (int r = 0; r <= runs; ++r) {
        gh.render(p, a);
        const GpuTiming& t = gh.timing();
        timer = timer && t.gpu_timer;
        if (r > 0) gpu_ms.push_back(t.premultiply_ms + t.diffuse_ms + t.composite_ms);
      }
      // Re-render after a parameter change: same inputs, new kappa_s.
      HazeParams q = p;
      q.kappa_s = 0.9;
      HazeAnalysis qa = analyse_haze(scene.rgb, scene.range, q);
      for (int r = 0; r < runs; ++r) {
        const auto t0 = Clock::now();
        gh.render(r % 2 ? p : q, r % 2 ? a : qa);
        rerender_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
      Exec ex;
      ex.threads = threads;
      for (int r = 0; r <= runs; ++r) {
        const auto t0 = Clock::now();
        apply_haze(scene.rgb, scene.range, p, a, ex);
        if (r > 0) cpu_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
      const double g = bench::spread(gpu_ms).median;
      std::printf("| %dx%d | %s | %s | %.1f | %d | %.2f | %.3f | %.1f | %s | %.1f |\n", w, h, to_string(c.s).c_str(),
                  to_string(c.p).c_str(), a.sigma_max, a.plan.iterations + 3, g, g / (a.plan.iterations + 3),
                  bench::spread(rerender_ms).median, timer ? "query" : "wall", bench::spread(cpu_ms).median);
      std::fflush(stdout);
    }
  }
  return 0;
}
