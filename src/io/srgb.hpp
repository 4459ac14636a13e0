// brume — the sRGB transfer over whole images (internal): a table of the
// decode per distinct integer value (brume/io.hpp's srgb_to_linear, bit for
// bit, without a pow per value).
#pragma once

#include <cstddef>
#include <limits>
#include <vector>

#include "brume/io.hpp"

namespace brume::io {

// An integer file's values are at most 2^bits distinct floats, so the curve
// is evaluated once per distinct value and looked up after. Keyed by the
// exact float (slot: the nearest count), so any value -- a 12-bit count
// remapped by read_raw, a collision -- that is not the slot's key is
// computed and becomes it: the result is srgb_to_linear(v) bit for bit.
class SrgbDecodeTable {
 public:
  explicit SrgbDecodeTable(int bits)
      : scale_(static_cast<float>((1u << bits) - 1u)),
        key_(std::size_t(1) << bits, std::numeric_limits<float>::quiet_NaN()),
        val_(std::size_t(1) << bits, 0.0f) {}
  float operator()(float v) {
    const float s = v * scale_;
    if (!(s >= 0.0f && s <= scale_)) return srgb_to_linear(v);
    const auto k = static_cast<std::size_t>(s + 0.5f);
    if (key_[k] == v) return val_[k];  // a NaN key (empty slot) equals nothing
    const float r = srgb_to_linear(v);
    key_[k] = v;
    val_[k] = r;
    return r;
  }

 private:
  float scale_;
  std::vector<float> key_, val_;
};

}  // namespace brume::io
