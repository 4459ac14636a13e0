// brume compare (brume/compare.hpp): Morales eq. 3.14 histogram correlations
// against a Pearson correlation computed here from histograms known by
// construction, PSNR against its arithmetic, the behaviour the thesis relies
// on (a hue shift moves the hue-saturation correlation and not the brightness
// one; a brightness change the reverse), the mask, and the error paths.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <vector>

#include "brume/compare.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"

using namespace brume;
namespace fs = std::filesystem;

namespace {

// Linear RGB whose 8-bit sRGB encoding is exactly `code` (the decoding
// read_color applies to an 8-bit file).
float lin(int code) { return srgb_to_linear(static_cast<float>(code) / 255.0f); }

Image from_codes(const std::vector<std::array<int, 3>>& px, int w) {
  const int h = static_cast<int>(px.size()) / w;
  Image im(w, h, 3);
  for (std::size_t i = 0; i < px.size(); ++i)
    for (int c = 0; c < 3; ++c) im.data[i * 3 + c] = lin(px[i][c]);
  return im;
}

// Eq. 3.14 written out over the bins.
double pearson(const std::vector<double>& h1, const std::vector<double>& h2) {
  double m1 = 0, m2 = 0;
  for (std::size_t k = 0; k < h1.size(); ++k) m1 += h1[k], m2 += h2[k];
  m1 /= h1.size(), m2 /= h2.size();
  double s12 = 0, s11 = 0, s22 = 0;
  for (std::size_t k = 0; k < h1.size(); ++k) {
    s12 += (h1[k] - m1) * (h2[k] - m2);
    s11 += (h1[k] - m1) * (h1[k] - m1);
    s22 += (h2[k] - m2) * (h2[k] - m2);
  }
  return s12 / std::sqrt(s11 * s22);
}

// A reddish-orange texture (hue 0-40 deg, varied saturation and value),
// deterministic; max code <= 120 so that doubling the codes stays in range.
std::vector<std::array<int, 3>> orange_codes(int n) {
  std::vector<std::array<int, 3>> px;
  unsigned s = 12345;
  auto next = [&s](int m) {
    s = s * 1103515245u + 12345u;
    return static_cast<int>((s >> 16) % static_cast<unsigned>(m));
  };
  for (int i = 0; i < n; ++i) {
    const int r = 60 + next(61);       // 60..120
    const int b = next(r / 2);         // well below r
    const int g = b + next(r - b) * 2 / 3;  // between b and r: hue in (0, 40] deg
    px.push_back({r, g, b});
  }
  return px;
}

}  // namespace

TEST(Compare, IdenticalImagesCorrelateOneWithInfinitePsnr) {
  const Image a = from_codes(orange_codes(64 * 48), 64);
  const CompareResult r = compare_images(a, a);
  // compareHist subtracts sums of ~1e6: the only error is double rounding.
  EXPECT_NEAR(r.hs_correlation, 1.0, 1e-12);
  EXPECT_NEAR(r.v_correlation, 1.0, 1e-12);
  EXPECT_TRUE(std::isinf(r.psnr_linear_db) && r.psnr_linear_db > 0);
  EXPECT_TRUE(std::isinf(r.psnr_srgb8_db) && r.psnr_srgb8_db > 0);
  EXPECT_EQ(r.pixels, 64u * 48u);
  const nlohmann::json j = compare_result_json(r);
  EXPECT_EQ(j["psnr_linear_db"], "inf");  // JSON has no infinity: the string "inf", documented
  EXPECT_EQ(j["psnr_srgb8_db"], "inf");
  EXPECT_EQ(j["method"]["hue_saturation_bins"], nlohmann::json({50, 60}));
  EXPECT_EQ(j["method"]["brightness_bins"], 256);
}

TEST(Compare, PsnrIsItsArithmetic) {
  // 4x4 grey 0.5 (linear); B differs in one red sample by 0.125 (exact in
  // float), so MSE = 0.125^2 / 48 over 16 pixels x 3 channels.
  Image a(4, 4, 3, 0.5f), b = a;
  b.at(1, 2, 0) = 0.625f;
  const CompareResult r = compare_images(a, b);
  EXPECT_DOUBLE_EQ(r.mse_linear, 0.015625 / 48.0);
  EXPECT_NEAR(r.psnr_linear_db, 10.0 * std::log10(48.0 / 0.015625), 1e-9);
  // 8-bit sRGB codes from the IEC 61966-2-1 curve in double: 0.5 -> 187.52 -> 188,
  // 0.625 -> 207.15 -> 207 (both far from a rounding edge).
  auto code = [](double v) { return std::lround(255.0 * (1.055 * std::pow(v, 1.0 / 2.4) - 0.055)); };
  const double d8 = static_cast<double>(code(0.625) - code(0.5));
  EXPECT_EQ(d8, 19.0);
  EXPECT_DOUBLE_EQ(r.mse_srgb8, d8 * d8 / 48.0);
  EXPECT_NEAR(r.psnr_srgb8_db, 10.0 * std::log10(255.0 * 255.0 * 48.0 / (d8 * d8)), 1e-9);
}

TEST(Compare, CorrelationMatchesAnIndependentPearsonOnKnownHistograms) {
  // Pure colours have HSV known by definition (OpenCV 8-bit: H = degrees/2):
  // red H 0, yellow H 30, green H 60, blue H 120, all S = V = 255; grey g:
  // H = S = 0, V = g; (255,128,128): H 0, S = 255*127/255 = 127, V 255.
  // Bins: H -> floor(H*50/180), S -> floor(S*60/256), V -> V.
  struct Px {
    std::array<int, 3> rgb;
    int hbin, sbin, v;
  };
  const Px red{{255, 0, 0}, 0, 59, 255}, yellow{{255, 255, 0}, 8, 59, 255}, green{{0, 255, 0}, 16, 59, 255},
      blue{{0, 0, 255}, 33, 59, 255}, g64{{64, 64, 64}, 0, 0, 64}, g128{{128, 128, 128}, 0, 0, 128},
      g200{{200, 200, 200}, 0, 0, 200}, white{{255, 255, 255}, 0, 0, 255}, pink{{255, 128, 128}, 0, 29, 255};
  const std::vector<Px> A = {red, red, green, blue, yellow, g64, g128, pink};
  const std::vector<Px> B = {red, green, green, green, blue, g64, g200, white};
  auto image = [](const std::vector<Px>& p) {
    std::vector<std::array<int, 3>> c;
    for (const Px& x : p) c.push_back(x.rgb);
    return from_codes(c, 4);
  };
  auto hs = [](const std::vector<Px>& p) {
    std::vector<double> h(50 * 60, 0.0);
    for (const Px& x : p) h[x.hbin * 60 + x.sbin] += 1;
    return h;
  };
  auto v = [](const std::vector<Px>& p) {
    std::vector<double> h(256, 0.0);
    for (const Px& x : p) h[x.v] += 1;
    return h;
  };
  const CompareResult r = compare_images(image(A), image(B));
  // Same bins, same formula: only double rounding differs (sums of <= 8 counts).
  EXPECT_NEAR(r.hs_correlation, pearson(hs(A), hs(B)), 1e-12);
  EXPECT_NEAR(r.v_correlation, pearson(v(A), v(B)), 1e-12);
  // The case is not degenerate: neither correlation is 1 or 0.
  EXPECT_LT(r.hs_correlation, 0.9);
  EXPECT_GT(r.hs_correlation, 0.1);
  EXPECT_LT(r.v_correlation, 0.99);
}

TEST(Compare, HueShiftMovesHueSaturationNotBrightness) {
  // Rotating the channels (R,G,B) -> (G,B,R) turns hue by 120 deg and keeps
  // V = max and S = (max - min)/max exactly: the V histograms are identical.
  const auto codes = orange_codes(64 * 48);
  std::vector<std::array<int, 3>> rotated;
  for (const auto& c : codes) rotated.push_back({c[1], c[2], c[0]});
  const CompareResult r = compare_images(from_codes(codes, 64), from_codes(rotated, 64));
  EXPECT_NEAR(r.v_correlation, 1.0, 1e-12);
  // Orange (0-40 deg, OpenCV H <= 20) moves to 240-280 deg (H 120-140): no shared bins,
  // so the correlation is at most ~0 (measured -0.058: both means > 0).
  EXPECT_LT(r.hs_correlation, 0.05);
}

TEST(Compare, BrightnessChangeMovesBrightnessNotHueSaturation) {
  // Doubling the 8-bit codes keeps hue and saturation (ratios of differences)
  // and moves V from [60, 120] to [120, 240].
  const auto codes = orange_codes(64 * 48);
  std::vector<std::array<int, 3>> bright;
  for (const auto& c : codes) bright.push_back({2 * c[0], 2 * c[1], 2 * c[2]});
  const CompareResult r = compare_images(from_codes(codes, 64), from_codes(bright, 64));
  // Exact arithmetic gives 1; OpenCV's 12-bit fixed-point division can move
  // a few pixels' S or H across a bin edge (measured 0.99975 here).
  EXPECT_GT(r.hs_correlation, 0.95);
  // The V supports share only the value 120 (measured -0.29).
  EXPECT_LT(r.v_correlation, 0.05);
}

TEST(Compare, MaskExcludesPixels) {
  const Image a = from_codes(orange_codes(16 * 8), 16);
  Image b = a, mask(16, 8, 1, 1.0f);
  // B differs only in the left half, which the mask excludes.
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      b.at(x, y, 0) = 1.0f, b.at(x, y, 1) = 0.0f;
      mask.at(x, y) = 0.0f;
    }
  const CompareResult m = compare_images(a, b, &mask);
  EXPECT_EQ(m.pixels, 64u);
  EXPECT_TRUE(std::isinf(m.psnr_linear_db));
  EXPECT_NEAR(m.hs_correlation, 1.0, 1e-12);
  EXPECT_NEAR(m.v_correlation, 1.0, 1e-12);
  // Without the mask the difference is seen.
  const CompareResult all = compare_images(a, b);
  EXPECT_EQ(all.pixels, 128u);
  EXPECT_TRUE(std::isfinite(all.psnr_linear_db));
  EXPECT_LT(all.hs_correlation, 0.9);
  // An empty mask and a mask of another size are refused.
  Image none(16, 8, 1, 0.0f), small(8, 8, 1, 1.0f);
  EXPECT_THROW(compare_images(a, b, &none), Error);
  EXPECT_THROW(compare_images(a, b, &small), Error);
}

TEST(Compare, ValuesOutsideTheEncodableRangeAreCounted) {
  Image a(4, 2, 3, 0.5f), b = a;
  b.at(0, 0, 0) = 2.0f;   // HDR highlight
  b.at(1, 0, 2) = -0.1f;  // out-of-gamut negative
  const CompareResult r = compare_images(a, b);
  EXPECT_EQ(r.clipped_a, 0u);
  EXPECT_EQ(r.clipped_b, 2u);
  // Linear PSNR sees the full error: (1.5^2 + 0.6^2) / 24 (0.6 = 0.5 + 0.1, float-rounded).
  const double e1 = 1.5, e2 = 0.5 - static_cast<double>(-0.1f);
  EXPECT_NEAR(r.mse_linear, (e1 * e1 + e2 * e2) / 24.0, 1e-12);
}

TEST(Compare, FileErrorsNameTheFiles) {
  const fs::path dir = fs::temp_directory_path() / ("brume_test_compare_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string a = (dir / "a.png").string(), b = (dir / "b.png").string(), m = (dir / "m.png").string(),
                    js = (dir / "r.json").string();
  write_image(a, Image(8, 6, 3, 0.5f), WriteOptions{});
  write_image(b, Image(6, 8, 3, 0.5f), WriteOptions{});
  WriteOptions grey;
  grey.is_color = false;
  write_image(m, Image(4, 4, 1, 1.0f), grey);
  auto expect_error = [&](const CompareJob& job, std::vector<std::string> must) {
    try {
      run_compare_job(job);
      ADD_FAILURE() << "accepted";
    } catch (const Error& e) {
      for (const auto& s : must) EXPECT_NE(std::string(e.what()).find(s), std::string::npos) << s << ": " << e.what();
    }
    EXPECT_FALSE(fs::exists(js));
  };
  expect_error({a, b, "", js, "", ""}, {a, b, "8x6", "6x8"});
  expect_error({a, (dir / "missing.png").string(), "", js, "", ""}, {"missing.png"});
  expect_error({a, a, m, js, "", ""}, {m, "4x4", "8x6"});
  expect_error({a, "", "", js, "", ""}, {"--b"});
  expect_error({a, a, "", (dir / "no" / "r.json").string(), "", ""}, {"--json", "does not exist"});
  // The good case writes the JSON.
  run_compare_job({a, a, "", js, "", ""});
  EXPECT_TRUE(fs::exists(js));
  fs::remove_all(dir);
}
