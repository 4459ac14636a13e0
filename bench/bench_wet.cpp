// brume benchmark — wet ground (brume/wet.hpp, issue #57): the camera's pass (render_wet: the
// ground test, the darkening and the mirror march) on the demo scene at KITTI's size
// (1242x375; the tests' scene, tests/wet_demo.hpp: camera 1.6 m up, 5 deg down, the demo's
// vertical field of view, a ground tolerance of 2 cm) and on KITTI 000001 as `brume wet
// --velodyne` sees it (completed, camera 1.65 m up; ../shared/data), on one thread and
// on two, interleaved (each round runs all, in a turning order, so that a busy host slows
// all alike). And the LiDAR's pass
// (lidar_wet, one thread) on KITTI 000001's scan (../shared/data; a synthetic ground of its
// size when absent).
// Targets: issue #57, the camera <= 30 ms at 1242x375 on 2 cores; the LiDAR <= 5 ms per 120 k points.
// The camera runs both mirror marches (WetMarch), interleaved: their ratio is the default's speed-up.
//
// The output's bits are hashed (FNV-1a over the floats' bytes, each thread count): two builds that
// print the same hash wrote the same image (how a speed-up is checked to change no bit).
//
// Usage: brume_bench_wet [ROUNDS]
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/range_step.hpp"
#include "brume/wet.hpp"
#include "wet_demo.hpp"

using namespace brume;
using Clock = std::chrono::steady_clock;

namespace {

std::string load() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

std::uint64_t fnv1a(const Image& im) {
  std::uint64_t h = 14695981039346656037ull;
  for (const float v : im.data) {
    std::uint32_t b;
    std::memcpy(&b, &v, 4);
    for (int k = 0; k < 4; ++k) h = (h ^ ((b >> (8 * k)) & 0xffu)) * 1099511628211ull;
  }
  return h;
}

// The camera's pass on one scene: both marches (WetMarch: blocks asks every pixel, records before
// --mirror-march; above-ground, the default), each on one thread and on two, four runs a round in
// an order that turns each round; medians, the phases' times and the output's hash.
void bench_camera(const char* name, WetScene s, const WetFilm& w, int rounds) {
  const WetMarch marches[2] = {WetMarch::blocks, WetMarch::above_ground};
  std::vector<double> t[2][2], maps[2][2], march[2][2], speedup[2];
  std::uint64_t hash[2][2] = {};
  WetStats st[2];
  for (int r = 0; r <= rounds; ++r) {  // round 0 warms up
    double ms[2][2];
    for (int k = 0; k < 4; ++k) {
      const int j = (k + r) % 4, m = j / 2, i = j % 2;
      Exec e;
      e.threads = i + 1;
      s.march = marches[m];
      const auto a = Clock::now();
      const Image out = render_wet(s, w, e, &st[m]);
      ms[m][i] = std::chrono::duration<double, std::milli>(Clock::now() - a).count();
      if (r == 0) hash[m][i] = fnv1a(out);
      if (r > 0) maps[m][i].push_back(st[m].maps_ms), march[m][i].push_back(st[m].march_ms);
    }
    if (r == 0) continue;
    for (int m = 0; m < 2; ++m)
      for (int i = 0; i < 2; ++i) t[m][i].push_back(ms[m][i]);
    for (int i = 0; i < 2; ++i) speedup[i].push_back(ms[0][i] / ms[1][i]);
  }
  for (int m = 0; m < 2; ++m) {
    const bench::Spread a = bench::spread(t[m][0]), b = bench::spread(t[m][1]);
    std::printf("  camera, %s, --mirror-march %s (%zu ground px: %zu hits, %zu sky, %zu leave)  1 thread "
                "%7.2f ms [%.2f..%.2f]  2 threads %7.2f ms [%.2f..%.2f]\n",
                name, enum_name(wet_march_names(), marches[m]).c_str(), st[m].ground, st[m].hits, st[m].sky_pixels,
                st[m].left_frame, a.median, a.lo, a.hi, b.median, b.lo, b.hi);
    for (int i = 0; i < 2; ++i)
      std::printf("    %d thread%s: depth map and pyramids %.2f ms, ground and march %.2f ms (medians); output hash "
                  "%016llx\n",
                  i + 1, i ? "s" : " ", bench::spread(maps[m][i]).median, bench::spread(march[m][i]).median,
                  static_cast<unsigned long long>(hash[m][i]));
  }
  for (int i = 0; i < 2; ++i) {
    const bench::Spread q = bench::spread(speedup[i]);
    std::printf("  blocks / above-ground, %d thread%s: %.2fx [%.2f..%.2f]\n", i + 1, i ? "s" : "", q.median, q.lo,
                q.hi);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::max(1, std::atoi(argv[1])) : 15;
  std::printf("brume wet benchmark: %s, %d interleaved rounds (median [min..max]); load average %s\n",
              bench::cpu_name().c_str(), rounds, load().c_str());
  const int W = 1242, H = 375;
  const DemoScene d = render_demo_scene(W, H);
  WetFilm w;
  w.film_mm = 1.5;
  bench_camera("demo 1242x375", test::demo_wet_scene(d, W, H), w, rounds);  // the tests' scene (tests/wet_demo.hpp)

  // KITTI 000001 as `brume wet --image .. --velodyne .. --kitti-calib .. --camera-height 1.65 --film 1`
  // sees it (wet_pipeline.cpp's run_camera_wet): the scan projected and completed, haze's airlight,
  // the range prepared; issue #57's target scene.
  const std::string kd = std::string(BRUME_DATA_DIR) + "/kitti_object_000001";
  const std::string kimg = kd + "/image_2/000001.png", bin = kd + "/velodyne/000001.bin",
                    kcal = kd + "/calib/000001.txt";
  if (std::filesystem::exists(kimg) && std::filesystem::exists(bin) && std::filesystem::exists(kcal)) {
    const Image rgb = read_color(kimg);
    DepthSource src;
    src.velodyne = bin, src.kitti_calib = kcal;
    LoadedDepth depth = load_depth(src, rgb.width, rgb.height);
    depth.offset_scan = true;  // a scan from beside the camera (as the pipeline's inputs mark --velodyne)
    const RangeStep step = with_camera(RangeStep{}, depth);
    const CompletedRange done = complete_step(depth.range, rgb, step);
    HazeParams hp;
    hp.kappa_s = 0.0;
    const HazeAnalysis ha = analyse_haze(rgb, done.view(depth.range), hp);
    const PreparedRange prep = prepare_step(done.view(depth.range), step, {}, 0, true);
    CameraPose pose;
    pose.height_m = 1.65;
    WetScene k;
    k.rgb = rgb, k.range = prep.range, k.camera = depth_camera(src, rgb.width, rgb.height, pose), k.sky = ha.airlight;
    WetFilm wk;
    wk.film_mm = 1.0;
    bench_camera("KITTI 000001", k, wk, rounds);
  } else {
    std::printf("  (%s is absent: no KITTI camera run)\n", kd.c_str());
  }

  std::vector<float> scan;
  if (std::filesystem::exists(bin)) {
    scan = read_kitti_bin(bin, "--points");
  } else {
    std::printf("  (%s is absent: a synthetic ground of its size)\n", bin.c_str());
    for (int i = 0; i < 120268; ++i) {
      const double r = 3.0 + 0.0005 * i, az = 0.01 * i;
      scan.insert(scan.end(), {static_cast<float>(r * std::cos(az)), static_cast<float>(r * std::sin(az)), -1.73f, 0.3f});
    }
  }
  const std::size_t n = scan.size() / 4;
  std::vector<float> out(scan.size());
  std::vector<std::uint8_t> labels(n);
  LidarWetParams p;
  p.film = w;
  LidarWetStats ls;
  const bench::Spread l = bench::time_ms([&] { ls = lidar_wet(scan.data(), out.data(), n, p, labels.data()); }, rounds);
  std::printf("  lidar, %zu points (%zu ground, %zu lost), 1 thread: %7.2f ms [%.2f..%.2f]\n", n, ls.ground, ls.lost,
              l.median, l.lo, l.hi);
  std::printf(" load average at the end %s\n", load().c_str());
  return 0;
}
