// The spectral core of aerial perspective (brume/aerial.hpp): the scattering
// coefficients against the thesis' numbers and their closed-form scalings,
// the weather classes of Table 3.1 as docs/aerial.md corrects it, the built-in CIE
// fit against the real CIE table, the sensitivity loaders against the shared
// camspec data and against files that must be rejected, and Gamma against an
// independent fine integral and against its own table.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "flat_sensitivity.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

const char* kCie = "spectral/CIE_xyz_1931_2deg.csv";
const char* kCanonCsv = "spectral/Canon_5DMarkII_camspec.csv";
const char* kDatabase = "spectral/camspec_database.txt";



// Independent of the library's quadrature: composite Simpson over 380-780 nm
// with a 0.05 nm step (8000 intervals; its h^4 error is ~1e-16 here).
double flat_gamma_fine(const Atmosphere& a, double s_m) {
  const int n = 8000;
  const double h = 400.0 / n;
  double sum = 0.0;
  for (int i = 0; i <= n; ++i) {
    const double l = 380.0 + i * h;
    const double beta = rayleigh_beta_per_m(l, a.altitude_m) + mie_beta_per_m(l, a.turbidity, a.altitude_m);
    const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    sum += w * std::exp(-beta * s_m);
  }
  return sum * h / 3.0 / 400.0;
}

class SpectralFiles : public ScratchDirTest {
 protected:
  std::string file(const std::string& name, const std::string& text) const {
    const std::string p = (dir / name).string();
    std::ofstream(p) << text;
    return p;
  }
};

}  // namespace

// ---- coefficients ------------------------------------------------------------------

TEST(AerialCoefficients, ThesisValuesAt550nm) {
  // The thesis' Table 3.1 values (3 significant figures, hence 1 %).
  EXPECT_NEAR(rayleigh_beta_per_m(550.0, 0.0) * 1e3, 0.0141, 0.01 * 0.0141);
  EXPECT_NEAR(mie_beta_per_m(550.0, 1.6, 0.0) * 1e3, 0.0639, 0.01 * 0.0639);
  EXPECT_EQ(mie_beta_per_m(550.0, 1.0, 0.0), 0.0);  // T = 1: no aerosol at all
}

TEST(AerialCoefficients, WavelengthLaws) {
  // Rayleigh ~ lambda^-4, Mie with Junge nu = 4 ~ lambda^-(nu-2) = lambda^-2;
  // the ratios are exact up to double rounding (1e-12 relative).
  const double r = rayleigh_beta_per_m(400.0, 0.0) / rayleigh_beta_per_m(760.0, 0.0);
  EXPECT_NEAR(r, std::pow(760.0 / 400.0, 4), 1e-12 * r);
  const double m = mie_beta_per_m(400.0, 5.0, 0.0) / mie_beta_per_m(760.0, 5.0, 0.0);
  EXPECT_NEAR(m, std::pow(760.0 / 400.0, 2), 1e-12 * m);
  // beta_M is linear in (T - 1).
  EXPECT_NEAR(mie_beta_per_m(550.0, 11.0, 0.0), 10.0 * mie_beta_per_m(550.0, 2.0, 0.0),
              1e-12 * mie_beta_per_m(550.0, 11.0, 0.0));
}

TEST(AerialCoefficients, AltitudeScalesByScaleHeights) {
  // Closed form: beta(h0) = beta(0) e^{-h0/H}, H = 7994 m (air), 1200 m (aerosol).
  for (double h : {-500.0, 431.0, 2000.0, 9000.0}) {
    const double r = rayleigh_beta_per_m(500.0, h) / rayleigh_beta_per_m(500.0, 0.0);
    const double m = mie_beta_per_m(500.0, 3.0, h) / mie_beta_per_m(500.0, 3.0, 0.0);
    EXPECT_NEAR(r, std::exp(-h / 7994.0), 1e-12 * r) << h;
    EXPECT_NEAR(m, std::exp(-h / 1200.0), 1e-12 * m) << h;
  }
}

TEST(AerialCoefficients, WeatherClassesOfTable31AsCorrected) {
  // docs/aerial.md: Table 3.1's "min/max" columns are beta_M bounds at 550 nm;
  // with beta_M ~ (T - 1) and T = 1.6 <-> 0.0639 /km they imply the turbidity
  // at which each class starts: T = 1 + 0.6 beta / 0.0639. Tolerance 0.5 % of
  // T - 1: the table's 4-digit bounds against our 0.06385 /km at T = 1.6.
  struct Class {
    const char* name;
    double beta_per_km, t;
  };
  const Class classes[] = {{"exceptionally clear", 0.0639, 1.6},
                           {"clear", 0.1819, 1.0 + 0.6 * 0.1819 / 0.0639},        // 2.708
                           {"light haze", 0.3769, 1.0 + 0.6 * 0.3769 / 0.0639},   // 4.539
                           {"haze", 0.9399, 1.0 + 0.6 * 0.9399 / 0.0639},         // 9.825
                           {"fog", 1.9459, 1.0 + 0.6 * 1.9459 / 0.0639}};         // 19.27
  const double per_t = mie_beta_per_m(550.0, 2.0, 0.0) * 1e3;  // /km per unit of T - 1
  for (const Class& c : classes) {
    const double t = 1.0 + c.beta_per_km / per_t;
    EXPECT_NEAR(t - 1.0, c.t - 1.0, 0.005 * (c.t - 1.0)) << c.name;
    EXPECT_LE(t, 20.0) << c.name << ": every class lies inside the accepted turbidities";
  }
  EXPECT_NEAR(1.0 + 0.1819 / per_t, 2.7, 0.02);  // "clear starts at T ~ 2.7"
  // A turbidity inside each class gives a beta_M inside its bounds.
  const double inside[] = {2.0, 3.5, 7.0, 15.0};
  for (int k = 0; k < 4; ++k) {
    const double b = mie_beta_per_m(550.0, inside[k], 0.0) * 1e3;
    EXPECT_GT(b, classes[k].beta_per_km) << classes[k].name;
    EXPECT_LT(b, classes[k + 1].beta_per_km) << classes[k].name;
  }
}

TEST(AerialCoefficients, BadInputsNameTheFlagValueAndRange) {
  std::string e = error_of([] { validate_atmosphere({0.99, 0.0}); });
  EXPECT_NE(e.find("--turbidity 0.99"), std::string::npos) << e;
  EXPECT_NE(e.find("[1, 20]"), std::string::npos) << e;
  e = error_of([] { validate_atmosphere({20.5, 0.0}); });
  EXPECT_NE(e.find("--turbidity 20.5"), std::string::npos) << e;
  e = error_of([] { validate_atmosphere({NAN, 0.0}); });
  EXPECT_NE(e.find("--turbidity nan"), std::string::npos) << e;
  e = error_of([] { validate_atmosphere({2.0, -501.0}); });
  EXPECT_NE(e.find("--altitude -501"), std::string::npos) << e;
  EXPECT_NE(e.find("[-500, 9000]"), std::string::npos) << e;
  e = error_of([] { validate_atmosphere({2.0, 9001.0}); });
  EXPECT_NE(e.find("--altitude 9001"), std::string::npos) << e;
  EXPECT_NO_THROW(validate_atmosphere({1.0, -500.0}));
  EXPECT_NO_THROW(validate_atmosphere({20.0, 9000.0}));
  e = error_of([] { rayleigh_beta_per_m(379.0, 0.0); });
  EXPECT_NE(e.find("379"), std::string::npos) << e;
  EXPECT_NE(e.find("[380, 780]"), std::string::npos) << e;
  e = error_of([] { mie_beta_per_m(781.0, 2.0, 0.0); });
  EXPECT_NE(e.find("781"), std::string::npos) << e;
  e = error_of([] { mie_beta_per_m(550.0, 21.0, 0.0); });
  EXPECT_NE(e.find("--turbidity 21"), std::string::npos) << e;
  e = error_of([] { attenuation_direct({2.0, 0.0}, flat_sensitivity(), -1.0); });
  EXPECT_NE(e.find("-1"), std::string::npos) << e;
  e = error_of([] { attenuation_table({2.0, 0.0}, flat_sensitivity(), 0.0); });
  EXPECT_NE(e.find("> 0"), std::string::npos) << e;
}

// ---- sensitivities ---------------------------------------------------------------------

TEST(AerialSensitivity, DefaultIsTheCieFitAgainstTheCieTable) {
  BRUME_REQUIRE_DATA(kCie);
  const SpectralSensitivity d = load_sensitivity("default");
  EXPECT_EQ(d.space, SensitivitySpace::xyz);
  EXPECT_TRUE(d.sha256.empty());
  ASSERT_EQ(d.q.size(), static_cast<std::size_t>(kSensitivitySamples));
  const SpectralSensitivity cie = load_sensitivity(data_path(kCie));  // header line "Wavelength,X,Y,Z"
  // Wyman, Sloan & Shirley's multi-lobe fit has no table of its own: its
  // error is that of a 10-parameter-per-curve fit, below the spread between
  // the observers behind the CIE standard (their claim). Measured here on
  // 380-780 nm: max 0.015 (x), 0.0076 (y), 0.024 (z, peak 1.78); we hold it
  // to 0.02, 0.01 and 0.03, and the integrals (which set Gamma's weights) to 0.3 %.
  const double tol[3] = {0.02, 0.01, 0.03};
  std::array<double, 3> area_fit{}, area_cie{};
  for (int i = 0; i < kSensitivitySamples; ++i)
    for (int c = 0; c < 3; ++c) {
      EXPECT_GE(d.q[i][c], 0.0) << "channel " << c << " at " << 380 + i << " nm";
      EXPECT_NEAR(d.q[i][c], cie.q[i][c], tol[c]) << "channel " << c << " at " << 380 + i << " nm";
      area_fit[c] += d.q[i][c];
      area_cie[c] += cie.q[i][c];
    }
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(area_fit[c] / area_cie[c], 1.0, 0.003) << c;
  // What matters downstream: Gamma with the fit against Gamma with the table.
  // Measured largest difference 3.6e-4 (T = 8, s = 10 km, z); held to 1e-3.
  for (double t : {1.0, 2.0, 8.0, 20.0})
    for (double s : {100.0, 1000.0, 10000.0, 100000.0}) {
      const auto a = attenuation_direct({t, 0.0}, d, s), b = attenuation_direct({t, 0.0}, cie, s);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 1e-3) << "T " << t << " s " << s << " c " << c;
    }
}

TEST(AerialSensitivity, CanonCsvOnTheGrid) {
  BRUME_REQUIRE_DATA(kCanonCsv);
  const std::string path = data_path(kCanonCsv);
  const SpectralSensitivity s = load_sensitivity(path);
  EXPECT_EQ(s.space, SensitivitySpace::camera_rgb);
  EXPECT_EQ(s.source, path);
  // SHA-256 as listed in ../shared/data/SOURCES.md.
  EXPECT_EQ(s.sha256, "a3c38660d9931cb920873661f0c270a61486c1c6b9d45f7b6d5c3a6cf9f40196");
  ASSERT_EQ(s.q.size(), static_cast<std::size_t>(kSensitivitySamples));
  // Rows 400,0.0019,0.0036,0.0127 and 410,0.0045,0.0123,0.0971; data 400-720 nm.
  EXPECT_EQ(s.q[20][0], 0.0019);
  EXPECT_EQ(s.q[20][2], 0.0127);
  EXPECT_NEAR(s.q[27][1], 0.0036 + 0.7 * (0.0123 - 0.0036), 1e-15);  // 407 nm: linear
  EXPECT_EQ(s.q[19][1], 0.0);   // 399 nm: outside the data
  EXPECT_EQ(s.q[341][1], 0.0);  // 721 nm
  EXPECT_GT(s.q[340][1], 0.0);  // 720 nm: the last row
}

TEST(AerialSensitivity, DatabaseEntryEqualsTheCsv) {
  BRUME_REQUIRE_DATA(kCanonCsv);
  BRUME_REQUIRE_DATA(kDatabase);
  const SpectralSensitivity csv = load_sensitivity(data_path(kCanonCsv));
  const std::string db = data_path(kDatabase);
  const SpectralSensitivity s = load_sensitivity(db + "#Canon 5DMarkII");
  EXPECT_EQ(s.source, db + "#Canon 5DMarkII");
  EXPECT_EQ(s.sha256, "067a7629d0836d0bc95f27b53f157ec0cf7e965beb66074426117c17fe1cda11");
  EXPECT_EQ(s.space, SensitivitySpace::camera_rgb);
  // The same decimal text in both files: equal to the last bit.
  for (int i = 0; i < kSensitivitySamples; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(s.q[i][c], csv.q[i][c]) << 380 + i << " nm, channel " << c;
  // Another camera parses too and differs.
  const SpectralSensitivity n = load_sensitivity(db + "#Nikon D700");
  EXPECT_NE(n.q[200][1], s.q[200][1]);
  const std::string e = error_of([&] { load_sensitivity(db + "#Canon 5D"); });
  EXPECT_NE(e.find("no camera named 'Canon 5D'"), std::string::npos) << e;
  EXPECT_NE(e.find("Canon 5DMarkII"), std::string::npos) << e;
  EXPECT_NE(e.find("SONY NEX-5N"), std::string::npos) << e;
}

TEST_F(SpectralFiles, CsvHeaderCommentsAndInterpolation) {
  const std::string p = file("q.csv", "# a comment\nwavelength_nm,r,g,b\n500,1,2,3\n# between rows\n510,3,2,1\r\n");
  const SpectralSensitivity s = load_sensitivity(p);
  EXPECT_EQ(s.q[120], (std::array<double, 3>{1, 2, 3}));  // 500 nm
  EXPECT_EQ(s.q[125], (std::array<double, 3>{2, 2, 2}));  // 505 nm
  EXPECT_EQ(s.q[130], (std::array<double, 3>{3, 2, 1}));  // 510 nm
  EXPECT_EQ(s.q[119], (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(s.q[131], (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(s.sha256, sha256_file(p));
}

TEST_F(SpectralFiles, BadCsvsNameFileLineAndValue) {
  struct Case {
    const char* name;
    const char* text;
    std::vector<std::string> expect;
  };
  const Case cases[] = {
      {"empty.csv", "# nothing\nwavelength_nm,r,g,b\n", {"no data rows"}},
      {"negwl.csv", "-400,1,1,1\n410,1,1,1\n", {"line 1", "-400", "negative"}},
      {"order.csv", "400,1,1,1\n410,1,1,1\n405,1,1,1\n", {"line 3", "405", "does not increase"}},
      {"dup.csv", "400,1,1,1\n400,1,1,1\n", {"line 2", "does not increase"}},
      {"text.csv", "400,1,1,1\n410,1,x1,1\n", {"line 2", "'x1'", "not a number"}},
      {"negq.csv", "400,1,1,1\n410,1,1,-0.5\n", {"line 2", "-0.5", "negative"}},
      {"fields.csv", "400,1,1\n", {"line 1", "3 fields"}},
      {"zero.csv", "400,1,0,1\n410,1,0,1\n", {"channel g", "zero"}},
      {"outside.csv", "800,1,1,1\n900,1,1,1\n", {"zero everywhere in 380-780"}},
  };
  for (const Case& c : cases) {
    const std::string p = file(c.name, c.text);
    const std::string e = error_of([&] { load_sensitivity(p); });
    EXPECT_NE(e.find(p), std::string::npos) << c.name << ": " << e;
    for (const auto& x : c.expect) EXPECT_NE(e.find(x), std::string::npos) << c.name << ": " << e;
  }
  const std::string e = error_of([&] { load_sensitivity((dir / "missing.csv").string()); });
  EXPECT_NE(e.find("missing.csv"), std::string::npos) << e;
  EXPECT_NE(e.find("default"), std::string::npos) << e;
}

// ---- attenuation -----------------------------------------------------------------------

TEST(AerialAttenuation, FlatSensitivityAgainstAFineIntegral) {
  // Gamma for q = 1 is the mean of e^{-beta s} over 380-780 nm; the library's
  // 1 nm Simpson sum against a 0.05 nm Simpson integral written here. 1e-9:
  // Simpson's h^4 error at h = 1 nm stays below it out to 100 km (the
  // trapezoid would be off by 2.6e-7 at 100 km, T = 1).
  const SpectralSensitivity flat = flat_sensitivity();
  for (double t : {1.0, 2.0, 8.0, 20.0})
    for (double h0 : {0.0, 2000.0})
      for (double s : {0.0, 100.0, 1000.0, 10000.0, 100000.0}) {
        const Atmosphere a{t, h0};
        const auto g = attenuation_direct(a, flat, s);
        const double ref = flat_gamma_fine(a, s);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(g[c], ref, 1e-9) << "T " << t << " h0 " << h0 << " s " << s;
      }
}

TEST(AerialAttenuation, SingleWavelengthIsBeerLambert) {
  // q = a delta at one grid node: Gamma = e^{-beta(lambda) s} exactly.
  SpectralSensitivity q = flat_sensitivity();
  for (auto& v : q.q) v = {0.0, 0.0, 0.0};
  q.q[70] = {1.0, 0.0, 0.0};   // 450 nm (odd node: Simpson weight 4)
  q.q[170] = {0.0, 1.0, 0.0};  // 550 nm
  q.q[400] = {0.0, 0.0, 1.0};  // 780 nm (end node: weight 1)
  const Atmosphere a{3.0, 500.0};
  const double lam[3] = {450.0, 550.0, 780.0};
  for (double s : {10.0, 5000.0, 80000.0}) {
    const auto g = attenuation_direct(a, q, s);
    for (int c = 0; c < 3; ++c) {
      const double e = std::exp(-(rayleigh_beta_per_m(lam[c], 500.0) + mie_beta_per_m(lam[c], 3.0, 500.0)) * s);
      EXPECT_NEAR(g[c], e, 1e-14 + 1e-13 * e) << s << " " << c;
    }
  }
}

TEST(AerialAttenuation, InUnitIntervalAndMonotoneOutTo100km) {
  // The default sensitivity is non-negative (xyz), so Gamma in (0, 1],
  // non-increasing in s and in T, for every T in 1..20.
  std::vector<SpectralSensitivity> qs = {load_sensitivity("default")};
  if (have_data(kCanonCsv)) qs.push_back(load_sensitivity(data_path(kCanonCsv)));
  for (const SpectralSensitivity& q : qs) {
    std::vector<std::array<double, 3>> prev_t;
    for (int t = 1; t <= 20; ++t) {
      const Atmosphere a{static_cast<double>(t), 0.0};
      const auto g0 = attenuation_direct(a, q, 0.0);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(g0[c], 1.0) << q.source;  // exactly: the normaliser's own sum
      std::array<double, 3> prev = g0;
      std::vector<std::array<double, 3>> row;
      for (int k = 0; k <= 60; ++k) {
        const double s = 100000.0 * std::pow(10.0, -5.0 + 5.0 * k / 60.0);  // 1 m .. 100 km
        const auto g = attenuation_direct(a, q, s);
        row.push_back(g);
        for (int c = 0; c < 3; ++c) {
          EXPECT_GT(g[c], 0.0) << q.source << " T " << t << " s " << s << " c " << c;
          EXPECT_LE(g[c], 1.0) << q.source << " T " << t << " s " << s << " c " << c;
          EXPECT_LT(g[c], prev[c]) << q.source << " T " << t << " s " << s << " c " << c;
          if (!prev_t.empty()) {
            EXPECT_LT(g[c], prev_t[k][c]) << q.source << " T " << t << " s " << s << " c " << c;
          }
        }
        prev = g;
      }
      prev_t = row;
    }
  }
}

TEST(AerialAttenuation, TableAgainstTheDirectIntegral) {
  // ln Gamma is convex in s (the log of a mixture of exponentials), its
  // curvature the variance of beta under the weights e^{-beta s} q, largest
  // near s = 0 and for high T; linear interpolation in ln Gamma errs by at most
  // step^2/8 times that variance. Measured max |table - direct| over 0..100 km
  // (nodes and mid-cells, default sensitivity): 4096 samples (step 24 m):
  // 4.8e-8 (T 1), 1.2e-7 (T 2), 3.1e-6 (T 8), 2.0e-5 (T 20, at s = 37 m);
  // 16384 samples (step 6 m) divide these by 16. Held here: 16384 samples to
  // 2e-6 for T = 1, 2, 8, 20, and a render-sized table (4096 samples over
  // 2 km, the demo scene's scale; 6.3e-8 measured with the f32 look-up) to
  // 1e-7 -- both far below 1e-4.
  const SpectralSensitivity q = load_sensitivity("default");
  struct Case {
    double s_max;
    int samples;
    double tol;
  };
  for (const Case& k : {Case{100000.0, 16384, 2e-6}, Case{2000.0, 4096, 1e-7}})
    for (double t : {1.0, 2.0, 8.0, 20.0}) {
      const Atmosphere a{t, 0.0};
      const AttenuationTable tab = attenuation_table(a, q, k.s_max, k.samples);
      ASSERT_EQ(tab.log_gamma.size(), static_cast<std::size_t>(k.samples));
      EXPECT_EQ(tab.log_gamma[0], (std::array<float, 3>{0.0f, 0.0f, 0.0f}));
      double worst = 0.0, worst_s = 0.0;
      const int n = 4000;
      for (int i = 0; i <= n; ++i) {
        // Mid-cell points (the worst place for interpolation) and nodes.
        const double s0 = i * k.s_max / n;
        const double s = i % 2 ? (std::floor(s0 / tab.step_m) + 0.5) * tab.step_m : s0;
        const auto d = attenuation_direct(a, q, s);
        const auto g = tab.at(s);
        for (int c = 0; c < 3; ++c)
          if (std::abs(g[c] - d[c]) > worst) worst = std::abs(g[c] - d[c]), worst_s = s;
      }
      std::printf("  s_max %6.0f m, %5d samples, T %4.1f: table max |Gamma - direct| = %.3g at s = %.1f m\n", k.s_max,
                  k.samples, t, worst, worst_s);
      EXPECT_LT(worst, k.tol) << "T " << t << " at s " << worst_s;
      // Nodes hold the direct integral itself (float rounding of ln Gamma).
      for (int i : {1, 100, k.samples - 1}) {
        const auto d = attenuation_direct(a, q, i * tab.step_m);
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(tab.log_gamma[i][c], std::log(d[c]), 1e-6 * std::max(1.0, std::abs(std::log(d[c]))));
      }
    }
}

TEST(AerialAttenuation, TableExtrapolatesAlongItsLastSlope) {
  // A closed form with ln Gamma linear in s is reproduced beyond the grid.
  const AttenuationTable t = AttenuationTable::from_function(
      [](double s) { return std::array<double, 3>{std::exp(-1e-4 * s), std::exp(-2e-4 * s), std::exp(-3e-4 * s)}; },
      1000.0, 11);
  for (double s : {0.0, 55.0, 1000.0, 1500.0}) {
    const auto g = t.at(s);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(g[c], std::exp(-(c + 1) * 1e-4 * s), 1e-6) << s;
  }
}

TEST(AerialAttenuation, ExpFAgainstDoubleExp) {
  // exp_f (Cody-Waite + Cephes' polynomial, f32) against double exp on a dense
  // grid of f32 arguments: the bound stated in aerial.hpp, 1e-7 relative
  // (about 1 ulp; 8.0e-8 measured), over the whole normal range of results;
  // 0 below it, inf above.
  double worst = 0.0, worst_x = 0.0;
  for (int k = 0; k <= 2000000; ++k) {
    const float x = -87.0f + 175.0f * static_cast<float>(k) / 2000000.0f;  // [-87, 88]
    const double want = std::exp(static_cast<double>(x));
    const double rel = std::abs(AttenuationTable::exp_f(x) - want) / want;
    if (rel > worst) worst = rel, worst_x = x;
  }
  std::printf("  exp_f: max relative error %.3g at x = %.6g\n", worst, worst_x);
  EXPECT_LT(worst, 1e-7) << "at x = " << worst_x;
  EXPECT_EQ(AttenuationTable::exp_f(0.0f), 1.0f);  // Gamma(0) = 1 exactly
  EXPECT_EQ(AttenuationTable::exp_f(-100.0f), 0.0f);
  EXPECT_EQ(AttenuationTable::exp_f(-1.0e4f), 0.0f);
  EXPECT_TRUE(std::isinf(AttenuationTable::exp_f(100.0f)));
}

TEST(AerialAttenuation, F32LookUpAgainstTheDoubleInterpolation) {
  // at() runs the interpolation in f32 with exp_f; the same interpolation in
  // double (t, f, ln Gamma and exp all double: the look-up before the speed
  // work) differs by the f32 rounding of t and ln Gamma (relative ~1.2e-7
  // |ln Gamma|) plus exp_f's 1e-7: aerial.hpp states <= 1.5e-7 absolute for
  // Gamma in [0, 1] (6.7e-8 measured). Spectral tables (default sensitivity) for a scene (2 km)
  // and a landscape (100 km), T 1 .. 20, s over the grid and 20 % beyond it.
  const SpectralSensitivity q = load_sensitivity("default");
  for (double s_max : {2000.0, 100000.0})
    for (double t : {1.0, 8.0, 20.0}) {
      const AttenuationTable tab = attenuation_table({t, 0.0}, q, s_max);
      double worst = 0.0, worst_s = 0.0;
      for (int k = 0; k <= 100000; ++k) {
        const double s = 1.2 * s_max * k / 100000.0 + 0.37 * (k % 7);  // off the nodes too
        const double u = s / tab.step_m;
        const std::size_t last = tab.log_gamma.size() - 1;
        const std::size_t i = u >= static_cast<double>(last) ? last - 1 : static_cast<std::size_t>(u);
        const double f = u - static_cast<double>(i);
        const auto g = tab.at(s);
        for (int c = 0; c < 3; ++c) {
          const double a = tab.log_gamma[i][c], b = tab.log_gamma[i + 1][c];
          const double want = s > 0.0 ? std::exp(a + f * (b - a)) : 1.0;
          if (std::abs(g[c] - want) > worst) worst = std::abs(g[c] - want), worst_s = s;
        }
      }
      std::printf("  s_max %6.0f m, T %4.1f: max |at - double interpolation| = %.3g at s = %.1f m\n", s_max, t, worst,
                  worst_s);
      EXPECT_LT(worst, 1.5e-7) << "s_max " << s_max << " T " << t << " at s " << worst_s;
    }
}

TEST(AerialAttenuation, RecurrenceNodesHoldTheDirectIntegral) {
  // The table's nodes come from a recurrence over s (re-seeded every 64
  // nodes); its drift (<= 1.4e-14 relative) is far below the f32 storage of
  // ln Gamma, so EVERY node equals ln attenuation_direct rounded to f32 within
  // 1 ulp (a 1-ulp flip where the double value lies at a rounding midpoint).
  const SpectralSensitivity q = load_sensitivity("default");
  const Atmosphere a{8.0, 0.0};
  const AttenuationTable tab = attenuation_table(a, q, 100000.0, 4096);
  int worst_ulp = 0;
  for (std::size_t i = 1; i < tab.log_gamma.size(); ++i) {
    const auto d = attenuation_direct(a, q, static_cast<double>(i) * tab.step_m);
    for (int c = 0; c < 3; ++c) {
      const float want = static_cast<float>(std::log(d[c]));
      float lo = want, hi = want;
      int ulp = 0;
      while (tab.log_gamma[i][c] != lo && tab.log_gamma[i][c] != hi && ulp < 100)
        lo = std::nextafter(lo, -INFINITY), hi = std::nextafter(hi, INFINITY), ++ulp;
      worst_ulp = std::max(worst_ulp, ulp);
    }
  }
  EXPECT_LE(worst_ulp, 1);
}
