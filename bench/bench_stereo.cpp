// brume benchmark — `brume depth stereo` on an ETH3D pair (941x490
// playground_1l; terrace 713x434 too), against OpenCV's plain StereoSGBM
// (one direction, the parameters) over the same disparity range.
//
// Cases (one warm-up, then the median and spread of --runs timed runs):
//  * compute_stereo with --max-disparity auto (rectification check, the
//    quarter-resolution range pass, both views matched on two threads, the
//    left-right check, speckles, fill, confidence);
//  * the same with the range given (no coarse pass);
//  * plain SGBM over that range, for scale.
// The target (issue #40): 941x490 in <= 0.5 s on 2 cores.
//
//   brume_bench_stereo [--runs N] [--data DIR]
//
// Output: a Markdown table on stdout, with the CPU model.
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>

#include "brume/stereo.hpp"

#include "bench_util.hpp"
#include "brume_opencv.hpp"

using namespace brume;

int main(int argc, char** argv) {
  int runs = 7;
  std::string data = BRUME_DATA_DIR;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--runs") && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--data") && i + 1 < argc) data = argv[++i];
  }
  std::printf("CPU: %s, %u hardware threads; brume matches the two views on 2 threads\n\n",
              bench::cpu_name().c_str(), std::thread::hardware_concurrency());
  std::printf("| scene | size | range | case | median ms | min..max ms |\n|---|---|---|---|---|---|\n");
  for (const char* scene : {"playground_1l", "terrace"}) {
    const std::string dir = data + "/eth3d_two_view/" + scene + "/";
    StereoView l, r;
    try {
      l = read_stereo_view(dir + "im0.png", "--left");
      r = read_stereo_view(dir + "im1.png", "--right");
    } catch (const std::exception& e) {
      std::printf("| %s | skipped: %s |\n", scene, e.what());
      continue;
    }
    StereoParams p;
    const StereoResult first = compute_stereo(l, r, p);
    const int max_d = first.record["searched_px"][1].get<int>();
    char size[32], range[32];
    std::snprintf(size, sizeof size, "%dx%d", l.width, l.height);
    std::snprintf(range, sizeof range, "0-%d", max_d);
    auto row = [&](const char* what, const bench::Spread& s) {
      std::printf("| %s | %s | %s | %s | %.0f | %.0f..%.0f |\n", scene, size, range, what, s.median, s.lo, s.hi);
    };
    row("brume, --max-disparity auto", bench::time_ms([&] { compute_stereo(l, r, p); }, runs));
    StereoParams given = p;
    given.max_disparity = max_d;
    row("brume, range given", bench::time_ms([&] { compute_stereo(l, r, given); }, runs));
    const cv::Mat L(l.height, l.width, CV_8UC3, l.rgb.data()), R(r.height, r.width, CV_8UC3, r.rgb.data());
    auto sgbm = cv::StereoSGBM::create(0, max_d + 1, 5, 8 * 3 * 25, 32 * 3 * 25, 1, 63, 10, 100, 2);
    cv::Mat d;
    row("plain OpenCV SGBM (one view)", bench::time_ms([&] { sgbm->compute(L, R, d); }, runs));
  }
  return 0;
}
