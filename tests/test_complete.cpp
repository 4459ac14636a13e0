// brume tests — depth completion (brume/complete.hpp, `brume depth complete`,
// `--complete` on the effects and in `brume batch`).
//
// On KITTI object frame 000001 (../shared/data, skipped when absent):
//  - 10 % of the lidar points held out at random (seeds 1-10), completed
//    from the rest, KITTI depth completion's metrics at the held-out pixels
//    against IP-Basic (Ku et al.'s morphological baseline) written in
//    tests/ip_basic.hpp (plain loops, no OpenCV, so that it is independent
//    of brume's pilot), on the returns the occlusion rule keeps and on all;
//  - the labelled truck and car keep their distance;
//  - the sky rule: the open sky stays unknown, the trees above the scan are
//    structure;
//  - bad inputs and the command line end to end.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "brume/complete.hpp"
#include "brume/depth.hpp"
#include "brume/depth_source.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "depth/sky_check.hpp"
#include "eth3d_scan.hpp"
#include "ip_basic.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;
using brume::ip_basic::ku_baseline;

namespace {

const std::string kKitti = "kitti_object_000001/";
std::string kitti(const std::string& rel) { return data_path(kKitti + rel); }

struct KittiFrame {
  Image rgb;
  LidarImage scan;
};
KittiFrame load_kitti() {
  KittiFrame f;
  f.rgb = read_color(kitti("image_2/000001.png"));
  f.scan = project_velodyne(kitti("velodyne/000001.bin"), read_kitti_calib(kitti("calib/000001.txt")), f.rgb.width,
                            f.rgb.height);
  return f;
}

double median_in(const Image& im, int l, int t, int r, int b) {
  std::vector<float> v;
  for (int y = t; y <= b; ++y)
    for (int x = l; x <= r; ++x)
      if (std::isfinite(im.at(x, y))) v.push_back(im.at(x, y));
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

// Held-out lidar points (issue 52, item 3): 10 % of the returns held out at
// random with each of the seeds 1-10, completed from the rest by brume (the
// default parameters, as for --velodyne: occlusion auto on a scan from
// beside the camera) and by IP-Basic's "fast" configuration as
// reimplemented in tests/ip_basic.hpp (plain loops, no OpenCV, so that it is
// independent of brume's pilot), both here on the same held-out sets; KITTI
// depth completion's metrics on planar depth (tests/ip_basic.hpp), the mean
// over the ten seeds.
//
// The truth: the held-out returns that the occlusion rule (occluded_returns,
// brume/complete.hpp step 0), applied to the FULL scan, keeps. A return it
// drops (2.6 % of this frame's) has a nearer return just below or beside it:
// a background point the scanner saw past a foreground edge or through
// glass, where the camera sees the foreground; a completion for the camera
// should not reproduce it, so neither method is scored there. Both are
// scored on the same set. All held-out returns are printed too.
//
// Targets (issue 52): on that truth, brume's MAE <= IP-Basic's and RMSE
// <= 0.9x IP-Basic's. With step 2b (complete-edges image) brume reaches
// 0.861x and 0.899x (2026-12-07; seeds 101-110, a check against tuning to
// these: 0.859x, 0.897x), so the RMSE bound has a margin of 0.1 %: the
// computation is deterministic (row bands, fixed order) and the same on
// every thread count, but another compiler's float rounding could move the
// some 1 800 errors' mean by that much; a failure there is worth a look, not a
// widened bound. On all held-out returns brume's RMSE is 0.997x (its
// completion replaces the dropped background returns by the foreground):
// checked against 1.02x, a regression bound.
TEST(Complete, HeldOutReturnsAgainstIpBasicTenSeeds) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const KittiFrame f = load_kitti();
  const KittiCalib cal = read_kitti_calib(kitti("calib/000001.txt"));
  Intrinsics cam;
  cam.fx = cal.P2[0], cam.fy = cal.P2[5], cam.cx = cal.P2[2], cam.cy = cal.P2[6];
  const Image& full = f.scan.range;
  const std::vector<std::uint8_t> occluded = occluded_returns(full);
  CompleteParams p;  // the defaults, for a scan from beside the camera (as --velodyne gives it)
  p.offset_scan = true;
  std::vector<std::size_t> known;
  std::size_t n_occluded = 0;
  for (std::size_t i = 0; i < full.pixels(); ++i)
    if (std::isfinite(full.data[i])) known.push_back(i), n_occluded += occluded[i];
  EXPECT_LT(n_occluded, known.size() / 20);  // a few per cent of the returns
  ip_basic::DcMetrics mean[2][2];  // [brume, IP-Basic][truth, all]
  std::size_t missing = 0, held_n = 0;
  for (int seed = 1; seed <= 10; ++seed) {
    const ip_basic::HeldOut h = ip_basic::hold_out(full, known, occluded, seed);
    const Image ours = complete_range(h.sparse, f.rgb, p, 0, &cam).range;
    const Image ipb = ku_baseline(h.sparse);
    for (int m = 0; m < 2; ++m)
      for (int s = 0; s < 2; ++s) {
        const ip_basic::DcMetrics d = ip_basic::dc_metrics(m ? ipb : ours, full, s ? h.held : h.kept, cam);
        if (m == 1) {
          EXPECT_EQ(d.missing, 0u);
        }
        if (m == 0 && s == 1) missing += d.missing, held_n += h.held.size();
        mean[m][s].mae_mm += d.mae_mm / 10, mean[m][s].rmse_mm += d.rmse_mm / 10;
        mean[m][s].imae_per_km += d.imae_per_km / 10, mean[m][s].irmse_per_km += d.irmse_per_km / 10;
      }
  }
  for (int s = 0; s < 2; ++s)
    std::printf("%s, mean of seeds 1-10: brume MAE %.0f mm RMSE %.0f mm iMAE %.3f iRMSE %.3f /km; IP-Basic MAE %.0f "
                "RMSE %.0f iMAE %.3f iRMSE %.3f; ratio MAE %.3f RMSE %.3f\n",
                s ? "all held-out returns" : "held-out returns the occlusion rule keeps", mean[0][s].mae_mm,
                mean[0][s].rmse_mm, mean[0][s].imae_per_km, mean[0][s].irmse_per_km, mean[1][s].mae_mm,
                mean[1][s].rmse_mm, mean[1][s].imae_per_km, mean[1][s].irmse_per_km,
                mean[0][s].mae_mm / mean[1][s].mae_mm, mean[0][s].rmse_mm / mean[1][s].rmse_mm);
  // Every held-out return lies inside the scan: a value for all but at most
  // 0.5 % (an isolated return off a wire or a twig that the sky rule takes).
  EXPECT_LE(missing, held_n / 200);
  EXPECT_LE(mean[0][0].mae_mm, mean[1][0].mae_mm);
  EXPECT_LE(mean[0][0].rmse_mm, 0.9 * mean[1][0].rmse_mm);
  EXPECT_LE(mean[0][1].rmse_mm, 1.02 * mean[1][1].rmse_mm);
}

// The occlusion rule itself: a background return (40 m) seen between the
// returns of a nearer object (10 m) on the scan line below and beside it is
// dropped and completed with the object's range; the object's returns, the
// background's away from the object and a ground-like gradient (a few per
// cent per line) are kept; --complete-occlusion off keeps every return, and
// auto drops them only from a scan taken from beside the camera.
TEST(Complete, OcclusionDropsBackgroundSeenPastAnEdge) {
  const int W = 40, H = 30;
  Image rgb(W, H, 3, 0.3f), sparse(W, H, 1, NAN);
  for (int x = 0; x < W; ++x) {
    for (int y = 2; y < 12; y += 4) sparse.at(x, y) = 40.0f;  // background lines
    for (int y = 20; y < H; y += 4) sparse.at(x, y) = 20.0f - 0.2f * y;    // ground-like: nearer line by line
  }
  for (int x = 10; x < 20; ++x) sparse.at(x, 10) = 10.0f;  // the object's top line
  sparse.at(15, 6) = 40.0f;
  sparse.at(15, 9) = 40.0f;  // seen past the object's top edge: 1 row above its returns
  const std::vector<std::uint8_t> o = occluded_returns(sparse);
  auto at = [&](int x, int y) { return o[static_cast<std::size_t>(y) * W + x]; };
  EXPECT_EQ(at(15, 9), 1);
  EXPECT_EQ(at(12, 6), 1);  // 4 rows above the object's line, within the window's 8
  EXPECT_EQ(at(5, 6), 0);   // beside the object, more than 3 columns away
  EXPECT_EQ(at(15, 10), 0);
  for (int y = 20; y < H; y += 4) EXPECT_EQ(at(25, y), 0) << y;
  CompleteParams scan;  // auto, the default, on a scan from beside the camera
  scan.offset_scan = true;
  const CompleteResult c = complete_range(sparse, rgb, scan);
  EXPECT_NEAR(c.range.at(15, 9), 10.0f, 0.5f);
  EXPECT_LT(c.confidence.at(15, 9), 1.0f);
  EXPECT_GT(c.occluded, 0u);
  EXPECT_EQ(complete_record(scan, c)["complete_occlusion"], "on");
  CompleteParams on;
  on.occlusion = CompleteOcclusion::on;
  EXPECT_EQ(complete_range(sparse, rgb, on).occluded, c.occluded);
  CompleteParams off;
  off.occlusion = CompleteOcclusion::off;
  off.offset_scan = true;
  const CompleteResult k = complete_range(sparse, rgb, off);
  EXPECT_EQ(k.range.at(15, 9), 40.0f);
  EXPECT_EQ(k.occluded, 0u);
  EXPECT_FALSE(complete_record(off, k).contains("complete_occlusion"));
  const CompleteResult a = complete_range(sparse, rgb);  // auto on a map seen from the camera
  EXPECT_EQ(a.range.at(15, 9), 40.0f);
  EXPECT_EQ(a.occluded, 0u);
  EXPECT_NE(complete_record({}, a)["complete_occlusion"].get<std::string>().find("off (auto"), std::string::npos);
}

// A labelled object keeps its distance: the median completed range inside
// the truck's and the car's 2D boxes (label_2) against the median of the scan
// points in the same boxes (tolerances below).
TEST(Complete, LabelledObjectsKeepTheirDistance) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const KittiFrame f = load_kitti();
  const CompleteResult c = complete_range(f.scan.range, f.rgb);
  struct Box {
    const char* name;
    int l, t, r, b;
    double expect_m;
  };
  // Boxes of label_2, shrunk by 2 px; the rear of the truck at ~63 m, the car at ~59 m (issue 40).
  for (Box box : {Box{"truck", 601, 158, 627, 187, 63.0}, Box{"car", 390, 184, 421, 201, 59.0}}) {
    const double scan = median_in(f.scan.range, box.l, box.t, box.r, box.b);
    const double done = median_in(c.range, box.l, box.t, box.r, box.b);
    const int qx = (box.r - box.l) / 4, qy = (box.b - box.t) / 4;
    const double scan_c = median_in(f.scan.range, box.l + qx, box.t + qy, box.r - qx, box.b - qy);
    const double done_c = median_in(c.range, box.l + qx, box.t + qy, box.r - qx, box.b - qy);
    std::printf("%s: scan median %.2f m, completed median %.2f m; central half: %.2f m, %.2f m\n", box.name, scan,
                done, scan_c, done_c);
    EXPECT_NEAR(scan, box.expect_m, 2.0) << box.name;
    // 3 % (1.8 m at 60 m): the boxes also hold road, background and, at the
    // car, the guard rail in front of it (30-45 m), which the completion
    // counts at every pixel and the scan only at its few returns (10 in the
    // car's box, 70 in the truck's). The central half is printed, not checked: at the
    // car the rail's share of it moves with the refinement's radius
    // (59.1 m at r = 6, 55.4 m at r = 5).
    EXPECT_NEAR(done, scan, 0.03 * scan) << box.name;
    // Every pixel of the box has a range (the objects lie inside the scan).
    for (int y = box.t; y <= box.b; ++y)
      for (int x = box.l; x <= box.r; ++x) ASSERT_TRUE(std::isfinite(c.range.at(x, y))) << box.name << " " << x << "," << y;
  }
}

// The sky rule on KITTI: the open sky above the road stays unknown; the
// trees on the left, above the scan's upper limit (row ~120), are structure
// with a low confidence; measurements keep their value and confidence 1.
TEST(Complete, SkyStaysUnknownAndTreesAboveTheScanAreStructure) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const KittiFrame f = load_kitti();
  const CompleteResult c = complete_range(f.scan.range, f.rgb);
  EXPECT_GT(c.scan_top_row, 110);
  auto fraction = [&](int l, int t, int r, int b, auto pred) {
    std::size_t n = 0, k = 0;
    for (int y = t; y <= b; ++y)
      for (int x = l; x <= r; ++x, ++n) k += pred(x, y) ? 1 : 0;
    return static_cast<double>(k) / static_cast<double>(n);
  };
  // Open sky: above the road's vanishing point.
  EXPECT_GT(fraction(420, 0, 600, 60, [&](int x, int y) { return std::isnan(c.range.at(x, y)); }), 0.97);
  // Trees on the left, rows 60-110 (above the scan): a range, low confidence.
  EXPECT_GT(fraction(10, 60, 70, 110, [&](int x, int y) { return std::isfinite(c.range.at(x, y)); }), 0.97);
  EXPECT_LT(fraction(10, 60, 70, 110, [&](int x, int y) { return c.confidence.at(x, y) > 0.2f; }), 0.05);
  // The blue sky at the top right (x 780-1010, rows 0-120; sRGB blue > red
  // + 0.15 and > 0.6), beside the trees: sky, also its rim along the
  // treeline (the cyan halo under haze and rain while it took the trees'
  // depth). Measured 2026-12-07: 92.4 % (80.4 % by the rule of records
  // before complete-sky-edge, whose roughness window left a 2-4 px rim);
  // the rest lies between the crowns' leaves, mixed with them. 0.9 holds
  // it with room for rounding and fails on a return of the rim.
  auto srgb = [](float v) { return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f; };
  std::size_t blue = 0, blue_sky = 0;
  for (int y = 0; y <= 120; ++y)
    for (int x = 780; x <= 1010; ++x) {
      const float r = srgb(f.rgb.at(x, y, 0)), b = srgb(f.rgb.at(x, y, 2));
      if (!(b > r + 0.15f && b > 0.6f) || std::isfinite(f.scan.range.at(x, y))) continue;
      ++blue;
      blue_sky += c.sky_mask.at(x, y) > 0.0f;
    }
  const double blue_share = static_cast<double>(blue_sky) / static_cast<double>(blue);
  std::printf("KITTI blue sky at the top right: %zu pixels, %.1f %% sky\n", blue, 100 * blue_share);
  EXPECT_GT(blue_share, 0.9);
  for (std::size_t i = 0; i < c.range.pixels(); ++i) {
    const float r = f.scan.range.data[i];
    if (std::isfinite(r)) {
      ASSERT_EQ(c.range.data[i], r);
      ASSERT_EQ(c.confidence.data[i], 1.0f);
    }
    ASSERT_GE(c.confidence.data[i], 0.0f);
    ASSERT_LE(c.confidence.data[i], 1.0f);
  }
}

// No depth is invented across an image edge: two layers, 10 m behind a dark
// left half and 50 m behind a bright right half, sampled on every 4th row
// and column; every completed pixel takes one of the two ranges, the one of
// its side of the edge (the colour edge, not the nearest sample).
TEST(Complete, DepthEdgesFollowImageEdges) {
  const int W = 96, H = 64;
  Image rgb(W, H, 3), sparse(W, H, 1, NAN);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const bool right = x >= 50;
      for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = right ? 0.6f : 0.05f;
      if (y % 4 == 1 && x % 4 == 0) sparse.at(x, y) = right ? 50.0f : 10.0f;
    }
  const CompleteResult c = complete_range(sparse, rgb);
  for (int y = 8; y < H - 8; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = c.range.at(x, y);
      ASSERT_TRUE(std::isfinite(r)) << x << "," << y;
      // Both layers are constant, so any value but theirs is made up: the
      // only tolerance is float rounding of the weighted mean (1e-5 relative).
      ASSERT_NEAR(r, x >= 50 ? 50.0f : 10.0f, 1e-4f * r) << x << "," << y;
    }
}

// Step 2b (complete-edges image): a foreground object and the background
// beside it of the same colour (a dark car before a dark shadow), told apart
// only by the object's outline, a 1 px bright line. The pilot keeps the
// nearest return, so with complete-edges nearest (the rule of records before
// issue 52) the background beside the outline takes the object's 10 m; with
// image the returns behind the outline no longer count as the pixel's side
// and the far layer (50 m) is taken. Both layers are constant: the only
// tolerance is float rounding of the weighted mean (1e-4 relative).
TEST(Complete, DepthEdgeTakesTheLayerOfItsOwnSide) {
  const int W = 96, H = 64, edge = 49;
  Image rgb(W, H, 3), sparse(W, H, 1, NAN);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = x == edge ? 0.8f : 0.05f;
      if (y % 4 == 1 && x % 4 == 0 && x != edge) sparse.at(x, y) = x > edge ? 50.0f : 10.0f;
    }
  CompleteParams image, nearest;
  nearest.edges = CompleteEdges::nearest;
  const CompleteResult a = complete_range(sparse, rgb, image), b = complete_range(sparse, rgb, nearest);
  std::size_t wrong_nearest = 0;
  for (int y = 8; y < H - 8; ++y)
    for (int x = 0; x < W; ++x) {
      if (x == edge) continue;  // the outline itself belongs to either side
      const float want = x > edge ? 50.0f : 10.0f, r = a.range.at(x, y);
      ASSERT_NEAR(r, want, 1e-4f * want) << x << "," << y;
      wrong_nearest += std::abs(b.range.at(x, y) - want) > 0.1f * want;
    }
  // The old rule's error, which step 2b mends: at least a column's worth.
  EXPECT_GE(wrong_nearest, static_cast<std::size_t>(H - 16)) << "the nearest layer no longer crosses the outline";
}

// The result does not depend on the thread count (row bands, fixed order).
TEST(Complete, SameResultOnOneAndTwoThreads) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const KittiFrame f = load_kitti();
  const CompleteResult a = complete_range(f.scan.range, f.rgb, {}, 1), b = complete_range(f.scan.range, f.rgb, {}, 2);
  ASSERT_EQ(a.range.data.size(), b.range.data.size());
  for (std::size_t i = 0; i < a.range.data.size(); ++i) {
    const float x = a.range.data[i], y = b.range.data[i];
    ASSERT_TRUE((std::isnan(x) && std::isnan(y)) || x == y) << i;
    ASSERT_EQ(a.confidence.data[i], b.confidence.data[i]) << i;
  }
}

TEST(Complete, LibraryErrors) {
  Image rgb(8, 6, 3, 0.5f);
  EXPECT_NE(error_of([&] { complete_range(Image(8, 6, 1, NAN), rgb); }).find("no measured pixel"), std::string::npos);
  EXPECT_NE(error_of([&] { complete_range(Image(9, 6, 1, 5.0f), rgb); }).find("same size"), std::string::npos);
  EXPECT_NE(error_of([&] { complete_range(Image(8, 6, 1, -1.0f), rgb); }).find("negative"), std::string::npos);
  CompleteParams p;
  p.radius_px = 0;
  EXPECT_NE(error_of([&] { complete_range(Image(8, 6, 1, 5.0f), rgb, p); }).find("--complete-radius"),
            std::string::npos);
}

// ---- above the scan (issue 52): structure continues what the scan saw ----

// A pixel's range over its planar depth: sqrt(1 + ((x - cx)/fx)^2 + ((y - cy)/fy)^2).
double stretch(const Intrinsics& k, int x, int y) {
  const double a = (x - k.cx) / k.fx, b = (y - k.cy) / k.fy;
  return std::sqrt(1.0 + a * a + b * b);
}

// The scan of tests/eth3d_scan.hpp for an ETH3D two-view scene of the data.
using eth3d::SimulatedScan;
using eth3d::share_off;
SimulatedScan eth3d_kitti_like(const std::string& scene) {
  return eth3d::kitti_like_scan(data_path("eth3d_two_view/" + scene + "/"));
}

// ETH3D terrace with the simulated scan: the upper 40 % (no return there)
// has at most 15 % of its ground-truth pixels off by more than 10 % with the
// planar method (issue 52's target; 61 % with the column rule). The 15 %
// leaves room for what no continuation from below can know: surfaces that
// are not vertical (the terrace's roof, seen from below, comes nearer
// towards the top of the frame) and objects that begin above the scan.
// playground_1l is printed, not checked: its upper part is mostly wooden
// canopies overhanging nearer than anything the scan's top rows see (no
// continuation from below can know them; the fusion with the
// second view is meant for it).
TEST(Complete, AboveTheScanStructureContinuesOnEth3d) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/disp0.pfm");
  for (const char* scene : {"terrace", "playground_1l"}) {
    if (!have_data(std::string("eth3d_two_view/") + scene + "/im0.png")) continue;
    const SimulatedScan e = eth3d_kitti_like(scene);
    CompleteParams column, planar;
    column.method = CompleteMethod::column;
    planar.method = CompleteMethod::planar;
    const CompleteResult a = complete_range(e.sparse, e.rgb, column, 0, &e.k);
    const CompleteResult b = complete_range(e.sparse, e.rgb, planar, 0, &e.k);
    std::size_t n = 0;
    const double off_a = share_off(a.range, e.truth, 0, e.top, &n), off_b = share_off(b.range, e.truth, 0, e.top);
    const double low_a = share_off(a.range, e.truth, e.top, e.truth.height),
                 low_b = share_off(b.range, e.truth, e.top, e.truth.height);
    std::printf("%s, upper 40 %% (%zu ground-truth pixels) off by > 10 %%: column %.1f %%, planar %.1f %%; lower "
                "60 %%: %.1f %%, %.1f %%\n",
                scene, n, 100 * off_a, 100 * off_b, 100 * low_a, 100 * low_b);
    if (std::string(scene) == "terrace") {
      EXPECT_LE(off_b, 0.15);
    }
    // Below the scan's top the methods agree (the planar rule changes only
    // what lies above each column's topmost return).
    EXPECT_NEAR(low_b, low_a, 0.005) << scene;
  }
}

// Step 2b does not make a dense map worse between the scan lines: ETH3D
// with the simulated scan of the "above the scan" test (48 full rows over
// the lower 60 %; the pixels between them with ground truth), the MAE, RMSE
// and share off by > 10 % with complete-edges image at most nearest's
// (terrace 8.0/40.3 mm against 8.0/40.6 mm, playground_1l 26.7/124.0 mm
// against 26.8/126.0 mm, 2026-12-07); the tolerance 0.2 % is float rounding
// of sums over 10^5 pixels, far below a real change (step 2b moves them by
// 1-2 %).
TEST(Complete, DepthEdgesNoWorseBetweenScanLinesOnEth3d) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/disp0.pfm");
  for (const char* scene : {"terrace", "playground_1l"}) {
    if (!have_data(std::string("eth3d_two_view/") + scene + "/im0.png")) continue;
    const SimulatedScan e = eth3d_kitti_like(scene);
    double m[2][3] = {};  // [image, nearest][MAE, RMSE, share off]
    for (int k = 0; k < 2; ++k) {
      CompleteParams p;
      if (k) p.edges = CompleteEdges::nearest;
      const Image r = complete_range(e.sparse, e.rgb, p, 0, &e.k).range;
      double a = 0, a2 = 0;
      std::size_t n = 0, off = 0;
      for (int y = e.top; y < e.truth.height; ++y)
        for (int x = 0; x < e.truth.width; ++x) {
          const float t = e.truth.at(x, y), v = r.at(x, y);
          if (!std::isfinite(t) || std::isfinite(e.sparse.at(x, y))) continue;
          ++n;
          if (!std::isfinite(v)) {
            ++off;
            continue;
          }
          a += std::abs(v - t), a2 += (v - t) * (v - t), off += std::abs(v - t) > 0.1f * t;
        }
      ASSERT_GT(n, 10000u) << scene;
      m[k][0] = a / n, m[k][1] = std::sqrt(a2 / n), m[k][2] = static_cast<double>(off) / n;
    }
    std::printf("%s between the scan lines: complete-edges image MAE %.2f mm RMSE %.2f mm off %.3f %%; nearest %.2f "
                "mm, %.2f mm, %.3f %%\n",
                scene, 1e3 * m[0][0], 1e3 * m[0][1], 100 * m[0][2], 1e3 * m[1][0], 1e3 * m[1][1], 100 * m[1][2]);
    for (int j = 0; j < 3; ++j) EXPECT_LE(m[0][j], 1.002 * m[1][j]) << scene << " figure " << j;
  }
}

// KITTI 000001, the trees on the right above the scan (x 850-1240, y
// 10-170, the pixels above each column's topmost return): the completed
// planar depth lies within +-25 % of the planar depth of the column's three
// topmost returns (their median) at >= 85 % of them (issue 52's regression
// target; 21 % with the column rule, whose values there are the pilot's far
// fills). 25 %: the trees' crowns are not planes (leaves at 11-25 m, with
// gaps onto farther trees), so a continuation is right only to that degree;
// the pixels the sky rule leaves unknown (sky between the crowns) are not
// counted, and their share is printed.
TEST(Complete, TreesAboveTheKittiScanContinueTheirReturns) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const KittiFrame f = load_kitti();
  const KittiCalib cal = read_kitti_calib(kitti("calib/000001.txt"));
  Intrinsics k;
  k.fx = cal.P2[0], k.fy = cal.P2[5], k.cx = cal.P2[2], k.cy = cal.P2[6];
  float rmax = 0.0f;
  for (float r : f.scan.range.data)
    if (std::isfinite(r)) rmax = std::max(rmax, r);
  for (CompleteMethod m : {CompleteMethod::column, CompleteMethod::planar}) {
    CompleteParams p;
    p.method = m;
    const CompleteResult c = complete_range(f.scan.range, f.rgb, p, 0, &k);
    std::size_t n = 0, ok = 0, sky = 0;
    for (int x = 850; x <= 1240; ++x) {
      std::vector<double> z;
      int top = -1;
      for (int y = 0; y < f.scan.range.height && z.size() < 3; ++y)
        if (std::isfinite(f.scan.range.at(x, y))) {
          if (top < 0) top = y;
          z.push_back(f.scan.range.at(x, y) / stretch(k, x, y));
        }
      if (z.empty()) continue;
      std::sort(z.begin(), z.end());
      const double zref = z.size() == 2 ? 0.5 * (z[0] + z[1]) : z[z.size() / 2];
      for (int y = 10; y <= 170 && y < top; ++y) {
        if (c.sky_mask.at(x, y) > 0.0f) {
          ++sky;
          continue;
        }
        ++n;
        const float r = c.range.at(x, y);
        ok += std::isfinite(r) && std::abs(r / stretch(k, x, y) - zref) <= 0.25 * zref ? 1 : 0;
        // Never behind the sky: no continued range beyond the farthest return.
        if (m == CompleteMethod::planar) {
          ASSERT_LE(r, rmax) << x << "," << y;
        }
      }
    }
    const double share = static_cast<double>(ok) / static_cast<double>(n);
    std::printf("KITTI trees above the scan, %s: %zu pixels (%zu sky, not counted), %.1f %% within 25 %% of their "
                "column's top returns\n",
                enum_name(complete_method_names(), m).c_str(), n, sky, 100 * share);
    if (m == CompleteMethod::planar) {
      EXPECT_GE(share, 0.85);
    }
  }
}

// A vertical wall (planar depth 10 m, seen by a level pinhole camera) with
// scan rows over its lower half only: above them the planar method gives
// the wall's range within 1 % (z continued, not the range), where the column
// rule, repeating the range near the scan's top, is 5.6 % short at the top
// corners; the confidence falls with the distance from the last return.
// 1 %: the refined band just above the top returns (step 2) averages the
// returns' ranges over its window, and at the image's side edges the window
// is one-sided while the range grows towards the edge (0.8 % at x = 0); the
// continuation carries that band's value up.
TEST(Complete, PlanarContinuationOfAVerticalWall) {
  const int W = 120, H = 80;
  Intrinsics k;
  k.fx = k.fy = 100.0, k.cx = 59.5, k.cy = 39.5;
  Image rgb(W, H, 3), sparse(W, H, 1, NAN);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      // A dark wall with a faint texture above a white road marking (the
      // image's brightest 3 %): the wall is not bright, so never taken for sky.
      for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = y >= H - 2 ? 1.0f : 0.04f + 0.01f * ((x / 2 + y / 2) % 2);
      if (y >= 40 && y % 4 == 0) sparse.at(x, y) = static_cast<float>(10.0 * stretch(k, x, y));
    }
  const CompleteResult c = complete_range(sparse, rgb, {}, 0, &k);
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = c.range.at(x, y);
      ASSERT_TRUE(std::isfinite(r)) << x << "," << y;
      ASSERT_NEAR(r, 10.0 * stretch(k, x, y), 0.01 * r) << x << "," << y;
    }
  CompleteParams column;
  column.method = CompleteMethod::column;
  const CompleteResult old = complete_range(sparse, rgb, column, 0, &k);
  EXPECT_LT(old.range.at(0, 0), 0.96 * 10.0 * stretch(k, 0, 0));
  EXPECT_GT(c.confidence.at(60, 30), c.confidence.at(60, 5));
  EXPECT_LE(c.confidence.at(60, 30), 0.2f);
  const nlohmann::json rec = complete_record({}, c);
  EXPECT_EQ(rec["complete_method"], "planar");
  EXPECT_GT(rec["continued_fraction"].get<double>(), 0.4);
}

// The sky rule's brightness and edge (complete-sky-brightness,
// complete-sky-edge): a frame 96x64 whose top 40 rows, above a scan (every
// 4th row from 40, 10 m), hold a saturated white sky (left third) beside a
// deep blue one (GeoPose3K's Matterhorn sky, sRGB (0.14, 0.45, 0.82): luma
// 0.41, largest channel 0.82), a dark smooth block (sRGB ~0.15: a crown,
// rows 16-39, columns 60-79) standing in the blue and a dark pole
// (columns 44-45) from the top row down to the scan, and a bright red pole
// (sRGB (0.9, 0.3, 0.2): largest channel 0.9, as bright as the sky by it,
// but 0.7 away from the white beside it) at columns 20-21. Today's rule:
// every pixel of both skies is sky (NaN) -- also the sky right beside the
// block and the poles, where the 5x5 roughness window straddles the edge
// (the halo of KITTI 000001) --, and no pixel of the block or the poles is
// (the red one: the edge grows only into colours like the sky's).
// The rule of records before it (luma, no edge) leaves the blue sky
// structure (0.41 < 0.7 x the white's 1) and the white sky's rim beside the
// pole too: the test fails without the change.
TEST(Complete, BlueSkyBesideAWhiteOneIsSkyDarkStructureIsNot) {
  const int W = 96, H = 64;
  const float white[3] = {1.0f, 1.0f, 1.0f};
  // Linear RGB of sRGB (0.14, 0.45, 0.82), (0.15, 0.16, 0.14), 0.5.
  const float blue[3] = {0.01739f, 0.17064f, 0.63828f};
  const float dark[3] = {0.01961f, 0.02198f, 0.01739f};
  const float ground[3] = {0.21404f, 0.21404f, 0.21404f};
  auto is_block = [](int x, int y) { return y >= 16 && y < 40 && x >= 60 && x < 80; };
  const float red[3] = {0.78741f, 0.07324f, 0.03310f};
  auto is_pole = [](int x, int y) { return y < 40 && (x == 44 || x == 45); };
  auto is_red = [](int x, int y) { return y < 40 && (x == 20 || x == 21); };
  Image rgb(W, H, 3), sparse(W, H, 1, NAN);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float* c = y >= 40                          ? ground
                       : is_block(x, y) || is_pole(x, y) ? dark
                       : is_red(x, y)                    ? red
                       : x < 32                          ? white
                                                         : blue;
      for (int k = 0; k < 3; ++k) rgb.at(x, y, k) = c[k];
      if (y >= 40 && y % 4 == 0) sparse.at(x, y) = 10.0f;
    }
  const CompleteResult c = complete_range(sparse, rgb);
  std::size_t sky = 0, structure_as_sky = 0;
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < W; ++x) {
      // (row 39 lies within 1 px of the scan's top returns: never sky)
      if (is_block(x, y) || is_pole(x, y) || is_red(x, y) || y == 39) {
        ASSERT_TRUE(std::isfinite(c.range.at(x, y))) << x << "," << y;
        structure_as_sky += c.sky_mask.at(x, y) > 0.0f;
      } else {
        ASSERT_TRUE(std::isnan(c.range.at(x, y))) << x << "," << y;
        ++sky;
      }
    }
  EXPECT_EQ(structure_as_sky, 0u);
  EXPECT_EQ(c.sky, sky);
  const nlohmann::json rec = complete_record({}, c);
  EXPECT_EQ(rec["sky_brightness"], "max");
  EXPECT_EQ(rec["sky_edge_px"], 3);

  CompleteParams old;
  old.sky_brightness = CompleteSkyBrightness::luma;
  old.sky_edge_px = 0;
  old.sky_blue = 0.0;  // (and neither of the rules after it)
  old.sky_border = 0.0;
  const CompleteResult o = complete_range(sparse, rgb, old);
  EXPECT_TRUE(std::isfinite(o.range.at(90, 2)));  // the blue sky: structure by luma
  EXPECT_TRUE(std::isfinite(o.range.at(43, 2)));  // the white sky beside the pole: rough
  EXPECT_LT(o.sky, sky / 2);
  const nlohmann::json orec = complete_record(old, o);
  EXPECT_FALSE(orec.contains("sky_brightness"));  // as records before the rule
  EXPECT_FALSE(orec.contains("sky_edge_px"));
}

// A clear sky darker than the scene's snow, under a black border
// (GeoPose3K's Matterhorn photo: a panorama's warp leaves rows of black at
// the top, 2-40 px, and its sky near the top, sRGB ~(0.11, 0.36, 0.67), has
// a largest channel of 0.63-0.72 against 0.7 x the snow's 0.98). Synthetic:
// rows 0-1 black, 6 rows at the left corner; the sky sRGB (0.11, 0.36, 0.67)
// over rows 2-39; the lower 24 rows, measured, half of them white snow (so
// the 99th percentile of the largest channel is 1). Today's rule: every
// unmeasured pixel above the scan is sky -- the blue sky (blue exceeds red
// by 0.56 >= complete-sky-blue 0.2) and the black border it touches the top
// row through (<= complete-sky-border 0.03) --, and no measured pixel is.
// The rule of records before it (sky-blue 0, sky-border 0) finds no sky at
// all (the blue sky is dark, and the border cuts it from the top row): the
// test fails without the change.
TEST(Complete, ADarkBlueSkyUnderABlackBorderIsSky) {
  const int W = 96, H = 64;
  // Linear RGB of sRGB (0.11, 0.36, 0.67), 1, 0.5 and 0.
  const float blue[3] = {0.01177f, 0.10702f, 0.40724f};
  const float snow[3] = {1.0f, 1.0f, 1.0f}, rock[3] = {0.21404f, 0.21404f, 0.21404f}, black[3] = {0, 0, 0};
  auto is_border = [](int x, int y) { return y < 2 || (x < 8 && y < 6); };
  Image rgb(W, H, 3), sparse(W, H, 1, NAN);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float* c = y >= 40 ? (x < W / 2 ? snow : rock) : is_border(x, y) ? black : blue;
      for (int k = 0; k < 3; ++k) rgb.at(x, y, k) = c[k];
      if (y >= 40 && y % 4 == 0) sparse.at(x, y) = 1000.0f;
    }
  const CompleteResult c = complete_range(sparse, rgb);
  std::size_t sky = 0;
  for (int y = 0; y < 39; ++y)  // (row 39 lies within 1 px of the scan's top returns: never sky)
    for (int x = 0; x < W; ++x) {
      ASSERT_TRUE(std::isnan(c.range.at(x, y))) << x << "," << y;
      ASSERT_GT(c.sky_mask.at(x, y), 0.0f) << x << "," << y;
      ++sky;
    }
  EXPECT_EQ(c.sky, sky);
  const nlohmann::json rec = complete_record({}, c);
  EXPECT_EQ(rec["sky_blue"], 0.2);
  EXPECT_EQ(rec["sky_border"], 0.03);

  CompleteParams old;
  old.sky_blue = 0.0;
  old.sky_border = 0.0;
  const CompleteResult o = complete_range(sparse, rgb, old);
  EXPECT_EQ(o.sky, 0u);
  EXPECT_TRUE(std::isfinite(o.range.at(50, 10)));
  const nlohmann::json orec = complete_record(old, o);
  EXPECT_FALSE(orec.contains("sky_blue"));  // as records before the rule
  EXPECT_FALSE(orec.contains("sky_border"));
  // Each half alone: blue without the border is cut from the top row by it;
  // the border without blue has only the border as sky.
  CompleteParams blue_only, border_only;
  blue_only.sky_border = 0.0;
  border_only.sky_blue = 0.0;
  EXPECT_EQ(complete_range(sparse, rgb, blue_only).sky, 0u);
  const CompleteResult b = complete_range(sparse, rgb, border_only);
  EXPECT_TRUE(std::isnan(b.range.at(2, 2)));      // the border
  EXPECT_TRUE(std::isfinite(b.range.at(50, 10)));  // the sky: dark by brightness
}

// The same on the real photo: GeoPose3K's Matterhorn (a DEM's distances,
// -1 where the terrain model has none: the sky, and the warp's black border).
// With --complete on, the pixels the DEM leaves unknown above its terrain
// that the photo shows (not border-black) are sky at >= 95 % (measured
// 96.3 %; the rest, looked at, is the ridge left of the peak, which the photo
// shows up to ~57 rows above the DEM's outline -- the two are misregistered
// there --: mountain, rightly kept as structure), and no measured pixel is
// sky. The rule of records before it took none as sky (measured 0 %): the
// sky's top rows, largest channel 0.63-0.72, fall under 0.7 x the snow's
// 0.98, and the border cuts them from the top row.
TEST(Complete, MatterhornSkyIsSkyUnderItsBlackBorder) {
  BRUME_REQUIRE_DATA("geopose3k_matterhorn/distance.pfm");
  const std::string dir = data_path("geopose3k_matterhorn/");
  const Image rgb = read_color(dir + "photo.jpg");
  Image dist = read_scalar(dir + "distance.pfm");
  for (float& v : dist.data)
    if (v == -1.0f) v = NAN;
  const int W = dist.width, H = dist.height;
  std::vector<int> top(W, H);  // the DEM's topmost known row of each column
  for (int x = 0; x < W; ++x)
    for (int y = H - 1; y >= 0; --y)
      if (std::isfinite(dist.at(x, y))) top[x] = y;
  auto shown_sky = [&](int x, int y) {
    const float* c = rgb.row(y) + 3 * x;
    return y < top[x] && std::max({c[0], c[1], c[2]}) > 0.01f;  // linear 0.01: sRGB 0.1, not the border
  };
  for (const bool now : {true, false}) {
    CompleteParams p;
    if (!now) p.sky_blue = p.sky_border = 0.0;
    const CompleteResult c = complete_range(dist, rgb, p);
    std::size_t n = 0, sky = 0, measured_sky = 0;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const bool is_sky = c.sky_mask.at(x, y) > 0.0f;
        if (std::isfinite(dist.at(x, y))) measured_sky += is_sky;
        if (!shown_sky(x, y)) continue;
        ++n;
        sky += is_sky;
      }
    const double share = static_cast<double>(sky) / static_cast<double>(n);
    std::printf("Matterhorn, %s rule: %.1f %% of the %zu unknown pixels above the terrain are sky\n",
                now ? "today's" : "the old", 100 * share, n);
    EXPECT_EQ(measured_sky, 0u);
    if (now)
      EXPECT_GE(share, 0.95);
    else
      EXPECT_LT(share, 0.01);
  }
}

// The preparation's sky checked against the scene (src/depth/sky_check.hpp):
// an unknown region reaching the top is counted as sky by Hansard's rule, and
// its pixels below a known pixel of their column as under a surface. Exact
// counts on a synthetic frame: the top quarter unknown (sky, none under a
// surface); a "table" of known range across rows 14-15 of columns 10-49 with
// unknown range beneath it down to row 25 joined to the sky by column 5
// (one region: 12x64 + 40x10 + a 1 px wide joint), whose pixels under the
// table are under a surface; a hole of 30 px (1 %) away from the top is a
// hole, not sky.
TEST(Complete, PreparedSkyCheckCountsSkyUnderSurfaces) {
  const int W = 64, H = 48;
  Image range(W, H, 1, 10.0f);
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < W; ++x) range.at(x, y) = NAN;
  const PrepareParams p;
  PreparedSkyCheck a = check_prepared_sky(ConstImageView(range), p);
  EXPECT_EQ(a.pixels, static_cast<std::size_t>(W * H));
  EXPECT_EQ(a.sky, static_cast<std::size_t>(12 * W));
  EXPECT_EQ(a.under, 0u);
  for (int y = 16; y < 26; ++y)
    for (int x = 10; x < 50; ++x) range.at(x, y) = NAN;  // beneath the table (rows 14-15 stay known)
  for (int y = 12; y < 16; ++y) range.at(5, y) = NAN;     // the joint: column 5, rows 12-15 (left of the table)
  for (int y = 16; y < 17; ++y)
    for (int x = 5; x < 10; ++x) range.at(x, y) = NAN;  // row 16, columns 5-9: reaching beneath the table
  for (int y = 30; y < 33; ++y)
    for (int x = 52; x < 62; ++x) range.at(x, y) = 0.0f;  // a hole of 30 px
  a = check_prepared_sky(ConstImageView(range), p);
  // Sky: the top rows, the joint (4 + 5 px) and the region beneath the table (400 px).
  EXPECT_EQ(a.sky, static_cast<std::size_t>(12 * W + 4 + 5 + 400));
  // Under a surface: those below a known pixel of their column -- beneath the table, the joint's row 16
  // (columns 6-9 have row 12-15 known above them; column 5 has none).
  EXPECT_EQ(a.under, static_cast<std::size_t>(400 + 4));
  PrepareParams strict;
  strict.sky_min_fraction = strict.sky_large_fraction = 0.5;  // the region (38 %) no longer counts as sky
  EXPECT_EQ(check_prepared_sky(ConstImageView(range), strict).sky, 0u);
}

class CompleteCli : public ScratchDirTest {};

// Bad inputs through the command line: a scan with no point in view, an image
// of another size than the calibration's camera or the sparse map, a
// calibration file without one of its keys. Each a clear error, nothing written.
TEST_F(CompleteCli, BadInputs) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const std::string img = kitti("image_2/000001.png"), calib = kitti("calib/000001.txt");
  // Points 10 m behind the lidar (x < 0 in Velodyne coordinates) only.
  {
    std::ofstream o(p("behind.bin"), std::ios::binary);
    for (int i = 0; i < 100; ++i) {
      const float pt[4] = {-10.0f, static_cast<float>(i) * 0.1f - 5.0f, 0.0f, 0.5f};
      o.write(reinterpret_cast<const char*>(pt), sizeof pt);
    }
  }
  CliRun r = run("depth complete --image " + img + " --velodyne " + p("behind.bin") + " --kitti-calib " + calib +
                 " --out " + p("a.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("no point of the scan falls inside the image"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("a.exr")));
  // An image of half the size: the calibration's principal point is not near its centre.
  Image half(621, 188, 3, 0.5f);
  write_image(p("half.png"), half, WriteOptions{});
  r = run("depth complete --image " + p("half.png") + " --velodyne " + kitti("velodyne/000001.bin") +
          " --kitti-calib " + calib + " --out " + p("b.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("do not belong together"), std::string::npos) << r.output;
  // A sparse range map of another size than the image.
  WriteOptions data;
  data.is_color = false;
  write_image(p("small.exr"), Image(100, 50, 1, 7.0f), data);
  r = run("depth complete --image " + img + " --range " + p("small.exr") + " --out " + p("c.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("100x50"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("1242x375"), std::string::npos) << r.output;
  // A calibration file without Tr_velo_to_cam.
  {
    std::ifstream in(calib);
    std::ofstream o(p("calib.txt"));
    for (std::string line; std::getline(in, line);)
      if (line.rfind("Tr_velo_to_cam", 0) != 0) o << line << "\n";
  }
  r = run("depth complete --image " + img + " --velodyne " + kitti("velodyne/000001.bin") + " --kitti-calib " +
          p("calib.txt") + " --out " + p("d.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("lacks Tr_velo_to_cam"), std::string::npos) << r.output;
  for (const char* f : {"b.exr", "c.exr", "d.exr"}) EXPECT_FALSE(fs::exists(p(f))) << f;
}

// --complete-stereo-fattening guards the fusion with --stereo-right's view:
// given where no second view is fused (a sparse map alone, an effect's
// completion alone) it would change nothing, and is refused, naming the
// flag and the fix; nothing is written. Without it the same runs work.
TEST_F(CompleteCli, StereoFatteningWithoutASecondViewIsRefused) {
  Image rgb(64, 48, 3, 0.4f), sparse(64, 48, 1, NAN);
  for (int y = 24; y < 48; y += 4)
    for (int x = 0; x < 64; ++x) sparse.at(x, y) = 8.0f;
  write_image(p("im.png"), rgb, WriteOptions{});
  WriteOptions data;
  data.is_color = false;
  write_image(p("sparse.exr"), sparse, data);
  const std::string in = " --image " + p("im.png") + " --range " + p("sparse.exr");
  CliRun r = run("depth complete" + in + " --complete-stereo-fattening 3 --out " + p("a.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--complete-stereo-fattening guards the fusion"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--stereo-right"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("a.exr")));
  r = run("haze" + in + " --complete on --visibility 100 --complete-stereo-fattening 3 --out " + p("h.png"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--complete-stereo-fattening guards the fusion"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("h.png")));
  r = run("depth complete" + in + " --out " + p("a.exr"));
  EXPECT_EQ(r.status, 0) << r.output;
  r = run("haze" + in + " --complete on --visibility 100 --out " + p("h.png"));
  EXPECT_EQ(r.status, 0) << r.output;
}

// `brume depth complete` on KITTI end to end: the dense map, its confidence
// and the record naming the method and its parameters.
TEST_F(CompleteCli, DepthCompleteOnKitti) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const CliRun r = run("depth complete --image " + kitti("image_2/000001.png") + " --velodyne " +
                       kitti("velodyne/000001.bin") + " --kitti-calib " + kitti("calib/000001.txt") + " --out " +
                       p("dense.exr") + " --confidence " + p("conf.exr") + " --record " + p("rec.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image dense = read_scalar(p("dense.exr")), conf = read_scalar(p("conf.exr"));
  EXPECT_EQ(dense.width, 1242);
  EXPECT_EQ(dense.height, 375);
  std::size_t finite = 0;
  for (float v : dense.data) finite += std::isfinite(v) ? 1 : 0;
  // The sky (about a fifth of the frame) stays unknown; the rest is completed.
  EXPECT_GT(finite, dense.pixels() * 6 / 10);
  EXPECT_LT(finite, dense.pixels() * 95 / 100);
  for (float v : conf.data) ASSERT_TRUE(v >= 0.0f && v <= 1.0f);
  const nlohmann::json rec = read_json(p("rec.json"));
  EXPECT_EQ(rec["command"], "depth complete");
  EXPECT_NE(rec["complete"]["method"].get<std::string>().find("Ku et al. 2018"), std::string::npos);
  EXPECT_EQ(rec["job"]["complete"]["complete-radius"], CompleteParams{}.radius_px);
  EXPECT_EQ(rec["job"]["complete"]["complete-occlusion"], "auto");
  EXPECT_EQ(rec["complete"]["complete_occlusion"], "on");  // --velodyne: a scan from beside the camera
  EXPECT_GT(rec["complete"]["occluded_returns"].get<int>(), 0);
  // The record repeats the run.
  const CliRun again = run("run " + p("rec.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
}

// An effect on a KITTI scan: --complete auto (the default) completes the scan
// the preparation would refuse; --complete off refuses it as before.
TEST_F(CompleteCli, HazeOnALidarScan) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const std::string in = "--image " + kitti("image_2/000001.png") + " --velodyne " + kitti("velodyne/000001.bin") +
                         " --kitti-calib " + kitti("calib/000001.txt") + " --visibility 150";
  CliRun r = run("haze " + in + " --out " + p("h.png") + " --record " + p("h.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("h.json"));
  EXPECT_EQ(rec["prepare"]["complete"]["applied"], true);
  EXPECT_EQ(rec["prepare"]["complete"]["mode"], "auto");
  EXPECT_EQ(rec["prepare"]["applied"], true);
  // The hazed frame is not uniform: the near road keeps more of its contrast than the far sky.
  const Image h = read_color(p("h.png"));
  EXPECT_GT(std::abs(h.at(620, 370, 1) - h.at(620, 20, 1)), 0.1f);
  r = run("haze " + in + " --complete off --out " + p("off.png"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("below --min-coverage"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("off.png")));
  // Completion parameters that --complete off would ignore are refused.
  r = run("haze " + in + " --complete off --complete-radius 3 --out " + p("off.png"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--complete-radius is a completion parameter"), std::string::npos) << r.output;
}

// brume batch --dataset DIR --layout kitti end to end, on a KITTI-layout folder
// of links to the shared frame; given as --scan, the flag's former name, which
// stays accepted.
TEST_F(CompleteCli, BatchScanKitti) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  for (const char* sub : {"image_2/000001.png", "velodyne/000001.bin", "calib/000001.txt"}) {
    fs::create_directories(dir / "kitti" / fs::path(sub).parent_path());
    fs::create_symlink(kitti(sub), dir / "kitti" / sub);
  }
  CliRun r = run("batch --scan " + p("kitti") + " --layout kitti --manifest " + p("m.jsonl") + " --out-dir " +
                 p("out") + " --effect haze --param visibility=150 --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::exists(p("out/image_2/000001.png"))) << r.output;
  r = run("batch --manifest " + p("m.jsonl") + " --out-dir " + p("off") +
          " --effect haze --param visibility=150 --param complete=off --quiet");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("below --min-coverage"), std::string::npos) << r.output;
}

// A record written before completion existed (no "complete" block, no
// --complete) replays as before: its job reads as auto, which leaves a
// dense map (ETH3D terrace, half its pixels known) untouched.
TEST_F(CompleteCli, RecordsWithoutCompletionReplayAsBefore) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/disp0.pfm");
  const std::string e = data_path("eth3d_two_view/terrace/");
  CliRun r = run("haze --image " + e + "im0.png --disparity " + e + "disp0.pfm --calib " + e +
                 "calib.txt --visibility 25 --out " + p("h.exr") + " --record " + p("h.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  nlohmann::json rec = read_json(p("h.json"));
  EXPECT_EQ(rec["prepare"]["complete"]["applied"], false);
  rec["job"].erase("complete");
  rec["job"]["prepare"].erase("complete");
  rec["prepare"].erase("complete");
  std::ofstream(p("old.json")) << rec.dump(2);
  fs::create_directories(dir / "again");
  r = run("run " + p("old.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("h.exr"), p("again/h.exr"));
}

// brume depth prepare: with --image a lidar scan is completed, then
// prepared; without one (--like only) it is refused as before.
TEST_F(CompleteCli, DepthPrepareCompletesWithAnImage) {
  BRUME_REQUIRE_DATA(kKitti + "velodyne/000001.bin");
  const std::string scan =
      "--velodyne " + kitti("velodyne/000001.bin") + " --kitti-calib " + kitti("calib/000001.txt");
  CliRun r = run("depth prepare " + scan + " --image " + kitti("image_2/000001.png") + " --out " + p("p.exr") +
                 " --record " + p("p.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("p.json"));
  EXPECT_EQ(rec["complete"]["applied"], true);
  EXPECT_GT(rec["prepare"]["sky_fraction"].get<double>(), 0.1);  // the sky the completion left unknown
  const Image prepared = read_scalar(p("p.exr"));
  for (float v : prepared.data) ASSERT_TRUE(std::isfinite(v) && v > 0.0f);
  r = run("depth prepare " + scan + " --like " + kitti("image_2/000001.png") + " --out " + p("q.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("below --min-coverage"), std::string::npos) << r.output;
  r = run("depth prepare " + scan + " --like " + kitti("image_2/000001.png") + " --complete on --out " + p("q.exr"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("give --image FILE"), std::string::npos) << r.output;
}

// KITTI depth completion's intrinsics/*.txt (the 3x3 K as 9 numbers) as a
// --calib: it gives the camera for --z (fx, fy, cx, cy each from its place
// in K), is refused where a baseline is needed (--disparity), and a file of
// 8 numbers or a matrix that is not [fx 0 cx; 0 fy cy; 0 0 1] is refused
// naming the file and what it holds. The conversion checked at every pixel
// against the ray factor computed here (1e-6 relative: float rounding).
TEST_F(CompleteCli, KittiIntrinsicsAsCalibration) {
  auto text = [&](const char* name, const char* body) {
    std::ofstream(p(name)) << body;
    return p(name);
  };
  const std::string K = text("K.txt", "721.5377 0 609.5593 0 700.25 172.854 0 0 1\n");
  const Intrinsics k = read_calib_camera(K);
  EXPECT_EQ(k.fx, 721.5377);
  EXPECT_EQ(k.fy, 700.25);
  EXPECT_EQ(k.cx, 609.5593);
  EXPECT_EQ(k.cy, 172.854);
  EXPECT_NE(error_of([&] { read_stereo_calib(K); }).find("no stereo baseline"), std::string::npos);
  EXPECT_NE(error_of([&] { read_calib_camera(text("k8.txt", "1 0 2 0 1 3 0 0\n")); }).find("holds 8 numbers"),
            std::string::npos);
  EXPECT_NE(error_of([&] { read_calib_camera(text("kbad.txt", "1 0 2 0 1 3 0 1 1\n")); }).find("not a camera matrix"),
            std::string::npos);
  EXPECT_NE(error_of([&] { read_calib_camera(text("kneg.txt", "-1 0 2 0 1 3 0 0 1\n")); }).find("fx"),
            std::string::npos);
  // --z with it, through the command line.
  Image z(40, 30, 1, 12.0f);
  z.at(3, 4) = NAN;
  WriteOptions data;
  data.is_color = false;
  write_image(p("z.pfm"), z, data);
  CliRun r = run("depth convert --z " + p("z.pfm") + " --calib " + K + " --out " + p("r.pfm") + " --record " +
                 p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image range = read_scalar(p("r.pfm"));
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) {
      if (x == 3 && y == 4) continue;
      const double a = (x - k.cx) / k.fx, b = (y - k.cy) / k.fy;
      ASSERT_NEAR(range.at(x, y), 12.0 * std::sqrt(1 + a * a + b * b), 1e-6 * range.at(x, y)) << x << "," << y;
    }
  // The record names the file with its hash, so brume run repeats it.
  r = run("run " + p("r.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  // A disparity with it: refused, naming the file.
  r = run("depth convert --disparity " + p("z.pfm") + " --calib " + K + " --out " + p("d.pfm"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("3x3 camera matrix"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("d.pfm")));
}

// --complete-method: an unknown name is refused naming the flag and the
// choices; column gives the record of the old rule (no continued_fraction)
// and planar, the default, the new one.
TEST_F(CompleteCli, CompleteMethodFlag) {
  Image rgb(48, 32, 3, 0.3f), sparse(48, 32, 1, NAN);
  for (int y = 16; y < 32; y += 3)
    for (int x = 0; x < 48; ++x) sparse.at(x, y) = 8.0f;
  WriteOptions data;
  data.is_color = false;
  write_image(p("rgb.png"), rgb, WriteOptions{});
  write_image(p("sparse.pfm"), sparse, data);
  const std::string in = "depth complete --image " + p("rgb.png") + " --range " + p("sparse.pfm");
  CliRun r = run(in + " --complete-method nearest --out " + p("x.pfm"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--complete-method"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("planar"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("x.pfm")));
  r = run(in + " --out " + p("a.pfm") + " --record " + p("a.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(read_json(p("a.json"))["job"]["complete"]["complete-method"], "planar");
  EXPECT_EQ(read_json(p("a.json"))["complete"]["complete_method"], "planar");
  EXPECT_EQ(read_json(p("a.json"))["job"]["complete"]["complete-edges"], "image");
  EXPECT_EQ(read_json(p("a.json"))["complete"]["complete_edges"], "image");
  EXPECT_EQ(read_json(p("a.json"))["complete"]["complete_occlusion"],
            "off (auto: the range map is not a scan from beside the camera)");
  r = run(in + " --complete-method column --out " + p("b.pfm") + " --record " + p("b.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_FALSE(read_json(p("b.json"))["complete"].contains("complete_method"));
  r = run("run " + p("a.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
}

// ETH3D's ground-truth disparity has holes where the laser saw nothing
// (shadows under the tables, glass, a building's far facade): the preparation
// takes the regions that reach the top as sky, and an effect paints them with
// the airlight. The command says so (stderr and the record), names the fix,
// and --complete on completes them instead; a real sky above a mountain
// (GeoPose3K's Matterhorn) warns nothing.
TEST_F(CompleteCli, PreparedSkyThatIsNotSkyWarns) {
  BRUME_REQUIRE_DATA("eth3d_two_view/terrace/disp0.pfm");
  const std::string e = data_path("eth3d_two_view/terrace/");
  const std::string in =
      "--image " + e + "im0.png --disparity " + e + "disp0.pfm --calib " + e + "calib.txt --visibility 100";
  CliRun r = run("haze " + in + " --out " + p("t.png") + " --record " + p("t.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("brume haze: warning: the range's unknown regions that the preparation takes as sky"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("give --complete on"), std::string::npos) << r.output;
  const nlohmann::json prep = read_json(p("t.json"))["prepare"], c = prep["complete"];
  ASSERT_TRUE(c.contains("warnings")) << c.dump();
  // Measured 2026-12-07: 36.7 % of the frame taken as sky, 26.7 % of it under a surface (warns at 5 %).
  // The counts are exact for this file; 0.005 only lets a reader that rounds disparity differently by a
  // few pixels pass, far from the 5 % that decides the warning.
  EXPECT_NEAR(prep["sky_fraction"].get<double>(), 0.367, 0.005);
  EXPECT_NEAR(c["prepared_sky_under_surface_fraction"].get<double>(), 0.267, 0.005);
  r = run("haze " + in + " --complete on --out " + p("on.png") + " --record " + p("on.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(r.output.find("warning"), std::string::npos) << r.output;
  EXPECT_LT(read_json(p("on.json"))["prepare"]["complete"]["sky_fraction"].get<double>(), 0.05);
  if (!have_data("geopose3k_matterhorn/distance.pfm")) return;
  const std::string g = data_path("geopose3k_matterhorn/");
  r = run("haze --image " + g + "photo.jpg --range " + g + "distance.pfm --unknown-value -1 --visibility 30000 --out " +
          p("g.png") + " --record " + p("g.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(r.output.find("warning"), std::string::npos) << r.output;
  EXPECT_EQ(read_json(p("g.json"))["prepare"]["complete"]["prepared_sky_under_surface_fraction"].get<double>(), 0.0);
}
