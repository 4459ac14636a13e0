// brume benchmark — depth completion (brume/complete.hpp) on KITTI object
// frame 000001 (1242x375, 18 630 lidar points in view), against its peer:
// Ku et al.'s morphological pipeline alone (OpenCV calls, as the paper's
// Python code makes them), the pilot brume refines.
//
// Target (issue 40): a 1242x375 completion in <= 60 ms on 2 cores.
//
//   brume_bench_complete [--runs N] [--data DIR]   (DIR: ../shared/data by default)
//
// Output: a Markdown table on stdout with the CPU, threads and size.
#include <omp.h>

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>
#include <cstring>
#include <functional>
#include <string>

#include "brume/complete.hpp"
#include "brume/depth.hpp"
#include "brume/io.hpp"

#include "bench_util.hpp"
#include "brume_opencv.hpp"

using namespace brume;

namespace {

// Ku et al. 2018: invert, diamond 5x5 dilation, 5x5 closing, 7x7 and 31x31
// fills, 5x5 median and Gaussian on the valid pixels, invert back.
cv::Mat ku(const Image& sparse) {
  cv::Mat d(sparse.height, sparse.width, CV_32F);
  for (std::size_t i = 0; i < sparse.pixels(); ++i)
    d.ptr<float>()[i] = std::isfinite(sparse.data[i]) ? 100.0f - sparse.data[i] : 0.0f;
  const cv::Mat diamond = (cv::Mat_<std::uint8_t>(5, 5) << 0, 0, 1, 0, 0, 0, 1, 1, 1, 0, 1, 1, 1, 1, 1, 0, 1, 1, 1,
                           0, 0, 0, 1, 0, 0);
  cv::dilate(d, d, diamond);
  cv::morphologyEx(d, d, cv::MORPH_CLOSE, cv::Mat::ones(5, 5, CV_8U));
  for (int k : {7, 31}) {
    cv::Mat f;
    cv::dilate(d, f, cv::Mat::ones(k, k, CV_8U));
    f.copyTo(d, d < 0.1f);
  }
  cv::Mat m;
  cv::medianBlur(d, m, 5);
  m.copyTo(d, d > 0.1f);
  cv::GaussianBlur(d, m, cv::Size(5, 5), 0);
  m.copyTo(d, d > 0.1f);
  return d;
}

// Process CPU time [ms] of one call, all threads: on a shared host the wall
// time waits for the cores, the CPU time does not.
double cpu_ms(const std::function<void()>& fn) {
  timespec a{}, b{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a);
  fn();
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
  return (b.tv_sec - a.tv_sec) * 1e3 + (b.tv_nsec - a.tv_nsec) * 1e-6;
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 21;
  std::string data = BRUME_DATA_DIR;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--runs") && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--data") && i + 1 < argc) data = argv[++i];
    else {
      std::fprintf(stderr, "usage: brume_bench_complete [--runs N] [--data DIR]\n");
      return 2;
    }
  }
  const std::string k = data + "/kitti_object_000001/";
  Image rgb;
  LidarImage scan;
  try {
    rgb = read_color(k + "image_2/000001.png");
    scan = project_velodyne(k + "velodyne/000001.bin", read_kitti_calib(k + "calib/000001.txt"), rgb.width, rgb.height);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "brume_bench_complete: needs %s (KITTI frame 000001): %s\n", k.c_str(), e.what());
    return 1;
  }
  std::printf("CPU: %s; %dx%d, %zu lidar points in view; median (min..max) of %d runs after a warm-up\n\n",
              bench::cpu_name().c_str(), rgb.width, rgb.height, scan.points_in_view, runs);
  std::printf("| threads | brume complete_range, wall [ms] | its CPU time [ms] | Ku et al. (OpenCV) alone, wall [ms] |\n"
              "|---|---|---|---|\n");
  for (int t : {1, 2}) {
    cv::setNumThreads(t);
    omp_set_num_threads(t);
    const bench::Spread a = bench::time_ms([&] { (void)complete_range(scan.range, rgb, {}, t); }, runs);
    const bench::Spread b = bench::time_ms([&] { (void)ku(scan.range); }, runs);
    std::vector<double> cpu;
    for (int i = 0; i < runs; ++i) cpu.push_back(cpu_ms([&] { (void)complete_range(scan.range, rgb, {}, t); }));
    const bench::Spread c = bench::spread(cpu);
    std::printf("| %d | %.1f (%.1f..%.1f) | %.1f (%.1f..%.1f) | %.1f (%.1f..%.1f) |\n", t, a.median, a.lo, a.hi,
                c.median, c.lo, c.hi, b.median, b.lo, b.hi);
  }
  return 0;
}
