// Renders as 3D artists write them (issue #50): Blender 3.4's multilayer
// OpenEXR files (tests/renders/, made by examples/blender_fixtures.py with
// Cycles and Eevee: Combined, AO, Depth, Mist and Normal passes), read by
// layer and by pass, their backgrounds unknown, their camera in millimetres,
// and outputs a compositor keeps using. The independent references: the
// projection Blender itself computed for each render (the fixture's .json,
// calc_matrix_camera), Beer-Lambert's exp(-3.912 r / V) in double precision
// here, and OpenImageIO reading the outputs.
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfFrameBuffer.h>

#include <cmath>
#include <fstream>

#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/rerun.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

std::string render(const std::string& name) { return std::string(BRUME_RENDERS_DIR) + "/" + name; }

// The camera Blender computed for a fixture: pixel intrinsics from its
// OpenGL projection P for the W x H image (x_ndc = P00 X/Zf - P02, pixel
// centres at integers: u = (x_ndc + 1) W/2 - 1/2; y down in the image).
struct BlenderCamera {
  int W = 0, H = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  nlohmann::json side;
};
BlenderCamera blender_camera(const std::string& fixture) {
  BlenderCamera c;
  c.side = read_json(render(fixture + ".json"));
  c.W = c.side["width"], c.H = c.side["height"];
  const auto& P = c.side["projection"];
  c.fx = P[0][0].get<double>() * c.W / 2.0;
  c.fy = P[1][1].get<double>() * c.H / 2.0;
  c.cx = (1.0 - P[0][2].get<double>()) * c.W / 2.0 - 0.5;
  c.cy = (1.0 + P[1][2].get<double>()) * c.H / 2.0 - 0.5;
  return c;
}

// The fixture's lens as brume's flags take it.
LensCamera lens_of(const nlohmann::json& side) {
  LensCamera l;
  const auto& cam = side["camera"];
  l.focal_length_mm = cam["lens_mm"].get<double>();
  l.sensor_width_mm = cam["sensor_width_mm"].get<double>();
  l.lens_shift = {cam["shift_x"].get<double>(), cam["shift_y"].get<double>()};
  return l;
}
std::string lens_flags(const nlohmann::json& side) {
  const auto& cam = side["camera"];
  char b[256];
  std::snprintf(b, sizeof b, " --focal-length %.9g --sensor-width %.9g --lens-shift %.9g,%.9g",
                cam["lens_mm"].get<double>(), cam["sensor_width_mm"].get<double>(), cam["shift_x"].get<double>(),
                cam["shift_y"].get<double>());
  return b;
}

}  // namespace

// ---- names -------------------------------------------------------------------------------
TEST(Renders, NamesOfLayersAndPasses) {
  const std::vector<std::string> blender = {"ViewLayer.AO.B", "ViewLayer.AO.G", "ViewLayer.AO.R",
                                            "ViewLayer.Combined.A", "ViewLayer.Combined.B", "ViewLayer.Combined.G",
                                            "ViewLayer.Combined.R", "ViewLayer.Depth.Z", "ViewLayer.Mist.Z",
                                            "ViewLayer.Normal.X", "ViewLayer.Normal.Y", "ViewLayer.Normal.Z"};
  EXPECT_EQ(colour_layers(blender), (std::vector<std::string>{"ViewLayer.AO", "ViewLayer.Combined"}));
  EXPECT_FALSE(plain_channels(blender));
  EXPECT_EQ(colour_layers({"R", "G", "B", "A", "Z"}), (std::vector<std::string>{""}));
  EXPECT_EQ(colour_layers({"diffuse.red", "diffuse.green", "diffuse.blue"}), (std::vector<std::string>{"diffuse"}));
  for (const char* plain : {"R G B", "R G B A", "Y", "Y A", "depth"}) {
    std::vector<std::string> v;
    std::istringstream s(plain);
    for (std::string w; s >> w;) v.push_back(w);
    EXPECT_TRUE(plain_channels(v)) << plain;
  }
  for (const char* d : {"Z", "depth", "Depth", "render.depth", "ViewLayer.Depth.Z", "RenderLayer.Depth.Z", "depth.Z"})
    EXPECT_TRUE(is_depth_pass_name(d)) << d;
  for (const char* n : {"ViewLayer.Mist.Z", "ViewLayer.Normal.Z", "ViewLayer.Combined.R", "Zdepth.R", "P.Z"})
    EXPECT_FALSE(is_depth_pass_name(n)) << n;
  EXPECT_TRUE(is_mist_pass_name("ViewLayer.Mist.Z"));
  EXPECT_FALSE(is_mist_pass_name("ViewLayer.Depth.Z"));
}

// ---- colour: the layer named, never the first three channels -------------------------------
TEST(Renders, ColourOfAFileWithSeveralLayersIsRefusedUnlessNamed) {
  for (const char* f : {"cycles.exr", "eevee.exr"}) {
    const std::string e = error_of([&] { (void)read_color(render(f)); });
    EXPECT_NE(e.find("2 colour layers (ViewLayer.AO, ViewLayer.Combined)"), std::string::npos) << e;
    EXPECT_NE(e.find("--image-layer"), std::string::npos) << e;
    ColorRead how;
    how.layer = "ViewLayer.Combined";
    FileInfo info;
    Image alpha;
    const Image rgb = read_color(render(f), how, &info, &alpha);
    EXPECT_EQ(info.layer, "ViewLayer.Combined");
    EXPECT_EQ(info.channels_read, (std::vector<std::string>{"ViewLayer.Combined.R", "ViewLayer.Combined.G",
                                                            "ViewLayer.Combined.B", "ViewLayer.Combined.A"}));
    EXPECT_TRUE(info.blender);
    // The peer: OpenImageIO's read of the same channels.
    auto in = OIIO::ImageInput::open(render(f));
    ASSERT_TRUE(in);
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<float> all(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
    ASSERT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, all.data()));
    const int r = spec.channelindex("ViewLayer.Combined.R"), a = spec.channelindex("ViewLayer.Combined.A");
    ASSERT_GE(r, 0);
    std::size_t differ = 0;
    for (std::size_t i = 0; i < rgb.pixels(); ++i) {
      for (int c = 0; c < 3; ++c) differ += rgb.data[i * 3 + c] != all[i * spec.nchannels + r + c];
      differ += alpha.data[i] != all[i * spec.nchannels + a];
    }
    EXPECT_EQ(differ, 0u) << f;
    how.layer = "ViewLayer.Beauty";
    const std::string e2 = error_of([&] { (void)read_color(render(f), how); });
    EXPECT_NE(e2.find("no colour layer named 'ViewLayer.Beauty'"), std::string::npos) << e2;
    EXPECT_NE(e2.find("ViewLayer.AO, ViewLayer.Combined"), std::string::npos) << e2;
  }
  // A plain file takes no layer.
  ColorRead how;
  how.layer = "ViewLayer.Combined";
  const std::string e = error_of([&] { (void)read_color(std::string(BRUME_RENDERS_DIR) + "/../../docs/images/clean.png", how); });
  EXPECT_NE(e.find("has none"), std::string::npos) << e;
}

// ---- depth: the pass found by name, Mist never, planar refused as range ------------------------
TEST(Renders, DepthPassIsFoundByNameAndMistIsNeverDepth) {
  for (const char* f : {"cycles.exr", "eevee.exr"}) {
    ScalarRead how;
    how.depth = true;
    FileInfo info;
    const Image z = read_scalar(render(f), how, &info);
    EXPECT_EQ(info.channels_read, std::vector<std::string>{"ViewLayer.Depth.Z"}) << f;
    EXPECT_EQ(info.channel_rule, "the file's one channel named like a depth pass");
    // A mask read (not depth) of the same file says which channel to extract.
    EXPECT_NE(error_of([&] { (void)read_scalar(render(f)); }).find("extract the one"), std::string::npos);
  }
  // Mist as the only candidate: refused by name; two depth passes: the list.
  const std::string dir = ::testing::TempDir();
  Image four(8, 6, 4);
  for (std::size_t i = 0; i < four.data.size(); ++i) four.data[i] = 0.25f + 0.01f * static_cast<float>(i % 7);
  WriteOptions w;
  w.is_color = false;
  w.channel_names = {"ViewLayer.Combined.B", "ViewLayer.Combined.G", "ViewLayer.Combined.R", "ViewLayer.Mist.Z"};
  write_image(dir + "/mist.exr", four, w);
  ScalarRead how;
  how.depth = true;
  std::string e = error_of([&] { (void)read_scalar(dir + "/mist.exr", how); });
  EXPECT_NE(e.find("only a Mist pass (ViewLayer.Mist.Z)"), std::string::npos) << e;
  EXPECT_NE(e.find("--depth-channel"), std::string::npos) << e;
  w.channel_names = {"A.Depth.Z", "B.Depth.Z", "C.R", "Z"};
  write_image(dir + "/two.exr", four, w);
  e = error_of([&] { (void)read_scalar(dir + "/two.exr", how); });
  EXPECT_NE(e.find("3 channels named like depth passes (A.Depth.Z, B.Depth.Z, Z)"), std::string::npos) << e;
  how.channel = "B.Depth.Z";
  FileInfo info;
  const Image b = read_scalar(dir + "/two.exr", how, &info);
  EXPECT_EQ(b.data[0], four.data[1]);
  EXPECT_EQ(info.channel_rule, "named by --depth-channel");
}

// ---- records before schema 4: the file's first channels, as they ran ------------------------------
TEST(Renders, OlderRecordsReadTheFirstChannelsAsTheyRan) {
  // --image-layer-rule and --depth-channel-rule, since(4, "first"): a job of
  // an older record lacks them and reads a file with layers as every read did
  // then -- the first three channels in the file's order as colour, and, as
  // depth, the first of three equal ones (on Blender's files both are the
  // grey AO pass: the issue's wrong pictures, repeated as recorded).
  for (const auto* spec : {input_param_table(true).find("image-layer-rule"),
                           input_param_table(true).find("depth-channel-rule")}) {
    ASSERT_NE(spec, nullptr);
    EXPECT_EQ(spec->spec.since_schema, 4);
    EXPECT_EQ(spec->spec.before_schema, "first");
  }
  for (const char* f : {"cycles.exr", "eevee.exr"}) {
    auto in = OIIO::ImageInput::open(render(f));
    ASSERT_TRUE(in);
    const OIIO::ImageSpec& spec = in->spec();
    std::vector<float> all(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
    ASSERT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, all.data()));
    ColorRead how;
    how.rule = LayerRule::first;
    FileInfo info;
    const Image rgb = read_color(render(f), how, &info);
    std::size_t differ = 0;
    for (std::size_t i = 0; i < rgb.pixels(); ++i)
      for (int c = 0; c < 3; ++c) differ += rgb.data[i * 3 + c] != all[i * spec.nchannels + c];
    EXPECT_EQ(differ, 0u) << f << ": the first three channels, " << spec.channelnames[0];
    ScalarRead depth;
    depth.depth = true;
    depth.rule = LayerRule::first;
    const Image v = read_scalar(render(f), depth, &info);
    differ = 0;
    for (std::size_t i = 0; i < v.pixels(); ++i) differ += v.data[i] != all[i * spec.nchannels];
    EXPECT_EQ(differ, 0u) << f << ": the first channel, " << spec.channelnames[0];
    // A layer or channel named is read by name under either rule.
    how.layer = "ViewLayer.Combined";
    (void)read_color(render(f), how, &info);
    EXPECT_EQ(info.layer, "ViewLayer.Combined");
  }
}

TEST(Renders, BlendersZPassIsPlanarAndRefusedAsRange) {
  // Planar: constant along a ground row (below the boxes' rows), as the issue measured.
  for (const char* f : {"cycles.exr", "eevee.exr"}) {
    ScalarRead how;
    how.depth = true;
    const Image z = read_scalar(render(f), how);
    const int y = z.height - 2;
    float lo = INFINITY, hi = 0;
    for (int x = 0; x < 10; ++x) lo = std::min(lo, z.at(x, y)), hi = std::max(hi, z.at(x, y));
    EXPECT_LT((hi - lo) / lo, 1e-4) << f << ": row " << y << " from " << lo << " to " << hi;
    DepthSource s;
    s.range = render(f);
    const std::string e = error_of([&] { (void)load_depth(s); });
    EXPECT_NE(e.find("planar depth"), std::string::npos) << e;
    EXPECT_NE(e.find("--z"), std::string::npos) << e;
  }
}

// ---- backgrounds: unknown by default, as stored; off for old records -------------------------
TEST(Renders, RendererBackgroundsAreUnknownAndOldRecordsKeepThem) {
  for (const auto& [f, bg] : {std::pair<const char*, float>{"cycles.exr", 1e10f}, {"eevee.exr", 65504.0f}}) {
    ScalarRead how;
    how.depth = true;
    const Image stored = read_scalar(render(f), how);
    std::size_t n_bg = 0;
    for (float v : stored.data) n_bg += v == bg;
    EXPECT_GT(n_bg, stored.pixels() / 4) << f << ": the sky holds the renderer's background value";
    DepthSource s;
    s.z = render(f);
    s.lens = lens_of(blender_camera(std::string(f).substr(0, std::string(f).size() - 4)).side);
    const LoadedDepth d = load_depth(s);
    EXPECT_EQ(d.record["render_background"]["pixels"].get<std::size_t>(), n_bg) << f;
    EXPECT_EQ(d.record["unknown_pixels"].get<std::size_t>(), n_bg) << f;
    EXPECT_EQ(d.record["channel"], "ViewLayer.Depth.Z");
    EXPECT_FALSE(d.record.contains("warnings")) << d.record.dump();
    s.render_background = RenderBackground::off;  // as schema <= 3 read them
    const LoadedDepth old = load_depth(s);
    EXPECT_EQ(old.record["unknown_pixels"].get<std::size_t>(), 0u);
    if (bg > 1e6f) {  // Cycles' 1e10 is implausible as a distance: warned about
      ASSERT_TRUE(old.record.contains("warnings")) << old.record.dump();
      EXPECT_NE(old.record["warnings"][0].get<std::string>().find("--z"), std::string::npos);
      EXPECT_NE(old.record["warnings"][0].get<std::string>().find("--renderer-background auto"), std::string::npos);
    } else {  // Eevee's 65504 m passes the plausibility rule: which is why the background rule names it
      EXPECT_FALSE(old.record.contains("warnings"));
    }
  }
  // Integer files hold counts: 65504 there is a distance.
  EXPECT_FALSE(is_render_background(65503.0f));
  EXPECT_TRUE(is_render_background(1e9f) && is_render_background(INFINITY) && is_render_background(-INFINITY));
}

// ---- the camera in millimetres against Blender's own projection ---------------------------------
TEST(Renders, CameraInMillimetresIsBlendersProjection) {
  for (const char* f : {"cycles", "eevee"}) {
    const BlenderCamera c = blender_camera(f);
    const Intrinsics k = lens_intrinsics(lens_of(c.side), c.W, c.H);
    // float32 projection entries: 1e-4 px.
    EXPECT_NEAR(k.fx, c.fx, 1e-4) << f;
    EXPECT_NEAR(k.fy, c.fy, 1e-4) << f;
    EXPECT_NEAR(k.cx, c.cx, 1e-4) << f;
    EXPECT_NEAR(k.cy, c.cy, 1e-4) << f;
  }
  // The fits, on a landscape and a portrait image (Blender's rules, brume/depth.hpp).
  LensCamera l;
  l.focal_length_mm = 50.0;
  l.sensor_width_mm = 36.0;
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 640, 480).fx, 50.0 * 640 / 36.0);  // auto: the larger side
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 480, 640).fx, 50.0 * 640 / 36.0);
  l.sensor_fit = SensorFit::horizontal;
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 480, 640).fx, 50.0 * 480 / 36.0);
  l.lens_shift = {0.1, -0.2};
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 480, 640).cx, 239.5 - 0.1 * 480);
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 480, 640).cy, 319.5 - 0.2 * 480);
  l.sensor_fit = SensorFit::vertical;
  EXPECT_NE(error_of([&] { (void)lens_intrinsics(l, 480, 640); }).find("--sensor-width"), std::string::npos);
  l.sensor_width_mm.reset();
  l.sensor_height_mm = 24.0;
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 480, 640).fy, 50.0 * 640 / 24.0);
  EXPECT_DOUBLE_EQ(lens_intrinsics(l, 480, 640).cx, 239.5 - 0.1 * 640);
  // With pixels too: they must agree within 1 %, and the shift is theirs to give.
  DepthSource s;
  s.lens.focal_length_mm = 35.0;
  s.lens.sensor_width_mm = 36.0;
  s.fov_x_deg = 2.0 * std::atan(18.0 / 35.0) * 180.0 / M_PI;
  EXPECT_NEAR(depth_intrinsics(s, 64, 48).fx, 35.0 * 64 / 36.0, 1e-9);
  s.fov_x_deg = 60.0;
  EXPECT_NE(error_of([&] { (void)depth_intrinsics(s, 64, 48); }).find("at most 1 %"), std::string::npos);
}

// ---- the issue's "done when", through the command line ------------------------------------------
class RendersCli : public ScratchDirTest {};

TEST_F(RendersCli, HazeOnCyclesAndEeveeRendersTransmitsAsBeerLambert) {
  for (const char* f : {"cycles", "eevee"}) {
    const BlenderCamera c = blender_camera(f);
    const std::string in = render(std::string(f) + ".exr");
    // No layer named: refused with the list, exit 2, nothing written.
    CliRun r = run("haze --image " + in + " --z " + in + lens_flags(c.side) + " --visibility 100 --out " + p("x.exr"));
    EXPECT_EQ(r.status, 2) << r.output;
    EXPECT_NE(r.output.find("ViewLayer.AO, ViewLayer.Combined"), std::string::npos) << r.output;
    EXPECT_FALSE(std::filesystem::exists(p("x.exr")));
    // The beauty pass named, the Depth pass found.
    const std::string out = p(std::string(f) + "-haze.exr"), t = p(std::string(f) + "-t.pfm"),
                      rec = p(std::string(f) + ".json");
    r = run("haze --image " + in + " --image-layer ViewLayer.Combined --z " + in + lens_flags(c.side) +
            " --visibility 100 --lambda 0 --out " + out + " --transmission " + t + " --record " + rec);
    ASSERT_EQ(r.status, 0) << r.output;
    const nlohmann::json j = read_json(rec);
    EXPECT_EQ(j["inputs"]["image"]["layer"], "ViewLayer.Combined");
    EXPECT_EQ(j["inputs"]["depth"]["channel"], "ViewLayer.Depth.Z");
    EXPECT_EQ(j["inputs"]["depth"]["channel_rule"], "the file's one channel named like a depth pass");
    ScalarRead how;
    how.depth = true;
    const Image z = read_scalar(in, how);
    const Image tau = read_scalar(t);
    // Scene pixels: exp(-3.912 r / V) with r from Blender's own camera (double).
    double worst = 0.0, sky_worst = 0.0;
    std::size_t scene = 0, sky = 0;
    const auto near_scene = [&](int x, int y) {  // within the 8 px margin of a scene pixel
      for (int v = std::max(0, y - 9); v < std::min(z.height, y + 10); ++v)
        for (int u = std::max(0, x - 9); u < std::min(z.width, x + 10); ++u)
          if (!is_render_background(z.at(u, v)) && (u - x) * (u - x) + (v - y) * (v - y) <= 81) return true;
      return false;
    };
    for (int y = 0; y < z.height; ++y)
      for (int x = 0; x < z.width; ++x) {
        const double zz = z.at(x, y), a = (x - c.cx) / c.fx, b = (y - c.cy) / c.fy;
        if (!is_render_background(z.at(x, y))) {  // (Cycles' 1e10, Eevee's 65504: the sky)
          const double ref = std::exp(-3.912 * zz * std::sqrt(1 + a * a + b * b) / 100.0);
          worst = std::max(worst, std::abs(tau.at(x, y) - ref));
          ++scene;
        } else if (!near_scene(x, y)) {  // sky beyond the horizon margin
          sky_worst = std::max(sky_worst, static_cast<double>(tau.at(x, y)));
          ++sky;
        }
      }
    EXPECT_GT(scene, z.pixels() / 3);
    EXPECT_GT(sky, 100u);
    EXPECT_LE(worst, 2e-3) << f << ": largest |tau - exp(-3.912 r/V)| on " << scene << " scene pixels";
    EXPECT_LE(sky_worst, 4e-4) << f << ": the sky is beyond the medium";
    std::printf("%s: %zu scene pixels, largest |tau - exp(-3.912 r/V)| %.3g; sky tau <= %.3g\n", f, scene, worst,
                sky_worst);
    // The output opens in OpenImageIO with the layer's names and its alpha (opaque render: 1).
    auto oin = OIIO::ImageInput::open(out);
    ASSERT_TRUE(oin);
    const OIIO::ImageSpec& spec = oin->spec();
    EXPECT_EQ(spec.nchannels, 4);
    EXPECT_GE(spec.channelindex("ViewLayer.Combined.A"), 0);
    std::vector<float> px(static_cast<std::size_t>(spec.width) * spec.height * 4);
    ASSERT_TRUE(oin->read_image(0, 0, 0, 4, OIIO::TypeDesc::FLOAT, px.data()));
    const int ai = spec.channelindex("ViewLayer.Combined.A");
    for (std::size_t i = 0; i < px.size() / 4; ++i) ASSERT_EQ(px[i * 4 + ai], 1.0f) << i;
    // brume run repeats it bit for bit.
    r = run("run " + rec + " --out-dir " + p(std::string(f) + "-again"));
    ASSERT_EQ(r.status, 0) << r.output;
    expect_same_pixels(t, p(std::string(f) + "-again/" + std::filesystem::path(t).filename().string()));
  }
}

TEST_F(RendersCli, KeepLayersWritesTheCompAndAlphaComposesOver) {
  const BlenderCamera c = blender_camera("cycles-transparent");
  const std::string in = render("cycles-transparent.exr");
  const std::string out = p("comp.exr"), rec = p("comp.json");
  // The transparent film's sky has no colour: the airlight must be given.
  CliRun r = run("haze --image " + in + " --image-layer ViewLayer.Combined --z " + in + lens_flags(c.side) +
                 " --visibility 60 --lambda 1 --keep-layers --out " + out);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--airlight R,G,B"), std::string::npos) << r.output;
  r = run("haze --image " + in + " --image-layer ViewLayer.Combined --z " + in + lens_flags(c.side) +
          " --visibility 60 --lambda 0 --airlight 0.45,0.6,0.85 --keep-layers --out " + out + " --record " + rec);
  ASSERT_EQ(r.status, 0) << r.output;
  auto oin = OIIO::ImageInput::open(out);
  ASSERT_TRUE(oin);
  const OIIO::ImageSpec spec = oin->spec();
  for (const char* ch : {"ViewLayer.Combined.R", "ViewLayer.Combined.A", "ViewLayer.AO.R", "ViewLayer.Depth.Z",
                         "ViewLayer.Mist.Z", "ViewLayer.Normal.X", "ViewLayer.Medium.R", "ViewLayer.Medium.A",
                         "ViewLayer.Transmission.V", "ViewLayer.BlurScale.V"})
    EXPECT_GE(spec.channelindex(ch), 0) << ch;
  std::vector<float> px(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
  ASSERT_TRUE(oin->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, px.data()));
  const auto at = [&](std::size_t i, const char* ch) { return px[i * spec.nchannels + spec.channelindex(ch)]; };
  // The input's other channels as stored; the alpha over; the medium is what was added.
  auto iin = OIIO::ImageInput::open(in);
  const OIIO::ImageSpec ispec = iin->spec();
  std::vector<float> ipx(static_cast<std::size_t>(ispec.width) * ispec.height * ispec.nchannels);
  ASSERT_TRUE(iin->read_image(0, 0, 0, ispec.nchannels, OIIO::TypeDesc::FLOAT, ipx.data()));
  const auto iat = [&](std::size_t i, const char* ch) { return ipx[i * ispec.nchannels + ispec.channelindex(ch)]; };
  EXPECT_EQ(spec.channelformat(spec.channelindex("ViewLayer.AO.R")), OIIO::TypeDesc::HALF);
  EXPECT_EQ(spec.channelformat(spec.channelindex("ViewLayer.Depth.Z")), OIIO::TypeDesc::FLOAT);
  double worst_alpha = 0, worst_colour = 0;
  std::size_t sky = 0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(spec.width) * spec.height; ++i) {
    for (const char* ch : {"ViewLayer.AO.G", "ViewLayer.Depth.Z", "ViewLayer.Mist.Z", "ViewLayer.Normal.Y"})
      ASSERT_EQ(at(i, ch), iat(i, ch)) << ch << " at " << i;
    const double T = at(i, "ViewLayer.Transmission.V"), A = iat(i, "ViewLayer.Combined.A");
    worst_alpha = std::max(worst_alpha, std::abs(at(i, "ViewLayer.Combined.A") - (T * A + (1 - T))));
    for (const char* ch : {"R", "G", "B"}) {
      const std::string cn = std::string("ViewLayer.Combined.") + ch, mn = std::string("ViewLayer.Medium.") + ch;
      // C' = T C + (1 - T) B, and the medium layer is the (1 - T) B part.
      worst_colour = std::max(worst_colour, std::abs(at(i, cn.c_str()) - (T * iat(i, cn.c_str()) + at(i, mn.c_str()))));
    }
    EXPECT_FLOAT_EQ(at(i, "ViewLayer.Medium.A"), static_cast<float>(1 - T));
    sky += A == 0.0;
  }
  EXPECT_GT(sky, 500u) << "the transparent film's sky";
  EXPECT_LT(worst_alpha, 1e-6);
  EXPECT_LT(worst_colour, 2e-6);
  const nlohmann::json j = read_json(rec);
  EXPECT_EQ(j["output_layers"]["medium"]["layer"], "ViewLayer.Medium");
}

TEST_F(RendersCli, DataWindowIsPaddedToTheDisplayWindow) {
  // A Nuke-style crop: the data window inside a 64 x 48 display window.
  const int W = 64, H = 48;
  Imf::Header h(W, H);
  h.dataWindow() = Imath::Box2i({10, 8}, {49, 37});
  h.channels().insert("R", Imf::Channel(Imf::FLOAT));
  h.channels().insert("G", Imf::Channel(Imf::FLOAT));
  h.channels().insert("B", Imf::Channel(Imf::FLOAT));
  h.channels().insert("Z", Imf::Channel(Imf::FLOAT));
  const int dw = 40, dh = 30;
  std::vector<float> v(static_cast<std::size_t>(dw) * dh * 4, 0.5f);
  for (int i = 0; i < dw * dh; ++i) v[static_cast<std::size_t>(i) * 4 + 3] = 5.0f + i % 7;
  {
    Imf::OutputFile o(p("crop.exr").c_str(), h);
    Imf::FrameBuffer fb;
    char* base = reinterpret_cast<char*>(v.data()) - (10 + 8 * dw) * 16;
    for (int c = 0; c < 4; ++c) fb.insert(std::string(1, "RGBZ"[c]), Imf::Slice(Imf::FLOAT, base + 4 * c, 16, 16 * dw));
    o.setFrameBuffer(fb);
    o.writePixels(dh);
  }
  FileInfo info;
  const Image rgb = read_color(p("crop.exr"), Transfer::automatic, &info);
  EXPECT_EQ(rgb.width, W);
  EXPECT_EQ(rgb.height, H);
  EXPECT_TRUE(info.padded);
  EXPECT_EQ(rgb.at(0, 0, 0), 0.0f);
  EXPECT_EQ(rgb.at(10, 8, 0), 0.5f);
  ScalarRead how;
  how.depth = true;
  const Image z = read_scalar(p("crop.exr"), how);
  EXPECT_TRUE(std::isnan(z.at(0, 0)));
  EXPECT_EQ(z.at(10, 8), 5.0f);
  // Intrinsics from the display window: its centre, whatever the data window.
  const CliRun r = run("depth convert --z " + p("crop.exr") + " --fov-x 60 --out " + p("r.pfm") + " --record " + p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json j = read_json(p("r.json"));
  EXPECT_DOUBLE_EQ(j["depth"]["intrinsics"]["cx_px"].get<double>(), 31.5);
  EXPECT_EQ(j["depth"]["data_window"], nlohmann::json::array({10, 8, 49, 37}));
}

// ---- records of schema <= 3 repeat: depth of field's lens moved to the camera block --------------
TEST_F(RendersCli, DepthOfFieldLensOfAnOlderRecordRepeats) {
  CliRun r = run("demo --out-dir " + p("scene") + " --width 96 --height 64");
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string base = " --image " + p("scene/clean.png") + " --range " + p("scene/range.exr") +
                           " --focus-distance 5 --f-number 2 --focal-length 35 --sensor-width 36 --fov-x 54.4322";
  r = run("dof" + base + " --sensor-fit horizontal --out " + p("new.pfm") + " --record " + p("new.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  // The same job as a schema-3 record wrote it: the lens in the dof block, no sensor fit.
  nlohmann::json old = read_json(p("new.json"));
  old["schema_version"] = 3;
  old["job"]["dof"]["focal-length"] = old["job"]["depth"]["focal-length"];
  old["job"]["dof"]["sensor-width"] = old["job"]["depth"]["sensor-width"];
  for (const char* k : {"focal-length", "sensor-width", "sensor-height", "sensor-fit", "lens-shift",
                        "renderer-background"})
    old["job"]["depth"].erase(k);
  old["job"]["output"].erase("out-alpha");
  old["job"]["output"].erase("keep-layers");
  old["job"]["input"].erase("image-layer");
  std::ofstream(p("old.json")) << old.dump(2);
  r = run("run " + p("old.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("new.pfm"), p("again/new.pfm"));
}
