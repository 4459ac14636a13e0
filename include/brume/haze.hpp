// brume — haze and fog with scattering blur
// (Hansard, "Fast synthesis of atmospheric image effects", eq. 1-7).
//
//   tau(x)   = exp(-(kappa_a + kappa_s) R(x))                   (eq. 1)
//   F0       = tau (E, 1)          premultiplied RGBA            (eq. 2)
//   sigma(x) = sigma0 + R'^{3/2} (sigma_max - sigma0),
//   sigma_max = sigma0 + lambda sqrt(kappa_s)                    (eq. 7)
//   F        = F0 diffused to sigma(x)  (brume/diffusion.hpp)    (eq. 3)
//   out      = F.rgb + (1 - F.a) B                               (eq. 4)
//
// Units follow the paper: R' = R / R_max and kappa' = kappa R_max are
// dimensionless, so --kappa-a 0.25 means "optical depth 0.25 at R_max".
// A visibility V in metres (Koschmieder, 2 % contrast threshold) gives the
// physical extinction 3.912 / V per metre instead; the single-scattering
// albedo omega splits it into kappa_s = omega beta and kappa_a = (1-omega) beta.
//
// Unknown range (NaN, +-inf or 0, e.g. lidar sky) is, until the depth issue's
// sky and hole processing lands, treated as the far end of the scene: R = R_max.
// It then gets the largest blur and the far transmission, which is what sky
// should look like under haze; the count is reported in the record.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

enum class Composite { premultiplied, naive };
Composite parse_composite(const std::string& s);
std::string to_string(Composite c);

struct HazeParams {
  double kappa_a = 0.0;      // [1] absorption, normalised kappa_a R_max, >= 0
  double kappa_s = 0.25;     // [1] scattering, normalised kappa_s R_max, >= 0
  double lambda = 15.0;      // [px] blur gain: sigma_max = sigma0 + lambda sqrt(kappa_s)
  double sigma0 = 1.0;       // [px] inner scale of the input image, > 0
  double range_max_m = 0.0;  // [m] R_max; 0 = the largest finite range in the map
  double visibility_m = 0.0; // [m] meteorological visibility; 0 = use kappa_a/kappa_s
  double albedo = 1.0;       // [1] single-scattering albedo with --visibility, [0, 1]
  bool airlight_auto = true;
  std::array<float, 3> airlight{0.8f, 0.8f, 0.8f};  // linear RGB when !airlight_auto
  Composite composite = Composite::premultiplied;
  DiffusionParams diffusion;  // scheme, precision (sigma0 is copied from above)
};

// The declaration table of HazeParams' numeric fields (flags, checks, record).
const std::vector<ParamDecl<HazeParams>>& haze_param_table();

// Image-wide statistics, computed once before the per-pixel apply.
struct HazeAnalysis {
  double range_max_m = 0.0;   // R_max used
  double range_min_m = 0.0;   // smallest known range
  std::size_t unknown_pixels = 0;
  double kappa_a = 0.0, kappa_s = 0.0;  // normalised coefficients used
  double extinction_per_m = 0.0;        // (kappa_a + kappa_s) / R_max
  double sigma_max = 0.0;               // [px]
  std::array<float, 3> airlight{};      // linear RGB used
  std::string airlight_source;          // "given", "sky median", "99th percentile luminance"
  DiffusionPlan plan;
};

// Validates parameters and inputs (throws brume::Error) and gathers the
// image-wide statistics. `range` is in metres, 1 channel, same size as rgb.
HazeAnalysis analyse_haze(const Image& rgb, const Image& range, const HazeParams& p);

struct HazeResult {
  Image rgb;           // linear RGB with haze
  Image transmission;  // blurred tau (premultiplied alpha after diffusion), 1 channel
  Image scale;         // target scale sigma(x) in px, 1 channel
};

HazeResult apply_haze(const Image& rgb, const Image& range, const HazeParams& p,
                      const HazeAnalysis& a, const Exec& exec = {});

}  // namespace brume
