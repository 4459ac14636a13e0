// brume — scalar double-precision reference of the diffusion schemes.
//
// A literal transcription of eq. 11-13 and 17-18 (and the exact-variance
// offset of DESIGN.md) with no optimisation: one pixel at a time, every
// neighbour index mirrored, every rate and offset computed from its closed
// form (exp, not the fast path's running product). It is the oracle the fast
// path and, later, the GPU backend are tested against. f16 mode rounds the
// stored values to binary16 after every iteration, as the fast path does.
#include <algorithm>
#include <cmath>
#include <vector>

#include "cpu/diffusion_kernels.hpp"

namespace brume::cpu {
namespace {

double to_half(double v) { return static_cast<double>(static_cast<_Float16>(static_cast<float>(v))); }

// Linear interpolation of channel c of a W x H x C double image at the
// fractional column position x + d (d may be negative), row y, mirrored.
struct Grid {
  int w, h, c;
  const std::vector<double>* v;
  double at(int x, int y, int ch) const {
    return (*v)[(static_cast<std::size_t>(mirror(y, h)) * w + mirror(x, w)) * c + ch];
  }
  // Sample at (x + dx, y + dy) where exactly one of dx, dy is non-zero.
  double sample(int x, int y, double dx, double dy, int ch) const {
    double d = dx != 0.0 ? dx : dy;
    double fl = std::floor(d);
    double fr = d - fl;
    int i0 = static_cast<int>(fl);
    double a, b;
    if (dx != 0.0) {
      a = at(x + i0, y, ch);
      b = at(x + i0 + 1, y, ch);
    } else {
      a = at(x, y + i0, ch);
      b = at(x, y + i0 + 1, ch);
    }
    return a + fr * (b - a);
  }
};

// brume_edge_rate in double (the shared float version is the one under test).
double edge_rate(double a, double b, EdgeRate mode) {
  switch (mode) {
    case EdgeRate::min: return std::min(a, b);
    case EdgeRate::harmonic: return a + b > 0.0 ? 2.0 * a * b / (a + b) : 0.0;
    case EdgeRate::mean: break;
  }
  return 0.5 * (a + b);
}

}  // namespace

void diffuse_reference(Image& f, const Image& sigma, const DiffusionPlan& plan,
                       const DiffusionParams& p) {
  const int W = f.width, H = f.height, N = plan.iterations;
  const double s0 = p.sigma0;
  const bool f16 = p.precision == Precision::f16;
  const std::size_t np = f.pixels();

  std::vector<double> cur(f.data.begin(), f.data.end()), next(cur.size());
  if (f16)
    for (double& v : cur) v = to_half(v);
  std::vector<double> rho(np);
  for (std::size_t i = 0; i < np; ++i) {
    double s = sigma.data[i];
    rho[i] = p.scheme == Scheme::standard ? (s * s - s0 * s0) / (2.0 * N)  // eq. 13
                                          : std::log(s / s0) / N;          // eq. 18
  }
  const Grid rgrid{W, H, 1, &rho};
  const double ux[4] = {-1, 1, 0, 0}, uy[4] = {0, 0, -1, 1};

  for (int k = 0; k < N; ++k) {
    const Grid fgrid{W, H, 4, &cur};
    for (int y = 0; y < H; ++y) {
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        const double r = rho[i];
        double h = 1.0;  // standard scheme: unit offsets
        if (p.scheme != Scheme::standard) {
          double sk = s0 * std::exp(k * r);  // eq. 18
          if (p.scheme == Scheme::invariant) {
            h = sk;
          } else {
            // 2 rho (h^2 + f(1-f)) = sk^2 (e^{2 rho} - 1); limit sk^2 at rho = 0.
            double m = r > 0.0 ? sk * sk * std::expm1(2.0 * r) / (2.0 * r) : sk * sk;
            double n = std::floor(std::sqrt(m));
            h = (m + n * (n + 1.0)) / (2.0 * n + 1.0);
          }
        }
        double w[4];
        for (int u = 0; u < 4; ++u)  // eq. 12, neighbour rate sampled like F
          w[u] = edge_rate(r, rgrid.sample(x, y, ux[u] * h, uy[u] * h, 0), p.edge_rate);
        for (int c = 0; c < 4; ++c) {
          const double fc = cur[i * 4 + c];
          double acc = fc;
          for (int u = 0; u < 4; ++u)  // eq. 11
            acc += w[u] * (fgrid.sample(x, y, ux[u] * h, uy[u] * h, c) - fc);
          next[i * 4 + c] = f16 ? to_half(acc) : acc;
        }
      }
    }
    cur.swap(next);
  }
  for (std::size_t i = 0; i < cur.size(); ++i) f.data[i] = static_cast<float>(cur[i]);
}

}  // namespace brume::cpu
