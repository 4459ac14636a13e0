// brume — scalar double-precision reference of the diffusion schemes.
//
// A literal transcription of eq. 11-13 and 17-18 (and the exact-variance
// offset of docs/diffusion.md) with no optimisation: one pixel at a time, every
// neighbour index mirrored, every rate and offset computed from its closed
// form (exp, not the fast path's running product). It is the oracle the fast
// path and, later, the GPU backend are tested against. f16 mode rounds the
// stored values to binary16 after every iteration, as the fast path does.
// Any channel count: channels are independent (the rates never depend on F).
#include <algorithm>
#include <cmath>
#include <vector>

#include "diffusion/half.hpp"
#include "diffusion/diffusion_kernels.hpp"
#include "diffusion/diffusion_stencil.hpp"

namespace brume::cpu {
namespace {

double to_half(double v) { return static_cast<double>(static_cast<half_t>(static_cast<float>(v))); }

// Linear interpolation of channel c of a W x H x C double image at the
// fractional column position x + d (d may be negative), row y, mirrored.
struct Grid {
  int w, h, c;
  const std::vector<double>* v;
  double at(int x, int y, int ch) const {
    return (*v)[(static_cast<std::size_t>(mirror(y, h)) * w + mirror(x, w)) * c + ch];
  }
  // The rate of the tap at (x + dx, y + dy) (brume_tap_rate in double): the
  // interpolated rate for the mean, the smaller rate of the texels the tap
  // reads for min and harmonic.
  double tap_rate(int x, int y, double dx, double dy, EdgeRate mode) const {
    const double d = dx != 0.0 ? dx : dy;
    const double fl = std::floor(d), fr = d - fl;
    const int i0 = static_cast<int>(fl);
    const double a = dx != 0.0 ? at(x + i0, y, 0) : at(x, y + i0, 0);
    const double b = dx != 0.0 ? at(x + i0 + 1, y, 0) : at(x, y + i0 + 1, 0);
    if (mode == EdgeRate::mean) return a + fr * (b - a);
    return fr > 0.0 ? std::min(a, b) : a;
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

// Eq. 11 with unit offsets and a weight per edge: the standard scheme, once
// its edge rates are formed, and the leak-free conductance of depth of field.
void diffuse_conductance_reference(Image& f, const std::vector<double>& wx, const std::vector<double>& wy,
                                   int iterations, bool f16) {
  const int W = f.width, H = f.height, C = f.channels;
  std::vector<double> cur(f.data.begin(), f.data.end()), next(cur.size());
  if (f16)
    for (double& v : cur) v = to_half(v);
  for (int k = 0; k < iterations; ++k) {
    const Grid g{W, H, C, &cur};
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        // Edges beyond the image are mirror edges: weight 0, no flux.
        const double wl = x > 0 ? wx[i - 1] : 0.0, wr = wx[i];
        const double wu = y > 0 ? wy[i - W] : 0.0, wd = wy[i];
        for (int c = 0; c < C; ++c) {
          const double v = brume_diffusion_update(cur[i * C + c], g.at(x - 1, y, c), g.at(x + 1, y, c),
                                                  g.at(x, y - 1, c), g.at(x, y + 1, c), wl, wr, wu, wd);
          next[i * C + c] = f16 ? to_half(v) : v;
        }
      }
    cur.swap(next);
  }
  for (std::size_t i = 0; i < cur.size(); ++i) f.data[i] = static_cast<float>(cur[i]);
}

void diffuse_reference(Image& f, const std::vector<double>& rho, int iterations, const DiffusionParams& p) {
  const int W = f.width, H = f.height, C = f.channels, N = iterations;
  const double s0 = p.sigma0;
  const bool f16 = p.precision == Precision::f16;

  if (p.scheme == Scheme::standard) {
    // Eq. 12: one rate per edge from its two ends (symmetric in both, so the
    // flux is antisymmetric and mass is conserved).
    std::vector<double> wx(rho.size(), 0.0), wy(rho.size(), 0.0);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        if (x + 1 < W) wx[i] = edge_rate(rho[i], rho[i + 1], p.edge_rate);
        if (y + 1 < H) wy[i] = edge_rate(rho[i], rho[i + W], p.edge_rate);
      }
    diffuse_conductance_reference(f, wx, wy, N, f16);
    return;
  }

  std::vector<double> cur(f.data.begin(), f.data.end()), next(cur.size());
  if (f16)
    for (double& v : cur) v = to_half(v);
  const Grid rgrid{W, H, 1, &rho};
  const double ux[4] = {-1, 1, 0, 0}, uy[4] = {0, 0, -1, 1};

  for (int k = 0; k < N; ++k) {
    const Grid fgrid{W, H, C, &cur};
    for (int y = 0; y < H; ++y) {
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        const double r = rho[i];
        const double sk = s0 * std::exp(k * r);  // eq. 18
        double h = sk;                           // the published offset
        if (p.scheme == Scheme::invariant_exact) {
          // 2 rho (h^2 + f(1-f)) = sk^2 (e^{2 rho} - 1); limit sk^2 at rho = 0.
          double m = r > 0.0 ? sk * sk * std::expm1(2.0 * r) / (2.0 * r) : sk * sk;
          double n = std::floor(std::sqrt(m));
          h = (m + n * (n + 1.0)) / (2.0 * n + 1.0);
        }
        double w[4];
        for (int u = 0; u < 4; ++u)  // eq. 12 with the tap's rate (brume_tap_rate)
          w[u] = edge_rate(r, rgrid.tap_rate(x, y, ux[u] * h, uy[u] * h, p.edge_rate), p.edge_rate);
        for (int c = 0; c < C; ++c) {
          double s[4];
          for (int u = 0; u < 4; ++u) s[u] = fgrid.sample(x, y, ux[u] * h, uy[u] * h, c);
          const double v = brume_diffusion_update(cur[i * C + c], s[0], s[1], s[2], s[3], w[0], w[1], w[2], w[3]);
          next[i * C + c] = f16 ? to_half(v) : v;
        }
      }
    }
    cur.swap(next);
  }
  for (std::size_t i = 0; i < cur.size(); ++i) f.data[i] = static_cast<float>(cur[i]);
}

}  // namespace brume::cpu
