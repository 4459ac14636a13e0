// brume benchmarks — the camera pass rain and snow share (src/effects/rain/streaks.hpp; issues
// #56 and #58): the demo scene at KITTI's size and focal length, and the effect against the same
// call at rate 0 (the no-op: the analytic pass and composite alone), interleaved (each round runs
// both, in alternating order, so that a busy host slows both alike). Each figure: median
// [min..max] over the rounds of the wall time and of the process's CPU time (all threads); the
// output's hash (FNV-1a over its floats' bytes) is printed, so that two builds' images can be
// compared bit for bit from their benches' lines.
#pragma once

#include <time.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/image.hpp"
#include "brume/rain.hpp"

namespace brume::bench {

// The demo scene rendered at 1242x375 (KITTI object's image size) seen with KITTI 000001's
// camera 2 focal length (calib P2, 721.5 px); `demo` keeps the images the scene views.
inline CameraRainScene kitti_sized_demo(DemoScene& demo) {
  const int W = 1242, H = 375;
  demo = render_demo_scene(W, H);
  CameraRainScene sc;
  sc.rgb = demo.rgb;
  sc.range = demo.range;
  sc.k.fx = sc.k.fy = 721.5377;
  sc.k = resolve(sc.k, W, H);
  sc.airlight = {0.7f, 0.72f, 0.75f};
  return sc;
}

// FNV-1a over an image's float bytes.
inline std::uint64_t image_hash(const Image& im) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  const auto* b = reinterpret_cast<const unsigned char*>(im.data.data());
  for (std::size_t i = 0; i < im.data.size() * sizeof(float); ++i) h = (h ^ b[i]) * 0x100000001b3ull;
  return h;
}

inline double process_cpu_ms() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

// `effect` against `noop`, interleaved over `rounds` (and a warm-up round); `effect` returns its
// image (hashed) and `counts` describes its last run. Prints one line headed `label`.
inline void camera_against_noop(const std::string& label, int rounds, const std::function<Image()>& effect,
                                const std::function<Image()>& noop, const std::function<std::string()>& counts) {
  std::vector<double> wa, ca, wb, cb, extra, extra_cpu;
  std::uint64_t hash = 0;
  for (int r = 0; r <= rounds; ++r) {  // round 0 warms up
    double w[2] = {0, 0}, c[2] = {0, 0};
    for (int k = 0; k < 2; ++k) {
      const int which = (k == 0) == (r % 2 == 0) ? 0 : 1;
      const double c0 = process_cpu_ms();
      const auto a = std::chrono::steady_clock::now();
      Image im = which == 0 ? effect() : noop();
      w[which] = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count();
      c[which] = process_cpu_ms() - c0;
      if (which == 0) hash = image_hash(im);  // outside the timing
    }
    if (r == 0) continue;
    wa.push_back(w[0]), ca.push_back(c[0]), wb.push_back(w[1]), cb.push_back(c[1]);
    extra.push_back(w[0] - w[1]), extra_cpu.push_back(c[0] - c[1]);
  }
  const auto put = [](const char* what, const std::vector<double>& v) {
    const Spread s = spread(v);
    std::printf(" %s %.1f [%.1f..%.1f]", what, s.median, s.lo, s.hi);
  };
  std::printf("  %s: wall", label.c_str());
  put("", wa);
  std::printf(" (cpu");
  put("", ca);
  std::printf(") | rate 0 wall");
  put("", wb);
  std::printf(" (cpu");
  put("", cb);
  std::printf(") | beyond it wall");
  put("", extra);
  std::printf(" (cpu");
  put("", extra_cpu);
  std::printf(") | %s; image %016llx\n", counts().c_str(), static_cast<unsigned long long>(hash));
}

// The rates among argv[from..]; an argument epsilon=E sets `epsilon` (the thinning's ε; else left).
inline std::vector<double> rates_from(int argc, char** argv, int from, double& epsilon) {
  std::vector<double> rates;
  for (int i = from; i < argc; ++i) {
    if (std::strncmp(argv[i], "epsilon=", 8) == 0) epsilon = std::atof(argv[i] + 8);
    else rates.push_back(std::atof(argv[i]));
  }
  return rates;
}

// An effect's camera pass (`what`: "rain") at each rate on the scene above, 2 threads, against
// rate 0: P its parameters (the rate set by `set_rate`; `epsilon` >= 0 replaces the thinning's ε),
// `render` the pass (S its counts, told by `counts`).
template <class P, class S>
void camera_rates(const std::string& what, int rounds, const std::vector<double>& rates, double epsilon,
                  const std::function<void(P&, double)>& set_rate,
                  const std::function<Image(const CameraRainScene&, const P&, const Exec&, S*)>& render,
                  const std::function<std::string(const S&)>& counts) {
  DemoScene d;
  const CameraRainScene sc = kitti_sized_demo(d);
  Exec ex;
  ex.threads = 2;
  std::printf(" camera %s, the demo scene at %dx%d (fx %.1f px), 1/60 s, 2 threads, ms (wall; the process's CPU):\n",
              what.c_str(), sc.rgb.width(), sc.rgb.height(), sc.k.fx);
  for (const double rate : rates) {
    P p, none;
    set_rate(p, rate);
    if (epsilon >= 0.0) p.epsilon = epsilon;
    set_rate(none, 0.0);
    S st;
    char label[48];
    std::snprintf(label, sizeof label, "%5g mm/h, epsilon %g", rate, p.epsilon);
    camera_against_noop(
        label, rounds, [&] { return render(sc, p, ex, &st); }, [&] { return render(sc, none, ex, nullptr); },
        [&] { return counts(st); });
  }
}

}  // namespace brume::bench
