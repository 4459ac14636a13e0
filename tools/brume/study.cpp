// brume study diffusion — the accuracy and speed study of Hansard §5.2-5.3
// on brume's own code (issue #5, first part: the measurements; plots, the
// space-variant gather and mip-map peers and the leakage study are to come).
//
// accuracy.csv: scheme,precision,backend,sigma,rms,iterations,spread
//   RMS against a true double-precision Gaussian of sqrt(sigma^2 - sigma0^2)
//   (sampled kernel of radius 5 sigma, normalised, half-sample mirror
//   boundary) over the image without a 4 sigma border, on linear RGB in
//   [0, 1]; "spread" is the per-axis standard deviation an impulse reaches
//   (target sqrt(sigma^2 - sigma0^2)).
// speed.csv: method,precision,backend,sigma,seconds,iterations
//   brume's schemes, OpenCV's GaussianBlur at the same sigma (space-invariant)
//   and a memory-streaming floor (copying the RGBA float image as many times
//   as the scheme iterates), on a 1600x1120 image (timings do not depend on
//   content), median of 3 after a warm-up.
//
// Accuracy uses Middlebury 2005 "Art" (463x370, the real [0,1] image the
// tests use) from ../shared/data, or --image.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "brume/demo_scene.hpp"
#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/io.hpp"
#include "depth/opencv.hpp"

namespace fs = std::filesystem;
using namespace brume;
using Clock = std::chrono::steady_clock;

namespace {

int reflect(int i, int n) {
  while (i < 0 || i >= n) i = i < 0 ? -1 - i : 2 * n - 1 - i;
  return i;
}

// True Gaussian reference in double (separable, radius 5 sigma, mirror).
Image gaussian(const Image& in, double sigma) {
  const int W = in.width, H = in.height, C = in.channels;
  const int r = static_cast<int>(std::ceil(5.0 * sigma));
  std::vector<double> k(2 * r + 1), tmp(in.data.size());
  double sum = 0;
  for (int i = -r; i <= r; ++i) sum += k[i + r] = std::exp(-0.5 * i * i / (sigma * sigma));
  for (double& v : k) v /= sum;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < C; ++c) {
        double a = 0;
        for (int i = -r; i <= r; ++i) a += k[i + r] * in.data[(static_cast<std::size_t>(y) * W + reflect(x + i, W)) * C + c];
        tmp[(static_cast<std::size_t>(y) * W + x) * C + c] = a;
      }
  Image out(W, H, C);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < C; ++c) {
        double a = 0;
        for (int i = -r; i <= r; ++i) a += k[i + r] * tmp[(static_cast<std::size_t>(reflect(y + i, H)) * W + x) * C + c];
        out.data[(static_cast<std::size_t>(y) * W + x) * C + c] = static_cast<float>(a);
      }
  return out;
}

double rms_rgb(const Image& a, const Image& b, int border) {
  double ss = 0;
  std::size_t n = 0;
  for (int y = border; y < a.height - border; ++y)
    for (int x = border; x < a.width - border; ++x)
      for (int c = 0; c < 3; ++c) {
        const double e = static_cast<double>(a.at(x, y, c)) - b.at(x, y, c);
        ss += e * e;
        ++n;
      }
  return n ? std::sqrt(ss / n) : NAN;
}

Image rgba(const Image& rgb) {
  Image f(rgb.width, rgb.height, 4, 1.0f);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = rgb.data[i * 3 + c];
  return f;
}

struct Runner {
  GpuContext* gpu;
  DiffusionPlan run(Image& f, double sigma, const DiffusionParams& p) const {
    Image map(f.width, f.height, 1, static_cast<float>(sigma));
    return gpu ? diffuse_gpu(*gpu, f, map, sigma, p) : diffuse(f, map, sigma, p);
  }
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

std::string data_dir() {
  // The shared data beside the repository, found from the working directory.
  for (fs::path p = fs::current_path(); !p.empty(); p = p.parent_path()) {
    if (fs::exists(p / "shared" / "data")) return (p / "shared" / "data").string();
    if (p == p.parent_path()) break;
  }
  return "";
}

}  // namespace

int run_study(const std::string& what, const std::string& out_dir, bool quick, const std::string& backend,
              const std::string& image_path) {
  if (what != "diffusion") throw Error("brume study '" + what + "': the only study is 'diffusion'");
  if (backend != "cpu" && backend != "gpu" && backend != "all")
    throw Error("--backend '" + backend + "' is not allowed for the study; use cpu, gpu or all");
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir)) throw Error("--out-dir '" + out_dir + "' cannot be created");
  std::string img = image_path;
  if (img.empty()) {
    const std::string d = data_dir();
    img = d.empty() ? "" : d + "/middlebury2005_thirdsize/Art/view1.png";
    if (img.empty() || !fs::exists(img))
      throw Error("no --image given and ../shared/data/middlebury2005_thirdsize/Art/view1.png not found; give --image FILE (a real image in [0,1])");
  }
  const Image acc_img = rgba(read_color(img));

  std::unique_ptr<GpuContext> ctx;
  std::vector<std::pair<std::string, GpuContext*>> backends;
  if (backend != "gpu") backends.emplace_back("cpu", nullptr);
  if (backend != "cpu") {
    ctx = std::make_unique<GpuContext>();  // throws with the reason
    backends.emplace_back("gpu", ctx.get());
  }
  const std::vector<double> sigmas = quick ? std::vector<double>{2, 5, 10} : std::vector<double>{1.5, 2, 3, 4, 5, 7, 10, 13, 16, 20, 25};
  const Scheme schemes[] = {Scheme::standard, Scheme::invariant, Scheme::invariant_exact};
  const Precision precs[] = {Precision::f32, Precision::f16};

  std::ofstream acc(fs::path(out_dir) / "accuracy.csv");
  acc << "scheme,precision,backend,sigma,rms,iterations,spread\n";
  std::fprintf(stderr, "brume study: accuracy on %s (%dx%d)\n", img.c_str(), acc_img.width, acc_img.height);
  for (double sigma : sigmas) {
    const Image ref = gaussian(acc_img, std::sqrt(sigma * sigma - 1.0));
    for (auto& [bname, g] : backends)
      for (Scheme s : schemes)
        for (Precision pr : precs) {
          if (quick && g && s == Scheme::standard && sigma > 5) continue;  // software GPUs: minutes
          DiffusionParams p;
          p.scheme = s;
          p.precision = pr;
          Image f = acc_img;
          const DiffusionPlan plan = Runner{g}.run(f, sigma, p);
          // Impulse spread on a field big enough that no mass reaches the border.
          const int n = 2 * static_cast<int>(std::ceil(6 * sigma)) + 3;
          Image imp(n, n, 4, 0.0f);
          imp.at(n / 2, n / 2, 0) = 1.0f;
          Runner{g}.run(imp, sigma, p);
          double m = 0, v = 0;
          for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) m += imp.at(x, y, 0), v += imp.at(x, y, 0) * (x - n / 2) * (x - n / 2);
          const double e = rms_rgb(f, ref, static_cast<int>(std::ceil(4 * sigma)));
          acc << to_string(s) << "," << to_string(pr) << "," << bname << "," << sigma << "," << e << "," << plan.iterations
              << "," << std::sqrt(v / m) << "\n";
          std::fprintf(stderr, "  %-15s %s %s sigma %5.1f: rms %.3e, %4d iterations\n", to_string(s).c_str(),
                       to_string(pr).c_str(), bname.c_str(), sigma, e, plan.iterations);
        }
  }
  acc.close();

  // Speed on 1600x1120.
  const int W = quick ? 463 : 1600, H = quick ? 370 : 1120;
  const Image big = rgba(render_demo_scene(W, H).rgb);
  std::ofstream spd(fs::path(out_dir) / "speed.csv");
  spd << "method,precision,backend,sigma,seconds,iterations\n";
  const int runs = 3;
  auto timeit = [&](auto&& fn) {
    fn();
    std::vector<double> t;
    for (int r = 0; r < runs; ++r) {
      const auto t0 = Clock::now();
      fn();
      t.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    }
    return median(t);
  };
  std::fprintf(stderr, "brume study: speed on %dx%d\n", W, H);
  for (double sigma : quick ? std::vector<double>{5, 10} : std::vector<double>{5, 10, 15, 20, 25}) {
    Image rgb3(W, H, 3);
    for (std::size_t i = 0; i < big.pixels(); ++i) std::memcpy(&rgb3.data[i * 3], &big.data[i * 4], 12);
    const cv::Mat src(H, W, CV_32FC3, rgb3.data.data());
    cv::Mat dst;
    const double tcv = timeit([&] { cv::GaussianBlur(src, dst, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT); });
    spd << "opencv-gaussianblur,f32,cpu," << sigma << "," << tcv << ",1\n";
    for (auto& [bname, g] : backends)
      for (Scheme s : schemes)
        for (Precision pr : precs) {
          if (s == Scheme::standard && (g || (quick && sigma > 5))) continue;  // hundreds of passes
          DiffusionParams p;
          p.scheme = s;
          p.precision = pr;
          int iters = 0;
          const double t = timeit([&] {
            Image f = big;
            iters = Runner{g}.run(f, sigma, p).iterations;
          });
          spd << "brume-" << to_string(s) << "," << to_string(pr) << "," << bname << "," << sigma << "," << t << "," << iters << "\n";
          if (s == Scheme::invariant_exact && pr == Precision::f32 && !g) {
            // Streaming floor: the same bytes copied as many times as the scheme iterates.
            std::vector<float> a(big.data), b(big.data.size());
            const double floor_t = timeit([&] {
              for (int k = 0; k < iters; ++k) std::memcpy(b.data(), a.data(), a.size() * sizeof(float)), a.swap(b);
            });
            spd << "memory-floor,f32,cpu," << sigma << "," << floor_t << "," << iters << "\n";
          }
          std::fprintf(stderr, "  %-15s %s %s sigma %4.1f: %8.1f ms (%d iterations), OpenCV %6.1f ms\n",
                       to_string(s).c_str(), to_string(pr).c_str(), bname.c_str(), sigma, t * 1e3, iters, tcv * 1e3);
        }
  }
  std::fprintf(stderr, "brume study: wrote %s/accuracy.csv and %s/speed.csv\n", out_dir.c_str(), out_dir.c_str());
  return 0;
}
