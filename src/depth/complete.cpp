// brume — depth completion (method, equations and rules in include/brume/complete.hpp).
#include "brume/complete.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

#include "brume/error.hpp"

#include "brume_opencv.hpp"
#include "core/schedule.hpp"
#include "core/srgb_curve.hpp"
#include "core/text.hpp"

namespace brume {

const EnumNames<CompleteMethod>& complete_method_names() {
  static const EnumNames<CompleteMethod> n = {{CompleteMethod::column, "column"}, {CompleteMethod::planar, "planar"}};
  return n;
}

const EnumNames<CompleteOcclusion>& complete_occlusion_names() {
  static const EnumNames<CompleteOcclusion> n = {
      {CompleteOcclusion::off, "off"}, {CompleteOcclusion::on, "on"}, {CompleteOcclusion::automatic, "auto"}};
  return n;
}

const EnumNames<CompleteSkyBrightness>& complete_sky_brightness_names() {
  static const EnumNames<CompleteSkyBrightness> n = {{CompleteSkyBrightness::luma, "luma"},
                                                     {CompleteSkyBrightness::max_channel, "max"}};
  return n;
}

const EnumNames<CompleteEdges>& complete_edges_names() {
  static const EnumNames<CompleteEdges> n = {{CompleteEdges::nearest, "nearest"}, {CompleteEdges::image, "image"}};
  return n;
}

const ParamTable<CompleteParams>& complete_param_table() {
  static const ParamTable<CompleteParams> t = [] {
    ParamTable<CompleteParams> d("complete");
    d.integer("complete-radius", &CompleteParams::radius_px, "px", Range::closed(1, 32),
              "radius of the image-guided refinement around each measurement (KITTI's scan lines lie 3-6 rows apart)")
        .real("complete-sigma-space", &CompleteParams::sigma_space_px, "px", Range::left_open(0.0, 100.0),
              "spatial scale of the refinement's weights")
        .real("complete-sigma-colour", &CompleteParams::sigma_colour, "1", Range::left_open(0.0, 10.0),
              "colour scale of the refinement's weights, in sRGB-encoded [0,1] units: depth is not averaged across "
              "image edges stronger than this")
        .real("complete-sigma-range", &CompleteParams::sigma_range, "1", Range::left_open(0.0, 10.0),
              "range scale of the refinement's weights, relative to the morphological pilot: keeps a pixel on its "
              "depth layer")
        .real("complete-sky-luminance", &CompleteParams::sky_luminance, "1", Range::closed(0.0, 1.0),
              "sky rule: an unmeasured pixel above the scan is sky when at least this bright (by "
              "--complete-sky-brightness, times the image's 99th percentile of it), smooth "
              "(--complete-sky-roughness) and connected to the top row")
        .real("complete-sky-roughness", &CompleteParams::sky_roughness, "1", Range::closed(0.0, 1.0),
              "sky rule: the largest 5x5 standard deviation of sRGB luma of a sky pixel (with "
              "--complete-sky-luminance); sky stays unknown (NaN)")
        .choice("complete-sky-brightness", &CompleteParams::sky_brightness, complete_sky_brightness_names(),
                "what the sky rule calls bright (--complete-sky-luminance): max, the largest sRGB channel (a clear "
                "blue sky beside a saturated white one is as bright as it); luma, sRGB luma (a blue sky is darker "
                "than white by 0.2-0.4 and fell under 0.7 x a white 99th percentile: the rule of records before "
                "it)")
        .since(4, "luma")
        .integer("complete-sky-edge", &CompleteParams::sky_edge_px, "px", Range::closed(0, 16),
                 "sky rule: the sky then grows by up to this many pixels into unmeasured pixels above the scan "
                 "that are bright (as --complete-sky-luminance) and within 0.3 (sRGB) of a sky neighbour's colour, "
                 "smooth or not: the sky's edge, where the 5x5 roughness window straddles a treeline; 0: no "
                 "growth (the rule of records before it)")
        .since(4, 0)
        .real("complete-sky-blue", &CompleteParams::sky_blue, "1", Range::closed(0.0, 1.0),
              "sky rule: an unmeasured pixel whose blue exceeds its red by at least this (sRGB) and is no smaller "
              "than its green is bright enough for the sky, however dark (a clear sky darker than the scene's "
              "snow or clouds); 0: brightness only (the rule of records before it)")
        .since(4, 0)
        .real("complete-sky-border", &CompleteParams::sky_border, "1", Range::closed(0.0, 0.2),
              "sky rule: unmeasured pixels no brighter than this (largest sRGB channel) and connected to the "
              "frame's edge through such pixels are a border outside the picture (a panorama's warp, a "
              "letterbox): above the scan they join the sky, and the sky touches the top row through them; 0: "
              "no border (the rule of records before it)")
        .since(4, 0)
        .choice("complete-method", &CompleteParams::method, complete_method_names(),
                "structure above the scan (not sky, no measurement near): planar continues each column's planar "
                "depth up from its topmost measurements, along image segments (issue 52); column takes the "
                "column's nearest estimate, the morphological pilot's wide fill (the rule of records before it)")
        .since(4, "column")
        .choice("complete-occlusion", &CompleteParams::occlusion, complete_occlusion_names(),
                "returns the camera cannot see: on drops a return when one within 3 columns, 1 row above to 8 "
                "below, is nearer by > 10 % and by > 0.03 /m in inverse range (a scanner beside the camera sees "
                "past foreground edges and through gaps; issue 52), then completes those pixels from the returns "
                "around them; auto: on for a scan from beside the camera (--velodyne), off for a map seen from "
                "the camera; off keeps every return (the rule of records before it)")
        .since(4, "off")
        .choice("complete-edges", &CompleteParams::edges, complete_edges_names(),
                "depth edges (where the nearest and farthest measurements around a pixel differ by > 5 %): image "
                "weighs each measurement also by the image edges on the straight path to the pixel and takes the "
                "far depth layer where it holds 3x the near layer's weight, so that a pixel takes the measurements "
                "of its own side (issue 52); nearest keeps the layer of the nearest measurement (the rule of "
                "records before it)")
        .since(4, "nearest")
        .integer("complete-stereo-fattening", &CompleteParams::stereo_fattening_px, "px", Range::closed(0, 32),
                 "with --stereo-right: a stereo value nearer than the completion's estimate does not replace it "
                 "where the pair itself sees the estimate's depth (within 5 %) within this many pixels: the "
                 "matcher's foreground fattening beside a nearer object, about one matching block (--stereo-block "
                 "5); 0: no such guard (the rule of records before it)")
        .since(4, 0);
    return d;
  }();
  return t;
}

namespace {

inline bool measured(float r) { return std::isfinite(r) && r > 0.0f; }

// The refinement's weight sums (weights in (0, 1]): below kMinWeight a
// pixel has no support. The trilateral mean is taken when its weight is at
// least kLayerShare of the space-and-colour weight (the pilot's depth layer
// holds a fair share of the measurements that look like the pixel); else the
// space-and-colour mean when that weight reaches kFallbackSupport (about one
// measurement of the pixel's colour within 2 px), else the pilot. Chosen on
// KITTI 000001's held-out points (tests/test_complete.cpp): shares of
// 0.02-0.1 and supports of 1e-6-0.6 moved the RMSE by up to 4 %.
constexpr float kMinWeight = 1e-6f;
constexpr float kLayerShare = 0.05f;
constexpr float kFallbackSupport = 0.3f;

// exp(-t) for t in [0, 16), nearest of 64 steps per unit (relative error
// <= 0.8 %); 0 beyond (e^-16 = 1.1e-7). The weights only rank and average
// measurements, so this costs no accuracy that matters, and 2 exp per pair
// (3.2 M pairs on KITTI) would cost ~25 ms.
struct ExpTable {
  static constexpr int kPerUnit = 64, kSize = 16 * kPerUnit;
  std::array<float, kSize> v{};
  ExpTable() {
    for (int i = 0; i < kSize; ++i) v[i] = static_cast<float>(std::exp(-(i + 0.5) / kPerUnit));
  }
  float operator()(float t) const {
    const float s = t * kPerUnit;
    return s < static_cast<float>(kSize) ? v[static_cast<int>(s)] : 0.0f;
  }
};

// sRGB encoding of linear [0, 1] (IEC 61966-2-1), 4096 steps: a step is at
// most 12.92/4096 = 0.003 of the encoded value, well under sigma_colour.
float srgb_encode(float x) {
  static const std::array<float, 4097> lut = [] {
    std::array<float, 4097> a{};
    for (int i = 0; i <= 4096; ++i) {
      const double v = i / 4096.0;
      a[i] = static_cast<float>(detail::srgb_encode_curve(v));
    }
    return a;
  }();
  const float c = std::clamp(x, 0.0f, 1.0f);
  return lut[static_cast<int>(c * 4096.0f + 0.5f)];
}


// The sky's edge (step 3, complete-sky-edge): a pixel joins the sky only
// within this sRGB distance of a sky neighbour's colour. Chosen on KITTI
// 000001 (the blue sky at the top right, tests/test_complete.cpp): 91.4 %
// of its pixels end as sky at 0.2, 92.4 % at 0.3, 93.9 % with no colour test
// -- which also took the truck's bluish roof edge, sRGB (0.22, 0.64, 0.85)
// beside the white sky (0.87 away), 3 px inside its label_2 box (80.4 % by
// the rule of records before complete-sky-edge).
constexpr float kSkyEdgeColour = 0.3f;

// Step 0's rule (brume/complete.hpp): the window and thresholds.
constexpr int kOccLeft = 3, kOccRight = 3, kOccUp = 1, kOccDown = 8;
constexpr float kOccRelative = 0.1f;  // nearer by more than this share of the range
constexpr float kOccInverse = 0.03f;  // [1/m] and by more than this in inverse range

// Step 2b (complete-edges image): a pixel lies at a depth edge when the
// far pilot exceeds the near one by more than kDepthEdge; there the far
// layer is taken when its weight exceeds kFarLayerVote times the near
// layer's. Chosen on KITTI 000001's held-out returns (seeds 1-10; seeds
// 101-110 give the same ratios within 0.01) with the ETH3D scans of
// tests/test_complete.cpp as a check (no figure between their lines worse):
// votes of 1-2 took background for pixels the camera sees as foreground
// (RMSE 0.96-0.94x IP-Basic's), 3-4 are alike; an edge test everywhere
// (no kDepthEdge) made ETH3D's MAE between the scan lines 2-3 % worse (it
// weighs texture as edges), 0.05-0.1 changed nothing there.
constexpr float kDepthEdge = 0.05f;
constexpr float kFarLayerVote = 3.0f;

bool occlusion_applies(const CompleteParams& p) {
  return p.occlusion == CompleteOcclusion::on || (p.occlusion == CompleteOcclusion::automatic && p.offset_scan);
}

}  // namespace

std::vector<std::uint8_t> occluded_returns(DenseImageRef range, int threads) {
  if (range.channels != 1)
    throw Error("occluded_returns: the range map has " + std::to_string(range.channels) + " channels; it must have one");
  const int W = range.width, H = range.height;
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  std::vector<std::uint8_t> o(range.pixels(), 0);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float rp = range.data[static_cast<std::size_t>(y) * W + x];
      if (!measured(rp)) continue;
      const float lim = std::min(rp * (1.0f - kOccRelative), 1.0f / (1.0f / rp + kOccInverse));
      bool occ = false;
      for (int v = std::max(0, y - kOccUp); v <= std::min(H - 1, y + kOccDown) && !occ; ++v)
        for (int u = std::max(0, x - kOccLeft); u <= std::min(W - 1, x + kOccRight); ++u) {
          const float rq = range.data[static_cast<std::size_t>(v) * W + u];
          if (measured(rq) && rq < lim) {
            occ = true;
            break;
          }
        }
      o[static_cast<std::size_t>(y) * W + x] = occ ? 1 : 0;
    }
  return o;
}

CompleteResult complete_range(DenseImageRef range, DenseImageRef guide, const CompleteParams& p, int threads,
                              const Intrinsics* camera) {
  complete_param_table().validate(p);
  if (range.empty()) throw Error("complete: the range map is empty (" + range.size_string() + ")");
  if (range.channels != 1)
    throw Error("complete: the range map has " + std::to_string(range.channels) + " channels; it must have one");
  if (guide.channels != 3)
    throw Error("complete: the colour image has " + std::to_string(guide.channels) +
                " channels; completion is guided by an RGB image (3 channels)");
  if (guide.width != range.width || guide.height != range.height)
    throw Error("complete: the range map is " + range.size_string() + " but the colour image is " +
                guide.size_string() + "; they must be the same size (for --velodyne the scan is projected to "
                "the image's size: check that --image and --kitti-calib belong to the same camera)");
  const int W = range.width, H = range.height;
  const std::size_t N = range.pixels();
  const int nt = threads > 0 ? threads : omp_get_max_threads();

  CompleteResult res;
  // ---- 0. returns the camera cannot see (dropped after the checks below) ----
  std::vector<std::uint8_t> dropped;
  if (occlusion_applies(p)) dropped = occluded_returns(range, nt);
  // ---- measurements ----
  std::vector<std::uint8_t> known(N, 0);
  std::size_t nk = 0;
  float rmax = 0.0f;
  for (std::size_t i = 0; i < N; ++i) {
    const float r = range.data[i];
    if (std::isfinite(r) && r < 0.0f)
      throw Error("complete: the range map has a negative value " + text::g(r) + " m at pixel (" +
                  std::to_string(i % W) + ", " + std::to_string(i / W) + "); known ranges must be > 0");
    if (measured(r)) {
      if (!(r >= kCompleteRangeMinM && r <= kCompleteRangeMaxM))
        throw Error("complete: the range map has " + text::g(r) + " m at pixel (" + std::to_string(i % W) + ", " +
                    std::to_string(i / W) + "); completion takes measurements from " + text::g(kCompleteRangeMinM) +
                    " m to " + text::g(kCompleteRangeMaxM) + " m (below, float rounding against the pilot's 1 m "
                    "offset loses them; above, no range map measures, and 3e38 is a fill value). If the file marks "
                    "unknown pixels with such a value, give it as --unknown-value; else check the map's units "
                    "(--depth-scale)");
      if (!dropped.empty() && dropped[i]) {
        ++res.occluded;
        continue;
      }
      known[i] = 1;
      ++nk;
      rmax = std::max(rmax, r);
      if (res.scan_top_row < 0) res.scan_top_row = static_cast<int>(i / W);
    }
  }
  if (nk == 0)
    throw Error("complete: the range map (" + range.size_string() +
                ") has no measured pixel (every value is NaN, inf or 0): nothing to complete from. For --velodyne, "
                "no point of the scan falls inside the image: check that --kitti-calib belongs to the scan and "
                "the image size to the camera (KITTI: image_2, P2)");
  res.measured = nk;
  res.known_fraction = static_cast<double>(nk) / static_cast<double>(N);
  const float dmax = 1.05f * rmax + 1.0f;
  res.d_max_m = dmax;

  // ---- 1. the morphological pilot (Ku et al. 2018), on the inverted range ----
  cv::Mat inv(H, W, CV_32F);
  for (std::size_t i = 0; i < N; ++i) inv.ptr<float>()[i] = known[i] ? dmax - range.data[i] : 0.0f;
  const cv::Mat diamond5 = (cv::Mat_<std::uint8_t>(5, 5) << 0, 0, 1, 0, 0, 0, 1, 1, 1, 0, 1, 1, 1, 1, 1, 0, 1, 1, 1,
                            0, 0, 0, 1, 0, 0);
  cv::dilate(inv, inv, diamond5);
  cv::morphologyEx(inv, inv, cv::MORPH_CLOSE, cv::Mat::ones(5, 5, CV_8U));
  for (int k : {7, 31}) {
    cv::Mat d;
    cv::dilate(inv, d, cv::Mat::ones(k, k, CV_8U));
    const cv::Mat empty = inv < 0.1f;
    d.copyTo(inv, empty);
  }
  {
    const cv::Mat valid = inv > 0.1f;
    cv::Mat m;
    cv::medianBlur(inv, m, 5);
    m.copyTo(inv, valid);
    cv::GaussianBlur(inv, m, cv::Size(5, 5), 0);
    m.copyTo(inv, valid);
  }
  std::vector<float> pilot(N);
  for (std::size_t i = 0; i < N; ++i) {
    const float v = inv.ptr<float>()[i];
    pilot[i] = v > 0.1f ? dmax - v : NAN;
  }
  // ---- 2b. the far pilot (complete-edges image): the farthest measurement
  // around, where it exceeds the near pilot by more than kDepthEdge ----
  std::vector<float> far_pilot;  // NaN where the pixel is not at a depth edge
  if (p.edges == CompleteEdges::image) {
    cv::Mat fr(H, W, CV_32F);
    for (std::size_t i = 0; i < N; ++i) fr.ptr<float>()[i] = known[i] ? range.data[i] : 0.0f;
    cv::dilate(fr, fr, diamond5);
    cv::Mat d;
    cv::dilate(fr, d, cv::Mat::ones(7, 7, CV_8U));
    const cv::Mat empty = fr < 0.1f;
    d.copyTo(fr, empty);
    far_pilot.assign(N, NAN);
    for (std::size_t i = 0; i < N; ++i) {
      const float v = fr.ptr<float>()[i];
      if (v > 0.1f && pilot[i] == pilot[i] && v > (1.0f + kDepthEdge) * pilot[i]) far_pilot[i] = v;
    }
  }

  // ---- the guide: sRGB-encoded colour and its luma ----
  std::vector<float> g(3 * N);
  std::vector<float> luma(N);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(N); ++i) {
    for (int c = 0; c < 3; ++c) g[3 * i + c] = srgb_encode(guide.data[3 * i + c]);
    luma[i] = 0.2126f * g[3 * i] + 0.7152f * g[3 * i + 1] + 0.0722f * g[3 * i + 2];
  }

  // ---- 2. guided refinement: a scatter from each measurement, in row bands ----
  const int r = p.radius_px;
  const int side = 2 * r + 1;
  std::vector<float> ws(static_cast<std::size_t>(side) * side);
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx)
      ws[(dy + r) * side + dx + r] = static_cast<float>(std::exp(-(dx * dx + dy * dy) / (2.0 * p.sigma_space_px * p.sigma_space_px)));
  const float inv_2sc2 = static_cast<float>(1.0 / (2.0 * p.sigma_colour * p.sigma_colour));
  const float inv_2sr2 = static_cast<float>(1.0 / (2.0 * p.sigma_range * p.sigma_range));
  static const ExpTable ex;
  std::vector<std::size_t> row_start(H + 1, 0);
  std::vector<int> kx;
  kx.reserve(nk);
  for (int y = 0; y < H; ++y) {
    row_start[y] = kx.size();
    for (int x = 0; x < W; ++x)
      if (known[static_cast<std::size_t>(y) * W + x]) kx.push_back(x);
  }
  row_start[H] = kx.size();
  // Per pixel, interleaved (one cache line per update): sum w R, sum w,
  // sum w_space w_colour R, sum w_space w_colour.
  std::vector<float> acc(4 * N, 0.0f);
  // Step 2b: the far layer's sum w R, sum w (touched at depth edges only),
  // and each offset's straight path from the measurement (linear offsets
  // of its pixels, from q at 0 to the pixel at path_n).
  const bool edges = !far_pilot.empty();
  std::vector<float> far_acc(edges ? 2 * N : 0, 0.0f);
  std::vector<std::ptrdiff_t> path;
  std::vector<int> path_n;
  if (edges) {
    path.assign(static_cast<std::size_t>(side) * side * (r + 1), 0);
    path_n.assign(static_cast<std::size_t>(side) * side, 0);
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        const int o = (dy + r) * side + dx + r;
        const int n = std::max(std::abs(dx), std::abs(dy));
        path_n[o] = n;
        for (int k = 1; k <= n; ++k)
          path[static_cast<std::size_t>(o) * (r + 1) + k] =
              static_cast<std::ptrdiff_t>(std::lround(static_cast<double>(k) * dy / n)) * W +
              std::lround(static_cast<double>(k) * dx / n);
      }
  }
  constexpr int kBand = 16;
  const int bands = (H + kBand - 1) / kBand;
#pragma omp parallel for num_threads(nt) schedule(dynamic)
  for (int b = 0; b < bands; ++b) {
    const int y0 = b * kBand, y1 = std::min(H, y0 + kBand);
    for (int qy = std::max(0, y0 - r); qy < std::min(H, y1 + r); ++qy) {
      for (std::size_t k = row_start[qy]; k < row_start[qy + 1]; ++k) {
        const int qx = kx[k];
        const std::size_t q = static_cast<std::size_t>(qy) * W + qx;
        const float rq = range.data[q];
        const float* gq = &g[3 * q];
        for (int py = std::max(y0, qy - r); py < std::min(y1, qy + r + 1); ++py) {
          const float* wrow = &ws[static_cast<std::size_t>(py - qy + r) * side + r];  // dx = 0
          const std::size_t rowp = static_cast<std::size_t>(py) * W;
          for (int px = std::max(0, qx - r); px < std::min(W, qx + r + 1); ++px) {
            const std::size_t i = rowp + px;
            if (known[i]) continue;
            const float* gp = &g[3 * i];
            const float d0 = gp[0] - gq[0], d1 = gp[1] - gq[1], d2 = gp[2] - gq[2];
            float wsc = wrow[px - qx] * ex((d0 * d0 + d1 * d1 + d2 * d2) * inv_2sc2);
            const float pf = edges ? far_pilot[i] : NAN;
            if (pf == pf && wsc > 0.0f) {
              // At a depth edge: the image edges on the path from q (step 2b).
              const int o = (py - qy + r) * side + px - qx + r;
              const std::ptrdiff_t* pth = &path[static_cast<std::size_t>(o) * (r + 1)];
              float m = 0.0f;
              for (int k = 1; k <= path_n[o]; ++k) {
                const float* a0 = &g[3 * (q + pth[k - 1])];
                const float* a1 = &g[3 * (q + pth[k])];
                const float e0 = a0[0] - a1[0], e1 = a0[1] - a1[1], e2 = a0[2] - a1[2];
                m = std::max(m, e0 * e0 + e1 * e1 + e2 * e2);
              }
              wsc *= ex(m * inv_2sc2);
              const float e = (rq - pf) / pf;
              const float wf = wsc * ex(e * e * inv_2sr2);
              far_acc[2 * i] += wf * rq;
              far_acc[2 * i + 1] += wf;
            }
            float w = wsc;
            const float pp = pilot[i];
            if (pp == pp) {  // not NaN
              const float e = (rq - pp) / pp;
              w *= ex(e * e * inv_2sr2);
            }
            float* a = &acc[4 * i];
            a[0] += w * rq;
            a[1] += w;
            a[2] += wsc * rq;
            a[3] += wsc;
          }
        }
      }
    }
  }

  res.range = Image(W, H, 1, NAN);
  res.confidence = Image(W, H, 1, 0.0f);
  res.sky_mask = Image(W, H, 1, 0.0f);
  float* out = res.range.data.data();
  float* conf = res.confidence.data.data();
  // Step 2b: at a depth edge the far layer replaces the near one where it
  // holds kFarLayerVote times its weight.
  if (edges)
    for (std::size_t i = 0; i < N; ++i) {
      float* a = &acc[4 * i];
      const float fw = far_acc[2 * i + 1];
      if (fw > kMinWeight && fw > kFarLayerVote * a[1]) a[0] = far_acc[2 * i], a[1] = fw;
    }
  auto num = [&](std::size_t i) { return acc[4 * i]; };
  auto den = [&](std::size_t i) { return acc[4 * i + 1]; };
  auto num_sc = [&](std::size_t i) { return acc[4 * i + 2]; };
  auto support = [&](std::size_t i) { return acc[4 * i + 3]; };
  for (std::size_t i = 0; i < N; ++i) {
    if (known[i]) {
      out[i] = range.data[i];
      conf[i] = 1.0f;
    } else if (den(i) > kMinWeight && den(i) >= kLayerShare * support(i)) {
      out[i] = num(i) / den(i);
      conf[i] = support(i) / (support(i) + 0.5f);
    } else if (support(i) > kFallbackSupport) {
      // The pilot's layer has (almost) no measurement of the pixel's colour
      // around it: the pilot's nearest-wins dilation crossed an image edge.
      // The measurements of the pixel's colour decide (no range term).
      out[i] = num_sc(i) / support(i);
      conf[i] = support(i) / (support(i) + 0.5f);
    } else if (pilot[i] == pilot[i]) {
      out[i] = pilot[i];
      conf[i] = 0.3f;
    }
  }

  // ---- 3. the sky rule ----
  {
    cv::Mat km(H, W, CV_8U, known.data()), near;
    cv::dilate(km, near, cv::Mat::ones(3, 3, CV_8U));
    // Brightness: luma, or the largest sRGB channel (a clear blue sky, luma
    // ~0.8 of a white one's, is as bright as it).
    // (The largest channel also tells a black border: complete-sky-border.)
    std::vector<float> max_channel;
    if (p.sky_brightness == CompleteSkyBrightness::max_channel || p.sky_border > 0.0) {
      max_channel.resize(N);
      for (std::size_t i = 0; i < N; ++i) max_channel[i] = std::max({g[3 * i], g[3 * i + 1], g[3 * i + 2]});
    }
    const std::vector<float>& bright = p.sky_brightness == CompleteSkyBrightness::max_channel ? max_channel : luma;
    // Its 99th percentile (1024 bins over [0, 1]).
    std::vector<std::size_t> hist(1025, 0);
    for (float y : bright) ++hist[static_cast<int>(std::clamp(y, 0.0f, 1.0f) * 1024.0f)];
    std::size_t acc = 0;
    int b99 = 1024;
    for (int b = 0; b <= 1024; ++b)
      if ((acc += hist[b]) >= static_cast<std::size_t>(0.99 * static_cast<double>(N))) {
        b99 = b;
        break;
      }
    const float lum_min = static_cast<float>(p.sky_luminance * (b99 + 0.5) / 1024.0);
    // Bright enough for the sky: by brightness, or blue (a clear sky, by
    // Rayleigh's λ⁻⁴, darker than snow or clouds beside it; complete-sky-blue).
    const float blue_min = static_cast<float>(p.sky_blue);
    auto sky_bright = [&](std::size_t i) {
      if (bright[i] >= lum_min) return true;
      const float* c = &g[3 * i];
      return blue_min > 0.0f && c[2] - c[0] >= blue_min && c[2] >= c[1];
    };
    // A border outside the picture (complete-sky-border): unmeasured pixels
    // no brighter than sky_border connected to the frame's edge through such
    // pixels (4-connected).
    std::vector<std::uint8_t> border(N, 0);
    if (p.sky_border > 0.0) {
      cv::Mat dark(H, W, CV_8U), dl;
      const float dark_max = static_cast<float>(p.sky_border);
      for (std::size_t i = 0; i < N; ++i)
        dark.data[i] = (!known[i] && max_channel[i] <= dark_max) ? 1 : 0;
      const int nd = cv::connectedComponents(dark, dl, 4, CV_32S);
      std::vector<std::uint8_t> edge(static_cast<std::size_t>(nd), 0);
      for (int x = 0; x < W; ++x) edge[dl.at<int>(0, x)] = edge[dl.at<int>(H - 1, x)] = 1;
      for (int y = 0; y < H; ++y) edge[dl.at<int>(y, 0)] = edge[dl.at<int>(y, W - 1)] = 1;
      edge[0] = 0;  // background
      for (std::size_t i = 0; i < N; ++i) border[i] = edge[dl.ptr<int>()[i]];
    }
    cv::Mat Y(H, W, CV_32F, luma.data()), m1, m2;
    cv::boxFilter(Y, m1, CV_32F, cv::Size(5, 5));
    cv::boxFilter(Y.mul(Y), m2, CV_32F, cv::Size(5, 5));
    const float rough2 = static_cast<float>(p.sky_roughness * p.sky_roughness);
    // The scan's upper limit in each column: the median of the topmost
    // measurements of the columns within 3 px that have one (H where none
    // has), so that one stray return (a wire) does not move it and a scan
    // with gaps between its columns still has a limit everywhere.
    std::vector<int> top_raw(W, H), top_row(W, H);
    for (int y = H - 1; y >= 0; --y)
      for (int x = 0; x < W; ++x)
        if (known[static_cast<std::size_t>(y) * W + x]) top_raw[x] = y;
    for (int x = 0; x < W; ++x) {
      std::array<int, 7> w7;
      int n7 = 0;
      for (int d = -3; d <= 3; ++d)
        if (x + d >= 0 && x + d < W && top_raw[x + d] < H) w7[n7++] = top_raw[x + d];
      if (n7 == 0) continue;
      std::nth_element(w7.begin(), w7.begin() + n7 / 2, w7.begin() + n7);
      top_row[x] = w7[n7 / 2];
    }
    cv::Mat cand(H, W, CV_8U);
    for (std::size_t i = 0; i < N; ++i) {
      const float mean = m1.ptr<float>()[i];
      const float var = m2.ptr<float>()[i] - mean * mean;
      const bool above = static_cast<int>(i / W) < top_row[i % W];
      cand.data[i] = (above && ((!near.data[i] && sky_bright(i) && var <= rough2) || border[i])) ? 1 : 0;
    }
    cv::morphologyEx(cand, cand, cv::MORPH_CLOSE, cv::Mat::ones(5, 5, CV_8U));
    for (std::size_t i = 0; i < N; ++i)
      if (static_cast<int>(i / W) >= top_row[i % W]) cand.data[i] = 0;
    cv::Mat labels;
    const int n = cv::connectedComponents(cand, labels, 8, CV_32S);
    std::vector<std::uint8_t> top(static_cast<std::size_t>(n), 0);
    for (int x = 0; x < W; ++x) top[labels.at<int>(0, x)] = 1;
    top[0] = 0;  // background
    std::vector<std::uint8_t> sky(N, 0);
    for (std::size_t i = 0; i < N; ++i) sky[i] = top[labels.ptr<int>()[i]] && !known[i];
    // The sky's edge: the roughness window straddles the sky's border (a
    // treeline), so the sky found above stops up to 2 px short of it, and
    // the pixels mixed with a leaf (1 px more) are darker still. The sky
    // grows by 8-connected steps into the pixels above the limit, away from
    // measurements, that are bright and within kSkyEdgeColour of a sky
    // neighbour's colour: dark structure stops it, and so does a bright
    // edge unlike the sky beside it.
    const float edge_colour2 = kSkyEdgeColour * kSkyEdgeColour;
    std::vector<std::uint8_t> grown;
    for (int step = 0; step < p.sky_edge_px; ++step) {
      grown = sky;
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const std::size_t i = static_cast<std::size_t>(y) * W + x;
          if (sky[i] || known[i] || near.data[i] || y >= top_row[x] || !sky_bright(i)) continue;
          const float* gp = &g[3 * i];
          bool next = false;
          for (int v = std::max(0, y - 1); v <= std::min(H - 1, y + 1) && !next; ++v)
            for (int u = std::max(0, x - 1); u <= std::min(W - 1, x + 1); ++u) {
              const std::size_t q = static_cast<std::size_t>(v) * W + u;
              if (!sky[q]) continue;
              const float* gq = &g[3 * q];
              const float d0 = gp[0] - gq[0], d1 = gp[1] - gq[1], d2 = gp[2] - gq[2];
              if (d0 * d0 + d1 * d1 + d2 * d2 <= edge_colour2) {
                next = true;
                break;
              }
            }
          if (next) grown[i] = 1;
        }
      sky.swap(grown);
    }
    for (std::size_t i = 0; i < N; ++i)
      if (sky[i]) {
        res.sky_mask.data[i] = 1.0f;
        out[i] = NAN;
        conf[i] = 0.0f;
        ++res.sky;
      }
  }

  auto refined_at = [&](std::size_t i) {
    return (den(i) > kMinWeight && den(i) >= kLayerShare * support(i)) || support(i) > kFallbackSupport;
  };
  // ---- 3c. planar: structure above the scan continues its planar depth ----
  std::vector<std::uint8_t> continued;
  if (p.method == CompleteMethod::planar) {
    continued.assign(N, 0);
    Intrinsics k;
    if (camera) {
      k = resolve(*camera, W, H);
    } else {
      k.fx = k.fy = W;
    }
    const double cx = std::isfinite(k.cx) ? k.cx : 0.5 * (W - 1), cy = std::isfinite(k.cy) ? k.cy : 0.5 * (H - 1);
    std::vector<float> fxu(W), fyv(H);
    for (int x = 0; x < W; ++x) fxu[x] = static_cast<float>((x - cx) / k.fx);
    for (int y = 0; y < H; ++y) fyv[y] = static_cast<float>((y - cy) / k.fy);
    // range = z * stretch(x, y)
    auto stretch = [&](int x, int y) { return std::sqrt(1.0f + fxu[x] * fxu[x] + fyv[y] * fyv[y]); };
    // Each column's topmost measurements: the continuation starts at the
    // topmost (b), from the median planar depth of the three topmost.
    std::vector<int> b(W, H), nb(W, 0);
    std::vector<std::array<float, 3>> top3(W);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        if (!known[i] || nb[x] == 3) continue;
        if (nb[x] == 0) b[x] = y;
        top3[x][nb[x]++] = range.data[i] / stretch(x, y);
      }
    std::vector<float> seed(W, NAN);
    for (int x = 0; x < W; ++x) {
      if (nb[x] == 0) continue;
      const std::array<float, 3>& v = top3[x];
      if (nb[x] == 1) seed[x] = v[0];
      else if (nb[x] == 2) seed[x] = 0.5f * (v[0] + v[1]);
      else seed[x] = std::max(std::min(v[0], v[1]), std::min(std::max(v[0], v[1]), v[2]));  // median of 3
    }
    // A column without a measurement starts at its neighbours' limit (the
    // median over 7 columns, as the sky rule's), from its own estimate there.
    {
      std::vector<int> lim(W, H);
      for (int x = 0; x < W; ++x) {
        std::array<int, 7> w7;
        int n7 = 0;
        for (int d = -3; d <= 3; ++d)
          if (x + d >= 0 && x + d < W && nb[x + d] > 0) w7[n7++] = b[x + d];
        if (n7 == 0) continue;
        std::nth_element(w7.begin(), w7.begin() + n7 / 2, w7.begin() + n7);
        lim[x] = w7[n7 / 2];
      }
      // No measurement within 3 columns (lim = H): no continuation (b = -1,
      // every row is below it); step 3b's rule fills the column.
      for (int x = 0; x < W; ++x)
        if (nb[x] == 0) b[x] = lim[x] < H ? lim[x] : -1;
    }
    const float zmax_range = rmax;  // never behind the farthest measurement (the sky lies at or beyond it)
    std::vector<float> cur(W, NAN), nxt(W, NAN);
    for (int y = H - 1; y >= 0; --y) {
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        if (y > b[x] || (y == b[x] && !(seed[x] == seed[x]))) {
          nxt[x] = out[i] == out[i] ? out[i] / stretch(x, y) : NAN;
          continue;
        }
        if (y == b[x]) {
          nxt[x] = seed[x];
          continue;
        }
        if (res.sky_mask.data[i] > 0.0f) {
          nxt[x] = NAN;
          continue;
        }
        if (known[i] || (out[i] == out[i] && refined_at(i))) {
          nxt[x] = out[i] / stretch(x, y);
          continue;
        }
        // The three neighbours below, weighted by colour likeness.
        const std::size_t below = i + W;
        const float* gp = &g[3 * i];
        float sw = 0.0f, swz = 0.0f, ss = 0.0f, ssz = 0.0f;
        for (int dx = -1; dx <= 1; ++dx) {
          const int u = x + dx;
          if (u < 0 || u >= W || !(cur[u] == cur[u])) continue;
          const float* gq = &g[3 * (below + dx)];
          const float d0 = gp[0] - gq[0], d1 = gp[1] - gq[1], d2 = gp[2] - gq[2];
          const float s = dx == 0 ? 1.0f : 0.5f;
          const float w = s * ex((d0 * d0 + d1 * d1 + d2 * d2) * inv_2sc2);
          sw += w, swz += w * cur[u], ss += s, ssz += s * cur[u];
        }
        if (ss == 0.0f) {
          nxt[x] = NAN;
          continue;
        }
        // Across an edge on every side the surface above is still unknown:
        // continue it by position alone.
        float z = sw > kMinWeight ? swz / sw : ssz / ss;
        const float st = stretch(x, y);
        z = std::min(z, zmax_range / st);
        nxt[x] = z;
        out[i] = z * st;
        conf[i] = 0.2f * std::exp(-static_cast<float>(b[x] - y) / 32.0f);
        continued[i] = 1;
        ++res.continued;
      }
      std::swap(cur, nxt);
    }
  }

  // ---- 3b. structure: extend each column's nearest estimate (below first) ----
  std::vector<std::uint8_t> estimated(N);
  for (std::size_t i = 0; i < N; ++i) estimated[i] = out[i] == out[i];
  // Row by row (contiguous: a column walk would miss the cache at every
  // pixel), keeping each column's nearest estimate below (bottom-up) and
  // above (top-down).
  {
    std::vector<float> below_v(N), cur_v(W, NAN);
    std::vector<int> below_at(N), cur_at(W, -1);
    for (int y = H - 1; y >= 0; --y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        if (estimated[i]) cur_v[x] = out[i], cur_at[x] = y;
        below_v[i] = cur_v[x], below_at[i] = cur_at[x];
      }
    std::fill(cur_v.begin(), cur_v.end(), NAN);
    std::fill(cur_at.begin(), cur_at.end(), -1);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        if (estimated[i]) {
          cur_v[x] = out[i], cur_at[x] = y;
          continue;
        }
        if (res.sky_mask.data[i] > 0.0f) continue;
        if (below_v[i] == below_v[i]) {
          out[i] = below_v[i];
          conf[i] = 0.2f * std::exp(static_cast<float>(y - below_at[i]) / 32.0f);
        } else if (cur_v[x] == cur_v[x]) {
          out[i] = cur_v[x];
          conf[i] = 0.2f * std::exp(static_cast<float>(cur_at[x] - y) / 32.0f);
        }
      }
  }
  for (std::size_t i = 0; i < N; ++i) {
    if (known[i]) continue;
    if (res.sky_mask.data[i] > 0.0f) continue;
    if (!(out[i] == out[i])) ++res.unknown;
    else if (!estimated[i] || (!continued.empty() && continued[i])) ++res.extrapolated;
    else if (refined_at(i)) ++res.refined;
    else ++res.pilot_only;
  }
  res.completed_fraction = static_cast<double>(N - res.sky - res.unknown) / static_cast<double>(N);
  return res;
}

void check_stereo_fattening_given(bool fused, const std::set<std::string>& given) {
  if (!fused && given.count("complete-stereo-fattening"))
    throw Error("--complete-stereo-fattening guards the fusion with the second view of a stereo pair, and none is "
                "fused here: it would change nothing; drop --complete-stereo-fattening (the command line fuses a "
                "second view given by --stereo-right beside the sparse depth source)");
}

nlohmann::json complete_record(const CompleteParams& p, const CompleteResult& r) {
  const double n = static_cast<double>(r.range.pixels());
  const char* pilot =
      "Ku et al. 2018 morphological pilot (diamond 5x5 dilation, 5x5 closing, 7x7 and 31x31 fills, 5x5 median "
      "and Gaussian, on D_max - R) refined by a joint trilateral filter of the measurements (space, sRGB "
      "colour, range against the pilot; space and colour alone where the pilot's layer has < 5 % of the "
      "weight); sky: unmeasured bright smooth regions above the scan's upper limit touching the top row, left "
      "unknown; ";
  nlohmann::json j = {{"method", std::string(pilot) + "other unmeasured pixels extend their column's nearest "
                                                       "estimate (below first)"},
                      {"radius_px", p.radius_px},
                      {"sigma_space_px", p.sigma_space_px},
                      {"sigma_colour", p.sigma_colour},
                      {"sigma_range", p.sigma_range},
                      {"sky_luminance", p.sky_luminance},
                      {"sky_roughness", p.sky_roughness},
                      {"d_max_m", r.d_max_m},
                      {"known_fraction", r.known_fraction},
                      {"completed_fraction", r.completed_fraction},
                      {"refined_fraction", r.refined / n},
                      {"pilot_only_fraction", r.pilot_only / n},
                      {"extrapolated_fraction", r.extrapolated / n},
                      {"sky_fraction", r.sky / n},
                      {"unknown_fraction", r.unknown / n},
                      {"scan_top_row", r.scan_top_row}};
  // (records before the blue-sky rule have neither key: luma, no edge)
  if (p.sky_brightness != CompleteSkyBrightness::luma)
    j["sky_brightness"] = enum_name(complete_sky_brightness_names(), p.sky_brightness);
  if (p.sky_edge_px != 0) j["sky_edge_px"] = p.sky_edge_px;
  if (p.sky_blue != 0.0) j["sky_blue"] = p.sky_blue;  // (records before it have neither key: 0)
  if (p.sky_border != 0.0) j["sky_border"] = p.sky_border;
  if (p.method == CompleteMethod::planar) {  // (the column method's record is as before issue #52)
    j["method"] = std::string(pilot) +
                  "structure above each column's topmost measurement continues the median planar depth of its "
                  "three topmost measurements upward, each pixel the colour-weighted mean of its three neighbours "
                  "below, never beyond the farthest measurement (issue 52); other unmeasured pixels extend their "
                  "column's nearest estimate (below first)";
    j["complete_method"] = "planar";
    j["continued_fraction"] = r.continued / n;
  }
  if (p.edges == CompleteEdges::image) {  // (records before it took the nearest layer and say nothing)
    j["method"] = j["method"].get<std::string>() +
                  "; at depth edges (farthest measurement around > 1.05 x the pilot) the space-colour weight also "
                  "falls with the largest sRGB step on the straight path from the measurement, and the far layer "
                  "(a farthest-wins 5x5 diamond and 7x7 fill) is taken where it holds 3x the near layer's weight "
                  "(issue 52)";
    j["complete_edges"] = "image";
  }
  if (p.occlusion == CompleteOcclusion::automatic && !occlusion_applies(p))
    j["complete_occlusion"] = "off (auto: the range map is not a scan from beside the camera)";
  if (occlusion_applies(p)) {  // (records before it dropped nothing and say nothing)
    j["method"] = "returns with a nearer return within 3 columns, 1 row above to 8 below (nearer by > 10 % and "
                  "by > 0.03 /m in inverse range: seen past a foreground edge or through glass) dropped and "
                  "completed; " +
                  j["method"].get<std::string>();
    j["complete_occlusion"] = "on";
    j["occluded_returns"] = r.occluded;
  }
  return j;
}

}  // namespace brume
