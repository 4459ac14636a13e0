// brume tests — the helpers of the tests that need only the bottom of the
// library (brume/image.hpp, brume/diffusion.hpp): an independent Gaussian
// reference, comparison statistics, a scale map, error messages. The
// engine-only build (tests/engine/: the diffusion engine and its tests, cross-
// built for aarch64 and run under qemu) compiles its tests with this header
// alone; tests/test_util.hpp includes it for every other test.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <ostream>
#include <string>

#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "brume/image.hpp"
#include "brume_reference.hpp"

namespace brume {
// Readable parameter names in test output (found by argument-dependent lookup).
inline void PrintTo(Scheme s, std::ostream* os) { *os << to_string(s); }
inline void PrintTo(Precision p, std::ostream* os) { *os << to_string(p); }
}  // namespace brume

namespace brume::test {

// The independent mirror and Gaussian references (study/reference), shared
// with `brume study`.
using reference::gaussian_reference;
using reference::reflect;

struct Diff {
  double max_abs = 0.0, rms = 0.0, psnr = 0.0;
  int worst_x = -1, worst_y = -1;
};

// Compare channels [0, nc) of a and b over the interior (border pixels excluded).
inline Diff compare(const Image& a, const Image& b, int border = 0, int nc = -1) {
  Diff d;
  if (nc < 0) nc = a.channels;
  double ss = 0.0;
  std::size_t n = 0;
  for (int y = border; y < a.height - border; ++y)
    for (int x = border; x < a.width - border; ++x)
      for (int c = 0; c < nc; ++c) {
        double e = std::abs(static_cast<double>(a.at(x, y, c)) - b.at(x, y, c));
        if (!(e <= d.max_abs)) d.max_abs = e, d.worst_x = x, d.worst_y = y;
        ss += e * e;
        ++n;
      }
  d.rms = n ? std::sqrt(ss / n) : 0.0;
  d.psnr = d.rms > 0 ? -20.0 * std::log10(d.rms) : 999.0;
  return d;
}

inline std::ostream& operator<<(std::ostream& o, const Diff& d) {
  return o << "max " << d.max_abs << " at (" << d.worst_x << ", " << d.worst_y << "), rms " << d.rms << ", psnr "
           << d.psnr << " dB";
}

// A space-variant scale map: a horizontal ramp from sigma0 to smax with a
// step in the middle rows (a depth edge).
inline Image ramp_map(int w, int h, double s0, double smax) {
  Image m(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double t = static_cast<double>(x) / (w - 1);
      if (y > h / 3 && y < 2 * h / 3) t = x < w / 2 ? 0.1 : 0.9;
      m.at(x, y) = static_cast<float>(s0 + t * (smax - s0));
    }
  return m;
}

// The message of the brume::Error f must throw (for checking that it names
// the problem); a test failure, and "", when it throws none.
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no brume::Error thrown";
  return "";
}

}  // namespace brume::test
