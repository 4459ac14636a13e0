// JPEG (src/io/formats/jpeg.cpp).
#include "io/io_test_util.hpp"

using namespace brume::test_io;

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
