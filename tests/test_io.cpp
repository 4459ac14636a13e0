// File I/O: PFM against an independent parser, round trips through every
// format, named EXR channels, raw integer counts, sRGB, and error paths.
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
#include "io/exr_direct.hpp"
#include "io/hdr_direct.hpp"
#include "io/jpeg_direct.hpp"
#include "io/png_direct.hpp"
#include "io/tiff_direct.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {
// The tests' pseudo-random numbers: the 32-bit LCG of Numerical Recipes'
// ranqd1, so that every run draws the same values. next(): the new state;
// unit(): its top 24 bits as a float in [0, 1).
struct Lcg {
  std::uint32_t s;
  std::uint32_t next() { return s = s * 1664525u + 1013904223u; }
  float unit() { return static_cast<float>(next() >> 8) / 16777216.0f; }
};

fs::path tmpdir() {
  fs::path d = fs::temp_directory_path() / ("brume_test_io_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// Independent PFM reader: header "Pf"/"PF", "W H", scale (negative = little
// endian), then rows from the bottom of the picture to the top.
Image parse_pfm(const std::string& path) {
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

Image gradient(int w, int h, int c) {
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
std::vector<float> oiio_pixels(const std::string& p, OIIO::ImageSpec* spec = nullptr, std::string* format = nullptr) {
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
std::vector<TiffEntry> tiff_ifd(const std::string& b, std::uint32_t at) {
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
std::vector<std::uint32_t> tiff_longs(const TiffEntry& e) {
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
void oiio_write_as_brume(const fs::path& path, const Image& img, OIIO::TypeDesc type, bool srgb,
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
void expect_oiio_image(const std::string& p, const Image& got, const OIIO::ImageSpec& spec,
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
FileInfo expect_public_read(const std::string& p, const Image& got, double count_max,
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

}  // namespace

TEST(IO, PfmMatchesIndependentParserOnEth3d) {
  const std::string rel = "eth3d_two_view/playground_1l/disp0.pfm";
  BRUME_REQUIRE_DATA(rel);
  Image a = read_scalar(data_path(rel));
  Image b = parse_pfm(data_path(rel));
  ASSERT_EQ(a.width, 941);
  ASSERT_EQ(a.height, 490);
  ASSERT_EQ(a.width, b.width);
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    if (std::isinf(b.data[i])) {
      ASSERT_TRUE(std::isinf(a.data[i])) << i;
    } else {
      ASSERT_EQ(a.data[i], b.data[i]) << "pixel " << i;
    }
  }
}

TEST(IO, SrgbTransferKnownValues) {
  EXPECT_NEAR(srgb_to_linear(0.5f), 0.214041f, 1e-6);
  EXPECT_NEAR(srgb_to_linear(0.04045f), 0.0031308f, 1e-7);
  for (float v : {0.0f, 0.001f, 0.1f, 0.5f, 0.99f, 1.0f}) EXPECT_NEAR(linear_to_srgb(srgb_to_linear(v)), v, 1e-6);
}

TEST(IO, RoundTripsEveryFormat) {
  // Tolerances: float formats are exact; half EXR keeps 11 bits (rel 2^-11);
  // 16-bit PNG/TIFF quantise sRGB codes to 1/65535 (linear error < 1e-4
  // after decoding); 8-bit to 1/255; RGBE keeps 8 mantissa bits (rel 1 %);
  // JPEG is lossy.
  fs::path d = tmpdir();
  Image rgb = gradient(37, 23, 3);
  struct Case {
    const char* name;
    const char* bits;
    double tol;
  };
  for (Case c : {Case{"a.exr", "float", 0.0}, Case{"b.pfm", "float", 0.0}, Case{"c.tif", "float", 0.0},
                 Case{"d.exr", "half", 5e-4}, Case{"e.png", "16", 1e-4}, Case{"f.tif", "16", 1e-4},
                 Case{"g.png", "8", 1e-2}, Case{"h.hdr", "float", 1e-2}, Case{"i.jpg", "8", 0.03}}) {
    WriteOptions o;
    o.bits = c.bits;
    const std::string p = (d / c.name).string();
    write_image(p, rgb, o);
    FileInfo info;
    Image back = read_color(p, Transfer::automatic, &info);
    ASSERT_EQ(back.width, rgb.width) << c.name;
    Diff df = compare(back, rgb);
    EXPECT_LE(df.max_abs, c.tol) << c.name << ": " << df;
  }
  // One-channel data maps are never sRGB-encoded.
  Image m = gradient(19, 11, 1);
  WriteOptions data;
  data.is_color = false;
  for (const char* name : {"m.exr", "m.pfm", "m.tif"}) {
    write_image((d / name).string(), m, data);
    Image back = read_scalar((d / name).string());
    EXPECT_EQ(back.data, m.data) << name;
  }
  fs::remove_all(d);
}

TEST(IO, ExrNamedChannelAndIntegerCounts) {
  fs::path d = tmpdir();
  // A render-style EXR with R, G, B and Z channels.
  {
    OIIO::ImageSpec spec(5, 4, 4, OIIO::TypeDesc::FLOAT);
    spec.channelnames = {"R", "G", "B", "Z"};
    std::vector<float> px(5 * 4 * 4);
    for (int i = 0; i < 20; ++i) px[i * 4 + 3] = 10.0f + i, px[i * 4] = 0.5f;
    auto out = OIIO::ImageOutput::create((d / "render.exr").string());
    ASSERT_TRUE(out->open((d / "render.exr").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data()));
    out->close();
  }
  Image z = read_scalar((d / "render.exr").string(), "Z");
  for (int i = 0; i < 20; ++i) EXPECT_EQ(z.data[i], 10.0f + i);
  try {
    read_scalar((d / "render.exr").string(), "depth");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("R, G, B, Z"), std::string::npos) << e.what();
  }
  EXPECT_THROW(read_scalar((d / "render.exr").string()), Error);  // ambiguous: channels differ

  // 16-bit PNG counts come back as raw integers (e.g. millimetres).
  {
    OIIO::ImageSpec spec(3, 2, 1, OIIO::TypeDesc::UINT16);
    std::vector<uint16_t> px = {0, 1, 1000, 5000, 65534, 65535};
    auto out = OIIO::ImageOutput::create((d / "mm.png").string());
    ASSERT_TRUE(out->open((d / "mm.png").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, px.data()));
    out->close();
  }
  FileInfo info;
  Image mm = read_scalar((d / "mm.png").string(), "", &info);
  EXPECT_TRUE(info.integer);
  EXPECT_EQ(info.bits, 16);
  std::vector<float> want = {0, 1, 1000, 5000, 65534, 65535};
  EXPECT_EQ(mm.data, want);
  fs::remove_all(d);
}

TEST(IO, FloatDataIsNeverWrittenToIntegerStorage) {
  // Data outside [0, 1] (metres, pixels) with a float_reason: every integer
  // storage (PNG, JPEG, 8/16-bit TIFF, whatever the extension's case) and
  // Radiance HDR are refused with the reason; float files are accepted.
  fs::path d = tmpdir();
  WriteOptions o;
  o.is_color = false;
  o.float_reason = "metres";
  for (const char* bad : {"a.png", "a.PNG", "a.jpeg", "a.hdr"})
    EXPECT_THROW(check_writable((d / bad).string(), o, "--out"), Error) << bad;
  WriteOptions o16 = o;
  o16.bits = "16";
  EXPECT_THROW(check_writable((d / "a.tif").string(), o16, "--out"), Error);
  for (const char* good : {"a.exr", "a.pfm", "a.tif", "a.TIFF"})
    EXPECT_NO_THROW(check_writable((d / good).string(), o, "--out")) << good;
  fs::remove_all(d);
}

TEST(IO, ExplicitSrgbTransferAppliesToPfmToo) {
  // --out-transfer srgb on a float file stores encoded values; the PFM writer
  // (brume's own) must store the same values as the OpenImageIO formats.
  fs::path d = tmpdir();
  WriteOptions o;
  o.transfer = Transfer::srgb;
  const Image img(4, 3, 3, 0.25f);
  write_image((d / "e.pfm").string(), img, o);
  write_image((d / "e.exr").string(), img, o);
  const float want = linear_to_srgb(0.25f);
  EXPECT_FLOAT_EQ(read_color((d / "e.pfm").string(), Transfer::linear).at(1, 1, 0), want);
  EXPECT_FLOAT_EQ(read_color((d / "e.exr").string(), Transfer::linear).at(1, 1, 0), want);
  fs::remove_all(d);
}

TEST(IO, ErrorsNameTheFile) {
  fs::path d = tmpdir();
  try {
    read_color((d / "missing.png").string());
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing.png"), std::string::npos);
  }
  // A truncated PNG.
  write_image((d / "whole.png").string(), gradient(64, 64, 3), WriteOptions{});
  {
    std::ifstream in(d / "whole.png", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), {});
    std::ofstream out(d / "cut.png", std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
  }
  try {
    read_color((d / "cut.png").string());
    FAIL() << "truncated file was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cut.png"), std::string::npos) << e.what();
  }
  // Unwritable output: nothing is left behind, not even a temporary.
  EXPECT_THROW(write_image((d / "no" / "such" / "dir.png").string(), gradient(4, 4, 3), WriteOptions{}), Error);
  // An OutputSet that is never committed removes its temporaries.
  {
    OutputSet s;
    s.write((d / "never.png").string(), gradient(4, 4, 3), WriteOptions{}, "--out");
  }
  for (auto& e : fs::directory_iterator(d)) {
    const std::string n = e.path().filename().string();
    EXPECT_TRUE(n == "whole.png" || n == "cut.png") << "left behind: " << n;
  }
  fs::remove_all(d);
}

// --compression reaches OpenImageIO's writer: the file says so when read back
// (EXR and TIFF name their compression; PNG's deflate level shows only in the
// size), lossless forms give exactly the pixels of the default, and each
// format refuses a name or level it does not take, naming what it takes.
TEST(IO, CompressionReachesTheWriterAndKeepsLosslessPixels) {
  fs::path d = tmpdir();
  // Smooth plus a little structure: compressible, but not trivially.
  Image rgb = gradient(96, 64, 3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 96; ++x) rgb.at(x, y, 1) += ((x * 7 + y * 3) % 11) * 0.01f;
  auto write_as = [&](const std::string& name, const std::string& bits, const std::string& comp) {
    WriteOptions o;
    o.bits = bits;
    o.compression = comp;
    const std::string p = (d / name).string();
    write_image(p, rgb, o);
    return p;
  };
  auto stored_compression = [](const std::string& p) {
    auto in = OIIO::ImageInput::open(p);
    EXPECT_TRUE(in) << p;
    return in ? std::string(in->spec().get_string_attribute("compression")) : std::string();
  };
  // PNG, 16 bits: the same samples at every level; stored blocks (none) are
  // at least the raw 96 x 64 x 3 x 2 bytes, level 9 well under them.
  const Image png_auto = read_color(write_as("auto.png", "16", "auto"));
  std::uintmax_t none_size = 0, z9_size = 0;
  for (const char* c : {"none", "zip", "zip:0", "zip:1", "zip:9", "rle", "fast"}) {
    const std::string p = write_as(std::string("c_") + (c[3] == ':' ? std::string("zip") + c[4] : c) + ".png", "16", c);
    EXPECT_EQ(read_color(p).data, png_auto.data) << c;
    if (std::string(c) == "none") none_size = fs::file_size(p);
    if (std::string(c) == "zip:9") z9_size = fs::file_size(p);
  }
  EXPECT_GE(none_size, 96u * 64 * 3 * 2);
  EXPECT_LT(z9_size, none_size * 3 / 4);
  // EXR float: lossless forms are exact and named in the file.
  for (const char* c : {"none", "rle", "zip", "zip:1", "zips", "piz"}) {
    const std::string p = write_as(std::string("e_") + (std::string(c) == "zip:1" ? "zip1" : c) + ".exr", "float", c);
    EXPECT_EQ(read_color(p).data, rgb.data) << c;
    const std::string name = std::string(c).substr(0, std::string(c).find(':'));
    EXPECT_EQ(stored_compression(p).substr(0, name.size()), name) << c;
  }
  // A lossy EXR form on colour is allowed and named.
  EXPECT_EQ(stored_compression(write_as("dwaa.exr", "half", "dwaa:45")).substr(0, 4), "dwaa");
  // TIFF, 16 bits.
  const Image tif_auto = read_color(write_as("auto.tif", "16", "auto"));
  for (const char* c : {"none", "lzw", "zip:1", "packbits"}) {
    const std::string n = std::string(c) == "zip:1" ? "zip" : c;
    const std::string p = write_as("t_" + n + ".tif", "16", c);
    EXPECT_EQ(read_color(p).data, tif_auto.data) << c;
    EXPECT_EQ(stored_compression(p), n) << c;
  }
  // JPEG: the quality is the compression; auto is OpenImageIO's 98, as the
  // help and io.hpp say (the same encoder at the same quality: the same bytes).
  EXPECT_EQ(fs::file_size(write_as("auto.jpg", "8", "auto")), fs::file_size(write_as("q98.jpg", "8", "jpeg:98")));
  EXPECT_LT(fs::file_size(write_as("q20.jpg", "8", "jpeg:20")), fs::file_size(write_as("q100.jpg", "8", "jpeg:100")));

  struct Bad {
    const char* file;
    const char* comp;
    bool data;
    const char* must_contain;
  };
  for (Bad b : {Bad{"x.png", "lzw", false, "none, zip, zip:0..9"}, Bad{"x.png", "zip:10", false, "0..9"},
                Bad{"x.png", "zip:", false, "not a whole number"}, Bad{"x.png", "none:3", false, "takes no level"},
                Bad{"x.png", "rle:1", false, "'rle' takes no level"},
                Bad{"x.exr", "dwaa", true, "lossy"}, Bad{"x.exr", "zip:0", false, "1..9"},
                Bad{"x.exr", "ZIP", false, "not a compression"}, Bad{"x.jpg", "jpeg", false, "jpeg:1..100"},
                Bad{"x.pfm", "zip", false, "auto, none"}, Bad{"x.hdr", "none", false, "auto, rle"}}) {
    WriteOptions o;
    o.compression = b.comp;
    o.is_color = !b.data;
    const std::string p = (d / b.file).string();
    try {
      check_writable(p, o, "--out");
      ADD_FAILURE() << b.file << " " << b.comp << " was accepted";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(b.must_contain), std::string::npos) << m;
      EXPECT_NE(m.find(std::string("'") + b.comp + "'"), std::string::npos) << m;
      EXPECT_NE(m.find(b.file), std::string::npos) << m;
    }
    EXPECT_FALSE(fs::exists(p));
  }
  fs::remove_all(d);
}

// The sRGB tables of read_color and of 8-bit writes give exactly the bits of
// the per-value curve: decoding every 8- and 16-bit code, and encoding a sweep
// of every 97th float in [0, 1.01] plus +-200 floats around each step of the
// curve, NaN, infinities, negatives and denormals, through whole PNG files,
// against OpenImageIO writing the per-value floats linear_to_srgb(max(v, 0)).
TEST(IO, SrgbTablesGiveThePerValueBits) {
  fs::path d = tmpdir();
  auto write_raw = [](const std::string& p, int w, int h, OIIO::TypeDesc file_type, OIIO::TypeDesc mem_type,
                      const void* data) {
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out);
    ASSERT_TRUE(out->open(p, OIIO::ImageSpec(w, h, 3, file_type)));
    ASSERT_TRUE(out->write_image(mem_type, data));
    ASSERT_TRUE(out->close());
  };
  auto read_as = [](const std::string& p, OIIO::TypeDesc t, std::size_t bytes) {
    std::vector<unsigned char> v(bytes);
    auto in = OIIO::ImageInput::open(p);
    EXPECT_TRUE(in && in->read_image(0, 0, 0, 3, t, v.data())) << p;
    return v;
  };
  // Decoding: every code of an 8-bit and of a 16-bit PNG.
  for (int bits : {8, 16}) {
    const int n = 1 << bits, w = 256, h = n / 256;
    std::vector<std::uint16_t> c16(static_cast<std::size_t>(n) * 3);
    std::vector<std::uint8_t> c8(c16.size());
    for (std::size_t i = 0; i < c16.size(); ++i) c16[i] = static_cast<std::uint16_t>((i / 3 + 7 * (i % 3)) % n), c8[i] = static_cast<std::uint8_t>(c16[i]);
    const std::string p = (d / ("codes" + std::to_string(bits) + ".png")).string();
    if (bits == 8) write_raw(p, w, h, OIIO::TypeDesc::UINT8, OIIO::TypeDesc::UINT8, c8.data());
    else write_raw(p, w, h, OIIO::TypeDesc::UINT16, OIIO::TypeDesc::UINT16, c16.data());
    std::vector<unsigned char> f = read_as(p, OIIO::TypeDesc::FLOAT, c16.size() * 4);
    const Image got = read_color(p);
    ASSERT_EQ(got.data.size(), c16.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < c16.size(); ++i) {
      float v;
      std::memcpy(&v, &f[i * 4], 4);
      const float want = srgb_to_linear(v);
      differ += std::memcmp(&want, &got.data[i], 4) != 0;
    }
    EXPECT_EQ(differ, 0u) << bits << "-bit";
  }
  // Encoding: the sweep, then the neighbours of every step it crossed.
  std::vector<float> v;
  std::uint32_t top;
  const float lim = 1.01f;
  std::memcpy(&top, &lim, 4);
  for (std::uint32_t b = 0; b <= top; b += 97) {
    float f;
    std::memcpy(&f, &b, 4);
    v.push_back(f);
  }
  {
    std::vector<float> e(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) e[i] = linear_to_srgb(std::max(v[i], 0.0f));
    std::vector<std::uint8_t> c(v.size());
    ASSERT_TRUE(OIIO::convert_pixel_values(OIIO::TypeDesc::FLOAT, e.data(), OIIO::TypeDesc::UINT8, c.data(),
                                           static_cast<int>(c.size())));
    const std::size_t sweep = v.size();
    int steps = 0;
    for (std::size_t i = 1; i < sweep; ++i)
      if (c[i] != c[i - 1]) {
        ++steps;
        std::uint32_t b;
        std::memcpy(&b, &v[i], 4);
        for (std::uint32_t q = b - 200; q <= b + 200; ++q) {
          float f;
          std::memcpy(&f, &q, 4);
          v.push_back(f);
        }
      }
    EXPECT_EQ(steps, 255);
  }
  for (float f : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                  -std::numeric_limits<float>::infinity(), -1.0f, -0.0f, 1e-42f, 2.0f, 1e30f})
    v.push_back(f);
  while (v.size() % 3) v.push_back(0.5f);
  const int w = 1024, h = static_cast<int>((v.size() / 3 + w - 1) / w);
  v.resize(static_cast<std::size_t>(w) * h * 3, 0.25f);
  Image img(w, h, 3);
  img.data = v;
  std::vector<float> per_value(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) per_value[i] = linear_to_srgb(std::max(v[i], 0.0f));
  const std::string old_path = (d / "per_value.png").string(), new_path = (d / "table.png").string();
  write_raw(old_path, w, h, OIIO::TypeDesc::UINT8, OIIO::TypeDesc::FLOAT, per_value.data());
  WriteOptions o;
  o.bits = "8";
  write_image(new_path, img, o);
  const auto a = read_as(old_path, OIIO::TypeDesc::UINT8, v.size()), b = read_as(new_path, OIIO::TypeDesc::UINT8, v.size());
  std::size_t differ = 0, first = 0;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (a[i] != b[i] && differ++ == 0) first = i;
  EXPECT_EQ(differ, 0u) << "first at value " << v[first] << ": per-value " << int(a[first]) << ", table " << int(b[first]);
  fs::remove_all(d);
}

// brume's PFM pixel reader against OpenImageIO's on the same files, bit for
// bit: RGB and grey, little- and big-endian, a header spaced unusually,
// non-finite values, and ETH3D's disparity maps.
TEST(IO, PfmPixelsReadStraightEqualOpenImageIO) {
  fs::path d = tmpdir();
  auto write_by_hand = [](const std::string& p, const std::string& header, int w, int h, int c, bool big) {
    std::ofstream f(p, std::ios::binary);
    f << header;
    for (int i = 0; i < w * h * c; ++i) {
      float v = i % 17 == 0 ? NAN : i % 23 == 0 ? INFINITY : 0.25f * i - 3.0f;
      std::uint32_t b;
      std::memcpy(&b, &v, 4);
      if (big) b = __builtin_bswap32(b);
      f.write(reinterpret_cast<const char*>(&b), 4);
    }
  };
  std::vector<std::string> files;
  write_by_hand((d / "le.pfm").string(), "PF\n7 5\n-1.0\n", 7, 5, 3, false);
  write_by_hand((d / "be.pfm").string(), "PF\n7 5\n1.0\n", 7, 5, 3, true);
  write_by_hand((d / "grey.pfm").string(), "Pf\n9 4\n-2.5\n", 9, 4, 1, false);
  write_by_hand((d / "spaced.pfm").string(), "PF  6\t3 \n -1\n", 6, 3, 3, false);
  // Outside the strict subset brume reads itself: OpenImageIO reads these
  // (a comment, a signed width, a hex scale), and must give the same.
  write_by_hand((d / "comment.pfm").string(), "PF\n# by hand\n7 5\n-1.0\n", 7, 5, 3, false);
  write_by_hand((d / "signed.pfm").string(), "PF\n+7 5\n-1.0\n", 7, 5, 3, false);
  write_by_hand((d / "hex.pfm").string(), "Pf\n7 5\n-0x1p1\n", 7, 5, 1, false);
  for (const char* n : {"le.pfm", "be.pfm", "grey.pfm", "spaced.pfm", "comment.pfm", "signed.pfm", "hex.pfm"})
    files.push_back((d / n).string());
  Image rgb = gradient(31, 17, 3);
  write_image((d / "brume.pfm").string(), rgb, WriteOptions{});
  files.push_back((d / "brume.pfm").string());
  for (const char* rel : {"eth3d_two_view/playground_1l/disp0.pfm", "eth3d_two_view/playground_1l/disp0GT.pfm"})
    if (have_data(rel)) files.push_back(data_path(rel));
  for (const std::string& p : files) {
    const std::vector<float> want = oiio_pixels(p);
    FileInfo info;
    auto in = OIIO::ImageInput::open(p);
    ASSERT_TRUE(in) << p;
    const OIIO::ImageSpec spec = in->spec();
    const int c = spec.nchannels;
    const std::string format = in->format_name();
    in.reset();
    const Image got = c == 1 ? read_scalar(p, "", &info) : read_color(p, Transfer::linear, &info);
    // The FileInfo the straight read makes up is the one OpenImageIO gives.
    EXPECT_EQ(info.format, format) << p;
    EXPECT_EQ(info.integer, false) << p;
    EXPECT_EQ(info.bits, 32) << p;
    EXPECT_EQ(info.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(info.description, spec.get_string_attribute("ImageDescription")) << p;
    EXPECT_EQ(got.width, spec.width) << p;
    EXPECT_EQ(got.height, spec.height) << p;
    ASSERT_EQ(got.data.size(), want.size()) << p;
    EXPECT_EQ(std::memcmp(got.data.data(), want.data(), want.size() * 4), 0) << p;
  }
  // A file shorter than its header says is left to OpenImageIO, whose
  // refusal names the file.
  {
    std::ofstream f(d / "short.pfm", std::ios::binary);
    f << "PF\n7 5\n-1.0\n" << std::string(7 * 4 * 3 * 4, '\0');  // four of the five rows
  }
  try {
    (void)read_color((d / "short.pfm").string(), Transfer::linear);
    ADD_FAILURE() << "a short PFM was read";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("short.pfm"), std::string::npos) << e.what();
  }
  fs::remove_all(d);
}

namespace {
std::string file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// A PNG written with libpng by hand (the shapes OpenImageIO's writer does
// not make: interlaced, palette, 1-bit, tRNS, one row filter forced, small
// IDAT chunks), values row-major (16 bits: big-endian). filters: libpng's
// PNG_FILTER_* mask (0: its default); idat_bytes: the zlib output per IDAT
// chunk (0: its default, 8192).
void write_png_by_hand(const std::string& p, int w, int h, int depth, int color, bool interlace,
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
}  // namespace

namespace {
// An EXR scanline file of one part cut into its parts: the bytes before the
// offset table (preamble and header), and each block's first line and data.
// lines: scanlines a block. Empty blocks when the file is too short.
struct ExrBlocks {
  std::string head;
  std::vector<int> y;
  std::vector<std::string> data;
};
ExrBlocks exr_blocks(const std::string& b, int height, int lines) {
  ExrBlocks r;
  std::size_t at = 8;
  while (at < b.size() && b[at] != '\0') {  // name\0 type\0 size value
    at = b.find('\0', at);
    at = b.find('\0', at + 1) + 1;
    if (at == 0 || at + 4 > b.size()) return {};
    std::uint32_t n;
    std::memcpy(&n, b.data() + at, 4);
    at += 4 + n;
  }
  r.head = b.substr(0, at + 1);
  const int blocks = (height + lines - 1) / lines;
  for (int k = 0; k < blocks; ++k) {
    std::uint64_t off;
    if (at + 1 + 8 * (k + 1) > b.size()) return {};
    std::memcpy(&off, b.data() + at + 1 + 8 * k, 8);
    if (off + 8 > b.size()) return {};
    std::int32_t y, n;
    std::memcpy(&y, b.data() + off, 4);
    std::memcpy(&n, b.data() + off + 4, 4);
    if (n < 0 || off + 8 + static_cast<std::uint64_t>(n) > b.size()) return {};
    r.y.push_back(y);
    r.data.push_back(b.substr(off + 8, static_cast<std::size_t>(n)));
  }
  return r;
}
// A ZIP/ZIPS block's raw scanline bytes (raw_size of them), by OpenEXR's
// rules read independently of brume: stored as is when it is raw_size
// long, else zlib (inflated by zlib itself), then the deltas summed and the
// two halves interleaved. "" when it does not inflate to exactly raw_size.
std::string exr_zip_block(const std::string& d, std::size_t raw_size) {
  if (d.size() == raw_size) return d;
  std::string t(raw_size, '\0');
  uLongf got = raw_size;
  if (uncompress(reinterpret_cast<Bytef*>(t.data()), &got, reinterpret_cast<const Bytef*>(d.data()), d.size()) != Z_OK ||
      got != raw_size)
    return "";
  for (std::size_t i = 1; i < raw_size; ++i) t[i] = static_cast<char>(t[i] + t[i - 1] - 128);
  std::string raw(raw_size, '\0');
  const std::size_t h = (raw_size + 1) / 2;
  for (std::size_t i = 0; i < raw_size; ++i) raw[i] = i % 2 ? t[h + i / 2] : t[i / 2];
  return raw;
}
}  // namespace

TEST(IO, ExrSubsetIsReadAsOpenImageIOReadsIt) {
  // Single-part half/float OpenEXR with one channel or R G B (A) is read
  // with OpenEXR itself (no OpenImageIO module load): values bit for bit,
  // FileInfo as OpenImageIO gives it, for every compression, scanline and
  // tiled files, NaN, inf and subnormal values. Every other EXR must be
  // declined (the direct-read counter does not move) and read by
  // OpenImageIO as before, with the same result.
  fs::path d = tmpdir();
  struct Spec {
    std::string name;
    int w, h;
    std::vector<std::string> channels;
    OIIO::TypeDesc type;
    std::string compression;
    bool tiled = false;
    bool offset_window = false;
    bool mixed = false;
    int subimages = 1;
    bool origin = false;      // data and display windows from (3, 2)
    bool decreasing = false;  // line order DECREASING_Y
    bool noise = false;       // values that do not deflate (stored blocks)
  };
  auto values = [](int w, int h, int c, bool noise = false) {
    std::vector<float> v(static_cast<std::size_t>(w) * h * c);
    std::uint32_t state = 99;
    for (std::size_t i = 0; i < v.size(); ++i) {
      state = state * 1664525u + 1013904223u;
      v[i] = i % 31 == 0 ? NAN : i % 37 == 0 ? -INFINITY : i % 41 == 0 ? 1e-41f : 0.173f * static_cast<float>(i) - 40.0f;
      if (noise && i % 31 && i % 37 && i % 41)
        v[i] = std::ldexp(static_cast<float>(state >> 8) / 16777216.0f - 0.5f, static_cast<int>(state % 21) - 10);
    }
    return v;
  };
  auto write = [&](const Spec& s) {
    const std::string p = (d / s.name).string();
    const int c = static_cast<int>(s.channels.size());
    OIIO::ImageSpec spec(s.w, s.h, c, s.type);
    spec.channelnames = s.channels;
    spec.attribute("compression", s.compression);
    spec.attribute("ImageDescription", "{\"written\": \"" + s.name + "\"}");
    if (s.tiled) spec.tile_width = spec.tile_height = 16;
    if (s.offset_window) spec.x = 3, spec.y = 2, spec.full_width = s.w + 6, spec.full_height = s.h + 4;
    if (s.origin) spec.x = spec.full_x = 3, spec.y = spec.full_y = 2;
    if (s.decreasing) spec.attribute("openexr:lineOrder", "decreasingY");
    if (s.mixed) {
      spec.channelformats.assign(static_cast<std::size_t>(c), OIIO::TypeDesc::HALF);
      spec.channelformats[0] = OIIO::TypeDesc::FLOAT;
    }
    const std::vector<float> v = values(s.w, s.h, c, s.noise);
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out) << p;
    std::vector<OIIO::ImageSpec> specs(static_cast<std::size_t>(s.subimages), spec);
    ASSERT_TRUE(out->open(p, s.subimages, specs.data())) << p << out->geterror();
    for (int k = 0; k < s.subimages; ++k) {
      if (k > 0) {
        ASSERT_TRUE(out->open(p, specs[static_cast<std::size_t>(k)], OIIO::ImageOutput::AppendSubimage));
      }
      ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, v.data())) << p << out->geterror();
    }
    ASSERT_TRUE(out->close()) << p;
  };
  const OIIO::TypeDesc H = OIIO::TypeDesc::HALF, F = OIIO::TypeDesc::FLOAT;
  std::vector<Spec> subset = {
      {"y_zip.exr", 37, 23, {"Y"}, F, "zip"},
      {"y_half_piz.exr", 37, 23, {"Y"}, H, "piz"},
      {"rgb_half_none.exr", 41, 19, {"R", "G", "B"}, H, "none"},
      {"rgba_float_rle.exr", 41, 19, {"R", "G", "B", "A"}, F, "rle"},
      {"z_tiled_zips.exr", 45, 33, {"Z"}, F, "zips"},
      {"depthz_half_b44.exr", 40, 24, {"depth.Z"}, H, "b44"},
      {"rgb_float_pxr24.exr", 29, 35, {"R", "G", "B"}, F, "pxr24"},
      {"rgb_half_dwaa.exr", 70, 40, {"R", "G", "B"}, H, "dwaa"},
  };
  // ZIP and ZIPS scanline files, whose blocks brume decodes itself: half
  // and float, 1, 3 and 4 channels, a window from (3, 2), decreasing line
  // order, blocks stored as is (noise), a short last block.
  for (Spec z : {Spec{"rgb_half_zip_origin.exr", 70, 40, {"R", "G", "B"}, H, "zip"},
                 Spec{"rgba_float_zips_decreasing.exr", 41, 19, {"R", "G", "B", "A"}, F, "zips"},
                 Spec{"y_float_zip_noise.exr", 64, 41, {"Y"}, F, "zip"},
                 Spec{"rgb_half_zips_noise.exr", 33, 9, {"R", "G", "B"}, H, "zips"},
                 Spec{"rgba_half_zip_decreasing.exr", 19, 37, {"R", "G", "B", "A"}, H, "zip"}}) {
    z.origin = z.name.find("origin") != std::string::npos;
    z.decreasing = z.name.find("decreasing") != std::string::npos;
    z.noise = z.name.find("noise") != std::string::npos;
    subset.push_back(z);
  }
  const std::vector<Spec> other = {
      {"rgbz.exr", 21, 13, {"R", "G", "B", "Z"}, F, "zip"},
      {"ya.exr", 21, 13, {"Y", "A"}, H, "zip"},
      {"window.exr", 21, 13, {"Y"}, F, "zip", false, true},
      {"mixed.exr", 21, 13, {"R", "G", "B"}, H, "zip", false, false, true},
      {"uint.exr", 21, 13, {"Y"}, OIIO::TypeDesc::UINT, "zip"},
      {"two_parts.exr", 21, 13, {"R", "G", "B"}, F, "zip", false, false, false, 2},
  };
  auto same_bits = [](const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
  };
  auto no_check = [](int, int, int) {};
  for (const Spec& s : subset) {
    write(s);
    const std::string p = (d / s.name).string();
    OIIO::ImageSpec spec;
    std::string format;
    const std::vector<float> want = oiio_pixels(p, &spec, &format);
    detail::ExrInfo info;
    Image got;
    ASSERT_TRUE(detail::read_exr_subset(p, &got, info, no_check, 0)) << p;
    EXPECT_TRUE(same_bits(got.data, want)) << p;
    if (s.noise) {  // the stored blocks are there
      const int lines = s.compression == "zips" ? 1 : 16;
      const ExrBlocks bl = exr_blocks(file_bytes(p), s.h, lines);
      int stored = 0;
      for (std::size_t k = 0; k < bl.data.size(); ++k)
        stored += bl.data[k].size() == static_cast<std::size_t>(s.w) * s.channels.size() * s.type.size() *
                                           static_cast<std::size_t>(std::min(lines, s.h - (bl.y[k] - bl.y[0])));
      EXPECT_GT(stored, 0) << p << ": no block stored as is";
      EXPECT_FALSE(bl.data.empty()) << p;
    }
    EXPECT_EQ(got.width, spec.width) << p;
    EXPECT_EQ(got.height, spec.height) << p;
    EXPECT_EQ(info.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(info.bits, static_cast<int>(spec.format.size() * 8)) << p;
    EXPECT_EQ(spec.get_int_attribute("oiio:BitsPerSample", 0), 0) << p << ": OpenImageIO now names a bit depth";
    EXPECT_EQ(info.description, spec.get_string_attribute("ImageDescription")) << p;
    EXPECT_EQ(format, "openexr");
    // Decompressed by OpenEXR's pool: the same values.
    Image threaded;
    ASSERT_TRUE(detail::read_exr_subset(p, &threaded, info, no_check, 2)) << p;
    EXPECT_TRUE(same_bits(threaded.data, want)) << p;
    // The public readers take the subset path and report OpenImageIO's FileInfo.
    const std::uint64_t before = detail::exr_direct_reads();
    FileInfo fi;
    if (s.channels.size() == 1)
      (void)read_scalar(p, "", &fi);
    else
      (void)read_color(p, Transfer::linear, &fi);
    EXPECT_EQ(detail::exr_direct_reads(), before + 1) << p;
    EXPECT_EQ(fi.format, "openexr") << p;
    EXPECT_FALSE(fi.integer) << p;
    EXPECT_EQ(fi.bits, info.bits) << p;
    EXPECT_EQ(fi.channel_names, info.channel_names) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_EQ(hd.width, spec.width);
    EXPECT_EQ(hd.channels, spec.nchannels);
  }
  for (const Spec& s : other) {
    write(s);
    const std::string p = (d / s.name).string();
    OIIO::ImageSpec spec;
    std::string format;
    const std::vector<float> want = oiio_pixels(p, &spec, &format);
    detail::ExrInfo info;
    Image got;
    EXPECT_FALSE(detail::read_exr_subset(p, &got, info, no_check, 0)) << p << " was taken by the subset reader";
    const std::uint64_t before = detail::exr_direct_reads();
    FileInfo fi;
    const Image pub = s.channels.size() == 1 ? read_scalar(p, "", &fi) : read_scalar(p, s.channels[0], &fi);
    EXPECT_EQ(detail::exr_direct_reads(), before) << p;
    EXPECT_EQ(fi.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    ASSERT_EQ(pub.data.size(), want.size() / static_cast<std::size_t>(spec.nchannels)) << p;
    if (!spec.format.is_floating_point()) continue;  // read_scalar gives an integer file's counts
    for (std::size_t i = 0; i < pub.data.size(); ++i) {
      const float a = pub.data[i], b = want[i * static_cast<std::size_t>(spec.nchannels)];
      if (!(a == b || (std::isnan(a) && std::isnan(b)))) {
        ADD_FAILURE() << p << " value " << i << ": " << a << " against OpenImageIO's " << b;
        break;
      }
    }
  }
  // A ZIP block whose stream is damaged (its Adler-32 no longer matches) is
  // declined as well.
  {
    const std::string full = (d / "rgb_half_zip_origin.exr").string(), bad = (d / "bad_block.exr").string();
    std::string bytes = file_bytes(full);
    bytes[bytes.size() - 40] = static_cast<char>(bytes[bytes.size() - 40] ^ 0x5a);
    std::ofstream(bad, std::ios::binary) << bytes;
    detail::ExrInfo info;
    Image got;
    EXPECT_FALSE(detail::read_exr_subset(bad, &got, info, no_check, 2));
    EXPECT_TRUE(got.data.empty());
  }
  // A truncated subset file is declined, and OpenImageIO's reading of it
  // decides (here: an error naming the file, or its partial image).
  {
    const std::string full = (d / "y_zip.exr").string(), cut = (d / "cut.exr").string();
    const std::string bytes = file_bytes(full);
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3);
    detail::ExrInfo info;
    Image got;
    EXPECT_FALSE(detail::read_exr_subset(cut, &got, info, no_check, 0));
    EXPECT_TRUE(got.data.empty());
  }
  fs::remove_all(d);
}

TEST(IO, ExrSubsetWritesTheFileOpenImageIOWrites) {
  // 1- and 3-channel EXR in half or float, linear, with the default or any
  // named compression, are written without OpenImageIO (no module load),
  // as OpenImageIO writes them for the same values and the attributes
  // brume gives it, once both files' time stamps (capDate, the time of
  // writing) are blanked: byte for byte through OpenEXR's writer (none,
  // rle, piz, pxr24, b44, b44a, dwaa, dwab); for zip (also "auto") and zips,
  // whose blocks brume deflates itself (libdeflate), the same preamble and
  // header bytes, the same blocks at the same lines, each block's data
  // inflating (zlib) to the bytes of OpenImageIO's block, and the values
  // read back by OpenImageIO equal to its file's. Outside the subset (a
  // level) OpenImageIO still writes.
  fs::path d = tmpdir();
  // The capDate attribute: name, type "string", a 4-byte size, the value.
  auto blank_stamp = [](std::string b) {
    const std::string key("capDate\0string\0", 15);
    const std::size_t at = b.find(key);
    if (at == std::string::npos) return std::string("no capDate");
    std::uint32_t n;
    std::memcpy(&n, b.data() + at + key.size(), 4);
    for (std::uint32_t k = 0; k < n; ++k) b[at + key.size() + 4 + k] = '#';
    return b;
  };
  const std::string desc = "{\"record\": \"brume\", \"n\": 1}";
  int compared = 0, zipped = 0;
  for (int c : {1, 3})
    for (bool half : {false, true})
      for (const char* comp :
           {"auto", "none", "rle", "zip", "zips", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab"}) {
        const std::string name = comp;
        const bool lossy = name == "pxr24" || name.rfind("b44", 0) == 0 || name.rfind("dwa", 0) == 0;
        if (c == 1 && lossy) continue;  // data maps are written losslessly (refused: another test)
        const bool zip = name == "auto" || name == "zip" || name == "zips";
        // Three ZIP blocks (the last one short); rows 16-31, one whole ZIP
        // block, of values that do not deflate (blocks stored as is).
        const int W = 67, H = 45;
        Image img = gradient(W, H, c);
        for (std::size_t i = 0; i < img.data.size(); i += 29) img.data[i] = i % 2 ? -3.25e-6f : 70000.0f;
        std::uint32_t state = 12345;
        for (int y = 16; y < 32; ++y)
          for (int x = 0; x < W; ++x)
            for (int k = 0; k < c; ++k) {
              state = state * 1664525u + 1013904223u;
              img.at(x, y, k) = std::ldexp(static_cast<float>(state >> 8) / 16777216.0f - 0.5f,
                                           static_cast<int>(state % 21) - 10);
            }
        const std::string tag = std::to_string(c) + (half ? "h_" : "f_") + comp;
        const fs::path mine = d / ("mine_" + tag + ".exr"), theirs = d / ("oiio_" + tag + ".exr");
        WriteOptions o;
        o.bits = half ? "half" : "float";
        o.compression = comp;
        o.description = desc;
        o.is_color = c == 3;
        if (c == 1) o.float_reason = "metres";
        const std::uint64_t before = detail::exr_direct_writes();
        write_image(mine.string(), img, o);
        EXPECT_EQ(detail::exr_direct_writes(), before + 1) << tag << " was not written without OpenImageIO";
        OIIO::ImageSpec spec(img.width, img.height, c, half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
        if (c == 1) spec.channelnames = {"Y"};
        spec.attribute("oiio:ColorSpace", "linear");
        spec.attribute("ImageDescription", desc);
        if (std::string(comp) != "auto") spec.attribute("compression", comp);
        auto out = OIIO::ImageOutput::create(theirs.string());
        ASSERT_TRUE(out && out->open(theirs.string(), spec)) << tag;
        ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data())) << tag;
        ASSERT_TRUE(out->close()) << tag;
        const std::string a = blank_stamp(file_bytes(mine)), b = blank_stamp(file_bytes(theirs));
        EXPECT_NE(a, "no capDate") << tag;
        ++compared;
        if (!zip) {
          EXPECT_TRUE(a == b) << tag << ": " << a.size() << " bytes against OpenImageIO's " << b.size();
          continue;
        }
        const int lines = name == "zips" ? 1 : 16;
        const ExrBlocks ma = exr_blocks(a, H, lines), mb = exr_blocks(b, H, lines);
        ASSERT_FALSE(ma.data.empty()) << tag << ": brume's file does not parse";
        ASSERT_FALSE(mb.data.empty()) << tag << ": OpenImageIO's file does not parse";
        EXPECT_TRUE(ma.head == mb.head) << tag << ": the preamble and header differ";
        EXPECT_EQ(ma.y, mb.y) << tag;
        const std::size_t row = static_cast<std::size_t>(W) * c * (half ? 2 : 4);
        int stored = 0;
        for (std::size_t k = 0; k < ma.data.size() && k < mb.data.size(); ++k) {
          const std::size_t raw = row * static_cast<std::size_t>(std::min(lines, H - ma.y[k]));
          const std::string ra = exr_zip_block(ma.data[k], raw), rb = exr_zip_block(mb.data[k], raw);
          EXPECT_FALSE(ra.empty()) << tag << " block " << k << " does not inflate";
          EXPECT_TRUE(ra == rb) << tag << " block " << k << " holds other values";
          stored += ma.data[k].size() == raw;
        }
        EXPECT_GT(stored, 0) << tag << ": no block stored as is (the test's noise)";
        EXPECT_LT(stored, static_cast<int>(ma.data.size())) << tag << ": no block deflated";
        EXPECT_EQ(oiio_pixels(mine.string()), oiio_pixels(theirs.string())) << tag;
        ++zipped;
      }
  EXPECT_EQ(compared, 34);
  EXPECT_EQ(zipped, 12);
  // A compression level is left to OpenImageIO (which names it in the file).
  {
    WriteOptions o;
    o.compression = "zip:9";
    const std::uint64_t before = detail::exr_direct_writes();
    write_image((d / "level.exr").string(), gradient(20, 10, 3), o);
    EXPECT_EQ(detail::exr_direct_writes(), before);
    EXPECT_EQ(read_color((d / "level.exr").string()).width, 20);
  }
  fs::remove_all(d);
}

TEST(IO, JpegSubsetIsReadAsOpenImageIOReadsIt) {
  // 8-bit grey and colour JPEG is read with libjpeg itself (no OpenImageIO
  // module load): the values bit for bit and FileInfo as OpenImageIO gives
  // them, for 4:2:0, 4:2:2 and 4:4:4 colour, grey, progressive, odd sizes
  // (partial MCUs) and a description (OpenImageIO writes it as a comment
  // and in Exif); through the public readers too. A file whose comment and
  // Exif description differ, and a truncated file, are declined (the
  // counter does not move) and read by OpenImageIO as before.
  fs::path d = tmpdir();
  struct Spec {
    std::string name;
    int w, h, c;
    std::string subsampling;  // "" : OpenImageIO's default
    bool progressive = false;
    std::string comment;
    std::string unused;
    int quality = 90;
  };
  auto pixels = [](int w, int h, int c) {
    std::vector<float> v(static_cast<std::size_t>(w) * h * c);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int k = 0; k < c; ++k)
          v[(static_cast<std::size_t>(y) * w + x) * c + k] =
              0.5f + 0.45f * std::sin(0.31f * x + 1.7f * k) * std::cos(0.23f * y) + ((x / 4 + y / 3 + k) % 2 ? 0.03f : -0.03f);
    return v;
  };
  auto write = [&](const Spec& s) {
    const std::string p = (d / s.name).string();
    OIIO::ImageSpec spec(s.w, s.h, s.c, OIIO::TypeDesc::UINT8);
    if (!s.subsampling.empty()) spec.attribute("jpeg:subsampling", s.subsampling);
    if (s.progressive) spec.attribute("jpeg:progressive", 1);
    if (!s.comment.empty()) spec.attribute("ImageDescription", s.comment);
    spec.attribute("CompressionQuality", s.quality);
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec)) << p;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, pixels(s.w, s.h, s.c).data())) << p;
    ASSERT_TRUE(out->close()) << p;
  };
  auto no_check = [](int, int, int) {};
  const std::vector<Spec> subset = {
      {"rgb.jpg", 64, 48, 3, "", false, "", "", 90},
      {"rgb_odd_420.jpg", 37, 23, 3, "4:2:0", false, "", "", 90},
      {"rgb_422.jpg", 41, 19, 3, "4:2:2", false, "", "", 90},
      {"rgb_444_q100.jpg", 29, 35, 3, "4:4:4", false, "", "", 100},
      {"rgb_progressive.jpg", 70, 40, 3, "", true, "", "", 90},
      {"grey_odd.jpg", 45, 33, 1, "", false, "", "", 90},
      // (OpenImageIO writes a description as a comment, in Exif and in IPTC)
      {"grey_progressive_comment.jpg", 33, 17, 1, "", true, "a comment", "", 90},
      {"rgb_comment.jpg", 40, 24, 3, "", false, R"({"record": "brume"})", "", 90},
  };

  int read = 0;
  for (const Spec& s : subset) {
    write(s);
    const std::string p = (d / s.name).string();
    OIIO::ImageSpec spec;
    const std::vector<float> want = oiio_pixels(p, &spec);
    detail::JpegInfo info;
    Image got;
    ASSERT_TRUE(detail::read_jpeg_subset(p, &got, info, no_check)) << p;
    expect_oiio_image(p, got, spec, want);
    EXPECT_EQ(info.description, spec.get_string_attribute("ImageDescription")) << p;
    // The public readers take the subset path and report OpenImageIO's FileInfo.
    const FileInfo fi = expect_public_read(p, got, 255.0, detail::jpeg_direct_reads);
    EXPECT_EQ(fi.format, "jpeg") << p;
    EXPECT_TRUE(fi.integer) << p;
    EXPECT_EQ(fi.bits, 8) << p;
    EXPECT_EQ(fi.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_EQ(hd.width, spec.width);
    EXPECT_EQ(hd.channels, spec.nchannels);
    EXPECT_EQ(hd.format, "jpeg");
    // sRGB decoding: OpenImageIO's values through the sRGB curve.
    const Image lin = s.c == 3 ? read_color(p, Transfer::srgb) : Image();
    if (s.c == 3) {
      ASSERT_EQ(lin.data.size(), want.size());
      for (std::size_t i = 0; i < want.size(); i += 7) EXPECT_EQ(lin.data[i], srgb_to_linear(want[i])) << p << " " << i;
    }
    ++read;
  }
  EXPECT_EQ(read, 8);
  // Declined: a comment and an Exif description that differ (the comment
  // of a file OpenImageIO wrote, changed), a truncated file.
  {
    std::string changed = file_bytes(d / "rgb_comment.jpg");
    const std::size_t com = changed.find(std::string("\xff\xfe", 2));
    ASSERT_NE(com, std::string::npos);
    changed[com + 5] = 'R';  // the comment's '"' after '{' (marker 2, length 2, '{' 1)
    std::ofstream(d / "differ.jpg", std::ios::binary) << changed;
    const std::string whole = file_bytes(d / "rgb.jpg");
    std::ofstream(d / "cut.jpg", std::ios::binary) << whole.substr(0, whole.size() * 2 / 3);
  }
  for (const char* n : {"differ.jpg", "cut.jpg"}) {
    const std::string p = (d / n).string();
    detail::JpegInfo info;
    Image got;
    EXPECT_FALSE(detail::read_jpeg_subset(p, &got, info, no_check)) << p << " was taken by the subset reader";
    EXPECT_TRUE(got.data.empty()) << p;
    const std::uint64_t before = detail::jpeg_direct_reads();
    try {
      (void)read_color(p, Transfer::linear);
    } catch (const Error&) {  // OpenImageIO's verdict on the truncated file
    }
    EXPECT_EQ(detail::jpeg_direct_reads(), before) << p;
  }
  fs::remove_all(d);
}

TEST(IO, TiffSubsetIsReadAsOpenImageIOReadsIt) {
  // The common TIFF files are read with libtiff itself (no OpenImageIO
  // module load): values bit for bit and FileInfo as OpenImageIO gives them,
  // for files OpenImageIO wrote (8/16-bit and float, grey and RGB, every
  // compression it writes, tiles, separate planes, a description) and files
  // libtiff wrote with what OpenImageIO does not write (big-endian, BigTIFF,
  // ZSTD and LZMA, odd strip heights, partial tiles, an Orientation);
  // through the public readers too. The forms left to OpenImageIO (alpha,
  // signed or 12-bit samples, BlackIsZero inverted, JPEG, a corrupt strip)
  // are declined: the counter does not move and OpenImageIO reads them.
  fs::path d = tmpdir();
  auto value = [](int x, int y, int k) {
    return 0.5 + 0.45 * std::sin(0.31 * x + 1.7 * k) * std::cos(0.23 * y) + ((x / 4 + y / 3 + k) % 2 ? 0.03 : -0.03);
  };
  // OpenImageIO's writer.
  struct OiioCase {
    std::string name;
    int w, h, c;
    OIIO::TypeDesc type;
    std::string compression;
    int tile = 0;
    bool separate = false;
    std::string description;
  };
  const std::vector<OiioCase> by_oiio = {
      {"u8_rgb_zip.tif", 64, 48, 3, OIIO::TypeDesc::UINT8, "zip", 0, false, ""},
      {"u16_rgb_zip.tif", 37, 71, 3, OIIO::TypeDesc::UINT16, "zip", 0, false, R"({"record": "brume"})"},
      {"f32_rgb_zip.tif", 41, 33, 3, OIIO::TypeDesc::FLOAT, "zip", 0, false, ""},
      {"f32_grey_lzw.tif", 29, 40, 1, OIIO::TypeDesc::FLOAT, "lzw", 0, false, ""},
      {"u16_grey_none.tif", 30, 35, 1, OIIO::TypeDesc::UINT16, "none", 0, false, ""},
      {"u8_grey_packbits.tif", 50, 20, 1, OIIO::TypeDesc::UINT8, "packbits", 0, false, ""},
      {"u16_rgb_lzw_tiled.tif", 45, 38, 3, OIIO::TypeDesc::UINT16, "lzw", 16, false, ""},
      {"f32_rgb_zip_separate.tif", 33, 40, 3, OIIO::TypeDesc::FLOAT, "zip", 0, true, ""},
      {"u8_rgb_tiled_separate.tif", 40, 21, 3, OIIO::TypeDesc::UINT8, "zip", 16, true, ""},
  };
  for (const OiioCase& c : by_oiio) {
    const std::string p = (d / c.name).string();
    OIIO::ImageSpec spec(c.w, c.h, c.c, c.type);
    spec.attribute("compression", c.compression);
    if (c.tile) spec.tile_width = spec.tile_height = c.tile;
    if (c.separate) spec.attribute("planarconfig", "separate");
    if (!c.description.empty()) spec.attribute("ImageDescription", c.description);
    std::vector<float> v(static_cast<std::size_t>(c.w) * c.h * c.c);
    for (int y = 0; y < c.h; ++y)
      for (int x = 0; x < c.w; ++x)
        for (int k = 0; k < c.c; ++k)
          v[(static_cast<std::size_t>(y) * c.w + x) * c.c + k] = static_cast<float>(value(x, y, k) * (k == 2 ? 3.7 : 1.0));
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec)) << p;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, v.data())) << p;
    ASSERT_TRUE(out->close()) << p;
  }
  // libtiff's writer: the forms above and those OpenImageIO does not write.
  struct RawCase {
    std::string name;
    int w, h, spp, bps, fmt, photo, comp, pred = 1, planar = PLANARCONFIG_CONTIG, tile = 0, rps = 0;
    const char* mode = "w";
    int orientation = 0, extra = 0;
  };
  const int lzma = TIFFIsCODECConfigured(COMPRESSION_LZMA) ? COMPRESSION_LZMA : COMPRESSION_NONE;
  const int zstd = TIFFIsCODECConfigured(COMPRESSION_ZSTD) ? COMPRESSION_ZSTD : COMPRESSION_NONE;
  const std::vector<RawCase> by_libtiff = {
      {"be_u16_rgb_lzw.tif", 39, 27, 3, 16, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_LZW, 2, PLANARCONFIG_CONTIG, 0, 5, "wb", 0, 0},
      {"be_f32_grey_zip.tif", 31, 22, 1, 32, SAMPLEFORMAT_IEEEFP, PHOTOMETRIC_MINISBLACK, COMPRESSION_ADOBE_DEFLATE, 1, PLANARCONFIG_CONTIG, 0, 7, "wb", 0, 0},
      {"be_f32_rgb_lzw_fp.tif", 31, 22, 3, 32, SAMPLEFORMAT_IEEEFP, PHOTOMETRIC_RGB, COMPRESSION_LZW, 3, PLANARCONFIG_CONTIG, 0, 7, "wb", 0, 0},
      {"bigtiff_u8_rgb.tif", 26, 19, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_PACKBITS, 1, PLANARCONFIG_CONTIG, 0, 4, "w8", 0, 0},
      {"zstd_u16_grey.tif", 44, 30, 1, 16, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, zstd, 2, PLANARCONFIG_CONTIG, 0, 11, "w", 0, 0},
      {"lzma_f32_rgb_sep.tif", 23, 17, 3, 32, SAMPLEFORMAT_IEEEFP, PHOTOMETRIC_RGB, lzma, 1, PLANARCONFIG_SEPARATE, 0, 3, "w", 0, 0},
      {"tiles_partial_f32.tif", 50, 37, 1, 32, SAMPLEFORMAT_IEEEFP, PHOTOMETRIC_MINISBLACK, COMPRESSION_DEFLATE, 1, PLANARCONFIG_CONTIG, 32, 0, "w", 0, 0},
      {"one_strip_rotated.tif", 17, 13, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 3, 0},
      // declined:
      {"grey_alpha.tif", 20, 10, 2, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 1},
      {"rgba.tif", 20, 10, 4, 16, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_ADOBE_DEFLATE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 1},
      {"signed.tif", 20, 10, 1, 16, SAMPLEFORMAT_INT, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 0},
      {"twelve_bits.tif", 20, 10, 1, 12, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 0},
      {"white_is_zero.tif", 20, 10, 1, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISWHITE, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 0},
      {"jpeg.tif", 32, 16, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_JPEG, 1, PLANARCONFIG_CONTIG, 0, 16, "w", 0, 0},
  };
  auto raw_write = [&](const RawCase& c) {
    const std::string p = (d / c.name).string();
    TIFF* t = TIFFOpen(p.c_str(), c.mode);
    ASSERT_TRUE(t) << p;
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, c.w);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, c.h);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, c.spp);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, c.bps);
    TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, c.fmt);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, c.photo);
    TIFFSetField(t, TIFFTAG_COMPRESSION, c.comp);
    TIFFSetField(t, TIFFTAG_PLANARCONFIG, c.planar);
    if (c.pred != 1) TIFFSetField(t, TIFFTAG_PREDICTOR, c.pred);
    if (c.orientation) TIFFSetField(t, TIFFTAG_ORIENTATION, c.orientation);
    if (c.extra) {
      const uint16_t ex[1] = {EXTRASAMPLE_UNASSALPHA};
      TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, ex);
    }
    if (c.tile) {
      TIFFSetField(t, TIFFTAG_TILEWIDTH, c.tile);
      TIFFSetField(t, TIFFTAG_TILELENGTH, c.tile);
    } else {
      TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, c.rps ? c.rps : c.h);
    }
    // Samples packed as the file stores them (native order: libtiff swaps
    // for "wb"); whole image per plane, then cut into strips or tiles.
    const int planes = c.planar == PLANARCONFIG_SEPARATE ? c.spp : 1, per_px = c.spp / planes;
    const int bytes = (c.bps + 7) / 8;
    auto sample = [&](int x, int y, int k, unsigned char* dst) {
      const double v = value(x, y, k);
      if (c.fmt == SAMPLEFORMAT_IEEEFP) {
        const float f = static_cast<float>(v * 2.5 - 0.4);
        std::memcpy(dst, &f, 4);
      } else if (c.bps == 8) {
        *dst = static_cast<unsigned char>(std::lround(v * 255));
      } else {
        const auto u = static_cast<std::uint16_t>(std::lround(v * (c.bps == 12 ? 4095 : 65535)));
        std::memcpy(dst, &u, 2);
      }
    };
    if (c.bps == 12) {  // packed: two samples in three bytes, rows padded to a byte
      const std::size_t rb = (static_cast<std::size_t>(c.w) * 12 + 7) / 8;
      std::vector<unsigned char> rows(rb * c.h, 0);
      for (int y = 0; y < c.h; ++y)
        for (int x = 0; x < c.w; ++x) {
          const auto u = static_cast<unsigned>(std::lround(value(x, y, 0) * 4095));
          const std::size_t bit = static_cast<std::size_t>(x) * 12;
          unsigned char* r = rows.data() + y * rb;
          for (int b = 0; b < 12; ++b)
            if (u >> (11 - b) & 1) r[(bit + b) / 8] |= static_cast<unsigned char>(0x80 >> ((bit + b) % 8));
        }
      ASSERT_GE(TIFFWriteEncodedStrip(t, 0, rows.data(), static_cast<tmsize_t>(rows.size())), 0) << p;
      TIFFClose(t);
      return;
    }
    for (int pl = 0; pl < planes; ++pl) {
      if (c.tile) {
        std::vector<unsigned char> buf(static_cast<std::size_t>(c.tile) * c.tile * per_px * bytes);
        for (int y0 = 0; y0 < c.h; y0 += c.tile)
          for (int x0 = 0; x0 < c.w; x0 += c.tile) {
            std::fill(buf.begin(), buf.end(), 0);
            for (int y = y0; y < std::min(c.h, y0 + c.tile); ++y)
              for (int x = x0; x < std::min(c.w, x0 + c.tile); ++x)
                for (int k = 0; k < per_px; ++k)
                  sample(x, y, pl + k, buf.data() + ((static_cast<std::size_t>(y - y0) * c.tile + (x - x0)) * per_px + k) * bytes);
            ASSERT_GE(TIFFWriteEncodedTile(t, TIFFComputeTile(t, x0, y0, 0, static_cast<uint16_t>(pl)), buf.data(),
                                           static_cast<tmsize_t>(buf.size())), 0) << p;
          }
      } else {
        const int rps = c.rps ? c.rps : c.h;
        for (int y0 = 0; y0 < c.h; y0 += rps) {
          const int rows = std::min(rps, c.h - y0);
          std::vector<unsigned char> buf(static_cast<std::size_t>(rows) * c.w * per_px * bytes);
          for (int y = y0; y < y0 + rows; ++y)
            for (int x = 0; x < c.w; ++x)
              for (int k = 0; k < per_px; ++k)
                sample(x, y, pl + k, buf.data() + ((static_cast<std::size_t>(y - y0) * c.w + x) * per_px + k) * bytes);
          ASSERT_GE(TIFFWriteEncodedStrip(t, TIFFComputeStrip(t, y0, static_cast<uint16_t>(pl)), buf.data(),
                                          static_cast<tmsize_t>(buf.size())), 0) << p;
        }
      }
    }
    TIFFClose(t);
  };
  for (const RawCase& c : by_libtiff) {
    if ((c.comp == COMPRESSION_JPEG) && !TIFFIsCODECConfigured(COMPRESSION_JPEG)) continue;
    raw_write(c);
  }
  // A private tag libtiff does not know when reading (it warns while
  // opening, which does not change the pixels): still the subset's.
  {
    const std::string p = (d / "private_tag.tif").string();
    static const TIFFFieldInfo info[] = {{65000, 1, 1, TIFF_LONG, FIELD_CUSTOM, 1, 0, const_cast<char*>("BrumePrivate")}};
    TIFF* t = TIFFOpen(p.c_str(), "w");
    ASSERT_TRUE(t);
    ASSERT_EQ(TIFFMergeFieldInfo(t, info, 1), 0);
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, 12);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, 5);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, 8);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
    TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, 5);
    TIFFSetField(t, 65000, 1234u);
    std::vector<unsigned char> px(60);
    for (std::size_t i = 0; i < px.size(); ++i) px[i] = static_cast<unsigned char>(i * 4);
    ASSERT_GE(TIFFWriteEncodedStrip(t, 0, px.data(), 60), 0);
    TIFFClose(t);
  }
  // A corrupt strip: bytes inside the first strip of a Deflate file overwritten.
  {
    std::string b = file_bytes(d / "u8_rgb_zip.tif");
    TIFF* t = TIFFOpen((d / "u8_rgb_zip.tif").string().c_str(), "r");
    ASSERT_TRUE(t);
    uint64_t* offs = nullptr;
    ASSERT_TRUE(TIFFGetField(t, TIFFTAG_STRIPOFFSETS, &offs));
    const std::size_t at = static_cast<std::size_t>(offs[0]) + 40;
    TIFFClose(t);
    for (std::size_t i = at; i < at + 24 && i < b.size(); ++i) b[i] = static_cast<char>(0xA5 ^ (i * 7));
    std::ofstream(d / "corrupt.tif", std::ios::binary) << b;
  }

  const std::vector<std::string> declined = {"grey_alpha.tif", "rgba.tif", "signed.tif", "twelve_bits.tif",
                                             "white_is_zero.tif", "jpeg.tif", "corrupt.tif"};
  auto no_check = [](int, int, int) {};
  int read = 0, refused = 0;
  for (const auto& e : fs::directory_iterator(d)) {
    const std::string p = e.path().string(), n = e.path().filename().string();
    const bool decline = std::find(declined.begin(), declined.end(), n) != declined.end();
    detail::TiffInfo info;
    Image got;
    if (decline) {
      EXPECT_FALSE(detail::read_tiff_subset(p, &got, info, no_check)) << p << " was taken by the subset reader";
      EXPECT_TRUE(got.data.empty()) << p;
      const std::uint64_t before = detail::tiff_direct_reads();
      try {
        (void)read_color(p, Transfer::linear);
      } catch (const Error&) {  // OpenImageIO's verdict on the corrupt strip
      }
      EXPECT_EQ(detail::tiff_direct_reads(), before) << p;
      ++refused;
      continue;
    }
    OIIO::ImageSpec spec;
    std::string format;
    const std::vector<float> want = oiio_pixels(p, &spec, &format);
    ASSERT_EQ(format, "tiff") << p;
    ASSERT_TRUE(detail::read_tiff_subset(p, &got, info, no_check)) << p;
    expect_oiio_image(p, got, spec, want);
    EXPECT_EQ(info.description, spec.get_string_attribute("ImageDescription")) << p;
    // The public readers take the subset path and report OpenImageIO's FileInfo.
    const double count_max = info.floating ? 0.0 : info.bits == 8 ? 255.0 : 65535.0;
    const FileInfo fi = expect_public_read(p, got, count_max, detail::tiff_direct_reads);
    EXPECT_EQ(fi.format, "tiff") << p;
    EXPECT_EQ(fi.integer, spec.format != OIIO::TypeDesc::FLOAT) << p;
    EXPECT_EQ(fi.bits, spec.get_int_attribute("oiio:BitsPerSample", static_cast<int>(spec.format.size()) * 8)) << p;
    EXPECT_EQ(fi.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(fi.description, spec.get_string_attribute("ImageDescription")) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_EQ(hd.width, spec.width);
    EXPECT_EQ(hd.height, spec.height);
    EXPECT_EQ(hd.channels, spec.nchannels);
    EXPECT_EQ(hd.format, "tiff");
    // sRGB decoding of an integer colour file: OpenImageIO's values through the curve.
    if (spec.nchannels == 3 && !info.floating) {
      const Image lin = read_color(p, Transfer::srgb);
      ASSERT_EQ(lin.data.size(), want.size());
      for (std::size_t i = 0; i < want.size(); i += 7) EXPECT_EQ(lin.data[i], srgb_to_linear(want[i])) << p << " " << i;
    }
    ++read;
  }
  EXPECT_EQ(read, 18);
  EXPECT_EQ(refused, TIFFIsCODECConfigured(COMPRESSION_JPEG) ? 7 : 6);
  fs::remove_all(d);
}

TEST(IO, TiffSubsetWritesTheFileOpenImageIOWrites) {
  // 1- and 3-channel TIFF in 8 or 16 bits or float, sRGB-encoded or linear,
  // with every compression brume offers, are written with libtiff itself
  // (no module load) as OpenImageIO writes them for the same values and the
  // attributes brume gives it: byte for byte once both files' DateTime (the
  // time of writing) is blanked -- except that the whole strips of a
  // Deflate file taller than one strip are deflated by brume (libdeflate):
  // there the same directory entries and values bar the strips' places and
  // sizes, the same Exif directory, each whole strip inflating to the bytes
  // of OpenImageIO's and the last, partial one (libtiff's) the same bytes.
  // Heights 1, 20, 32, 33 and 70 cover one partial strip, one whole strip,
  // whole strips and a tail; 1, 2 and 3 threads give one file.
  fs::path d = tmpdir();
  auto blank_date = [](std::string b) {
    // "YYYY:MM:DD HH:MM:SS\0", the DateTime tag's value (out of line: 20 bytes)
    int found = 0;
    for (std::size_t i = 0; i + 20 <= b.size(); ++i) {
      bool date = b[i + 19] == '\0';
      for (int k = 0; date && k < 19; ++k) {
        const char ch = b[i + static_cast<std::size_t>(k)];
        date = (k == 4 || k == 7 || k == 13 || k == 16) ? ch == ':' : k == 10 ? ch == ' ' : (ch >= '0' && ch <= '9');
      }
      if (date) {
        for (int k = 0; k < 19; ++k) b[i + static_cast<std::size_t>(k)] = '#';
        ++found;
      }
    }
    return found == 0 ? std::string("no DateTime") : b;
  };
  const std::string desc = "{\"record\": \"brume\", \"n\": 1}";
  struct Form {
    int c;
    std::string bits;
    Transfer transfer;
  };
  const std::vector<Form> forms = {{3, "8", Transfer::automatic},  {1, "8", Transfer::linear},
                                   {3, "16", Transfer::automatic}, {1, "16", Transfer::linear},
                                   {3, "float", Transfer::linear}, {1, "float", Transfer::linear},
                                   {3, "16", Transfer::linear}};
  int compared = 0, inflated = 0;
  for (const Form& f : forms)
    for (const char* comp : {"auto", "none", "lzw", "zip", "zip:1", "zip:9", "packbits"})
      for (int H : {1, 20, 32, 33, 70}) {
        const int W = H == 70 ? 67 : 29;
        Image img = gradient(W, H, f.c);
        for (std::size_t i = 0; i < img.data.size(); i += 29) img.data[i] = f.bits == "float" ? (i % 2 ? -3.25e-6f : 70000.0f) : (i % 2 ? -0.25f : 1.5f);
        std::uint32_t state = 12345;
        for (int y = 0; y < std::min(H, 8); ++y)  // noise that does not deflate
          for (int x = 0; x < W; ++x)
            for (int k = 0; k < f.c; ++k) {
              state = state * 1664525u + 1013904223u;
              img.at(x, y, k) = static_cast<float>(state >> 8) / 16777216.0f;
            }
        const std::string tag = std::to_string(f.c) + "c_" + f.bits + (f.transfer == Transfer::linear ? "_lin_" : "_") +
                                comp + "_h" + std::to_string(H);
        std::string name = tag;
        std::replace(name.begin(), name.end(), ':', '-');
        const fs::path mine = d / ("mine_" + name + ".tif"), theirs = d / ("oiio_" + name + ".tif");
        WriteOptions o;
        o.bits = f.bits;
        o.compression = comp;
        o.description = desc;
        o.is_color = f.c == 3;
        o.transfer = f.transfer;
        const std::uint64_t before = detail::tiff_direct_writes();
        write_image(mine.string(), img, o);
        EXPECT_EQ(detail::tiff_direct_writes(), before + 1) << tag << " was not written without OpenImageIO";
        const bool srgb = f.c == 3 && f.bits != "float" && f.transfer != Transfer::linear;
        const std::string cs = comp;
        oiio_write_as_brume(theirs, img, f.bits == "8" ? OIIO::TypeDesc::UINT8 : f.bits == "16" ? OIIO::TypeDesc::UINT16 : OIIO::TypeDesc::FLOAT,
                            srgb, desc, cs);
        const std::string a = blank_date(file_bytes(mine)), b = blank_date(file_bytes(theirs));
        EXPECT_NE(a, "no DateTime") << tag;
        ++compared;
        if (!(cs == "auto" || cs.rfind("zip", 0) == 0) || H <= 32) {
          EXPECT_TRUE(a == b) << tag << ": " << a.size() << " bytes against OpenImageIO's " << b.size();
          continue;
        }
        // Deflate, more than one strip: the same tags and values bar the
        // strips' places and sizes (the Exif directory's too), the same
        // strips, each whole one inflating to the bytes of OpenImageIO's,
        // the last (libtiff's) the same bytes.
        auto first = [](const std::string& f) {
          std::uint32_t at;
          std::memcpy(&at, f.data() + 4, 4);
          return at;
        };
        const std::vector<TiffEntry> ea = tiff_ifd(a, first(a)), eb = tiff_ifd(b, first(b));
        ASSERT_EQ(ea.size(), eb.size()) << tag;
        std::vector<std::uint32_t> off_a, off_b, len_a, len_b;
        for (std::size_t k = 0; k < ea.size(); ++k) {
          EXPECT_TRUE(ea[k].tag == eb[k].tag && ea[k].type == eb[k].type && ea[k].count == eb[k].count) << tag << " entry " << k;
          if (ea[k].tag == 273) off_a = tiff_longs(ea[k]), off_b = tiff_longs(eb[k]);
          else if (ea[k].tag == 279) len_a = tiff_longs(ea[k]), len_b = tiff_longs(eb[k]);
          else if (ea[k].tag == 34665) {
            const std::vector<TiffEntry> xa = tiff_ifd(a, tiff_longs(ea[k])[0]), xb = tiff_ifd(b, tiff_longs(eb[k])[0]);
            EXPECT_TRUE(xa.size() == 1 && xb.size() == 1 && xa[0].tag == 40961 && xa[0].value == xb[0].value) << tag;
          } else EXPECT_EQ(ea[k].value, eb[k].value) << tag << " tag " << ea[k].tag;
        }
        const std::size_t strips = static_cast<std::size_t>((H + 31) / 32), whole = static_cast<std::size_t>(H / 32);
        ASSERT_TRUE(off_a.size() == strips && off_b.size() == strips && len_a.size() == strips && len_b.size() == strips) << tag;
        const std::size_t strip_bytes = static_cast<std::size_t>(W) * f.c * (f.bits == "8" ? 1 : f.bits == "16" ? 2 : 4) * 32;
        for (std::size_t k = 0; k < strips; ++k) {
          const std::string sa = a.substr(off_a[k], len_a[k]), sb = b.substr(off_b[k], len_b[k]);
          if (k >= whole) {
            EXPECT_TRUE(sa == sb) << tag << " strip " << k;
            continue;
          }
          std::string ia(strip_bytes, '\0'), ib(strip_bytes, '\0');
          uLongf na = strip_bytes, nb = strip_bytes;
          ASSERT_EQ(uncompress(reinterpret_cast<Bytef*>(ia.data()), &na, reinterpret_cast<const Bytef*>(sa.data()), sa.size()), Z_OK) << tag << " strip " << k;
          ASSERT_EQ(uncompress(reinterpret_cast<Bytef*>(ib.data()), &nb, reinterpret_cast<const Bytef*>(sb.data()), sb.size()), Z_OK) << tag << " strip " << k;
          EXPECT_TRUE(na == strip_bytes && nb == strip_bytes && ia == ib) << tag << " strip " << k;
          ++inflated;
        }
      }
  EXPECT_EQ(compared, 7 * 7 * 5);
  EXPECT_EQ(inflated, 7 * 4 * 3);  // 7 forms x 4 Deflate settings x (1 + 2) whole strips
  // The thread count does not change the file.
  {
    Image img = gradient(90, 100, 3);
    std::string first;
    for (int threads : {1, 2, 3}) {
      IoThreads scope(threads);
      const fs::path p = d / ("threads" + std::to_string(threads) + ".tif");
      WriteOptions o;
      o.bits = "16";
      write_image(p.string(), img, o);
      const std::string b = blank_date(file_bytes(p));
      if (first.empty()) first = b;
      EXPECT_TRUE(b == first) << threads << " threads";
    }
  }
  fs::remove_all(d);
}

TEST(IO, JpegSubsetWritesTheFileOpenImageIOWrites) {
  // Grey and colour JPEG, sRGB-encoded or linear, at the default quality
  // (98) and others, are written with libjpeg itself (no module load) as
  // OpenImageIO writes them for the same values and the attributes brume
  // gives it: byte for byte -- its comment, Exif block (the description
  // inline when it fits an entry, else before IFD0; the Exif directory for
  // sRGB; an empty IFD0 with neither) and IPTC caption, the same tables and
  // scan. Descriptions of 0, 1, 3, 4, 5 and 1 175 bytes and one of 40 000
  // (past IPTC's 32 767: OpenImageIO still writes two length bytes);
  // sizes from 1 x 1 to partial MCUs.
  fs::path d = tmpdir();
  struct Form {
    int c;
    Transfer transfer;
  };
  int compared = 0;
  for (const Form& f : {Form{3, Transfer::automatic}, Form{3, Transfer::linear}, Form{1, Transfer::linear}})
    for (const char* comp : {"auto", "jpeg:1", "jpeg:50", "jpeg:90", "jpeg:100"})
      for (std::size_t dl : {std::size_t{0}, std::size_t{1}, std::size_t{3}, std::size_t{4}, std::size_t{5},
                             std::size_t{1175}, std::size_t{40000}})
        for (auto [W, H] : {std::pair{1, 1}, std::pair{37, 21}, std::pair{64, 48}}) {
          const std::string cs = comp;
          if (dl == 40000 && (cs != "auto" || W != 37)) continue;  // one long description is enough
          std::string desc;
          for (std::size_t i = 0; i < dl; ++i) desc += static_cast<char>(i % 61 == 60 ? ' ' : 'a' + i % 26);
          Image img = gradient(W, H, f.c);
          std::uint32_t state = 777;
          for (float& v : img.data)
            if ((state = state * 1664525u + 1013904223u) % 5 == 0) v = static_cast<float>(state >> 8) / 16777216.0f;
          const std::string tag = std::to_string(f.c) + "c" + (f.transfer == Transfer::linear ? "_lin_" : "_") + cs +
                                  "_d" + std::to_string(dl) + "_" + std::to_string(W) + "x" + std::to_string(H);
          std::string name = tag;
          std::replace(name.begin(), name.end(), ':', '-');
          const fs::path mine = d / ("mine_" + name + ".jpg"), theirs = d / ("oiio_" + name + ".jpg");
          WriteOptions o;
          o.compression = comp;
          o.description = desc;
          o.is_color = f.c == 3;
          o.transfer = f.transfer;
          const std::uint64_t before = detail::jpeg_direct_writes();
          write_image(mine.string(), img, o);
          EXPECT_EQ(detail::jpeg_direct_writes(), before + 1) << tag << " was not written without OpenImageIO";
          oiio_write_as_brume(theirs, img, OIIO::TypeDesc::UINT8, f.c == 3 && f.transfer != Transfer::linear, desc, cs);
          const std::string a = file_bytes(mine), b = file_bytes(theirs);
          EXPECT_TRUE(a == b) << tag << ": " << a.size() << " bytes against OpenImageIO's " << b.size();
          ++compared;
        }
  EXPECT_EQ(compared, 3 * (5 * 6 * 3 + 1));
  fs::remove_all(d);
}

TEST(IO, HdrSubsetIsReadAsOpenImageIOReadsIt) {
  // Radiance files of the common form are read by brume itself (no
  // OpenImageIO module load): the values bit for bit and FileInfo as
  // OpenImageIO gives them -- the Poly Haven skies in ../shared/data, files
  // OpenImageIO's writer made (run-length coded, and flat below 8 px
  // wide), a flat file by hand; the forms brume leaves to OpenImageIO are
  // declined (the direct-read counter does not move).
  fs::path d = tmpdir();
  auto oiio_write = [](const std::string& p, const Image& img) {
    OIIO::ImageSpec spec(img.width, img.height, 3, OIIO::TypeDesc::FLOAT);
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec)) << p;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data())) << p;
    ASSERT_TRUE(out->close()) << p;
  };
  auto hdr_values = [](int w, int h) {
    Image img(w, h, 3);
    for (std::size_t i = 0; i < img.data.size(); ++i)
      img.data[i] = i % 13 == 0 ? 0.0f : std::ldexp(static_cast<float>(i % 97) + 0.3f, static_cast<int>(i % 41) - 20);
    for (std::size_t i = 0; i + 2 < img.data.size(); i += 15) img.data[i] = img.data[i + 1] = img.data[i + 2] = 0.75f;  // runs
    return img;
  };
  std::vector<std::string> subset;
  for (const char* rel : {"sky_hdr_polyhaven/sky.hdr", "sky_hdr_polyhaven/park.hdr", "sky_hdr_polyhaven/sunrise.hdr"})
    if (have_data(rel)) subset.push_back(data_path(rel));
  for (const auto& [name, w, h] : {std::tuple{"rle.hdr", 37, 11}, std::tuple{"narrow.hdr", 5, 9}, std::tuple{"wide.hdr", 300, 4}}) {
    oiio_write((d / name).string(), hdr_values(w, h));
    subset.push_back((d / name).string());
  }
  // Flat at 8 px or more: the first pixel is not the "2 2" of a coded line.
  const std::string header = "#?RADIANCE\n# by hand\nGAMMA=1\nFORMAT=32-bit_rle_rgbe\n\n";
  {
    std::ofstream f(d / "flat.hdr", std::ios::binary);
    f << header << "-Y 3 +X 9\n";
    for (int i = 0; i < 27; ++i) {
      const unsigned char px[4] = {static_cast<unsigned char>(i * 9 % 256), static_cast<unsigned char>(i), 200,
                                   static_cast<unsigned char>(i % 5 ? 120 + i : 0)};
      f.write(reinterpret_cast<const char*>(px), 4);
    }
  }
  subset.push_back((d / "flat.hdr").string());
  for (const std::string& p : subset) {
    OIIO::ImageSpec spec;
    const std::vector<float> want = oiio_pixels(p, &spec);
    const std::uint64_t before = detail::hdr_direct_reads();
    FileInfo fi;
    const Image got = read_color(p, Transfer::linear, &fi);
    EXPECT_EQ(detail::hdr_direct_reads(), before + 1) << p << " was not read by brume itself";
    ASSERT_EQ(got.data.size(), want.size()) << p;
    EXPECT_EQ(std::memcmp(got.data.data(), want.data(), want.size() * sizeof(float)), 0) << p;
    EXPECT_EQ(fi.format, "hdr") << p;
    EXPECT_FALSE(fi.integer) << p;
    EXPECT_EQ(fi.bits, static_cast<int>(spec.format.size() * 8)) << p;
    EXPECT_EQ(fi.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(fi.description, spec.get_string_attribute("ImageDescription")) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_EQ(hd.width, spec.width);
    EXPECT_EQ(hd.height, spec.height);
  }
  // Declined: another orientation, XYZE, bytes after the image, a short
  // file (each left to OpenImageIO, whose reading or message stands).
  const std::string rle = (d / "rle.hdr").string();
  const std::string bytes = file_bytes(rle);
  const std::size_t res = bytes.find("-Y 11 +X 37\n");
  ASSERT_NE(res, std::string::npos);
  std::string flipped = bytes, xyze = bytes;
  flipped.replace(res, 12, "+Y 11 +X 37\n");
  const std::size_t fmt = xyze.find("FORMAT=32-bit_rle_rgbe");
  ASSERT_NE(fmt, std::string::npos);
  xyze.replace(fmt, 22, "FORMAT=32-bit_rle_xyze");
  const std::vector<std::pair<std::string, std::string>> other = {
      {"flipped.hdr", flipped}, {"xyze.hdr", xyze}, {"trailing.hdr", bytes + "tail"},
      {"short.hdr", bytes.substr(0, bytes.size() - 40)}};
  for (const auto& [name, content] : other) {
    const std::string p = (d / name).string();
    std::ofstream(p, std::ios::binary) << content;
    Image got;
    int w = 0, h = 0;
    EXPECT_FALSE(detail::read_hdr_subset(p, &got, w, h, [](int, int, int) {})) << name << " was taken";
    EXPECT_TRUE(got.data.empty()) << name;
  }
  fs::remove_all(d);
}

TEST(IO, HdrSubsetWritesTheFileOpenImageIOWrites) {
  // RGB images with values >= 0 or NaN are written as Radiance files by
  // brume itself: byte for byte OpenImageIO's file for the same values --
  // run-length coded widths (runs, literal stretches over 128 bytes, short
  // runs before long ones), flat narrow ones, zeros, values below 1e-32,
  // large and tiny exponents, NaN in each component. A negative value
  // leaves the file to OpenImageIO (the counter does not move).
  fs::path d = tmpdir();
  int compared = 0;
  for (const auto& [w, h] : {std::pair{40, 3}, std::pair{300, 7}, std::pair{5, 4}, std::pair{8, 2}, std::pair{1, 1}}) {
    Image img(w, h, 3);
    for (std::size_t i = 0; i < img.data.size(); ++i) {
      const std::size_t px = i / 3;
      img.data[i] = (px > 20 && px < 220) ? std::ldexp(static_cast<float>((i * 53) % 241) + 0.5f, static_cast<int>(i % 7))  // long literal stretches
                    : px % 11 < 5   ? 0.5f                                                        // runs
                    : px % 11 < 7 ? 0.0f                                                        // zeros
                    : px % 11 == 7 ? 1e-33f                                                     // below 1e-32
                                   : std::ldexp(static_cast<float>((i * 37) % 251) + 0.25f, static_cast<int>(i % 61) - 30);
    }
    for (std::size_t i = 2; i < img.data.size(); i += 17) img.data[i] = NAN;  // NaN in R, G and B of various pixels
    const fs::path mine = d / ("mine_" + std::to_string(w) + ".hdr"), theirs = d / ("oiio_" + std::to_string(w) + ".hdr");
    const std::uint64_t before = detail::hdr_direct_writes();
    write_image(mine.string(), img, WriteOptions{});
    EXPECT_EQ(detail::hdr_direct_writes(), before + 1) << w;
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    spec.attribute("oiio:ColorSpace", "linear");
    auto out = OIIO::ImageOutput::create(theirs.string());
    ASSERT_TRUE(out && out->open(theirs.string(), spec)) << w;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data())) << w;
    ASSERT_TRUE(out->close()) << w;
    const std::string a = file_bytes(mine), b = file_bytes(theirs);
    EXPECT_TRUE(a == b) << w << "x" << h << ": " << a.size() << " bytes against OpenImageIO's " << b.size();
    ++compared;
  }
  EXPECT_EQ(compared, 5);
  Image neg(9, 2, 3, 0.25f);
  neg.data[4] = -1.0f;
  const std::uint64_t before = detail::hdr_direct_writes();
  write_image((d / "neg.hdr").string(), neg, WriteOptions{});
  EXPECT_EQ(detail::hdr_direct_writes(), before);
  fs::remove_all(d);
}

TEST(IO, PngSubsetIsReadAsOpenImageIOReadsIt) {
  // 8/16-bit grey and RGB PNG are read with libpng itself (no OpenImageIO
  // module load): the values (every 8- and 16-bit count), FileInfo and the
  // Description text must be what OpenImageIO gives, bit for bit; every
  // other PNG must be declined by the subset reader and read by OpenImageIO
  // as before.
  fs::path d = tmpdir();
  auto oiio_write = [](const std::string& p, int w, int h, int c, OIIO::TypeDesc t, const void* px,
                       const std::string& desc) {
    OIIO::ImageSpec spec(w, h, c, t);
    if (!desc.empty()) spec.attribute("ImageDescription", desc);
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec)) << p;
    ASSERT_TRUE(out->write_image(t, px)) << p;
    ASSERT_TRUE(out->close()) << p;
  };
  std::vector<std::string> subset, other;
  {
    std::vector<unsigned char> g8(256 * 3);
    for (std::size_t i = 0; i < g8.size(); ++i) g8[i] = static_cast<unsigned char>(i * 7 % 256);
    oiio_write((d / "g8.png").string(), 256, 3, 1, OIIO::TypeDesc::UINT8, g8.data(), "{\"a\": \"brume\"}");
    std::vector<std::uint16_t> g16(256 * 256);
    for (std::size_t i = 0; i < g16.size(); ++i) g16[i] = static_cast<std::uint16_t>(i);
    oiio_write((d / "g16.png").string(), 256, 256, 1, OIIO::TypeDesc::UINT16, g16.data(), "");
    std::vector<unsigned char> c8(97 * 13 * 3);
    for (std::size_t i = 0; i < c8.size(); ++i) c8[i] = static_cast<unsigned char>((i * 2654435761u) >> 24);
    oiio_write((d / "rgb8.png").string(), 97, 13, 3, OIIO::TypeDesc::UINT8, c8.data(), "x");
    std::vector<std::uint16_t> c16(61 * 7 * 3);
    for (std::size_t i = 0; i < c16.size(); ++i) c16[i] = static_cast<std::uint16_t>((i * 2654435761u) >> 16);
    oiio_write((d / "rgb16.png").string(), 61, 7, 3, OIIO::TypeDesc::UINT16, c16.data(), "");
    std::vector<unsigned char> i8(33 * 21 * 3);
    for (std::size_t i = 0; i < i8.size(); ++i) i8[i] = static_cast<unsigned char>(i * 13 % 251);
    write_png_by_hand((d / "interlaced.png").string(), 33, 21, 8, PNG_COLOR_TYPE_RGB, true, i8);
    for (const char* n : {"g8.png", "g16.png", "rgb8.png", "rgb16.png", "interlaced.png"})
      subset.push_back((d / n).string());
    // Outside the subset: alpha (OpenImageIO associates it), grey + alpha,
    // palette, 1-bit grey, a tRNS chunk.
    std::vector<unsigned char> a8(19 * 5 * 4);
    for (std::size_t i = 0; i < a8.size(); ++i) a8[i] = static_cast<unsigned char>(i * 31 % 256);
    oiio_write((d / "rgba.png").string(), 19, 5, 4, OIIO::TypeDesc::UINT8, a8.data(), "");
    oiio_write((d / "ga.png").string(), 19, 5, 2, OIIO::TypeDesc::UINT8, a8.data(), "");
    std::vector<unsigned char> pal(8 * 4);
    for (std::size_t i = 0; i < pal.size(); ++i) pal[i] = static_cast<unsigned char>(i % 4);
    write_png_by_hand((d / "palette.png").string(), 8, 4, 8, PNG_COLOR_TYPE_PALETTE, false, pal);
    std::vector<unsigned char> bits(2 * 4, 0xA5);
    write_png_by_hand((d / "bits1.png").string(), 16, 4, 1, PNG_COLOR_TYPE_GRAY, false, bits);
    std::vector<unsigned char> tr(8 * 4, 3);
    write_png_by_hand((d / "trns.png").string(), 8, 4, 8, PNG_COLOR_TYPE_GRAY, false, tr, true);
    for (const char* n : {"rgba.png", "ga.png", "palette.png", "bits1.png", "trns.png"})
      other.push_back((d / n).string());
  }
  for (const char* rel : {"middlebury2005_thirdsize/Art/view1.png", "middlebury2005_thirdsize/Art/disp1.png"})
    if (have_data(rel)) subset.push_back(data_path(rel));
  auto none = [](int, int, int) {};
  for (const std::string& p : subset) {
    Image raw;
    detail::PngInfo pi;
    EXPECT_TRUE(detail::read_png_subset(p, &raw, pi, none)) << p << " was not read by the subset reader";
  }
  for (const std::string& p : other) {
    Image raw;
    detail::PngInfo pi;
    EXPECT_FALSE(detail::read_png_subset(p, &raw, pi, none)) << p << " is outside the subset";
  }
  std::vector<std::string> all = subset;
  all.insert(all.end(), other.begin(), other.end());
  for (const std::string& p : all) {
    auto in = OIIO::ImageInput::open(p);
    ASSERT_TRUE(in) << p;
    const OIIO::ImageSpec spec = in->spec();
    const int c = spec.nchannels;
    std::vector<float> want(static_cast<std::size_t>(spec.width) * spec.height * c);
    ASSERT_TRUE(in->read_image(0, 0, 0, c, OIIO::TypeDesc::FLOAT, want.data())) << p;
    in.reset();
    const ImageHeader hd = read_header(p);  // (the subset's: the header alone)
    EXPECT_EQ(hd.width, spec.width) << p;
    EXPECT_EQ(hd.height, spec.height) << p;
    EXPECT_EQ(hd.channels, c) << p;
    EXPECT_EQ(hd.format, "png") << p;
    FileInfo info;
    const Image got = read_color(p, Transfer::linear, &info);
    EXPECT_EQ(info.format, "png") << p;
    EXPECT_TRUE(info.integer) << p;
    EXPECT_EQ(info.bits, static_cast<int>(spec.format.size() * 8)) << p;
    EXPECT_EQ(info.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(info.description, spec.get_string_attribute("ImageDescription")) << p;
    ASSERT_EQ(got.width, spec.width) << p;
    ASSERT_EQ(got.height, spec.height) << p;
    // read_color: grey to RGB, alpha dropped; the values themselves (linear).
    std::size_t differ = 0;
    for (std::size_t i = 0; i < got.pixels(); ++i)
      for (int k = 0; k < 3; ++k) {
        const float w = want[i * c + (c >= 3 ? k : 0)];
        if (std::memcmp(&w, &got.data[i * 3 + k], 4) != 0) ++differ;
      }
    EXPECT_EQ(differ, 0u) << p;
    if (c == 1) {  // counts
      const Image counts = read_scalar(p);
      const double max = spec.format.size() == 1 ? 255.0 : 65535.0;
      std::size_t bad = 0;
      for (std::size_t i = 0; i < want.size(); ++i)
        if (counts.data[i] != static_cast<float>(std::nearbyint(want[i] * max))) ++bad;
      EXPECT_EQ(bad, 0u) << p;
    }
  }
  // A file cut inside a chunk is refused by name before libpng (or
  // OpenImageIO after it) allocates the chunk's declared length; a file cut
  // at a chunk boundary goes to libpng, whose error declines it, and then to
  // OpenImageIO (which reads a file that lacks only its IEND, as before).
  auto refusal = [&](const std::string& name) {
    Image raw;
    detail::PngInfo pi;
    try {
      detail::read_png_subset((d / name).string(), &raw, pi, none);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  {
    const std::string b = file_bytes(d / "rgb16.png");
    std::ofstream(d / "cut.png", std::ios::binary) << b.substr(0, b.size() * 2 / 3);
    const std::string e = refusal("cut.png");
    EXPECT_NE(e.find("cut.png"), std::string::npos) << e;
    EXPECT_NE(e.find("IDAT chunk"), std::string::npos) << e;
    EXPECT_NE(e.find("truncated or corrupt"), std::string::npos) << e;
    std::ofstream(d / "cut_at_chunk.png", std::ios::binary) << b.substr(0, b.size() - 12);  // without IEND
    Image raw;
    detail::PngInfo pi;
    EXPECT_FALSE(detail::read_png_subset((d / "cut_at_chunk.png").string(), &raw, pi, none));
    EXPECT_EQ(read_color((d / "cut_at_chunk.png").string()).data, read_color((d / "rgb16.png").string()).data);
  }
  // A tEXt chunk declaring 2^31 - 1 bytes in a file of ~100 (fuzz_image's
  // finding): refused with the chunk's name and sizes, also by read_header
  // and read_color, with no 2 GB allocation (the fuzz regression checks
  // that under libFuzzer's malloc limit).
  {
    std::string b = file_bytes(d / "rgb16.png").substr(0, 33);  // signature and IHDR
    b += std::string("\x7f\xff\xff\xff", 4) + "tEXt" + "Comment";
    std::ofstream(d / "huge_text.png", std::ios::binary) << b;
    const std::string e = refusal("huge_text.png");
    EXPECT_NE(e.find("tEXt chunk at byte 33 declares 2147483647 bytes"), std::string::npos) << e;
    EXPECT_THROW(read_header((d / "huge_text.png").string()), Error);
    EXPECT_THROW(read_color((d / "huge_text.png").string()), Error);
  }
  fs::remove_all(d);
}

namespace {
// PNG assembled chunk by chunk (zlib's compress2 and crc32), so that a test
// sets every byte: the rows' filter bytes, how the zlib stream is split
// into IDAT chunks, what follows them.
std::string be32_bytes(std::uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8), static_cast<char>(v)};
}
std::string png_chunk(const std::string& type, const std::string& data) {
  const std::string body = type + data;
  const auto crc = crc32(0, reinterpret_cast<const Bytef*>(body.data()), static_cast<uInt>(body.size()));
  return be32_bytes(static_cast<std::uint32_t>(data.size())) + body + be32_bytes(static_cast<std::uint32_t>(crc));
}
std::string zlib_stream(const std::string& raw) {
  uLongf n = compressBound(static_cast<uLong>(raw.size()));
  std::string z(n, '\0');
  compress2(reinterpret_cast<Bytef*>(z.data()), &n, reinterpret_cast<const Bytef*>(raw.data()),
            static_cast<uLong>(raw.size()), 6);
  z.resize(n);
  return z;
}
std::string png_head(int w, int h) {  // signature and IHDR: 8-bit grey, not interlaced
  return std::string("\x89PNG\r\n\x1a\n", 8) +
         png_chunk("IHDR", be32_bytes(static_cast<std::uint32_t>(w)) + be32_bytes(static_cast<std::uint32_t>(h)) +
                               std::string("\x08\x00\x00\x00\x00", 5));
}
}  // namespace

TEST(IO, PngImageDataIsDecodedExactly) {
  // The subset reader inflates a non-interlaced file's image data with
  // libdeflate and undoes the row filters itself (png_direct.cpp). PNG
  // decoding is exact, so every count must come back as written, for every
  // filter libpng's writer can force (None, Sub, Up, Average, Paeth, and
  // its adaptive mix), every byte count per pixel of the subset (grey and
  // RGB at 8 and 16 bits: 1, 2, 3, 6), widths of 1 pixel up (a row shorter
  // than the filters' left neighbour), one row (the row above is zeros) and
  // more, the zlib stream in one IDAT chunk or in many small ones; data
  // random, smooth (Paeth's ties) and constant. Each read must take that
  // path (png_fast_reads), and anything unusual must not: it goes to
  // libpng as before, which declines the broken files below.
  fs::path d = tmpdir();
  auto none = [](int, int, int) {};
  Lcg lcg{12345};
  auto rnd = [&] { return lcg.next() >> 24; };
  const std::pair<int, const char*> filters[] = {{PNG_FILTER_NONE, "none"}, {PNG_FILTER_SUB, "sub"},
                                                  {PNG_FILTER_UP, "up"},     {PNG_FILTER_AVG, "avg"},
                                                  {PNG_FILTER_PAETH, "paeth"}, {PNG_ALL_FILTERS, "all"}};
  int files = 0;
  for (int depth : {8, 16})
    for (int color : {PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_RGB})
      for (int w : {1, 2, 7, 64})
        for (int h : {1, 6})
          for (const auto& [filter, fname] : filters)
            for (std::size_t idat : {std::size_t{8192}, std::size_t{61}}) {
              const int c = color == PNG_COLOR_TYPE_RGB ? 3 : 1;
              const std::size_t values = static_cast<std::size_t>(w) * h * c, vb = depth / 8;
              std::vector<unsigned char> bytes(values * vb);
              for (std::size_t i = 0; i < bytes.size(); ++i) {
                const std::size_t row = i / (bytes.size() / h);
                bytes[i] = static_cast<unsigned char>(row % 3 == 0 ? rnd() : row % 3 == 1 ? (i * 7 + row * 3) % 256 : 200);
              }
              const std::string p =
                  (d / ("f_" + std::to_string(depth) + "_" + std::to_string(c) + "_" + std::to_string(w) + "x" +
                        std::to_string(h) + "_" + fname + "_" + std::to_string(idat) + ".png"))
                      .string();
              write_png_by_hand(p, w, h, depth, color, false, bytes, false, filter, idat);
              Image got;
              detail::PngInfo pi;
              const std::uint64_t before = detail::png_fast_reads();
              ASSERT_TRUE(detail::read_png_subset(p, &got, pi, none)) << p;
              EXPECT_EQ(detail::png_fast_reads(), before + 1) << p << " did not take the fast path";
              ASSERT_EQ(got.data.size(), values) << p;
              std::size_t bad = 0;
              for (std::size_t i = 0; i < values; ++i) {
                const unsigned count = vb == 1 ? bytes[i] : (bytes[2 * i] << 8) | bytes[2 * i + 1];
                const float want = static_cast<float>(count) * (depth == 8 ? 1.0f / 255.0f : 1.0f / 65535.0f);
                if (std::memcmp(&want, &got.data[i], 4) != 0) ++bad;
              }
              EXPECT_EQ(bad, 0u) << p;
              ++files;
            }
  EXPECT_EQ(files, 384);

  // Hand-assembled 8-bit grey files, 5 x 4: rows of a filter byte (None) and
  // the counts 10 y + x.
  const int w = 5, h = 4;
  auto rows = [&](int n, int bad_filter_row = -1) {
    std::string raw;
    for (int y = 0; y < n; ++y) {
      raw += static_cast<char>(y == bad_filter_row ? 5 : 0);
      for (int x = 0; x < w; ++x) raw += static_cast<char>(10 * y + x);
    }
    return raw;
  };
  const std::string head = png_head(w, h), iend = png_chunk("IEND", "");
  const std::string z = zlib_stream(rows(h));
  struct Case {
    const char* name;
    std::string bytes;
    bool fast;  // taken by the fast path
    bool read;  // read (by either path: the counts checked)
  };
  std::string bad_crc = png_chunk("IDAT", z);
  bad_crc[bad_crc.size() - 1] ^= 1;
  const Case cases[] = {
      {"split.png",  // the stream in three IDAT chunks, one empty; text after them
       head + png_chunk("IDAT", z.substr(0, 7)) + png_chunk("IDAT", "") + png_chunk("IDAT", z.substr(7)) +
           png_chunk("tEXt", std::string("Comment\0after", 13)) + iend,
       true, true},
      {"bad_filter.png", head + png_chunk("IDAT", zlib_stream(rows(h, 2))) + iend, false, false},
      {"short_stream.png", head + png_chunk("IDAT", zlib_stream(rows(h - 1))) + iend, false, false},
      {"long_stream.png", head + png_chunk("IDAT", zlib_stream(rows(h + 1))) + iend, false, false},
      {"bad_crc.png", head + bad_crc + iend, false, false},
      {"bad_adler.png", head + png_chunk("IDAT", z.substr(0, z.size() - 1) + static_cast<char>(z.back() ^ 1)) + iend,
       false, false},
      {"after_stream.png", head + png_chunk("IDAT", z + "xyz") + iend, false, false},
      {"idat_text_idat.png",
       head + png_chunk("IDAT", z.substr(0, 7)) + png_chunk("tEXt", std::string("Comment\0x", 9)) +
           png_chunk("IDAT", z.substr(7)) + iend,
       false, false},
      // A critical chunk after the image data: left to libpng, which reads
      // the file (it does not check chunks after the image data it reads).
      {"critical_after.png", head + png_chunk("IDAT", z) + png_chunk("ABCD", "x") + iend, false, true},
      {"no_iend.png", head + png_chunk("IDAT", z), false, false},
  };
  for (const Case& k : cases) {
    const std::string p = (d / k.name).string();
    std::ofstream(p, std::ios::binary) << k.bytes;
    Image got;
    detail::PngInfo pi;
    const std::uint64_t before = detail::png_fast_reads();
    const bool read = detail::read_png_subset(p, &got, pi, none);
    EXPECT_EQ(detail::png_fast_reads(), before + (k.fast ? 1 : 0)) << k.name;
    if (k.read) {
      ASSERT_TRUE(read) << k.name;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          EXPECT_EQ(got.data[y * w + x], static_cast<float>(10 * y + x) * (1.0f / 255.0f)) << k.name;
    } else {
      EXPECT_FALSE(read) << k.name << ": libpng read it, or declined it with no complaint";
    }
  }
  fs::remove_all(d);
}

namespace {
// The PNG OpenImageIO's writer makes of img's values at `bits` (8 or 16),
// with brume's attributes for transfer t and description desc, at the
// compression setting comp (brume's spelling: auto, zip:N, none, rle).
void write_png_with_oiio(const std::string& path, const Image& img, const char* bits, Transfer t,
                         const std::string& comp, const std::string& desc) {
  OIIO::ImageSpec spec(img.width, img.height, img.channels,
                       std::string(bits) == "8" ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::UINT16);
  if (img.channels == 1) spec.channelnames = {"Y"};
  spec.attribute("oiio:ColorSpace", t == Transfer::srgb ? "sRGB" : "linear");
  if (!desc.empty()) spec.attribute("ImageDescription", desc);
  if (comp.rfind("zip:", 0) == 0) spec.attribute("png:compressionLevel", std::stoi(comp.substr(4)));
  if (comp == "none") spec.attribute("png:compressionLevel", 0);
  if (comp == "rle") spec.attribute("compression", "rle"), spec.attribute("png:filter", 0x20);
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out && out->open(path, spec)) << path;
  if (t == Transfer::srgb && std::string(bits) == "8") {
    std::vector<std::uint8_t> codes(img.data.size());
    srgb_encode_8(img.data.data(), codes.data(), codes.size());
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, codes.data()));
  } else {
    std::vector<float> v = img.data;
    if (t == Transfer::srgb)
      for (float& x : v) x = linear_to_srgb(std::max(x, 0.0f));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, v.data()));
  }
  ASSERT_TRUE(out->close());
}
}  // namespace

TEST(IO, PngFastIsAPngOfTheSamePixels) {
  // `--compression fast` (brume batch's PNG default) writes the image data
  // itself (Up rows, libdeflate level 1, IDAT chunks of 1 MiB) after the
  // chunks libpng writes. OpenImageIO (its own libpng read, not brume's
  // reader) must read the same values from it as from the `rle` file of
  // the same image, whose bytes before the first IDAT it must share; an
  // image over 1 MiB deflated spans several IDAT chunks; brume reads the
  // file back on its fast path.
  fs::path d = tmpdir();
  Lcg lcg{7};
  auto rnd = [&] { return lcg.unit(); };
  struct Case {
    int w, h, c;
    const char* bits;
    bool noise;
  };
  for (const Case& k : {Case{97, 31, 3, "8", false}, Case{64, 17, 1, "16", false}, Case{53, 9, 3, "16", false},
                        Case{640, 480, 3, "16", true}}) {
    Image img(k.w, k.h, k.c);
    for (int y = 0; y < k.h; ++y)
      for (int x = 0; x < k.w; ++x)
        for (int ch = 0; ch < k.c; ++ch)
          img.at(x, y, ch) = k.noise ? rnd() : static_cast<float>((x * 3 + y * 5 + ch * 40) % 97) / 96.0f;
    const std::string tag = std::to_string(k.w) + "_" + k.bits + "_" + std::to_string(k.c);
    auto write = [&](const std::string& comp) {
      WriteOptions o;
      o.bits = k.bits;
      o.compression = comp;
      const std::string p = (d / (tag + "_" + comp + ".png")).string();
      write_image(p, img, o);
      return p;
    };
    const std::string fast = write("fast"), rle = write("rle");
    auto oiio_counts = [](const std::string& p) {
      auto in = OIIO::ImageInput::open(p);
      EXPECT_TRUE(in) << p;
      if (!in) return std::vector<std::uint16_t>();
      const OIIO::ImageSpec spec = in->spec();
      std::vector<std::uint16_t> v(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
      EXPECT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT16, v.data())) << p;
      return v;
    };
    const std::vector<std::uint16_t> want = oiio_counts(rle);
    ASSERT_EQ(want.size(), img.data.size()) << tag;
    EXPECT_TRUE(oiio_counts(fast) == want) << tag << ": OpenImageIO reads other values from the fast file";
    const std::string fb = file_bytes(fast), rb = file_bytes(rle);
    const std::size_t head = rb.find("IDAT") - 4;  // the first IDAT's length
    ASSERT_NE(head + 4, std::string::npos);
    EXPECT_EQ(fb.substr(0, head), rb.substr(0, head)) << tag << ": the chunks before the image data differ";
    std::size_t idats = 0;
    for (std::size_t at = fb.find("IDAT"); at != std::string::npos; at = fb.find("IDAT", at + 4)) ++idats;
    if (k.noise)  // 640 x 480 x 6 bytes of noise: ~1.8 MB deflated
      EXPECT_GE(idats, 2u) << tag;
    else
      EXPECT_EQ(idats, 1u) << tag;
    EXPECT_EQ(fb.substr(fb.size() - 12), rb.substr(rb.size() - 12)) << tag << ": IEND";
    Image back;
    detail::PngInfo pi;
    const std::uint64_t before = detail::png_fast_reads();
    ASSERT_TRUE(detail::read_png_subset(fast, &back, pi, [](int, int, int) {})) << tag;
    EXPECT_EQ(detail::png_fast_reads(), before + 1) << tag;
  }
  fs::remove_all(d);
}

TEST(IO, PngLongImageDataIsDeflatedInSegments) {
  // Image data over detail::kDeflateSegment bytes are filtered by brume with
  // libpng's choice per row and deflated in segments on several threads
  // (png_direct.hpp). Against OpenImageIO's writer (libpng's single stream)
  // on the same values and settings: the same bytes before the image data,
  // the same filtered rows once inflated (so the same filter on every row:
  // a tie between two filters' sums, or between Paeth's up and up-left
  // neighbours, broken the other way fails it 8x), a stream of about the
  // same length (each segment primed with the 32 KiB before it), and the
  // same file from 1, 2 and 3 threads. Shapes:
  // RGB 8-bit sRGB (the 8-bit codes), grey 16-bit linear (big-endian
  // counts), one column (libpng drops the filters that read to the left)
  // and one row (those that read the row above).
  fs::path d = tmpdir();
  Lcg lcg{11};
  auto rnd = [&] { return lcg.unit(); };
  struct Case {
    int w, h, c;
    const char* bits;
    Transfer t;
  };
  auto image_data = [](const std::string& b) {  // the bytes before the first IDAT, the zlib stream
    const std::size_t first = b.find("IDAT") - 4;
    std::string z;
    for (std::size_t at = first; at + 8 <= b.size();) {
      const std::uint32_t n = (std::uint32_t{static_cast<unsigned char>(b[at])} << 24) |
                              (std::uint32_t{static_cast<unsigned char>(b[at + 1])} << 16) |
                              (std::uint32_t{static_cast<unsigned char>(b[at + 2])} << 8) |
                              static_cast<unsigned char>(b[at + 3]);
      if (b.compare(at + 4, 4, "IDAT") == 0) z += b.substr(at + 8, n);
      at += 12 + n;
    }
    return std::make_pair(b.substr(0, first), z);
  };
  auto inflate_all = [](const std::string& z, std::size_t n) {
    std::string raw(n + 1, '\0');
    uLongf got = static_cast<uLongf>(raw.size());
    const int rc = uncompress(reinterpret_cast<Bytef*>(raw.data()), &got, reinterpret_cast<const Bytef*>(z.data()),
                              static_cast<uLong>(z.size()));
    EXPECT_EQ(rc, Z_OK);
    raw.resize(got);
    return raw;
  };
  // The last two: eight rows of noise repeated down the image (each
  // segment's data repeats what the 8 kB before it holds, so a segment not
  // primed with them codes its first rows as literals: 2-3x the stream),
  // and 16-bit RGB noise (6 bytes a pixel; a stream over 1 MiB, several
  // IDAT chunks).
  for (const Case& k : {Case{480, 400, 3, "8", Transfer::srgb}, Case{300, 480, 1, "16", Transfer::linear},
                        Case{1, 140000, 1, "16", Transfer::linear}, Case{270000, 1, 1, "8", Transfer::linear},
                        Case{1000, 600, 1, "8", Transfer::linear}, Case{640, 480, 3, "16", Transfer::linear}}) {
    Image img(k.w, k.h, k.c);
    std::vector<float> noise(static_cast<std::size_t>(k.w) * 8);
    for (float& v : noise) v = rnd();
    for (int y = 0; y < k.h; ++y)  // smooth gradients with noise in a band: every filter wins somewhere
      for (int x = 0; x < k.w; ++x)
        for (int ch = 0; ch < k.c; ++ch) {
          const float smooth = static_cast<float>((x + 2 * y + 37 * ch) % 400) / 400.0f;
          img.at(x, y, ch) = k.w == 1000   ? noise[static_cast<std::size_t>(y % 8) * 1000 + x]
                             : k.w == 640 ? rnd()
                                          : (y + x) % 97 < 30 ? rnd() : smooth;
        }
    const std::size_t raw_bytes = (static_cast<std::size_t>(k.w) * k.c * (k.bits[0] == '8' ? 1 : 2) + 1) * k.h;
    ASSERT_GT(raw_bytes, detail::kDeflateSegment);
    for (const char* comp : {"auto", "zip:1", "zip:9", "none", "rle"}) {
      const std::string tag = std::to_string(k.w) + "x" + std::to_string(k.h) + "x" + std::to_string(k.c) + " " +
                              k.bits + " bits, " + comp;
      WriteOptions o;
      o.bits = k.bits;
      o.transfer = k.t;
      o.compression = comp;
      std::string mine[3];
      for (int t = 1; t <= 3; ++t) {
        const IoThreads io(t);
        const std::string p = (d / ("mine" + std::to_string(t) + ".png")).string();
        write_image(p, img, o);
        mine[t - 1] = file_bytes(p);
      }
      EXPECT_TRUE(mine[0] == mine[1] && mine[0] == mine[2]) << tag << ": the file depends on the thread count";
      const std::string theirs = (d / "theirs.png").string();
      ASSERT_NO_FATAL_FAILURE(write_png_with_oiio(theirs, img, k.bits, k.t, comp, ""));
      const auto [my_head, my_z] = image_data(mine[0]);
      const auto [their_head, their_z] = image_data(file_bytes(theirs));
      EXPECT_EQ(my_head, their_head) << tag << ": the chunks before the image data differ";
      EXPECT_NE(my_z, their_z) << tag << ": one stream, not segments";
      if (k.w == 640) {  // 1.8 MB of noise: the stream in IDAT chunks of 1 MiB
        EXPECT_GE(my_z.size(), std::size_t{1} << 20) << tag;
      }
      const std::string my_raw = inflate_all(my_z, raw_bytes), their_raw = inflate_all(their_z, raw_bytes);
      ASSERT_EQ(their_raw.size(), raw_bytes) << tag;
      EXPECT_TRUE(my_raw == their_raw) << tag << ": other filtered rows than libpng's";
      // Segments primed with the 32 KiB before them: within 0.5 % (+ 64
      // bytes) of the single stream (without the priming the repeated
      // noise rows' stream is 2.2x OpenImageIO's at every level but none).
      EXPECT_LE(static_cast<double>(my_z.size()), 1.005 * static_cast<double>(their_z.size()) + 64) << tag;
      auto values = [&](const std::string& p) { return k.c == 3 ? read_color(p).data : read_scalar(p).data; };
      EXPECT_TRUE(values((d / "mine1.png").string()) == values(theirs)) << tag;
    }
  }
  fs::remove_all(d);
}

TEST(IO, PngSubsetWritesTheFileOpenImageIOWrites) {
  // brume writes 1- and 3-channel 8/16-bit PNG with libpng itself: the file
  // must be the one OpenImageIO writes from the same values and attributes,
  // byte for byte (chunks, their order, the deflate stream), at each
  // compression setting, sRGB and linear, with and without a description.
  fs::path d = tmpdir();
  for (int w : {64, 37})
    for (int c : {1, 3})
      for (const char* bits : {"8", "16"})
        for (Transfer t : {Transfer::srgb, Transfer::linear})
          for (const char* comp : {"auto", "zip:1", "none", "rle"})
            for (const char* desc : {"", "{\"brume\": 1}"}) {
              Image img(w, 9, c);
              for (std::size_t i = 0; i < img.data.size(); ++i)
                img.data[i] = -0.05f + 1.1f * static_cast<float>((i * 2654435761u) % 10007) / 10006.0f;
              WriteOptions o;
              o.bits = bits;
              o.transfer = t;
              o.compression = comp;
              o.description = desc;
              const std::string mine = (d / "mine.png").string(), theirs = (d / "theirs.png").string();
              write_image(mine, img, o);
              ASSERT_NO_FATAL_FAILURE(write_png_with_oiio(theirs, img, bits, t, comp, desc));
              const std::string ba = file_bytes(mine), bb = file_bytes(theirs);
              EXPECT_TRUE(ba == bb) << "width " << w << ", " << c << " channels, " << bits << " bits, "
                                    << (t == Transfer::srgb ? "sRGB" : "linear") << ", " << comp << ", description '"
                                    << desc << "': " << ba.size() << " against " << bb.size() << " bytes";
            }
  fs::remove_all(d);
}

TEST(IO, UnassociatedChannelsAreReadAsOpenImageIOReadsThem) {
  // read_unassociated (brume insert's object layer): PNG with or without
  // alpha and OpenEXR R G B (A) are read without OpenImageIO's module; the
  // values, the alpha's index, whether it is marked straight, and FileInfo
  // must be OpenImageIO's own reading with oiio:UnassociatedAlpha, bit for
  // bit. Counts cover 0 and the maximum in every channel; a TIFF goes
  // through OpenImageIO itself.
  fs::path d = tmpdir();
  Lcg lcg{5};
  auto rnd = [&] { return lcg.next() >> 8; };
  struct Case {
    const char* name;
    int c;
    OIIO::TypeDesc type;
    bool direct;  // read without the module
  };
  const Case cases[] = {{"rgba8.png", 4, OIIO::TypeDesc::UINT8, true},   {"rgba16.png", 4, OIIO::TypeDesc::UINT16, true},
                        {"ga8.png", 2, OIIO::TypeDesc::UINT8, true},     {"ga16.png", 2, OIIO::TypeDesc::UINT16, true},
                        {"rgb8.png", 3, OIIO::TypeDesc::UINT8, true},    {"y16.png", 1, OIIO::TypeDesc::UINT16, true},
                        {"rgba_h.exr", 4, OIIO::TypeDesc::HALF, true},   {"rgba_f.exr", 4, OIIO::TypeDesc::FLOAT, true},
                        {"rgb_f.exr", 3, OIIO::TypeDesc::FLOAT, true},   {"rgba8.tif", 4, OIIO::TypeDesc::UINT8, false}};
  const int W = 67, H = 23;
  for (const Case& k : cases) {
    const std::string p = (d / k.name).string();
    std::vector<float> v(static_cast<std::size_t>(W) * H * k.c);
    const bool integer = k.type == OIIO::TypeDesc::UINT8 || k.type == OIIO::TypeDesc::UINT16;
    const double max = k.type == OIIO::TypeDesc::UINT8 ? 255.0 : 65535.0;
    for (std::size_t i = 0; i < v.size(); ++i)
      v[i] = i < static_cast<std::size_t>(2 * k.c) ? (i < static_cast<std::size_t>(k.c) ? 0.0f : 1.0f)  // 0 and max
             : integer ? static_cast<float>(static_cast<double>(rnd() % (static_cast<unsigned>(max) + 1)) / max)
                       : static_cast<float>(rnd() % 100000) / 65536.0f;
    OIIO::ImageSpec spec(W, H, k.c, k.type);
    if (k.c == 2) spec.channelnames = {"Y", "A"}, spec.alpha_channel = 1;
    if (k.c == 1) spec.channelnames = {"Y"};
    spec.attribute("oiio:UnassociatedAlpha", 1);  // the counts as given, not un-premultiplied
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec)) << p;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, v.data())) << p;
    ASSERT_TRUE(out->close()) << p;

    OIIO::ImageSpec config;
    config.attribute("oiio:UnassociatedAlpha", 1);
    auto in = OIIO::ImageInput::open(p, &config);
    ASSERT_TRUE(in) << p;
    const OIIO::ImageSpec& s = in->spec();
    std::vector<float> want(static_cast<std::size_t>(s.width) * s.height * s.nchannels);
    ASSERT_TRUE(in->read_image(0, 0, 0, s.nchannels, OIIO::TypeDesc::FLOAT, want.data())) << p;

    const std::uint64_t png_before = detail::png_fast_reads();
    const ChannelImage got = read_unassociated(p, "--object");
    EXPECT_TRUE(got.img.data == want) << p << ": other values than OpenImageIO's";
    EXPECT_EQ(got.img.channels, s.nchannels) << p;
    EXPECT_EQ(got.alpha, s.alpha_channel) << p;
    EXPECT_EQ(got.unassociated, s.get_int_attribute("oiio:UnassociatedAlpha", 0) != 0) << p;
    EXPECT_EQ(got.info.channel_names, std::vector<std::string>(s.channelnames.begin(), s.channelnames.end())) << p;
    EXPECT_EQ(got.info.integer, integer) << p;
    EXPECT_EQ(got.info.bits, static_cast<int>(s.format.size() * 8)) << p;
    EXPECT_EQ(got.info.format, std::string(in->format_name())) << p;
    if (k.direct && std::string(k.name).find(".png") != std::string::npos) {
      EXPECT_EQ(detail::png_fast_reads(), png_before + 1) << p << ": not read by brume's PNG reader";
    }
  }
  // The PNG reader takes alpha only when asked: read_color still declines
  // it to OpenImageIO (which premultiplies, as before).
  detail::PngInfo pi;
  Image img;
  EXPECT_FALSE(detail::read_png_subset((d / "rgba8.png").string(), &img, pi, [](int, int, int) {}));
  EXPECT_TRUE(detail::read_png_subset((d / "rgba8.png").string(), &img, pi, [](int, int, int) {}, {}, true));
  EXPECT_EQ(pi.channels, 4);
  const std::string e = error_of([&] { read_unassociated((d / "none.png").string(), "--object"); });
  EXPECT_NE(e.find("cannot read --object '"), std::string::npos) << e;
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
  fs::remove_all(d);
}
