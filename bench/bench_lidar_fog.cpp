// brume benchmark — the LiDAR fog (homogeneous, brume/lidar_fog.hpp): one
// call of lidar_fog on KITTI object 000001's scan (~120 k points, read from
// ../shared/data; a synthetic scan of the same size when absent) and on a
// 10x larger synthetic scan, the soft table's build included in every call
// (it is built per call); noise on, visibility 50 m; on one thread and on
// two (the points' loop is OpenMP from 2^20 points; the table is serial).
// Target (issue #41): >= 10 M points/s on 2 cores, the KITTI scan in <= 12 ms.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <omp.h>
#include <random>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/lidar_fog.hpp"

using namespace brume;

namespace {

std::vector<float> synthetic(std::size_t n) {
  std::mt19937 g(1);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<float> v(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double az = 6.283185307179586 * u(g), el = (u(g) - 0.8) * 0.45, r = 3.0 + 77.0 * u(g) * u(g);
    v[4 * i] = static_cast<float>(r * std::cos(el) * std::cos(az));
    v[4 * i + 1] = static_cast<float>(r * std::cos(el) * std::sin(az));
    v[4 * i + 2] = static_cast<float>(r * std::sin(el));
    v[4 * i + 3] = static_cast<float>(u(g));
  }
  return v;
}

void report(const char* name, const std::vector<float>& in, const LidarFogParams& p, int runs) {
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  LidarFogStats st;
  const bench::Spread t = bench::time_ms([&] { st = lidar_fog(in.data(), out.data(), n, p); }, runs);
  std::printf("  %-28s %8zu points  %7.3f ms [%.3f..%.3f]  %6.1f M points/s  (table %.3f ms, %.2f %% fog)", name, n,
              t.median, t.lo, t.hi, n / t.median / 1e3, st.table_ms, 100.0 * st.soft / n);
  if (st.tables) std::printf("  %zu tables, %zu nodes", st.tables, st.table_nodes);
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  const int runs = argc > 1 ? std::atoi(argv[1]) : 21;
  const bool layered_only = argc > 2 && std::string(argv[2]) == "layered";
  std::printf("brume lidar fog benchmark: %s, %d runs (median [min..max]), whole call with the table\n",
              bench::cpu_name().c_str(), runs);
  for (int threads : {1, 2}) {
    if (layered_only) break;
    omp_set_num_threads(threads);
    std::printf(" %d thread%s:\n", threads, threads > 1 ? "s" : "");
    LidarFogParams p;
    p.visibility_m = 50.0;
    const std::string kitti = std::string(BRUME_DATA_DIR) + "/kitti_object_000001/velodyne/000001.bin";
    if (std::filesystem::exists(kitti)) {
      report("KITTI 000001", read_kitti_bin(kitti, "--points"), p, runs);
    } else {
      std::printf("  (%s is absent: a synthetic scan of its size instead)\n", kitti.c_str());
      report("synthetic, KITTI's size", synthetic(120268), p, runs);
    }
    report("synthetic, 1.2 M points", synthetic(1202680), p, runs);
    p.visibility_m = 20.0;
    report("synthetic, 1.2 M, V = 20 m", synthetic(1202680), p, runs);
  }
  // Height-layered fog (issue #41 item 3): an exponential ground fog of
  // 0.08/m at the ground (V ~ 50 m there), falling off with B = 0.05/m, the
  // KITTI scan placed by its calibration and camera 2 at 1.65 m; the tables
  // (one an occupied elevation bin) built in every call.
  // Target: >= 2 M points/s on 2 cores (the KITTI scan in <= 60 ms).
  const std::string dir = std::string(BRUME_DATA_DIR) + "/kitti_object_000001";
  LidarFogParams l;
  l.profile = HeightProfile::exponential;
  l.fog.density_per_m = 0.08;
  l.fog.falloff_per_m = 0.05;
  const bool have = std::filesystem::exists(dir + "/velodyne/000001.bin");
  if (have) {
    l.pose.kitti_calib = dir + "/calib/000001.txt";
    l.fog.camera.height_m = 1.65;
  } else {
    l.pose.sensor_height_m = 1.73;
  }
  const std::vector<float> scan = have ? read_kitti_bin(dir + "/velodyne/000001.bin", "--points") : synthetic(120268);
  for (int threads : {1, 2}) {
    omp_set_num_threads(threads);
    std::printf(" height-layered, exponential, %d thread%s:\n", threads, threads > 1 ? "s" : "");
    for (double step : {0.05, 0.1, 0.2}) {
      l.elevation_step_deg = step;
      char name[64];
      std::snprintf(name, sizeof name, "%s, bins %.2f deg", have ? "KITTI 000001" : "synthetic", step);
      report(name, scan, l, runs);
    }
  }
  return 0;
}
