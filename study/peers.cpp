// brume — peers of the diffusion engine, for the study (study/include/brume/peers.hpp).
//
// Written to be fair competitors, not straw men: the gather is vectorised
// over the four channels and threaded over rows; the mip-map uses
// Gaussian-filtered levels and variance-matched blending (better than the
// usual log2 index), built with OpenCV's separable GaussianBlur and area
// resampling.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "brume/error.hpp"
#include "brume/peers.hpp"
#include "brume_opencv.hpp"

namespace brume::peers {
namespace {

// Half-sample mirror of an index into [0, n): ... 2 1 0 | 0 1 2 ... n-1 | n-1 ...
// (the library's boundary, so the peers and diffusion see the same picture).
int mirror(int i, int n) {
  if (i >= 0 && i < n) return i;
  const int period = 2 * n;
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - 1 - i;
}

typedef float v4 __attribute__((vector_size(16)));

v4 load4(const float* p) {
  v4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

void check(const Image& f, const Image& sigma, double sigma0, const char* who) {
  if (f.channels != 4) throw Error(std::string(who) + ": the image must have 4 channels");
  if (sigma.channels != 1 || sigma.width != f.width || sigma.height != f.height)
    throw Error(std::string(who) + ": the scale map must be one channel of the image's size");
  if (!(sigma0 > 0.0)) throw Error(std::string(who) + ": sigma0 must be > 0");
  for (float s : sigma.data)
    if (!std::isfinite(s) || s < sigma0)
      throw Error(std::string(who) + ": every target scale must be finite and >= sigma0");
}

int threads_of(const Exec& e) { return e.threads > 0 ? e.threads : omp_get_max_threads(); }

// Gaussian filter and 2x2 box of one pyramid step, in the finer level's pixels.
constexpr double kLevelSigma = 1.0;

}  // namespace

void gather_blur(Image& f, const Image& sigma, double sigma0, double radius_sigmas, const Exec& exec) {
  check(f, sigma, sigma0, "gather_blur");
  const int W = f.width, H = f.height;
  const Image src = f;
  const double s02 = sigma0 * sigma0;
#pragma omp parallel num_threads(threads_of(exec))
  {
    std::vector<float> g;
#pragma omp for schedule(dynamic, 4)
    for (int y = 0; y < H; ++y) {
      for (int x = 0; x < W; ++x) {
        const double sv = sigma.at(x, y);
        const double s = std::sqrt(std::max(sv * sv - s02, 0.0));
        float* o = &f.at(x, y, 0);
        if (s < 1e-6) {  // the identity: keep the input
          std::memcpy(o, src.row(y) + 4 * x, 4 * sizeof(float));
          continue;
        }
        const int r = static_cast<int>(std::ceil(radius_sigmas * s));
        g.resize(2 * r + 1);
        float gs = 0.0f;
        for (int i = -r; i <= r; ++i) gs += g[i + r] = static_cast<float>(std::exp(-0.5 * i * i / (s * s)));
        const bool inside_x = x - r >= 0 && x + r < W;
        v4 acc = {0, 0, 0, 0};
        for (int dy = -r; dy <= r; ++dy) {
          const float* row = src.row(mirror(y + dy, H));
          v4 racc = {0, 0, 0, 0};
          if (inside_x) {
            const float* p = row + (x - r) * 4;
            for (int i = 0; i <= 2 * r; ++i) racc += g[i] * load4(p + 4 * i);
          } else {
            for (int i = -r; i <= r; ++i) racc += g[i + r] * load4(row + 4 * mirror(x + i, W));
          }
          acc += g[dy + r] * racc;
        }
        acc /= gs * gs;
        std::memcpy(o, &acc, sizeof acc);
      }
    }
  }
}

double mipmap_level_variance(int k) {
  // Pyramid filters: step j (from level j to j+1) applies a Gaussian of
  // kLevelSigma and a 2x2 box (variance 1/4) in level-j pixels of size 2^j.
  double v = 0.0;
  for (int j = 0; j < k; ++j) v += std::ldexp(1.0, 2 * j) * (kLevelSigma * kLevelSigma + 0.25);
  // Bilinear reconstruction from texels 2^k apart: a sample at fraction t
  // between two texels adds t(1-t) texel^2; average over the 2^k output
  // pixel phases, u = (x + 0.5)/2^k - 0.5.
  const int n = 1 << k;
  double r = 0.0;
  for (int x = 0; x < n; ++x) {
    const double u = (x + 0.5) / n - 0.5;
    const double t = u - std::floor(u);
    r += t * (1.0 - t);
  }
  const double texel = n;
  return v + (r / n) * texel * texel;
}

void mipmap_blur(Image& f, const Image& sigma, double sigma0, const Exec& exec) {
  check(f, sigma, sigma0, "mipmap_blur");
  const int W = f.width, H = f.height;
  const double s02 = sigma0 * sigma0;
  double vmax = 0.0;
  for (float s : sigma.data) vmax = std::max(vmax, static_cast<double>(s) * s - s02);
  // Levels until the coarsest brackets the largest target variance (or the
  // image is one texel across).
  int K = 0;
  while (mipmap_level_variance(K) < vmax && (std::max(W, H) >> K) > 1) ++K;
  std::vector<double> var(K + 1);
  for (int k = 0; k <= K; ++k) var[k] = mipmap_level_variance(k);

  cv::setNumThreads(threads_of(exec));
  // Pad right and bottom (mirror) to a multiple of 2^K so every level halves exactly.
  const int step = 1 << K;
  const int Wp = (W + step - 1) / step * step, Hp = (H + step - 1) / step * step;
  std::vector<cv::Mat> lv(K + 1);
  cv::copyMakeBorder(cv::Mat(H, W, CV_32FC4, f.data.data()), lv[0], 0, Hp - H, 0, Wp - W, cv::BORDER_REFLECT);
  for (int k = 1; k <= K; ++k) {
    cv::Mat t;
    cv::GaussianBlur(lv[k - 1], t, cv::Size(0, 0), kLevelSigma, kLevelSigma, cv::BORDER_REFLECT);
    cv::resize(t, lv[k], cv::Size(lv[k - 1].cols / 2, lv[k - 1].rows / 2), 0, 0, cv::INTER_AREA);
  }

  // Bilinear sample of level k at output pixel (x, y), clamped to the
  // level's edge texels (CLAMP_TO_EDGE: the half-sample mirror at texel
  // centres).
  auto sample = [&](int k, int x, int y) -> v4 {
    const cv::Mat& m = lv[k];
    if (k == 0) return load4(m.ptr<float>(y) + 4 * x);
    const double s = 1.0 / (1 << k);
    const double u = (x + 0.5) * s - 0.5, v = (y + 0.5) * s - 0.5;
    const double fu = std::floor(u), fv = std::floor(v);
    const float tu = static_cast<float>(u - fu), tv = static_cast<float>(v - fv);
    const int x0 = std::clamp(static_cast<int>(fu), 0, m.cols - 1), x1 = std::clamp(static_cast<int>(fu) + 1, 0, m.cols - 1);
    const int y0 = std::clamp(static_cast<int>(fv), 0, m.rows - 1), y1 = std::clamp(static_cast<int>(fv) + 1, 0, m.rows - 1);
    const float* r0 = m.ptr<float>(y0);
    const float* r1 = m.ptr<float>(y1);
    const v4 a = load4(r0 + 4 * x0), b = load4(r0 + 4 * x1), c = load4(r1 + 4 * x0), d = load4(r1 + 4 * x1);
    const v4 top = a + tu * (b - a), bot = c + tu * (d - c);
    return top + tv * (bot - top);
  };

#pragma omp parallel for num_threads(threads_of(exec)) schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const double v = static_cast<double>(sigma.at(x, y)) * sigma.at(x, y) - s02;
      int k = 0;
      while (k < K && var[k + 1] <= v) ++k;
      v4 out;
      if (k == K) {
        out = sample(K, x, y);
      } else {
        const float w = static_cast<float>(std::max(v - var[k], 0.0) / (var[k + 1] - var[k]));
        const v4 a = sample(k, x, y);
        out = w > 0.0f ? a + w * (sample(k + 1, x, y) - a) : a;
      }
      std::memcpy(&f.at(x, y, 0), &out, sizeof out);
    }
}

}  // namespace brume::peers
