// TIFF (src/io/formats/tiff.cpp): the contract is pixels and the promised
// metadata. What brume writes reads back, through brume and through
// OpenImageIO, to the counts or floats it stored, with the description and
// bit depth; what OpenImageIO or libtiff write, brume reads to OpenImageIO's
// values; a damaged file is an error naming it.
#include "io/formats/format.hpp"
#include "io/io_test_util.hpp"

using namespace brume::test_io;

namespace {

// OpenImageIO's reading of a file with alpha kept as stored (read_unassociated's
// contract; without the hint OpenImageIO premultiplies an unassociated alpha).
std::vector<float> tiff_oiio_straight(const std::string& p, OIIO::ImageSpec* spec) {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(p, &config);
  EXPECT_TRUE(in) << p;
  if (!in) return {};
  *spec = in->spec();
  std::vector<float> v(static_cast<std::size_t>(spec->width) * spec->height * spec->nchannels);
  EXPECT_TRUE(in->read_image(0, 0, 0, spec->nchannels, OIIO::TypeDesc::FLOAT, v.data())) << p;
  return v;
}

bool tiff_same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * 4) == 0;
}

// The values a test image is made of: a gradient, noise that does not
// deflate, and values outside [0, 1] (clamped by integer storage).
Image tiff_test_image(int w, int h, int c, bool floating) {
  Image img = gradient(w, h, c);
  Lcg rng{12345};
  for (int y = 0; y < std::min(h, 8); ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) img.at(x, y, k) = rng.unit();
  for (std::size_t i = 0; i < img.data.size(); i += 29)
    img.data[i] = floating ? (i % 2 ? -3.25e-6f : 70000.0f) : (i % 2 ? -0.25f : 1.5f);
  return img;
}

}  // namespace

TEST(IO, TiffRoundTripsEveryDepthChannelCountAndCompression) {
  // 8/16-bit and float, 1 to 4 channels (the last of 2 and 4 an alpha),
  // every compression brume offers, one strip and several (640 x 480 is
  // 4 to 19 strips of brume's ~512 KiB): brume reads back the stored counts
  // (round(v x max), clamped) or floats bit for bit, as does OpenImageIO,
  // which also reports the description, the bit depth and the compression.
  // Integer files are stored linear here (the counts are then the values');
  // the sRGB-encoded forms are the next test's.
  fs::path d = tmpdir();
  const std::string desc = R"({"record": "brume", "n": 1})";
  int checked = 0;
  for (const std::string bits : {"8", "16", "float"})
    for (int c = 1; c <= 4; ++c)
      for (const std::string comp : {"auto", "none", "lzw", "zip", "zip:1", "zip:9", "packbits"})
        for (auto [W, H] : {std::pair{1, 1}, std::pair{37, 29}, std::pair{640, 480}}) {
          if (W == 640 && comp != "auto" && comp != "lzw") continue;  // several strips: the two predictor codecs
          const bool floating = bits == "float";
          const Image img = tiff_test_image(W, H, c, floating);
          const std::string tag = bits + "_" + std::to_string(c) + "c_" + comp + "_" + std::to_string(W);
          std::string name = tag;
          std::replace(name.begin(), name.end(), ':', '-');
          const std::string p = (d / (name + ".tif")).string();
          WriteOptions o;
          o.bits = bits;
          o.compression = comp;
          o.description = desc;
          o.transfer = Transfer::linear;
          write_image(p, img, o);
          EXPECT_STREQ(io::last_writer(), "tiff") << tag;
          // The stored values: counts over max as the readers give them (the
          // count times the float 1/max), or the floats.
          const float max = bits == "8" ? 255.0f : 65535.0f;
          std::vector<float> want(img.data.size());
          for (std::size_t i = 0; i < want.size(); ++i)
            want[i] = floating ? img.data[i] : static_cast<float>(io::to_count(img.data[i], max)) * (1.0f / max);
          const ChannelImage got = read_unassociated(p, "--image");
          EXPECT_STREQ(io::last_reader(), "tiff") << tag;
          EXPECT_TRUE(tiff_same_bits(got.img.data, want)) << tag << ": brume reads other values than were stored";
          EXPECT_EQ(got.info.format, "tiff") << tag;
          EXPECT_EQ(got.info.integer, !floating) << tag;
          EXPECT_EQ(got.info.bits, floating ? 32 : std::stoi(bits)) << tag;
          EXPECT_EQ(got.info.description, desc) << tag;
          EXPECT_EQ(got.alpha, c == 2 || c == 4 ? c - 1 : -1) << tag;
          if (c == 2 || c == 4) EXPECT_TRUE(got.unassociated) << tag;
          OIIO::ImageSpec spec;
          const std::vector<float> theirs = tiff_oiio_straight(p, &spec);
          EXPECT_TRUE(tiff_same_bits(theirs, want)) << tag << ": OpenImageIO reads other values than were stored";
          EXPECT_EQ(spec.nchannels, c) << tag;
          EXPECT_EQ(spec.format, bits == "8" ? OIIO::TypeDesc::UINT8 : bits == "16" ? OIIO::TypeDesc::UINT16 : OIIO::TypeDesc::FLOAT) << tag;
          EXPECT_EQ(spec.get_string_attribute("ImageDescription"), desc) << tag;
          EXPECT_EQ(spec.alpha_channel, c == 2 || c == 4 ? c - 1 : -1) << tag;
          EXPECT_EQ(got.info.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << tag;
          const std::string oc = spec.get_string_attribute("compression");
          EXPECT_EQ(oc, comp == "auto" || comp.rfind("zip", 0) == 0 ? std::string("zip") : comp) << tag;
          const ImageHeader hd = read_header(p);
          EXPECT_TRUE(hd.width == W && hd.height == H && hd.channels == c && hd.format == "tiff") << tag;
          ++checked;
        }
  EXPECT_EQ(checked, 3 * 4 * (7 * 2 + 2));
  fs::remove_all(d);
}

TEST(IO, TiffSrgbColourReadsBackThroughTheCurve) {
  // Colour in 8 or 16 bits is stored sRGB-encoded (8-bit: srgb_encode_8's
  // codes; 16-bit: round(linear_to_srgb(v) x 65535)); read_color decodes it
  // to the same linear values as decoding OpenImageIO's reading of the file.
  fs::path d = tmpdir();
  for (const std::string bits : {"8", "16"}) {
    const Image img = tiff_test_image(53, 41, 3, false);
    const std::string p = (d / ("srgb" + bits + ".tif")).string();
    WriteOptions o;
    o.bits = bits;
    write_image(p, img, o);
    std::vector<float> want(img.data.size());
    if (bits == "8") {
      std::vector<std::uint8_t> codes(img.data.size());
      srgb_encode_8(img.data.data(), codes.data(), codes.size());
      for (std::size_t i = 0; i < want.size(); ++i) want[i] = static_cast<float>(codes[i]) * (1.0f / 255.0f);
    } else {
      for (std::size_t i = 0; i < want.size(); ++i)
        want[i] = static_cast<float>(io::to_count(linear_to_srgb(std::max(img.data[i], 0.0f)), 65535.0f)) * (1.0f / 65535.0f);
    }
    EXPECT_TRUE(tiff_same_bits(oiio_pixels(p), want)) << p;
    EXPECT_TRUE(tiff_same_bits(read_color(p, Transfer::linear).data, want)) << p;
    const Image lin = read_color(p);  // automatic: an integer file is sRGB
    ASSERT_EQ(lin.data.size(), want.size());
    for (std::size_t i = 0; i < want.size(); ++i) ASSERT_EQ(lin.data[i], srgb_to_linear(want[i])) << p << " " << i;
  }
  fs::remove_all(d);
}

TEST(IO, TiffFilesOthersWriteReadAsOpenImageIOReadsThem) {
  // Files written by OpenImageIO's writer (every compression it writes,
  // tiles, separate planes, a description), by oiiotool (other strip heights,
  // tiles, compressions) and by libtiff itself with what those do not write
  // (big-endian, BigTIFF, ZSTD, LZMA and JPEG, each predictor, partial tiles
  // and strips, associated alpha): brume's row reads them (no module) to
  // OpenImageIO's values bit for bit, with its FileInfo. The forms outside
  // the row (signed and 12-bit samples, WhiteIsZero, another Orientation,
  // an extra sample that is not an alpha) are read through OpenImageIO.
  fs::path d = tmpdir();
  auto value = [](int x, int y, int k) {
    return 0.5 + 0.45 * std::sin(0.31 * x + 1.7 * k) * std::cos(0.23 * y) + ((x / 4 + y / 3 + k) % 2 ? 0.03 : -0.03);
  };
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
  // oiiotool: a noise pattern in other layouts.
  const std::vector<std::pair<std::string, std::string>> by_oiiotool = {
      {"tool_u16_rgb_rps7_zip.tif", "-d uint16 --compression zip --attrib tiff:RowsPerStrip 7"},
      {"tool_u8_grey_rps1_lzw.tif", "--ch 0 -d uint8 --compression lzw --attrib tiff:RowsPerStrip 1"},
      {"tool_f32_rgb_tile64_zip9.tif", "-d float --compression zip:9 --tile 64 64"},
      {"tool_u16_rgb_tile32_packbits.tif", "-d uint16 --compression packbits --tile 32 32"},
      {"tool_f32_grey_none.tif", "--ch 1 -d float --compression none"},
  };
  for (const auto& [name, args] : by_oiiotool) {
    const std::string p = (d / name).string();
    const std::string cmd = "oiiotool --pattern noise:type=uniform:min=0:max=1:seed=3 83x61 3 " + args + " -o '" + p +
                            "' > /dev/null 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
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
      {"le_u8_rgb_zip_hpred.tif", 45, 23, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_ADOBE_DEFLATE, 2, PLANARCONFIG_CONTIG, 0, 6, "w", 0, 0},
      {"bigtiff_u8_rgb.tif", 26, 19, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_PACKBITS, 1, PLANARCONFIG_CONTIG, 0, 4, "w8", 0, 0},
      {"zstd_u16_grey.tif", 44, 30, 1, 16, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, zstd, 2, PLANARCONFIG_CONTIG, 0, 11, "w", 0, 0},
      {"lzma_f32_rgb_sep.tif", 23, 17, 3, 32, SAMPLEFORMAT_IEEEFP, PHOTOMETRIC_RGB, lzma, 1, PLANARCONFIG_SEPARATE, 0, 3, "w", 0, 0},
      {"tiles_partial_f32.tif", 50, 37, 1, 32, SAMPLEFORMAT_IEEEFP, PHOTOMETRIC_MINISBLACK, COMPRESSION_DEFLATE, 1, PLANARCONFIG_CONTIG, 32, 0, "w", 0, 0},
      {"jpeg_rgb.tif", 32, 16, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_JPEG, 1, PLANARCONFIG_CONTIG, 0, 16, "w", 0, 0},
      {"rgba_assoc_u16.tif", 20, 10, 4, 16, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_ADOBE_DEFLATE, 2, PLANARCONFIG_CONTIG, 0, 0, "w", 0, EXTRASAMPLE_ASSOCALPHA},
      // read through OpenImageIO:
      {"grey_alpha_unspecified.tif", 20, 10, 2, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, EXTRASAMPLE_UNSPECIFIED},
      {"signed.tif", 20, 10, 1, 16, SAMPLEFORMAT_INT, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 0},
      {"twelve_bits.tif", 20, 10, 1, 12, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISBLACK, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 0},
      {"white_is_zero.tif", 20, 10, 1, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_MINISWHITE, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 0, 0},
      {"rotated.tif", 17, 13, 3, 8, SAMPLEFORMAT_UINT, PHOTOMETRIC_RGB, COMPRESSION_NONE, 1, PLANARCONFIG_CONTIG, 0, 0, "w", 3, 0},
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
    if (c.spp == 2 || c.spp == 4) {
      const uint16_t ex[1] = {static_cast<uint16_t>(c.extra)};
      TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, ex);
    }
    if (c.tile) {
      TIFFSetField(t, TIFFTAG_TILEWIDTH, c.tile);
      TIFFSetField(t, TIFFTAG_TILELENGTH, c.tile);
    } else {
      TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, c.rps ? c.rps : c.h);
    }
    // Samples as the file stores them (host order: libtiff swaps for "wb");
    // the whole image a plane, cut into strips or tiles.
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
    if (c.comp == COMPRESSION_JPEG && !TIFFIsCODECConfigured(COMPRESSION_JPEG)) continue;
    raw_write(c);
  }
  // A private tag libtiff does not know (it warns while opening, which does
  // not change the pixels): still the row's.
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

  const std::vector<std::string> by_oiio_module = {"grey_alpha_unspecified.tif", "signed.tif", "twelve_bits.tif",
                                                   "white_is_zero.tif", "rotated.tif"};
  int read = 0, elsewhere = 0;
  for (const auto& e : fs::directory_iterator(d)) {
    const std::string p = e.path().string(), n = e.path().filename().string();
    const bool outside = std::find(by_oiio_module.begin(), by_oiio_module.end(), n) != by_oiio_module.end();
    // read_unassociated: every channel as stored, alpha included.
    OIIO::ImageSpec spec;
    const std::vector<float> want = tiff_oiio_straight(p, &spec);
    const ChannelImage got = read_unassociated(p, "--image");
    EXPECT_STREQ(io::last_reader(), outside ? "oiio" : "tiff") << p;
    if (outside) {
      ++elsewhere;
      continue;
    }
    EXPECT_TRUE(tiff_same_bits(got.img.data, want)) << p << ": other values than OpenImageIO's";
    EXPECT_EQ(got.info.format, "tiff") << p;
    EXPECT_EQ(got.info.integer, spec.format != OIIO::TypeDesc::FLOAT) << p;
    EXPECT_EQ(got.info.bits, static_cast<int>(spec.format.size()) * 8) << p;
    EXPECT_EQ(got.info.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(got.info.description, spec.get_string_attribute("ImageDescription")) << p;
    EXPECT_EQ(got.alpha, spec.alpha_channel) << p;
    EXPECT_EQ(got.unassociated, spec.get_int_attribute("oiio:UnassociatedAlpha") != 0) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_TRUE(hd.width == spec.width && hd.height == spec.height && hd.channels == spec.nchannels && hd.format == "tiff")
        << p;
    // The colour and scalar readers: the same values (as counts for an integer scalar).
    if (spec.nchannels == 3) {
      EXPECT_TRUE(tiff_same_bits(read_color(p, Transfer::linear).data, want)) << p;
      EXPECT_STREQ(io::last_reader(), "tiff") << p;
      if (spec.format != OIIO::TypeDesc::FLOAT) {  // sRGB decoding: OpenImageIO's values through the curve
        const Image lin = read_color(p, Transfer::srgb);
        for (std::size_t i = 0; i < want.size(); i += 7) ASSERT_EQ(lin.data[i], srgb_to_linear(want[i])) << p << " " << i;
      }
    } else if (spec.nchannels == 1) {
      const Image s = read_scalar(p);
      EXPECT_STREQ(io::last_reader(), "tiff") << p;
      const double max = spec.format == OIIO::TypeDesc::UINT8 ? 255.0 : 65535.0;
      std::vector<float> counts = want;
      if (spec.format != OIIO::TypeDesc::FLOAT)
        for (float& v : counts) v = static_cast<float>(std::nearbyint(v * max));
      EXPECT_TRUE(tiff_same_bits(s.data, counts)) << p;
    }
    ++read;
  }
  EXPECT_EQ(read, 9 + 5 + (TIFFIsCODECConfigured(COMPRESSION_JPEG) ? 10 : 9) + 1);
  EXPECT_EQ(elsewhere, 5);
  fs::remove_all(d);
}

TEST(IO, DamagedTiffIsAnErrorNamingTheFile) {
  // A TIFF libtiff recognises but cannot decode -- cut short, a strip's
  // bytes overwritten, a directory past the end -- is an error that names
  // the file and gives libtiff's reason, printable; never pixels of a
  // partial decode, never a crash.
  fs::path d = tmpdir();
  const Image img = tiff_test_image(300, 200, 3, false);
  WriteOptions o;
  o.bits = "16";
  write_image((d / "whole.tif").string(), img, o);
  const std::string whole = file_bytes(d / "whole.tif");
  {
    std::ofstream(d / "cut.tif", std::ios::binary) << whole.substr(0, whole.size() / 2);
    std::string b = whole;
    for (std::size_t i = 200; i < 260; ++i) b[i] = static_cast<char>(0xA5 ^ (i * 7));
    std::ofstream(d / "corrupt.tif", std::ios::binary) << b;
    std::string no_dir = whole.substr(0, 8);
    no_dir[4] = '\x7f';  // IFD0 at 0x7f: past the end
    std::ofstream(d / "no_directory.tif", std::ios::binary) << no_dir;
  }
  for (const char* n : {"cut.tif", "corrupt.tif", "no_directory.tif"}) {
    const std::string p = (d / n).string();
    std::string e;
    try {
      (void)read_color(p, Transfer::linear);
    } catch (const Error& err) {
      e = err.what();
    }
    EXPECT_NE(e.find("cannot read '" + p + "': "), std::string::npos) << n << ": " << e;
    EXPECT_GT(e.size(), ("cannot read '" + p + "': ").size() + 3) << n << ": no reason in " << e;
    EXPECT_EQ(printable_text(e), e) << n;
  }
  fs::remove_all(d);
}
