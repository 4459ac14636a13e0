// OpenEXR (src/io/formats/exr.cpp).
#include "io/io_test_util.hpp"

using namespace brume::test_io;

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
