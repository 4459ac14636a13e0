// PNG (src/io/formats/png.cpp): values as OpenImageIO reads them, exact
// decoding of every filter and stream layout, damaged files refused by
// name, and round trips of every compression with their metadata.
#include "io/formats/format.hpp"
#include "io/io_test_util.hpp"

using namespace brume::test_io;

TEST(IO, PngIsReadAsOpenImageIOReadsIt) {
  // 8/16-bit grey and RGB PNG are read by the PNG row (libspng; no
  // OpenImageIO module load): the values (every 8- and 16-bit count),
  // FileInfo and the Description text must be what OpenImageIO gives, bit
  // for bit; the PNGs the row leaves (alpha, palette, 1-bit, tRNS) are read
  // by OpenImageIO, to its values.
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
  for (const char* rel : {"middlebury2005_thirdsize/Art/view1.png", "middlebury2005_thirdsize/Art/disp1.png",
                          "kitti_object_000001/image_2/000001.png", "eth3d_two_view/terrace/im0.png",
                          "eth3d_two_view/playground_1l/im1.png"})
    if (have_data(rel)) subset.push_back(data_path(rel));
  for (const std::string& p : subset) {
    read_color(p);
    EXPECT_STREQ(io::last_reader(), "png") << p << " was not read by the PNG row";
  }
  for (const std::string& p : other) {
    read_color(p);
    EXPECT_STREQ(io::last_reader(), "oiio") << p << " is not the PNG row's";
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
  // A file cut inside its image data is an error naming the file and
  // libspng's reason; a file that lacks only its IEND reads whole (as
  // OpenImageIO reads it).
  auto refusal = [&](const std::string& name) {
    try {
      read_color((d / name).string());
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
    EXPECT_NE(e.find("damaged PNG"), std::string::npos) << e;
    std::ofstream(d / "cut_at_chunk.png", std::ios::binary) << b.substr(0, b.size() - 12);  // without IEND
    EXPECT_EQ(read_color((d / "cut_at_chunk.png").string()).data, read_color((d / "rgb16.png").string()).data);
  }
  // A tEXt chunk declaring 2^31 - 1 bytes in a file of ~100 (fuzz_image's
  // finding): refused by name by read_header and read_color, with no 2 GB
  // allocation (libspng's chunk limit is the file's size; the fuzz
  // regression checks the allocation under libFuzzer's malloc limit).
  {
    std::string b = file_bytes(d / "rgb16.png").substr(0, 33);  // signature and IHDR
    b += std::string("\x7f\xff\xff\xff", 4) + "tEXt" + "Comment";
    std::ofstream(d / "huge_text.png", std::ios::binary) << b;
    const std::string e = refusal("huge_text.png");
    EXPECT_NE(e.find("huge_text.png"), std::string::npos) << e;
    EXPECT_NE(e.find("damaged PNG"), std::string::npos) << e;
    EXPECT_THROW(read_header((d / "huge_text.png").string()), Error);
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
  // PNG decoding is exact, so every count the PNG row reads must come back
  // as libpng wrote it, for every filter libpng's writer can force (None,
  // Sub, Up, Average, Paeth, and its adaptive mix), every byte count per
  // pixel (grey and RGB at 8 and 16 bits: 1, 2, 3, 6), widths of 1 pixel up
  // (a row shorter than the filters' left neighbour), one row (the row
  // above is zeros) and more, the zlib stream in one IDAT chunk or in many
  // small ones; data random, smooth (Paeth's ties) and constant. Broken
  // files are errors naming the file, never values.
  fs::path d = tmpdir();
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
              const Image got = c == 1 ? read_scalar(p) : read_color(p, Transfer::linear);
              EXPECT_STREQ(io::last_reader(), "png") << p;
              ASSERT_EQ(got.data.size(), values) << p;
              std::size_t bad = 0;
              for (std::size_t i = 0; i < values; ++i) {
                const unsigned count = vb == 1 ? bytes[i] : (bytes[2 * i] << 8) | bytes[2 * i + 1];
                const float want = c == 1 ? static_cast<float>(count)  // read_scalar: the counts
                                          : static_cast<float>(count) * (depth == 8 ? 1.0f / 255.0f : 1.0f / 65535.0f);
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
    bool read;  // read (the counts checked); else an error naming the file
  };
  std::string bad_crc = png_chunk("IDAT", z);
  bad_crc[bad_crc.size() - 1] ^= 1;
  const Case cases[] = {
      {"split.png",  // the stream in three IDAT chunks, one empty; text after them
       head + png_chunk("IDAT", z.substr(0, 7)) + png_chunk("IDAT", "") + png_chunk("IDAT", z.substr(7)) +
           png_chunk("tEXt", std::string("Comment\0after", 13)) + iend,
       true},
      {"bad_filter.png", head + png_chunk("IDAT", zlib_stream(rows(h, 2))) + iend, false},
      {"short_stream.png", head + png_chunk("IDAT", zlib_stream(rows(h - 1))) + iend, false},
      // Data past the image's rows in the stream, or after the stream: every
      // row is there and the excess is ignored (libpng calls it a benign
      // error).
      {"long_stream.png", head + png_chunk("IDAT", zlib_stream(rows(h + 1))) + iend, true},
      {"bad_crc.png", head + bad_crc + iend, false},
      {"bad_adler.png", head + png_chunk("IDAT", z.substr(0, z.size() - 1) + static_cast<char>(z.back() ^ 1)) + iend,
       false},
      {"after_stream.png", head + png_chunk("IDAT", z + "xyz") + iend, true},
      {"idat_text_idat.png",
       head + png_chunk("IDAT", z.substr(0, 7)) + png_chunk("tEXt", std::string("Comment\0x", 9)) +
           png_chunk("IDAT", z.substr(7)) + iend,
       false},
      // An unknown critical chunk: PNG's rule is that such an image is not
      // shown (it may change how the data are to be read).
      {"critical_after.png", head + png_chunk("IDAT", z) + png_chunk("ABCD", "x") + iend, false},
      // A file that ends after its image data reads, as OpenImageIO reads it.
      {"no_iend.png", head + png_chunk("IDAT", z), true},
  };
  for (const Case& k : cases) {
    const std::string p = (d / k.name).string();
    std::ofstream(p, std::ios::binary) << k.bytes;
    if (k.read) {
      const Image got = read_scalar(p);
      EXPECT_STREQ(io::last_reader(), "png") << k.name;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) EXPECT_EQ(got.data[y * w + x], static_cast<float>(10 * y + x)) << k.name;
    } else {
      try {
        read_scalar(p);
        ADD_FAILURE() << k.name << " was read";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(k.name), std::string::npos) << e.what();
      }
    }
  }
  fs::remove_all(d);
}

TEST(IO, PngRoundTripsEveryCompressionWithItsMetadata) {
  // The PNG row writes 1 or 3 channels at 8 or 16 bits, every compression
  // setting: the counts round(v x (2^bits - 1)) of the values it is given
  // (sRGB-encoded first for colour at automatic transfer), read back exactly
  // by brume and by OpenImageIO (PNG is lossless), with the description
  // (ASCII in tEXt, UTF-8 in iTXt), the bit depth and the colour space
  // OpenImageIO reports (sRGB chunk: "sRGB"; gAMA 1.0: linear). Noise 640 x
  // 480 x 16-bit makes a stream of several IDAT chunks; 1 x 1 the least.
  fs::path d = tmpdir();
  Lcg lcg{7};
  struct Case {
    int w, h, c;
    const char* bits;
    bool noise;
  };
  const std::string ascii = "{\"brume\": \"record\"}", utf8 = "Brouillard \xc3\xa0 9 km \xe2\x80\x94 record";
  int files = 0;
  for (const Case& k : {Case{97, 31, 3, "8", false}, Case{64, 17, 1, "16", false}, Case{53, 9, 3, "16", false},
                        Case{640, 480, 3, "16", true}, Case{1, 1, 1, "8", false}, Case{5, 3, 1, "8", true}}) {
    Image img(k.w, k.h, k.c);
    for (int y = 0; y < k.h; ++y)
      for (int x = 0; x < k.w; ++x)
        for (int ch = 0; ch < k.c; ++ch)
          img.at(x, y, ch) = k.noise ? lcg.unit() * 1.1f - 0.05f  // a little outside [0, 1]: clamped counts
                                     : static_cast<float>((x * 3 + y * 5 + ch * 40) % 97) / 96.0f;
    const float max = std::string(k.bits) == "8" ? 255.0f : 65535.0f;
    for (const char* comp : {"auto", "zip", "zip:0", "zip:9", "none", "rle", "fast"})
      for (Transfer t : {Transfer::srgb, Transfer::linear}) {
        const std::string tag = std::to_string(k.w) + "x" + std::to_string(k.h) + "x" + std::to_string(k.c) + "_" +
                                k.bits + "_" + comp + (t == Transfer::srgb ? "_srgb" : "_linear");
        const std::string p = (d / (tag + ".png")).string();
        WriteOptions o;
        o.bits = k.bits;
        o.compression = comp;
        o.transfer = t;
        o.description = files % 2 ? utf8 : ascii;
        write_image(p, img, o);
        EXPECT_STREQ(io::last_writer(), "png") << tag;
        // The counts, independently: the value (sRGB-encoded for srgb) times
        // max, rounded half away from zero, clamped.
        std::vector<float> want(img.data.size());
        for (std::size_t i = 0; i < want.size(); ++i) {
          const float v = t == Transfer::srgb ? linear_to_srgb(std::max(img.data[i], 0.0f)) : img.data[i];
          want[i] = std::clamp(std::round(v * max), 0.0f, max);
        }
        FileInfo fi;
        const Image back = read_scalar(p, k.c == 1 ? "" : "G", &fi);
        EXPECT_STREQ(io::last_reader(), "png") << tag;
        EXPECT_EQ(fi.bits, std::atoi(k.bits)) << tag;
        EXPECT_EQ(fi.description, o.description) << tag;
        std::size_t bad = 0;
        for (std::size_t i = 0; i < back.pixels(); ++i)
          bad += back.data[i] != want[i * k.c + (k.c == 3 ? 1 : 0)];
        EXPECT_EQ(bad, 0u) << tag << ": counts other than written";
        OIIO::ImageSpec spec;
        const std::vector<float> theirs = oiio_pixels(p, &spec);
        ASSERT_EQ(theirs.size(), want.size()) << tag;
        bad = 0;
        for (std::size_t i = 0; i < want.size(); ++i) bad += std::nearbyint(theirs[i] * max) != want[i];
        EXPECT_EQ(bad, 0u) << tag << ": OpenImageIO reads other counts";
        EXPECT_EQ(spec.format.size() * 8, std::string(k.bits) == "8" ? 8u : 16u) << tag;
        EXPECT_EQ(spec.get_string_attribute("ImageDescription"), o.description) << tag;
        const std::string cs = spec.get_string_attribute("oiio:ColorSpace");
        if (t == Transfer::srgb)
          EXPECT_EQ(cs, "sRGB") << tag;
        else
          EXPECT_NE(cs, "sRGB") << tag;
        ++files;
      }
    // The settings do what they say: stored blocks are the largest file,
    // and the most effort is no larger than the least on smooth data.
    if (!k.noise && k.w > 1) {
      const auto size = [&](const char* comp) {
        return fs::file_size(d / (std::to_string(k.w) + "x" + std::to_string(k.h) + "x" + std::to_string(k.c) + "_" +
                                  k.bits + "_" + comp + "_linear.png"));
      };
      EXPECT_GT(size("none"), size("auto"));
      EXPECT_LE(size("zip:9"), size("fast"));
    }
  }
  EXPECT_EQ(files, 6 * 7 * 2);
  fs::remove_all(d);
}

TEST(IO, PngAlphaIsStoredStraightAndUnencoded) {
  // Grey+alpha and RGBA: the colour channels sRGB-encoded (colour at
  // automatic transfer), the alpha -- coverage -- stored as its counts,
  // straight as PNG defines it; brume (read_unassociated) and OpenImageIO
  // (told to keep alpha unassociated) read back the same counts.
  fs::path d = tmpdir();
  for (int c : {2, 4})
    for (const char* bits : {"8", "16"}) {
      Image img(23, 7, c);
      for (std::size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<float>((i * 37) % 101) / 100.0f;
      std::string name = std::to_string(c);  // built piecewise: GCC 12's -Wrestrict misfires on "a" + ... (bug 105329)
      name += std::string("_") + bits + ".png";
      const std::string p = (d / name).string();
      WriteOptions o;
      o.bits = bits;
      write_image(p, img, o);
      EXPECT_STREQ(io::last_writer(), "png") << p;
      const float max = std::string(bits) == "8" ? 255.0f : 65535.0f;
      std::vector<float> want(img.data.size());
      for (std::size_t i = 0; i < want.size(); ++i) {
        const bool alpha = static_cast<int>(i % static_cast<std::size_t>(c)) == c - 1;
        const float v = alpha ? img.data[i] : linear_to_srgb(img.data[i]);
        want[i] = std::round(v * max);
      }
      const ChannelImage back = read_unassociated(p, "--object");
      EXPECT_EQ(back.alpha, c - 1) << p;
      ASSERT_EQ(back.img.data.size(), want.size()) << p;
      std::size_t bad = 0;
      for (std::size_t i = 0; i < want.size(); ++i) bad += std::round(back.img.data[i] * max) != want[i];
      EXPECT_EQ(bad, 0u) << p;
      OIIO::ImageSpec config;
      config.attribute("oiio:UnassociatedAlpha", 1);
      auto in = OIIO::ImageInput::open(p, &config);
      ASSERT_TRUE(in) << p;
      std::vector<float> theirs(want.size());
      ASSERT_TRUE(in->read_image(0, 0, 0, c, OIIO::TypeDesc::FLOAT, theirs.data())) << p;
      bad = 0;
      for (std::size_t i = 0; i < want.size(); ++i) bad += std::round(theirs[i] * max) != want[i];
      EXPECT_EQ(bad, 0u) << p << ": OpenImageIO reads other counts";
    }
  fs::remove_all(d);
}
