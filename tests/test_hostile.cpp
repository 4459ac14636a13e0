// Issue #51, "No silent garbage, no unbounded input": each reproducer of the
// issue as it was found (the command line; Python's are in
// python/tests/test_hostile.py, the batch's in test_batch.cpp), on the demo
// scene at 160 x 112 as there. Before the fixes these ran for minutes, spun
// on /dev/zero, hung on a FIFO, ended in "internal error: std::bad_alloc",
// or wrote a wrong result with exit 0; now each fails cleanly (exit 2, the
// flag or file named, nothing written) or gives the right result.
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "brume/command.hpp"
#include "brume/demo_scene.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

// KITTI object 000000's calibration (training; the values fuzz_velodyne uses).
const char* kKittiCalib =
    "P0: 707.0493 0 604.0814 0 0 707.0493 180.5066 0 0 0 1 0\n"
    "P2: 707.0493 0 604.0814 45.75831 0 707.0493 180.5066 -0.3454157 0 0 1 0.004981016\n"
    "R0_rect: 0.9999128 0.01009263 -0.008511932 -0.01012729 0.9999406 -0.004037671 0.008470675 0.004123522 "
    "0.9999556\n"
    "Tr_velo_to_cam: 0.006927964 -0.9999722 -0.002757829 -0.02457729 -0.001162982 0.002749836 -0.9999955 "
    "-0.06127237 0.9999753 0.006931141 -0.001143899 -0.3321029\n";

class Hostile : public ScratchDirTest {
 protected:
  std::string img, range;
  void SetUp() override {
    // The scene: the demo at 160 x 112 (clean.png, range.exr).
    const DemoScene s = render_demo_scene(160, 112);
    img = p("clean.png");
    range = p("range.exr");
    write_image(img, s.rgb, WriteOptions{});
    WriteOptions data;
    data.is_color = false;
    data.float_reason = "metres";
    write_image(range, s.range, data);
  }
  // A shell command line (the CLI as `brume`), bounded in time: a hang is a
  // failure (status 124), not a stuck suite.
  CliRun sh(const std::string& line, int seconds = 120) const {
    std::string cmd = line;
    for (std::size_t at = cmd.find("brume "); at != std::string::npos; at = cmd.find("brume ", at + 1))
      if (at == 0 || cmd[at - 1] == ' ' || cmd[at - 1] == ';') {
        cmd.replace(at, 5, BRUME_CLI);
        at += std::strlen(BRUME_CLI);
      }
    FILE* f = popen(("timeout " + std::to_string(seconds) + " sh -c '" + cmd + "' 2>&1").c_str(), "r");
    CliRun r{-1, ""};
    if (!f) return r;
    char buf[4096];
    while (std::fgets(buf, sizeof buf, f)) r.output += buf;
    const int st = pclose(f);
    r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
    return r;
  }
  // Every CLI run of these tests is bounded in time (the reproducers ran
  // for hours or forever before the fixes).
  CliRun run(const std::string& args, int seconds = 300) const { return sh("brume " + args, seconds); }
  void write_scan(const std::string& name, const std::vector<float>& xyzi) const {
    std::ofstream(p(name), std::ios::binary)
        .write(reinterpret_cast<const char*>(xyzi.data()), static_cast<std::streamsize>(xyzi.size() * 4));
  }
  // A record of a valid haze run, as JSON.
  nlohmann::json haze_record() {
    const CliRun r = run("haze --image " + img + " --range " + range + " --visibility 300 --lambda 6 --out " +
                         p("h.png") + " --record " + p("h.json"));
    EXPECT_EQ(r.status, 0) << r.output;
    return nlohmann::json::parse(file_bytes(p("h.json")));
  }
  void save(const nlohmann::json& j, const std::string& name) const { std::ofstream(p(name)) << j.dump(2); }
};

bool has(const CliRun& r, const std::string& text) { return r.output.find(text) != std::string::npos; }

}  // namespace

// Defect 1. `haze --visibility 300 --lambda 1e4 --scheme standard` printed "1
// iterations" (the count overflowed from sigma_max ~ 4e4 px) and wrote a
// banded, saturated image, exit 0; at lambda 1e3 it ran without bound; haze's
// lambda 1e9 ended in "internal error: std::bad_alloc"; fog's exited 0 with
// sigma 1.5e9 px; blur --sigma 10000 --scheme standard (within its cap) ran
// for hours on 160 x 112. The derived sigma_max is refused past 8 diagonals,
// naming itself, its value, the bound and the flags that set it.
TEST_F(Hostile, SigmaMaxPastTheImageIsRefusedNamingItsFlags) {
  const std::string io = " --image " + img + " --range " + range + " --out " + p("s.png");
  CliRun r = run("haze" + io + " --visibility 300 --lambda 1e4 --scheme standard");
  EXPECT_EQ(r.status, 2) << r.output;
  for (const char* want : {"sigma_max", "diagonal", "--lambda 10000", "--visibility 300", "R_max", "refuses more than 8"})
    EXPECT_TRUE(has(r, want)) << want << " in " << r.output;
  EXPECT_FALSE(fs::exists(p("s.png")));
  r = run("haze" + io + " --visibility 300 --lambda 1e3 --scheme standard");
  EXPECT_EQ(r.status, 2) << r.output;
  r = run("haze" + io + " --visibility 300 --lambda 1e9");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_FALSE(has(r, "internal error")) << r.output;
  EXPECT_TRUE(has(r, "sigma_max")) << r.output;
  r = run("fog" + io + " --camera-height 1.6 --fov-y 55 --lambda 1e9");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "--lambda 1e+09")) << r.output;
  r = run("blur --image " + img + " --sigma 10000 --scheme standard --out " + p("s.png"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "--sigma 10000")) << r.output;
  r = run("dof" + io + " --focus-distance 3 --coc-infinity 1e6 --coc-limit 1e6 --fov-y 55");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "--coc-limit")) << r.output;
  EXPECT_FALSE(fs::exists(p("s.png")));
  // What users run passes: the sampler's densest haze (visibility 50 m, lambda 8).
  r = run("haze" + io + " --visibility 50 --lambda 8");
  EXPECT_EQ(r.status, 0) << r.output;
}

// The standard scheme's work, iterations x pixels, is bounded too: sigma 300
// is within 8 diagonals of a 1000 x 800 image but needs 180 000 iterations
// of it (1.4e11 pixel-iterations); the message names the default scheme,
// which reaches it in tens.
TEST_F(Hostile, StandardSchemeWorkIsBounded) {
  write_image(p("big.png"), Image(1000, 800, 3, 0.5f), WriteOptions{});
  const std::string io = "blur --image " + p("big.png") + " --sigma 300 --out " + p("b.png");
  CliRun r = run(io + " --scheme standard");
  EXPECT_EQ(r.status, 2) << r.output;
  for (const char* want : {"pixel-iterations", "refuses more than 1e+11", "--scheme invariant-exact", "--sigma 300"})
    EXPECT_TRUE(has(r, want)) << want << " in " << r.output;
  EXPECT_FALSE(fs::exists(p("b.png")));
  r = run(io);
  EXPECT_EQ(r.status, 0) << r.output;
}

// The same check, from the same code, for `brume run` (a record edited to
// lambda 1e4) and brume view's plan (the command's preview); Python's is in
// python/tests/test_hostile.py.
TEST_F(Hostile, TheBoundHoldsForBrumeRunAndTheViewsPlan) {
  nlohmann::json rec = haze_record();
  rec["job"]["haze"]["lambda"] = 1e4;
  rec["job"]["diffusion"]["scheme"] = "standard";
  rec["job"]["output"]["out"] = p("again.png");
  save(rec, "edited.json");
  const CliRun r = run("run " + p("edited.json"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "sigma_max")) << r.output;
  EXPECT_FALSE(fs::exists(p("again.png")));

  const CommandDef* haze = find_command("haze");
  ASSERT_TRUE(haze && haze->preview);
  const Image rgb = read_color(img), measured = read_scalar(range);
  const PreparedRange prep = prepare_step(measured, RangeStep{}, {}, 1, true);
  const nlohmann::json job =
      haze->build({{"image", img}, {"range", range}, {"visibility", 300.0}, {"lambda", 1e4}, {"scheme", "standard"}});
  const std::string e = error_of([&] { haze->preview(job, PreviewInputs{rgb, measured, prep}); });
  EXPECT_NE(e.find("sigma_max"), std::string::npos) << e;
  EXPECT_NE(e.find("--lambda 10000"), std::string::npos) << e;
}

// Defect 4. Inputs are regular files, checked before anything is read:
// --image /dev/zero and a record naming /dev/zero spun forever, --points
// /dev/zero grew ~0.7 GB/s until the kernel killed it, `--points .` read a
// directory as 0 points with exit 0, and a FIFO blocked the open.
TEST_F(Hostile, InputsMustBeRegularFiles) {
  ASSERT_EQ(::mkfifo(p("fifo.png").c_str(), 0600), 0);
  CliRun r = sh("brume haze --image /dev/zero --range " + range + " --visibility 300 --out " + p("o.png"), 30);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "'/dev/zero': it is a character device, not a regular file")) << r.output;
  r = sh("brume haze --image " + p("fifo.png") + " --range " + range + " --visibility 300 --out " + p("o.png"), 30);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "FIFO")) << r.output;
  r = sh("brume depth convert --range " + p("fifo.png") + " --out " + p("o.exr"), 30);
  EXPECT_EQ(r.status, 2) << r.output;
  r = sh("brume lidar fog --points /dev/zero --visibility 50 --out " + p("o.bin"), 30);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "--points '/dev/zero'")) << r.output;
  r = sh("brume lidar fog --points " + dir.string() + " --visibility 50 --out " + p("o.bin"), 30);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "it is a directory")) << r.output;
  r = sh("brume depth convert --velodyne /dev/zero --kitti-calib " + p("fifo.png") + " --width 64 --height 32 --out " +
             p("o.exr"),
         30);
  EXPECT_EQ(r.status, 2) << r.output;
  r = sh("brume run /dev/zero", 30);
  EXPECT_EQ(r.status, 2) << r.output;
  // A record whose input names /dev/zero: refused when it is hashed, not spun on.
  nlohmann::json rec = haze_record();
  rec["inputs"]["image"]["path"] = "/dev/zero";
  rec["job"]["input"]["image"] = "/dev/zero";
  save(rec, "zero.json");
  r = sh("brume run " + p("zero.json"), 30);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "character device")) << r.output;
  EXPECT_FALSE(fs::exists(p("o.png")) || fs::exists(p("o.exr")) || fs::exists(p("o.bin")));
}

// Defect 4. One KITTI .bin reader with the 10 M point limit for every command
// that reads a scan: `lidar fog` and `haze --lidar` skipped it (50 M points
// ran at 2.4 GB). A sparse file of 50 M points is refused from its size.
TEST_F(Hostile, EveryScanReaderHasThePointLimit) {
  {
    std::ofstream f(p("huge.bin"), std::ios::binary);
  }
  fs::resize_file(p("huge.bin"), 50'000'000ull * 16);  // sparse: nothing is written
  const std::string calib = p("calib.txt");
  std::ofstream(calib) << kKittiCalib;
  for (const std::string& cmd :
       {"lidar fog --points " + p("huge.bin") + " --visibility 50 --out " + p("o.bin"),
        "haze --image " + img + " --range " + range + " --visibility 300 --lidar " + p("huge.bin") + " --lidar-out " +
            p("o.bin") + " --out " + p("o.png"),
        "depth convert --velodyne " + p("huge.bin") + " --kitti-calib " + calib + " --width 1242 --height 375 --out " +
            p("o.exr")}) {
    const CliRun r = sh("brume " + cmd, 60);
    EXPECT_EQ(r.status, 2) << cmd << ": " << r.output;
    EXPECT_TRUE(has(r, "holds 50 000 000 points")) << r.output;
    EXPECT_TRUE(has(r, "refuses more than 10 000 000")) << r.output;
  }
  EXPECT_FALSE(fs::exists(p("o.bin")) || fs::exists(p("o.png")) || fs::exists(p("o.exr")));
}

// Under a memory limit a scan within the point limit is refused before it is
// read with the documented message naming both amounts (it ended in
// std::bad_alloc).
TEST_F(Hostile, ScanBeyondTheMemoryLimitIsRefusedNamingBothAmounts) {
  if (kSanitizerBuild)
    GTEST_SKIP() << "a sanitizer build reserves terabytes of address space for its shadow memory at start, which "
                    "ulimit -v refuses; the uninstrumented build runs this case";
  {
    std::ofstream f(p("big.bin"), std::ios::binary);
  }
  fs::resize_file(p("big.bin"), 9'900'000ull * 16);  // 158 MB, sparse
  // An address-space limit of 600 MB: the process's own mappings at start
  // (~60 MB) leave less than the 9.9 M points x 80 bytes (755 MiB) the fog
  // needs.
  const CliRun r = sh("ulimit -v 600000; brume lidar fog --points " + p("big.bin") + " --visibility 50 --out " +
                      p("o.bin"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_FALSE(has(r, "bad_alloc")) << r.output;
  EXPECT_TRUE(has(r, "needs about")) << r.output;
  EXPECT_TRUE(has(r, "may use only")) << r.output;
  EXPECT_FALSE(fs::exists(p("o.bin")));
}

// Defect 4 and 5. The soft curve of a scan with one point at 1e6 m grew
// without bound, at 1e8 m ended in bad_alloc, at 1e20 m wrote "0,0" with exit
// 0; the layered fog wrote a NaN intensity for a point at 3e38 m; depth
// convert dropped NaN points that lidar fog refuses. One validation of a
// scan, whichever command reads it; tables bounded (a pulse of 1e-6 ns).
TEST_F(Hostile, ScansAreValidatedAndTablesBounded) {
  const std::string calib = p("calib.txt");
  std::ofstream(calib) << kKittiCalib;
  for (const double far : {1e6, 1e8, 1e20, 3e38}) {
    write_scan("far.bin", {10.0f, 1.0f, 0.0f, 0.5f, static_cast<float>(far), static_cast<float>(far), 0.0f, 0.0f});
    for (const std::string& cmd :
         {"lidar fog --points " + p("far.bin") + " --visibility 50 --out " + p("o.bin") + " --soft-curve " +
              p("c.csv"),
          "lidar fog --points " + p("far.bin") + " --profile exponential --density 0.05 --sensor-height 1.7 --out " +
              p("o.bin"),
          "depth convert --velodyne " + p("far.bin") + " --kitti-calib " + calib +
              " --width 1242 --height 375 --out " + p("o.exr")}) {
      const CliRun r = sh("brume " + cmd, 60);
      EXPECT_EQ(r.status, 2) << far << ": " << cmd << ": " << r.output;
      EXPECT_TRUE(has(r, "point 1 lies")) << r.output;
      EXPECT_TRUE(has(r, "up to 10000 m")) << r.output;
    }
  }
  write_scan("nan.bin", {10.0f, 1.0f, 0.0f, 0.5f, NAN, 0.0f, 0.0f, 0.5f});
  for (const std::string& cmd : {"lidar fog --points " + p("nan.bin") + " --visibility 50 --out " + p("o.bin"),
                                 "depth convert --velodyne " + p("nan.bin") + " --kitti-calib " + calib +
                                     " --width 1242 --height 375 --out " + p("o.exr")}) {
    const CliRun r = run(cmd);
    EXPECT_EQ(r.status, 2) << cmd << ": " << r.output;
    EXPECT_TRUE(has(r, "point 1 has a non-finite x")) << r.output;
  }
  write_scan("near.bin", {10.0f, 1.0f, 0.0f, 0.5f});
  const CliRun r = run("lidar fog --points " + p("near.bin") + " --visibility 50 --tau-h 1e-6 --out " + p("o.bin"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "--tau-h 1e-06 ns")) << r.output;
  EXPECT_FALSE(fs::exists(p("o.bin")) || fs::exists(p("c.csv")) || fs::exists(p("o.exr")));
  // A scan within the limits still runs, and its soft curve ends at its farthest point.
  write_scan("ok.bin", {10.0f, 1.0f, 0.0f, 0.5f, 80.0f, 0.0f, 0.0f, 0.2f});
  const CliRun ok =
      run("lidar fog --points " + p("ok.bin") + " --visibility 50 --out " + p("o.bin") + " --soft-curve " + p("c.csv"));
  EXPECT_EQ(ok.status, 0) << ok.output;
}

// KITTI odometry's calib.txt (P0-P3 and Tr:, the velodyne into camera 0's rectified frame) reads
// as the object benchmark's R0_rect and Tr_velo_to_cam with R0_rect = I: the object file's
// calibration rewritten in that form (Tr = R0_rect Tr_velo_to_cam, composed here in double and
// printed to 17 digits) projects a scan onto the same pixels at the same range (1e-6 relative:
// the two products round differently in the last bits); Tr: beside Tr_velo_to_cam: is a repeat.
TEST_F(Hostile, KittiOdometryCalibReadsAsTheObjectForm) {
  std::istringstream in(kKittiCalib);
  std::string line, p2;
  double r0[9], tr[12];
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "P2:") p2 = line;
    if (key == "R0_rect:")
      for (double& v : r0) ls >> v;
    if (key == "Tr_velo_to_cam:")
      for (double& v : tr) ls >> v;
  }
  std::ostringstream odo;
  odo.precision(17);
  odo << "P0: 707.0493 0 604.0814 0 0 707.0493 180.5066 0 0 0 1 0\n" << p2 << "\nTr:";
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) {
      double v = 0.0;
      for (int k = 0; k < 3; ++k) v += r0[3 * i + k] * tr[4 * k + j];
      odo << ' ' << v;
    }
  odo << '\n';
  std::ofstream(p("odo.txt")) << odo.str();
  std::ofstream(p("obj.txt")) << kKittiCalib;
  std::vector<float> pts;
  for (int k = 0; k < 400; ++k)  // ahead of the camera (x forward), across the view
    pts.insert(pts.end(), {5.0f + 0.2f * static_cast<float>(k % 50), -6.0f + 0.03f * static_cast<float>(k),
                           -1.5f + 0.004f * static_cast<float>(k), 0.3f});
  write_scan("s.bin", pts);
  const KittiCalib co = read_kitti_calib(p("odo.txt")), cb = read_kitti_calib(p("obj.txt"));
  for (int i = 0; i < 9; ++i) EXPECT_EQ(co.R0[i], i % 4 == 0 ? 1.0 : 0.0);
  const LidarImage a = project_velodyne(p("s.bin"), co, 1242, 375), b = project_velodyne(p("s.bin"), cb, 1242, 375);
  ASSERT_GT(b.pixels_hit, 300u);
  EXPECT_EQ(a.pixels_hit, b.pixels_hit);
  for (std::size_t i = 0; i < b.range.data.size(); ++i) {
    const float x = a.range.data[i], y = b.range.data[i];
    ASSERT_EQ(std::isnan(x), std::isnan(y)) << "pixel " << i;
    if (!std::isnan(y)) {
      ASSERT_NEAR(x, y, 1e-6 * y) << "pixel " << i;
    }
  }
  std::ofstream(p("both.txt")) << kKittiCalib << "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n";
  EXPECT_NE(error_of([&] { read_kitti_calib(p("both.txt")); }).find("repeats 'Tr_velo_to_cam:'"), std::string::npos);
}

// Defect 5. depth convert --velodyne accepted a singular R0_rect, an all-zero
// Tr_velo_to_cam and fx = 0 (a 100 % unknown map, exit 0) where the layered
// fog refused them, and a repeated P2: silently won. One reader checks every
// calibration wherever it is read.
TEST_F(Hostile, CalibrationsAreCheckedByTheOneReader) {
  write_scan("s.bin", {10.0f, 1.0f, 0.0f, 0.5f});
  const std::string base = kKittiCalib;
  auto line_of = [&](const std::string& key) {
    const std::size_t a = base.find(key), b = base.find('\n', a);
    return base.substr(a, b - a + 1);
  };
  const std::map<std::string, std::pair<std::string, std::string>> bad = {
      {"singular R0_rect", {line_of("R0_rect:"), "R0_rect: 0 0 0 0 0 0 0 0 0\n"}},
      {"zero Tr", {line_of("Tr_velo_to_cam:"), "Tr_velo_to_cam: 0 0 0 0 0 0 0 0 0 0 0 0\n"}},
      {"fx 0", {line_of("P2:"), "P2: 0 0 604.0814 45.75831 0 707.0493 180.5066 -0.3454157 0 0 1 0.004981016\n"}},
      {"repeated P2", {line_of("P2:"), line_of("P2:") + line_of("P2:")}},
  };
  const std::map<std::string, std::string> want = {{"singular R0_rect", "R0_rect (line 3) is not a rotation"},
                                                   {"zero Tr", "Tr_velo_to_cam (line 4) is not a rotation"},
                                                   {"fx 0", "P2's focal lengths (fx 0"},
                                                   {"repeated P2", "'P2:' on line 3 repeats the key of line 2"}};
  for (const auto& [name, edit] : bad) {
    std::string text = base;
    text.replace(text.find(edit.first), edit.first.size(), edit.second);
    std::ofstream(p("c.txt")) << text;
    for (const std::string& cmd :
         {"depth convert --velodyne " + p("s.bin") + " --kitti-calib " + p("c.txt") + " --width 1242 --height 375 --out " +
              p("o.exr"),
          "lidar fog --points " + p("s.bin") + " --profile exponential --kitti-calib " + p("c.txt") +
              " --camera-height 1.65 --out " + p("o.bin")}) {
      const CliRun r = run(cmd);
      EXPECT_EQ(r.status, 2) << name << ": " << cmd << ": " << r.output;
      EXPECT_TRUE(has(r, want.at(name))) << name << ": " << r.output;
      EXPECT_TRUE(has(r, "--kitti-calib '" + p("c.txt") + "'")) << r.output;
    }
  }
  // calib.txt too: a repeated key is refused.
  std::ofstream(p("calib.txt")) << "cam0=[700 0 300; 0 700 200; 0 0 1]\nbaseline=100\nbaseline=200\n";
  const CliRun r = run("depth convert --disparity " + range + " --calib " + p("calib.txt") + " --out " + p("o.exr"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "'baseline=' on line 3 repeats line 2")) << r.output;
  EXPECT_FALSE(fs::exists(p("o.exr")) || fs::exists(p("o.bin")));
}

// Defect 5. A swapped stereo pair "52.9 % filled", exit 0, no warning: now
// refused, exit 2, unless --stereo-allow-swapped says the order is meant.
TEST_F(Hostile, SwappedStereoPairIsRefused) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/im0.png");
  const std::string d = data_path("eth3d_two_view/terrace/");
  const std::string swapped = "depth stereo --left " + d + "im1.png --right " + d + "im0.png --calib " + d +
                              "calib.txt --out " + p("d.pfm");
  CliRun r = run(swapped);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(has(r, "look swapped")) << r.output;
  EXPECT_TRUE(has(r, "--stereo-allow-swapped")) << r.output;
  EXPECT_FALSE(fs::exists(p("d.pfm")));
  r = run(swapped + " --stereo-allow-swapped");
  EXPECT_EQ(r.status, 0) << r.output;
  r = run("depth stereo --left " + d + "im0.png --right " + d + "im1.png --calib " + d + "calib.txt --out " +
          p("d2.pfm"));
  EXPECT_EQ(r.status, 0) << r.output;
}

// Defect 5. Completing ranges of 3e38 or 1e-30 gave inf or nonsense silently.
TEST_F(Hostile, CompletionOfImplausibleRangesIsRefused) {
  // Stored values >= 1e9 are a renderer's "no surface" (unknown) unless
  // --renderer-background off (issue #50): 3e38 is a measurement only then;
  // 5e8 m is one under either rule.
  for (const auto& [v, flags] : {std::pair<float, const char*>{3e38f, " --renderer-background off"},
                                 {5e8f, ""}, {1e-30f, ""}}) {
    Image r(160, 112, 1, NAN);
    for (int x = 0; x < 160; x += 3) r.at(x, 80) = 10.0f;
    r.at(7, 80) = v;
    WriteOptions data;
    data.is_color = false;
    data.float_reason = "metres";
    write_image(p("sparse.exr"), r, data);
    const CliRun c =
        run("depth complete --image " + img + " --range " + p("sparse.exr") + flags + " --out " + p("o.exr"));
    EXPECT_EQ(c.status, 2) << v << ": " << c.output;
    EXPECT_TRUE(has(c, "at pixel (7, 80)")) << c.output;
    EXPECT_TRUE(has(c, "--unknown-value")) << c.output;
    EXPECT_FALSE(fs::exists(p("o.exr")));
  }
}

// Defect 6. Delete inputs.image.sha256 (or the inputs block) and `brume run`
// ran a replaced input, exit 0, no word. Now refused naming the input, or
// run with a warning when --rehash asks.
TEST_F(Hostile, RecordWithoutItsInputsHashIsRefused) {
  const nlohmann::json rec = haze_record();
  nlohmann::json no_hash = rec, no_inputs = rec;
  no_hash["inputs"]["image"].erase("sha256");
  no_inputs.erase("inputs");
  for (nlohmann::json* r : {&no_hash, &no_inputs}) (*r)["job"]["output"]["out"] = p("again.png");
  save(no_hash, "no_hash.json");
  save(no_inputs, "no_inputs.json");
  for (const char* f : {"no_hash.json", "no_inputs.json"}) {
    const CliRun r = run("run " + p(f));
    EXPECT_EQ(r.status, 2) << f << ": " << r.output;
    EXPECT_TRUE(has(r, "--image '" + img + "' but the record holds no SHA-256")) << r.output;
    EXPECT_TRUE(has(r, "--rehash")) << r.output;
    EXPECT_FALSE(fs::exists(p("again.png")));
  }
  const CliRun r = run("run " + p("no_hash.json") + " --rehash");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(has(r, "warning: the record holds no SHA-256 for --image")) << r.output;
  expect_same_pixels(p("h.png"), p("again.png"));
  // A replaced input whose hash is there is refused as before.
  write_image(img, Image(160, 112, 3, 0.5f), WriteOptions{});
  const CliRun changed = run("run " + p("h.json") + " --out-dir " + p("x"));
  EXPECT_EQ(changed.status, 2) << changed.output;
  EXPECT_TRUE(has(changed, "has changed since the record was made")) << changed.output;
}

// Every input a command's job names is declared reads_file, and a record of
// a run on files hashes each (or brume run would refuse its own records):
// the demo runs of scripts/compare-builds.sh repeat.
TEST_F(Hostile, RecordsOfRunsOnFilesRepeat) {
  const std::string io = " --image " + img + " --range " + range;
  std::ofstream(p("table.csv")) << "height_m,density_per_m\n0,0.02\n50,0.001\n";
  for (const std::string& cmd :
       {"haze" + io + " --visibility 800 --out " + p("a.png") + " --record " + p("a.json"),
        "fog" + io + " --profile table --table " + p("table.csv") + " --camera-height 1.6 --fov-y 55 --lambda 2 --out " +
            p("b.png") + " --record " + p("b.json"),
        "aerial" + io + " --turbidity 4 --lambda 2 --out " + p("c.png") + " --record " + p("c.json"),
        "blur --image " + img + " --sigma 3 --out " + p("d.png") + " --record " + p("d.json"),
        "depth convert --range " + range + " --out " + p("e.exr") + " --record " + p("e.json")}) {
    CliRun r = run(cmd);
    ASSERT_EQ(r.status, 0) << cmd << ": " << r.output;
    const std::string rec = cmd.substr(cmd.rfind(' ') + 1);
    r = run("run " + rec + " --out-dir " + p("again"));
    EXPECT_EQ(r.status, 0) << cmd << ": " << r.output;
    EXPECT_FALSE(has(r, "warning")) << r.output;
  }
  // Every text parameter of every command that names an input is declared so.
  // (Text that names no file: a channel's name, a layer's name in a file
  // with layers -- image-layer, a-layer, object-layer --, a compression, a
  // date, a vector's components -- rain's wind X,Y,Z --; a nested block's flag keeps its name
  // after a prefix, "sky-date".)
  auto names_no_file = [](const std::string& n) {
    for (const std::string x : {"depth-channel", "object-range-channel", "compression", "date", "layer", "wind"})
      if (n == x || (n.size() > x.size() && n.compare(n.size() - x.size() - 1, std::string::npos, "-" + x) == 0))
        return true;
    return false;
  };
  for (const CommandDef& c : commands()) {
    if (!c.writes_record) continue;
    for (const ParamSpec& s : c.specs) {
      if (s.kind != ParamKind::text || s.output_file || s.input_file) continue;
      EXPECT_TRUE(names_no_file(s.name)) << c.name << " --" << s.name
                                         << " is text but neither reads_file nor writes_file";
    }
  }
}
