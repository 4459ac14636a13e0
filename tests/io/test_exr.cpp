// OpenEXR (src/io/formats/exr.cpp): files brume writes read back, through
// brume and through OpenImageIO, to the values written (lossless forms) or
// within a stated error (lossy forms), with their description and colour
// space; files OpenImageIO writes are read to OpenImageIO's values; damaged
// files are errors naming the file.
#include <Imath/half.h>

#include <cerrno>

#include "io/formats/exr.hpp"
#include "io/formats/format.hpp"
#include "io/io_test_util.hpp"

using namespace brume::test_io;

namespace {

// Values that test the edges of both storages: NaN, infinities, a float
// subnormal (0 in half), values past half's range (inf in half), negatives,
// and a ramp of ordinary values.
std::vector<float> edge_values(std::size_t n) {
  std::vector<float> v(n);
  for (std::size_t i = 0; i < n; ++i)
    v[i] = i % 31 == 0   ? NAN
           : i % 37 == 0 ? -INFINITY
           : i % 41 == 0 ? 1e-41f
           : i % 43 == 0 ? 70000.0f
           : i % 47 == 0 ? -3.25e-6f
                         : 0.173f * static_cast<float>(i) - 40.0f;
  return v;
}

// What a file of this storage holds for v: v itself (float), or v rounded to
// half by Imath's conversion (round to nearest even; OpenEXR's too).
std::vector<float> stored(const std::vector<float>& v, bool half) {
  if (!half) return v;
  std::vector<float> r(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) r[i] = static_cast<float>(Imath::half(v[i]));
  return r;
}

// Equal value for value, bit for bit, any NaN equal to any NaN (a NaN's
// payload is not promised). Empty: equal; else where they first differ.
std::string differ(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return std::to_string(a.size()) + " values against " + std::to_string(b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::isnan(a[i]) && std::isnan(b[i])) continue;
    if (std::memcmp(&a[i], &b[i], 4) != 0)
      return "value " + std::to_string(i) + ": " + std::to_string(a[i]) + " against " + std::to_string(b[i]);
  }
  return {};
}

// The row's own read of a file (threads: OpenEXR's pool).
bool row_read(const std::string& p, io::Decoded& out, int threads = 2) {
  io::ReadRequest r;
  r.path = p;
  r.threads = threads;
  return io::exr_format().read(r, out);
}

std::vector<std::string> oiio_names(const OIIO::ImageSpec& spec) {
  return std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end());
}

}  // namespace

TEST(IO, ExrRoundTripsEveryStorageChannelCountAndLosslessCompression) {
  // Half and float, 1 to 5 channels (named as OpenImageIO names them), every
  // lossless compression and zip levels: the file reads back through the row
  // and through OpenImageIO to the values written (half: each rounded to
  // half), bit for bit, with the description. The row reads the sets it
  // takes (one channel, R G B, R G B A); R G and five channels go to
  // OpenImageIO, which gives the same values.
  fs::path d = tmpdir();
  const std::string desc = "{\"record\": \"brume\", \"caf\xC3\xA9\": 1}";
  const std::vector<std::vector<std::string>> names = {
      {"Y"}, {"R", "G"}, {"R", "G", "B"}, {"R", "G", "B", "A"}, {"R", "G", "B", "A", "channel4"}};
  int files = 0;
  for (bool half : {false, true})
    for (int c = 1; c <= 5; ++c)
      for (const char* comp : {"auto", "none", "rle", "zip", "zip:1", "zip:9", "zips", "zips:9", "piz"}) {
        const int W = 37, H = 35;  // three 16-line zip blocks, the last one short; two 32-line piz blocks
        Image img(W, H, c);
        img.data = edge_values(img.data.size());
        std::string tag = std::to_string(c) + (half ? "h_" : "f_") + comp;
        std::replace(tag.begin(), tag.end(), ':', '_');
        const std::string p = (d / (tag + ".exr")).string();
        WriteOptions o;
        o.bits = half ? "half" : "float";
        o.compression = comp;
        o.description = desc;
        o.is_color = c == 3 || c == 4;
        write_image(p, img, o);
        EXPECT_STREQ(io::last_writer(), "openexr") << tag;
        const std::vector<float> want = stored(img.data, half);

        OIIO::ImageSpec spec;
        const std::vector<float> theirs = oiio_pixels(p, &spec);
        EXPECT_EQ(differ(theirs, want), "") << tag << ": OpenImageIO's reading";
        EXPECT_EQ(oiio_names(spec), names[static_cast<std::size_t>(c - 1)]) << tag;
        EXPECT_EQ(spec.format, half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT) << tag;
        EXPECT_EQ(spec.get_string_attribute("ImageDescription"), desc) << tag;
        EXPECT_EQ(spec.get_string_attribute("oiio:ColorSpace"), "Linear") << tag;

        io::Decoded got;
        const bool taken = row_read(p, got);
        EXPECT_EQ(taken, c != 2 && c != 5) << tag;
        if (taken) {
          EXPECT_EQ(got.img.width, W) << tag;
          EXPECT_EQ(got.img.channels, c) << tag;
          EXPECT_EQ(differ(got.img.data, want), "") << tag << ": the row's reading";
          EXPECT_EQ(got.info.format, "openexr");
          EXPECT_FALSE(got.info.integer);
          EXPECT_EQ(got.info.bits, half ? 16 : 32) << tag;
          EXPECT_EQ(got.info.channel_names, names[static_cast<std::size_t>(c - 1)]) << tag;
          EXPECT_EQ(got.info.description, desc) << tag;
          EXPECT_EQ(got.alpha, c == 4 ? 3 : -1) << tag;
          EXPECT_FALSE(got.unassociated) << tag;
          io::Header hd;
          ASSERT_TRUE(io::exr_format().header(p, hd)) << tag;
          EXPECT_EQ(hd.width, W);
          EXPECT_EQ(hd.height, H);
          EXPECT_EQ(hd.channels, c);
        }
        // The public reader of one channel, by name: the row's, or for the
        // other channel sets (R, G; five channels) OpenEXR's named-channel read.
        FileInfo fi;
        const Image first = read_scalar(p, c == 1 ? "" : "R", &fi);
        EXPECT_STREQ(io::last_reader(), "openexr") << tag;
        std::vector<float> want_first;
        for (std::size_t i = 0; i < want.size(); i += static_cast<std::size_t>(c)) want_first.push_back(want[i]);
        EXPECT_EQ(differ(first.data, want_first), "") << tag;
        EXPECT_EQ(fi.description, desc) << tag;
        ++files;
      }
  EXPECT_EQ(files, 90);
  fs::remove_all(d);
}

TEST(IO, ExrLossyCompressionsStayWithinTheirErrors) {
  // pxr24, b44, b44a, dwaa and dwab on a colour image of the kind they are
  // meant for (smooth shading in 0.02..1.3, R G B and R G B A): the row and
  // OpenImageIO read the file to the same values (both decode with
  // OpenEXR), and those are within each form's error of the values written
  // (after rounding to half for half files):
  // each value within max(rel x |v|, abs) of v, each bound with its reason:
  struct Bound {
    const char* comp;
    bool half;
    double rel, abs;
    const char* why;
  };
  const Bound bounds[] = {
      {"pxr24", false, 1.0 / 32768, 0.0, "floats rounded to 24 bits: 15 mantissa bits kept (measured 1.5e-5)"},
      {"pxr24", true, 0.0, 0.0, "halves are stored whole (PXR24 is lossless on half)"},
      {"b44", false, 0.0, 0.0, "B44 compresses half channels only; floats are stored whole"},
      {"b44", true, 0.01, 0.0, "4x4 blocks of 6-bit differences in a log-like space: measured 0.78 % at most"},
      {"b44a", false, 0.0, 0.0, "as b44"},
      {"b44a", true, 0.01, 0.0, "as b44 (flat blocks stored as one value)"},
      {"dwaa", false, 0.0, 0.015,
       "DCT of half values quantised at level 45 in a perceptual space, so about even across shades, not relative: "
       "measured 0.0098 at most (RMS 0.0011)"},
      {"dwaa", true, 0.0, 0.015, "as dwaa float"},
      {"dwab", false, 0.0, 0.015, "as dwaa, in 256-line blocks"},
      {"dwab", true, 0.0, 0.015, "as dwaa"},
  };
  fs::path d = tmpdir();
  for (const Bound& b : bounds)
    for (int c : {3, 4}) {
      const int W = 67, H = 45;
      Image img(W, H, c);
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          for (int k = 0; k < c; ++k)
            img.at(x, y, k) = 0.02f + 1.2f * (0.5f + 0.5f * std::sin(0.07f * x + 0.05f * y + k)) *
                                          (0.4f + 0.6f * static_cast<float>(y) / H);
      const std::string tag = std::string(b.comp) + (b.half ? "_half_" : "_float_") + std::to_string(c);
      const std::string p = (d / (tag + ".exr")).string();
      WriteOptions o;
      o.bits = b.half ? "half" : "float";
      o.compression = b.comp;
      write_image(p, img, o);
      EXPECT_STREQ(io::last_writer(), "openexr") << tag;
      io::Decoded got;
      ASSERT_TRUE(row_read(p, got)) << tag;
      EXPECT_EQ(differ(got.img.data, oiio_pixels(p)), "") << tag << ": the row against OpenImageIO";
      const std::vector<float> want = stored(img.data, b.half);
      for (std::size_t i = 0; i < want.size(); ++i) {
        const double err = std::fabs(static_cast<double>(got.img.data[i]) - want[i]);
        if (!(err <= std::max(b.rel * std::fabs(want[i]), b.abs))) {
          ADD_FAILURE() << tag << " value " << i << ": " << got.img.data[i] << " for " << want[i] << "; " << b.why;
          break;
        }
      }
    }
  fs::remove_all(d);
}

TEST(IO, ExrCompressionLevelsReachTheFile) {
  // zip and zips levels and the DWA level change the file (a higher level:
  // smaller), and the files read back (zip: exactly).
  fs::path d = tmpdir();
  // Shading in steps of 1/64 with a pattern every 7 pixels: long matches, so
  // that the levels' effort shows.
  Image img(256, 64, 3);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      for (int k = 0; k < 3; ++k) img.at(x, y, k) = static_cast<float>((x * 3 + y * 5 + k * 11) % 64 + (x % 7 == 0)) / 64.0f;
  auto size_of = [&](const std::string& comp) {
    std::string name = comp;
    std::replace(name.begin(), name.end(), ':', '_');
    const std::string p = (d / (name + ".exr")).string();
    WriteOptions o;
    o.compression = comp;
    write_image(p, img, o);
    EXPECT_STREQ(io::last_writer(), "openexr") << comp;
    if (comp.rfind("zip", 0) == 0) {
      EXPECT_EQ(differ(read_color(p).data, img.data), "") << comp;
    }
    return fs::file_size(p);
  };
  EXPECT_GT(size_of("zip:1"), size_of("zip:9"));
  EXPECT_GT(size_of("zips:1"), size_of("zips:9"));
  EXPECT_GT(size_of("dwaa:1"), size_of("dwaa:1000"));
  EXPECT_GT(size_of("dwab:1"), size_of("dwab:1000"));
  fs::remove_all(d);
}

TEST(IO, ExrColourSpaceAndDescriptionAsOpenImageIOReadsThem) {
  // An sRGB request is stored as sRGB-encoded values and marked so
  // (OpenImageIO reads "sRGB" back); linear files carry no mark, which
  // OpenImageIO reports as linear.
  fs::path d = tmpdir();
  const Image img = gradient(21, 13, 3);
  WriteOptions o;
  o.transfer = Transfer::srgb;
  o.description = "{\"sky\": \"grey\"}";
  write_image((d / "s.exr").string(), img, o);
  EXPECT_STREQ(io::last_writer(), "openexr");
  OIIO::ImageSpec spec;
  const std::vector<float> v = oiio_pixels((d / "s.exr").string(), &spec);
  EXPECT_EQ(spec.get_string_attribute("oiio:ColorSpace"), "sRGB");
  EXPECT_EQ(spec.get_string_attribute("ImageDescription"), o.description);
  std::vector<float> encoded = img.data;
  for (float& x : encoded) x = linear_to_srgb(std::max(x, 0.0f));
  EXPECT_EQ(differ(v, encoded), "");
  o.transfer = Transfer::linear;
  write_image((d / "l.exr").string(), img, o);
  (void)oiio_pixels((d / "l.exr").string(), &spec);
  EXPECT_EQ(spec.get_string_attribute("oiio:ColorSpace"), "Linear");
  fs::remove_all(d);
}

TEST(IO, ExrThreadsGiveTheSameFileAndValues) {
  // OpenEXR's pool compresses and decompresses line blocks in parallel and
  // writes them in order: the same bytes, the same values, at 1 and 4 threads.
  fs::path d = tmpdir();
  Image img(300, 200, 3);
  img.data = edge_values(img.data.size());
  std::string bytes[2];
  for (int t : {1, 4}) {
    IoThreads scope(t);
    const std::string p = (d / ("t" + std::to_string(t) + ".exr")).string();
    WriteOptions o;
    o.bits = "half";
    write_image(p, img, o);
    bytes[t == 4] = file_bytes(p);
    io::Decoded got;
    ASSERT_TRUE(row_read(p, got, t));
    EXPECT_EQ(differ(got.img.data, stored(img.data, true)), "") << t << " threads";
  }
  EXPECT_TRUE(bytes[0] == bytes[1]);
  fs::remove_all(d);
}

TEST(IO, ExrCoreReadGivesOpenImageIOsValuesAcrossChunksAndThreads) {
  // Scanline files stored without compression, run-length, zips or zip are
  // read through OpenEXR's C core, chunk by chunk on the request's threads,
  // straight into the image (exr.cpp's read_core); OpenImageIO reads them
  // through OpenEXR's InputFile. Files of many chunks, the last one short
  // (150 rows: 150 zips chunks of 1 row, 9 zip chunks of 16 and one of 6),
  // a data window inside a larger display window, increasing and decreasing
  // line order, half and float, one, three and four channels: the same
  // values bit for bit at 1, 3 and 8 threads, the empty pixels the pad value.
  fs::path d = tmpdir();
  const int w = 97, h = 150;
  struct Case {
    const char* compression;
    OIIO::TypeDesc type;
    std::vector<std::string> channels;
    bool decreasing;
  };
  const OIIO::TypeDesc H = OIIO::TypeDesc::HALF, F = OIIO::TypeDesc::FLOAT;
  const std::vector<Case> cases = {
      {"none", F, {"Y"}, false},          {"rle", H, {"R", "G", "B"}, true},
      {"zips", F, {"R", "G", "B", "A"}, false}, {"zip", H, {"Y"}, true},
      {"zip", F, {"R", "G", "B"}, false}, {"zips", H, {"R", "G", "B", "A"}, true},
  };
  for (const Case& k : cases) {
    const std::string p = (d / (std::string(k.compression) + std::to_string(k.channels.size()) +
                                (k.type == H ? "h" : "f") + (k.decreasing ? "d" : "i") + ".exr"))
                              .string();
    const int c = static_cast<int>(k.channels.size());
    OIIO::ImageSpec spec(w, h, c, k.type);
    spec.channelnames = k.channels;
    spec.attribute("compression", k.compression);
    spec.x = 5, spec.y = 3, spec.full_width = w + 9, spec.full_height = h + 7;
    if (k.decreasing) spec.attribute("openexr:lineOrder", "decreasingY");
    const std::vector<float> v = edge_values(static_cast<std::size_t>(w) * h * c);
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec) && out->write_image(OIIO::TypeDesc::FLOAT, v.data()) && out->close()) << p;
    OIIO::ImageSpec got_spec;
    const std::vector<float> inside = oiio_pixels(p, &got_spec);
    const int fw = w + 9, fh = h + 7;
    const float pad = -2.5f;
    std::vector<float> want(static_cast<std::size_t>(fw) * fh * c, pad);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int ch = 0; ch < c; ++ch)
          want[(static_cast<std::size_t>(y + 3) * fw + (x + 5)) * c + ch] = inside[(static_cast<std::size_t>(y) * w + x) * c + ch];
    for (int threads : {1, 3, 8}) {
      io::ReadRequest r;
      r.path = p;
      r.threads = threads;
      r.pad = pad;
      io::Decoded got;
      ASSERT_TRUE(io::exr_format().read(r, got)) << p;
      EXPECT_EQ(got.img.width, fw) << p;
      EXPECT_EQ(got.img.height, fh) << p;
      EXPECT_EQ(differ(got.img.data, want), "") << p << " at " << threads << " threads";
      EXPECT_EQ(got.info.channel_names, oiio_names(got_spec)) << p;
    }
  }
  fs::remove_all(d);
}

TEST(IO, ExrFilesOpenImageIOWritesAreReadAsItReadsThem) {
  // Files OpenImageIO writes -- every compression, scanline and tiled, data
  // windows from (3, 2) and inside a larger display window, decreasing line
  // order, NaN, inf and subnormal values -- are read by the row to
  // OpenImageIO's values, bit for bit, with its FileInfo, at 0 and 2 threads.
  // Other files (other channel sets, mixed or integer channels, two parts)
  // are not the row's and go to OpenImageIO, with the same result.
  fs::path d = tmpdir();
  struct Spec {
    std::string name;
    int w, h;
    std::vector<std::string> channels;
    OIIO::TypeDesc type;
    std::string compression;
    bool tiled = false;
    bool window = false;      // data window (3, 2) inside a display window 6 wider, 4 taller
    bool mixed = false;       // first channel float, the others half
    int subimages = 1;
    bool origin = false;      // data and display windows from (3, 2)
    bool decreasing = false;  // line order DECREASING_Y
  };
  auto write = [&](const Spec& s) {
    const std::string p = (d / s.name).string();
    const int c = static_cast<int>(s.channels.size());
    OIIO::ImageSpec spec(s.w, s.h, c, s.type);
    spec.channelnames = s.channels;
    spec.attribute("compression", s.compression);
    spec.attribute("ImageDescription", "{\"written\": \"" + s.name + "\"}");
    if (s.tiled) spec.tile_width = spec.tile_height = 16;
    if (s.window) spec.x = 3, spec.y = 2, spec.full_width = s.w + 6, spec.full_height = s.h + 4;
    if (s.origin) spec.x = spec.full_x = 3, spec.y = spec.full_y = 2;
    if (s.decreasing) spec.attribute("openexr:lineOrder", "decreasingY");
    if (s.mixed) {
      spec.channelformats.assign(static_cast<std::size_t>(c), OIIO::TypeDesc::HALF);
      spec.channelformats[0] = OIIO::TypeDesc::FLOAT;
    }
    const std::vector<float> v = edge_values(static_cast<std::size_t>(s.w) * s.h * c);
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
  std::vector<Spec> taken = {
      {"y_zip.exr", 37, 23, {"Y"}, F, "zip"},
      {"y_half_piz.exr", 37, 23, {"Y"}, H, "piz"},
      {"rgb_half_none.exr", 41, 19, {"R", "G", "B"}, H, "none"},
      {"rgba_float_rle.exr", 41, 19, {"R", "G", "B", "A"}, F, "rle"},
      {"z_tiled_zips.exr", 45, 33, {"Z"}, F, "zips", true},
      {"rgba_tiled_half_piz.exr", 45, 33, {"R", "G", "B", "A"}, H, "piz", true},
      {"depthz_half_b44.exr", 40, 24, {"depth.Z"}, H, "b44"},
      {"rgb_float_pxr24.exr", 29, 35, {"R", "G", "B"}, F, "pxr24"},
      {"rgb_half_dwaa.exr", 70, 40, {"R", "G", "B"}, H, "dwaa"},
      {"rgb_half_dwab.exr", 70, 40, {"R", "G", "B"}, H, "dwab"},
      {"y_window.exr", 21, 13, {"Y"}, F, "zip", false, true},
      {"rgb_tiled_window.exr", 21, 13, {"R", "G", "B"}, H, "zip", true, true},
      {"rgb_half_zip_origin.exr", 70, 40, {"R", "G", "B"}, H, "zip"},
      {"rgba_float_zips_decreasing.exr", 41, 19, {"R", "G", "B", "A"}, F, "zips"},
  };
  for (Spec& s : taken) {
    s.origin = s.name.find("origin") != std::string::npos;
    s.decreasing = s.name.find("decreasing") != std::string::npos;
  }
  const std::vector<Spec> others = {
      {"rgbz.exr", 21, 13, {"R", "G", "B", "Z"}, F, "zip"},
      {"ya.exr", 21, 13, {"Y", "A"}, H, "zip"},
      {"mixed.exr", 21, 13, {"R", "G", "B"}, H, "zip", false, false, true},
      {"uint.exr", 21, 13, {"Y"}, OIIO::TypeDesc::UINT, "zip"},
      {"two_parts.exr", 21, 13, {"R", "G", "B"}, F, "zip", false, false, false, 2},
  };
  for (const Spec& s : taken) {
    write(s);
    const std::string p = (d / s.name).string();
    OIIO::ImageSpec spec;
    std::string format;
    std::vector<float> want = oiio_pixels(p, &spec, &format);
    if (s.window) {
      // brume reads the display window (issue #50): OpenImageIO's data-window
      // pixels placed in it, 0 elsewhere (OpenEXR's empty pixels).
      const int C = spec.nchannels, fw = spec.full_width, fh = spec.full_height;
      std::vector<float> full(static_cast<std::size_t>(fw) * fh * C, 0.0f);
      for (int y = 0; y < spec.height; ++y)
        for (int x = 0; x < spec.width; ++x)
          for (int c = 0; c < C; ++c)
            full[(static_cast<std::size_t>(y + spec.y - spec.full_y) * fw + (x + spec.x - spec.full_x)) * C + c] =
                want[(static_cast<std::size_t>(y) * spec.width + x) * C + c];
      want = full;
      spec.width = fw, spec.height = fh;
    }
    for (int threads : {0, 2}) {
      io::Decoded got;
      ASSERT_TRUE(row_read(p, got, threads)) << p;
      expect_oiio_image(p, got.img, spec, want);
      EXPECT_EQ(got.info.channel_names, oiio_names(spec)) << p;
      EXPECT_EQ(got.info.bits, static_cast<int>(spec.format.size() * 8)) << p;
      EXPECT_EQ(got.info.description, spec.get_string_attribute("ImageDescription")) << p;
    }
    EXPECT_EQ(format, "openexr");
    // The public readers take the row and report OpenImageIO's FileInfo.
    FileInfo fi;
    const Image pub = s.channels.size() == 1 ? read_scalar(p, "", &fi) : read_color(p, Transfer::linear, &fi);
    EXPECT_STREQ(io::last_reader(), "openexr") << p;
    if (s.channels.size() == 1 && !s.window) {
      EXPECT_EQ(differ(pub.data, want), "") << p;
    }
    if (s.channels.size() == 1 && s.window) {  // read_scalar's empty pixels are unknown
      std::vector<float> unknown_outside = want;
      for (int y = 0; y < spec.height; ++y)
        for (int x = 0; x < spec.width; ++x)
          if (x < 3 || y < 2 || x >= 3 + s.w || y >= 2 + s.h)
            unknown_outside[static_cast<std::size_t>(y) * spec.width + x] = NAN;
      EXPECT_EQ(differ(pub.data, unknown_outside), "") << p;
    }
    EXPECT_EQ(fi.format, "openexr") << p;
    EXPECT_FALSE(fi.integer) << p;
    EXPECT_EQ(fi.bits, static_cast<int>(spec.format.size() * 8)) << p;
    EXPECT_EQ(fi.channel_names, oiio_names(spec)) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_EQ(hd.width, spec.width);
    EXPECT_EQ(hd.height, spec.height);
    EXPECT_EQ(hd.channels, spec.nchannels);
    EXPECT_EQ(hd.format, "openexr");
  }
  for (const Spec& s : others) {
    write(s);
    const std::string p = (d / s.name).string();
    OIIO::ImageSpec spec;
    const std::vector<float> want = oiio_pixels(p, &spec);
    io::Decoded got;
    EXPECT_FALSE(row_read(p, got)) << p << " was taken by the row";
    FileInfo fi;
    // Channels beyond the plain sets and parts are read by name through
    // OpenEXR's multi-part API (issue #50); the plain ones OpenImageIO reads.
    const bool named = s.name == "rgbz.exr" || s.name == "two_parts.exr";
    if (s.subimages > 1) {  // "R" is in both parts: refused with the list
      const std::string e = error_of([&] { (void)read_scalar(p, "R", &fi); });
      EXPECT_NE(e.find("in 2 parts"), std::string::npos) << e;
      continue;
    }
    const Image pub = s.channels.size() == 1 ? read_scalar(p, "", &fi) : read_scalar(p, s.channels[0], &fi);
    EXPECT_STREQ(io::last_reader(), named ? "openexr" : "oiio") << p;
    if (named) {  // the file's own order (OpenEXR sorts by name)
      std::vector<std::string> a = fi.channel_names, b = oiio_names(spec);
      std::sort(a.begin(), a.end()), std::sort(b.begin(), b.end());
      EXPECT_EQ(a, b) << p;
    } else {
      EXPECT_EQ(fi.channel_names, oiio_names(spec)) << p;
    }
    ASSERT_EQ(pub.data.size(), want.size() / static_cast<std::size_t>(spec.nchannels)) << p;
    if (!spec.format.is_floating_point()) continue;  // read_scalar gives an integer file's counts
    std::vector<float> first;
    for (std::size_t i = 0; i < want.size(); i += static_cast<std::size_t>(spec.nchannels)) first.push_back(want[i]);
    EXPECT_EQ(differ(pub.data, first), "") << p;
  }
  fs::remove_all(d);
}

TEST(IO, ExrDamagedFilesAreErrorsNamingTheFile) {
  // A file of the row's kind that OpenEXR cannot decode -- a damaged zip
  // block, a truncated file, a damaged header -- is an error that names the
  // file and gives OpenEXR's reason; nothing is returned.
  fs::path d = tmpdir();
  const std::string full = (d / "full.exr").string();
  Image img(70, 40, 3);
  img.data = edge_values(img.data.size());
  write_image(full, img, WriteOptions{});
  const std::string bytes = file_bytes(full);
  auto damaged = [&](const std::string& name, const std::string& b) {
    const std::string p = (d / name).string();
    std::ofstream(p, std::ios::binary) << b;
    for (int k = 0; k < 3; ++k) {
      std::string e;
      try {
        if (k == 0) (void)read_color(p);
        if (k == 1) {
          io::Decoded got;
          (void)row_read(p, got);
        }
        if (k == 2) (void)read_unassociated(p, "--object");
      } catch (const Error& x) {
        e = x.what();
      }
      EXPECT_NE(e.find("cannot read"), std::string::npos) << name << " reader " << k << ": " << e;
      EXPECT_NE(e.find(p), std::string::npos) << name << " reader " << k << ": " << e;
    }
  };
  std::string block = bytes;
  block[block.size() - 40] = static_cast<char>(block[block.size() - 40] ^ 0x5a);
  damaged("bad_block.exr", block);
  damaged("cut.exr", bytes.substr(0, bytes.size() * 2 / 3));
  damaged("no_pixels.exr", bytes.substr(0, 300));
  // A window that ends before it starts: OpenEXR's header check.
  std::string window = bytes;
  const std::size_t at = window.find(std::string("dataWindow\0box2i\0", 17));
  ASSERT_NE(at, std::string::npos);
  const std::int32_t max_x = -5;
  std::memcpy(&window[at + 17 + 4 + 8], &max_x, 4);
  damaged("window.exr", window);
  fs::remove_all(d);
}

TEST(IO, ExrHugeAttributeIsRefusedOnEveryPath) {
  // OpenEXR 3.1 allocates a header attribute at its declared size; the guard
  // refuses an attribute larger than the rest of the file before OpenEXR
  // opens it, on every reader, naming the file (the fuzz reproducer: its
  // first byte is the fuzz target's choice of extension).
  fs::path d = tmpdir();
  const fs::path repro = fs::path(__FILE__).parent_path().parent_path().parent_path() / "fuzz" / "corpus" / "image" /
                         "openexr_huge_attribute.bin";
  ASSERT_TRUE(fs::exists(repro)) << repro;
  const std::string p = (d / "huge.exr").string();
  std::ofstream(p, std::ios::binary) << file_bytes(repro).substr(1);
  auto refused = [&](const char* what, const std::function<void()>& f) {
    std::string e;
    try {
      f();
    } catch (const Error& x) {
      e = x.what();
    }
    EXPECT_NE(e.find("declares"), std::string::npos) << what << ": " << e;
    EXPECT_NE(e.find(p), std::string::npos) << what << ": " << e;
  };
  refused("read_header", [&] { (void)read_header(p); });
  refused("read_color", [&] { (void)read_color(p); });
  refused("read_scalar", [&] { (void)read_scalar(p); });
  refused("read_unassociated", [&] { (void)read_unassociated(p, "--object"); });
  refused("the row's header", [&] {
    io::Header h;
    (void)io::exr_format().header(p, h);
  });
  refused("the row's read", [&] {
    io::Decoded got;
    (void)row_read(p, got);
  });
  refused("the guard", [&] { io::check_exr_attributes(p); });
  fs::remove_all(d);
}

TEST(IO, ExrHeaderLimitsComeBeforeAllocation) {
  // check() sees the size before any pixel is allocated or decoded; what it
  // throws propagates and nothing is returned.
  fs::path d = tmpdir();
  const std::string p = (d / "a.exr").string();
  write_image(p, gradient(40, 30, 4), WriteOptions{});
  io::ReadRequest r;
  r.path = p;
  int w = 0, h = 0, c = 0;
  r.check = [&](int a, int b, int k) {
    w = a, h = b, c = k;
    throw Error("over the limit");
  };
  io::Decoded got;
  EXPECT_THROW(io::exr_format().read(r, got), Error);
  EXPECT_EQ(w, 40);
  EXPECT_EQ(h, 30);
  EXPECT_EQ(c, 4);
  EXPECT_TRUE(got.img.data.empty());
  fs::remove_all(d);
}

TEST(IO, ExrWriteFailureGivesTheReasonAndErrno) {
  // A file that cannot be created: false, errno and OpenEXR's reason naming it.
  const std::vector<float> v(12, 0.5f);
  io::WriteRequest r;
  r.width = 2, r.height = 2, r.channels = 3, r.values = v.data();
  std::string why;
  errno = 0;
  EXPECT_FALSE(io::exr_format().write("/nonexistent-brume-dir/x.exr", r, &why));
  EXPECT_EQ(errno, ENOENT);
  EXPECT_NE(why.find("/nonexistent-brume-dir/x.exr"), std::string::npos) << why;
  // Integer storage is not OpenEXR's: --bits 16 is refused by the table,
  // before any work, naming what .exr takes.
  WriteOptions o;
  o.bits = "16";
  try {
    write_image((fs::temp_directory_path() / "brume_exr_bits16.exr").string(), Image(2, 2, 3, 0.5f), o);
    ADD_FAILURE() << "16-bit integer EXR was written";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("half or float"), std::string::npos) << e.what();
  }
}
