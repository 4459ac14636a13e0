// brume tests — a sparse depth source fused with a stereo view (issue 52,
// item 2; brume/fuse.hpp): `brume depth complete` and `--complete` with
// --stereo-right beside a scan.
//
//  - the fit of the matched disparity to the scan's, on synthetic data with a
//    known scale, offset and outliers;
//  - KITTI's calibration: the baseline from P2 and P3 of the real file;
//  - ETH3D playground_1l and terrace with the KITTI-like scan of the "above
//    the scan" test (tests/eth3d_scan.hpp): the issue's targets;
//  - the command line: the docs' example, its record and replay, and the
//    errors (sizes, calibration, --complete off, depth convert).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "brume/complete.hpp"
#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/fuse.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "eth3d_scan.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;
using namespace brume::eth3d;

namespace {

WriteOptions float_map() {
  WriteOptions w;
  w.is_color = false;
  return w;
}

// The fit recovers a known disparity scale and offset (d_s = 1.1 d + 2 px)
// through 20 % of gross outliers: Huber IRLS down-weights them. Tolerance
// 0.01 on the scale and 0.05 px on the offset: the inliers carry 0.05 px of
// noise over 4000 pixels (a standard error ~0.003 px), so the slack is for
// the outliers' residual pull under Huber's linear weights, not for noise.
TEST(Fuse, FitRecoversScaleAndOffsetThroughOutliers) {
  const int W = 80, H = 60;
  StereoGeometry g;
  g.f_px = 500.0, g.baseline_m = 0.1, g.doffs_px = 0.0;
  g.k.fx = g.k.fy = 500.0, g.k.cx = W / 2.0, g.k.cy = H / 2.0;
  StereoResult st;
  st.disparity = Image(W, H, 1, NAN);
  st.confidence = Image(W, H, 1, 1.0f);
  Image scan(W, H, 1, NAN);
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.05);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const double d = 5.0 + 40.0 * x / W + 5.0 * y / H;
      st.disparity.at(x, y) = static_cast<float>(d);
      if (y % 3) continue;  // the scan sees every third row
      double ds = 1.1 * d + 2.0 + noise(rng);
      if (u(rng) < 0.2) ds = 3.0 + 60.0 * u(rng);  // a gross outlier
      const double a = (x - g.k.cx) / g.k.fx, b = (y - g.k.cy) / g.k.fy;
      scan.at(x, y) = static_cast<float>(g.f_px * g.baseline_m / ds * std::sqrt(1 + a * a + b * b));
    }
  const StereoFill f = fit_stereo_to_scan(scan, st, g);
  EXPECT_NEAR(f.record["scale"].get<double>(), 1.1, 0.01) << f.record.dump(2);
  EXPECT_NEAR(f.record["offset_px"].get<double>(), 2.0, 0.05) << f.record.dump(2);
  EXPECT_EQ(f.record["pixels_both_see"].get<std::size_t>(), static_cast<std::size_t>(W * (H / 3)));
  EXPECT_LT(f.record["residuals_after"]["median_abs_px"].get<double>(),
            f.record["residuals_before"]["median_abs_px"].get<double>());
  // The fitted range at a pixel the scan does not see: z = f B / (1.1 d + 2).
  const double d = st.disparity.at(10, 1), a = (10 - g.k.cx) / g.k.fx, b = (1 - g.k.cy) / g.k.fy;
  EXPECT_NEAR(f.range.at(10, 1), 50.0 / (1.1 * d + 2.0) * std::sqrt(1 + a * a + b * b), 0.01 * f.range.at(10, 1));
}

// A second view that disagrees with the scan (here: zero disparity
// everywhere, as a view given twice matches) is not used: the fit would
// find a = 1 and an offset that turns every pixel into one distance. Fewer
// than half the pixels both see within 1 px after the fit (here none) ->
// confidence 0 everywhere, so the fusion takes nothing, and a warning.
TEST(Fuse, PairThatDisagreesWithTheScanIsNotUsed) {
  const int W = 64, H = 48;
  StereoGeometry g;
  g.f_px = 500.0, g.baseline_m = 0.1;
  g.k.fx = g.k.fy = 500.0, g.k.cx = W / 2.0, g.k.cy = H / 2.0;
  StereoResult st;
  st.disparity = Image(W, H, 1, 0.0f);
  st.confidence = Image(W, H, 1, 1.0f);
  Image scan(W, H, 1, NAN);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> d(5.0f, 40.0f);  // the scan's disparities [px], spread evenly
  for (int y = H / 2; y < H; y += 2)
    for (int x = 0; x < W; ++x) scan.at(x, y) = 50.0f / d(rng);  // f B = 50 px m
  const StereoFill f = fit_stereo_to_scan(scan, st, g);
  EXPECT_FALSE(f.record["used"].get<bool>()) << f.record.dump(2);
  EXPECT_TRUE(f.record.contains("warning"));
  CompleteResult done;
  done.range = Image(W, H, 1, NAN);
  done.confidence = Image(W, H, 1, 0.0f);
  done.sky_mask = Image(W, H, 1, 0.0f);
  const nlohmann::json rec = fuse_stereo(done, scan, f, 5);
  EXPECT_EQ(rec["stereo_fraction"].get<double>(), 0.0);
}

// The fattening guard (complete-stereo-fattening): no scan return in the
// frame; the completion's estimate is the background, 20 m, everywhere; the
// pair sees a nearer object (10 m) over x < 40 of which x 32-39 is the
// matcher's fattening past the object's true edge, and the background's 20
// m beyond. Every match is strong (confidence 1). With a 5 px guard the
// pixels within 5 px of where the pair sees 20 m (x 35-39) keep the
// estimate, the rest of the object (x < 35) takes 10 m; with 0 (the rule of
// records before it) all of x < 40 takes 10 m. Exact values: the fusion
// copies them.
TEST(Fuse, FatteningBesideANearerObjectKeepsTheEstimate) {
  const int W = 64, H = 16;
  StereoFill f;
  f.range = Image(W, H, 1, 20.0f);
  f.confidence = Image(W, H, 1, 1.0f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < 40; ++x) f.range.at(x, y) = 10.0f;
  const Image scan(W, H, 1, NAN);
  for (int guard : {5, 0}) {
    CompleteResult done;
    done.range = Image(W, H, 1, 20.0f);
    done.confidence = Image(W, H, 1, 0.2f);
    done.sky_mask = Image(W, H, 1, 0.0f);
    const nlohmann::json rec = fuse_stereo(done, scan, f, 5, guard);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        ASSERT_EQ(done.range.at(x, y), (x < (guard ? 35 : 40)) ? 10.0f : 20.0f) << "guard " << guard << " at " << x;
    EXPECT_EQ(rec.contains("stereo_fattening_px"), guard > 0);
  }
}

// KITTI's object calibration (the real file of 000001): fx from P2, the
// baseline (P2[0,3] - P3[0,3]) / fx = (44.857 + 339.524) / 721.538 = 0.5327
// m (KITTI's cameras 2 and 3 are ~0.54 m apart); tolerance 1 mm, the file's
// digits give far more. A file without P3 is refused, naming it.
class FuseKitti : public ScratchDirTest {};
TEST_F(FuseKitti, BaselineFromP2AndP3) {
  BRUME_REQUIRE_DATA("kitti_object_000001/calib/000001.txt");
  const std::string calib = data_path("kitti_object_000001/calib/000001.txt");
  DepthSource s;
  s.velodyne = data_path("kitti_object_000001/velodyne/000001.bin");
  s.kitti_calib = calib;
  s.stereo_right = "right.png";
  EXPECT_TRUE(s.fused());
  const StereoGeometry g = stereo_geometry(s, 1242, 375);
  EXPECT_NEAR(g.f_px, 721.5377, 1e-4);
  EXPECT_NEAR(g.baseline_m, 0.5327, 1e-3);
  EXPECT_NEAR(g.doffs_px, 0.0, 1e-9);
  EXPECT_NEAR(g.k.cx, 609.5593, 1e-4);
  {
    std::ifstream in(calib);
    std::ofstream o(p("nop3.txt"));
    for (std::string line; std::getline(in, line);)
      if (line.rfind("P3:", 0) != 0) o << line << "\n";
  }
  s.kitti_calib = p("nop3.txt");
  try {
    stereo_geometry(s, 1242, 375);
    FAIL() << "a calibration without P3 was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("has no P3"), std::string::npos) << e.what();
  }
}

struct FusedRun {
  double up_scan, up_fused, low_scan, low_fused;
  nlohmann::json record;
};

// The scan-only completion and the fused one of an ETH3D frame, through
// load_depth and complete_step (the path of every effect's --complete).
FusedRun fused_eth3d(const std::string& scene, const std::string& scratch) {
  const SimulatedScan e = kitti_like_scan(data_path("eth3d_two_view/" + scene + "/"));
  const std::string dir = data_path("eth3d_two_view/" + scene + "/");
  write_image(scratch, e.sparse, float_map());
  DepthSource s;
  s.range = scratch;
  s.calib = dir + "calib.txt";
  const LoadedDepth scan = load_depth(s, e.rgb.width, e.rgb.height);
  s.stereo_right = dir + "im1.png";
  s.stereo_left = dir + "im0.png";
  const LoadedDepth both = load_depth(s, e.rgb.width, e.rgb.height);
  RangeStep step;
  step.complete = CompleteMode::on;
  const CompletedRange a = complete_step(scan.range, e.rgb, with_camera(step, scan));
  const CompletedRange b = complete_step(both.range, e.rgb, with_camera(step, both));
  FusedRun r;
  r.up_scan = share_off(a.range, e.truth, 0, e.top), r.up_fused = share_off(b.range, e.truth, 0, e.top);
  const int H = e.truth.height;
  r.low_scan = share_off(a.range, e.truth, e.top, H), r.low_fused = share_off(b.range, e.truth, e.top, H);
  r.record = b.record;
  r.record["depth"] = both.record;
  return r;
}

// ETH3D playground_1l and terrace, the KITTI-like scan (48 full rows over the
// lower 60 %, nothing above), the share of ground-truth pixels off by > 10 %:
//  - lower 60 %: at most the scan-only share + 0.02 (issue 52's target;
//    measured 0.07 % and 0.04 %, the scan wins there);
//  - upper 40 %, playground_1l: at most half the scan-only share (the
//    issue's target; measured 14.9 % against 79.0 %: its canopies overhang
//    nearer than the scan's top, which no continuation knows);
//  - upper 40 %, terrace: at most half the scan-only share as well
//    (measured 0.38 % against 1.09 %): the planar continuation is already
//    right there but beside the pillar, where the matcher's foreground
//    fattening (4.3 % of the upper 40 % when the pair is taken alone) gave
//    0.64 % before the fattening guard (complete-stereo-fattening 5).
// The fit's scale within 5 % of 1 and offset within 1 px: the ETH3D
// calibration is right, so the fit must find (about) the identity
// (measured 0.99 and 0.98, +0.2-0.3 px: the matcher's sub-pixel bias).
class FuseEth3d : public ScratchDirTest {};
TEST_F(FuseEth3d, SecondViewFillsAboveTheScan) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/im1.png");
  for (const char* scene : {"playground_1l", "terrace"}) {
    if (!have_data(std::string("eth3d_two_view/") + scene + "/im1.png")) continue;
    const FusedRun r = fused_eth3d(scene, p(std::string(scene) + ".pfm"));
    const nlohmann::json& fit = r.record["stereo_fusion"]["fit"];
    std::printf("%s: off by > 10 %%, upper 40 %%: scan only %.2f %%, fused %.2f %%; lower 60 %%: %.2f %%, %.2f %%; "
                "fit scale %.4f offset %.3f px over %zu pixels; stereo took %.1f %% of the frame\n",
                scene, 100 * r.up_scan, 100 * r.up_fused, 100 * r.low_scan, 100 * r.low_fused,
                fit["scale"].get<double>(), fit["offset_px"].get<double>(),
                fit["pixels_both_see"].get<std::size_t>(),
                100 * r.record["stereo_fusion"]["stereo_fraction"].get<double>());
    EXPECT_LE(r.up_fused, 0.5 * r.up_scan) << scene;
    EXPECT_EQ(r.record["stereo_fusion"]["stereo_fattening_px"], 5) << scene;
    EXPECT_LE(r.low_fused, r.low_scan + 0.02) << scene;
    EXPECT_NEAR(fit["scale"].get<double>(), 1.0, 0.05) << scene;
    EXPECT_NEAR(fit["offset_px"].get<double>(), 0.0, 1.0) << scene;
    // The search range came from the scan, not the coarse pass.
    EXPECT_GT(r.record["depth"]["stereo"]["search"]["z_min_m"].get<double>(), 0.0) << scene;
  }
}

class FuseCli : public ScratchDirTest {
 protected:
  std::string e = data_path("eth3d_two_view/terrace/");
  // The simulated scan of terrace as a file.
  std::string sparse() {
    write_image(p("sparse.pfm"), kitti_like_scan(e).sparse, float_map());
    return p("sparse.pfm");
  }
};

// The docs' example end to end: a dense map, the confidence, the record with
// the fit, and `brume run` repeating it bit for bit.
TEST_F(FuseCli, DepthCompleteWithStereoRight) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/im1.png");
  const std::string args = "depth complete --range " + sparse() + " --image " + e + "im0.png --stereo-right " + e +
                           "im1.png --calib " + e + "calib.txt";
  const CliRun r = run(args + " --out " + p("dense.pfm") + " --confidence " + p("conf.pfm") + " --record " +
                       p("rec.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("rec.json"));
  const nlohmann::json& fu = rec["complete"]["stereo_fusion"];
  // (9.5 % of terrace's frame; 11.5 % without the fattening guard)
  EXPECT_GT(fu["stereo_fraction"].get<double>(), 0.05) << fu.dump(2);
  EXPECT_TRUE(fu["fit"].contains("residuals_after"));
  EXPECT_TRUE(rec["inputs"]["depth"]["stereo"].contains("matching"));
  const CliRun again = run("run " + p("rec.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  const Image a = read_scalar(p("dense.pfm")), b = read_scalar(p("again/dense.pfm"));
  ASSERT_EQ(a.data.size(), b.data.size());
  EXPECT_EQ(0, std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)));
  // A record made before the fattening guard (no complete-stereo-fattening
  // in its job) repeats the rule before it, --complete-stereo-fattening 0.
  ASSERT_EQ(run(args + " --complete-stereo-fattening 0 --out " + p("old.pfm")).status, 0);
  nlohmann::json old = rec;
  ASSERT_EQ(old["job"]["complete"].erase("complete-stereo-fattening"), 1u) << rec["job"].dump(2);
  std::ofstream(p("old.json")) << old.dump(2);
  const CliRun replay = run("run " + p("old.json") + " --out-dir " + p("old-dir"));
  ASSERT_EQ(replay.status, 0) << replay.output;
  const Image c = read_scalar(p("old.pfm")), d = read_scalar(p("old-dir/dense.pfm"));
  ASSERT_EQ(c.data.size(), d.data.size());
  EXPECT_EQ(0, std::memcmp(c.data.data(), d.data.data(), c.data.size() * sizeof(float)));
  EXPECT_NE(0, std::memcmp(a.data.data(), c.data.data(), a.data.size() * sizeof(float)));
  // An effect with --complete: the same fusion (the record's complete block).
  const CliRun h = run("haze --range " + p("sparse.pfm") + " --image " + e + "im0.png --stereo-right " + e +
                       "im1.png --calib " + e + "calib.txt --visibility 50 --out " + p("h.png") + " --record " +
                       p("h.json"));
  ASSERT_EQ(h.status, 0) << h.output;
  EXPECT_NE(read_json(p("h.json")).dump().find("stereo_fusion"), std::string::npos);
}

// Bad inputs: each a clear error naming the flag and the fix, exit non-zero,
// nothing written.
TEST_F(FuseCli, Errors) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/im1.png");
  const std::string scan = sparse(), im0 = e + "im0.png", im1 = e + "im1.png", calib = e + "calib.txt";
  auto fails = [&](const std::string& args, const std::string& says) {
    const CliRun r = run(args + " --out " + p("x.pfm"));
    EXPECT_NE(r.status, 0) << args;
    EXPECT_NE(r.output.find(says), std::string::npos) << args << "\n" << r.output;
    EXPECT_FALSE(fs::exists(p("x.pfm"))) << args;
  };
  const std::string base = "depth complete --range " + scan + " --image " + im0;
  // A right view of another size than the image.
  write_image(p("small.png"), Image(300, 200, 3, 0.5f), WriteOptions{});
  fails(base + " --stereo-right " + p("small.png") + " --calib " + calib, "300x200");
  // No calibration at all.
  fails(base + " --stereo-right " + im1, "needs the pair's calibration");
  // A calib.txt of another size (playground's, 941x490, beside terrace's 713x434).
  if (have_data("eth3d_two_view/playground_1l/calib.txt"))
    fails(base + " --stereo-right " + im1 + " --calib " + data_path("eth3d_two_view/playground_1l/calib.txt"),
          "the calibration must be the pair's");
  // --complete off on an effect: the fusion is the completion's.
  fails("haze --range " + scan + " --image " + im0 + " --stereo-right " + im1 + " --calib " + calib +
            " --visibility 50 --complete off",
        "--complete off");
  // depth convert converts one source.
  fails("depth convert --range " + scan + " --stereo-right " + im1 + " --stereo-left " + im0 + " --calib " + calib,
        "fused with a sparse source by the completion");
}

}  // namespace
