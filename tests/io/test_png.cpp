// PNG (src/io/formats/png.cpp).
#include "io/io_test_util.hpp"

using namespace brume::test_io;

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
