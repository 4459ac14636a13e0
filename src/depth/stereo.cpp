// brume — disparity from a rectified stereo pair (see brume/stereo.hpp for
// the method and its references).
#include "brume/stereo.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <thread>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/record.hpp"
#include "brume_opencv.hpp"
#include "core/text.hpp"
#include "core/timing.hpp"

namespace brume {

const ParamTable<StereoParams>& stereo_param_table() {
  static const ParamTable<StereoParams> t = [] {
    ParamTable<StereoParams> d("stereo");
    d.real("max-disparity", &StereoParams::max_disparity, "px", Range::closed(1.0, 65535.0),
           "largest disparity searched (a whole number below the image width; rounded up to a multiple of 16 "
           "less 1); auto: from a quarter-resolution pass")
        .choice("stereo-mode", &StereoParams::mode, {"3way", "sgbm", "hh"},
                "semi-global matching's aggregation: 3way (3 directions in parallel strips; the fastest, and the "
                "best on ETH3D), sgbm (5 directions), hh (8 directions, a whole cost volume in memory)")
        .integer("stereo-block", &StereoParams::block, "px", Range::closed(1, 11),
                 "matching window side (odd); P1 = 8*3*b^2, P2 = 32*3*b^2")
        .real("stereo-uniqueness", &StereoParams::uniqueness, "%", Range::closed(0.0, 100.0),
              "margin by which the best matching cost must beat the second best")
        .real("stereo-lr-tolerance", &StereoParams::lr_tolerance_px, "px", Range::left_open(0.0, 64.0),
              "left-right consistency: |d_left - d_right| allowed at a kept pixel")
        .integer("stereo-speckle-window", &StereoParams::speckle_window, "px", Range::closed(0, 10000),
                 "connected regions of fewer pixels than this, off their surroundings, are unknown; 0: off")
        .real("stereo-speckle-range", &StereoParams::speckle_range_px, "px", Range::left_open(0.0, 64.0),
              "largest disparity step between neighbours inside one region (speckle filter)")
        .choice("stereo-fill", &StereoParams::fill, {"occlusions", "none"},
                "occlusions: a row's unknown run bounded by known pixels, no longer than the range searched, "
                "takes the farther of its two neighbours; none: unmatched pixels stay unknown")
        .real("stereo-rectified-tolerance", &StereoParams::rectified_tolerance_px, "px",
              Range::left_open(0.0, 1000.0),
              "largest vertical offset between the views (fitted to matched features) anywhere in the image")
        .boolean("stereo-allow-swapped", &StereoParams::allow_swapped,
                 "match a pair whose features lie mostly at negative disparity (x_left < x_right), which is refused "
                 "by default as a swapped pair");
    return d;
  }();
  return t;
}

StereoView read_stereo_view(const std::string& path, const std::string& flag, nlohmann::json* file_rec,
                            const std::string& layer, const std::string& layer_flag) {
  if (path.empty()) throw Error("no " + flag + " given: name the view's image file");
  FileInfo info;
  Image im;
  try {
    ColorRead how;
    how.transfer = Transfer::linear;  // an integer file's counts / (2^bits - 1), not decoded
    how.layer = layer;
    how.layer_flag = layer_flag.empty() ? flag + "-layer" : layer_flag;
    im = read_color(path, how, &info);
  } catch (const Error& e) {
    throw Error(flag + ": " + e.what());
  }
  if (file_rec) *file_rec = file_record(path, info, im);
  StereoView v;
  v.width = im.width, v.height = im.height;
  v.rgb.resize(im.pixels() * 3);
  if (info.integer) {
    // Matching works on the stored (sRGB-encoded) counts: a 16-bit file's
    // are rounded to 8 bits.
    for (std::size_t i = 0; i < v.rgb.size(); ++i)
      v.rgb[i] = static_cast<unsigned char>(std::clamp(std::lround(im.data[i] * 255.0f), 0L, 255L));
  } else {
    for (float& x : im.data) x = std::isfinite(x) ? std::min(x, 1.0f) : 0.0f;
    srgb_encode_8(im.data.data(), v.rgb.data(), v.rgb.size());
  }
  return v;
}

namespace {

cv::Mat as_mat(const StereoView& v) {
  return cv::Mat(v.height, v.width, CV_8UC3, const_cast<unsigned char*>(v.rgb.data()));
}

int sgbm_mode(const std::string& m) {
  if (m == "hh") return cv::StereoSGBM::MODE_HH;
  if (m == "3way") return cv::StereoSGBM::MODE_SGBM_3WAY;
  return cv::StereoSGBM::MODE_SGBM;
}

// One direction of the matching, in 1/16 px (CV_16S, < 0 unknown), the
// reference view's size. mirrored: the right view's disparity, matched as
// the left one of the mirrored pair. Both views are padded on the reference
// side's left by `nd` replicated columns (step 3 of the method).
cv::Mat match_one(const cv::Mat& L, const cv::Mat& R, int nd, const StereoParams& p, bool mirrored, bool pad) {
  cv::Mat l, r;
  if (mirrored) {
    cv::flip(R, l, 1);
    cv::flip(L, r, 1);
  } else {
    l = L, r = R;
  }
  const int padw = pad ? nd : 0;
  cv::Mat lp, rp;
  cv::copyMakeBorder(l, lp, 0, 0, padw, 0, cv::BORDER_REPLICATE);
  cv::copyMakeBorder(r, rp, 0, 0, padw, 0, cv::BORDER_REPLICATE);
  const int c = L.channels(), b = p.block;
  auto sgbm = cv::StereoSGBM::create(0, nd, b, 8 * c * b * b, 32 * c * b * b, -1, 63,
                                     static_cast<int>(std::lround(p.uniqueness)), 0, 0, sgbm_mode(p.mode));
  cv::Mat d;
  sgbm->compute(lp, rp, d);
  d = d(cv::Rect(padw, 0, L.cols, L.rows)).clone();
  if (mirrored) cv::flip(d, d, 1);
  return d;
}

struct Matched {
  cv::Mat disp16;  // CV_16S, 1/16 px, -16 unknown
  cv::Mat lr_diff; // CV_32F, |d_L - d_R| at kept pixels
};

// Both directions (side by side on two threads unless threads == 1) and
// the left-right check, then the speckle filter.
Matched match_pair(const cv::Mat& L, const cv::Mat& R, int nd, const StereoParams& p, int threads, double lr_tol,
                   int speckle_window, double speckle_range) {
  cv::Mat dl, dr;
  if (threads == 1) {
    dl = match_one(L, R, nd, p, false, true);
    dr = match_one(L, R, nd, p, true, true);
  } else {
    std::exception_ptr err;
    std::thread t([&] {
      try {
        dr = match_one(L, R, nd, p, true, true);
      } catch (...) {
        err = std::current_exception();
      }
    });
    dl = match_one(L, R, nd, p, false, true);
    t.join();
    if (err) std::rethrow_exception(err);
  }
  const int W = L.cols, H = L.rows;
  Matched m;
  m.disp16 = cv::Mat(H, W, CV_16S, cv::Scalar(-16));
  m.lr_diff = cv::Mat(H, W, CV_32F, cv::Scalar(0));
  for (int y = 0; y < H; ++y) {
    const short* a = dl.ptr<short>(y);
    const short* b = dr.ptr<short>(y);
    short* o = m.disp16.ptr<short>(y);
    float* df = m.lr_diff.ptr<float>(y);
    for (int x = 0; x < W; ++x) {
      if (a[x] < 0) continue;
      const double d = a[x] / 16.0;
      const long xr = std::lround(x - d);
      if (xr < 0 || xr >= W || b[xr] < 0) continue;  // matched outside the right view, or unmatched there
      const double diff = std::abs(b[xr] / 16.0 - d);
      if (diff > lr_tol) continue;
      o[x] = a[x];
      df[x] = static_cast<float>(diff);
    }
  }
  if (speckle_window > 0) cv::filterSpeckles(m.disp16, -16, speckle_window, speckle_range * 16.0);
  return m;
}

int round_up_16(int n) { return (n + 15) / 16 * 16; }

// ---- is the pair rectified? ---------------------------------------------------
struct RectifyCheck {
  nlohmann::json record;
  bool checked = false;
  double worst_px = 0.0;
  std::string worst_corner;
  std::size_t matches = 0, inliers = 0;
  double median_abs_dy = 0.0;
  // The inliers' disparities x_left - x_right beyond +-1 px: a pair in the
  // right order sees every point at d >= 0, a swapped one at d <= 0.
  std::size_t positive = 0, negative = 0;
};

// dy = a + b u + c v with u = x / W, v = y / H (conditioning), least squares over `idx`.
std::array<double, 3> fit_plane(const std::vector<std::array<double, 3>>& pts, const std::vector<std::size_t>& idx) {
  double A[3][3] = {}, r[3] = {};
  for (std::size_t i : idx) {
    const double f[3] = {1.0, pts[i][0], pts[i][1]};
    for (int j = 0; j < 3; ++j) {
      r[j] += f[j] * pts[i][2];
      for (int k = 0; k < 3; ++k) A[j][k] += f[j] * f[k];
    }
  }
  // Gaussian elimination with partial pivoting (3x3).
  int piv[3] = {0, 1, 2};
  for (int c = 0; c < 3; ++c) {
    int best = c;
    for (int j = c + 1; j < 3; ++j)
      if (std::abs(A[piv[j]][c]) > std::abs(A[piv[best]][c])) best = j;
    std::swap(piv[c], piv[best]);
    const double p = A[piv[c]][c];
    if (std::abs(p) < 1e-12) return {NAN, NAN, NAN};
    for (int j = c + 1; j < 3; ++j) {
      const double f = A[piv[j]][c] / p;
      for (int k = c; k < 3; ++k) A[piv[j]][k] -= f * A[piv[c]][k];
      r[piv[j]] -= f * r[piv[c]];
    }
  }
  std::array<double, 3> x{};
  for (int c = 2; c >= 0; --c) {
    double s = r[piv[c]];
    for (int k = c + 1; k < 3; ++k) s -= A[piv[c]][k] * x[k];
    x[c] = s / A[piv[c]][c];
  }
  return x;
}

// Each row of `a` (ORB's 256-bit descriptors as 4 words) to its nearest row
// of `b` in Hamming distance. With the popcnt instruction where the CPU has
// it (GCC/Clang clones; the baseline x86-64 has none): OpenCV's
// cross-checked BFMatcher took ~100 ms on 1500 x 1500 descriptors here,
// this ~5 ms. GCC only, as the fog's fast rows' clones: Clang's sanitizer builds
// instrument the clones' ifunc resolver, which runs before ThreadSanitizer
// is set up (the TSan suite's test binary crashed at start-up).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("popcnt", "default")))
#endif
void nearest_rows(const std::uint64_t* a, std::size_t na,
                                                                        const std::uint64_t* b, std::size_t nb,
                                                                        int* idx, int* dist) {
  for (std::size_t i = 0; i < na; ++i) {
    const std::uint64_t* p = a + 4 * i;
    int best = 257, at = -1;
    for (std::size_t j = 0; j < nb; ++j) {
      const std::uint64_t* q = b + 4 * j;
      const int d = __builtin_popcountll(p[0] ^ q[0]) + __builtin_popcountll(p[1] ^ q[1]) +
                    __builtin_popcountll(p[2] ^ q[2]) + __builtin_popcountll(p[3] ^ q[3]);
      if (d < best) best = d, at = static_cast<int>(j);
    }
    idx[i] = at;
    dist[i] = best;
  }
}

// Mutual nearest neighbours between two sets of ORB descriptors (CV_8U, 32 bytes a row).
std::vector<cv::DMatch> mutual_nearest(const cv::Mat& dl, const cv::Mat& dr) {
  std::vector<cv::DMatch> out;
  if (dl.empty() || dr.empty() || dl.cols != 32 || dr.cols != 32) return out;
  auto words = [](const cv::Mat& d) {
    std::vector<std::uint64_t> w(static_cast<std::size_t>(d.rows) * 4);
    for (int r = 0; r < d.rows; ++r) std::memcpy(w.data() + 4 * static_cast<std::size_t>(r), d.ptr(r), 32);
    return w;
  };
  const std::vector<std::uint64_t> a = words(dl), b = words(dr);
  std::vector<int> ab(dl.rows), dab(dl.rows), ba(dr.rows), dba(dr.rows);
  nearest_rows(a.data(), dl.rows, b.data(), dr.rows, ab.data(), dab.data());
  nearest_rows(b.data(), dr.rows, a.data(), dl.rows, ba.data(), dba.data());
  for (int i = 0; i < dl.rows; ++i)
    if (ab[i] >= 0 && ba[ab[i]] == i) out.emplace_back(i, ab[i], static_cast<float>(dab[i]));
  return out;
}

RectifyCheck check_rectified(const cv::Mat& L, const cv::Mat& R) {
  RectifyCheck rc;
  cv::Mat gl, gr;
  cv::cvtColor(L, gl, cv::COLOR_RGB2GRAY);
  cv::cvtColor(R, gr, cv::COLOR_RGB2GRAY);
  // One pyramid level: a rectified pair's views have the same scale, and
  // FAST's corners at full resolution sit on whole pixels, so a match's dy is
  // exact; coarser levels' positions (1.2^k px steps) tilted ETH3D
  // playground's fitted plane by 0.9 px across the image.
  auto orb = cv::ORB::create(1500, 1.2f, 1);
  std::vector<cv::KeyPoint> kl, kr;
  cv::Mat dl, dr;
  orb->detectAndCompute(gl, cv::noArray(), kl, dl);
  orb->detectAndCompute(gr, cv::noArray(), kr, dr);
  std::vector<cv::DMatch> matches = mutual_nearest(dl, dr);
  // (u, v, dy) of the mutual nearest neighbours with a close descriptor (at
  // most 64 of ORB's 256 bits differ).
  std::vector<cv::Point2f> pl, pr;
  for (const cv::DMatch& m : matches) {
    if (m.distance > 64) continue;
    pl.push_back(kl[m.queryIdx].pt);
    pr.push_back(kr[m.trainIdx].pt);
  }
  // FAST's corners lie on whole pixels: refined to sub-pixel positions
  // (the corner's gradient-orthogonality, 5x5 window) so that dy is not
  // quantised.
  if (!pl.empty()) {
    const cv::TermCriteria stop(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.01);
    cv::cornerSubPix(gl, pl, cv::Size(2, 2), cv::Size(-1, -1), stop);
    cv::cornerSubPix(gr, pr, cv::Size(2, 2), cv::Size(-1, -1), stop);
  }
  std::vector<std::array<double, 3>> pts;
  for (std::size_t i = 0; i < pl.size(); ++i)
    pts.push_back({pl[i].x / L.cols, pl[i].y / L.rows, static_cast<double>(pl[i].y - pr[i].y)});
  rc.matches = pts.size();
  rc.record = {{"method", "ORB features (1500 a view, full resolution), mutual nearest neighbours, corners refined to sub-pixel; dy = a + b x + c y by RANSAC "
                          "(1 px inliers), refitted to the inliers"},
               {"matches", pts.size()}};
  if (pts.size() < 12) {
    rc.record["checked"] = false;
    rc.record["why"] = "fewer than 12 features matched between the views";
    return rc;
  }
  // RANSAC over triples (fixed seed: the same pair gives the same verdict).
  std::mt19937 rng(12345);
  std::uniform_int_distribution<std::size_t> pick(0, pts.size() - 1);
  std::vector<std::size_t> best;
  for (int it = 0; it < 400; ++it) {
    const std::vector<std::size_t> s = {pick(rng), pick(rng), pick(rng)};
    if (s[0] == s[1] || s[1] == s[2] || s[0] == s[2]) continue;
    const auto m = fit_plane(pts, s);
    if (!std::isfinite(m[0])) continue;
    std::vector<std::size_t> in;
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (std::abs(m[0] + m[1] * pts[i][0] + m[2] * pts[i][1] - pts[i][2]) <= 1.0) in.push_back(i);
    if (in.size() > best.size()) best = std::move(in);
  }
  if (best.size() < 8) {
    rc.record["checked"] = false;
    rc.record["why"] = "fewer than 8 matched features agree on one vertical offset";
    return rc;
  }
  const auto m = fit_plane(pts, best);
  rc.checked = true;
  rc.inliers = best.size();
  for (std::size_t i : best) {
    const double dx = static_cast<double>(pl[i].x) - static_cast<double>(pr[i].x);
    rc.positive += dx > 1.0;
    rc.negative += dx < -1.0;
  }
  std::vector<double> ady;
  for (std::size_t i : best) ady.push_back(std::abs(pts[i][2]));
  std::nth_element(ady.begin(), ady.begin() + ady.size() / 2, ady.end());
  rc.median_abs_dy = ady[ady.size() / 2];
  const std::pair<const char*, std::array<double, 2>> corners[] = {
      {"top-left", {0, 0}}, {"top-right", {1, 0}}, {"bottom-left", {0, 1}}, {"bottom-right", {1, 1}}};
  nlohmann::json at = nlohmann::json::object();
  for (const auto& [name, uv] : corners) {
    const double dy = m[0] + m[1] * uv[0] + m[2] * uv[1];
    at[name] = dy;
    if (std::abs(dy) >= rc.worst_px) rc.worst_px = std::abs(dy), rc.worst_corner = name;
  }
  rc.record["checked"] = true;
  rc.record["inliers"] = best.size();
  rc.record["dy_px"] = {{"a", m[0]}, {"b_per_width", m[1]}, {"c_per_height", m[2]}};
  rc.record["dy_at_corners_px"] = at;
  rc.record["median_abs_dy_px"] = rc.median_abs_dy;
  rc.record["disparity_sign"] = {{"positive", rc.positive}, {"negative", rc.negative},
                                 {"rule", "inliers at x_left - x_right > 1 px and < -1 px; swapped when at least 12 "
                                          "are negative and more than four times the positive ones"}};
  return rc;
}

// ---- the range searched when --max-disparity is auto ---------------------------
struct AutoRange {
  int max_disparity = 0;
  nlohmann::json record;
};

AutoRange auto_range(const cv::Mat& L, const cv::Mat& R, const StereoParams& p, int threads) {
  constexpr int kScale = 4;
  if (L.cols < 32 * kScale || L.rows < 16 * kScale) {  // too small for a coarse pass: a fixed range
    AutoRange a;
    a.max_disparity = std::min(L.cols - 1, 64);
    a.record = {{"method", "none: the view is under 128x64 px"}, {"max_disparity_px", a.max_disparity},
                {"rule", "min(64, width - 1)"}};
    return a;
  }
  cv::Mat l, r;
  cv::resize(L, l, cv::Size(std::max(1, L.cols / kScale), std::max(1, L.rows / kScale)), 0, 0, cv::INTER_AREA);
  cv::resize(R, r, l.size(), 0, 0, cv::INTER_AREA);
  const int nd_c = std::clamp(l.cols / 2 / 16 * 16, 16, 512);
  StereoParams q = p;
  q.block = 5;
  q.uniqueness = std::max(p.uniqueness, 10.0);
  const Matched m = match_pair(l, r, nd_c, q, threads, 1.0, 25, 1.0);
  // The largest consistent disparity, after the speckle filter.
  int largest = -1;
  std::size_t known = 0;
  for (int y = 0; y < m.disp16.rows; ++y)
    for (int x = 0; x < m.disp16.cols; ++x) {
      const short v = m.disp16.at<short>(y, x);
      if (v >= 0) ++known, largest = std::max<int>(largest, v);
    }
  AutoRange a;
  const double coarse = largest / 16.0;
  // Back to full resolution, plus one coarse pixel (the quarter-resolution
  // pass's own error) and the block's half-width of detail it cannot see.
  a.max_disparity = largest < 0 ? std::min(L.cols - 1, 64)
                                : std::min(L.cols - 1, static_cast<int>(std::ceil(kScale * (coarse + 1.0))) + p.block);
  a.record = {{"method", "SGBM at 1/4 resolution, both views, left-right check 1 px, speckles < 25 px removed"},
              {"coarse_range_px", nd_c - 1},
              {"coarse_largest_px", largest < 0 ? nlohmann::json() : nlohmann::json(coarse)},
              {"coarse_known_fraction", static_cast<double>(known) / std::max<std::size_t>(1, m.disp16.total())},
              {"max_disparity_px", a.max_disparity},
              {"rule", "4 (largest + 1) + block, at most width - 1; 64 when nothing matched"}};
  if (largest >= 16 * (nd_c - 2))
    a.record["note"] = "the coarse pass found disparities at its limit; give --max-disparity if nearer objects matter";
  return a;
}

}  // namespace

StereoResult compute_stereo(const StereoView& left, const StereoView& right, const StereoParams& p,
                            const std::string& left_flag, const std::string& right_flag, int threads) {
  const auto t0 = std::chrono::steady_clock::now();
  stereo_param_table().validate(p);
  if (p.block % 2 == 0)
    throw Error("--stereo-block " + std::to_string(p.block) + " is not allowed: the matching window needs a centre "
                "pixel; use an odd size (3, 5, 7)");
  if (left.width != right.width || left.height != right.height)
    throw Error(left_flag + " is " + std::to_string(left.width) + "x" + std::to_string(left.height) + " but " +
                right_flag + " is " + std::to_string(right.width) + "x" + std::to_string(right.height) +
                "; the views of a rectified pair have the same size (rectify them together)");
  const int W = left.width, H = left.height;
  if (W < 16 || H < 8)
    throw Error(left_flag + " is " + std::to_string(W) + "x" + std::to_string(H) +
                "; stereo matching needs at least 16x8 pixels");
  if (p.max_disparity) {
    const double n = *p.max_disparity;
    if (n != std::floor(n) || n < 1 || n > W - 1)
      throw Error("--max-disparity " + text::g(n, 9) + " is not allowed: it must be a whole number of pixels from 1 to " +
                  std::to_string(W - 1) + " (the view is " + std::to_string(W) +
                  " px wide; a match cannot lie further away); use auto to find it from a coarse pass");
  }
  const cv::Mat L = as_mat(left), R = as_mat(right);
  StereoResult out;
  nlohmann::json& rec = out.record;
  rec["method"] = "semi-global matching (Hirschmueller 2008; OpenCV StereoSGBM), both views with a left-right check, "
                  "left border padded, speckle filter, sub-pixel parabola";
  rec["params"] = stereo_param_table().to_json(p);

  const auto t_check = std::chrono::steady_clock::now();
  RectifyCheck rc = check_rectified(L, R);
  rec["rectification"] = rc.record;
  rec["rectification"]["tolerance_px"] = p.rectified_tolerance_px;
  const double check_ms = ms_since(t_check);
  if (rc.checked && rc.worst_px > p.rectified_tolerance_px)
    throw Error(left_flag + " and " + right_flag + " are not a rectified pair: the check of the vertical offset "
                "between the views (dy = a + b x + c y fitted by RANSAC to " + std::to_string(rc.inliers) + " of " +
                std::to_string(rc.matches) + " matched ORB features) finds " + text::g(rc.worst_px, 3) + " px at the " +
                rc.worst_corner + " corner (median |dy| " + text::g(rc.median_abs_dy, 3) + " px), more than "
                "--stereo-rectified-tolerance " + text::g(p.rectified_tolerance_px, 3) + " px. Matching searches along rows "
                "only: rectify the pair first (OpenCV stereoRectify and remap with the calibration), or check that "
                "the views are the left and right image of one rectified pair");

  // A swapped pair (the right view given as the left): matched along rows
  // in one direction only, it "filled" over half of ETH3D terrace with
  // wrong depth, exit 0 (issue #51). The features the check above matched
  // tell at no cost: in a pair in the right order a point's x_left -
  // x_right is >= 0, in a swapped one <= 0. Of the inliers beyond 1 px,
  // ETH3D terrace has 0 negative and 383 positive (swapped: 383 and 0),
  // playground_1l 7 and 448 (2026-12-05).
  if (rc.checked && rc.negative >= 12 && rc.negative > 4 * rc.positive && !p.allow_swapped)
    throw Error(left_flag + " and " + right_flag + " look swapped: of the " + std::to_string(rc.inliers) +
                " features matched between them, " + std::to_string(rc.negative) + " lie at negative disparity "
                "(x_left < x_right) and " + std::to_string(rc.positive) + " at positive; in a rectified pair the "
                "left view sees every point further right. Exchange the two files, or pass --stereo-allow-swapped "
                "if the pair really is in this order");

  int max_d = 0;
  const auto t_auto = std::chrono::steady_clock::now();
  if (p.max_disparity) {
    max_d = static_cast<int>(*p.max_disparity);
    rec["max_disparity"] = {{"given_px", max_d}};
  } else {
    AutoRange a = auto_range(L, R, p, threads);
    max_d = a.max_disparity;
    rec["max_disparity"] = {{"auto", a.record}};
  }
  const double auto_ms = ms_since(t_auto);
  const int nd = round_up_16(max_d + 1);
  // The work, bounded where it is decided (issue #51): semi-global matching
  // costs each disparity of each pixel in both directions, so the disparity
  // range times the pixels is its measure (brume/stereo.hpp, kMaxStereoWork).
  const double cells = static_cast<double>(nd) * W * H;
  if (cells > kMaxStereoWork)
    throw Error("stereo matching of the " + std::to_string(W) + "x" + std::to_string(H) + " pair over " +
                std::to_string(nd) + " disparities (" +
                (p.max_disparity ? "--max-disparity " + std::to_string(max_d) : "the coarse pass's range") +
                ", rounded up to a multiple of 16) is " + text::g(cells, 3) + " disparity-pixels; brume refuses "
                "more than " + text::g(kMaxStereoWork, 3) + ": give a smaller --max-disparity, or match a "
                "downscaled pair");
  // Working memory: OpenCV's cost volume (2 bytes a disparity; hh keeps the
  // whole image's, the others a few rows' of aggregated costs) in each of
  // the two directions, on the padded width.
  const double per_dir = p.mode == "hh" ? 2.0 * (W + nd) * H * nd * 2 : 2.0 * (W + nd) * nd * 2 * 16;
  check_memory(static_cast<std::uint64_t>(2 * per_dir + 64.0 * W * H), "stereo matching of a " + std::to_string(W) +
                                                                            "x" + std::to_string(H) + " pair over " +
                                                                            std::to_string(nd) + " disparities");
  rec["searched_px"] = {0, nd - 1};

  const auto t_match = std::chrono::steady_clock::now();
  Matched m = match_pair(L, R, nd, p, threads, p.lr_tolerance_px, p.speckle_window, p.speckle_range_px);
  const double match_ms = ms_since(t_match);

  // Float disparity, confidence of the matched pixels.
  out.disparity = Image(W, H, 1, NAN);
  out.confidence = Image(W, H, 1, 0.0f);
  cv::Mat known(H, W, CV_32F), dv(H, W, CV_32F), dv2(H, W, CV_32F);
  std::size_t matched = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const short v = m.disp16.at<short>(y, x);
      const bool k = v >= 0;
      const float d = k ? v / 16.0f : 0.0f;
      if (k) out.disparity.at(x, y) = d, ++matched;
      known.at<float>(y, x) = k ? 1.0f : 0.0f;
      dv.at<float>(y, x) = d;
      dv2.at<float>(y, x) = d * d;
    }
  cv::Mat sk, sd, sd2;
  cv::boxFilter(known, sk, CV_32F, cv::Size(5, 5), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  cv::boxFilter(dv, sd, CV_32F, cv::Size(5, 5), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  cv::boxFilter(dv2, sd2, CV_32F, cv::Size(5, 5), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!(known.at<float>(y, x) > 0.0f)) continue;
      const double n = sk.at<float>(y, x), mean = sd.at<float>(y, x) / n;
      const double var = std::max(0.0, sd2.at<float>(y, x) / n - mean * mean);
      const double lr = 1.0 - m.lr_diff.at<float>(y, x) / (2.0 * p.lr_tolerance_px);
      out.confidence.at(x, y) = static_cast<float>(std::clamp(lr / (1.0 + var), 0.0, 1.0));
    }

  // Fill: occluded runs take the background (step 5).
  std::size_t filled = 0;
  if (p.fill == "occlusions")
    for (int y = 0; y < H; ++y) {
      float* d = out.disparity.row(y);
      float* c = out.confidence.row(y);
      int x = 0;
      while (x < W) {
        if (std::isfinite(d[x])) {
          ++x;
          continue;
        }
        const int a = x;
        while (x < W && !std::isfinite(d[x])) ++x;
        const int len = x - a;
        if (a == 0 || x == W || len > nd) continue;
        const float v = std::min(d[a - 1], d[x]);
        for (int i = a; i < x; ++i) d[i] = v, c[i] = 0.2f;
        filled += static_cast<std::size_t>(len);
      }
    }
  const double px = static_cast<double>(W) * H;
  rec["matched_fraction"] = matched / px;
  rec["filled_fraction"] = filled / px;
  rec["unknown_fraction"] = (px - matched - filled) / px;
  rec["timing_ms"] = {{"rectification_check", check_ms}, {"range", auto_ms}, {"matching", match_ms},
                      {"total", ms_since(t0)}};
  return out;
}

}  // namespace brume
