// brume benchmark — rain (issue #56's speed targets), on one thread:
//   lidar:  lidar_rain on KITTI object 000001's scan (~120 k points, read from
//           ../shared/data; a synthetic scan of its size when absent), reading
//           and writing left out, against the same build's beam-by-beam search
//           (each beam's cone cells enumerated and their drops tested: the
//           algorithm before the cell-major pass, src/effects/rain/rain_internal.hpp),
//           interleaved (each round runs both, in alternating order, so that a
//           busy host slows both alike); the outputs and labels of the two are
//           compared byte for byte in every round. Target: <= 20 ms a scan on one core.
//   camera: render_camera_rain at 1242x375 (the demo scene's range and colour
//           at KITTI's size, KITTI's focal length 721.5 px), 25 mm/h, 1/60 s, on
//           2 threads, against the same call at rate 0 (the no-op: the analytic
//           pass and composite alone), interleaved, with the image's hash
//           (bench_camera.hpp). Target: <= 100 ms beyond the no-op.
//   splat:  the streaks' splat alone on the same scene (the drops drawn once, at each rate), the
//           CPU's splat_streaks on 2 threads against the GPU's (GpuStreakSplatter, issue #56 item
//           2: bin on the CPU, upload, the rain.splat pass, read back), interleaved, each stage
//           timed (the pass by timer queries where the driver has them), the GPU's image against
//           the CPU's (max |difference|); where no GPU context can be made, the CPU's alone and
//           the reason. On llvmpipe (Mesa's software rasteriser) the GPU's times say nothing
//           about a GPU: bench/nvidia_visit.sh runs this mode on one.
// Each figure: median [min..max] over the rounds, wall time and CPU time (the
// calling thread's for the LiDAR, the process's for the camera); the CPU (family, model), the SIMD level Highway picks (the
// rain code itself is scalar, built for the x86-64 baseline) and the load
// average at the start and the end are printed.
//
// Usage: brume_bench_rain [ROUNDS] [lidar|lidar-alone|camera|splat] [RATE ...] [epsilon=E] (the camera's thinning ε)
// (lidar-alone: the cell-major pass only, for profiling)
#include <omp.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "bench_camera.hpp"
#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/gpu_context.hpp"
#include "brume/rain.hpp"
#include "core/simd.hpp"
#include "effects/rain/rain_gpu.hpp"
#include "effects/rain/rain_internal.hpp"

using namespace brume;

namespace {

using Clock = std::chrono::steady_clock;

double thread_ms() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

std::string load() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

struct Timing {
  double wall, cpu;
};

template <class F>
Timing timed(F&& f) {
  const double c0 = thread_ms();
  const auto a = Clock::now();
  f();
  return {std::chrono::duration<double, std::milli>(Clock::now() - a).count(), thread_ms() - c0};
}

void print_spread(const char* what, const std::vector<double>& v) {
  const bench::Spread s = bench::spread(v);
  std::printf(" %s %.1f [%.1f..%.1f]", what, s.median, s.lo, s.hi);
}

int lidar(int rounds, const std::vector<double>& rates, bool alone) {
  const std::string file = std::string(BRUME_DATA_DIR) + "/kitti_object_000001/velodyne/000001.bin";
  const bool have = std::filesystem::exists(file);
  if (!have) std::printf("  (%s is absent: a synthetic scan of its size instead)\n", file.c_str());
  const std::vector<float> scan = have ? read_kitti_bin(file, "--points") : bench::synthetic_scan(120268);
  const std::size_t n = scan.size() / 4;
  std::printf(" lidar rain, %s (%zu points), one thread, ms (wall; thread CPU):\n", have ? "KITTI 000001" : "synthetic",
              n);
  int bad = 0;
  for (const double rate : rates) {
    LidarRainParams p;
    p.drops.rate_mm_h = rate;
    std::vector<float> a(scan.size()), b(scan.size());
    std::vector<std::uint8_t> la(n), lb(n);
    std::vector<double> wa, ca, wb, cb, ratio;
    LidarRainStats st;
    for (int r = 0; r < rounds; ++r) {
      Timing ta{}, tb{};
      ScanRun rb;
      for (int k = 0; k < 2; ++k) {
        if ((k == 0) == (r % 2 == 0)) {
          ta = timed([&] { st = lidar_rain(scan.data(), a.data(), n, p, la.data()); });
        } else if (!alone) {
          const std::unique_ptr<Medium> m = lidar_rain_as_medium_searching(p, LidarRainSearch::by_beam);
          const ScanDetection det{p.noise_floor, p.seed};
          tb = timed([&] { rb = scan_through_media({m.get()}, scan.data(), b.data(), n, "scan", &det, lb.data()); });
        }
      }
      if (alone) {
        wa.push_back(ta.wall), ca.push_back(ta.cpu);
        continue;
      }
      const bool same = rb.lost == st.run.lost && la == lb &&
                        std::memcmp(a.data(), b.data(), 16 * (n - st.run.lost)) == 0;
      if (!same) ++bad, std::printf("  ** %g mm/h, round %d: the cell-major output differs from the beam-by-beam one\n", rate, r);
      wa.push_back(ta.wall), ca.push_back(ta.cpu), wb.push_back(tb.wall), cb.push_back(tb.cpu);
      ratio.push_back(tb.cpu / ta.cpu);
    }
    std::printf("  %5g mm/h: cell-major", rate);
    print_spread("wall", wa);
    print_spread("cpu", ca);
    if (alone) {
      std::printf(" (%zu moved, %zu lost, %zu drops drawn)\n", st.run.echoes, st.run.lost, st.drops_drawn);
      continue;
    }
    std::printf(" | beam by beam");
    print_spread("wall", wb);
    print_spread("cpu", cb);
    const bench::Spread q = bench::spread(ratio);
    std::printf(" | %.0fx [%.0f..%.0f] (cpu); %zu moved, %zu lost, %zu drops drawn; outputs %s\n", q.median, q.lo, q.hi,
                st.run.echoes, st.run.lost, st.drops_drawn, bad ? "DIFFER" : "identical");
  }
  return bad;
}

int camera(int rounds, const std::vector<double>& rates, double epsilon) {
  bench::camera_rates<CameraRainParams, CameraRainStats>(
      "rain", rounds, rates, epsilon, [](CameraRainParams& p, double rate) { p.drops.rate_mm_h = rate; },
      [](const CameraRainScene& sc, const CameraRainParams& p, const Exec& ex, CameraRainStats* st) {
        return render_camera_rain(sc, p, ex, st);
      },
      [](const CameraRainStats& st) {
        return std::to_string(st.cells) + " cells, " + std::to_string(st.drops_seen) + " drops seen, " +
               std::to_string(st.drops_drawn) + " drawn";
      });
  return 0;
}

// The splat alone: CPU against GPU on the same drawn streaks and background (the scene through
// the analytic media, rendered once with the splat made a no-op by taking the streaks out).
int splat(int rounds, const std::vector<double>& rates, double epsilon) {
  DemoScene d;
  CameraRainScene sc = bench::kitti_sized_demo(d);
  const int W = sc.rgb.width(), H = sc.rgb.height();
  const StreakCamera cam{W, H, sc.k.fx, sc.k.fy, sc.k.cx, sc.k.cy};
  std::unique_ptr<GpuContext> ctx;
  try {
    ctx = std::make_unique<GpuContext>();
  } catch (const Error& e) {
    std::printf("  (no GPU context: %s; the CPU's splat alone)\n", e.what());
  }
  std::printf(" the splat alone, the demo scene at %dx%d (fx %.1f px), 1/60 s; CPU: 2 threads; GPU: %s; ms:\n", W, H,
              sc.k.fx, ctx ? (ctx->info().renderer + ", " + ctx->info().version).c_str() : "none");
  if (ctx && ctx->info().software)
    std::printf("  (a software renderer: its times are a sanity figure only and say nothing about a GPU)\n");
  Exec ex;
  ex.threads = 2;
  int bad = 0;
  for (const double rate : rates) {
    CameraRainParams p;
    p.drops.rate_mm_h = rate;
    if (epsilon >= 0.0) p.epsilon = epsilon;
    StreakSlabs slabs;
    CameraRainStats st;
    (void)render_camera_rain_drawn(sc, p, ex, &st, nullptr, &slabs);
    CameraRainParams none = p;
    none.drops.rate_mm_h = 0.0;
    const Image base = render_camera_rain(sc, none, ex);  // a background of the same kind
    StreakSplatTiming tm;
    std::optional<GpuStreakSplatter> gs;
    if (ctx) gs.emplace(*ctx, tm);
    std::vector<double> cpu_ms, gpu_ms, bin, up, pass, back;
    Image a, b;
    std::size_t clamped[2] = {0, 0};
    for (int r = 0; r <= rounds; ++r) {  // round 0 warms up (the pass compiles)
      for (int k = 0; k < 2; ++k) {
        const bool gpu = (k == 0) == (r % 2 == 0);
        if (gpu && !gs) continue;
        Image im = base;
        const auto t0 = Clock::now();
        const StreakSplat s = gpu ? gs->splat(slabs, sc.range, im, cam, ex.threads)
                                  : splat_streaks(slabs, sc.range, im, cam, ex.threads);
        const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
        clamped[gpu] = s.alpha_clamped;
        if (r == 0) continue;
        (gpu ? gpu_ms : cpu_ms).push_back(ms);
        if (gpu) bin.push_back(tm.bin_ms), up.push_back(tm.upload_ms), pass.push_back(tm.splat_ms),
            back.push_back(tm.readback_ms);
        (gpu ? b : a) = std::move(im);
      }
    }
    std::printf("  %5g mm/h: %zu streaks; CPU", rate, st.drops_drawn);
    print_spread("", cpu_ms);
    if (gs) {
      double max_diff = 0.0;
      for (std::size_t i = 0; i < a.data.size(); ++i)
        max_diff = std::max(max_diff, static_cast<double>(std::abs(a.data[i] - b.data[i])));
      const std::string pass_what = std::string("+ pass (") + (tm.gpu_timer ? "timer query)" : "wall)");
      const std::pair<const char*, const std::vector<double>*> parts[] = {
          {"| GPU", &gpu_ms}, {"= bin+pack", &bin}, {"+ upload", &up}, {pass_what.c_str(), &pass}, {"+ read back", &back}};
      for (const auto& [what, v] : parts) print_spread(what, *v);
      std::printf(" | %zu list entries; clamped %zu (CPU %zu); max |GPU - CPU| %.3g", tm.list_entries, clamped[1],
                  clamped[0], max_diff);
      if (!(max_diff <= 1e-4)) ++bad, std::printf(" ** beyond the test's bound, 1e-4");
    }
    std::printf("\n");
  }
  return bad;
}

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::max(1, std::atoi(argv[1])) : 5;
  const std::string only = argc > 2 ? argv[2] : "";
  double epsilon = -1.0;
  std::vector<double> rates = bench::rates_from(argc, argv, 3, epsilon);
  if (rates.empty()) rates = {5.0, 25.0, 100.0};
  const std::vector<std::int64_t> t = simd::targets();
  std::printf("brume rain benchmark: %s, Highway target %s (rain: scalar, x86-64 baseline), %d interleaved rounds; "
              "load average %s\n",
              bench::cpu_name().c_str(), t.empty() ? "none" : simd::target_name(t.front()).c_str(), rounds,
              load().c_str());
  int bad = 0;
  if (only.empty() || only == "lidar" || only == "lidar-alone") bad += lidar(rounds, rates, only == "lidar-alone");
  if (only.empty() || only == "camera") bad += camera(rounds, only.empty() ? std::vector<double>{25.0} : rates, epsilon);
  if (only == "splat") bad += splat(rounds, rates, epsilon);
  std::printf(" load average at the end %s\n", load().c_str());
  return bad ? 1 : 0;
}
