// Image I/O through the table of formats: PFM against an independent parser,
// round trips through every format, named EXR channels, raw integer counts,
// sRGB, compression settings, alpha, and error paths.
#include "io/formats/format.hpp"
#include "io/io_test_util.hpp"

using namespace brume::test_io;

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
    EXPECT_NE(std::string(e.what()).find("B, G, R, Z"), std::string::npos) << e.what();  // the file's order
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
  // JPEG: the quality is the compression; auto is 98, as the help says (the
  // same encoder at the same quality: the same file).
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
      EXPECT_STREQ(io::last_reader(), "png") << p << ": not read by the PNG row";
    }
  }
  // The PNG row takes alpha only when asked: read_color leaves it to
  // OpenImageIO (which premultiplies).
  read_color((d / "rgba8.png").string());
  EXPECT_STREQ(io::last_reader(), "oiio");
  EXPECT_EQ(read_unassociated((d / "rgba8.png").string(), "--object").img.channels, 4);
  EXPECT_STREQ(io::last_reader(), "png");
  const std::string e = error_of([&] { read_unassociated((d / "none.png").string(), "--object"); });
  EXPECT_NE(e.find("cannot read --object '"), std::string::npos) << e;
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
  fs::remove_all(d);
}

TEST(IO, EveryRowChecksTheSizeLimitBeforeDecoding) {
  // Each row of the table calls the size check after its header and before
  // it allocates: one pixel over --max-pixels is refused by read_color and
  // read_header with the limit to give; exactly enough reads, by the row.
  struct Reset {
    ~Reset() { set_max_pixels(default_max_pixels); }
  } reset;
  fs::path d = tmpdir();
  const Image img(8, 6, 3, 0.25f);  // 48 pixels
  const std::pair<const char*, const char*> rows[] = {{"png", "png"},      {"jpg", "jpeg"}, {"tif", "tiff"},
                                                      {"exr", "openexr"}, {"pfm", "pnm"},  {"hdr", "hdr"}};
  for (const auto& [ext, row] : rows) {
    const std::string p = (d / (std::string("limit.") + ext)).string();
    write_image(p, img, WriteOptions{});
    set_max_pixels(47);
    for (auto read : std::vector<std::function<void()>>{[&] { read_color(p); }, [&] { read_header(p); }}) {
      try {
        read();
        ADD_FAILURE() << p << " was read over the limit";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("--max-pixels 48"), std::string::npos) << e.what();
      }
    }
    set_max_pixels(48);
    EXPECT_EQ(read_color(p).pixels(), 48u) << p;
    EXPECT_STREQ(io::last_reader(), row) << p;
  }
  fs::remove_all(d);
}
