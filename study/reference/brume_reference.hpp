// brume — independent double-precision references shared by the tests and the
// study (internal, header only, never installed).
//
// Written apart from the library on purpose: a fast path is only checked if
// its reference shares none of its code, so nothing here includes src/.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

#include "brume/image.hpp"

namespace brume::reference {

// Half-sample mirror of an index into [0, n): ... 1 0 | 0 1 ... n-1 | n-1 n-2 ...
inline int reflect(int i, int n) {
  while (i < 0 || i >= n) i = i < 0 ? -1 - i : 2 * n - 1 - i;
  return i;
}

// True Gaussian convolution in double precision: sampled kernel of radius
// ceil(5 sigma) (truncation < 6e-7 of the mass), normalised, separable, with
// the half-sample mirror boundary. Channels [0, nc) are blurred independently
// (nc < 0: all of them); the others are copied from the input. Each output
// value is one fixed-order sum, so the threads do not change the result.
inline Image gaussian_reference(const Image& in, double sigma, int nc = -1) {
  const int W = in.width, H = in.height, C = in.channels;
  if (sigma <= 0.0) return in;
  if (nc < 0 || nc > C) nc = C;
  const int r = static_cast<int>(std::ceil(5.0 * sigma));
  std::vector<double> k(2 * r + 1);
  double sum = 0.0;
  for (int i = -r; i <= r; ++i) sum += k[i + r] = std::exp(-0.5 * i * i / (sigma * sigma));
  for (double& v : k) v /= sum;
  std::vector<double> tmp(in.data.size());
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < nc; ++c) {
        double a = 0.0;
        for (int i = -r; i <= r; ++i)
          a += k[i + r] * in.data[(static_cast<std::size_t>(y) * W + reflect(x + i, W)) * C + c];
        tmp[(static_cast<std::size_t>(y) * W + x) * C + c] = a;
      }
  Image out = in;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < nc; ++c) {
        double a = 0.0;
        for (int i = -r; i <= r; ++i)
          a += k[i + r] * tmp[(static_cast<std::size_t>(reflect(y + i, H)) * W + x) * C + c];
        out.data[(static_cast<std::size_t>(y) * W + x) * C + c] = static_cast<float>(a);
      }
  return out;
}

}  // namespace brume::reference
