// File I/O: PFM against an independent parser, round trips through every
// format, named EXR channels, raw integer counts, sRGB, and error paths.
#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

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
  for (const char* c : {"none", "zip", "zip:0", "zip:1", "zip:9"}) {
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
  // JPEG: the quality is the compression.
  EXPECT_LT(fs::file_size(write_as("q20.jpg", "8", "jpeg:20")), fs::file_size(write_as("q100.jpg", "8", "jpeg:100")));

  struct Bad {
    const char* file;
    const char* comp;
    bool data;
    const char* must_contain;
  };
  for (Bad b : {Bad{"x.png", "lzw", false, "none, zip, zip:0..9"}, Bad{"x.png", "zip:10", false, "0..9"},
                Bad{"x.png", "zip:", false, "not a whole number"}, Bad{"x.png", "none:3", false, "takes no level"},
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
