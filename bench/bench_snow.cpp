// brume benchmark — snow (brume/snow.hpp, issue #58's speed targets):
//   lidar:  lidar_snow (the footprint model, one thread, reading and writing left out) on KITTI
//           000001's scan (../shared/data; a synthetic wall of its size when absent) at 0.5, 1, 2
//           and 5 mm/h water equivalent. Target: <= 30 ms per 120 k points on one core without a
//           precomputed set.
//   camera: render_camera_snow at 1242x375 (the demo scene at KITTI's size and focal length), 1/60
//           s, 2 threads, against the same call at rate 0, interleaved, with the image's hash
//           (bench_camera.hpp), at 2 mm/h (or the rates given). Target: <= 150 ms on 2 cores.
//
// Usage: brume_bench_snow [ROUNDS] [lidar|camera] [RATE ...] [epsilon=E] (the camera's thinning ε; else its default)
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_camera.hpp"
#include "bench_util.hpp"
#include "brume/depth.hpp"
#include "brume/snow.hpp"
#include "core/simd.hpp"

using namespace brume;

namespace {

std::string simd_target() {
  const std::vector<std::int64_t> t = simd::targets();
  return t.empty() ? "none" : simd::target_name(t.front());
}

void camera(int rounds, const std::vector<double>& rates, double epsilon) {
  bench::camera_rates<CameraSnowParams, CameraSnowStats>(
      "snow", rounds, rates, epsilon, [](CameraSnowParams& p, double rate) { p.flakes.rate_mm_h = rate; },
      [](const CameraRainScene& sc, const CameraSnowParams& p, const Exec& ex, CameraSnowStats* st) {
        return render_camera_snow(sc, p, ex, st);
      },
      [](const CameraSnowStats& st) {
        return std::to_string(st.cells) + " cells, " + std::to_string(st.flakes_seen) + " flakes seen, " +
               std::to_string(st.flakes_drawn) + " drawn";
      });
}

void lidar(int rounds) {
  const std::string bin = std::string(BRUME_DATA_DIR) + "/kitti_object_000001/velodyne/000001.bin";
  std::vector<float> scan;
  if (std::filesystem::exists(bin)) {
    scan = read_kitti_bin(bin, "--points");
  } else {
    std::printf("  (%s is absent: a synthetic wall of its size)\n", bin.c_str());
    for (int i = 0; i < 120268; ++i)
      scan.insert(scan.end(), {20.0f, static_cast<float>(-8.0 + 16.0 * (i % 1000) / 1000.0),
                               static_cast<float>(-2.0 + 4.0 * (i / 1000) / 121.0), 0.5f});
  }
  const std::size_t n = scan.size() / 4;
  std::vector<float> out(scan.size());
  std::vector<std::uint8_t> labels(n);
  for (double rate : {0.5, 1.0, 2.0, 5.0}) {
    LidarSnowParams p;
    p.flakes.rate_mm_h = rate;
    LidarSnowStats st;
    std::vector<double> cpu;
    const bench::Spread t = bench::time_ms(
        [&] {
          timespec a, b;
          clock_gettime(CLOCK_THREAD_CPUTIME_ID, &a);
          st = lidar_snow(scan.data(), out.data(), n, p, labels.data());
          clock_gettime(CLOCK_THREAD_CPUTIME_ID, &b);
          cpu.push_back((b.tv_sec - a.tv_sec) * 1e3 + (b.tv_nsec - a.tv_nsec) * 1e-6);
        },
        rounds);
    cpu.erase(cpu.begin());  // the warm-up
    const bench::Spread c = bench::spread(cpu);
    std::printf("  %4.1f mm/h, %zu points: %zu moved to flakes, %zu lost, %zu flakes drawn  1 thread %7.2f ms "
                "[%.2f..%.2f] wall, %7.2f ms [%.2f..%.2f] of CPU\n",
                rate, n, st.run.echoes, st.run.lost, st.flakes_drawn, t.median, t.lo, t.hi, c.median, c.lo, c.hi);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::max(1, std::atoi(argv[1])) : 15;
  const std::string only = argc > 2 ? argv[2] : "";
  double epsilon = -1.0;
  std::vector<double> rates = bench::rates_from(argc, argv, 3, epsilon);
  std::printf("brume snow benchmark: %s, Highway target %s (snow: scalar, x86-64 baseline), %d rounds (median "
              "[min..max]); load average %s\n",
              bench::cpu_name().c_str(), simd_target().c_str(), rounds, bench::load_average().c_str());
  if (only.empty() || only == "lidar") lidar(rounds);
  if (only.empty() || only == "camera") camera(rounds, rates.empty() ? std::vector<double>{2.0} : rates, epsilon);
  std::printf(" load average at the end %s\n", bench::load_average().c_str());
  return 0;
}
