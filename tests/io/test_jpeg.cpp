// JPEG (src/io/formats/jpeg.cpp): what brume writes reads back, through
// brume and through OpenImageIO, to the same decoded pixels, near what was
// written, with the description; what OpenImageIO writes and the shared
// photos read to OpenImageIO's values; a damaged file is an error naming it.
#include <cstddef>  // (jpeglib.h uses size_t and FILE without including their headers)
#include <cstdio>
#include <jpeglib.h>

#include "io/formats/format.hpp"
#include "io/io_test_util.hpp"

using namespace brume::test_io;

namespace {
bool jpeg_same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * 4) == 0;
}
}  // namespace

TEST(IO, JpegRoundTripsGreyAndColourAtEveryQuality) {
  // Grey and colour at the default quality (98) and others, sizes from 1 x 1
  // to partial MCUs: brume's reading equals OpenImageIO's bit for bit (the
  // same library decodes), the description comes back whole -- one comment,
  // or several for a text past a marker's 65 533 bytes, which OpenImageIO
  // reports as its first part -- and the counts are near the written ones:
  // the largest error is bounded per quality (on a smooth gradient, the
  // content JPEG is meant for).
  fs::path d = tmpdir();
  struct Quality {
    const char* compression;
    int max_error;  // counts of 255, on this content (measured, with headroom)
    const char* subsampling;
  };
  // At 90 and above, chroma is kept at full resolution (4:4:4).
  // The bounds: the largest error measured on this gradient (2026-12-05,
  // libjpeg-turbo 2.1.5) plus one count. Colour's floor is the 8-bit YCbCr
  // round trip itself (4 counts at quality 100, where the DCT's quantisation
  // is all ones); a partial MCU (37 x 21) is the worst case at each quality.
  // Quality 1 promises no likeness, only a file that decodes.
  const Quality qualities[] = {{"auto", 6, "4:4:4"}, {"jpeg:100", 5, "4:4:4"}, {"jpeg:90", 15, "4:4:4"},
                               {"jpeg:50", 36, "4:2:0"}, {"jpeg:1", 255, "4:2:0"}};
  int checked = 0;
  for (int c : {1, 3})
    for (const Quality& q : qualities)
      for (auto [W, H] : {std::pair{1, 1}, std::pair{37, 21}, std::pair{160, 120}})
        for (std::size_t dl : {std::size_t{0}, std::size_t{1175}, std::size_t{150000}}) {
          if (dl == 150000 && (W != 37 || std::string(q.compression) != "auto")) continue;  // one long text is enough
          std::string desc;
          for (std::size_t i = 0; i < dl; ++i) desc += static_cast<char>(i % 61 == 60 ? ' ' : 'a' + i % 26);
          const Image img = gradient(W, H, c);
          const std::string tag = std::to_string(c) + "c_" + q.compression + "_" + std::to_string(W) + "_d" + std::to_string(dl);
          std::string name = tag;
          std::replace(name.begin(), name.end(), ':', '-');
          const std::string p = (d / (name + ".jpg")).string();
          WriteOptions o;
          o.compression = q.compression;
          o.description = desc;
          o.is_color = c == 3;
          write_image(p, img, o);
          EXPECT_STREQ(io::last_writer(), "jpeg") << tag;
          OIIO::ImageSpec spec;
          const std::vector<float> theirs = oiio_pixels(p, &spec);
          ChannelImage got = read_unassociated(p, "--image");
          EXPECT_STREQ(io::last_reader(), "jpeg") << tag;
          EXPECT_TRUE(jpeg_same_bits(got.img.data, theirs)) << tag << ": other values than OpenImageIO's";
          EXPECT_EQ(got.info.format, "jpeg") << tag;
          EXPECT_EQ(got.info.bits, 8) << tag;
          EXPECT_TRUE(got.info.integer) << tag;
          EXPECT_EQ(got.info.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << tag;
          EXPECT_EQ(got.info.description, desc) << tag;
          const std::string od = spec.get_string_attribute("ImageDescription");
          EXPECT_EQ(od, desc.substr(0, 65533)) << tag << ": OpenImageIO's description";
          if (c == 3) {
            EXPECT_EQ(spec.get_string_attribute("jpeg:subsampling"), q.subsampling) << tag;
          }
          // The stored counts: sRGB codes for colour, round(v x 255) for grey data.
          std::vector<std::uint8_t> codes(img.data.size());
          if (c == 3) {
            srgb_encode_8(img.data.data(), codes.data(), codes.size());
          } else {
            for (std::size_t i = 0; i < codes.size(); ++i) codes[i] = static_cast<std::uint8_t>(io::to_count(img.data[i], 255.0f));
          }
          int worst = 0;
          for (std::size_t i = 0; i < codes.size(); ++i)
            worst = std::max(worst, std::abs(static_cast<int>(std::lround(got.img.data[i] * 255.0f)) - codes[i]));
          EXPECT_LE(worst, q.max_error) << tag;
          ++checked;
        }
  EXPECT_EQ(checked, 2 * (5 * 3 * 2 + 1));
  fs::remove_all(d);
}

TEST(IO, JpegFilesOthersWriteReadAsOpenImageIOReadsThem) {
  // 4:2:0, 4:2:2 and 4:4:4 colour, grey, progressive, odd sizes (partial
  // MCUs) and a description, written by OpenImageIO, and the shared photo
  // (../shared/data's geopose3k_matterhorn/photo.jpg, when present):
  // brume's row reads them (no module) to OpenImageIO's values bit for bit
  // and its FileInfo; read_color's sRGB decoding is OpenImageIO's values
  // through the curve. A CMYK file is read through OpenImageIO.
  fs::path d = tmpdir();
  struct Spec {
    std::string name;
    int w, h, c;
    std::string subsampling;  // "" : OpenImageIO's default
    bool progressive = false;
    std::string comment;
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
  const std::vector<Spec> specs = {
      {"rgb.jpg", 64, 48, 3, "", false, "", 90},
      {"rgb_odd_420.jpg", 37, 23, 3, "4:2:0", false, "", 90},
      {"rgb_422.jpg", 41, 19, 3, "4:2:2", false, "", 90},
      {"rgb_444_q100.jpg", 29, 35, 3, "4:4:4", false, "", 100},
      {"rgb_progressive.jpg", 70, 40, 3, "", true, "", 90},
      {"grey_odd.jpg", 45, 33, 1, "", false, "", 90},
      // (OpenImageIO writes a description as a comment, in Exif and in IPTC)
      {"grey_progressive_comment.jpg", 33, 17, 1, "", true, "a comment", 90},
      {"rgb_comment.jpg", 40, 24, 3, "", false, R"({"record": "brume"})", 90},
  };
  std::vector<std::string> files;
  for (const Spec& s : specs) {
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
    files.push_back(p);
  }
  // The shared photo (a 1225 x 871 camera JPEG), when ../shared/data is there.
  if (have_data("geopose3k_matterhorn/photo.jpg")) files.push_back(data_path("geopose3k_matterhorn/photo.jpg"));
  for (const std::string& p : files) {
    OIIO::ImageSpec spec;
    const std::vector<float> want = oiio_pixels(p, &spec);
    const Image got = spec.nchannels == 3 ? read_color(p, Transfer::linear) : read_unassociated(p, "--image").img;
    EXPECT_STREQ(io::last_reader(), "jpeg") << p;
    EXPECT_TRUE(jpeg_same_bits(got.data, want)) << p << ": other values than OpenImageIO's";
    FileInfo fi;
    const Image lin = read_color(p, Transfer::automatic, &fi);
    EXPECT_EQ(fi.format, "jpeg") << p;
    EXPECT_EQ(fi.bits, 8) << p;
    EXPECT_EQ(fi.description, spec.get_string_attribute("ImageDescription")) << p;
    if (spec.nchannels == 3) {
      for (std::size_t i = 0; i < want.size(); i += 7) ASSERT_EQ(lin.data[i], srgb_to_linear(want[i])) << p << " " << i;
    }
    const ImageHeader hd = read_header(p);
    EXPECT_TRUE(hd.width == spec.width && hd.height == spec.height && hd.channels == spec.nchannels && hd.format == "jpeg") << p;
  }
  // CMYK, written with libjpeg: outside the row (OpenImageIO converts it).
  {
    const std::string p = (d / "cmyk.jpg").string();
    std::FILE* f = std::fopen(p.c_str(), "wb");
    ASSERT_TRUE(f);
    jpeg_compress_struct z{};
    jpeg_error_mgr err{};
    z.err = jpeg_std_error(&err);
    jpeg_create_compress(&z);
    jpeg_stdio_dest(&z, f);
    z.image_width = 16, z.image_height = 8, z.input_components = 4, z.in_color_space = JCS_CMYK;
    jpeg_set_defaults(&z);
    jpeg_start_compress(&z, TRUE);
    std::vector<unsigned char> row(16 * 4, 100);
    for (int y = 0; y < 8; ++y) {
      JSAMPROW r = row.data();
      jpeg_write_scanlines(&z, &r, 1);
    }
    jpeg_finish_compress(&z);
    jpeg_destroy_compress(&z);
    std::fclose(f);
    OIIO::ImageSpec spec;
    const std::vector<float> want = oiio_pixels(p, &spec);
    EXPECT_TRUE(jpeg_same_bits(read_color(p, Transfer::linear).data, want)) << p;
    EXPECT_STREQ(io::last_reader(), "oiio") << p;
  }
  fs::remove_all(d);
}

TEST(IO, DamagedJpegIsAnErrorNamingTheFile) {
  // A JPEG cut short (libjpeg would fill the rest with grey and warn), one
  // whose scan ends early at an inserted marker, and one whose header is
  // garbage: each an error naming the file and libjpeg's reason, printable.
  fs::path d = tmpdir();
  Image img = gradient(96, 64, 3);
  write_image((d / "whole.jpg").string(), img, WriteOptions{});
  const std::string whole = file_bytes(d / "whole.jpg");
  const std::size_t sos = whole.find(std::string("\xff\xda", 2));
  ASSERT_NE(sos, std::string::npos);
  std::ofstream(d / "cut.jpg", std::ios::binary) << whole.substr(0, whole.size() * 2 / 3);
  std::string ended = whole;
  ended.replace((sos + whole.size()) / 2, 2, std::string("\xff\xd9", 2));
  std::ofstream(d / "ended.jpg", std::ios::binary) << ended;
  std::string garbage = whole.substr(0, 3) + std::string(40, '\xc3');
  std::ofstream(d / "garbage.jpg", std::ios::binary) << garbage;
  for (const char* n : {"cut.jpg", "ended.jpg", "garbage.jpg"}) {
    const std::string p = (d / n).string();
    const std::string e = error_of([&] { (void)read_color(p, Transfer::linear); });
    EXPECT_NE(e.find("cannot read '" + p + "': "), std::string::npos) << n << ": " << e;
    EXPECT_EQ(printable_text(e), e) << n;
  }
  fs::remove_all(d);
}
