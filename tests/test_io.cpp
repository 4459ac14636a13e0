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
