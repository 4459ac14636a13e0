// The table of formats (format.hpp): the rows in the order a read's sniff
// tries them, lookup by extension and by signature, and the integer-count
// conversion the integer rows share.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "io/formats/format.hpp"

namespace brume::io {

const std::vector<const Format*>& formats() {
  static const std::vector<const Format*> rows = {
      &pfm_format(), &png_format(), &jpeg_format(), &tiff_format(), &exr_format(), &hdr_format(),
  };
  return rows;
}

const Format* format_of_extension(const std::string& ext) {
  for (const Format* f : formats())
    if (std::find(f->extensions.begin(), f->extensions.end(), ext) != f->extensions.end()) return f;
  return nullptr;
}

const Format* format_of_file(const std::string& path) {
  unsigned char head[16] = {};
  std::ifstream in(path, std::ios::binary);
  in.read(reinterpret_cast<char*>(head), sizeof head);
  const auto n = static_cast<std::size_t>(in.gcount());
  for (const Format* f : formats())
    if (f->sniff(head, n)) return f;
  return nullptr;
}

void CountValues::reset(int bits, const std::function<float(float, int)>& map) {
  bits_ = bits;
  map_ = map;
  k_ = bits == 8 ? 1.0f / 255.0f : 1.0f / 65535.0f;
  table_.clear();
  known_.clear();
  if (bits == 8) {
    table_.resize(256);
    for (unsigned c = 0; c < 256; ++c) {
      const float v = static_cast<float>(c) * k_;
      table_[c] = map_ ? map_(v, 8) : v;
    }
  } else if (map_) {
    table_.assign(65536, 0.0f);  // [count]: its value, filled as met
    known_.assign(65536, 0);
  }
}

void CountValues::convert(const unsigned char* src, float* dst, std::size_t n, std::size_t step) {
  if (bits_ == 8) {
    for (std::size_t i = 0; i < n; ++i) dst[i * step] = table_[src[i]];
    return;
  }
  for (std::size_t i = 0; i < n; ++i) {
    std::uint16_t c;
    std::memcpy(&c, src + 2 * i, 2);
    if (!map_) {
      dst[i * step] = static_cast<float>(c) * k_;
    } else {
      if (!known_[c]) table_[c] = map_(static_cast<float>(c) * k_, 16), known_[c] = 1;
      dst[i * step] = table_[c];
    }
  }
}

void store_samples(const WriteRequest& r, std::size_t at, std::size_t n, unsigned char* dst) {
  if (r.type == Storage::u8 && r.codes) {
    std::memcpy(dst, r.codes + at, n);
  } else if (r.type == Storage::u8) {
    for (std::size_t i = 0; i < n; ++i) dst[i] = static_cast<unsigned char>(to_count(r.values[at + i], 255.0f));
  } else if (r.type == Storage::u16) {
    for (std::size_t i = 0; i < n; ++i) {
      const auto v = static_cast<std::uint16_t>(to_count(r.values[at + i], 65535.0f));
      std::memcpy(dst + 2 * i, &v, 2);
    }
  } else {
    std::memcpy(dst, r.values + at, n * sizeof(float));
  }
}

}  // namespace brume::io
