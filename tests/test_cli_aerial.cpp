// `brume aerial` end to end: every output and the record, `brume run`
// repeating it bit for bit, and the error paths (message naming the flag or
// file, non-zero exit, nothing written).
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "brume/io.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

class CliAerial : public ScratchDirTest {
 protected:
  std::string img, range;
  void SetUp() override {
    Image rgb(48, 32, 3), r(48, 32, 1);
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 48; ++x) {
        for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = y < 6 ? 0.75f : (((x / 4 + y / 4 + c) % 2) ? 0.8f : 0.1f);
        r.at(x, y) = y < 6 ? NAN : 100.0f + 40.0f * (32 - y);  // 140 .. 1140 m, sky above
      }
    img = (dir / "img.exr").string();
    range = (dir / "range.exr").string();
    write_image(img, rgb, WriteOptions{});
    WriteOptions data;
    data.is_color = false;
    write_image(range, r, data);
  }
  bool only_inputs_left() const {
    for (auto& e : fs::directory_iterator(dir)) {
      const std::string n = e.path().filename().string();
      if (n != "img.exr" && n != "range.exr") return false;
    }
    return true;
  }
};

}  // namespace

TEST_F(CliAerial, WritesEveryOutputAndARecord) {
  CliRun r = run("aerial --image " + img + " --range " + range + " --turbidity 4 --altitude 200 --lambda 5 --out " +
                 p("o.exr") + " --attenuation " + p("g.exr") + " --scale-map " + p("s.exr") + " --record " +
                 p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"o.exr", "g.exr", "s.exr", "r.json"}) EXPECT_TRUE(fs::exists(p(f))) << f;
  const nlohmann::json j = read_json(p("r.json"));
  const auto& d = j["aerial"]["derived"];
  EXPECT_EQ(d["mode"], "render");
  EXPECT_NEAR(d["range_max_m"].get<double>(), 1140.0, 1e-3);
  EXPECT_EQ(d["unknown_range_pixels"], 6 * 48);
  // Iinf from the sky's median, which is uniformly 0.75.
  EXPECT_EQ(d["airlight_linear_rgb"], nlohmann::json({0.75, 0.75, 0.75}));
  for (const char* k : {"100_m", "1000_m", "10000_m"}) EXPECT_EQ(d["gamma_at"][k].size(), 3u) << k;
  EXPECT_TRUE(d["sensitivity"].contains("sha256"));
  EXPECT_EQ(j["job"]["aerial"]["turbidity"], 4.0);
  // kappa_s' = beta(550) R_max, and sigma_max = sigma0 + lambda sqrt(kappa_s').
  EXPECT_NEAR(d["sigma_max_px"].get<double>(), 1.0 + 5.0 * std::sqrt(d["kappa_s_normalised"].get<double>()), 1e-5);
  // Sky unchanged; the attenuation file has three channels, 1 on the sky.
  const Image o = read_color(p("o.exr")), in = read_color(img), g = read_color(p("g.exr"));
  EXPECT_EQ(o.at(10, 2, 0), in.at(10, 2, 0));
  ASSERT_EQ(g.channels, 3);
  EXPECT_EQ(g.at(10, 2, 2), 1.0f);
  EXPECT_LT(g.at(10, 31, 2), 1.0f);
}

TEST_F(CliAerial, ErrorPathsAreClearAndLeaveNothing) {
  Image small(20, 10, 1, 3.0f);
  WriteOptions data;
  data.is_color = false;
  write_image(p("small.exr"), small, data);
  const std::string io = " --image " + img + " --range " + range + " --out " + p("o.exr") + " --record " + p("r.json");
  struct Case {
    std::string args, must_contain;
  };
  const Case cases[] = {
      {"aerial" + io + " --turbidity 25", "--turbidity"},
      {"aerial" + io + " --turbidity 0.5", "--turbidity"},
      {"aerial" + io + " --altitude 9500", "--altitude"},
      {"aerial" + io + " --altitude -600", "--altitude"},
      {"aerial" + io + " --remove --from-turbidity 3", "--from-turbidity"},
      {"aerial" + io + " --from-horizon 0.5,0.5,0.5", "--from-horizon"},
      {"aerial" + io + " --remove --lambda 4", "--lambda"},
      {"aerial" + io + " --gamma-floor 1", "--gamma-floor"},
      {"aerial --image " + img + " --range " + p("small.exr") + " --out " + p("o.exr"), "20x10"},
  };
  for (const Case& c : cases) {
    CliRun r = run(c.args);
    EXPECT_EQ(r.status, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.must_contain), std::string::npos) << c.args << "\n" << r.output;
    for (auto& e : fs::directory_iterator(dir)) {
      const std::string n = e.path().filename().string();
      EXPECT_TRUE(n == "img.exr" || n == "range.exr" || n == "small.exr") << c.args << " left " << n;
    }
  }
}

TEST_F(CliAerial, RunRepeatsARecordBitForBit) {
  fs::create_directories(p("first"));
  const std::string base = "aerial --image " + img + " --range " + range;
  CliRun a = run(base + " --turbidity 6 --horizon 0.7,0.72,0.75 --lambda 4 --distance-scale 2 --out " +
                 p("first/a.exr") + " --attenuation " + p("first/g.exr") + " --record " + p("first/a.json"));
  ASSERT_EQ(a.status, 0) << a.output;
  CliRun re = run(base + " --turbidity 8 --from-turbidity 3 --from-horizon 0.6,0.6,0.65 --out " + p("first/re.exr") +
                  " --record " + p("first/re.json"));
  ASSERT_EQ(re.status, 0) << re.output;
  CliRun rm = run(base + " --turbidity 3 --remove --gamma-floor 0.01 --out " + p("first/rm.exr") + " --record " +
                  p("first/rm.json"));
  ASSERT_EQ(rm.status, 0) << rm.output;
  EXPECT_EQ(read_json(p("first/re.json"))["aerial"]["derived"]["mode"], "re-render");
  EXPECT_EQ(read_json(p("first/rm.json"))["aerial"]["derived"]["mode"], "remove");
  for (const char* rec : {"a.json", "re.json", "rm.json"}) {
    CliRun r = run("run " + p(std::string("first/") + rec) + " --out-dir " + p("again"));
    ASSERT_EQ(r.status, 0) << rec << "\n" << r.output;
  }
  for (const char* f : {"a.exr", "g.exr", "re.exr", "rm.exr"}) {
    expect_same_pixels(p(std::string("first/") + f), p(std::string("again/") + f));
  }
  nlohmann::json r1 = read_json(p("first/a.json")), r2 = read_json(p("again/a.json"));
  r1["job"]["output"] = r2["job"]["output"] = nullptr;
  EXPECT_EQ(r1["job"], r2["job"]);
}
