// brume — the sRGB transfer (IEC 61966-2-1): the exact piecewise curve, and
// 8-bit encoding of whole images by a table of the curve's 255 steps.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "brume/io.hpp"
#include "core/srgb_curve.hpp"
#include "io/formats/format.hpp"

namespace brume {

float srgb_to_linear(float v) { return detail::srgb_decode_curve(v); }

float linear_to_srgb(float v) { return detail::srgb_encode_curve(v); }

namespace {

// 8-bit sRGB encoding: the code of v is to_count(linear_to_srgb(max(v, 0)),
// 255) (format.hpp: round half away from zero), a non-decreasing step
// function of v with 255 steps. Their thresholds -- the least float giving
// each code, found once by bisection over the floats' ordered bit patterns
// -- turn encoding into a few comparisons: a bucket on v's top 16 bits gives
// the code at the bucket's start, and one comparison with the next step's
// threshold the rest, with no branch on the value (a loop over the steps,
// whose exit depends on the value, took 5 % of a batch of 8-bit PNG
// frames). IO.SrgbTablesGiveThePerValueBits checks every 97th float in
// [0, 1.01] and each step's neighbours against the per-value codes.
class SrgbEncoder8 {
 public:
  static const SrgbEncoder8& get() {
    static const SrgbEncoder8 e;
    return e;
  }
  std::uint8_t operator()(float v) const {
    if (std::isnan(v)) return nan_code_;
    if (!(v > 0.0f)) return zero_code_;  // negative and -0: max(v, 0) is 0
    std::uint32_t b;
    std::memcpy(&b, &v, 4);
    const std::size_t i = b >> 16;
    if (i >= bucket_.size()) return 255;  // v >= 2 (and +inf): past the last step
    const Bucket& k = bucket_[i];
    unsigned c = k.code + (v >= k.next ? 1u : 0u);  // no branch on the data: a step is a coin toss
    if (k.more) [[unlikely]]
      while (c < 255 && v >= threshold_[c + 1]) ++c;
    return static_cast<std::uint8_t>(c);
  }

 private:
  // The per-value codes of v.
  static std::vector<std::uint8_t> slow(const std::vector<float>& v) {
    std::vector<std::uint8_t> c(v.size());
    for (std::size_t i = 0; i < v.size(); ++i)
      c[i] = static_cast<std::uint8_t>(io::to_count(linear_to_srgb(std::max(v[i], 0.0f)), 255.0f));
    return c;
  }
  static float from_bits(std::uint32_t b) {
    float f;
    std::memcpy(&f, &b, 4);
    return f;
  }
  SrgbEncoder8() {
    const std::vector<std::uint8_t> ends = slow({std::numeric_limits<float>::quiet_NaN(), 0.0f});
    nan_code_ = ends[0];
    zero_code_ = ends[1];
    const std::uint32_t top = 0x40000000u;  // 2.0f, whose code is 255
    // All 255 bisections in step: lo[k] < threshold <= hi[k] (slow(lo) < k <= slow(hi)).
    std::vector<std::uint32_t> lo(256, 0), hi(256, top);
    for (int step = 0; step < 32; ++step) {
      std::vector<float> mid(256);
      for (unsigned k = 0; k < 256; ++k) mid[k] = from_bits(lo[k] + (hi[k] - lo[k]) / 2);
      const std::vector<std::uint8_t> c = slow(mid);
      for (unsigned k = zero_code_ + 1u; k < 256; ++k) {
        if (hi[k] - lo[k] <= 1) continue;
        const std::uint32_t m = lo[k] + (hi[k] - lo[k]) / 2;
        (c[k] >= k ? hi[k] : lo[k]) = m;
      }
    }
    threshold_.assign(256, 0.0f);
    for (unsigned k = zero_code_ + 1u; k < 256; ++k) threshold_[k] = from_bits(hi[k]);
    std::vector<float> starts((top >> 16) + 1);
    for (std::size_t i = 0; i < starts.size(); ++i) starts[i] = from_bits(static_cast<std::uint32_t>(i << 16));
    const std::vector<std::uint8_t> start = slow(starts);
    bucket_.resize(starts.size());
    for (std::size_t i = 0; i < starts.size(); ++i) {
      Bucket& k = bucket_[i];
      k.code = start[i];
      k.next = k.code < 255 ? threshold_[k.code + 1] : std::numeric_limits<float>::infinity();
      // A bucket spans 2^-7 of its floats' magnitude and the codes' steps
      // are at least 0.89 % of theirs apart (1/(255 x 0.44), the curve's
      // largest v d(srgb)/dv), so no bucket holds two steps; `more` keeps
      // the result exact were one to.
      const float last = from_bits(static_cast<std::uint32_t>((i << 16) | 0xffffu));
      k.more = k.code < 254 && i + 1 < starts.size() && last >= threshold_[k.code + 2];
    }
  }
  // The code at a bucket's first float, and the threshold of the next step.
  struct Bucket {
    float next;
    std::uint8_t code;
    bool more;  // the bucket holds a second step (none does; see above)
  };
  std::uint8_t nan_code_ = 0, zero_code_ = 0;
  std::vector<float> threshold_;  // [k]: the least float whose code is >= k
  std::vector<Bucket> bucket_;    // [b >> 16]
};

}  // namespace

void srgb_encode_8(const float* v, std::uint8_t* out, std::size_t n) {
  const SrgbEncoder8& e = SrgbEncoder8::get();
  for (std::size_t i = 0; i < n; ++i) out[i] = e(v[i]);
}

}  // namespace brume
