// brume — space-variant Gaussian blur by inhomogeneous diffusion
// (Hansard, "Fast synthesis of atmospheric image effects", §3).
//
// Input: a four-channel image F (premultiplied RGBA for haze; any four
// channels otherwise) at inner scale sigma0, and a target scale map sigma(x)
// in pixels, sigma(x) >= sigma0. Output: F diffused so that, where sigma is
// locally constant, F has been convolved with a Gaussian of standard
// deviation sqrt(sigma(x)^2 - sigma0^2) (per axis).
//
// Schemes (equation numbers from the paper):
//  - standard (eq. 11-13): explicit Euler on the 4-neighbour Laplacian,
//      N = ceil((smax^2 - s0^2) / (2 rho_max)), rho(x) = (s(x)^2 - s0^2)/(2N),
//      rho(x,u) = (rho(x+u) + rho(x))/2 (eq. 12). Each iteration adds per-axis
//      variance 2 rho. ~1250 iterations for sigma = 25 px.
//  - invariant (eq. 17-18): Eberly's geometric scale steps,
//      N = ceil(ln(smax/s0) / rho_max), rho(x) = ln(s(x)/s0)/N,
//      neighbour offsets +-sigma_k(x) = s0 exp(k rho(x)), sampled bilinearly.
//      As published it under-blurs (sigma = 25 reaches ~22.0), because an
//      iteration adds variance 2 rho sigma_k^2 while the step needs
//      sigma_k^2 (e^{2 rho} - 1).
//  - invariant-exact (default): same N and rates, but the offset h_k is chosen
//      so that 2 rho (h_k^2 + f(1-f)) = sigma_{k+1}^2 - sigma_k^2, where
//      f = frac(h_k) and f(1-f) is the variance that linear interpolation
//      itself adds. Reaches the target variance exactly. (../shared/DESIGN.md)
//
// Boundary rule: half-sample mirror (the image is reflected about its outer
// pixel edges: ... c b a | a b c ...), which is the zero-flux condition of
// the standard scheme and OpenCV's BORDER_REFLECT.
//
// Precision: f32 stores F in float between iterations; f16 rounds every
// stored value to IEEE binary16 after each iteration, exactly what an
// RGBA16F texture holds (the paper's 16-bit experiment).
#pragma once

#include <optional>
#include <string>

#include "brume/exec.hpp"
#include "brume/image.hpp"

namespace brume {

enum class Scheme { standard, invariant, invariant_exact };
enum class Precision { f32, f16 };
// How eq. 11's edge rate rho(x,u) is formed from the rates at the two ends
// (src/shared/haze_math.glsl, brume_edge_rate): the paper's mean, or min or
// harmonic mean, which stop a blurred background from leaking into the edge
// of a sharp foreground object (measured by `brume study diffusion`).
enum class EdgeRate { mean = 0, min = 1, harmonic = 2 };

std::string to_string(Scheme s);
std::string to_string(Precision p);
Scheme parse_scheme(const std::string& s);        // throws brume::Error
Precision parse_precision(const std::string& s);  // throws brume::Error
std::string to_string(EdgeRate e);
EdgeRate parse_edge_rate(const std::string& s);   // throws brume::Error

struct DiffusionParams {
  Scheme scheme = Scheme::invariant_exact;
  Precision precision = Precision::f32;
  double sigma0 = 1.0;   // [px] inner scale of the input, > 0
  // Largest rate per iteration, (0, 0.25] (0.25 is the 2-D stability limit);
  // unset picks the scheme's default: 0.25 for standard and invariant (the
  // paper's setting, kept for reproduction) and 0.2 for invariant-exact. At
  // rho = 1/4 the stencil's centre weight 1 - 4 rho vanishes and the large
  // late offsets leave a visible kernel-shape error; measured on Middlebury
  // Art against a true Gaussian, rho_max 0.2 halves the RMS at sigma = 25 px
  // (2.1e-3 -> 1.1e-3) for 17 instead of 13 iterations.
  std::optional<double> rho_max;  // unset: the scheme's default
  // Default harmonic: `brume study diffusion` measured the paper's mean
  // putting 26-47 % of a blurred background's colour into the 2 px rim of a
  // sharp foreground object (up to 95 % in single pixels) where harmonic and
  // min put none, and harmonic stays within O(eps^2) of the mean where the
  // rates vary smoothly (min departs at O(eps)). A constant scale gives the
  // same Gaussian in every mode. `mean` reproduces the paper.
  EdgeRate edge_rate = EdgeRate::harmonic;
};

// The rate limit a run will use (resolves an unset rho_max to the scheme default).
double effective_rho_max(const DiffusionParams& p);

// Iteration count and the derived quantities of a run (for parameter records).
struct DiffusionPlan {
  int iterations = 0;
  double rho_max = 0.0;    // rate limit used
  double sigma_max = 0.0;  // [px] scale the iteration count was planned for
};

// N for a given largest target scale (eq. 13 / eq. 18).
DiffusionPlan plan_diffusion(const DiffusionParams& p, double sigma_max);

// Check a diffusion problem (channels, sizes, every target scale finite and
// in [sigma0, sigma_max]) and plan it; every backend calls this first.
DiffusionPlan validate_diffusion(const Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p);

// Diffuse `f` (4 channels, in place) to the per-pixel target scale `sigma`
// (1 channel, same size, every value finite and in [sigma0, sigma_max]).
// sigma_max sets the iteration count; pass the largest value of `sigma` or a
// larger a-priori bound (haze uses sigma0 + lambda sqrt(kappa_s) so that N
// does not depend on image content). Throws brume::Error on bad input.
DiffusionPlan diffuse(Image& f, const Image& sigma, double sigma_max,
                      const DiffusionParams& p, const Exec& exec = {});

}  // namespace brume
