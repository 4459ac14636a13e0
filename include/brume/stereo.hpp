// brume — disparity from a rectified stereo pair: `brume depth stereo` and
// the `--stereo-right` depth source of every effect.
//
// Convention (the one `--disparity` reads, Middlebury 2014 / ETH3D): the
// disparity of left-view pixel (x, y) is d = x - x_R in pixels of the left
// view, where (x_R, y) is the same scene point in the right view, so that
// Z = f B / (d + doffs) with calib.txt's f (px), B (m) and doffs (px). The
// disparity map is a 1-channel float image the left view's size; unknown
// pixels are NaN.
//
// Method (docs/depth.md, "Stereo pairs"):
//  1. Semi-global matching, Hirschmueller, "Stereo processing by semiglobal
//     matching and mutual information", PAMI 30(2) 2008, as OpenCV's
//     StereoSGBM computes it: the Birchfield-Tomasi sampling-insensitive
//     cost on the x-derivative prefiltered image and on the colour, summed
//     over a block x block window, aggregated along 3 directions (`3way`,
//     the default: OpenCV's MODE_SGBM_3WAY, run in parallel strips), 5
//     (`sgbm`) or 8 (`hh`), with smoothness penalties P1 = 8 C b^2 for a
//     1 px step and P2 = 32 C b^2 for larger ones (C channels, b the block
//     size); sub-pixel disparity by the parabola through the aggregated costs
//     at d - 1, d, d + 1 (1/16 px steps); a best cost that does not beat the
//     second best by `uniqueness` percent is unknown.
//  2. Both views: the right view's disparity d_R is matched the same way
//     (the mirrored pair), and a left pixel is kept only when
//     |d_L(x) - d_R(x - d_L(x))| <= `lr-tolerance` (Hirschmueller 2008,
//     section 3.4: occlusions and mismatches fail it).
//  3. The left border: OpenCV leaves the first (range) columns unknown; brume
//     pads both views on the left by the search range (edge pixels
//     replicated), so every column is matched, and a border pixel whose
//     match lies outside the right view fails the check of step 2 instead.
//  4. Speckles: 4-connected regions of fewer than `speckle-window` pixels
//     whose neighbouring disparities differ by at most `speckle-range`
//     (a small island in a different depth) are unknown (cv::filterSpeckles).
//  5. Fill (`fill occlusions`): an unknown run of a row bounded on both sides
//     by known pixels and no longer than the search range takes the smaller
//     (farther) of its two bounding disparities: a pixel occluded in the
//     right view belongs to the background (Hirschmueller 2008, 3.4). Runs
//     that reach the image's side and longer runs (sky, blank walls) stay
//     unknown; `fill none` leaves every unmatched pixel unknown.
// Confidence (0-1): 0 unknown; a filled pixel 0.2; a matched one
// (1 - |d_L - d_R| / (2 lr-tolerance)) / (1 + s^2), s the standard deviation
// [px] of the known disparities of its 5x5 neighbourhood (a consistent and
// locally smooth match is near 1).
//
// Before matching, the pair is checked to be rectified: ORB features matched
// between the views (mutual nearest neighbours), a plane dy = a + b x + c y
// fitted to their vertical offsets by RANSAC; a fitted |dy| over
// `rectified-tolerance` at any image corner (a vertical shift, a rotation,
// a scale) is an error naming the check. `--max-disparity auto` takes the
// search range from the same matcher at quarter resolution (a range of up to
// half the image's width), its largest consistent disparity times 4 plus a
// margin.
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

// The largest matching a pair may ask for, in disparities x pixels (each
// cost evaluated in both directions): 4e10, ten times Middlebury 2014 at
// full size (2880 x 1988 over 640 disparities: 3.7e9); ETH3D's two-view
// pairs over their whole calib.txt range (713 x 434 x 713) are 2.2e8, a
// KITTI frame over 256 disparities 1.2e8. Past it, --max-disparity (up to
// the width) times the pixels ran for hours (issue #51).
constexpr double kMaxStereoWork = 4e10;

struct StereoParams {
  std::optional<double> max_disparity;  // [px] largest disparity searched, whole, 1..width-1; unset: auto
  std::string mode = "3way";            // 3way (3 directions, parallel) | sgbm (5) | hh (8)
  int block = 5;                        // [px] odd, 1..11: matching window
  double uniqueness = 10.0;             // [%] 0..100: margin of the best cost over the second best
  double lr_tolerance_px = 1.0;         // [px] > 0: left-right consistency
  int speckle_window = 100;             // [px] 0 (off)..10000: largest removed speckle area
  double speckle_range_px = 2.0;        // [px] > 0: disparity step inside a speckle
  std::string fill = "occlusions";      // occlusions | none
  double rectified_tolerance_px = 1.0;  // [px] > 0: largest vertical offset between the views
  bool allow_swapped = false;           // match a pair whose features lie at negative disparity (refused: swapped)
};
const ParamTable<StereoParams>& stereo_param_table();

// A rectified pair as 8-bit encoded values (sRGB-encoded counts 0..255,
// interleaved RGB), as matchers take them: brume's linear images are
// re-encoded with stereo_view().
struct StereoView {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;  // width * height * 3
};
// An image read from `path` for matching: an 8-bit file's counts as stored,
// a 16-bit file's scaled to 8 bits, a float file (linear) sRGB-encoded and
// clamped to [0, 1]. `flag` names the option in messages.
StereoView read_stereo_view(const std::string& path, const std::string& flag, nlohmann::json* file_record = nullptr,
                            const std::string& layer = "", const std::string& layer_flag = "");

struct StereoResult {
  Image disparity;   // [px] left view's size, NaN unknown
  Image confidence;  // 0..1
  nlohmann::json record;  // parameters, the range searched, the rectification check, coverage, timing
};
// Disparity of `left` against `right` (same size, rectified). `threads`: 0 =
// two (the two views are matched side by side), else at most that many.
// Throws brume::Error naming `left_flag`/`right_flag` for mismatched sizes,
// an unrectified pair, or a --max-disparity out of range.
StereoResult compute_stereo(const StereoView& left, const StereoView& right, const StereoParams& p,
                            const std::string& left_flag = "--left", const std::string& right_flag = "--right",
                            int threads = 0);

}  // namespace brume
