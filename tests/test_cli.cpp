// The command-line tool end to end: a real run with every auxiliary output and
// the parameter record, the demo, and the error paths (clear message naming
// the file or flag, non-zero exit, no output left behind).
#include <OpenImageIO/imageio.h>
#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <nlohmann/json.hpp>

#include "brume/io.hpp"
#include "brume/pipeline.hpp"  // kRecordSchemaVersion
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

// Every channel of an image file, as stored (colour files decoded to linear RGB).
Image read_scalar_or_color(const std::string& path) {
  const std::string n = fs::path(path).filename().string();
  return n == "t.exr" || n == "z.exr" ? read_scalar(path) : read_color(path);
}

class Cli : public ScratchDirTest {
 protected:
  std::string img, range, range16;
  void SetUp() override {
    Image rgb(48, 32, 3), r(48, 32, 1);
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 48; ++x) {
        for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = ((x / 4 + y / 4 + c) % 2) ? 0.8f : 0.1f;
        r.at(x, y) = y < 6 ? NAN : 2.0f + 0.5f * (32 - y);
      }
    img = (dir / "img.png").string();
    range = (dir / "range.exr").string();
    write_image(img, rgb, WriteOptions{});
    WriteOptions data;
    data.is_color = false;
    write_image(range, r, data);
    // The same range in millimetres as 16-bit counts.
    Image mm = r;
    for (float& v : mm.data) v = std::isfinite(v) ? v * 1000.0f / 65535.0f : 0.0f;
    range16 = (dir / "range_mm.png").string();
    write_image(range16, mm, data);
  }
  bool only_inputs_left() const {
    for (auto& e : fs::directory_iterator(dir)) {
      std::string n = e.path().filename().string();
      if (n != "img.png" && n != "range.exr" && n != "range_mm.png") return false;
    }
    return true;
  }
};

}  // namespace

TEST_F(Cli, HazeWritesEveryOutputAndARecord) {
  CliRun r = run("haze --image " + img + " --range " + range + " --kappa-s 0.5 --lambda 8 --out " + p("out.png") +
              " --transmission " + p("t.exr") + " --scale-map " + p("s.exr") + " --record " + p("rec.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"out.png", "t.exr", "s.exr", "rec.json"}) EXPECT_TRUE(fs::exists(p(f))) << f;
  std::ifstream js(p("rec.json"));
  nlohmann::json j = nlohmann::json::parse(js);
  EXPECT_EQ(j["tool"], "brume");
  EXPECT_EQ(j["haze"]["diffusion"]["iterations"], 10);  // ceil(ln(1 + 8 sqrt(0.5)) / 0.2), invariant-exact default
  EXPECT_NEAR(j["haze"]["derived"]["sigma_max_px"].get<double>(), 1 + 8 * std::sqrt(0.5), 1e-5);
  EXPECT_NEAR(j["haze"]["derived"]["range_max_m"].get<double>(), 15.0, 1e-6);
  EXPECT_EQ(j["haze"]["derived"]["unknown_range_pixels"], 6 * 48);
  EXPECT_EQ(j["inputs"]["image"]["sha256"].get<std::string>().size(), 64u);
  // The same record is embedded in the PNG.
  auto in = OIIO::ImageInput::open(p("out.png"));
  ASSERT_TRUE(in);
  std::string desc = in->spec().get_string_attribute("ImageDescription");
  EXPECT_NE(desc.find("\"sigma_max_px\""), std::string::npos);
  // Scale map: sigma0 at R = 0 grows to sigma_max at R_max.
  Image s = read_scalar(p("s.exr"));
  const double smax = 1 + 8 * std::sqrt(0.5);
  EXPECT_NEAR(s.at(0, 6), smax, 1e-5);                                   // R = 15 m = R_max
  EXPECT_NEAR(s.at(0, 31), 1 + std::pow(2.5 / 15.0, 1.5) * (smax - 1), 1e-5);  // R = 2.5 m
  EXPECT_NEAR(s.at(0, 0), smax, 1e-5);                                   // unknown -> R_max
}

TEST_F(Cli, IntegerRangeNeedsItsScale) {
  CliRun r = run("haze --image " + img + " --range " + range16 + " --out " + p("o.png"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--range-scale"), std::string::npos) << r.output;
  EXPECT_TRUE(only_inputs_left());
  CliRun ok = run("haze --image " + img + " --range " + range16 + " --range-scale 0.001 --out " + p("o.exr") +
               " --record " + p("r.json"));
  ASSERT_EQ(ok.status, 0) << ok.output;
  std::ifstream js(p("r.json"));
  nlohmann::json j = nlohmann::json::parse(js);
  EXPECT_NEAR(j["haze"]["derived"]["range_max_m"].get<double>(), 15.0, 1e-3);
}

TEST_F(Cli, ErrorPathsAreClearAndLeaveNothing) {
  struct Case {
    std::string args, must_contain;
  };
  const std::string io = " --out " + p("o.png");
  std::ofstream(p("cut.png")) << "\x89PNG\r\n\x1a\n trunc";
  Image small(20, 10, 1, 3.0f);
  WriteOptions data;
  data.is_color = false;
  write_image(p("small.exr"), small, data);
  const Case cases[] = {
      {"haze --image " + p("nope.png") + " --range " + range + io, "nope.png"},
      {"haze --image " + p("cut.png") + " --range " + range + io, "cut.png"},
      {"haze --image " + img + " --range " + p("small.exr") + io, "20x10"},
      {"haze --image " + img + " --range " + p("small.exr") + io, "48x32"},
      {"haze --image " + img + " --range " + range + " --kappa-s -1" + io, "--kappa-s"},
      {"haze --image " + img + " --range " + range + " --lambda nan" + io, "--lambda"},
      {"haze --image " + img + " --range " + range + " --sigma0 0" + io, "--sigma0"},
      {"haze --image " + img + " --range " + range + " --airlight 1,2" + io, "--airlight"},
      {"haze --image " + img + " --range " + range + " --visibility 100 --kappa-s 1" + io, "--visibility"},
      {"haze --image " + img + " --range " + range + " --scheme fast" + io, "--scheme"},
      {"haze --image " + img + " --range " + range + " --out " + p("missing/dir/o.png"), "missing/dir"},
      {"haze --image " + img + " --range " + range + " --out " + p("o.xyz"), "o.xyz"},
      {"haze --image " + img + " --range " + range + " --out " + p("o.jpg") + " --bits 16", "--bits"},
      {"haze --image " + img + " --range " + range + " --out " + p("o.tif") + " --bits half", "8, 16 or float (or write half to .exr)"},
      {"haze --image " + img + " --range " + range + io + " --record " + p("no/r.json"), "--record"},
      {"haze --image " + img + " --range " + range + io + " --compression lzw", "none, zip, zip:0..9"},
      {"haze --image " + img + " --range " + range + " --out " + p("o.exr") + " --compression zip:12", "1..9"},
      {"blur --image " + img + " --sigma 0.5" + io, "below the inner scale"},
      {"blur --image " + img + io, "--sigma"},
  };
  for (const Case& c : cases) {
    CliRun r = run(c.args);
    EXPECT_NE(r.status, 0) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.must_contain), std::string::npos) << c.args << "\n" << r.output;
    for (auto& e : fs::directory_iterator(dir)) {
      std::string n = e.path().filename().string();
      EXPECT_TRUE(n == "img.png" || n == "range.exr" || n == "range_mm.png" || n == "cut.png" || n == "small.exr")
          << c.args << " left " << n;
    }
  }
}

// --timing ends with the whole run's breakdown: its parts are non-negative
// and add up to the whole (each printed rounded: within 1.5 ms).
TEST_F(Cli, TimingPrintsTheWholeRunBreakdown) {
  const CliRun r = run("blur --image " + img + " --sigma 3 --out " + p("b.pfm") + " --timing");
  ASSERT_EQ(r.status, 0) << r.output;
  const std::regex line(
      "brume blur: whole run ([0-9.]+) ms: start-up ([0-9.]+) ms \\(exec to main, 10 ms ticks\\), read ([0-9.]+) ms "
      "\\(decode, depth conversion\\), effect ([0-9.]+) ms, write ([0-9.]+) ms \\(encode to temporaries\\), rename "
      "([0-9.]+) ms, other (-?[0-9.]+) ms");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, line)) << r.output;
  double parts = 0.0;
  for (int i = 2; i <= 7; ++i) {
    const double v = std::stod(m[i].str());
    if (i < 7) {
      EXPECT_GE(v, 0.0) << m[0];
    }
    parts += v;
  }
  EXPECT_NEAR(parts, std::stod(m[1].str()), 1.5) << m[0];  // six parts and the whole, each rounded
  EXPECT_GT(std::stod(m[3].str()), 0.0) << "the image was read: " << m[0];
  EXPECT_GT(std::stod(m[5].str()), 0.0) << "the output was written: " << m[0];
}

// OpenImageIO lives in brume_codec.so, loaded only when a file needs it
// (src/io/codec.hpp): PFM, PNG, JPEG, EXR, HDR and TIFF runs work with no
// module at all, a mixed-type EXR input names the module's load in --timing, and a module that cannot be loaded is
// an error naming every path tried, with nothing written.
TEST_F(Cli, CodecModuleIsLoadedOnlyWhenAFormatNeedsIt) {
  Image rgb(24, 16, 3, 0.5f);
  rgb.at(3, 4, 1) = 2.0f;
  write_image(p("in.pfm"), rgb, WriteOptions{});  // brume's own PFM writer
  write_image(p("in.jpg"), rgb, WriteOptions{});  // the JPEG row
  {
    // An EXR of mixed channel types (R float, G and B half), which the
    // OpenEXR row leaves to OpenImageIO. (A two-part file no longer is: its
    // parts are layers, read through OpenEXR's multi-part API, issue #50.)
    OIIO::ImageSpec spec(24, 16, 3, OIIO::TypeDesc::HALF);
    spec.channelformats.assign(3, OIIO::TypeDesc::HALF);
    spec.channelformats[0] = OIIO::TypeDesc::FLOAT;
    auto out = OIIO::ImageOutput::create(p("mixed.exr"));
    ASSERT_TRUE(out && out->open(p("mixed.exr"), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, rgb.data.data()));
    ASSERT_TRUE(out->close());
  }
  struct EnvGuard {
    explicit EnvGuard(const char* v) { ::setenv("BRUME_CODEC_MODULE", v, 1); }
    ~EnvGuard() { ::unsetenv("BRUME_CODEC_MODULE"); }
  };
  {
    EnvGuard none("/nonexistent/brume_codec.so");
    const CliRun r = run("blur --image " + p("in.pfm") + " --sigma 3 --out " + p("o.pfm") + " --timing");
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_EQ(r.output.find("codec module"), std::string::npos) << r.output;
    EXPECT_EQ(read_color(p("o.pfm")).width, 24);

    // 8/16-bit grey and RGB PNG are read and written without the module
    // (src/io/formats/png.cpp).
    const CliRun png_only = run("blur --image " + img + " --sigma 3 --out " + p("o.png") + " --timing");
    ASSERT_EQ(png_only.status, 0) << png_only.output;
    EXPECT_EQ(png_only.output.find("codec module"), std::string::npos) << png_only.output;
    EXPECT_TRUE(fs::exists(p("o.png")));

    // 8-bit grey and colour JPEG are read without it (src/io/formats/jpeg.cpp).
    const CliRun jpeg_in = run("blur --image " + p("in.jpg") + " --sigma 3 --out " + p("oj.png") + " --timing");
    ASSERT_EQ(jpeg_in.status, 0) << jpeg_in.output;
    EXPECT_EQ(jpeg_in.output.find("codec module"), std::string::npos) << jpeg_in.output;
    EXPECT_TRUE(fs::exists(p("oj.png")));

    // So are single-part OpenEXR of one channel or R G B (A), half or float
    // (src/io/formats/exr.cpp), in and out, at any compression and level.
    write_image(p("in.exr"), rgb, WriteOptions{});
    const CliRun exr_only = run("blur --image " + p("in.exr") + " --sigma 3 --out " + p("o.exr") + " --bits half --timing");
    ASSERT_EQ(exr_only.status, 0) << exr_only.output;
    EXPECT_EQ(exr_only.output.find("codec module"), std::string::npos) << exr_only.output;
    EXPECT_EQ(read_color(p("o.exr")).width, 24);
    const CliRun exr_level = run("blur --image " + p("in.exr") + " --sigma 3 --out " + p("o9.exr") + " --compression zip:9");
    ASSERT_EQ(exr_level.status, 0) << exr_level.output;
    EXPECT_EQ(read_color(p("o9.exr")).width, 24);
    fs::remove(p("o9.exr"));
    // And Radiance HDR of the common form (src/io/formats/hdr.cpp).
    write_image(p("in.hdr"), rgb, WriteOptions{});
    const CliRun hdr_only = run("blur --image " + p("in.hdr") + " --sigma 3 --out " + p("o.hdr") + " --timing");
    ASSERT_EQ(hdr_only.status, 0) << hdr_only.output;
    EXPECT_EQ(hdr_only.output.find("codec module"), std::string::npos) << hdr_only.output;
    EXPECT_EQ(read_color(p("o.hdr")).width, 24);

    // And TIFF of 1 to 4 channels, 8/16-bit or float (src/io/formats/tiff.cpp), in and out.
    write_image(p("in.tif"), rgb, WriteOptions{});
    const CliRun tif_only = run("blur --image " + p("in.tif") + " --sigma 3 --out " + p("o.tif") + " --timing");
    ASSERT_EQ(tif_only.status, 0) << tif_only.output;
    EXPECT_EQ(tif_only.output.find("codec module"), std::string::npos) << tif_only.output;
    EXPECT_EQ(read_color(p("o.tif")).width, 24);

    // And JPEG out (src/io/formats/jpeg.cpp).
    const CliRun jpeg_out = run("blur --image " + img + " --sigma 3 --out " + p("o.jpg") + " --timing");
    ASSERT_EQ(jpeg_out.status, 0) << jpeg_out.output;
    EXPECT_EQ(jpeg_out.output.find("codec module"), std::string::npos) << jpeg_out.output;
    EXPECT_TRUE(fs::exists(p("o.jpg")));

    // A mixed-type EXR is still OpenImageIO's.
    const CliRun bad = run("blur --image " + p("mixed.exr") + " --sigma 3 --out " + p("o9.exr"));
    EXPECT_EQ(bad.status, 2) << bad.output;
    for (const char* want : {"reading '", "mixed.exr", "brume_codec.so", "/nonexistent/brume_codec.so: no such file",
                             "BRUME_CODEC_MODULE"})
      EXPECT_NE(bad.output.find(want), std::string::npos) << want << "\n" << bad.output;
    EXPECT_FALSE(fs::exists(p("o9.exr")));
  }
  for (const char* lib : {"/lib/x86_64-linux-gnu/libz.so.1", "/usr/lib/x86_64-linux-gnu/libz.so.1"}) {
    if (!fs::exists(lib)) continue;
    EnvGuard other(lib);  // a shared object, but not brume's module
    const CliRun bad = run("blur --image " + p("mixed.exr") + " --sigma 3 --out " + p("o9.exr"));
    EXPECT_EQ(bad.status, 2) << bad.output;
    EXPECT_NE(bad.output.find("no brume_codec_api in it"), std::string::npos) << bad.output;
    break;
  }
  const CliRun exr9 = run("blur --image " + p("mixed.exr") + " --sigma 3 --out " + p("o.exr") + " --timing");
  ASSERT_EQ(exr9.status, 0) << exr9.output;
  EXPECT_NE(exr9.output.find("of which loading the OpenImageIO codec module"), std::string::npos) << exr9.output;
  for (auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".brume-tmp-"), std::string::npos) << e.path();
}

TEST_F(Cli, BlurConstantScaleIsAGaussian) {
  // brume blur --sigma S on a float file equals a true Gaussian of
  // sqrt(S^2 - sigma0^2) (same 2e-3 RMS bound as the library test).
  Image rgb(64, 48, 3);
  for (std::size_t i = 0; i < rgb.data.size(); ++i) rgb.data[i] = static_cast<float>((i * 7919) % 1000) / 999.0f;
  write_image(p("in.exr"), rgb, WriteOptions{});
  CliRun r = run("blur --image " + p("in.exr") + " --sigma 4 --out " + p("b.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  Image got = read_color(p("b.exr"));
  Image ref = gaussian_reference(rgb, std::sqrt(15.0));
  EXPECT_LE(compare(got, ref, 16).rms, 2e-3);
}

TEST_F(Cli, DemoWritesItsImages) {
  CliRun r = run("demo --out-dir " + p("demo") + " --width 160 --height 112");
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"clean.png", "range.exr", "range-preview.png", "haze.png", "fog.png", "haze.json", "fog.json"})
    EXPECT_TRUE(fs::exists(p("demo/" + std::string(f)))) << f;
}

TEST_F(Cli, DepthConvertWritesRangeAndZ) {
  // A planar z map of 4 m everywhere with fx = 40 px: range at the corner
  // pixel (0, 0) is 4 sqrt(1 + ((0 - 23.5)/40)^2 + ((0 - 15.5)/40)^2).
  Image z(48, 32, 1, 4.0f);
  WriteOptions data;
  data.is_color = false;
  write_image(p("z.exr"), z, data);
  CliRun r = run("depth convert --z " + p("z.exr") + " --fx 40 --out " + p("r.exr") + " --record " + p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  Image range = read_scalar(p("r.exr"));
  const double a = 23.5 / 40, b = 15.5 / 40;
  EXPECT_NEAR(range.at(0, 0), 4.0 * std::sqrt(1 + a * a + b * b), 1e-5);
  CliRun back = run("depth convert --range " + p("r.exr") + " --fx 40 --kind z --out " + p("z2.pfm"));
  ASSERT_EQ(back.status, 0) << back.output;
  for (float v : read_scalar(p("z2.pfm")).data) ASSERT_NEAR(v, 4.0f, 1e-5);
}

TEST_F(Cli, DepthErrorPathsAreClearAndLeaveNothing) {
  std::ofstream(p("nokeys.txt")) << "cam0=[500 0 10; 0 500 10; 0 0 1]\n";
  std::ofstream(p("badf.txt")) << "cam0=[-5 0 10; 0 -5 10; 0 0 1]\nbaseline=100\n";
  std::ofstream(p("wrongsize.txt")) << "cam0=[500 0 10; 0 500 10; 0 0 1]\nbaseline=100\nwidth=640\nheight=480\n";
  Image d(20, 10, 1, 5.0f);
  WriteOptions data;
  data.is_color = false;
  write_image(p("d.pfm"), d, data);
  write_image(p("buf.exr"), Image(48, 32, 1, 0.5f), data);
  struct Case {
    std::string args, must_contain;
  };
  const std::string out = " --out " + p("o.exr");
  const Case cases[] = {
      {"depth convert --disparity " + p("d.pfm") + " --calib " + p("nokeys.txt") + out, "baseline"},
      {"depth convert --disparity " + p("d.pfm") + " --calib " + p("badf.txt") + out, "focal length"},
      {"depth convert --disparity " + p("d.pfm") + " --calib " + p("wrongsize.txt") + out, "640x480"},
      {"depth convert --disparity " + p("d.pfm") + " --fx 0 --baseline 0.1" + out, "--fx"},
      {"depth convert --depth-buffer " + p("buf.exr") + " --near 5 --far 5 --fov-y 50" + out, "--far"},
      {"depth convert --depth-buffer " + p("buf.exr") + " --near 1 --far 10" + out, "--fov"},
      {"depth convert --depth-buffer " + p("buf.exr") + " --near 1 --far 10 --fov-y 50 --convention gl" + out, "--convention"},
      {"depth convert --z " + p("buf.exr") + out, "--fx"},
      {"depth convert --range " + p("buf.exr") + " --out " + p("o.png"), ".exr"},
      {"depth convert --range " + p("buf.exr") + " --out " + p("o.PNG"), "metres"},  // extension case does not matter
      {"depth prepare --range " + p("buf.exr") + " --out " + p("o.jpg"), "metres"},
      {"depth convert --range " + p("buf.exr") + " --z " + p("buf.exr") + out, "exactly one"},
      {"haze --image " + img + " --disparity " + p("d.pfm") + " --fx 500 --baseline 0.1 --out " + p("h.png"), "20x10"},
  };
  for (const Case& c : cases) {
    CliRun r = run(c.args);
    EXPECT_NE(r.status, 0) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.must_contain), std::string::npos) << c.args << "\n" << r.output;
    for (const char* f : {"o.exr", "o.png", "o.PNG", "o.jpg", "h.png"}) EXPECT_FALSE(fs::exists(p(f))) << c.args;
  }
}

TEST_F(Cli, PrepareFromTheCommandLine) {
  // The fixture's range has its top 6 rows unknown (sky). haze prepares it by
  // default and records what it did; `depth prepare` writes the range and masks.
  CliRun h = run("haze --image " + img + " --range " + range + " --out " + p("h.exr") + " --record " + p("h.json"));
  ASSERT_EQ(h.status, 0) << h.output;
  std::ifstream js(p("h.json"));
  nlohmann::json j = nlohmann::json::parse(js);
  EXPECT_EQ(j["prepare"]["applied"], true);
  EXPECT_NEAR(j["prepare"]["sky_fraction"].get<double>(), 6.0 / 32.0, 1e-9);
  EXPECT_NEAR(j["prepare"]["s_max_m"].get<double>(), 1.25 * 15.0, 1e-4);
  CliRun off = run("haze --image " + img + " --range " + range + " --prepare off --out " + p("o.exr") + " --record " + p("o.json"));
  ASSERT_EQ(off.status, 0) << off.output;
  std::ifstream js2(p("o.json"));
  EXPECT_EQ(nlohmann::json::parse(js2)["prepare"]["applied"], false);
  CliRun bad = run("haze --image " + img + " --range " + range + " --prepare maybe --out " + p("b.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--prepare"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("b.exr")));

  CliRun d = run("depth prepare --range " + range + " --out " + p("prep.exr") + " --masks " + p("masks") +
                 " --sky-margin 3");
  ASSERT_EQ(d.status, 0) << d.output;
  Image prep = read_scalar(p("prep.exr"));
  Image orig = read_scalar(range);
  for (std::size_t i = 0; i < prep.data.size(); ++i) {
    ASSERT_TRUE(std::isfinite(prep.data[i]));
    if (std::isfinite(orig.data[i])) {
      ASSERT_EQ(prep.data[i], orig.data[i]);  // known values untouched
    }
  }
  for (const char* f : {"sky.png", "holes.png", "margin.png", "prepared-preview.png"})
    EXPECT_TRUE(fs::exists(p("masks/" + std::string(f)))) << f;
}

TEST_F(Cli, BackendFlags) {
  CliRun bad = run("haze --image " + img + " --range " + range + " --backend cuda --out " + p("b.png"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--backend"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("b.png")));
  // A command with no GPU pass refuses the GPU before it reads anything.
  CliRun insert = run("insert --image " + img + " --range " + range + " --backend gpu --out " + p("r.png"));
  EXPECT_NE(insert.status, 0);
  EXPECT_NE(insert.output.find("insert runs on the CPU only"), std::string::npos) << insert.output;
  EXPECT_FALSE(fs::exists(p("r.png")));
  CliRun both = run("blur --image " + img + " --sigma 3 --backend gpu --reference --out " + p("b.png"));
  EXPECT_NE(both.status, 0);
  EXPECT_NE(both.output.find("--reference"), std::string::npos) << both.output;
  // gpu: either it runs, or it fails saying there is no context and what to do.
  CliRun g = run("haze --image " + img + " --range " + range + " --backend gpu --timing --out " + p("g.exr") +
                 " --record " + p("g.json"));
  if (g.status != 0) {
    EXPECT_NE(g.output.find("no OpenGL ES 3.2 context"), std::string::npos) << g.output;
    EXPECT_NE(g.output.find("--backend cpu"), std::string::npos) << g.output;
    BRUME_NO_GPU("no GPU context (its error message was checked): " + g.output);
  }
  EXPECT_NE(g.output.find("diffusion"), std::string::npos) << g.output;  // --timing
  std::ifstream js(p("g.json"));
  nlohmann::json j = nlohmann::json::parse(js);
  EXPECT_EQ(j["execution"]["backend"], "gpu");
  CliRun c = run("haze --image " + img + " --range " + range + " --out " + p("c.exr"));
  ASSERT_EQ(c.status, 0) << c.output;
  EXPECT_LE(compare(read_color(p("g.exr")), read_color(p("c.exr"))).rms, 1e-3);
  // auto takes the GPU only when it is hardware: on a software rasteriser
  // (llvmpipe in CI) it runs on the CPU and says why.
  CliRun a = run("haze --image " + img + " --range " + range + " --backend auto --out " + p("a.exr") + " --record " +
                 p("a.json"));
  ASSERT_EQ(a.status, 0) << a.output;
  std::ifstream ja(p("a.json"));
  const nlohmann::json ra = nlohmann::json::parse(ja);
  if (j["execution"]["gpu"]["software"].get<bool>()) {
    EXPECT_EQ(ra["execution"]["backend"], "cpu");
    EXPECT_NE(ra["execution"].value("gpu_skipped", "").find(j["execution"]["gpu"]["renderer"].get<std::string>()),
              std::string::npos);
    EXPECT_NE(a.output.find("software rasteriser"), std::string::npos) << a.output;
  } else {
    EXPECT_EQ(ra["execution"]["backend"], "gpu");
  }
}

TEST_F(Cli, PreparationFlagsAreCheckedWhateverTheInput) {
  // A range without unknown pixels is not prepared, but its preparation
  // flags are still range-checked (they used to pass silently), and a
  // preparation flag that --prepare off would ignore is refused.
  CliRun d = run("depth prepare --range " + range + " --out " + p("prep.exr"));
  ASSERT_EQ(d.status, 0) << d.output;
  const std::string base = "haze --image " + img + " --range " + p("prep.exr") + " --out " + p("o.png");
  struct Case {
    std::string args, must_contain;
  };
  const Case cases[] = {
      {base + " --s-max-factor 0.5", "--s-max-factor"},
      {base + " --sky-margin -3", "--sky-margin"},
      {base + " --min-coverage 7", "--min-coverage"},
      {base + " --prepare off --sky-margin 4", "--prepare off"},
      {base + " --prepare off --s-max-factor 1.25", "--s-max-factor"},  // given explicitly, even at its default
      {"depth prepare --range " + range + " --out " + p("o.exr") + " --sky-margin -1", "--sky-margin"},
      {base + " --range-max 0", "--range-max"},  // no 0 sentinel: auto is spelled auto
  };
  for (const Case& c : cases) {
    CliRun r = run(c.args);
    EXPECT_NE(r.status, 0) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.must_contain), std::string::npos) << c.args << "\n" << r.output;
    EXPECT_EQ(r.output.find("PrepareParams"), std::string::npos) << r.output;  // user-facing names only
    EXPECT_FALSE(fs::exists(p("o.png"))) << c.args;
    EXPECT_FALSE(fs::exists(p("o.exr"))) << c.args;
  }
  CliRun ok = run(base + " --prepare off --range-max auto");
  EXPECT_EQ(ok.status, 0) << ok.output;
}

TEST_F(Cli, RunRepeatsARecordBitForBit) {
  // `brume run record.json` reads the job back through the same declarations
  // that made the flags: the outputs must be identical to the last bit.
  fs::create_directories(p("first"));
  CliRun h = run("haze --image " + img + " --range " + range16 + " --range-scale 0.001 --visibility 30 --albedo 0.8" +
                 " --lambda 6 --airlight 0.7,0.72,0.75 --scheme invariant --edge-rate min --sky-margin 3 --out " +
                 p("first/h.png") + " --transmission " + p("first/t.exr") + " --record " + p("first/h.json"));
  ASSERT_EQ(h.status, 0) << h.output;
  CliRun b = run("blur --image " + img + " --sigma 4.5 --rho-max 0.15 --precision f16 --out " + p("first/b.exr") +
                 " --record " + p("first/b.json"));
  ASSERT_EQ(b.status, 0) << b.output;
  CliRun c = run("depth convert --range " + range + " --kind z --fov-x 60 --out " + p("first/z.exr") + " --record " +
                 p("first/z.json"));
  ASSERT_EQ(c.status, 0) << c.output;
  for (const char* rec : {"h.json", "b.json", "z.json"}) {
    CliRun r = run("run " + p(std::string("first/") + rec) + " --out-dir " + p("again"));
    ASSERT_EQ(r.status, 0) << rec << "\n" << r.output;
  }
  for (const char* f : {"h.png", "t.exr", "b.exr", "z.exr"}) {
    const Image a = read_scalar_or_color(p(std::string("first/") + f)), b2 = read_scalar_or_color(p(std::string("again/") + f));
    ASSERT_EQ(a.data.size(), b2.data.size()) << f;
    EXPECT_EQ(std::memcmp(a.data.data(), b2.data.data(), a.data.size() * sizeof(float)), 0) << f << " differs";
  }
  // The repeated record has the same job.
  std::ifstream j1(p("first/h.json")), j2(p("again/h.json"));
  nlohmann::json r1 = nlohmann::json::parse(j1), r2 = nlohmann::json::parse(j2);
  r1["job"]["output"] = r2["job"]["output"] = nullptr;  // the paths moved to --out-dir
  EXPECT_EQ(r1["job"], r2["job"]);
  EXPECT_EQ(r2["schema_version"], kRecordSchemaVersion);
  // A changed input is refused: the record describes a run on other bytes.
  write_image(img, Image(48, 32, 3, 0.5f), WriteOptions{});
  CliRun changed = run("run " + p("first/h.json") + " --out-dir " + p("third"));
  EXPECT_NE(changed.status, 0);
  EXPECT_NE(changed.output.find("has changed"), std::string::npos) << changed.output;
  EXPECT_FALSE(fs::exists(p("third/h.png")));
}

TEST_F(Cli, ImageTransferGammaAndTableAreRecordedAndRepeat) {
  // --image-transfer gamma:G / table:FILE reach the read (the output differs
  // from the sRGB read's), the record keeps the text and the table's hash,
  // brume run repeats both bit for bit, and a changed table is refused.
  const std::string table = p("response.txt");
  {
    std::ofstream t(table);
    for (int i = 0; i < 256; ++i) t << std::pow(i / 255.0, 2.4) << (i % 16 == 15 ? "\n" : " ");
  }
  const std::string common = "haze --image " + img + " --range " + range + " --visibility 30 --airlight 0.7,0.72,0.75";
  fs::create_directories(p("first"));
  for (const std::string& form : {std::string("srgb"), std::string("gamma:2.2"), "table:" + table}) {
    const std::string stem = form == "srgb" ? "s" : form[0] == 'g' ? "g" : "t";
    CliRun r = run(common + " --image-transfer " + form + " --out " + p("first/" + stem + ".exr") + " --record " +
                   p("first/" + stem + ".json"));
    ASSERT_EQ(r.status, 0) << form << "\n" << r.output;
  }
  const Image s = read_color(p("first/s.exr")), g = read_color(p("first/g.exr")), t = read_color(p("first/t.exr"));
  EXPECT_NE(s.data, g.data);
  EXPECT_NE(g.data, t.data);
  std::ifstream gj(p("first/g.json")), tj(p("first/t.json"));
  const nlohmann::json gr = nlohmann::json::parse(gj), tr = nlohmann::json::parse(tj);
  EXPECT_EQ(gr["job"]["input"]["image-transfer"], "gamma:2.2");
  EXPECT_EQ(gr["inputs"]["image"]["transfer_applied"], "gamma:2.2");
  EXPECT_EQ(tr["job"]["input"]["image-transfer"], "table:" + table);
  EXPECT_EQ(tr["inputs"]["image"]["transfer_table"]["entries"], 256);
  EXPECT_EQ(tr["inputs"]["image"]["transfer_table"]["sha256"], sha256_file(table));
  for (const char* stem : {"g", "t"}) {
    CliRun r = run(std::string("run ") + p(std::string("first/") + stem + ".json") + " --out-dir " + p("again"));
    ASSERT_EQ(r.status, 0) << stem << "\n" << r.output;
    const Image a = read_color(p(std::string("first/") + stem + ".exr")),
                b = read_color(p(std::string("again/") + stem + ".exr"));
    EXPECT_EQ(a.data, b.data) << stem;
  }
  std::ofstream(table, std::ios::app) << "1\n";
  CliRun changed = run("run " + p("first/t.json") + " --out-dir " + p("third"));
  EXPECT_NE(changed.status, 0);
  EXPECT_NE(changed.output.find("response.txt"), std::string::npos) << changed.output;
  EXPECT_FALSE(fs::exists(p("third/t.exr")));
  // A bad value names the flag and what is allowed; nothing is written.
  CliRun bad = run(common + " --image-transfer gamma:0 --out " + p("bad.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--image-transfer 'gamma:0'"), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("table:FILE"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("bad.exr")));
}

TEST_F(Cli, StudyDiffusionQuickWritesItsTables) {
  // `brume study diffusion --quick` (issue #5's smoke test): the three CSVs
  // with their columns, every scheme in f32 and f16 and both peers, numbers
  // that agree with the library tests (invariant-exact at sigma = 5 well
  // under 2e-3; the leak-free edge rates leave no background in the sharp
  // square, the paper's mean does), the summary and the leakage crops.
  BRUME_REQUIRE_DATA(kArt);
  CliRun r = run("study diffusion --quick --backend cpu --image " + data_path(kArt) + " --out-dir " + p("study"));
  ASSERT_EQ(r.status, 0) << r.output;
  std::ifstream acc(p("study/accuracy.csv")), spd(p("study/speed.csv")), lk(p("study/leakage.csv"));
  std::string header, line;
  std::getline(acc, header);
  EXPECT_EQ(header, "scheme,precision,backend,sigma,rms,iterations,spread");
  int rows = 0;
  bool seen_exact = false;
  while (std::getline(acc, line)) {
    ++rows;
    if (line.rfind("invariant-exact,f32,cpu,5,", 0) == 0) {
      seen_exact = true;
      EXPECT_LT(std::stod(line.substr(std::string("invariant-exact,f32,cpu,5,").size())), 2e-3) << line;
    }
  }
  EXPECT_EQ(rows, (3 * 2 + 2) * 3);  // (3 schemes x 2 precisions + 2 peers) x 3 sigma
  EXPECT_TRUE(seen_exact);
  std::getline(spd, header);
  EXPECT_EQ(header, "method,precision,backend,sigma,seconds,iterations,map,runs");
  int srows = 0;
  while (std::getline(spd, line)) ++srows;
  EXPECT_GT(srows, 6);
  std::getline(lk, header);
  EXPECT_EQ(header, "method,edge_rate,backend,sigma_far,into_near_mean,into_near_max,into_far_mean");
  std::map<std::string, double> rim;
  while (std::getline(lk, line)) {
    std::stringstream ss(line);
    std::string f[7];
    for (auto& x : f) std::getline(ss, x, ',');
    rim[f[0] + "/" + f[1]] = std::stod(f[4]);
  }
  for (const char* k : {"invariant-exact/mean", "invariant-exact/harmonic", "standard/min", "mipmap/-"})
    ASSERT_EQ(rim.count(k), 1u) << "leakage.csv has no row " << k;
  EXPECT_GT(rim.at("invariant-exact/mean"), 0.1);
  EXPECT_EQ(rim.at("invariant-exact/harmonic"), 0.0);
  EXPECT_EQ(rim.at("standard/min"), 0.0);
  // The figures are matplotlib's (python/brume/plots.py, tested by python/tests/test_plots.py): the study
  // writes the leakage crops they show (the 160 px scene's corner: 2 x 160/8 px) and says how to draw them.
  for (const char* crop : {"standard_mean", "standard_min", "standard_harmonic", "invariant-exact_mean",
                           "invariant-exact_min", "invariant-exact_harmonic", "mipmap", "gather"}) {
    Image im = read_color(p(std::string("study/leakage_crops/") + crop + ".png"));
    EXPECT_EQ(im.width, 40) << crop;
    EXPECT_EQ(im.height, 40) << crop;
  }
  for (const char* png : {"accuracy.png", "speed.png", "leakage.png"})
    EXPECT_FALSE(std::filesystem::exists(p(std::string("study/") + png))) << png;
  EXPECT_NE(r.output.find("python3 -m brume.plots " + p("study")), std::string::npos) << r.output;
  EXPECT_TRUE(std::filesystem::exists(p("study/summary.md")));
}

TEST_F(Cli, StudyLeakageAloneWritesItsCsvAndCrops) {
  // `--only leakage` (regenerates docs/study/leakage.* without re-timing the
  // speed part): leakage.csv and leakage_crops/ and nothing else; no image
  // needed. The leak-free edge rates put no near colour into the far ring
  // since the streak fix (the bound 1e-3; the paper's mean does).
  CliRun r = run("study diffusion --quick --backend cpu --only leakage --out-dir " + p("lk"));
  ASSERT_EQ(r.status, 0) << r.output;
  std::set<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(p("lk"))) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"leakage.csv", "leakage_crops"}));
  std::ifstream lk(p("lk/leakage.csv"));
  std::string line;
  std::getline(lk, line);
  std::map<std::string, double> far;
  while (std::getline(lk, line)) {
    std::stringstream ss(line);
    std::string f[7];
    for (auto& x : f) std::getline(ss, x, ',');
    far[f[0] + "/" + f[1]] = std::stod(f[6]);
  }
  for (const char* k : {"invariant/min", "invariant/harmonic", "invariant-exact/min", "invariant-exact/harmonic"}) {
    ASSERT_EQ(far.count(k), 1u) << k;
    EXPECT_LE(far.at(k), 1e-3) << k;
  }
  EXPECT_GT(far.at("invariant-exact/mean"), 0.1);
  EXPECT_NE(run("study diffusion --only speed --out-dir " + p("lk2")).status, 0);
}

TEST_F(Cli, UnknownValueTurnsASkySentinelIntoSky) {
  // The fixture's range with its 6 sky rows stored as -1 (GeoPose3K's
  // convention) instead of NaN: with --unknown-value -1, haze prepares it as
  // the NaN version would be; without it, the map is refused and the message
  // names the flag.
  Image r = read_scalar(range);
  for (float& v : r.data)
    if (std::isnan(v)) v = -1.0f;
  WriteOptions data;
  data.is_color = false;
  write_image(p("geo.exr"), r, data);
  CliRun bad = run("haze --image " + img + " --range " + p("geo.exr") + " --out " + p("o.exr"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("--unknown-value -1"), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("geo.exr"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("o9.exr")));

  CliRun ok = run("haze --image " + img + " --range " + p("geo.exr") + " --unknown-value -1 --out " + p("o.exr") +
                  " --record " + p("o.json"));
  ASSERT_EQ(ok.status, 0) << ok.output;
  nlohmann::json j = nlohmann::json::parse(std::ifstream(p("o.json")));
  EXPECT_EQ(j["job"]["depth"]["unknown-value"], -1.0);
  EXPECT_EQ(j["inputs"]["depth"]["unknown_value_pixels"], 6 * 48);
  EXPECT_EQ(j["haze"]["derived"]["unknown_range_pixels"], 6 * 48);
  EXPECT_EQ(j["prepare"]["applied"], true);
  EXPECT_NEAR(j["prepare"]["sky_fraction"].get<double>(), 6.0 / 32.0, 1e-9);
  // The same pixels as the NaN-marked original.
  CliRun nan = run("haze --image " + img + " --range " + range + " --out " + p("n.exr"));
  ASSERT_EQ(nan.status, 0) << nan.output;
  const Image a = read_color(p("o.exr")), b = read_color(p("n.exr"));
  EXPECT_EQ(a.data, b.data);
  // `brume run` repeats it (the flag is part of the record's job).
  CliRun again = run("run " + p("o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  EXPECT_EQ(read_color(p("again/o.exr")).data, a.data);
}

TEST_F(Cli, DepthConvertWithUnknownValueComparesStoredCounts) {
  // 16-bit millimetre counts with 65535 as "no data": compared before
  // --range-scale, so 65535 (not 65.535 m) is what the user writes.
  Image mm = read_scalar(range16);  // counts; the sky rows are 0 (unknown already)
  for (int x = 0; x < 48; ++x) mm.at(x, 31) = 65535.0f / 65535.0f;  // bottom row: the sentinel
  for (int y = 6; y < 31; ++y)
    for (int x = 0; x < 48; ++x) mm.at(x, y) /= 65535.0f;
  WriteOptions data;
  data.is_color = false;
  write_image(p("mm.png"), mm, data);
  CliRun r = run("depth convert --range " + p("mm.png") + " --range-scale 0.001 --unknown-value 65535 --out " +
                 p("r.exr") + " --record " + p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image out = read_scalar(p("r.exr"));
  for (int x = 0; x < 48; ++x) {
    EXPECT_TRUE(std::isnan(out.at(x, 31))) << x;
    EXPECT_NEAR(out.at(x, 30), 3.0, 1e-3) << x;  // 2 + 0.5 (32 - 30) m, 1 mm counts
  }
  nlohmann::json j = nlohmann::json::parse(std::ifstream(p("r.json")));
  EXPECT_EQ(j["depth"]["unknown_value_pixels"], 48);
  EXPECT_EQ(j["result"]["unknown_pixels"], 7 * 48);  // 6 sky rows (0 counts) + the sentinel row
}

TEST_F(Cli, CompareWritesJsonAndNamesItsInputs) {
  CliRun same = run("compare --a " + img + " --b " + img + " --json " + p("c.json"));
  ASSERT_EQ(same.status, 0) << same.output;
  EXPECT_NE(same.output.find("inf dB"), std::string::npos) << same.output;
  nlohmann::json j = nlohmann::json::parse(std::ifstream(p("c.json")));
  EXPECT_EQ(j["command"], "compare");
  EXPECT_NEAR(j["result"]["hue_saturation_correlation"].get<double>(), 1.0, 1e-12);
  EXPECT_EQ(j["result"]["psnr_linear_db"], "inf");
  EXPECT_EQ(j["result"]["pixels_compared"], 48 * 32);
  EXPECT_EQ(j["inputs"]["a"]["sha256"].get<std::string>().size(), 64u);
  // A hazed copy differs; the mask (a grey PNG) restricts the pixels.
  ASSERT_EQ(run("haze --image " + img + " --range " + range + " --out " + p("h.png")).status, 0);
  Image mask(48, 32, 1, 0.0f);
  for (int x = 0; x < 10; ++x) mask.at(x, 20) = 1.0f;
  WriteOptions grey;
  grey.is_color = false;
  write_image(p("m.png"), mask, grey);
  CliRun diff = run("compare --a " + img + " --b " + p("h.png") + " --mask " + p("m.png") + " --json " + p("d.json"));
  ASSERT_EQ(diff.status, 0) << diff.output;
  nlohmann::json d = nlohmann::json::parse(std::ifstream(p("d.json")));
  EXPECT_EQ(d["result"]["pixels_compared"], 10);
  EXPECT_TRUE(d["result"]["psnr_linear_db"].is_number());
  CliRun bad = run("compare --a " + img + " --b " + p("nope.png") + " --json " + p("e.json"));
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.output.find("nope.png"), std::string::npos) << bad.output;
  EXPECT_FALSE(fs::exists(p("e.json")));
}
