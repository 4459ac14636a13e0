// `brume insert` end to end: outputs and the record, `brume run` repeating it
// bit for bit, the object file conventions (PNG straight sRGB alpha), and the
// error paths (message naming the files, non-zero exit, nothing written).
#include <unistd.h>

#include <OpenImageIO/imageio.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>
#include <nlohmann/json.hpp>

#include "brume/insert.hpp"
#include "brume/io.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

// An 8-bit RGBA PNG holding the counts px as given (straight alpha).
void write_rgba8_png(const std::string& path, int w, int h, const std::vector<unsigned char>& px) {
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(w, h, 4, OIIO::TypeDesc::UINT8);
  spec.alpha_channel = 3;
  spec.attribute("oiio:UnassociatedAlpha", 1);  // write the values as given
  ASSERT_TRUE(out->open(path, spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
  ASSERT_TRUE(out->close());
}

class CliInsert : public ScratchDirTest {
 protected:
  std::string img, range, obj, orange;
  const std::set<std::string> inputs = {"img.exr", "range.exr", "obj.exr", "orange.exr", "small.exr"};
  void SetUp() override {
    Image rgb(48, 32, 3), r(48, 32, 1), o(48, 32, 4, 0.0f), orr(48, 32, 1, NAN);
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 48; ++x) {
        for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = y < 6 ? 0.75f : (((x / 4 + y / 4 + c) % 2) ? 0.8f : 0.1f);
        r.at(x, y) = y < 6 ? NAN : 100.0f + 40.0f * (32 - y);  // 140 .. 1140 m, sky above
        if (x >= 10 && x < 30 && y >= 2 && y < 28) {  // a tower at 300 m: over the sky, partly hidden
          const float a = (x == 10 || x == 29) ? 0.5f : 1.0f;
          o.at(x, y, 0) = 0.6f * a, o.at(x, y, 1) = 0.3f * a, o.at(x, y, 2) = 0.2f * a, o.at(x, y, 3) = a;
          orr.at(x, y) = 300.0f;
        }
      }
    img = p("img.exr"), range = p("range.exr"), obj = p("obj.exr"), orange = p("orange.exr");
    write_image(img, rgb, WriteOptions{});
    write_image(obj, o, WriteOptions{});
    WriteOptions data;
    data.is_color = false;
    write_image(range, r, data);
    write_image(orange, orr, data);
    write_image(p("small.exr"), Image(40, 32, 4, 0.5f), WriteOptions{});
  }
  std::string base() const {
    return "insert --image " + img + " --range " + range + " --object " + obj + " --object-range " + orange +
           " --turbidity 6";
  }
  bool only_inputs_left() const {
    for (auto& e : fs::directory_iterator(dir))
      if (!inputs.count(e.path().filename().string())) return false;
    return true;
  }
};

}  // namespace

TEST_F(CliInsert, WritesTheCompositeCoverageAndARecord) {
  CliRun r = run(base() + " --horizon 0.7,0.72,0.75 --out " + p("o.exr") + " --coverage " + p("c.exr") +
                 " --record " + p("o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image out = read_color(p("o.exr")), photo = read_color(img), cov = read_scalar(p("c.exr"));
  // Rows 6 .. 31 of the scene are at 140 .. 1140 m: the tower at 300 m is in
  // front where the scene is farther (rows with 100 + 40 (32 - y) >= 300, y <= 27).
  EXPECT_EQ(cov.at(20, 3), 1.0f);   // over the sky
  EXPECT_EQ(cov.at(20, 27), 1.0f);  // 300 m scene: a tie, the object wins
  EXPECT_EQ(cov.at(10, 3), 0.5f);   // the half-covered edge
  EXPECT_NE(out.at(20, 3, 0), photo.at(20, 3, 0));
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 48; ++x)
      if (x < 10 || x >= 30 || y < 2 || y >= 28) {
        for (int c = 0; c < 3; ++c) ASSERT_EQ(out.at(x, y, c), photo.at(x, y, c)) << x << ", " << y;
      }
  const nlohmann::json rec = read_json(p("o.json"));
  EXPECT_EQ(rec["command"], "insert");
  EXPECT_EQ(rec["insert"]["derived"]["object_pixels"], 20 * 26);
  EXPECT_EQ(rec["insert"]["derived"]["visible_pixels"], 20 * 26);
  EXPECT_TRUE(rec["inputs"]["object"].contains("sha256"));
  EXPECT_EQ(rec["job"]["aerial"]["turbidity"], 6.0);
}

TEST_F(CliInsert, ATowerBehindTheNearGroundIsHidden) {
  // The same tower at 700 m: hidden by the ground rows whose range < 700 m (y > 17).
  Image orr = read_scalar(orange);
  for (float& v : orr.data)
    if (std::isfinite(v)) v = 700.0f;
  WriteOptions data;
  data.is_color = false;
  write_image(orange, orr, data);
  CliRun r = run(base() + " --lambda 3 --out " + p("o.exr") + " --record " + p("o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image out = read_color(p("o.exr")), photo = read_color(img);
  for (int y = 18; y < 32; ++y)
    for (int x = 0; x < 48; ++x)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(out.at(x, y, c), photo.at(x, y, c)) << x << ", " << y;
  EXPECT_EQ(read_json(p("o.json"))["insert"]["derived"]["hidden_pixels"], 20 * 10);
}

TEST_F(CliInsert, PngObjectIsSrgbWithStraightAlpha) {
  // 8-bit PNG, stored straight: colour 200/255 (sRGB) at alpha 128/255 reads as
  // linear premultiplied srgb_to_linear(200/255) x 128/255 (float rounding only).
  const std::string png = p("obj.png");
  ASSERT_NO_FATAL_FAILURE(write_rgba8_png(png, 2, 1, {200, 100, 50, 128, 10, 20, 30, 255}));
  FileInfo info;
  const Image o = read_object_rgba(png, &info);
  ASSERT_EQ(o.channels, 4);
  const float a = 128.0f / 255.0f;
  EXPECT_NEAR(o.at(0, 0, 0), srgb_to_linear(200.0f / 255.0f) * a, 1e-6);
  EXPECT_NEAR(o.at(0, 0, 1), srgb_to_linear(100.0f / 255.0f) * a, 1e-6);
  EXPECT_NEAR(o.at(0, 0, 3), a, 1e-6);
  EXPECT_NEAR(o.at(1, 0, 2), srgb_to_linear(30.0f / 255.0f), 1e-6);
  // EXR: as stored (premultiplied).
  const Image e = read_object_rgba(obj);
  EXPECT_EQ(e.at(10, 3, 0), 0.3f);
  EXPECT_EQ(e.at(10, 3, 3), 0.5f);
}

TEST_F(CliInsert, EverydayObjectFilesNeedNoCodecModule) {
  // An RGBA object as OpenEXR or as 8-bit PNG is read without OpenImageIO's
  // module (read_unassociated, brume/io.hpp): with no module to load, the
  // run still succeeds and --timing names no module load.
  const std::string png = p("obj.png");
  std::vector<unsigned char> px(48 * 32 * 4, 0);
  for (int i = 0; i < 48 * 32; i += 3) px[i * 4] = 200, px[i * 4 + 3] = 255;
  ASSERT_NO_FATAL_FAILURE(write_rgba8_png(png, 48, 32, px));
  ::setenv("BRUME_CODEC_MODULE", "/nonexistent/brume_codec.so", 1);
  const CliRun e = run(base() + " --out " + p("o1.exr") + " --timing");
  const CliRun g = run("insert --image " + img + " --range " + range + " --object " + png + " --object-range " +
                       orange + " --turbidity 6 --out " + p("o2.exr") + " --timing");
  ::unsetenv("BRUME_CODEC_MODULE");
  ASSERT_EQ(e.status, 0) << e.output;
  EXPECT_EQ(e.output.find("codec module"), std::string::npos) << e.output;
  ASSERT_EQ(g.status, 0) << g.output;
  EXPECT_EQ(g.output.find("codec module"), std::string::npos) << g.output;
}

TEST_F(CliInsert, ErrorPathsAreClearAndLeaveNothing) {
  const std::string out = " --out " + p("o.exr") + " --record " + p("o.json");
  CliRun r = run("insert --image " + img + " --range " + range + " --object " + p("small.exr") + " --object-range " +
                 orange + " --turbidity 4" + out);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("small.exr"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("img.exr"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("40x32"), std::string::npos) << r.output;
  EXPECT_TRUE(only_inputs_left());

  r = run("insert --image " + img + " --range " + range + " --object " + obj + " --turbidity 4" + out);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--object-range"), std::string::npos) << r.output;
  EXPECT_TRUE(only_inputs_left());

  r = run("insert --image " + img + " --range " + range + " --object " + obj + " --object-range " + p("none.exr") +
          " --turbidity 4" + out);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("none.exr"), std::string::npos) << r.output;
  EXPECT_TRUE(only_inputs_left());

  r = run("insert --image " + img + " --range " + range + " --object " + obj + " --object-range " + orange +
          " --turbidity 25" + out);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--turbidity"), std::string::npos) << r.output;
  EXPECT_TRUE(only_inputs_left());

  r = run(base() + " --remove" + out);
  EXPECT_NE(r.status, 0);
  EXPECT_TRUE(only_inputs_left());

  r = run(base() + " --backend gpu" + out);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--backend cpu"), std::string::npos) << r.output;
  EXPECT_TRUE(only_inputs_left());
}

TEST_F(CliInsert, RunRepeatsARecordBitForBit) {
  fs::create_directories(p("first"));
  CliRun a = run(base() + " --horizon 0.7,0.72,0.75 --lambda 4 --distance-scale 2 --out " + p("first/a.exr") +
                 " --coverage " + p("first/c.exr") + " --record " + p("first/a.json"));
  ASSERT_EQ(a.status, 0) << a.output;
  CliRun r = run("run " + p("first/a.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"a.exr", "c.exr"}) {
    expect_same_pixels(p(std::string("first/") + f), p(std::string("again/") + f));
  }
  nlohmann::json r1 = read_json(p("first/a.json")), r2 = read_json(p("again/a.json"));
  r1["job"]["output"] = r2["job"]["output"] = nullptr;
  EXPECT_EQ(r1["job"], r2["job"]);
}
