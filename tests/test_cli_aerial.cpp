// `brume aerial` end to end: every output and the record, `brume run`
// repeating it bit for bit, and the error paths (message naming the flag or
// file, non-zero exit, nothing written).
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "brume/aerial.hpp"
#include "brume/camera.hpp"
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
  struct Case {
    std::string args, must_contain;
  };
  // Each case exits 2 naming what it must, and leaves only the inputs
  // (img.exr, range.exr and a small.exr a case may read).
  template <std::size_t N>
  void expect_refused(const Case (&cases)[N]) {
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
  expect_refused(cases);
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

// --path slant from the command line (issue #59): the record says where the
// targets' altitudes came from, `brume run` repeats it bit for bit (from the
// pose and from a --target-altitude file), and what it cannot do is refused
// with nothing written.
TEST_F(CliAerial, SlantPathRecordsRepeatsAndRefuses) {
  fs::create_directories(p("first"));
  Image alt(48, 32, 1, 1650.0f);
  WriteOptions data;
  data.is_color = false;
  write_image(p("first/alt.exr"), alt, data);
  const std::string base = "aerial --image " + img + " --range " + range + " --altitude 1500 --turbidity 5";
  CliRun a = run(base + " --path slant --fov-x 40 --pitch 12 --roll 3 --out " + p("first/a.exr") + " --attenuation " +
                 p("first/g.exr") + " --record " + p("first/a.json"));
  ASSERT_EQ(a.status, 0) << a.output;
  EXPECT_NE(a.output.find("(slant path)"), std::string::npos) << a.output;
  CliRun b = run(base + " --path slant --target-altitude " + p("first/alt.exr") + " --remove --out " + p("first/b.exr") +
                 " --record " + p("first/b.json"));
  ASSERT_EQ(b.status, 0) << b.output;
  const nlohmann::json ja = read_json(p("first/a.json")), jb = read_json(p("first/b.json"));
  EXPECT_EQ(ja["job"]["aerial"]["path"], "slant");
  EXPECT_EQ(ja["job"]["camera"]["pitch"], 12.0);
  EXPECT_GT(ja["aerial"]["derived"]["slant_path"]["dh_max_m"].get<double>(), 100.0);
  EXPECT_NE(jb["aerial"]["derived"]["slant_path"]["target_altitude"].get<std::string>().find("alt.exr"),
            std::string::npos);
  EXPECT_NEAR(jb["aerial"]["derived"]["slant_path"]["dh_min_m"].get<double>(), 150.0, 1e-9);
  for (const char* rec : {"a.json", "b.json"}) {
    CliRun r = run("run " + p(std::string("first/") + rec) + " --out-dir " + p("again"));
    ASSERT_EQ(r.status, 0) << rec << "\n" << r.output;
  }
  for (const char* f : {"a.exr", "g.exr", "b.exr"}) expect_same_pixels(p(std::string("first/") + f), p(std::string("again/") + f));
  // A level render differs from the slant one (targets 150 m above: thinner air).
  CliRun l = run(base + " --remove --out " + p("first/l.exr"));
  ASSERT_EQ(l.status, 0) << l.output;
  EXPECT_NE(file_bytes(p("first/l.exr")), file_bytes(p("first/b.exr")));

  fs::remove_all(p("first"));
  fs::remove_all(p("again"));
  Image small(20, 10, 1, 900.0f);
  write_image(p("small.exr"), small, data);
  const std::string io = " --image " + img + " --range " + range + " --out " + p("o.exr") + " --record " + p("r.json");
  const Case cases[] = {
      {"aerial" + io + " --path slant", "--target-altitude FILE"},
      {"aerial" + io + " --fov-x 40 --pitch 3", "--path slant"},
      {"aerial" + io + " --target-altitude " + p("small.exr"), "--path slant"},
      {"aerial" + io + " --path slant --target-altitude " + p("small.exr"), "20x10"},
      {"aerial" + io + " --path slant --target-altitude " + p("small.exr") + " --pitch 2", "drop one of them"},
      {"aerial" + io + " --path slant --fov-x 40 --pitch -80 --altitude 0", "below the model's -500 m"},
      {"aerial" + io + " --airlight sunset", "horizon"},
  };
  expect_refused(cases);
}

// Removal that goes below zero is counted exactly on the output, warned
// about in the terminal and in the record, and shown on the summary line.
TEST_F(CliAerial, NegativePixelsAreCountedAndSaid) {
  CliRun r = run("aerial --image " + img + " --range " + range + " --turbidity 12 --remove --airlight 0.9,0.9,0.9 --out " +
                 p("o.exr") + " --record " + p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image o = read_color(p("o.exr")), rg = read_scalar(range);
  std::size_t neg = 0, ground = 0;
  float least = 0.0f;
  for (std::size_t i = 0; i < o.pixels(); ++i) {
    if (!std::isfinite(rg.data[i])) continue;  // the sky rows
    ++ground;
    const float m = std::min({o.data[3 * i], o.data[3 * i + 1], o.data[3 * i + 2]});
    neg += m < 0.0f;
    least = std::min(least, m);
  }
  ASSERT_GT(neg, 0u);  // the dark squares far away: darker than the air alone
  const nlohmann::json d = read_json(p("r.json"))["aerial"]["derived"]["negative_pixels"];
  EXPECT_EQ(d["count"].get<std::size_t>(), neg);
  EXPECT_EQ(d["of_ground_pixels"].get<std::size_t>(), ground);
  EXPECT_EQ(d["least_value"].get<float>(), least);
  EXPECT_EQ(read_json(p("r.json"))["aerial"]["warnings"].size(), 1u);
  EXPECT_NE(r.output.find("warning:"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("below zero"), std::string::npos) << r.output;
  // A render of a non-negative image has none, and says nothing.
  CliRun q = run("aerial --image " + img + " --range " + range + " --out " + p("q.exr") + " --record " + p("q.json"));
  ASSERT_EQ(q.status, 0) << q.output;
  EXPECT_EQ(read_json(p("q.json"))["aerial"]["derived"]["negative_pixels"]["count"], 0);
  EXPECT_EQ(q.output.find("warning"), std::string::npos) << q.output;
}

// The GeoPose3K Matterhorn photo from the camera's solved pose (issue #59),
// with the horizon's airlight: the attenuation on land beyond 10 km equals the slant closed form at each
// pixel (Gamma per XYZ channel from the spectral integral at the equivalent
// distances of its ray, the table's 1e-6 and f32: 2e-6).
TEST_F(CliAerial, MatterhornSlantAttenuationIsTheClosedForm) {
  BRUME_REQUIRE_DATA("geopose3k_matterhorn/distance.pfm");
  const std::string m = data_path("geopose3k_matterhorn/");
  CliRun r = run("aerial --image " + m + "photo.jpg --range " + m + "distance.pfm --unknown-value -1 --remove "
                 "--altitude 2910 --fov-x 42.5 --pitch 0.7 --path slant --turbidity contrast --airlight horizon "
                 "--out " + p("o.exr") + " --attenuation " + p("g.exr") + " --record " + p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  // --turbidity contrast on this photo: the terrain's contrast does not fall
  // with distance (meadows near, rock and snow far; docs/aerial.md), so the
  // fit sits on T = 1 and says so; the attenuation below is at the fitted T.
  const nlohmann::json rec = read_json(p("r.json"));
  const nlohmann::json& fit = rec["turbidity_fit"];
  const double t_fit = fit["turbidity"].get<double>();
  EXPECT_EQ(rec["job"]["aerial"]["turbidity"], "contrast");
  EXPECT_EQ(rec["aerial"]["parameters"]["aerial"]["turbidity"].get<double>(), t_fit);
  EXPECT_TRUE(fit["at_lower_bound"].get<bool>()) << fit.dump();
  EXPECT_NE(r.output.find("sits on its lower bound T = 1"), std::string::npos) << r.output;
  EXPECT_GT(fit["bins"].size(), 20u);
  CliRun again = run("run " + p("r.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("o.exr"), p("again/o.exr"));
  const Image g = read_color(p("g.exr")), d = read_scalar(m + "distance.pfm");
  CameraPose pose;
  pose.pitch_deg = 0.7;
  const Camera cam = make_camera(camera_from_fov(g.width, g.height, 42.5).k, g.width, g.height, pose);
  const SpectralSensitivity q = load_sensitivity("default");
  double worst = 0.0;
  int n = 0;
  for (int y = 0; y < g.height; y += 5)
    for (int x = 0; x < g.width; x += 5) {
      const double s = d.at(x, y);
      if (!(s > 10000.0)) continue;
      const SlantDistances sd = slant_distances(s, s * cam.world_ray(x, y).y);
      const auto want = attenuation_slant_direct({t_fit, 2910.0}, q, sd.rayleigh_m, sd.mie_m);
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(g.at(x, y, c) - want[c]));
      ++n;
    }
  EXPECT_GT(n, 500);
  EXPECT_LE(worst, 2e-6);
  const nlohmann::json& j = rec["aerial"]["derived"];
  EXPECT_NEAR(j["slant_path"]["dh_max_m"].get<double>(), 1568.0, 30.0);  // the summit, 4,478 m
  EXPECT_LT(j["negative_pixels"]["fraction"].get<double>(), 0.40);
  // Issue #59's removal targets per band of distance (< 5, 5-10, > 10 km):
  // at most 40 % of the ground pixels with a channel <= 0, the least
  // channel's 1st percentile >= -0.25; and the far land's contrast (mean
  // |Y difference| of right neighbours on one surface, ranges within 1 %,
  // beyond 10 km) raised by x1.08-1.5 from the photo's.
  const Image out = read_color(p("o.exr")), photo = read_color(m + "photo.jpg");
  std::vector<float> least[3];
  std::size_t ground[3] = {0, 0, 0}, below[3] = {0, 0, 0};
  double dy_out = 0.0, dy_in = 0.0;
  const auto luma = [](const Image& im, int x, int y) {
    return 0.2126 * im.at(x, y, 0) + 0.7152 * im.at(x, y, 1) + 0.0722 * im.at(x, y, 2);
  };
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      const float s = d.at(x, y);
      if (!(s > 0.0f)) continue;
      const int band = s < 5000.0f ? 0 : s < 10000.0f ? 1 : 2;
      const float lo = std::min({out.at(x, y, 0), out.at(x, y, 1), out.at(x, y, 2)});
      ++ground[band];
      below[band] += lo <= 0.0f ? 1 : 0;
      least[band].push_back(lo);
      const float s2 = x + 1 < out.width ? d.at(x + 1, y) : NAN;
      if (band == 2 && s2 > 0.0f && std::abs(s2 - s) < 0.01f * s) {
        dy_out += std::abs(luma(out, x + 1, y) - luma(out, x, y));
        dy_in += std::abs(luma(photo, x + 1, y) - luma(photo, x, y));
      }
    }
  for (int b = 0; b < 3; ++b) {
    ASSERT_GT(ground[b], 1000u) << "band " << b;
    auto k = least[b].begin() + static_cast<std::ptrdiff_t>(least[b].size() / 100);
    std::nth_element(least[b].begin(), k, least[b].end());
    std::printf("Matterhorn band %d: %.1f %% of %zu ground pixels <= 0, 1st percentile of the least channel %.3f\n", b,
                100.0 * below[b] / ground[b], ground[b], *k);
    EXPECT_LE(static_cast<double>(below[b]) / ground[b], 0.40) << "band " << b;
    EXPECT_GE(*k, -0.25f) << "band " << b;
  }
  std::printf("Matterhorn far contrast x%.3f (Y, beyond 10 km)\n", dy_out / dy_in);
  EXPECT_GE(dy_out / dy_in, 1.08);
  EXPECT_LE(dy_out / dy_in, 1.5);
  // The horizon's airlight: within 10 % of the sky just above the far ridges
  // in G and B (about 0.45, 0.85 linear, measured on the photo for issue #59).
  EXPECT_NEAR(j["airlight_linear_rgb"][1].get<double>(), 0.45, 0.045);
  EXPECT_NEAR(j["airlight_linear_rgb"][2].get<double>(), 0.85, 0.085);
}
