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
// Each figure: median [min..max] over the rounds, wall time and CPU time (the
// calling thread's for the LiDAR, the process's for the camera); the CPU (family, model), the SIMD level Highway picks (the
// rain code itself is scalar, built for the x86-64 baseline) and the load
// average at the start and the end are printed.
//
// Usage: brume_bench_rain [ROUNDS] [lidar|lidar-alone|camera] [RATE ...] [epsilon=E] (the camera's thinning ε)
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
#include <random>
#include <string>
#include <vector>

#include "bench_camera.hpp"
#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/depth.hpp"
#include "brume/rain.hpp"
#include "core/simd.hpp"
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
  std::printf(" load average at the end %s\n", load().c_str());
  return bad ? 1 : 0;
}
