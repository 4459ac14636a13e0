// brume benchmark — the diffusion engine against OpenCV's GaussianBlur.
//
// Issue #2's benchmark: a 1600x1120 RGB float image, target sigma = 25 px.
// `brume blur` (default scheme) against cv::GaussianBlur at the same sigma on
// the same pixels, the same thread count, measured in the same run. Also the
// standard scheme at sigma = 10 and 25, the published invariant scheme, f16
// storage, a genuinely space-variant scale map, iteration counts and the peak
// memory of each case (every case runs in its own child process, started by
// re-executing this program with --case K, whose ru_maxrss is read back; a
// fork() of a process that has used OpenMP is not safe with libgomp).
//
// Convention (STYLE.md #13): one warm-up, then the median and the spread
// (min..max) of --runs timed runs; machine, threads and size are printed.
//
//   brume_bench_blur [--image FILE] [--runs N] [--threads N] [--quick]
//
// Without --image the built-in demo scene is rendered at 1600x1120 and used
// (written to a temporary EXR and read back, so both contenders see the same
// file). Output: a Markdown table on stdout.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "brume/demo_scene.hpp"
#include "brume/diffusion.hpp"
#include "brume/io.hpp"
#include "bench_util.hpp"
#include "brume_opencv.hpp"

using namespace brume;

namespace {

struct Timing {
  double median, lo, hi;
  long peak_kb;
};

Timing measure(const std::function<void()>& fn, int runs) {
  const bench::Spread t = bench::time_ms(fn, runs);
  struct rusage ru {};
  getrusage(RUSAGE_SELF, &ru);
  return Timing{t.median * 1e-3, t.lo * 1e-3, t.hi * 1e-3, ru.ru_maxrss};
}

}  // namespace

int main(int argc, char** argv) {
  std::string image;
  int runs = 5, threads = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN)), only = -1;
  bool quick = false;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--image" && i + 1 < argc) image = argv[++i];
    else if (a == "--case" && i + 1 < argc) only = std::atoi(argv[++i]);
    else if (a == "--runs" && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--quick") quick = true;
    else {
      std::fprintf(stderr, "usage: %s [--image FILE] [--runs N] [--threads N] [--quick]\n", argv[0]);
      return 2;
    }
  }
  std::string tmp;
  if (image.empty()) {
    tmp = (std::filesystem::temp_directory_path() / ("brume_bench_" + std::to_string(getpid()) + ".exr")).string();
    write_image(tmp, render_demo_scene(1600, 1120).rgb, WriteOptions{});
    image = tmp;
  }

  struct Case {
    bool opencv;
    Scheme scheme;
    Precision precision;
    double sigma;
    bool variant;
    int runs;
  };
  std::vector<Case> cases = {
      {true, Scheme::standard, Precision::f32, 25.0, false, runs},
      {false, Scheme::invariant_exact, Precision::f32, 25.0, false, runs},
      {false, Scheme::invariant_exact, Precision::f16, 25.0, false, runs},
      {false, Scheme::invariant_exact, Precision::f32, 25.0, true, runs},
      {false, Scheme::invariant, Precision::f32, 25.0, false, runs},
      {true, Scheme::standard, Precision::f32, 10.0, false, runs},
      {false, Scheme::invariant_exact, Precision::f32, 10.0, false, runs},
  };
  if (!quick) {
    cases.push_back({false, Scheme::standard, Precision::f32, 10.0, false, std::max(1, runs / 2)});
    cases.push_back({false, Scheme::standard, Precision::f32, 25.0, false, 1});
  }

  if (only >= 0) {  // child: run one case, print "median lo hi iterations peak_kb"
    const Image rgb = read_color(image);
    const int W = rgb.width, H = rgb.height;
    const Case& c = cases.at(static_cast<std::size_t>(only));
    Timing t{};
    int iters = 1;
    if (c.opencv) {
      cv::setNumThreads(threads);
      const cv::Mat src(H, W, CV_32FC3, const_cast<float*>(rgb.data.data()));
      cv::Mat dst;
      t = measure([&] { cv::GaussianBlur(src, dst, cv::Size(0, 0), c.sigma, c.sigma, cv::BORDER_REFLECT); }, c.runs);
    } else {
      DiffusionParams dp;
      dp.scheme = c.scheme;
      dp.precision = c.precision;
      Exec ex;
      ex.threads = threads;
      // A space-variant map like haze makes: sigma0 at the bottom row growing
      // as R'^{3/2} to sigma_max at the top.
      Image map(W, H, 1, static_cast<float>(c.sigma));
      if (c.variant)
        for (int y = 0; y < H; ++y) {
          const double r = 1.0 - static_cast<double>(y) / (H - 1);
          for (int x = 0; x < W; ++x) map.at(x, y) = static_cast<float>(1.0 + std::pow(r, 1.5) * (c.sigma - 1.0));
        }
      // The whole of `brume blur`'s work: RGB -> RGBA, diffuse, RGBA -> RGB.
      t = measure(
          [&] {
            Image f(W, H, 4);
            for (std::size_t i = 0; i < rgb.pixels(); ++i) {
              std::memcpy(&f.data[i * 4], &rgb.data[i * 3], 3 * sizeof(float));
              f.data[i * 4 + 3] = 1.0f;
            }
            iters = diffuse(f, map, c.sigma, dp, ex).iterations;
            Image out(W, H, 3);
            for (std::size_t i = 0; i < rgb.pixels(); ++i)
              std::memcpy(&out.data[i * 3], &f.data[i * 4], 3 * sizeof(float));
          },
          c.runs);
    }
    std::printf("%.9f %.9f %.9f %d %ld %d %d\n", t.median, t.lo, t.hi, iters, t.peak_kb, W, H);
    return 0;
  }

  struct Row {
    std::string method, precision, map;
    double sigma;
    int iterations;
    Timing t;
  };
  std::vector<Row> rows;
  int W = 0, H = 0;
  for (std::size_t k = 0; k < cases.size(); ++k) {
    const Case& c = cases[k];
    std::string cmd = std::string(argv[0]) + " --case " + std::to_string(k) + " --image '" + image + "' --runs " +
                      std::to_string(runs) + " --threads " + std::to_string(threads) + (quick ? " --quick" : "");
    FILE* p = popen(cmd.c_str(), "r");
    Row r{};
    if (!p || std::fscanf(p, "%lf %lf %lf %d %ld %d %d", &r.t.median, &r.t.lo, &r.t.hi, &r.iterations, &r.t.peak_kb, &W,
                          &H) != 7) {
      std::fprintf(stderr, "case %zu failed\n", k);
      return 1;
    }
    pclose(p);
    r.sigma = c.sigma;
    r.precision = to_string(c.precision);
    r.map = c.variant ? "space-variant" : "constant";
    r.method = c.opencv ? "OpenCV GaussianBlur (" + std::to_string(cvRound(c.sigma * 4 * 2 + 1) | 1) + " taps)"
                        : "brume " + to_string(c.scheme);
    rows.push_back(r);
    std::fprintf(stderr, "%s sigma %.0f %s %s: %.1f ms\n", r.method.c_str(), r.sigma, r.precision.c_str(),
                 r.map.c_str(), r.t.median * 1e3);
  }
  if (!tmp.empty()) std::filesystem::remove(tmp);

  std::printf("# brume_bench_blur\n\n- machine: %s, %d threads\n- image: %dx%d RGB float (%s)\n- runs: %d after one warm-up; time = median (min..max)\n- peak RSS: the whole process (input image, buffers, libraries)\n\n",
              bench::cpu_name().c_str(), threads, W, H, image == tmp ? "built-in demo scene" : image.c_str(), runs);
  std::printf("| method | precision | scale map | sigma px | iterations | time ms | vs OpenCV same sigma | peak RSS MB |\n");
  std::printf("|---|---|---|---:|---:|---:|---:|---:|\n");
  for (const Row& r : rows) {
    double cv_t = 0;
    for (const Row& q : rows)
      if (q.method.rfind("OpenCV", 0) == 0 && q.sigma == r.sigma) cv_t = q.t.median;
    std::printf("| %s | %s | %s | %.0f | %d | %.1f (%.1f..%.1f) | %.3fx | %.0f |\n", r.method.c_str(), r.precision.c_str(),
                r.map.c_str(), r.sigma, r.iterations, r.t.median * 1e3, r.t.lo * 1e3, r.t.hi * 1e3,
                cv_t > 0 ? r.t.median / cv_t : 0.0, r.t.peak_kb / 1024.0);
  }
  return 0;
}
