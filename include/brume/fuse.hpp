// brume — a sparse depth source fused with a rectified stereo view (issue
// #52): `brume depth complete` and `--complete` on every effect with a scan
// (--velodyne, --range with unknown pixels, ...) and --stereo-right R.
//
// Method (docs/depth-sources.md, "A sparse source and a stereo view"):
//  1. The camera of the pair: f, B, doffs from --calib (Middlebury 2014 /
//     ETH3D calib.txt), from --kitti-calib (f = P2[0,0]; B = (P2[0,3] -
//     P3[0,3]) / f, the rectified cameras 2 and 3; doffs = 0), or from --fx
//     and --baseline.
//  2. The search range from the scan: the nearest return's planar depth
//     z_min gives the largest disparity the scene holds where the scan sees,
//     d = f B / z_min - doffs; the matcher (brume/stereo.hpp) searches
//     [0, ceil(1.25 d) + block] px (at most width - 1; the matcher rounds
//     the count up to a multiple of 16): the margin covers what lies up to
//     a quarter nearer than the scan's nearest return (above its field of
//     view) and the matching window's half-width twice, as the coarse pass
//     of --max-disparity auto does; the lower bound stays 0 so that what
//     lies beyond the scan's range is found. --max-disparity, when given,
//     wins.
//  3. The fit: at the pixels where both see (a scan measurement and a
//     matched disparity of confidence >= 0.25), the scan's disparity
//     d_s = f B / z_scan - doffs against the matched d: d_s = a d + b by
//     iteratively reweighted least squares with Huber's weights (k = 1.345
//     sigma, sigma = 1.4826 MAD of the residuals, at least 0.1 px), from
//     a = 1 and b = the median of d_s - d; with fewer than 50 such pixels, or
//     a scale outside [0.8, 1.25] (a pair and a scan that disagree so much
//     are not one camera), the fit falls back to the offset alone (a = 1, b
//     the median), recorded. Under 50 % of them within 1 px after the fit:
//     the pair is not used (a warning). The fit and residuals: the record.
//  4. Fusion, after the scan's completion (brume/complete.hpp): where the
//     scan supports a pixel (a measurement within the refinement's window,
//     complete-radius: measured and refined pixels) the scan's value stays.
//     Elsewhere -- above its field of view, gaps wider than the window,
//     beyond its range -- a stereo pixel (matched or occlusion-filled) of
//     confidence >= 0.25, at the fitted range z = f B / (a d + b + doffs):
//       - fills a pixel the completion left unknown or took for sky, with
//         the stereo confidence (the pair matched it: the sky rule cannot
//         tell a bright smooth wall from the sky, the pair can);
//       - confirms the completion's estimate (continued above the scan,
//         extended, or the pilot's) within 5 % of it: the estimate, which
//         comes from the returns, stays, with the larger confidence;
//       - replaces an estimate it disagrees with only where the match is
//         strong (confidence >= 0.9: the views agree within 0.1 px and the
//         5x5 disparities within ~0.3 px) and outside the left border band
//         (x below twice the range searched: the right view may not see it,
//         and the horizontal paths carry the padded border's costs inward),
//         or, a second pass, where >= 13 of its 5x5 neighbours were replaced;
//       - but not by a NEARER value where the pair itself sees the
//         estimate's depth (within 5 %, confidence >= 0.25) within
//         complete-stereo-fattening px (5, about one matching block; 0, the
//         rule of records before it, no such guard): the matcher's
//         foreground fattening, a nearer object's disparity carried a
//         block's width past its edge onto the background beside it
//         (ETH3D terrace's pillar: 0.64 -> 0.38 % of the upper 40 % off by
//         > 10 %).
//     Why (ETH3D with a KITTI-like scan, docs/depth-sources.md): the planar
//     continuation is right where surfaces continue (terrace: 1.1 % off by
//     > 10 % above the scan, the matcher alone 4.3 %: fattening beside a
//     pillar), wrong where they do not (playground_1l's canopies: 79 %, the
//     matcher 4.7 %): the rule keeps the first, takes the pair in the second.
//     Pixels the pair does not match keep the completion's value (or stay
//     unknown / sky).
#pragma once

#include <memory>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/complete.hpp"
#include "brume/image.hpp"
#include "brume/stereo.hpp"

namespace brume {

// A rectified pair's geometry: Z = f B / (d + doffs).
struct StereoGeometry {
  double f_px = 0.0, baseline_m = 0.0, doffs_px = 0.0;
  Intrinsics k;       // the left view's camera (range <-> planar depth)
  nlohmann::json record;
};

// The stereo pixels the fusion takes need at least this confidence
// (brume/stereo.hpp: a matched pixel's (1 - lr/2tol)/(1 + s^2), a filled
// occlusion's 0.2): half a pixel of left-right disagreement and a 5x5
// disparity spread of ~1.7 px give 0.25.
constexpr float kFuseMinConfidence = 0.25f;
// A stereo pixel within this fraction of the completion's estimate confirms it.
constexpr float kFuseAgree = 0.05f;
// A stereo pixel replaces an estimate it disagrees with from this confidence.
constexpr float kFuseOverrideConfidence = 0.9f;

// The second view's range, fitted to the scan: what the completion fills with.
struct StereoFill {
  Image range;       // [m] along the ray, from the fitted disparity; NaN where the pair gives none
  Image confidence;  // the matcher's, 0 where unknown
  int border_px = 0;  // twice the largest disparity searched: the left border band (step 4)
  nlohmann::json record;  // the matching, the search range, the fit
};

// The largest disparity to search for the scan `scan_range` (metres along
// the ray, NaN unknown) in geometry g, for a matching window of `block` px:
// step 2 above; 0 when the scan has no return. `rule` gets the rule and its numbers.
int stereo_search_bound(DenseImageRef scan_range, const StereoGeometry& g, int width, int block, nlohmann::json* rule);

// Step 3: the matched disparity fitted to the scan and converted to range.
StereoFill fit_stereo_to_scan(DenseImageRef scan_range, const StereoResult& st, const StereoGeometry& g);

// Step 4 on a completion of `scan_range` (radius: its complete-radius):
// the stereo fill takes the pixels the scan does not support. Returns the
// record block ("stereo_fusion").
// fattening_px: complete-stereo-fattening (0: no guard).
nlohmann::json fuse_stereo(CompleteResult& done, DenseImageRef scan_range, const StereoFill& fill, int radius,
                           int fattening_px = 0);

}  // namespace brume
