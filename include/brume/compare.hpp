// brume — how alike two images are, the way Morales judges a re-rendered
// photo against a real one (thesis §3.4, eq. 3.14), plus PSNR.
//
// Histogram correlation (Morales eq. 3.14; OpenCV's HISTCMP_CORREL):
//
//   Corr(H1, H2) = Σ_k (H1(k) − H̄1)(H2(k) − H̄2) / sqrt(Σ_k (H1(k) − H̄1)² · Σ_k (H2(k) − H̄2)²)
//
// over the bins k of two histograms of the HSV values of the compared pixels:
//   - hue–saturation: a joint 2-D histogram, 50 hue bins over H ∈ [0, 180)
//     (OpenCV's 8-bit hue, degrees / 2) × 60 saturation bins over S ∈ [0, 256);
//   - brightness: 256 bins of V ∈ [0, 256).
// 1 is a perfect match; the value is in [−1, 1] and does not change when a
// histogram is scaled (so the pixel count, or a normalisation, does not
// matter). HSV is taken, as the thesis and OpenCV's tutorial take it, from
// 8-bit sRGB-encoded colour: linear values are encoded with the exact sRGB
// curve (brume::linear_to_srgb) and rounded to 8 bits; values outside [0, 1]
// cannot be encoded and are clipped there, and the number of clipped samples
// is reported (never dropped silently). The histograms, cvtColor and
// compareHist are OpenCV's (imgproc), not re-implemented.
//
// PSNR = 10 log10(peak² / MSE) over the compared pixels and all three
// channels, twice:
//   - linear: on the linear float RGB, peak 1 (display white; HDR values
//     above 1 just add to the error);
//   - srgb8: on the 8-bit sRGB codes the histograms use, peak 255.
// Identical images have MSE 0 and PSNR +inf (JSON: the string "inf").
#pragma once

#include <cstddef>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"

namespace brume {

// The histogram layout (stated in every record).
constexpr int kCompareHueBins = 50;         // over OpenCV 8-bit H in [0, 180)
constexpr int kCompareSaturationBins = 60;  // over S in [0, 256)
constexpr int kCompareValueBins = 256;      // over V in [0, 256)

struct CompareResult {
  double hs_correlation = 0.0;   // eq. 3.14 on the 50x60 hue–saturation histogram, [-1, 1]
  double v_correlation = 0.0;    // eq. 3.14 on the 256-bin brightness histogram, [-1, 1]
  double mse_linear = 0.0;       // mean squared error of linear RGB (per channel sample)
  double psnr_linear_db = 0.0;   // peak 1; +inf when mse_linear == 0
  double mse_srgb8 = 0.0;        // of the 8-bit sRGB codes
  double psnr_srgb8_db = 0.0;    // peak 255; +inf when mse_srgb8 == 0
  std::size_t pixels = 0;        // pixels compared (the mask's non-zero ones, or all)
  std::size_t clipped_a = 0, clipped_b = 0;  // samples outside [0, 1] clipped by the 8-bit encoding
};

// a, b: linear RGB of the same size (3 channels). mask: null, or one channel
// of the same size whose non-zero pixels are compared. Throws brume::Error on
// a size or channel mismatch, a NaN sample, or a mask selecting no pixel.
CompareResult compare_images(const Image& a, const Image& b, const Image* mask = nullptr);

// {"hue_saturation_correlation", "brightness_correlation", "psnr_linear_db",
//  "psnr_srgb8_db", ..., "method": {bins, ranges, colour space}}; a PSNR of
// +inf is written as the string "inf".
nlohmann::json compare_result_json(const CompareResult& r);

// `brume compare`: files to numbers.
struct CompareJob {
  std::string a;     // image A (read with read_color: integer files sRGB, float files linear)
  std::string b;     // image B, same size
  std::string mask;  // optional grey image, non-zero = compared; same size
  std::string json;  // optional: write the result and the record here
  std::string a_layer, b_layer;  // A's and B's layers in files with layers (brume/io.hpp); "": plain
};
const ParamTable<CompareJob>& compare_job_table();

// Reads the files, compares, writes --json (atomically) and returns the
// record: header, job, inputs (path, size, SHA-256), result.
nlohmann::json run_compare_job(const CompareJob& job, const RunContext& ctx = {});

}  // namespace brume
