// brume benchmark — a sparse scan fused with a stereo view (issue 52, item
// 2; brume/fuse.hpp) on ETH3D two-view pairs (playground_1l 941x490,
// terrace 713x434) with the KITTI-like scan of tests/eth3d_scan.hpp (48 full
// rows over the lower 60 %), against the scan-only completion.
//
// Each case is what `brume depth complete` and `--complete` run: the depth
// source loaded (the scan from a PFM; with --stereo-right also the two
// views read, the rectification check, the matching over the range the
// scan bounds, the fit) and the completion step (with the fusion). The two
// cases run interleaved, one warm-up each, then --runs timed pairs.
// Target (issue 52): with stereo <= 250 ms on an ETH3D pair.
//
//   brume_bench_fuse [--runs N] [--data DIR] [--threads T]
//
// Output: a Markdown table on stdout with the CPU, the threads and the load.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "brume/depth_source.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"

#include "bench_util.hpp"
#include "eth3d_scan.hpp"

using namespace brume;

namespace {

std::string load_average() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 9, threads = 2;
  std::string data = BRUME_DATA_DIR;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--runs") && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--data") && i + 1 < argc) data = argv[++i];
    else if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
  }
  omp_set_num_threads(threads);
  std::printf("CPU: %s; %d OpenMP threads (the matcher: its two views side by side); load average before: %s\n\n",
              bench::cpu_name().c_str(), threads, load_average().c_str());
  std::printf("| scene | size | case | median ms | min..max ms |\n|---|---|---|---|---|\n");
  const std::string scratch = (std::filesystem::temp_directory_path() / "brume_bench_fuse.pfm").string();
  for (const char* scene : {"playground_1l", "terrace"}) {
    const std::string dir = data + "/eth3d_two_view/" + scene + "/";
    eth3d::SimulatedScan e;
    try {
      e = eth3d::kitti_like_scan(dir);
    } catch (const std::exception& x) {
      std::printf("| %s | skipped: %s |\n", scene, x.what());
      continue;
    }
    WriteOptions w;
    w.is_color = false;
    write_image(scratch, e.sparse, w);
    DepthSource scan;
    scan.range = scratch;
    scan.calib = dir + "calib.txt";
    DepthSource fused = scan;
    fused.stereo_right = dir + "im1.png";
    fused.stereo_left = dir + "im0.png";
    RangeStep step;
    step.complete = CompleteMode::on;
    auto once = [&](const DepthSource& s) {
      const auto t0 = std::chrono::steady_clock::now();
      const LoadedDepth ld = load_depth(s, e.rgb.width, e.rgb.height);
      const CompletedRange done = complete_step(ld.range, e.rgb, with_camera(step, ld), {}, threads);
      if (!done.applied) std::abort();
      return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    };
    once(scan), once(fused);  // warm-up
    std::vector<double> a, b;
    for (int i = 0; i < runs; ++i) a.push_back(once(scan)), b.push_back(once(fused));
    char size[32];
    std::snprintf(size, sizeof size, "%dx%d", e.rgb.width, e.rgb.height);
    for (const auto* c : {&a, &b}) {
      const bench::Spread s = bench::spread(*c);
      std::printf("| %s | %s | %s | %.0f | %.0f..%.0f |\n", scene, size,
                  c == &a ? "scan only (load + completion)" : "scan + --stereo-right (load, match, fit, completion, fusion)",
                  s.median, s.lo, s.hi);
    }
  }
  std::filesystem::remove(scratch);
  std::printf("\nload average after: %s\n", load_average().c_str());
  return 0;
}
