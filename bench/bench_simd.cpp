// brume benchmark — the diffusion's vector kernels alone, on one thread, in
// thread CPU time: what a loaded host can still compare between two builds
// (wall-clock A/B on a shared 2-vCPU host swung 0.3..1.9x between rounds;
// issue #55's Highway port was measured with this, docs/performance.md).
//
// 1600x1120, `brume::diffuse` on one thread: constant sigma 25 and 10 (RGB
// rows, f32), constant sigma 25 in f16 (RGBA, binary16 storage),
// space-variant sigma <= 25 (RGB rows and RGBA; a map varying along rows and
// columns, so rows split into many runs), and 40 iterations of the
// conductance stencil (RGBA, per-edge weights). Each case: one warm-up, then
// REPS calls; the median and the minimum of their thread CPU times (ms),
// one tab-separated line a case.
//
//   brume_bench_simd [--simd avx2] [--reps N]
//
// --simd avx2: the kernels at most at AVX2 on an AVX-512 host (as
// brume_bench_blur --simd). To compare two builds, build this file against
// each build's library (the same source) and run the two alternately.
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/diffusion.hpp"
#include "core/simd.hpp"
#include "diffusion/diffusion_kernels.hpp"

using namespace brume;

namespace {
double thread_ms() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}
}  // namespace

int main(int argc, char** argv) {
  int reps = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--simd" && i + 1 < argc && std::string(argv[i + 1]) == "avx2") {
      ++i;
      cpu::set_diffusion_simd_limit(1);
      for (std::int64_t t : simd::targets())
        if (simd::target_name(t) == "AVX2") simd::force_target(t);
    } else if (a == "--reps" && i + 1 < argc) {
      reps = std::max(1, std::atoi(argv[++i]));
    } else {
      std::fprintf(stderr, "usage: %s [--simd avx2] [--reps N]\n", argv[0]);
      return 2;
    }
  }
  const int W = 1600, H = 1120;
  Image rgb(W, H, 3), rgba(W, H, 4), map(W, H, 1), wx(W, H, 1), wy(W, H, 1);
  for (std::size_t i = 0; i < rgb.data.size(); ++i) rgb.data[i] = static_cast<float>((i * 7919) % 1009) / 1008.0f;
  for (std::size_t i = 0; i < rgba.data.size(); ++i) rgba.data[i] = static_cast<float>((i * 7919) % 1013) / 1012.0f;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      // haze-like: largest at the top, modulated along the row, steps every 97 columns
      const double v = std::pow(1.0 - static_cast<double>(y) / H, 1.5) * (0.75 + 0.25 * std::sin(x / 37.0)) *
                       ((x / 97) % 3 == 0 ? 0.6 : 1.0);
      map.at(x, y) = static_cast<float>(std::max(1.0, 25.0 * v));
      wx.at(x, y) = 0.25f * static_cast<float>((x * 31 + y * 17) % 23) / 22.0f;
      wy.at(x, y) = 0.25f * static_cast<float>((x * 13 + y * 29) % 19) / 18.0f;
    }
  Exec ex;
  ex.threads = 1;
  DiffusionParams f32, f16;
  f16.precision = Precision::f16;
  std::printf("# brume_bench_simd: %s, 1 thread, %d reps; case, median ms, min ms (thread CPU time)\n",
              bench::cpu_name().c_str(), reps);
  auto time = [&](const char* name, auto fn) {
    fn();
    std::vector<double> t;
    for (int r = 0; r < reps; ++r) {
      const double a = thread_ms();
      fn();
      t.push_back(thread_ms() - a);
    }
    std::sort(t.begin(), t.end());
    std::printf("%s\t%.2f\t%.2f\n", name, t[t.size() / 2], t[0]);
  };
  time("constant s25 RGB f32", [&] { Image g = rgb; diffuse(g, 25.0, f32, ex); });
  time("constant s10 RGB f32", [&] { Image g = rgb; diffuse(g, 10.0, f32, ex); });
  time("constant s25 RGBA f16", [&] { Image g = rgba; diffuse(g, 25.0, f16, ex); });
  time("space-variant s<=25 RGB f32", [&] { Image g = rgb; diffuse(g, map, 25.0, f32, ex); });
  time("space-variant s<=25 RGBA f32", [&] { Image g = rgba; diffuse(g, map, 25.0, f32, ex); });
  time("conductance RGBA f32 40 it", [&] { Image g = rgba; diffuse_conductance(g, wx, wy, 40, Precision::f32, ex); });
  return 0;
}
