// Radiance HDR (src/io/formats/hdr.cpp).
#include "io/io_test_util.hpp"

using namespace brume::test_io;

TEST(IO, HdrSubsetIsReadAsOpenImageIOReadsIt) {
  // Radiance files of the common form are read by brume itself (no
  // OpenImageIO module load): the values bit for bit and FileInfo as
  // OpenImageIO gives them -- the Poly Haven skies in ../shared/data, files
  // OpenImageIO's writer made (run-length coded, and flat below 8 px
  // wide), a flat file by hand; the forms brume leaves to OpenImageIO are
  // declined (the direct-read counter does not move).
  fs::path d = tmpdir();
  auto oiio_write = [](const std::string& p, const Image& img) {
    OIIO::ImageSpec spec(img.width, img.height, 3, OIIO::TypeDesc::FLOAT);
    auto out = OIIO::ImageOutput::create(p);
    ASSERT_TRUE(out && out->open(p, spec)) << p;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data())) << p;
    ASSERT_TRUE(out->close()) << p;
  };
  auto hdr_values = [](int w, int h) {
    Image img(w, h, 3);
    for (std::size_t i = 0; i < img.data.size(); ++i)
      img.data[i] = i % 13 == 0 ? 0.0f : std::ldexp(static_cast<float>(i % 97) + 0.3f, static_cast<int>(i % 41) - 20);
    for (std::size_t i = 0; i + 2 < img.data.size(); i += 15) img.data[i] = img.data[i + 1] = img.data[i + 2] = 0.75f;  // runs
    return img;
  };
  std::vector<std::string> subset;
  for (const char* rel : {"sky_hdr_polyhaven/sky.hdr", "sky_hdr_polyhaven/park.hdr", "sky_hdr_polyhaven/sunrise.hdr"})
    if (have_data(rel)) subset.push_back(data_path(rel));
  for (const auto& [name, w, h] : {std::tuple{"rle.hdr", 37, 11}, std::tuple{"narrow.hdr", 5, 9}, std::tuple{"wide.hdr", 300, 4}}) {
    oiio_write((d / name).string(), hdr_values(w, h));
    subset.push_back((d / name).string());
  }
  // Flat at 8 px or more: the first pixel is not the "2 2" of a coded line.
  const std::string header = "#?RADIANCE\n# by hand\nGAMMA=1\nFORMAT=32-bit_rle_rgbe\n\n";
  {
    std::ofstream f(d / "flat.hdr", std::ios::binary);
    f << header << "-Y 3 +X 9\n";
    for (int i = 0; i < 27; ++i) {
      const unsigned char px[4] = {static_cast<unsigned char>(i * 9 % 256), static_cast<unsigned char>(i), 200,
                                   static_cast<unsigned char>(i % 5 ? 120 + i : 0)};
      f.write(reinterpret_cast<const char*>(px), 4);
    }
  }
  subset.push_back((d / "flat.hdr").string());
  for (const std::string& p : subset) {
    OIIO::ImageSpec spec;
    const std::vector<float> want = oiio_pixels(p, &spec);
    const std::uint64_t before = detail::hdr_direct_reads();
    FileInfo fi;
    const Image got = read_color(p, Transfer::linear, &fi);
    EXPECT_EQ(detail::hdr_direct_reads(), before + 1) << p << " was not read by brume itself";
    ASSERT_EQ(got.data.size(), want.size()) << p;
    EXPECT_EQ(std::memcmp(got.data.data(), want.data(), want.size() * sizeof(float)), 0) << p;
    EXPECT_EQ(fi.format, "hdr") << p;
    EXPECT_FALSE(fi.integer) << p;
    EXPECT_EQ(fi.bits, static_cast<int>(spec.format.size() * 8)) << p;
    EXPECT_EQ(fi.channel_names, std::vector<std::string>(spec.channelnames.begin(), spec.channelnames.end())) << p;
    EXPECT_EQ(fi.description, spec.get_string_attribute("ImageDescription")) << p;
    const ImageHeader hd = read_header(p);
    EXPECT_EQ(hd.width, spec.width);
    EXPECT_EQ(hd.height, spec.height);
  }
  // Declined: another orientation, XYZE, bytes after the image, a short
  // file (each left to OpenImageIO, whose reading or message stands).
  const std::string rle = (d / "rle.hdr").string();
  const std::string bytes = file_bytes(rle);
  const std::size_t res = bytes.find("-Y 11 +X 37\n");
  ASSERT_NE(res, std::string::npos);
  std::string flipped = bytes, xyze = bytes;
  flipped.replace(res, 12, "+Y 11 +X 37\n");
  const std::size_t fmt = xyze.find("FORMAT=32-bit_rle_rgbe");
  ASSERT_NE(fmt, std::string::npos);
  xyze.replace(fmt, 22, "FORMAT=32-bit_rle_xyze");
  const std::vector<std::pair<std::string, std::string>> other = {
      {"flipped.hdr", flipped}, {"xyze.hdr", xyze}, {"trailing.hdr", bytes + "tail"},
      {"short.hdr", bytes.substr(0, bytes.size() - 40)}};
  for (const auto& [name, content] : other) {
    const std::string p = (d / name).string();
    std::ofstream(p, std::ios::binary) << content;
    Image got;
    int w = 0, h = 0;
    EXPECT_FALSE(detail::read_hdr_subset(p, &got, w, h, [](int, int, int) {})) << name << " was taken";
    EXPECT_TRUE(got.data.empty()) << name;
  }
  fs::remove_all(d);
}

TEST(IO, HdrSubsetWritesTheFileOpenImageIOWrites) {
  // RGB images with values >= 0 or NaN are written as Radiance files by
  // brume itself: byte for byte OpenImageIO's file for the same values --
  // run-length coded widths (runs, literal stretches over 128 bytes, short
  // runs before long ones), flat narrow ones, zeros, values below 1e-32,
  // large and tiny exponents, NaN in each component. A negative value
  // leaves the file to OpenImageIO (the counter does not move).
  fs::path d = tmpdir();
  int compared = 0;
  for (const auto& [w, h] : {std::pair{40, 3}, std::pair{300, 7}, std::pair{5, 4}, std::pair{8, 2}, std::pair{1, 1}}) {
    Image img(w, h, 3);
    for (std::size_t i = 0; i < img.data.size(); ++i) {
      const std::size_t px = i / 3;
      img.data[i] = (px > 20 && px < 220) ? std::ldexp(static_cast<float>((i * 53) % 241) + 0.5f, static_cast<int>(i % 7))  // long literal stretches
                    : px % 11 < 5   ? 0.5f                                                        // runs
                    : px % 11 < 7 ? 0.0f                                                        // zeros
                    : px % 11 == 7 ? 1e-33f                                                     // below 1e-32
                                   : std::ldexp(static_cast<float>((i * 37) % 251) + 0.25f, static_cast<int>(i % 61) - 30);
    }
    for (std::size_t i = 2; i < img.data.size(); i += 17) img.data[i] = NAN;  // NaN in R, G and B of various pixels
    const fs::path mine = d / ("mine_" + std::to_string(w) + ".hdr"), theirs = d / ("oiio_" + std::to_string(w) + ".hdr");
    const std::uint64_t before = detail::hdr_direct_writes();
    write_image(mine.string(), img, WriteOptions{});
    EXPECT_EQ(detail::hdr_direct_writes(), before + 1) << w;
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    spec.attribute("oiio:ColorSpace", "linear");
    auto out = OIIO::ImageOutput::create(theirs.string());
    ASSERT_TRUE(out && out->open(theirs.string(), spec)) << w;
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data.data())) << w;
    ASSERT_TRUE(out->close()) << w;
    const std::string a = file_bytes(mine), b = file_bytes(theirs);
    EXPECT_TRUE(a == b) << w << "x" << h << ": " << a.size() << " bytes against OpenImageIO's " << b.size();
    ++compared;
  }
  EXPECT_EQ(compared, 5);
  Image neg(9, 2, 3, 0.25f);
  neg.data[4] = -1.0f;
  const std::uint64_t before = detail::hdr_direct_writes();
  write_image((d / "neg.hdr").string(), neg, WriteOptions{});
  EXPECT_EQ(detail::hdr_direct_writes(), before);
  fs::remove_all(d);
}
