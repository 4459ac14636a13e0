// Radiance HDR (src/io/formats/hdr.cpp).
#include "io/formats/format.hpp"
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
    FileInfo fi;
    const Image got = read_color(p, Transfer::linear, &fi);
    EXPECT_STREQ(io::last_reader(), "hdr") << p << " was not read by brume itself";
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
    try {
      read_color(p, Transfer::linear);
    } catch (const Error&) {  // OpenImageIO's message for what it cannot read either
    }
    EXPECT_STREQ(io::last_reader(), "oiio") << name << " was taken";
  }
  fs::remove_all(d);
}

TEST(IO, HdrRoundTripsWithinRgbePrecision) {
  // RGB images with values >= 0 or NaN are written as Radiance files by
  // brume itself: run-length coded widths (runs, literal stretches over 128
  // bytes, short runs before long ones), flat narrow ones, zeros, values
  // below 1e-32, large and tiny exponents, NaN in each component. RGBE keeps
  // 8 bits of mantissa under the pixel's largest component m, so each value
  // reads back within m / 128 (its exponent e has m in [2^(e-1), 2^e), the
  // mantissa steps 2^(e-8)); values under 1e-32 and a NaN pixel's are 0.
  // OpenImageIO reads the same floats from the file as brume. A negative
  // value, which RGBE cannot hold, is an error naming the pixel (never
  // clamped), and nothing is written.
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
    const std::string mine = (d / ("mine_" + std::to_string(w) + ".hdr")).string();
    write_image(mine, img, WriteOptions{});
    EXPECT_STREQ(io::last_writer(), "hdr") << w;
    const Image back = read_color(mine, Transfer::linear);
    const std::vector<float> theirs = oiio_pixels(mine);
    ASSERT_EQ(theirs.size(), back.data.size()) << w;
    EXPECT_EQ(std::memcmp(theirs.data(), back.data.data(), theirs.size() * 4), 0) << w << ": OpenImageIO reads other values";
    std::size_t bad = 0;
    for (std::size_t px = 0; px < back.pixels(); ++px) {
      const float* v = &img.data[px * 3];
      // m: the largest component that is a number (Walter's comparisons
      // skip NaN); a NaN red makes the whole pixel 0, another NaN its own
      // component 0.
      float m = 0.0f;
      for (int k = 0; k < 3; ++k)
        if (!std::isnan(v[k])) m = std::max(m, v[k]);
      for (int k = 0; k < 3; ++k) {
        const float got = back.data[px * 3 + k];
        if (std::isnan(v[k]) || std::isnan(v[0]) || m < 1e-32f)
          bad += got != 0.0f;
        else
          bad += !(std::fabs(got - v[k]) <= m / 128.0f);
      }
    }
    EXPECT_EQ(bad, 0u) << w << "x" << h;
    ++compared;
  }
  EXPECT_EQ(compared, 5);
  Image neg(9, 2, 3, 0.25f);
  neg.data[4] = -1.0f;
  try {
    write_image((d / "neg.hdr").string(), neg, WriteOptions{});
    ADD_FAILURE() << "a negative value was written to Radiance HDR";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("neg.hdr"), std::string::npos) << m;
    EXPECT_NE(m.find("pixel (1, 0) is -1"), std::string::npos) << m;
  }
  EXPECT_FALSE(fs::exists(d / "neg.hdr"));
  fs::remove_all(d);
}
