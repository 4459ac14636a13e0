// brume benchmark — the LiDAR fog (brume/lidar_fog.hpp), homogeneous and
// height-layered: one call of lidar_fog, its tables built in every call (they
// are built per call), noise on, on one thread and on two, interleaved (each
// round runs both, in alternating order, so that a busy host slows both
// alike); the ratio is one thread's time over two threads' in the same round.
// Scans: KITTI object 000001 (~120 k points, read from ../shared/data; a
// synthetic scan of the same size when absent) and 1.2 M points: for the
// homogeneous fog a synthetic scan (uniform azimuth, ranges 3..80 m), for the
// layered fog KITTI's scan ten times, each copy's points moved by up to 1 cm
// (the layered fog needs the scan's calibration; a synthetic scan at 1.73 m
// when KITTI is absent).
// Targets: issue #41, >= 10 M points/s (homogeneous) and >= 2 M points/s
// (layered) on 2 cores; issue #55 item 5, two threads >= 1.5x one thread on
// 1.2 M points and never slower than one thread on a KITTI scan.
//
// Usage: brume_bench_lidar_fog [ROUNDS] [homogeneous|layered|sizes]
// (sizes: synthetic scans of 2^16..2^21 points, where one thread ends)
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/lidar_fog.hpp"

using namespace brume;

namespace {

using Clock = std::chrono::steady_clock;

// `copies` copies of a scan, each point of each copy after the first moved
// by up to 1 cm on each axis.
std::vector<float> replicated(const std::vector<float>& scan, int copies) {
  std::mt19937 g(2);
  std::uniform_real_distribution<float> u(-0.01f, 0.01f);
  std::vector<float> v;
  v.reserve(scan.size() * static_cast<std::size_t>(copies));
  for (int c = 0; c < copies; ++c)
    for (std::size_t i = 0; i < scan.size(); ++i) v.push_back(scan[i] + (c > 0 && i % 4 != 3 ? u(g) : 0.0f));
  return v;
}

std::string load() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

void report(const char* name, const std::vector<float>& in, const LidarFogParams& p, int rounds) {
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  LidarFogStats st;
  std::vector<double> t[2], ratio;
  for (int r = 0; r <= rounds; ++r) {  // round 0 warms up
    double ms[2];
    for (int k = 0; k < 2; ++k) {
      const int i = (r % 2) ? 1 - k : k;  // 1, 2 threads, then 2, 1
      omp_set_num_threads(i + 1);
      const auto a = Clock::now();
      st = lidar_fog(in.data(), out.data(), n, p);
      ms[i] = std::chrono::duration<double, std::milli>(Clock::now() - a).count();
    }
    if (r == 0) continue;
    t[0].push_back(ms[0]), t[1].push_back(ms[1]), ratio.push_back(ms[0] / ms[1]);
  }
  const bench::Spread a = bench::spread(t[0]), b = bench::spread(t[1]), q = bench::spread(ratio);
  std::printf("  %-28s %8zu points  1 thread %7.2f ms [%.2f..%.2f]  2 threads %7.2f ms [%.2f..%.2f]  "
              "1/2: %.2fx [%.2f..%.2f]  (%.1f M points/s on 2; %.2f %% fog",
              name, n, a.median, a.lo, a.hi, b.median, b.lo, b.hi, q.median, q.lo, q.hi, n / b.median / 1e3,
              100.0 * st.soft / n);
  if (st.tables) std::printf(", %zu tables, %zu nodes", st.tables, st.table_nodes);
  std::printf(")\n");
}

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::max(1, std::atoi(argv[1])) : 21;
  const std::string only = argc > 2 ? argv[2] : "";
  std::printf("brume lidar fog benchmark: %s, %d interleaved rounds of 1 and 2 threads (median [min..max]), whole "
              "call with the tables; load average %s\n",
              bench::cpu_name().c_str(), rounds, load().c_str());
  const std::string dir = std::string(BRUME_DATA_DIR) + "/kitti_object_000001";
  const bool have = std::filesystem::exists(dir + "/velodyne/000001.bin");
  if (!have) std::printf("  (%s is absent: synthetic scans of its size instead)\n", dir.c_str());
  const std::vector<float> scan = have ? read_kitti_bin(dir + "/velodyne/000001.bin", "--points") : bench::synthetic_scan(120268);
  const char* kitti = have ? "KITTI 000001" : "synthetic, KITTI's size";
  if (only == "sizes") {  // where one thread ends: synthetic scans from 2^16 to 2^21 points
    LidarFogParams p, l;
    p.visibility_m = 50.0;
    l.profile = HeightProfile::exponential;
    l.fog.density_per_m = 0.08;
    l.fog.falloff_per_m = 0.05;
    l.pose.sensor_height_m = 1.73;
    for (int e = 16; e <= 21; ++e) {
      const std::vector<float> v = bench::synthetic_scan(std::size_t{1} << e);
      char name[64];
      std::snprintf(name, sizeof name, "homogeneous, 2^%d", e);
      report(name, v, p, rounds);
      std::snprintf(name, sizeof name, "layered, 2^%d", e);
      report(name, v, l, rounds);
    }
    std::printf(" load average at the end %s\n", load().c_str());
    return 0;
  }
  if (only != "layered") {
    std::printf(" homogeneous, visibility 50 m (20 m in the last row):\n");
    LidarFogParams p;
    p.visibility_m = 50.0;
    report(kitti, scan, p, rounds);
    const std::vector<float> big = bench::synthetic_scan(1202680);
    report("synthetic, 1.2 M points", big, p, rounds);
    p.visibility_m = 20.0;
    report("synthetic, 1.2 M, V = 20 m", big, p, rounds);
  }
  if (only == "homogeneous") return 0;
  // Height-layered fog (issue #41 item 3): an exponential ground fog of
  // 0.08/m at the ground (V ~ 50 m there), falling off with B = 0.05/m, the
  // KITTI scan placed by its calibration and camera 2 at 1.65 m; the tables
  // (one an occupied elevation bin) built in every call.
  LidarFogParams l;
  l.profile = HeightProfile::exponential;
  l.fog.density_per_m = 0.08;
  l.fog.falloff_per_m = 0.05;
  if (have) {
    l.pose.kitti_calib = dir + "/calib/000001.txt";
    l.fog.camera.height_m = 1.65;
  } else {
    l.pose.sensor_height_m = 1.73;
  }
  std::printf(" height-layered, exponential:\n");
  for (double step : {0.05, 0.1, 0.2}) {
    l.elevation_step_deg = step;
    char name[64];
    std::snprintf(name, sizeof name, "%s, bins %.2f deg", have ? "KITTI 000001" : "synthetic", step);
    report(name, scan, l, rounds);
  }
  l.elevation_step_deg = 0.1;
  report(have ? "KITTI x10 (1 cm), bins 0.10" : "synthetic x10, bins 0.10", replicated(scan, 10), l, rounds);
  std::printf(" load average at the end %s\n", load().c_str());
  return 0;
}
