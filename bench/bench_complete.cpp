// brume benchmark — depth completion (brume/complete.hpp) on KITTI object
// frame 000001 (1242x375, 18 630 lidar points in view), against its peer:
// Ku et al.'s morphological pipeline alone (OpenCV calls, as the paper's
// Python code makes them), the pilot brume refines.
//
// Target (issue 40): a 1242x375 completion in <= 60 ms on 2 cores.
//
//   brume_bench_complete [--runs N] [--data DIR]   (DIR: ../shared/data by default)
//
// Output: Markdown tables on stdout with the CPU, threads and size: the
// time of one completion, then KITTI depth completion's four metrics (MAE,
// RMSE [mm], iMAE, iRMSE [1/km], on planar depth; tests/ip_basic.hpp) at 10 %
// of the returns held out (ten fixed seeds), brume against IP-Basic's "fast"
// configuration as reimplemented for the tests (tests/ip_basic.hpp, plain
// loops), both run here on the same held-out sets (issue 52, item 4), on
// the held-out returns the occlusion rule keeps (brume/complete.hpp step 0)
// and on all of them (item 3).
#include <omp.h>

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>
#include <cstring>
#include <functional>
#include <string>

#include "brume/complete.hpp"
#include "brume/depth.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"

#include "bench_util.hpp"
#include "brume_opencv.hpp"
#include "ip_basic.hpp"

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
  keep_freed_heap();  // as the CLI and brume batch run (brume/pipeline.hpp): freed buffers are reused
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
  const KittiCalib cal = read_kitti_calib(k + "calib/000001.txt");
  Intrinsics cam;
  cam.fx = cal.P2[0], cam.fy = cal.P2[5], cam.cx = cal.P2[2], cam.cy = cal.P2[6];
  CompleteParams scan_p;  // the defaults as --velodyne runs them (occlusion auto: on for a scan from beside the camera)
  scan_p.offset_scan = true;
  CompleteParams column;
  column.method = CompleteMethod::column;
  CompleteParams nearest = scan_p;  // without step 2b (the rule before complete-edges image)
  nearest.edges = CompleteEdges::nearest;
  std::printf("| threads | brume complete_range (planar, the default), wall [ms] | its CPU time [ms] | "
              "--complete-edges nearest, wall [ms] | --complete-method column, wall [ms] | Ku et al. (OpenCV) alone, "
              "wall [ms] |\n|---|---|---|---|---|---|\n");
  for (int t : {1, 2}) {
    cv::setNumThreads(t);
    omp_set_num_threads(t);
    // Interleaved: each spread's runs alternate with the others' (a shared
    // host's load then weighs on all alike).
    auto wall = [](const std::function<void()>& fn) {
      const auto t0 = std::chrono::steady_clock::now();
      fn();
      return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    };
    std::vector<double> ta, tn, tc, tb, cpu;
    for (int i = 0; i < runs + 1; ++i) {
      const double a1 = wall([&] { (void)complete_range(scan.range, rgb, scan_p, t, &cam); });
      const double n1 = wall([&] { (void)complete_range(scan.range, rgb, nearest, t, &cam); });
      const double c1 = wall([&] { (void)complete_range(scan.range, rgb, column, t, &cam); });
      const double b1 = wall([&] { (void)ku(scan.range); });
      cpu.push_back(cpu_ms([&] { (void)complete_range(scan.range, rgb, scan_p, t, &cam); }));
      if (i == 0) continue;  // the warm-up
      ta.push_back(a1), tn.push_back(n1), tc.push_back(c1), tb.push_back(b1);
    }
    cpu.erase(cpu.begin());
    const bench::Spread a = bench::spread(ta), nn = bench::spread(tn), cc = bench::spread(tc), b = bench::spread(tb),
                        c = bench::spread(cpu);
    std::printf("| %d | %.1f (%.1f..%.1f) | %.1f (%.1f..%.1f) | %.1f (%.1f..%.1f) | %.1f (%.1f..%.1f) | %.1f "
                "(%.1f..%.1f) |\n",
                t, a.median, a.lo, a.hi, c.median, c.lo, c.hi, nn.median, nn.lo, nn.hi, cc.median, cc.lo, cc.hi,
                b.median, b.lo, b.hi);
  }

  // KITTI depth completion's metrics at held-out returns, ten seeds: on the
  // returns the occlusion rule keeps (the truth of tests/test_complete.cpp:
  // a return it drops is background the camera does not see), and on all.
  const std::vector<std::uint8_t> occluded = occluded_returns(scan.range);
  std::vector<std::size_t> known;
  std::size_t n_occ = 0;
  for (std::size_t i = 0; i < scan.range.pixels(); ++i)
    if (std::isfinite(scan.range.data[i])) known.push_back(i), n_occ += occluded[i];
  std::printf("\nHeld-out returns (10 %% of %zu, seeds 1-10), planar depth; brume (default parameters) against "
              "IP-Basic (fast, tests/ip_basic.hpp); truth: the held-out returns the occlusion rule keeps (it drops "
              "%zu of the %zu returns)\n\n"
              "| seed | brume MAE [mm] | RMSE [mm] | iMAE [1/km] | iRMSE [1/km] | IP-Basic MAE [mm] | RMSE [mm] | "
              "iMAE [1/km] | iRMSE [1/km] |\n|---|---|---|---|---|---|---|---|---|\n",
              known.size(), n_occ, known.size());
  ip_basic::DcMetrics sum[2][2];  // [brume, IP-Basic][kept, all]
  auto add = [](ip_basic::DcMetrics& s, const ip_basic::DcMetrics& m) {
    s.mae_mm += m.mae_mm / 10, s.rmse_mm += m.rmse_mm / 10;
    s.imae_per_km += m.imae_per_km / 10, s.irmse_per_km += m.irmse_per_km / 10;
  };
  auto row = [](const char* label, const ip_basic::DcMetrics& a, const ip_basic::DcMetrics& b) {
    std::printf("| %s | %.0f | %.0f | %.3f | %.3f | %.0f | %.0f | %.3f | %.3f |\n", label, a.mae_mm, a.rmse_mm,
                a.imae_per_km, a.irmse_per_km, b.mae_mm, b.rmse_mm, b.imae_per_km, b.irmse_per_km);
  };
  for (int seed = 1; seed <= 10; ++seed) {
    const ip_basic::HeldOut h = ip_basic::hold_out(scan.range, known, occluded, seed);
    const CompleteResult ours = complete_range(h.sparse, rgb, scan_p, 0, &cam);
    const Image ipb = ip_basic::ku_baseline(h.sparse);
    ip_basic::DcMetrics m[2][2];
    for (int s = 0; s < 2; ++s) {
      m[0][s] = ip_basic::dc_metrics(ours.range, scan.range, s ? h.held : h.kept, cam);
      m[1][s] = ip_basic::dc_metrics(ipb, scan.range, s ? h.held : h.kept, cam);
      add(sum[0][s], m[0][s]), add(sum[1][s], m[1][s]);
    }
    row(std::to_string(seed).c_str(), m[0][0], m[1][0]);
  }
  row("mean", sum[0][0], sum[1][0]);
  row("mean, all held-out returns", sum[0][1], sum[1][1]);
  std::printf("\nratios of the means (brume / IP-Basic): kept returns MAE %.3f RMSE %.3f; all MAE %.3f RMSE %.3f\n",
              sum[0][0].mae_mm / sum[1][0].mae_mm, sum[0][0].rmse_mm / sum[1][0].rmse_mm,
              sum[0][1].mae_mm / sum[1][1].mae_mm, sum[0][1].rmse_mm / sum[1][1].rmse_mm);
  return 0;
}
