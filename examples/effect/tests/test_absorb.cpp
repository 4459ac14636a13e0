// `brume absorb`, the example effect (examples/effect/): its maths against a
// double-precision reference, its refusals, and the command from files to
// files with the record `brume run` repeats. Built only in the scratch tree of
// the ctest example_effect_builds_from_its_files.
#include <cmath>
#include <fstream>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "brume/absorb.hpp"
#include "brume/io.hpp"
#include "test_util.hpp"

namespace brume::test {
namespace {

// C exp(-kappa_a R) in float against the same in double. Tolerance, relative:
// the float path rounds kappa_a (0.5 ulp), the product kappa_a R (0.5 ulp,
// which moves the exponent by up to kappa_a R 2^-24 and so T by as much,
// relatively), glibc's expf (< 1 ulp) and the final product (0.5 ulp):
// 2^-24 (3 + kappa_a R) with a margin of 2. Absolute, where the results are
// subnormal (below 2^-126, spaced 2^-149): T's rounding to that spacing times a
// colour <= 4, and the product's own rounding, 2.5 2^-149; 3 2^-149.
TEST(Absorb, IsBeerLambertAgainstDouble) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> col(0.0f, 4.0f), rr(0.01f, 2000.0f);
  const int w = 37, h = 23;  // odd sizes: no row is special
  Image rgb(w, h, 3), range(w, h, 1);
  for (float& v : rgb.data) v = col(rng);
  for (float& v : range.data) v = rr(rng);
  for (double k : {0.0, 1e-4, 0.01, 0.5, 10.0}) {
    SCOPED_TRACE(k);
    AbsorbParams p;
    p.absorption_per_m = k;
    const AbsorbRun r = run_absorb(rgb, range, p);
    EXPECT_EQ(r.unknown_pixels, 0u);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const double kr = static_cast<double>(static_cast<float>(k)) * range.at(x, y);
        const double t = std::exp(-kr);
        const double tol = 2.0 * std::ldexp(3.0 + kr, -24), sub = 3.0 * std::ldexp(1.0, -149);
        ASSERT_NEAR(r.transmission.at(x, y), t, tol * t + sub) << x << "," << y;
        for (int c = 0; c < 3; ++c)
          ASSERT_NEAR(r.rgb.at(x, y, c), rgb.at(x, y, c) * t, tol * rgb.at(x, y, c) * t + sub);
      }
  }
}

// Unknown range keeps its colour, counted; the parameter's range and the
// shapes are refused with the flag's name.
TEST(Absorb, UnknownRangeAndRefusals) {
  Image rgb(4, 1, 3, 0.5f), range(4, 1, 1, 10.0f);
  range.at(0, 0) = std::numeric_limits<float>::quiet_NaN();
  range.at(1, 0) = std::numeric_limits<float>::infinity();
  range.at(2, 0) = 0.0f;
  const AbsorbRun r = run_absorb(rgb, range, AbsorbParams{});
  EXPECT_EQ(r.unknown_pixels, 3u);
  EXPECT_EQ(r.record["unknown_range_pixels"], 3);
  for (int x = 0; x < 3; ++x) EXPECT_EQ(r.rgb.at(x, 0, 1), 0.5f);
  EXPECT_LT(r.rgb.at(3, 0, 1), 0.5f);
  AbsorbParams bad;
  bad.absorption_per_m = -1.0;
  EXPECT_NE(error_of([&] { run_absorb(rgb, range, bad); }).find("absorption"), std::string::npos);
  const Image narrow(3, 1, 1, 1.0f);
  EXPECT_NE(error_of([&] { run_absorb(rgb, narrow, AbsorbParams{}); }).find("image's size"), std::string::npos);
}

class AbsorbCli : public ScratchDirTest {};

// From files to files: the output, the map, the record; `brume run` repeats
// the record to the last bit.
TEST_F(AbsorbCli, WritesTheRecordThatRunRepeats) {
  const Scene s = scene(24, 16, 4);
  write_image(p("a.pfm"), s.rgb, WriteOptions{}, "");
  write_image(p("a.range.pfm"), s.range, WriteOptions{}, "");
  CliRun r = run("absorb --image " + p("a.pfm") + " --range " + p("a.range.pfm") + " --absorption 0.002 --out " +
                 p("o.exr") + " --transmission " + p("t.exr") + " --record " + p("o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("brume absorb:"), std::string::npos) << r.output;
  const nlohmann::json rec = read_json(p("o.json"));
  EXPECT_EQ(rec["command"], "absorb");
  EXPECT_EQ(rec["prepare"]["applied"], true);  // the four sky rows were prepared
  const Image t = read_scalar(p("t.exr"));
  const Image o = read_color(p("o.exr"));
  // A pixel of known range: its transmission and colour as run_absorb gives them.
  EXPECT_FLOAT_EQ(t.at(5, 10), std::exp(-0.002f * s.range.at(5, 10)));
  EXPECT_FLOAT_EQ(o.at(5, 10, 0), t.at(5, 10) * s.rgb.at(5, 10, 0));
  CliRun again = run("run " + p("o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("o.exr"), p("again/o.exr"));
  // Bad input: the flag, the value and what is allowed; nothing written.
  CliRun bad = run("absorb --image " + p("a.pfm") + " --range " + p("a.range.pfm") + " --absorption 11 --out " +
                   p("b.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--absorption"), std::string::npos) << bad.output;
  EXPECT_FALSE(std::filesystem::exists(p("b.exr")));
}

}  // namespace
}  // namespace brume::test
