// brume — range-map preparation (Hansard §4.1): hole filling, sky
// identification and horizon matting. Known values are never changed.
//
//  1. Unknown pixels (NaN, inf, 0) are grouped into 8-connected components.
//     A component is SKY if it touches the top image border and covers at
//     least sky_min_fraction of the image, or covers at least
//     sky_large_fraction of the image anywhere; every other component is a
//     HOLE.
//  2. Each hole is filled with one constant: RANSAC over the known values on
//     its boundary (the known pixels 4-adjacent to it), choosing the value
//     with the smallest robust (Tukey biweight) sum of gradients across the
//     boundary. The value therefore lies within the boundary's range.
//  3. Sky gets S_max = s_max_factor * R_max (> R_max).
//  4. A margin of width mu (sky_margin_px) between scene and sky -- the sky
//     pixels whose exact Euclidean distance to the scene is <= mu -- is solved
//     for Laplace's equation, S = R on the scene side and S = S_max on the sky
//     side, to a stated residual (not the paper's fixed ~2 mu Jacobi sweeps).
//     The same system with 0 on the scene side and 1 on the sky side (and
//     above the top row: the sky goes on above the frame) gives the sky
//     weight w (harmonic across the margin, exactly 1 on the sky beyond it,
//     0 elsewhere): the effects in physical units blend the
//     scene's and the sky's transmissions with it (brume/haze.hpp, "The sky").
//  5. Inputs whose known pixels cover less than min_coverage of the image (a
//     projected lidar scan) are refused with a message: filling them would
//     invent most of the map.
#pragma once

#include <cstdint>
#include <vector>

#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

struct PrepareParams {
  double sky_margin_px = 8.0;        // [px] mu, width of the matted horizon, >= 0
  double sky_min_fraction = 0.005;   // [1] top-touching unknown area that counts as sky
  double sky_large_fraction = 0.05;  // [1] unknown area that counts as sky anywhere
  double s_max_factor = 1.25;        // [1] S_max = factor * R_max, > 1
  double min_coverage = 0.2;         // [1] smallest known fraction accepted
  double residual_tol = 1e-6;        // [1] margin solve: max |discrete Laplacian| / S_max
  int ransac_iterations = 64;        // candidate values tried per hole
  std::uint64_t seed = 1;            // RANSAC seed (results are deterministic)
};
// The block that declares all eight preparation parameters (--sky-margin, ...).
const ParamTable<PrepareParams>& prepare_param_table();

struct PrepareResult {
  Image range;        // prepared range in metres, every value finite and > 0
  Image sky_mask;     // 1 where the pixel is sky (including the margin), else 0
  Image hole_mask;    // 1 where a hole was filled, else 0
  Image margin_mask;  // 1 where the margin was solved, else 0
  Image sky_weight;   // (when asked for) 1 on the sky beyond the margin, harmonic in (0, 1) across the margin, else 0
  double range_max_m = 0.0;  // R_max: largest known range
  double s_max_m = 0.0;      // S_max assigned to the sky
  double known_fraction = 0.0;
  std::size_t holes = 0, hole_pixels = 0, sky_pixels = 0, margin_pixels = 0;
  double margin_residual = 0.0;  // achieved max |discrete Laplacian| / S_max over the margin
  int solver_iterations = 0;
  double weight_residual = 0.0;  // the sky weight's max |discrete Laplacian| (of 1) over the margin
  int weight_iterations = 0;
};

// Throws brume::Error for sparse or empty inputs (message says what to do).
// threads: the OpenMP threads of its parallel loops (0 = all hardware
// threads, as Exec::threads; the result does not depend on it). OpenCV's
// labelling and distance transform run on OpenCV's own pool. sky_weight:
// also solve PrepareResult::sky_weight (a second solve over the margin, for
// an effect whose sky lies beyond the scene's range); else it stays empty.
PrepareResult prepare_range(DenseImageRef range, const PrepareParams& p = {}, int threads = 0, bool sky_weight = false);

}  // namespace brume
