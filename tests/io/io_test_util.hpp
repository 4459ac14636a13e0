// Shared by the image I/O tests (tests/io/): a fixed pseudo-random sequence,
// a scratch folder, an independent PFM parser, test images and OpenImageIO
// as the peer reader.
#pragma once
#include <OpenImageIO/imageio.h>
#include <png.h>
#include <tiffio.h>
#include <zlib.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <tuple>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace brume::test_io {
// The tests' pseudo-random numbers: the 32-bit LCG of Numerical Recipes'
// ranqd1, so that every run draws the same values. next(): the new state;
// unit(): its top 24 bits as a float in [0, 1).
struct Lcg {
  std::uint32_t s;
  std::uint32_t next() { return s = s * 1664525u + 1013904223u; }
  float unit() { return static_cast<float>(next() >> 8) / 16777216.0f; }
};

inline fs::path tmpdir() {
  fs::path d = fs::temp_directory_path() / ("brume_test_io_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// Independent PFM reader: header "Pf"/"PF", "W H", scale (negative = little
// endian), then rows from the bottom of the picture to the top.
inline Image parse_pfm(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string magic;
  int w, h;
  double scale;
  in >> magic >> w >> h >> scale;
  in.get();
  const int c = magic == "PF" ? 3 : 1;
  Image im(w, h, c);
  std::vector<unsigned char> row(static_cast<std::size_t>(w) * c * 4);
  for (int y = h - 1; y >= 0; --y) {
    in.read(reinterpret_cast<char*>(row.data()), static_cast<std::streamsize>(row.size()));
    for (int i = 0; i < w * c; ++i) {
      unsigned char b[4];
      std::memcpy(b, &row[i * 4], 4);
      if (scale > 0) std::swap(b[0], b[3]), std::swap(b[1], b[2]);
      float v;
      std::memcpy(&v, b, 4);
      im.data[(static_cast<std::size_t>(y) * w) * c + i] = v;
    }
  }
  return im;
}

inline Image gradient(int w, int h, int c) {
  Image im(w, h, c);
  // Smooth, so that lossy JPEG is measured on content it is meant for.
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k)
        im.at(x, y, k) = 0.6f * x / (w - 1) + 0.3f * y / (h - 1) + 0.05f * k;
  return im;
}

// Every channel of a file as OpenImageIO reads it, as floats (the peer of
// brume's own readers); its spec and format name through the pointers.
inline std::vector<float> oiio_pixels(const std::string& p, OIIO::ImageSpec* spec = nullptr, std::string* format = nullptr) {
  auto in = OIIO::ImageInput::open(p);
  EXPECT_TRUE(in) << p;
  if (!in) return {};
  const OIIO::ImageSpec& s = in->spec();
  if (spec) *spec = s;
  if (format) *format = in->format_name();
  std::vector<float> v(static_cast<std::size_t>(s.width) * s.height * s.nchannels);
  EXPECT_TRUE(in->read_image(0, 0, 0, s.nchannels, OIIO::TypeDesc::FLOAT, v.data())) << p;
  return v;
}

// The entries of a classic little-endian TIFF directory at `at`: tag, type,
// count and the value's bytes (inline or where its offset points).
struct TiffEntry {
  unsigned tag, type;
  std::uint32_t count;
  std::string value;
};
inline std::vector<TiffEntry> tiff_ifd(const std::string& b, std::uint32_t at) {
  auto u16 = [&](std::size_t i) { return static_cast<unsigned>(static_cast<unsigned char>(b[i]) | static_cast<unsigned char>(b[i + 1]) << 8); };
  auto u32 = [&](std::size_t i) { return static_cast<std::uint32_t>(u16(i) | u16(i + 2) << 16); };
  std::vector<TiffEntry> v;
  if (at + 2 > b.size()) return v;
  const unsigned n = u16(at);
  for (unsigned k = 0; k < n && at + 2 + 12 * (k + 1) <= b.size(); ++k) {
    const std::size_t e = at + 2 + 12 * k;
    TiffEntry t{u16(e), u16(e + 2), u32(e + 4), {}};
    const std::size_t size = t.type == 3 ? 2 : t.type == 4 || t.type == 13 ? 4 : t.type == 5 ? 8 : 1;
    const std::size_t len = size * t.count, where = len <= 4 ? e + 8 : u32(e + 8);
    if (where + len <= b.size()) t.value = b.substr(where, len);
    v.push_back(t);
  }
  return v;
}
inline std::vector<std::uint32_t> tiff_longs(const TiffEntry& e) {
  std::vector<std::uint32_t> v;
  const std::size_t size = e.type == 3 ? 2 : 4;
  for (std::size_t i = 0; i + size <= e.value.size(); i += size) {
    std::uint32_t x = 0;
    std::memcpy(&x, e.value.data() + i, size);
    v.push_back(x);
  }
  return v;
}

// The file OpenImageIO writes for what brume's general write path gives it
// (image_io.cpp, OutputSet::write): the storage type, Y for one channel,
// the colour space, the description, the compression attributes; 8-bit
// sRGB as brume's own codes, other sRGB values encoded first, else the
// floats.
inline void oiio_write_as_brume(const fs::path& path, const Image& img, OIIO::TypeDesc type, bool srgb,
                         const std::string& desc, const std::string& compression) {
  OIIO::ImageSpec spec(img.width, img.height, img.channels, type);
  if (img.channels == 1) spec.channelnames = {"Y"};
  spec.attribute("oiio:ColorSpace", srgb ? "sRGB" : "linear");
  if (!desc.empty()) spec.attribute("ImageDescription", desc);
  if (compression != "auto") spec.attribute("compression", compression);
  const std::string e = path.extension().string();
  if ((e == ".tif" || e == ".tiff") && compression.rfind("zip:", 0) == 0)
    spec.attribute("tiff:zipquality", std::stoi(compression.substr(4)));
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), spec)) << path;
  if (srgb && type == OIIO::TypeDesc::UINT8) {
    std::vector<std::uint8_t> codes(img.data.size());
    srgb_encode_8(img.data.data(), codes.data(), codes.size());
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, codes.data())) << path;
  } else {
    std::vector<float> v = img.data;
    if (srgb)
      for (float& x : v) x = linear_to_srgb(std::max(x, 0.0f));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, v.data())) << path;
  }
  ASSERT_TRUE(out->close()) << path;
}

// A subset reader's image against OpenImageIO's reading of the same file:
// the size and every value's bits.
inline void expect_oiio_image(const std::string& p, const Image& got, const OIIO::ImageSpec& spec,
                       const std::vector<float>& want) {
  EXPECT_EQ(got.width, spec.width) << p;
  EXPECT_EQ(got.height, spec.height) << p;
  EXPECT_EQ(got.channels, spec.nchannels) << p;
  EXPECT_TRUE(got.data.size() == want.size() && std::memcmp(got.data.data(), want.data(), want.size() * 4) == 0)
      << p << ": other values than OpenImageIO's";
}

// The public readers on a file of a subset take the subset path once (the
// subset's counter, `reads`, moves by one) and give its image `got`:
// read_scalar for one channel (an integer file's counts: count_max > 0),
// read_color for three. Returns their FileInfo.
inline FileInfo expect_public_read(const std::string& p, const Image& got, double count_max,
                            std::uint64_t (*reads)()) {
  const std::uint64_t before = reads();
  FileInfo fi;
  const Image pub = got.channels == 1 ? read_scalar(p, "", &fi) : read_color(p, Transfer::linear, &fi);
  EXPECT_EQ(reads(), before + 1) << p;
  std::vector<float> expect = got.data;
  if (got.channels == 1 && count_max > 0)
    for (float& v : expect) v = static_cast<float>(std::nearbyint(v * count_max));
  EXPECT_TRUE(pub.data.size() == expect.size() && std::memcmp(pub.data.data(), expect.data(), expect.size() * 4) == 0)
      << p;
  return fi;
}

inline std::string file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// A PNG written with libpng by hand (the shapes OpenImageIO's writer does
// not make: interlaced, palette, 1-bit, tRNS, one row filter forced, small
// IDAT chunks), values row-major (16 bits: big-endian). filters: libpng's
// PNG_FILTER_* mask (0: its default); idat_bytes: the zlib output per IDAT
// chunk (0: its default, 8192).
inline void write_png_by_hand(const std::string& p, int w, int h, int depth, int color, bool interlace,
                       const std::vector<unsigned char>& bytes, bool trns = false, int filters = 0,
                       std::size_t idat_bytes = 0) {
  std::FILE* f = std::fopen(p.c_str(), "wb");
  ASSERT_TRUE(f) << p;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  ASSERT_EQ(setjmp(png_jmpbuf(png)), 0) << p;
  png_init_io(png, f);
  if (filters) png_set_filter(png, PNG_FILTER_TYPE_BASE, filters);
  if (idat_bytes) png_set_compression_buffer_size(png, idat_bytes);
  png_set_IHDR(png, info, w, h, depth, color, interlace ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_color palette[4] = {{0, 0, 0}, {255, 0, 0}, {0, 255, 0}, {10, 20, 30}};
  if (color == PNG_COLOR_TYPE_PALETTE) png_set_PLTE(png, info, palette, 4);
  png_color_16 t{};
  t.gray = 3;
  if (trns) png_set_tRNS(png, info, nullptr, 0, &t);
  png_write_info(png, info);
  const std::size_t rowbytes = png_get_rowbytes(png, info);
  std::vector<png_bytep> rows(h);
  std::vector<unsigned char> copy = bytes;  // libpng takes non-const rows
  for (int y = 0; y < h; ++y) rows[y] = copy.data() + y * rowbytes;
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  std::fclose(f);
}

}  // namespace brume::test_io

