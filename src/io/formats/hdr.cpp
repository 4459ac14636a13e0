// Radiance HDR (RGBE), read and written by brume itself: a text header and
// run-length coded RGBE pixels, which no Debian library reads better, and
// `brume sky fit`'s sky photos are such files.
//  - read: the magic line "#?RADIANCE" or "#?RGBE", header lines up to an
//    empty line (FORMAT, if given, 32-bit_rle_rgbe; other variables and
//    comments change no value), the resolution line "-Y H +X W" (rows top to
//    bottom), then every scanline run-length coded (the "2 2 hi lo" form, for
//    8 <= W < 32768) or, when the first scanline is not, the whole image
//    stored flat, four bytes a pixel. Values (m_R, m_G, m_B) x 2^(e - 136)
//    for e > 0, else 0 (Walter's rgbe2float, as OpenImageIO reads them):
//    exact in float. FileInfo: format "hdr", 32-bit float, R G B. Anything
//    else (XYZE, another orientation, the old run-length form, a malformed
//    scanline, bytes after the image) goes to OpenImageIO.
//  - write: RGB whose values are all >= 0 or NaN (a sky render's ground is
//    NaN): the header "#?RADIANCE", "FORMAT=32-bit_rle_rgbe", "-Y H +X W";
//    each pixel by Walter's float2rgbe (frexp of the largest component);
//    scanlines of 8 to 32767 px run-length coded component by component
//    (runs of 4 or more, at most 127; literal stretches of at most 128),
//    others flat. Negative or infinite values, which RGBE cannot hold, are
//    an error naming the first (never clamped).
// Tests: IO.Hdr* (tests/io/test_hdr.cpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "io/formats/format.hpp"

namespace brume::io {
namespace hdr_row {
// One RGBE pixel to floats: Walter's rgbe2float.
inline void rgbe_to_float(const unsigned char* p, float* out) {
  if (p[3] == 0) {
    out[0] = out[1] = out[2] = 0.0f;
    return;
  }
  const float f = std::ldexp(1.0f, static_cast<int>(p[3]) - (128 + 8));
  out[0] = static_cast<float>(p[0]) * f;
  out[1] = static_cast<float>(p[1]) * f;
  out[2] = static_cast<float>(p[2]) * f;
}

// The header: returns the offset of the first pixel byte, or 0 when the
// file is outside the subset.
std::size_t parse_header(const std::string& b, int& W, int& H) {
  std::size_t i = 0;
  auto line = [&](std::string& l) {
    const std::size_t e = b.find('\n', i);
    if (e == std::string::npos) return false;
    l.assign(b, i, e - i);
    i = e + 1;
    return true;
  };
  std::string l;
  if (!line(l) || (l != "#?RADIANCE" && l != "#?RGBE")) return 0;
  for (;;) {
    if (!line(l)) return 0;
    if (l.empty()) break;
    if (l.rfind("FORMAT=", 0) == 0 && l != "FORMAT=32-bit_rle_rgbe") return 0;
  }
  if (!line(l)) return 0;
  char ys[3], xs[3], tail;
  long h = 0, w = 0;
  if (std::sscanf(l.c_str(), "%2s %ld %2s %ld%c", ys, &h, xs, &w, &tail) != 4) return 0;
  if (std::strcmp(ys, "-Y") != 0 || std::strcmp(xs, "+X") != 0 || h < 1 || w < 1 || h > (1 << 30) || w > (1 << 30))
    return 0;
  // Digits only (no sign, spaces as written by every writer seen).
  if (l != "-Y " + std::to_string(h) + " +X " + std::to_string(w)) return 0;
  W = static_cast<int>(w);
  H = static_cast<int>(h);
  return i;
}

// One run-length coded scanline (each of the four components in turn: a
// count byte > 128 repeats the next byte count - 128 times, else that many
// bytes follow) into `row` (4 bytes a pixel). Returns the offset after it,
// or 0 when malformed.
std::size_t rle_scanline(const std::string& b, std::size_t i, int W, unsigned char* row) {
  if (i + 4 > b.size()) return 0;
  const auto* u = reinterpret_cast<const unsigned char*>(b.data());
  if (u[i] != 2 || u[i + 1] != 2 || (u[i + 2] & 0x80) || ((u[i + 2] << 8) | u[i + 3]) != W) return 0;
  i += 4;
  for (int c = 0; c < 4; ++c) {
    int x = 0;
    while (x < W) {
      if (i >= b.size()) return 0;
      int n = u[i++];
      if (n > 128) {
        n -= 128;
        if (n > W - x || i >= b.size()) return 0;
        const unsigned char v = u[i++];
        for (int k = 0; k < n; ++k) row[(x + k) * 4 + c] = v;
      } else {
        if (n == 0 || n > W - x || i + static_cast<std::size_t>(n) > b.size()) return 0;
        for (int k = 0; k < n; ++k) row[(x + k) * 4 + c] = u[i + k];
        i += static_cast<std::size_t>(n);
      }
      x += n;
    }
  }
  return i;
}

// out == nullptr: the header only, from the file's first 64 KiB (a header
// longer than that is left to OpenImageIO).
bool read_hdr(const std::string& path, Image* out, int& width, int& height,
              const std::function<void(int, int, int)>& check) {
  std::string b;
  {
    std::ifstream f(path, std::ios::binary);
    char magic[2];
    if (!f.read(magic, 2) || magic[0] != '#' || magic[1] != '?') return false;
    f.seekg(0);
    if (out) {
      b.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
      if (!f.eof() && f.fail()) return false;
    } else {
      b.resize(64 * 1024);
      f.read(b.data(), static_cast<std::streamsize>(b.size()));
      b.resize(static_cast<std::size_t>(f.gcount()));
    }
  }
  int W = 0, H = 0;
  std::size_t i = parse_header(b, W, H);
  if (i == 0) return false;
  check(W, H, 3);
  if (!out) {
    width = W, height = H;
    return true;
  }
  Image img(W, H, 3);
  std::vector<unsigned char> row(static_cast<std::size_t>(W) * 4);
  const auto* u = reinterpret_cast<const unsigned char*>(b.data());
  const bool rle = W >= 8 && W < 32768 && i + 4 <= b.size() && u[i] == 2 && u[i + 1] == 2 && !(u[i + 2] & 0x80);
  if (!rle) {
    // Flat: four bytes a pixel, exactly the image's.
    const std::size_t n = static_cast<std::size_t>(W) * static_cast<std::size_t>(H);
    if (b.size() - i != n * 4) return false;
    for (std::size_t k = 0; k < n; ++k) rgbe_to_float(u + i + 4 * k, img.data.data() + 3 * k);
  } else {
    for (int y = 0; y < H; ++y) {
      i = rle_scanline(b, i, W, row.data());
      if (i == 0) return false;
      float* o = img.data.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(W) * 3;
      for (int x = 0; x < W; ++x) rgbe_to_float(row.data() + 4 * x, o + 3 * x);
    }
    if (i != b.size()) return false;  // bytes after the image: left to OpenImageIO
  }
  width = W, height = H;
  *out = std::move(img);
  return true;
}

// Walter's float2rgbe: the largest component's frexp sets the exponent.
// NaN takes the path it takes there (comparisons with it are false): a NaN
// red makes the pixel (0, 0, 0, 128) -- frexp's exponent of NaN is 0 in
// glibc -- and any other NaN component a 0 byte, which is what the cast of
// a NaN gives on x86-64 (the low byte of 0x80000000) and arm64 (0);
// written out here rather than left to the cast, which is undefined for
// NaN in C++. (Negative values, where the two differ, are not in the subset.)
inline unsigned char rgbe_byte(float x) { return std::isnan(x) ? 0 : static_cast<unsigned char>(x); }
inline void float_to_rgbe(const float* c, unsigned char* p) {
  float v = c[0];
  if (c[1] > v) v = c[1];
  if (c[2] > v) v = c[2];
  if (v < 1e-32) {
    p[0] = p[1] = p[2] = p[3] = 0;
    return;
  }
  int e = 0;
  if (!std::isnan(v)) v = static_cast<float>(std::frexp(v, &e) * 256.0 / v);
  p[0] = rgbe_byte(c[0] * v);
  p[1] = rgbe_byte(c[1] * v);
  p[2] = rgbe_byte(c[2] * v);
  p[3] = static_cast<unsigned char>(e + 128);
}

// Walter's RGBE_WriteBytes_RLE: one component of a scanline.
void rle_bytes(const unsigned char* data, int n, std::string& out) {
  constexpr int kMinRun = 4;
  int cur = 0;
  while (cur < n) {
    int beg = cur, run = 0, old_run = 0;
    // The next run of at least kMinRun, if any.
    while (run < kMinRun && beg < n) {
      beg += run;
      old_run = run;
      run = 1;
      while (beg + run < n && run < 127 && data[beg] == data[beg + run]) ++run;
    }
    // A short run just before it is written as a run.
    if (old_run > 1 && old_run == beg - cur) {
      out += static_cast<char>(128 + old_run);
      out += static_cast<char>(data[cur]);
      cur = beg;
    }
    // The bytes up to the run, in stretches of at most 128.
    while (cur < beg) {
      const int m = std::min(beg - cur, 128);
      out += static_cast<char>(m);
      out.append(reinterpret_cast<const char*>(data + cur), static_cast<std::size_t>(m));
      cur += m;
    }
    if (run >= kMinRun) {
      out += static_cast<char>(128 + run);
      out += static_cast<char>(data[beg]);
      cur += run;
    }
  }
}


bool write_hdr(const std::string& path, int width, int height, const float* px) {
  std::string out = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y " + std::to_string(height) + " +X " +
                    std::to_string(width) + "\n";
  const std::size_t W = static_cast<std::size_t>(width);
  std::vector<unsigned char> rgbe(W * 4), comp(W);
  for (int y = 0; y < height; ++y) {
    const float* row = px + static_cast<std::size_t>(y) * W * 3;
    for (std::size_t x = 0; x < W; ++x) float_to_rgbe(row + 3 * x, rgbe.data() + 4 * x);
    if (width < 8 || width > 0x7fff) {
      out.append(reinterpret_cast<const char*>(rgbe.data()), rgbe.size());
      continue;
    }
    out += static_cast<char>(2);
    out += static_cast<char>(2);
    out += static_cast<char>(width >> 8);
    out += static_cast<char>(width & 0xff);
    for (int c = 0; c < 4; ++c) {
      for (std::size_t x = 0; x < W; ++x) comp[x] = rgbe[4 * x + static_cast<std::size_t>(c)];
      rle_bytes(comp.data(), width, out);
    }
  }
  std::ofstream f(path, std::ios::binary);
  f.write(out.data(), static_cast<std::streamsize>(out.size()));
  f.close();
  if (!f) return false;
  return true;
}

bool sniff(const unsigned char* h, std::size_t n) { return n >= 2 && h[0] == '#' && h[1] == '?'; }

bool header(const std::string& path, Header& out) {
  int w = 0, h = 0;
  if (!read_hdr(path, nullptr, w, h, [](int, int, int) {})) return false;
  out = {w, h, 3};
  return true;
}

bool read(const ReadRequest& r, Decoded& out) {
  int w = 0, h = 0;
  if (!read_hdr(r.path, &out.img, w, h, r.check)) return false;
  out.info.format = "hdr";
  out.info.integer = false;
  out.info.bits = 32;
  out.info.channel_names = {"R", "G", "B"};
  return true;
}

std::string refuse(const WriteRequest& r) {
  if (r.srgb) return "Radiance HDR holds linear values; drop --out-transfer srgb or write .exr";
  const std::size_t n = static_cast<std::size_t>(r.width) * static_cast<std::size_t>(r.height) * 3;
  for (std::size_t i = 0; i < n; ++i)
    if (r.values[i] < 0.0f || r.values[i] > 3.4028235e38f)  // NaN passes; -x, inf not
    {
      char v[32];
      std::snprintf(v, sizeof v, "%g", static_cast<double>(r.values[i]));
      return "Radiance HDR (RGBE) holds no negative or infinite values, and pixel (" +
             std::to_string(i / 3 % static_cast<std::size_t>(r.width)) + ", " +
             std::to_string(i / 3 / static_cast<std::size_t>(r.width)) + ") is " + v +
             "; write .exr, .pfm or .tif (float), which hold any value";
    }
  return {};
}

bool write(const std::string& tmp, const WriteRequest& r, std::string*) { return write_hdr(tmp, r.width, r.height, r.values); }
}  // namespace hdr_row

const Format& hdr_format() {
  using namespace hdr_row;
  static const Format f{.name = "hdr", .title = "Radiance HDR", .extensions = {".hdr"}, .bits = {"float"},
                        .color_bits = "float", .data_bits = "float", .compressions = {{"rle", 1, 0, false}},
                        .channel_counts = {3}, .holds_data = false, .sniff = sniff, .header = header, .read = read,
                        .refuse = refuse, .write = write, .auto_is = "rle"};
  return f;
}

}  // namespace brume::io
