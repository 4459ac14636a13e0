// A camera frame and its LiDAR scan from one medium (brume/lidar_camera.hpp,
// issue #41 item 4): the camera effects' --lidar/--lidar-out. The foggy scan
// must be `brume lidar fog`'s with the same flags and alpha = the camera's
// extinction, to the bit; the one record must show that alpha beside the
// camera's own extinction, equal numbers; `brume run` must repeat both
// outputs; batch names the scan beside the image; bad inputs write nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "brume/aerial.hpp"
#include "brume/batch.hpp"
#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/lidar_camera.hpp"
#include "brume/depth.hpp"  // kitti_bin_bytes
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace lidar_camera_tests {

const char* kKittiDir = "kitti_object_000001";

std::string bytes_of(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Points on random beams at 1.5 to 60 m, reflectance in [0, 1]: near
// enough that visibility 80 m turns some into fog.
std::vector<float> synthetic_scan(std::size_t n, unsigned seed) {
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<float> v(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double az = 2 * M_PI * u(g), el = (u(g) - 0.7) * 0.4, r = 1.5 + 58.5 * u(g);
    v[4 * i] = static_cast<float>(r * std::cos(el) * std::cos(az));
    v[4 * i + 1] = static_cast<float>(r * std::cos(el) * std::sin(az));
    v[4 * i + 2] = static_cast<float>(r * std::sin(el));
    v[4 * i + 3] = static_cast<float>(u(g));
  }
  return v;
}

class LidarCamera : public ScratchDirTest {
 protected:
  std::string img, range, scan;
  void SetUp() override {
    Image rgb(48, 32, 3), r(48, 32, 1);
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 48; ++x) {
        for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = ((x / 4 + y / 4 + c) % 2) ? 0.8f : 0.1f;
        r.at(x, y) = y < 6 ? NAN : 2.0f + 2.0f * (32 - y);
      }
    img = p("img.png");
    range = p("range.exr");
    write_image(img, rgb, WriteOptions{});
    WriteOptions data;
    data.is_color = false;
    write_image(range, r, data);
    const std::vector<float> pts = synthetic_scan(4000, 3);
    scan = p("scan.bin");
    std::ofstream(scan, std::ios::binary) << kitti_bin_bytes(pts.data(), pts.size() / 4);
  }
  // The camera run with its scan, `brume lidar fog` with the same flags, the
  // record checked against both, and `brume run` repeating both outputs.
  void camera_and_lidar_agree(const std::string& frame, const std::string& points, const std::string& cam,
                              const std::string& lidar_flags, const std::string& lidar_fog_flags) {
    fs::create_directories(p("first"));
    const CliRun r = run(cam + " " + frame + " --lidar " + points + " --lidar-out " + p("first/s.bin") + " " +
                         lidar_flags + " --out " + p("first/o.png") + " --record " + p("first/o.json"));
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_NE(r.output.find("and its scan"), std::string::npos) << r.output;
    const nlohmann::json rec = read_json(p("first/o.json"));
    // One record: alpha is the camera's extinction, the same double.
    const double alpha = rec["lidar"]["alpha_per_m"].get<double>();
    EXPECT_EQ(alpha, rec["haze"]["derived"]["extinction_per_m"].get<double>());
    EXPECT_EQ(alpha, rec["lidar"]["parameters"]["lidar"]["alpha"].get<double>());
    EXPECT_EQ(rec["inputs"]["lidar"]["sha256"], sha256_file(points));
    EXPECT_EQ(rec["job"]["lidar"]["lidar"], points);
    // The same scan as brume lidar fog's with the same flags.
    const CliRun l = run("lidar fog --points " + points + " " + lidar_fog_flags + " --out " + p("l.bin"));
    ASSERT_EQ(l.status, 0) << l.output;
    const std::string foggy = bytes_of(p("first/s.bin"));
    EXPECT_EQ(foggy.size(), fs::file_size(points));
    EXPECT_TRUE(foggy == bytes_of(p("l.bin")));
    EXPECT_FALSE(foggy == bytes_of(points));  // the fog changed it
    // brume run repeats both outputs.
    const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
    ASSERT_EQ(again.status, 0) << again.output;
    EXPECT_TRUE(foggy == bytes_of(p("again/s.bin")));
    expect_same_pixels(p("first/o.png"), p("again/o.png"));
    nlohmann::json a = read_json(p("again/o.json"))["lidar"], b = rec["lidar"];
    for (const char* t : {"points_ms", "table_ms"}) a.erase(t), b.erase(t);  // timings
    EXPECT_EQ(a, b);
  }
};

// Haze at visibility 80 m: alpha = 3.912/80 (Koschmieder), in the record
// twice (haze's derived extinction and the lidar block), equal.
TEST_F(LidarCamera, HazeOnASyntheticFrameAndScan) {
  camera_and_lidar_agree("--image " + img + " --range " + range, scan, "haze --visibility 80",
                         "--lidar-seed 4 --lidar-p0 60", "--visibility 80 --seed 4 --p0 60");
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["lidar"]["alpha_per_m"].get<double>(), 3.912 / 80.0);
  EXPECT_EQ(rec["lidar"]["seed"], 4);
  EXPECT_EQ(rec["job"]["lidar"]["lidar-p0"], 60.0);
  EXPECT_GT(rec["lidar"]["soft_points"].get<int>(), 0);
}

TEST_F(LidarCamera, HazeOnTheKittiFrame) {
  BRUME_REQUIRE_DATA(kKittiDir);
  const std::string k = data_path(kKittiDir);
  const std::string velo = k + "/velodyne/000001.bin";
  camera_and_lidar_agree("--image " + k + "/image_2/000001.png --velodyne " + velo + " --kitti-calib " + k +
                             "/calib/000001.txt",
                         velo, "haze --visibility 80", "--lidar-noise off", "--visibility 80 --noise off");
}

// Fog with a height profile on the KITTI frame: the scan in the same layered
// fog (brume lidar fog --profile with the same density fields, calibration and
// camera pose) to the bit; no one alpha in the record, the profile instead;
// brume run repeats both, and refuses once the calibration file changed (it
// places the scan and projects the depth: an input, by SHA-256). Without
// --kitti-calib the scan has no pose: refused.
TEST_F(LidarCamera, LayeredFogOnTheKittiFrame) {
  BRUME_REQUIRE_DATA(kKittiDir);
  const std::string k = data_path(kKittiDir), velo = k + "/velodyne/000001.bin", calib = p("calib.txt");
  fs::copy_file(k + "/calib/000001.txt", calib);  // a copy in the test's folder, changed below
  const std::string fog = " --profile exponential --density 0.08 --falloff 0.3 --camera-height 1.65 --pitch 1";
  fs::create_directories(p("first"));
  const CliRun r = run("fog --image " + k + "/image_2/000001.png --velodyne " + velo + " --kitti-calib " + calib + fog +
                       " --lidar " + velo + " --lidar-out " + p("first/s.bin") + " --lidar-seed 2 --out " +
                       p("first/o.png") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_TRUE(rec["lidar"]["alpha_per_m"].is_null());
  EXPECT_EQ(rec["lidar"]["profile"], "exponential");
  EXPECT_GT(rec["lidar"]["soft_points"].get<int>(), 0);
  const CliRun l = run("lidar fog --points " + velo + " --kitti-calib " + calib + fog + " --seed 2 --out " + p("l.bin"));
  ASSERT_EQ(l.status, 0) << l.output;
  const std::string foggy = bytes_of(p("first/s.bin"));
  EXPECT_TRUE(foggy == bytes_of(p("l.bin")));
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  EXPECT_TRUE(foggy == bytes_of(p("again/s.bin")));
  expect_same_pixels(p("first/o.png"), p("again/o.png"));
  EXPECT_EQ(rec["inputs"]["kitti_calib"]["path"], calib);
  EXPECT_EQ(rec["inputs"]["depth"]["kitti_calib"]["path"], calib);
  std::ofstream(calib, std::ios::app) << "\n";
  const CliRun changed = run("run " + p("first/o.json") + " --out-dir " + p("changed"));
  EXPECT_EQ(changed.status, 2) << changed.output;
  EXPECT_NE(changed.output.find("calib.txt' has changed"), std::string::npos) << changed.output;
}

TEST_F(LidarCamera, LayeredFogNeedsTheScansPose) {
  const CliRun r = run("fog --image " + img + " --range " + range + " --profile exponential --camera-height 1.6 "
                       "--fov-y 40 --lidar " + scan + " --lidar-out " + p("s.bin") + " --out " + p("o.png"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--kitti-calib"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("s.bin")) || fs::exists(p("o.png")));
}

// The other media: fog's constant profile (alpha = its density), the chain
// (haze's), aerial at 905 nm (Rayleigh + Mie written out here, double).
TEST_F(LidarCamera, FogChainAndAerialGiveTheirExtinction) {
  const std::string frame = " --image " + img + " --range " + range + " --lidar " + scan + " --out " + p("o.png") +
                            " --record " + p("o.json");
  CliRun r = run("fog --profile constant --density 0.03" + frame + " --lidar-out " + p("f.bin"));
  ASSERT_EQ(r.status, 0) << r.output;
  nlohmann::json rec = read_json(p("o.json"));
  EXPECT_EQ(rec["lidar"]["alpha_per_m"].get<double>(), rec["job"]["fog"]["density"].get<double>());
  r = run("haze --visibility 120 --dof-focus-distance 10 --dof-focal-length 50 --dof-f-number 2 --dof-sensor-width 36" + frame +
          " --lidar-out " + p("c.bin"));
  ASSERT_EQ(r.status, 0) << r.output;
  rec = read_json(p("o.json"));
  EXPECT_EQ(rec["command"], "haze+dof");
  EXPECT_EQ(rec["lidar"]["alpha_per_m"].get<double>(), rec["haze"]["derived"]["extinction_per_m"].get<double>());
  // Aerial: beta_R = 8 pi^3 (n^2 - 1)^2 / (3 N lambda^4) (6 + 3 p_n)/(6 - 7 p_n) K_R e^{-h/H_R},
  // beta_M = 0.434 c(T) pi (2 pi/lambda)^2 K_M e^{-h/H_M} (Preetham/Morales, the
  // aerial header's constants), times --distance-scale. Tolerance 1e-13
  // relative: the same formula, evaluated in another order.
  r = run("aerial --turbidity 6 --altitude 300 --distance-scale 2" + frame + " --lidar-out " + p("a.bin"));
  ASSERT_EQ(r.status, 0) << r.output;
  rec = read_json(p("o.json"));
  const double l = 905e-9, n2 = 1.0003 * 1.0003 - 1.0, pn = 0.035;
  const double br = 8 * M_PI * M_PI * M_PI * n2 * n2 / (3 * 2.545e25 * l * l * l * l) * (6 + 3 * pn) / (6 - 7 * pn) *
                    1.0396 * std::exp(-300.0 / 7994.0);
  const double bm = 0.434 * (0.65 * 6 - 0.65) * 1e-16 * M_PI * std::pow(2 * M_PI / l, 2.0) * 0.0092 *
                    std::exp(-300.0 / 1200.0);
  EXPECT_NEAR(rec["lidar"]["alpha_per_m"].get<double>(), 2 * (br + bm), 1e-13 * 2 * (br + bm));
  EXPECT_EQ(rec["lidar"]["wavelength_nm"], 905.0);
  // At 905 nm the air is clearer than at 550 nm (lambda^-4 and lambda^-2).
  EXPECT_LT(br + bm, rayleigh_beta_per_m(550, 300) + mie_beta_per_m(550, 6, 300));
  r = run("aerial --turbidity 6" + frame + " --lidar-out " + p("a2.bin") + " --lidar-wavelength 1550");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(read_json(p("o.json"))["lidar"]["wavelength_nm"], 1550.0);
}

// Every bad combination: an error naming the flag, exit non-zero, nothing
// written -- not the image, the record or the scan (also when the camera
// fails after the scan was fogged: the outputs go together or not at all).
TEST_F(LidarCamera, BadInputsWriteNothing) {
  std::ofstream(p("odd.bin"), std::ios::binary) << std::string(40, '\0');
  const std::string in = " --image " + img + " --range " + range;
  const std::string outs = " --out " + p("o.png") + " --record " + p("o.json");
  const std::string both = " --lidar " + scan + " --lidar-out " + p("s.bin");
  struct Case {
    std::string args, says;
  };
  for (const Case& c : {
           Case{"haze --visibility 80" + in + " --lidar-out " + p("s.bin"), "--lidar-out '"},
           Case{"haze --visibility 80" + in + " --lidar " + scan, "without --lidar-out"},
           Case{"haze --visibility 80" + in + " --lidar " + scan + " --lidar-out " + p("s.png"), "*.bin"},
           Case{"haze --kappa-s 0.5" + in + both, "metres"},
           Case{"haze --visibility 80" + in + " --lidar-seed 3", "no --lidar is given"},
           Case{"haze --visibility 80" + in + both + " --lidar-r2 0.5", "--lidar-r2"},
           Case{"haze --visibility 80" + in + both + " --lidar-wavelength 1550", "grey"},
           Case{"haze --visibility 80" + in + " --lidar " + p("odd.bin") + " --lidar-out " + p("s.bin"), "16 bytes"},
           Case{"haze --visibility 80 --image " + p("nope.png") + " --range " + range + both, "nope.png"},
           Case{"fog" + in + both, "varies with height"},
           Case{"fog --classic linear" + in + both, "metres"},
           Case{"aerial --remove" + in + both, "--remove"},
           Case{"dof --focus-distance 5 --focal-length 50 --f-number 2" + in + both, "does not fog a LiDAR scan"},
       }) {
    SCOPED_TRACE(c.args);
    const CliRun r = run(c.args + outs);
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find(c.says), std::string::npos) << r.output;
    for (const char* f : {"o.png", "o.json", "s.bin", "s.png"}) EXPECT_FALSE(fs::exists(p(f))) << f;
  }
}

// The one function that turns a camera job into the scan's alpha (where the
// layered model will enter): its answers and refusals.
TEST(LidarCameraMedium, FromEachCommandsJob) {
  const CommandDef* haze = find_command("haze");
  const CommandDef* fog = find_command("fog");
  ASSERT_TRUE(haze && fog);
  EXPECT_EQ(camera_lidar_medium(*haze, haze->build({{"visibility", 250.0}}), 905).alpha_per_m, 3.912 / 250);
  EXPECT_EQ(camera_lidar_medium(*haze, haze->build({{"kappa-a", 0.1}, {"kappa-s", 0.3}, {"range-max", 200.0}}), 905)
                .alpha_per_m,
            (0.1 + 0.3) / 200.0);
  EXPECT_NE(error_of([&] { camera_lidar_medium(*haze, haze->defaults, 905); }).find("metres"), std::string::npos);
  EXPECT_EQ(camera_lidar_medium(*fog, fog->build({{"profile", "constant"}, {"density", 0.01}}), 905).alpha_per_m,
            0.01);
  // a height profile has no one alpha: the model integrates it along each beam
  EXPECT_TRUE(std::isnan(camera_lidar_medium(*fog, fog->defaults, 905).alpha_per_m));
  // Every command with the lidar block has a medium hook; those without have no block.
  for (const CommandDef& c : commands()) {
    SCOPED_TRACE(c.name);
    if (c.spec("lidar-out")) {
      EXPECT_TRUE(c.extinction_per_m || c.spectral_extinction_per_m);
      EXPECT_TRUE(is_output_file(*c.spec("lidar-out")));
      EXPECT_EQ(c.spec("lidar-out")->output_of, "lidar");
    }
  }
  for (const char* n : {"dof", "blur", "insert", "lidar fog"}) EXPECT_FALSE(find_command(n)->spec("lidar-out")) << n;
}

// brume batch: a 'lidar' column fogs each frame's scan, written as
// <key>.bin beside the image; the record is the frame's one record.
TEST_F(LidarCamera, BatchWritesTheScanBesideTheImage) {
  std::ofstream(p("m.csv")) << "key,image,range,lidar\nframe.png," << img << "," << range << "," << scan
                            << "\nnoscan.png," << img << "," << range << ",\n";
  const CliRun r = run("batch --manifest " + p("m.csv") + " --out-dir " + p("out") +
                       " --effect haze --param visibility=80 --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  ASSERT_TRUE(fs::exists(p("out/frame.bin")));
  EXPECT_FALSE(fs::exists(p("out/noscan.bin")));
  const CliRun l = run("lidar fog --points " + scan + " --visibility 80 --out " + p("l.bin"));
  ASSERT_EQ(l.status, 0) << l.output;
  EXPECT_TRUE(bytes_of(p("out/frame.bin")) == bytes_of(p("l.bin")));
  const nlohmann::json rec = read_json(p("out/frame.json"));
  EXPECT_EQ(rec["lidar"]["alpha_per_m"].get<double>(), rec["haze"]["derived"]["extinction_per_m"].get<double>());
  EXPECT_FALSE(read_json(p("out/noscan.json")).contains("lidar"));
  // A LiDAR setting for a row without a scan is a manifest error (it would be ignored).
  const CliRun noscan = run("batch --manifest " + p("m.csv") + " --out-dir " + p("out2") +
                            " --effect haze --param visibility=80 --param lidar-seed=2 --quiet");
  EXPECT_NE(noscan.status, 0);
  EXPECT_NE(noscan.output.find("line 3: --lidar-seed"), std::string::npos) << noscan.output;
  EXPECT_FALSE(fs::exists(p("out2/frame.bin")));
  // The scan is an output: a column may not name it.
  std::ofstream(p("bad.csv")) << "image,range,lidar,lidar-out\n" << img << "," << range << "," << scan << ",x.bin\n";
  const CliRun bad = run("batch --manifest " + p("bad.csv") + " --out-dir " + p("bad") + " --effect haze --quiet");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("is an output"), std::string::npos) << bad.output;
}

TEST(LidarCameraScan, KittiLayoutFillsTheLidarColumn) {
  DatasetOptions o;
  o.dir = ".";
  o.layout = "middlebury";
  o.lidar = true;
  EXPECT_NE(error_of([&] { dataset_manifest(o); }).find("--layout kitti"), std::string::npos);
  BRUME_REQUIRE_DATA(kKittiDir);
  o.dir = data_path(kKittiDir);
  o.layout = "kitti";
  const std::vector<nlohmann::json> rows = dataset_manifest(o);
  ASSERT_FALSE(rows.empty());
  for (const auto& row : rows) EXPECT_EQ(row["lidar"], row["velodyne"]);
  o.lidar = false;
  EXPECT_FALSE(dataset_manifest(o).front().contains("lidar"));
}

}  // namespace lidar_camera_tests
