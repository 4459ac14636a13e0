// TIFF (src/io/formats/tiff.cpp).
#include "io/io_test_util.hpp"

using namespace brume::test_io;

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
