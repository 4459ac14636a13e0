// brume — a sparse depth source fused with a stereo view (see brume/fuse.hpp).
#include "brume/fuse.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "core/text.hpp"

namespace brume {

namespace {

// The length of pixel (x, y)'s ray per unit of planar depth.
double ray_factor(const Intrinsics& k, int x, int y) {
  const double a = (x - k.cx) / k.fx, b = (y - k.cy) / k.fy;
  return std::sqrt(1.0 + a * a + b * b);
}

double median_of(std::vector<double> v) {
  if (v.empty()) return NAN;
  const std::size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(m), v.end());
  return v[m];
}

// One pixel both see: the matched disparity d and the scan's d_s.
struct BothSee {
  double d, ds;
};

nlohmann::json residuals(const std::vector<BothSee>& pairs, double a, double b) {
  std::vector<double> r;
  r.reserve(pairs.size());
  double s2 = 0.0;
  std::size_t within = 0;
  for (const BothSee& p : pairs) {
    const double e = p.ds - (a * p.d + b);
    r.push_back(std::abs(e));
    s2 += e * e;
    within += std::abs(e) <= 1.0 ? 1 : 0;
  }
  const double n = static_cast<double>(std::max<std::size_t>(1, pairs.size()));
  return {{"median_abs_px", pairs.empty() ? nlohmann::json() : nlohmann::json(median_of(std::move(r)))},
          {"rms_px", std::sqrt(s2 / n)},
          {"within_1px_fraction", within / n}};
}

}  // namespace

int stereo_search_bound(DenseImageRef scan, const StereoGeometry& g, int width, int block, nlohmann::json* rule) {
  double z_min = INFINITY;
  for (int y = 0; y < scan.height; ++y)
    for (int x = 0; x < scan.width; ++x) {
      const float r = scan.at(x, y);
      if (known_range(r) && r > 0.0f) z_min = std::min(z_min, r / ray_factor(g.k, x, y));
    }
  const double d_near = std::isfinite(z_min) ? g.f_px * g.baseline_m / z_min - g.doffs_px : NAN;
  if (!(d_near > 0.0)) return 0;
  const int bound = std::min(width - 1, static_cast<int>(std::ceil(1.25 * d_near)) + block);
  if (rule)
    *rule = {{"rule", "[0, ceil(1.25 d_near) + block] px, at most width - 1; d_near = f B / z_min - doffs, z_min the "
                      "planar depth of the scan's nearest return"},
             {"z_min_m", z_min},
             {"d_near_px", d_near},
             {"max_disparity_px", bound}};
  return bound;
}

StereoFill fit_stereo_to_scan(DenseImageRef scan, const StereoResult& st, const StereoGeometry& g) {
  const int W = st.disparity.width, H = st.disparity.height;
  const double fb = g.f_px * g.baseline_m;
  std::vector<BothSee> pairs;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = scan.at(x, y), d = st.disparity.at(x, y);
      if (!known_range(r) || !(r > 0.0f) || !std::isfinite(d) || st.confidence.at(x, y) < kFuseMinConfidence)
        continue;
      pairs.push_back({d, fb / (r / ray_factor(g.k, x, y)) - g.doffs_px});
    }
  // Huber IRLS of d_s = a d + b from a = 1, b = median(d_s - d).
  std::vector<double> diff;
  diff.reserve(pairs.size());
  for (const BothSee& p : pairs) diff.push_back(p.ds - p.d);
  const double b0 = pairs.empty() ? 0.0 : median_of(diff);
  double a = 1.0, b = b0;
  int iterations = 0;
  constexpr std::size_t kMinPairs = 50;
  if (pairs.size() >= kMinPairs) {
    std::vector<double> e(pairs.size());
    for (; iterations < 30; ++iterations) {
      for (std::size_t i = 0; i < pairs.size(); ++i) e[i] = pairs[i].ds - (a * pairs[i].d + b);
      std::vector<double> ae(e.size());
      const double med = median_of(e);
      for (std::size_t i = 0; i < e.size(); ++i) ae[i] = std::abs(e[i] - med);
      const double k = 1.345 * std::max(0.1, 1.4826 * median_of(ae));
      double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
      for (std::size_t i = 0; i < pairs.size(); ++i) {
        const double w = std::abs(e[i]) <= k ? 1.0 : k / std::abs(e[i]);
        sw += w, sx += w * pairs[i].d, sy += w * pairs[i].ds;
        sxx += w * pairs[i].d * pairs[i].d, sxy += w * pairs[i].d * pairs[i].ds;
      }
      const double det = sw * sxx - sx * sx;
      if (!(std::abs(det) > 1e-12 * sw * sxx)) break;
      const double na = (sw * sxy - sx * sy) / det, nb = (sy - na * sx) / sw;
      const bool done = std::abs(na - a) < 1e-7 && std::abs(nb - b) < 1e-5;
      a = na, b = nb;
      if (done) break;
    }
  }
  std::string model = "d_s = a d + b, Huber IRLS (k = 1.345 sigma, sigma = 1.4826 MAD, >= 0.1 px)";
  if (pairs.size() < kMinPairs) {
    model = "offset only (fewer than 50 pixels both see): d_s = d + median(d_s - d)";
    a = 1.0, b = pairs.empty() ? 0.0 : b0;
  } else if (!(a >= 0.8 && a <= 1.25)) {
    model = "offset only (the fitted scale " + std::to_string(a) + " is outside [0.8, 1.25]): d_s = d + median(d_s - d)";
    a = 1.0, b = b0;
  }

  StereoFill out;
  out.border_px = st.record.contains("searched_px") ? 2 * st.record["searched_px"][1].get<int>() : 0;
  out.range = Image(W, H, 1, NAN);
  out.confidence = st.confidence;
  std::size_t valid = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float d = st.disparity.at(x, y);
      const double dd = a * d + b + g.doffs_px;
      if (std::isfinite(d) && dd > 0.0) {
        out.range.at(x, y) = static_cast<float>(fb / dd * ray_factor(g.k, x, y));
        ++valid;
      } else {
        out.confidence.at(x, y) = 0.0f;
      }
    }
  out.record = {{"model", model},
                {"scale", a},
                {"offset_px", b},
                {"pixels_both_see", pairs.size()},
                {"iterations", iterations},
                {"pair_rule", "a scan measurement and a matched disparity of confidence >= " +
                                  text::g(kFuseMinConfidence, 3)},
                {"residuals_before", residuals(pairs, 1.0, 0.0)},
                {"residuals_after", residuals(pairs, a, b)},
                {"valid_fraction", static_cast<double>(valid) / std::max<std::size_t>(1, out.range.pixels())},
                {"used", true}};
  // A pair that does not agree with the scan where both see (fewer than
  // half the pixels within 1 px after the fit: another scene, a view given
  // twice, a calibration of another pair) would fill with nonsense: unused.
  const double within = out.record["residuals_after"]["within_1px_fraction"].get<double>();
  if (pairs.size() >= kMinPairs && within < 0.5) {
    std::fill(out.confidence.data.begin(), out.confidence.data.end(), 0.0f);
    out.record["used"] = false;
    out.record["warning"] = "the second view disagrees with the scan where both see (" + text::g(100 * within, 3) +
                            " % of " + std::to_string(pairs.size()) + " pixels within 1 px of disparity after the "
                            "fit, at least 50 % needed): it is not used; check that the views and the scan belong "
                            "together and the calibration is theirs";
  }
  return out;
}

nlohmann::json fuse_stereo(CompleteResult& done, DenseImageRef scan, const StereoFill& fill, int radius,
                           int fattening_px) {
  const int W = scan.width, H = scan.height;
  if (fill.range.width != W || fill.range.height != H || done.range.width != W || done.range.height != H)
    throw Error("the stereo view's range is " + fill.range.size_string() + " but the completed scan is " +
                scan.size_string() + "; the fusion needs both at the image's size (a scaled preview cannot fuse)");
  // Summed-area table of the measurements: a pixel is the scan's when one
  // lies within its (2 radius + 1)^2 window (the refinement's).
  std::vector<int> sat(static_cast<std::size_t>(W + 1) * (H + 1), 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      sat[(y + 1) * (W + 1) + x + 1] = (known_range(scan.at(x, y)) ? 1 : 0) + sat[y * (W + 1) + x + 1] +
                                       sat[(y + 1) * (W + 1) + x] - sat[y * (W + 1) + x];
  std::size_t taken = 0, over_sky = 0, over_unknown = 0, over_estimate = 0, scan_supported = 0, agreed = 0,
              kept = 0, by_region = 0;
  // Per pixel: an estimate the pair replaced, or one it disagreed with but left.
  constexpr std::uint8_t kOverEstimate = 1, kKept = 2, kFattened = 3;
  std::size_t fattened = 0;
  // The matcher's foreground fattening (fattening_px > 0): does the pair
  // itself see the estimate r's depth within fattening_px of (x, y)?
  auto pair_sees = [&](int x, int y, float r) {
    for (int yy = std::max(0, y - fattening_px); yy <= std::min(H - 1, y + fattening_px); ++yy)
      for (int xx = std::max(0, x - fattening_px); xx <= std::min(W - 1, x + fattening_px); ++xx) {
        const float v = fill.range.at(xx, yy);
        if (std::isfinite(v) && fill.confidence.at(xx, yy) >= kFuseMinConfidence && std::abs(v - r) <= kFuseAgree * v)
          return true;
      }
    return false;
  };
  std::vector<std::uint8_t> state(static_cast<std::size_t>(W) * H, 0);
  for (int y = 0; y < H; ++y) {
    const int y0 = std::max(0, y - radius), y1 = std::min(H, y + radius + 1);
    for (int x = 0; x < W; ++x) {
      const int x0 = std::max(0, x - radius), x1 = std::min(W, x + radius + 1);
      const int n = sat[y1 * (W + 1) + x1] - sat[y0 * (W + 1) + x1] - sat[y1 * (W + 1) + x0] + sat[y0 * (W + 1) + x0];
      if (n > 0) {
        ++scan_supported;
        continue;
      }
      const float v = fill.range.at(x, y), c = fill.confidence.at(x, y);
      if (!std::isfinite(v) || c < kFuseMinConfidence) continue;
      float& r = done.range.at(x, y);
      float& conf = done.confidence.at(x, y);
      float& sky = done.sky_mask.at(x, y);
      if (std::isfinite(r) && sky == 0.0f) {
        // The completion's estimate (continued, extended or the pilot's):
        // confirmed where the pair agrees, replaced only by a strong match.
        if (std::abs(r - v) <= kFuseAgree * v) {
          ++agreed;
          conf = std::max(conf, c);
          continue;
        }
        if (c < kFuseOverrideConfidence || x < fill.border_px) {
          ++kept;
          state[static_cast<std::size_t>(y) * W + x] = kKept;
          continue;
        }
        if (fattening_px > 0 && v < r && pair_sees(x, y, r)) {
          // Nearer, beside where the pair sees the estimate's depth: the
          // matcher's fattening of a nearer object; the estimate stays (and
          // the region pass below does not take it either).
          ++kept, ++fattened;
          state[static_cast<std::size_t>(y) * W + x] = kFattened;
          continue;
        }
        ++over_estimate;
        state[static_cast<std::size_t>(y) * W + x] = kOverEstimate;
      } else if (sky > 0.0f) {
        ++over_sky, sky = 0.0f;
      } else {
        ++over_unknown;
      }
      ++taken;
      r = v;
      conf = c;
    }
  }
  // A disagreeing estimate left by the pixel rule inside a region the pair
  // replaced (at least 13 of its 5x5 neighbourhood replaced: a weaker match
  // amid strong ones, e.g. the streaks of a canopy) takes the pair's value.
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (state[static_cast<std::size_t>(y) * W + x] != kKept) continue;
      int n = 0;
      for (int yy = std::max(0, y - 2); yy <= std::min(H - 1, y + 2); ++yy)
        for (int xx = std::max(0, x - 2); xx <= std::min(W - 1, x + 2); ++xx)
          n += state[static_cast<std::size_t>(yy) * W + xx] == kOverEstimate ? 1 : 0;
      if (n < 13) continue;
      done.range.at(x, y) = fill.range.at(x, y);
      done.confidence.at(x, y) = fill.confidence.at(x, y);
      ++by_region, ++taken, ++over_estimate, --kept;
    }
  std::size_t finite = 0;
  for (float v : done.range.data) finite += std::isfinite(v) ? 1 : 0;
  const double px = static_cast<double>(std::max<std::size_t>(1, done.range.pixels()));
  done.completed_fraction = finite / px;
  nlohmann::json rec = {{"rule", "where a measurement lies within the refinement's window (complete-radius) the scan's completion "
                   "stays; elsewhere a stereo pixel of confidence >= " + text::g(kFuseMinConfidence, 3) +
                       " fills what the completion left unknown or took for sky, confirms an estimate within " +
                       text::g(100 * kFuseAgree, 3) + " % of it (the estimate stays, its confidence the larger), "
                       "and replaces one it disagrees with only at confidence >= " +
                       text::g(kFuseOverrideConfidence, 3) + " outside the left border band (x < " +
                       std::to_string(fill.border_px) + " px, twice the range searched), or where at least 13 of "
                       "its 5x5 neighbours were so replaced"},
          {"stereo_by_region_fraction", by_region / px},
          {"scan_supported_fraction", scan_supported / px},
          {"stereo_fraction", taken / px},
          {"stereo_over_estimate_fraction", over_estimate / px},
          {"stereo_over_sky_fraction", over_sky / px},
          {"stereo_over_unknown_fraction", over_unknown / px},
          {"estimate_confirmed_fraction", agreed / px},
          {"estimate_kept_fraction", kept / px},
          {"completed_fraction", done.completed_fraction}};
  if (fattening_px > 0) {  // (records before the guard say nothing of it)
    rec["rule"] = rec["rule"].get<std::string>() + "; never by a nearer value where the pair sees the estimate's depth "
                  "(within " + text::g(100 * kFuseAgree, 3) + " %) within " + std::to_string(fattening_px) +
                  " px: the matcher's foreground fattening";
    rec["stereo_fattening_px"] = fattening_px;
    rec["estimate_kept_as_fattening_fraction"] = fattened / px;
  }
  return rec;
}

}  // namespace brume
