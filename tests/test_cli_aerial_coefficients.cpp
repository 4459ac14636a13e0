// `brume aerial coefficients` end to end: the CSV tables against the library's
// own functions (same numbers, printed to 12 significant digits), the column
// names per sensitivity space, and the error paths (message naming the flag
// or file and the value, exit status 2, nothing written).
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "brume/aerial.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

std::vector<std::vector<std::string>> read_csv(const std::string& path) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    std::vector<std::string> r;
    std::stringstream ss(line);
    std::string x;
    while (std::getline(ss, x, ',')) r.push_back(x);
    rows.push_back(r);
  }
  return rows;
}

class CliAerialCoefficients : public ScratchDirTest {};

}  // namespace

TEST_F(CliAerialCoefficients, TablesMatchTheLibrary) {
  CliRun r = run("aerial coefficients --turbidity 8 --altitude 431 --distances 0,100,1000,10000 --out " +
                 p("t.csv") + " --spectrum " + p("s.csv"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto t = read_csv(p("t.csv"));
  ASSERT_EQ(t.size(), 5u);
  EXPECT_EQ(t[0], (std::vector<std::string>{"distance_m", "gamma_x", "gamma_y", "gamma_z"}));  // default: CIE XYZ
  const SpectralSensitivity q = load_sensitivity("default");
  const double d[4] = {0, 100, 1000, 10000};
  for (int i = 0; i < 4; ++i) {
    ASSERT_EQ(t[i + 1].size(), 4u);
    EXPECT_EQ(std::stod(t[i + 1][0]), d[i]);
    const auto g = attenuation_direct({8.0, 431.0}, q, d[i]);
    // 12 significant digits in the file.
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(std::stod(t[i + 1][1 + c]), g[c], 1e-11 * g[c]) << i << " " << c;
  }
  const auto s = read_csv(p("s.csv"));
  ASSERT_EQ(s.size(), 402u);  // header + 380..780 nm
  EXPECT_EQ(s[0], (std::vector<std::string>{"wavelength_nm", "beta_rayleigh_per_m", "beta_mie_per_m"}));
  for (int i : {0, 170, 400}) {
    const double l = 380.0 + i;
    EXPECT_EQ(std::stod(s[i + 1][0]), l);
    EXPECT_NEAR(std::stod(s[i + 1][1]), rayleigh_beta_per_m(l, 431.0), 1e-11 * rayleigh_beta_per_m(l, 431.0));
    EXPECT_NEAR(std::stod(s[i + 1][2]), mie_beta_per_m(l, 8.0, 431.0), 1e-11 * mie_beta_per_m(l, 8.0, 431.0));
  }
}

TEST_F(CliAerialCoefficients, CameraSensitivityGivesRgbColumns) {
  BRUME_REQUIRE_DATA("spectral/camspec_database.txt");
  const std::string db = data_path("spectral/camspec_database.txt");
  CliRun r = run("aerial coefficients --turbidity 2 --sensitivity '" + db + "#Canon 5DMarkII' --out " + p("t.csv"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto t = read_csv(p("t.csv"));
  ASSERT_EQ(t.size(), 4u);  // default distances 100, 1000, 10000
  EXPECT_EQ(t[0], (std::vector<std::string>{"distance_m", "gamma_r", "gamma_g", "gamma_b"}));
  const auto g = attenuation_direct({2.0, 0.0}, load_sensitivity(db + "#Canon 5DMarkII"), 10000.0);
  EXPECT_NEAR(std::stod(t[3][3]), g[2], 1e-11 * g[2]);
  // Blue is scattered more than red: lower transmission.
  EXPECT_LT(std::stod(t[3][3]), std::stod(t[3][1]));
}

TEST_F(CliAerialCoefficients, BadInputsNameTheValueAndWriteNothing) {
  const std::string bad_csv = p("bad.csv");
  std::ofstream(bad_csv) << "# comments only\n";
  struct Case {
    std::string args;
    std::vector<std::string> expect;
  };
  const std::vector<Case> cases = {
      {"--turbidity 0.5", {"--turbidity", "0.5", "[1, 20]"}},
      {"--turbidity 25", {"--turbidity", "25"}},
      {"--altitude -600", {"--altitude", "-600", "[-500, 9000]"}},
      {"--altitude 9500", {"--altitude", "9500"}},
      {"--distances 100,-5", {"--distances", "'-5'"}},
      {"--distances 100,abc", {"--distances", "'abc'"}},
      {"--sensitivity " + bad_csv, {"bad.csv", "no data rows"}},
      {"--sensitivity " + p("missing.csv"), {"missing.csv"}},
      {"--spectrum " + p("nodir/s.csv"), {"--spectrum", "nodir"}},
  };
  for (const Case& c : cases) {
    CliRun r = run("aerial coefficients " + c.args + " --out " + p("t.csv"));
    EXPECT_EQ(r.status, 2) << c.args << ": " << r.output;
    for (const auto& x : c.expect) EXPECT_NE(r.output.find(x), std::string::npos) << c.args << ": " << r.output;
    EXPECT_FALSE(fs::exists(p("t.csv"))) << c.args;
  }
  CliRun r = run("aerial coefficients --turbidity 2");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--out"), std::string::npos) << r.output;
  // Only the inputs this test wrote remain.
  for (auto& e : fs::directory_iterator(dir)) EXPECT_EQ(e.path().filename(), "bad.csv");
}
