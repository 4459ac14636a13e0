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
//   brume_bench_blur --ab [--rounds R] [--size WxH] [--image FILE] [--threads N]
//                    [--fusion HALO_ROWS,RING_BYTES,BAND_HALOS] [--simd avx2]
//
// --ab (issue #16): the interleaved A/B harness. In one process, each round
// runs every contender once, in its own shuffled order, after a pause:
// OpenCV at sigma 25, brume at sigma 25 with the fused schedule and with one
// pass per iteration, brume in f16, the space-variant map both ways, the
// demo scene's own haze map (demo_haze_map: many runs per row, as real maps
// have), OpenCV and brume at sigma 10. After a warm-up round,
// R rounds; per contender the median and spread of its times, and the median
// (and spread) of its per-round ratio to OpenCV at the same sigma, so that a
// host's drift during the run moves both sides of a ratio alike. --size
// renders the demo scene at another size (e.g. 4000x2800, an image that
// outgrows a smaller last-level cache); --fusion sets the fused schedule's
// limits (src/diffusion/diffusion_kernels.hpp) for tuning them on a host;
// --simd avx2 runs the vector kernels at most at AVX2 on an AVX-512 host
// (the row kernels' cap, cpu::set_diffusion_simd_limit(1), and Highway's
// target forced to AVX2, simd::force_target), to time an AVX2-only CPU's
// code on it.
//
// Without --image the built-in demo scene is rendered at 1600x1120 and used
// (written to a temporary EXR and read back, so both contenders see the same
// file). Output: a Markdown table on stdout.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <random>
#include <thread>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "brume/blur.hpp"
#include "brume/demo_scene.hpp"
#include "brume/diffusion.hpp"
#include "brume/io.hpp"
#include "bench_util.hpp"
#include "brume_opencv.hpp"
#include "core/simd.hpp"
#include "diffusion/diffusion_kernels.hpp"  // the fusion limits, for the A/B of the two schedules
#include "shared/prelude_cpp.h"       // brume_target_scale (eq. 7)

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

// A space-variant map like haze makes: sigma0 at the bottom row growing as
// R'^{3/2} to sigma_max at the top (Hansard eq. 7, brume_target_scale).
Image haze_like_map(int W, int H, double sigma) {
  Image map(W, H, 1);
  for (int y = 0; y < H; ++y) {
    const float r = static_cast<float>(1.0 - static_cast<double>(y) / (H - 1));
    for (int x = 0; x < W; ++x) map.at(x, y) = shared::brume_target_scale(r, 1.0f, static_cast<float>(sigma));
  }
  return map;
}

// The map `brume haze` makes from the demo scene's range at W x H (eq. 7,
// brume_target_scale of R' = R / R_max over its finite ranges; the sky, with
// no range, at R_max, as apply_haze treats unknown range). Unlike
// haze_like_map, whose rows are each one rate (one run per row), the range
// of the ground, the objects and the sky edge varies along the rows too:
// many runs, as on real data.
Image demo_haze_map(int W, int H, double sigma) {
  const Image range = render_demo_scene(W, H).range;
  float rmax = 0.0f;
  for (const float r : range.data)
    if (std::isfinite(r) && r > rmax) rmax = r;
  Image map(W, H, 1);
  for (std::size_t i = 0; i < map.data.size(); ++i) {
    const float r = range.data[i];
    const float rn = std::isfinite(r) && r > 0.0f ? r / rmax : 1.0f;
    map.data[i] = shared::brume_target_scale(rn, 1.0f, static_cast<float>(sigma));
  }
  return map;
}

// `brume blur`'s whole work on an RGB image, as the library does it
// (run_blur: the engine's working copy of the pixels -- RGB rows for a
// constant scale in f32, else RGBA -- the diffusion, the RGB result): a
// constant sigma (map null) or a scale map.
int blur_rgb(const Image& rgb, const Image* map, double sigma, const DiffusionParams& dp, const Exec& ex) {
  return run_blur(rgb, map ? std::nullopt : std::optional<double>(sigma), map, dp, ex).plan.iterations;
}

// The interleaved A/B harness (--ab; see the header comment).
int run_ab(const std::string& image, const std::string& label, int threads, int rounds,
           const cpu::FusionLimits& fusion) {
  cpu::set_diffusion_fusion(&fusion);  // the fused contenders' limits (--fusion; default: the library's)
  const Image rgb = read_color(image);
  const int W = rgb.width, H = rgb.height;
  cv::setNumThreads(threads);
  const cv::Mat src(H, W, CV_32FC3, const_cast<float*>(rgb.data.data()));
  cv::Mat dst;
  const Image v25 = haze_like_map(W, H, 25.0);
  const Image d25 = demo_haze_map(W, H, 25.0);
  Exec ex;
  ex.threads = threads;
  DiffusionParams f32, f16;
  f16.precision = Precision::f16;
  const cpu::FusionLimits unfused{0, 0, 0};
  struct Contender {
    std::string name;
    double sigma;  // the OpenCV peer of its ratio
    std::function<void()> run;
    std::vector<double> ms, ratio;
  };
  // The same sigma-25 blur with blocking off for the call.
  auto one_pass_each = [&](const Image* map) {
    return [&, m = map] {
      cpu::set_diffusion_fusion(&unfused);
      blur_rgb(rgb, m, 25, f32, ex);
      cpu::set_diffusion_fusion(&fusion);
    };
  };
  std::vector<Contender> cs = {
      {"OpenCV GaussianBlur sigma 25", 25,
       [&] { cv::GaussianBlur(src, dst, cv::Size(0, 0), 25, 25, cv::BORDER_REFLECT); }, {}, {}},
      {"brume constant sigma 25, f32, fused passes", 25, [&] { blur_rgb(rgb, nullptr, 25, f32, ex); }, {}, {}},
      {"brume constant sigma 25, f32, one pass per iteration", 25, one_pass_each(nullptr), {}, {}},
      {"brume constant sigma 25, f16", 25, [&] { blur_rgb(rgb, nullptr, 25, f16, ex); }, {}, {}},
      {"brume space-variant sigma <= 25, f32, fused passes", 25, [&] { blur_rgb(rgb, &v25, 25, f32, ex); }, {}, {}},
      {"brume space-variant sigma <= 25, f32, one pass per iteration", 25, one_pass_each(&v25), {}, {}},
      {"brume space-variant sigma <= 25, demo scene's haze map, f32, fused passes", 25,
       [&] { blur_rgb(rgb, &d25, 25, f32, ex); }, {}, {}},
      {"OpenCV GaussianBlur sigma 10", 10,
       [&] { cv::GaussianBlur(src, dst, cv::Size(0, 0), 10, 10, cv::BORDER_REFLECT); }, {}, {}},
      {"brume constant sigma 10, f32", 10, [&] { blur_rgb(rgb, nullptr, 10, f32, ex); }, {}, {}},
  };
  for (Contender& c : cs) c.run();  // warm-up round: workspaces, page faults, OpenCV's pools
  std::mt19937 rng(20261202);
  const int pause_ms = std::getenv("BRUME_BENCH_PAUSE_MS") ? std::atoi(std::getenv("BRUME_BENCH_PAUSE_MS")) : 200;
  for (int r = 0; r < rounds; ++r) {
    std::vector<double> t(cs.size());
    // Each round runs the contenders in its own order (a fixed-seed shuffle),
    // so that none always follows the same one, with a pause before each:
    // the contender run right after OpenCV was measured 1.8x slower at
    // 4000x2800 on 2 cores, even with fusion off (the same work as the next
    // contender's), and the pause removed that (OpenCV's worker threads still
    // spinning when the next contender's threads start is the likely cause).
    std::vector<std::size_t> order(cs.size());
    for (std::size_t q = 0; q < order.size(); ++q) order[q] = q;
    std::shuffle(order.begin(), order.end(), rng);
    for (const std::size_t i : order) {
      std::this_thread::sleep_for(std::chrono::milliseconds(pause_ms));
      const auto a = std::chrono::steady_clock::now();
      cs[i].run();
      t[i] = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count();
      cs[i].ms.push_back(t[i]);
      if (std::getenv("BRUME_BENCH_VERBOSE")) std::fprintf(stderr, "  %-55s %8.1f ms\n", cs[i].name.c_str(), t[i]);
    }
    for (std::size_t i = 0; i < cs.size(); ++i)
      for (std::size_t j = 0; j < cs.size(); ++j)
        if (cs[j].name.rfind("OpenCV", 0) == 0 && cs[j].sigma == cs[i].sigma) cs[i].ratio.push_back(t[i] / t[j]);
    std::fprintf(stderr, "round %d/%d done\n", r + 1, rounds);
  }
  std::printf("# brume_bench_blur --ab\n\n- machine: %s, %d threads\n- image: %dx%d RGB float (%s)\n"
              "- %d interleaved rounds after a warm-up round; median (min..max); ratio: median (min..max) of the "
              "per-round ratios to OpenCV at the same sigma\n\n",
              bench::cpu_name().c_str(), threads, W, H, label.c_str(), rounds);
  std::printf("- fusion limits: halo %d rows, rings %lld bytes per thread, bands >= %d halos\n\n", fusion.halo_rows,
              fusion.ring_bytes, fusion.band_halos);
  std::printf("| contender | time ms | vs OpenCV same sigma |\n|---|---:|---:|\n");
  for (const Contender& c : cs) {
    const bench::Spread t = bench::spread(c.ms), q = bench::spread(c.ratio);
    std::printf("| %s | %.1f (%.1f..%.1f) | %.3fx (%.3f..%.3f) |\n", c.name.c_str(), t.median, t.lo, t.hi, q.median,
                q.lo, q.hi);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string image;
  int runs = 5, threads = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN)), only = -1;
  bool quick = false, ab = false;
  int rounds = 9, size_w = 1600, size_h = 1120;
  cpu::FusionLimits fusion = cpu::diffusion_fusion_limits();
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--image" && i + 1 < argc) image = argv[++i];
    else if (a == "--ab") ab = true;
    else if (a == "--fusion" && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%d,%lld,%d", &fusion.halo_rows, &fusion.ring_bytes, &fusion.band_halos) != 3) {
        std::fprintf(stderr, "--fusion: expected HALO_ROWS,RING_BYTES,BAND_HALOS, got '%s'\n", argv[i]);
        return 2;
      }
    }
    else if (a == "--rounds" && i + 1 < argc) rounds = std::max(1, std::atoi(argv[++i]));
    else if (a == "--size" && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%dx%d", &size_w, &size_h) != 2 || size_w < 64 || size_h < 64) {
        std::fprintf(stderr, "--size: expected WxH, each at least 64, got '%s'\n", argv[i]);
        return 2;
      }
    }
    else if (a == "--case" && i + 1 < argc) only = std::atoi(argv[++i]);
    else if (a == "--runs" && i + 1 < argc) runs = std::atoi(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--quick") quick = true;
    else if (a == "--simd" && i + 1 < argc && std::string(argv[i + 1]) == "avx2") {
      ++i;
      cpu::set_diffusion_simd_limit(1);
      for (std::int64_t t : simd::targets())
        if (simd::target_name(t) == "AVX2") simd::force_target(t);
    }
    else {
      std::fprintf(stderr,
                   "usage: %s [--image FILE] [--runs N] [--threads N] [--quick]\n"
                   "       %s --ab [--rounds R] [--size WxH] [--image FILE] [--threads N] [--simd avx2]\n",
                   argv[0], argv[0]);
      return 2;
    }
  }
  std::string tmp;
  if (image.empty()) {
    tmp = (std::filesystem::temp_directory_path() / ("brume_bench_" + std::to_string(getpid()) + ".exr")).string();
    write_image(tmp, render_demo_scene(size_w, size_h).rgb, WriteOptions{});
    image = tmp;
  }
  if (ab) {
    const int rc = run_ab(image, image == tmp ? "built-in demo scene" : image, threads, rounds, fusion);
    if (!tmp.empty()) std::filesystem::remove(tmp);
    return rc;
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
      const Image map = c.variant ? haze_like_map(W, H, c.sigma) : Image();
      // The whole of `brume blur`'s work (blur_rgb).
      t = measure([&] { iters = blur_rgb(rgb, c.variant ? &map : nullptr, c.sigma, dp, ex); }, c.runs);
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
