// Declared transfers of input images (--image-transfer gamma:G and
// table:FILE, brume/io.hpp's TransferFunction): what each maps a stored code
// to, against the codes written by hand with libpng and the curve evaluated
// here in double; alpha untouched; the text round trip records rely on; and
// the refusals.
#include <cmath>

#include "io/io_test_util.hpp"

using namespace brume::test_io;

namespace {

// An 8-bit RGB PNG of every code: pixel i holds code i in R, 255 - i in G
// and (7 i) mod 256 in B (16 x 16 pixels); with `alpha`, RGBA with alpha 200.
std::string all_codes_png(const fs::path& d, bool alpha = false) {
  std::vector<unsigned char> b;
  for (int i = 0; i < 256; ++i) {
    for (int v : {i, 255 - i, (7 * i) % 256}) b.push_back(static_cast<unsigned char>(v));
    if (alpha) b.push_back(200);
  }
  const std::string p = (d / (alpha ? "codes_rgba.png" : "codes.png")).string();
  write_png_by_hand(p, 16, 16, 8, alpha ? PNG_COLOR_TYPE_RGB_ALPHA : PNG_COLOR_TYPE_RGB, false, b);
  return p;
}

int code_of(int i, int c) { return c == 0 ? i : c == 1 ? 255 - i : (7 * i) % 256; }

std::string write_text(const fs::path& p, const std::string& text) {
  std::ofstream(p) << text;
  return p.string();
}

ColorRead with(const TransferFunction& t) {
  ColorRead how;
  how.transfer = t;
  return how;
}

}  // namespace

TEST(Transfer, GammaMapsEachCodeToItsPower) {
  // Expected: (code / 255)^G in double, rounded to float once; brume maps
  // each code through a table of floats made the same way: equal bits.
  const fs::path d = tmpdir();
  const std::string png = all_codes_png(d);
  for (double g : {2.2, 1.8, 0.5}) {
    const TransferFunction t = parse_transfer_function("gamma:" + nlohmann::json(g).dump(), "--image-transfer");
    ASSERT_EQ(t.kind, Transfer::gamma);
    ASSERT_EQ(t.gamma, g);
    FileInfo info;
    const Image img = read_color(png, with(t), &info);
    ASSERT_EQ(img.width, 16);
    for (int i = 0; i < 256; ++i)
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(img.data[static_cast<std::size_t>(i) * 3 + c],
                  static_cast<float>(std::pow(code_of(i, c) / 255.0, g)))
            << "gamma " << g << " pixel " << i << " channel " << c;
    EXPECT_EQ(to_string(info.transfer), "gamma:" + nlohmann::json(g).dump());
  }
  // With alpha (read associated, as OpenImageIO reads a PNG's straight alpha):
  // the curve meets the associated colour, as the sRGB decode does, and alpha
  // -- a coverage count -- is never put through it.
  const std::string rgba = all_codes_png(d, true);
  Image lin_alpha, alpha;
  const Image lin = read_color(rgba, with(Transfer::linear), nullptr, &lin_alpha);
  const Image g22 = read_color(rgba, with(parse_transfer_function("gamma:2.2", "--f")), nullptr, &alpha);
  for (std::size_t k = 0; k < lin.data.size(); ++k)
    ASSERT_EQ(g22.data[k], static_cast<float>(std::pow(static_cast<double>(lin.data[k]), 2.2))) << k;
  ASSERT_EQ(alpha.channels, 1);
  EXPECT_EQ(alpha.data, lin_alpha.data);
  for (float a : alpha.data) ASSERT_NEAR(a, 200.0 / 255.0, 1e-7);  // the count over 255 in float
  // gamma:1 is the linear read, bit for bit (and says so).
  EXPECT_EQ(to_string(parse_transfer_function("gamma:1", "--image-transfer")), "linear");
  const Image lin8 = read_color(png, Transfer::linear);
  const Image g1 = read_color(png, with(parse_transfer_function("gamma:1", "--image-transfer")));
  EXPECT_EQ(lin8.data, g1.data);
}

TEST(Transfer, TableOfEveryCodeGivesItsEntriesAndFewerEntriesInterpolate) {
  const fs::path d = tmpdir();
  const std::string png = all_codes_png(d);
  // 256 entries (a measured response's shape: code^2.6 with a toe), one per
  // line with comments and commas: code i reads entry i exactly.
  std::string text = "# camera response, code 0..255\n";
  std::vector<double> entry(256);
  for (int i = 0; i < 256; ++i) {
    entry[i] = 0.002 * i / 255.0 + 0.998 * std::pow(i / 255.0, 2.6);
    text += nlohmann::json(entry[i]).dump() + (i % 8 == 7 ? "\n" : ", ");
  }
  const TransferFunction t = parse_transfer_function("table:" + write_text(d / "t256.txt", text), "--image-transfer");
  ASSERT_EQ(t.table.size(), 256u);
  EXPECT_EQ(t.table_sha256, sha256_file((d / "t256.txt").string()));
  const Image img = read_color(png, with(t));
  for (int i = 0; i < 256; ++i)
    for (int c = 0; c < 3; ++c)
      ASSERT_EQ(img.data[static_cast<std::size_t>(i) * 3 + c], static_cast<float>(entry[code_of(i, c)]))
          << "pixel " << i << " channel " << c;
  // Three entries: linear between codes 0, 127.5 and 255 (the interpolation
  // computed here in double; float rounding once: equal bits).
  const TransferFunction t3 = parse_transfer_function("table:" + write_text(d / "t3.txt", "0 0.2 1\n"), "--x");
  const Image img3 = read_color(png, with(t3));
  for (int i = 0; i < 256; ++i)
    for (int c = 0; c < 3; ++c) {
      const double x = code_of(i, c) / 255.0 * 2.0;
      const double want = x <= 1.0 ? 0.2 * x : 0.2 + 0.8 * (x - 1.0);
      ASSERT_NEAR(img3.data[static_cast<std::size_t>(i) * 3 + c], want, 1e-7) << i << " " << c;  // float of double
    }
}

TEST(Transfer, FloatFilesTakeGammaWithTheSignAndRefuseATableOutsideItsCodes) {
  const fs::path d = tmpdir();
  Image f(3, 1, 3);
  const float vals[9] = {0.25f, 0.5f, 1.0f, -0.25f, 0.0f, 2.0f, 0.75f, 0.125f, 0.0625f};
  std::copy(vals, vals + 9, f.data.begin());
  const std::string pfm = (d / "f.pfm").string();
  write_image(pfm, f, WriteOptions{});
  const Image g = read_color(pfm, with(parse_transfer_function("gamma:2", "--image-transfer")));
  for (int i = 0; i < 9; ++i)
    EXPECT_EQ(g.data[i], static_cast<float>(vals[i] < 0 ? -std::pow(-vals[i], 2.0) : std::pow(vals[i], 2.0))) << i;
  const TransferFunction t = parse_transfer_function("table:" + write_text(d / "t.txt", "0 1"), "--image-transfer");
  try {
    read_color(pfm, with(t));
    FAIL() << "a float value outside [0, 1] went through a table";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("f.pfm"), std::string::npos) << m;
    EXPECT_NE(m.find("outside [0, 1]"), std::string::npos) << m;
    EXPECT_NE(m.find("x 1, y 0, channel 0"), std::string::npos) << m;  // -0.25, the first outside
  }
}

TEST(Transfer, TextRoundTripsAndBadValuesAreRefusedWithTheFix) {
  const fs::path d = tmpdir();
  for (const char* w : {"auto", "srgb", "linear"})
    EXPECT_EQ(to_string(parse_transfer_function(w, "--image-transfer")), w);
  // The shortest text of the double: a record's job reads back the same gamma.
  for (double g : {2.2, 1.0 / 2.2, 2.4, 10.0, 1.0000000000000002}) {
    const std::string s = to_string(parse_transfer_function("gamma:" + nlohmann::json(g).dump(), "--f"));
    EXPECT_EQ(parse_transfer_function(s, "--f").gamma, g) << s;
  }
  const std::string dec = write_text(d / "dec.txt", "0 0.5 0.4 1");
  const std::string one = write_text(d / "one.txt", "# only\n0.5\n");
  const std::string junk = write_text(d / "junk.txt", "0 0.5\n0.7 abc 1\n");
  const struct {
    std::string value, says;
  } bad[] = {
      {"gamma", "is not allowed"},
      {"gamma:", "(0, 10]"},
      {"gamma:0", "(0, 10]"},
      {"gamma:-2", "(0, 10]"},
      {"gamma:11", "(0, 10]"},
      {"gamma:nan", "(0, 10]"},
      {"gamma:2.2x", "(0, 10]"},
      {"table:", "names no file"},
      {"table:" + (d / "none.txt").string(), "none.txt"},
      {"table:" + dec, "decreases at entry 2 (0.5 then 0.4)"},
      {"table:" + one, "holds 1 value; a transfer table needs at least 2"},
      {"table:" + junk, "line 2 of"},
      {"sRGB", "is not allowed"},
  };
  for (const auto& b : bad) {
    try {
      parse_transfer_function(b.value, "--image-transfer");
      ADD_FAILURE() << b.value << " was accepted";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("--image-transfer"), std::string::npos) << m;
      EXPECT_NE(m.find(b.says), std::string::npos) << b.value << ": " << m;
    }
  }
}
