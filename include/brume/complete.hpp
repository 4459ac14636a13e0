// brume — depth completion: a sparse range map (a projected lidar scan, a
// stereo map with large holes) and its colour image -> a dense range map of
// the image's size, a per-pixel confidence, and the sky left unknown.
//
// Method (classical, image-guided, on the CPU):
//
//  0. Occlusion (complete-occlusion auto, the default since issue #52: on
//     for a scan taken from beside the camera, --velodyne, off for a map
//     seen from the camera itself; off is the rule of records before it): a
//     return the camera cannot see is dropped before completion. KITTI's scanner sits 8 cm above, 27 cm
//     behind and 6 cm beside camera 2, so it sees past a foreground object's
//     top and right edges, and through glass and gaps: in the image such a
//     background return lies INSIDE the foreground object, next to the
//     object's own, nearer returns (the scan lines below it, the samples on
//     its left). Rule (occluded_returns): a return R_p is dropped when a
//     return R_q of the window x-3..x+3, y-1..y+8 (the next scan line below
//     is 3-6 rows away) is nearer by more than 10 % and by more than
//     0.03 m^-1 in inverse range (1/R_q - 1/R_p > 0.03: at least ~1.6 px of
//     parallax for the 7.6 cm vertical offset at KITTI's fx = 721 px, while
//     consecutive scan lines on flat ground differ by ~0.004 m^-1). The
//     dropped pixels are completed like any other unmeasured pixel, from
//     the returns around them (the foreground's). Chosen on KITTI 000001's
//     held-out returns with seeds 101-110 (tests/test_complete.cpp reports
//     seeds 1-10); it drops 2.6 % of that frame's returns. On a map seen
//     from the camera itself nothing is hidden and the rule would only drop
//     visible background next to a foreground edge (ETH3D terrace with a
//     simulated scan: the MAE between its lines 8 -> 11 mm): auto leaves
//     such maps alone.
//  1. Pilot: the morphological pipeline of Ku, Harakeh and Waslander, "In
//     defense of classical image processing: fast depth completion on the
//     CPU" (CRV 2018), section III, on the inverted range D' = D_max - R
//     (so that a dilation keeps the NEAREST value, which covers the
//     background points a lidar sees past a foreground edge): dilation with
//     a 5x5 diamond kernel; closing with a 5x5 full kernel; empty pixels
//     filled by a 7x7 dilation, then by a 31x31 dilation; a 5x5 median and
//     a 5x5 Gaussian (sigma 0 = OpenCV's 1.1 px) on the filled pixels. The
//     paper's "extend to the top of the frame" is replaced by step 3's rule.
//     D_max = 1.05 max R + 1 m. Kernel sizes are the paper's best (its
//     Table I); they are constants, not parameters.
//  2. Guided refinement: at every pixel p without a measurement, within
//     radius r (complete-radius) of measured pixels q,
//
//        R(p) = sum_q w_pq R_q / sum_q w_pq,
//        w_pq = exp(-|p-q|^2 / 2 s_x^2)                       (space)
//             * exp(-|g_p - g_q|^2 / 2 s_c^2)                 (colour)
//             * exp(-((R_q - P_p) / (s_r P_p))^2 / 2)          (range),
//
//     a joint (cross) bilateral filter of the measurements (Kopf et al.,
//     "Joint bilateral upsampling", SIGGRAPH 2007; normalised convolution,
//     Knutsson & Westin 1993), with a third, range term against the pilot
//     P (a joint trilateral filter): g is the colour image sRGB-encoded in
//     [0, 1] (where a difference is closer to what is seen), s_x
//     complete-sigma-space [px], s_c complete-sigma-colour, s_r
//     complete-sigma-range (relative). The colour term stops the average at
//     image edges, the range term keeps a pixel with the depth layer the
//     pilot put it on. Where that layer holds less than 5 % of the space and
//     colour weight (sum w < 0.05 sum w_space w_colour: the pilot's
//     nearest-wins dilation crossed an image edge) and that weight is at
//     least 0.3 (about one measurement of the pixel's colour within 2 px),
//     the range term is dropped and the measurements of the pixel's colour
//     decide. Either way R(p) lies in [min, max] of the measurements around
//     p. Elsewhere the pilot stays. Measured pixels keep their value exactly.
//  2b. Depth edges (complete-edges image, the default since issue #52;
//     nearest is the rule of records before it): the pilot keeps the
//     NEAREST return, so where a pixel of the background lies next to a
//     foreground object (the returns around it split into two depth
//     layers) the range term above pulls it onto the foreground. A second,
//     far pilot F keeps the FARTHEST return (5x5 diamond dilation of the
//     range, empty pixels filled by a 7x7 one). At a depth edge, F > 1.05 P:
//       - the space-and-colour weight also falls with the image edges that
//         the straight path from q to p crosses:
//           w_space w_colour * exp(-m_pq / 2 s_c^2), m_pq the largest
//           squared sRGB difference of consecutive pixels on the path
//           (the rounded line from q to p, both ends included: for a
//           neighbour, the colour term once more);
//         a return of the same colour behind an edge (a dark car beside a
//         dark shadow) no longer counts as the pixel's own side;
//       - the trilateral mean is also taken against F (the far layer); the
//         far layer is taken when its weight is more than 3 times the near
//         layer's: the image says the pixel belongs to the background
//         (votes of 1-2 also took background for foreground pixels of
//         KITTI 000001's held-out returns, 3-4 did not).
//     Chosen on KITTI 000001's held-out returns (seeds 1-10, checked on
//     101-110) and the ETH3D scans of tests/test_complete.cpp (no figure
//     between their scan lines worse): 1.05, 3 and s_c for the path.
//  3. Above and beside the scan (no pilot value): SKY or STRUCTURE, per
//     region, from the image and the scan's extent:
//       the scan's upper limit: in each column, its topmost measurement
//         (median over 5 columns); only pixels above it can be sky;
//       candidate sky: pixels above the limit, with no measurement within 1 px, that are bright
//         (brightness >= complete-sky-luminance x the image's 99th percentile
//         of it; brightness: complete-sky-brightness max, the largest sRGB
//         channel, or luma, sRGB luma, the rule of records before it) and
//         smooth (standard deviation of luma in a 5x5 window <=
//         complete-sky-roughness), closed with a 5x5 kernel (thin wires and
//         twigs against the sky stay sky), then cut back to above the limit;
//         by luma a clear blue sky (KITTI 000001's: sRGB (0.55, 0.85, 1),
//         luma 0.8) is darker than a saturated white one, and GeoPose3K's
//         Matterhorn's deep blue (0.14, 0.45, 0.82), luma 0.41, fell under
//         0.7 x its snow's 0.80; by the largest channel both are 0.82-1;
//       sky: the 8-connected regions of candidates that touch the top row
//         of the image, then grown by up to complete-sky-edge (3) 8-connected
//         steps into pixels above the limit, with no measurement within 1 px,
//         that are bright (as above; smooth or not) and within 0.3 (sRGB) of
//         a sky neighbour's colour (a bright edge unlike the sky, KITTI's
//         bluish truck roof beside the white sky, stays): the 5x5 roughness window
//         straddles the sky's border with a treeline, so the regions stop
//         2 px short of it, and the sky between the leaves of the crown's rim
//         is rough too (0: no growth, the rule of records before it: on KITTI
//         000001 the 2-4 px rim of blue sky took the trees' depth and
//         stayed blue under haze or rain, a cyan halo); the sky is unknown
//         (NaN) in the output, also where the pilot's 31x31 fill had reached
//         it (the pilot does not know the sky);
//       structure: every other pixel without a value; it takes the value of
//         the nearest estimate below it in its column (above the scan's
//         upper limit: Ku's "extend to top"), else above it, with
//         confidence 0.2 exp(-d / 32 px), d its distance in rows to that
//         estimate. A column without any estimate stays unknown (the range
//         preparation fills it as a hole).
//     A bright, smooth wall that reaches the top of the frame above the scan
//     is taken for sky: no image rule can tell them apart without depth.
//  3c. complete-method planar (the default since issue #52; `column` is the
//     rule of step 3b alone, the only one of records before it): above the
//     scan, structure CONTINUES what the scan saw instead of taking its
//     column's nearest estimate (which, above the scan, is the pilot's 31x31
//     fill: far values). A vertical surface seen by a level camera has a
//     constant PLANAR depth z along each image column (a point of the plane
//     a X + c Z = d on the ray of column u has X/Z = (u - cx)/fx, so
//     Z (a (u - cx)/fx + c) = d whatever the row), so z is continued, not
//     the range:
//       seed: each column's planar depth at its topmost measurement, the
//         median of the planar depths of its three topmost measurements (one
//         stray return, a wire or a background point seen through leaves,
//         does not move it);
//       upward sweep, row by row from the seed: a pixel above its column's
//         topmost measurement that is neither sky nor measured nor refined
//         (step 2, i.e. near a measurement) takes the colour-weighted mean of
//         the planar depths of its three neighbours below (x-1, x, x+1; the
//         diagonal ones at half weight, each times
//         exp(-|g_p - g_q|^2 / 2 s_c^2), s_c complete-sigma-colour), so that
//         depth follows image segments, not only the column; refined pixels
//         keep their value and pass their planar depth on; sky pixels stop
//         the sweep (their columns above take their neighbours' depth or
//         none);
//       never behind the sky: a continued depth is at most the farthest
//         measurement (R_max; the preparation puts the sky at or beyond it);
//       range = z sqrt(1 + ((x - cx)/fx)^2 + ((y - cy)/fy)^2) with the
//         camera's intrinsics when the source gives them (KITTI: P2;
//         calib.txt; --fx...), else cx, cy at the image centre and fx = fy =
//         the image width (a 53 degree field of view; z and range differ by
//         < 4 % over such a frame);
//       confidence 0.2 exp(-d / 32 px), d the rows from the column's topmost
//         measurement.
//     Pixels it leaves without a value (below the scan, columns without any
//     measurement) take step 3b's rule.
//  4. Confidence in [0, 1]: 1 at measurements; sum w / (sum w + 0.5) from
//     the refinement (with the space and colour terms only: how much
//     measured support the pixel had); 0.3 where only the pilot filled it;
//     the structure rule's above; 0 at the sky and wherever unknown.
//
// Cost (bench/bench_complete.cpp): O(N) for the morphology and the sky rule,
// O(measurements x (2r+1)^2) for the refinement (a scatter from each
// measurement, in row bands so that the result does not depend on threads).
#pragma once

#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/depth.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

// How structure above the scan is filled (step 3b or 3c).
enum class CompleteMethod { column, planar };
const EnumNames<CompleteMethod>& complete_method_names();
// Whether returns the camera cannot see are dropped first (step 0): auto
// drops them from a scan taken from beside the camera (offset_scan: KITTI's
// --velodyne), not from a map seen from the camera itself (a render, a
// stereo map, a depth camera), where no return is hidden from it.
enum class CompleteOcclusion { off, on, automatic };
const EnumNames<CompleteOcclusion>& complete_occlusion_names();
// What the sky rule calls bright (step 3): sRGB luma (the rule of records
// before it) or the largest sRGB channel (a clear blue sky is as bright as a
// white one by it: KITTI 000001's and GeoPose3K's blue skies).
enum class CompleteSkyBrightness { luma, max_channel };
const EnumNames<CompleteSkyBrightness>& complete_sky_brightness_names();
// Which depth layer a pixel at a depth edge takes (step 2b): the pilot's
// nearest (the rule of records before it) or the one the image gives it.
enum class CompleteEdges { nearest, image };
const EnumNames<CompleteEdges>& complete_edges_names();

struct CompleteParams {
  // The refinement's defaults: near the smallest RMSE at KITTI 000001's
  // held-out points over r 3-8, s_x 1.5-3, s_c 0.05-0.2, s_r 0.04-0.3 (r 6
  // gains 0.4 % of RMSE for 40 % more time; beyond 6 nothing changes).
  int radius_px = 5;                // [px] r, refinement window radius, 1..32
  double sigma_space_px = 2.0;      // [px] s_x, spatial scale of the refinement, > 0
  double sigma_colour = 0.1;        // [1] s_c, colour scale (sRGB-encoded [0, 1] units), > 0
  double sigma_range = 0.15;        // [1] s_r, range scale relative to the pilot, > 0
  double sky_luminance = 0.7;       // [1] sky: luma >= this x the image's 99th percentile, [0, 1]
  double sky_roughness = 0.03;      // [1] sky: 5x5 standard deviation of luma <= this, >= 0
  // Bright by the largest channel (issue: the blue sky beside a saturated
  // one; luma is the rule of records before it: since(4, "luma")).
  CompleteSkyBrightness sky_brightness = CompleteSkyBrightness::max_channel;
  // [px] the sky grows by up to this many pixels (8-connected steps) into
  // bright unmeasured pixels above the scan: its edge, which the roughness
  // window (it straddles the sky's edge) leaves out, 0..16; 0: none (the
  // rule of records before it: since(4, 0)).
  int sky_edge_px = 3;
  // [1] a pixel whose blue exceeds its red by at least this (sRGB), and is
  // no smaller than its green, is bright enough for the sky: a clear sky
  // darker than the scene's snow or clouds (GeoPose3K's alpine sky), [0, 1];
  // 0: off (the rule of records before it: since(4, 0)).
  double sky_blue = 0.2;
  // [1] unmeasured pixels no brighter than this (largest sRGB channel) and
  // connected to the frame's edge through such pixels are a border outside
  // the picture (a panorama's warp, a letterbox): they join the sky above
  // the scan, which touches the top row through them, [0, 0.2]; 0: none
  // (the rule of records before it: since(4, 0)).
  double sky_border = 0.03;
  // Structure above the scan: planar (3c, issue #52) or column (3b, the rule
  // of records before it: since(4, "column")).
  CompleteMethod method = CompleteMethod::planar;
  // Returns behind a nearer return just below or beside them dropped (step
  // 0, issue #52; auto: for an offset scan) or all kept (the rule of records
  // before it: since(4, "off")).
  CompleteOcclusion occlusion = CompleteOcclusion::automatic;
  // Depth edges (step 2b, issue #52): the layer the image gives a pixel
  // (image) or the pilot's nearest (the rule of records before it:
  // since(4, "nearest")).
  CompleteEdges edges = CompleteEdges::image;
  // [px] fusion with a second view (brume/fuse.hpp step 4): a stereo value
  // nearer than the completion's estimate does not replace it where the
  // pair sees the estimate's depth within this distance (the matcher's
  // foreground fattening), 0..32; 0: no guard (the rule of records before
  // it: since(4, 0)).
  int stereo_fattening_px = 5;
  // Not a parameter: the range map is a scan projected from a sensor beside
  // the camera (--velodyne; LoadedDepth::offset_scan), for occlusion auto.
  bool offset_scan = false;
};
const ParamTable<CompleteParams>& complete_param_table();
// --complete-stereo-fattening given (`given`: the names set explicitly)
// where no second view is fused (`fused` false: no --stereo-right, or
// arrays) is refused: a parameter the run would ignore.
void check_stereo_fattening_given(bool fused, const std::set<std::string>& given);

struct CompleteResult {
  Image range;       // metres along the ray; NaN at the sky and where no rule gives a value
  Image confidence;  // [0, 1] per pixel
  Image sky_mask;    // 1 where the sky rule says sky, else 0
  double known_fraction = 0.0;      // measured pixels / all
  double completed_fraction = 0.0;  // finite output pixels / all
  std::size_t measured = 0, refined = 0, pilot_only = 0, extrapolated = 0, sky = 0, unknown = 0;
  std::size_t continued = 0;        // planar: pixels above the scan given a continued planar depth (3c)
  std::size_t occluded = 0;         // returns dropped by the occlusion rule (step 0)
  int scan_top_row = -1;            // topmost row with a measurement
  double d_max_m = 0.0;             // inversion constant of the pilot
};

// The span of measurements a completion takes [m] (issue #51: 3e38 gave inf,
// 1e-30 nonsense, silently). Below 1 mm the pilot's inversion
// D' = D_max - R, with D_max = 1.05 R_max + 1 m, keeps less than 1e-4 of R
// in float (its rounding is ~1.2e-7 m near 1 m); above 1000 km no range map
// of brume's sources measures (GeoPose3K's farthest mountains are ~100 km,
// KITTI's scan 120 m), and 1.05 R_max overflows float from 3.2e38 (a fill
// value such as FLT_MAX). A measurement outside it is refused, naming the
// pixel: give the file's fill value as --unknown-value, or fix its units.
constexpr double kCompleteRangeMinM = 1e-3;
constexpr double kCompleteRangeMaxM = 1e6;

// `range`: 1 channel, metres along the ray, unknown as NaN, +-inf or 0;
// `guide`: the colour image (3 channels, linear RGB, as read), same size.
// Throws brume::Error for a size mismatch, a negative range, a measurement
// outside [kCompleteRangeMinM, kCompleteRangeMaxM], or no measured pixel at
// all (e.g. a scan with no point in view). threads: OpenMP threads
// (0 = all; the result does not depend on it).
// camera: the intrinsics of the camera the range map belongs to (for the
// planar method's range <-> planar depth), or null (see 3c).
CompleteResult complete_range(DenseImageRef range, DenseImageRef guide, const CompleteParams& p = {}, int threads = 0,
                              const Intrinsics* camera = nullptr);

// Step 0's rule: 1 at each return (a finite range > 0) of `range` (1
// channel, metres along the ray) that a nearer return just below or beside
// it marks as not seen by the camera, else 0. The held-out tests and the
// bench score completion on the returns this rule keeps (and on all).
std::vector<std::uint8_t> occluded_returns(DenseImageRef range, int threads = 0);

// The record of a completion: method, parameters and what was found.
nlohmann::json complete_record(const CompleteParams& p, const CompleteResult& r);

}  // namespace brume
