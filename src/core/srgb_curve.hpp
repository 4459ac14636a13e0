// brume — the sRGB transfer curve (IEC 61966-2-1), once, in the precision of
// its argument: io's per-pixel encode and decode take it in float
// (brume/io.hpp's linear_to_srgb, srgb_to_linear), completion's guide table
// in double (src/depth/complete.cpp). Each gives the bits it gave when it
// spelled the curve out itself (the constants are converted to T first, as
// the float literals were). The browser's copy is render.js's SRGB.
#pragma once

#include <cmath>

namespace brume::detail {

template <class T>
T srgb_encode_curve(T v) {
  return v <= T(0.0031308) ? v * T(12.92) : T(1.055) * std::pow(v, T(1) / T(2.4)) - T(0.055);
}

template <class T>
T srgb_decode_curve(T v) {
  return v <= T(0.04045) ? v / T(12.92) : std::pow((v + T(0.055)) / T(1.055), T(2.4));
}

}  // namespace brume::detail
