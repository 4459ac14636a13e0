// brume — space-variant Gaussian blur by inhomogeneous diffusion
// (Hansard, "Fast synthesis of atmospheric image effects", §3).
//
// Input: an image F with any number of channels >= 1 (premultiplied RGBA for
// haze; six channels Gamma_c E_c, Gamma_c for spectral aerial perspective)
// at inner scale sigma0, and one of three descriptions of the blur, the same
// for every channel:
//  - diffuse: a target scale map sigma(x) in pixels, sigma(x) >= sigma0.
//    Where sigma is locally constant, F is convolved with a Gaussian of
//    standard deviation sqrt(sigma(x)^2 - sigma0^2) (per axis). This is
//    "compute the rate rho(x) from sigma (eq. 13 / eq. 18), then diffuse_rates".
//  - diffuse_rates: a per-pixel rate map rho(x) and the iteration count N,
//    for the standard and invariant schemes (edge rates from the two ends by
//    DiffusionParams::edge_rate, as for the sigma map).
//  - diffuse_conductance: a weight per edge (depth of field, Bertalmio et al.:
//    I <- I + 1/4 div^-(g grad^+ I), i.e. w = g/4 on each edge) and N.
// Channels are independent (no rate depends on F). The fast CPU path keeps
// F as one four-float vector per pixel and runs other channel counts as
// groups of four channels (the last padded with zeros): 6 channels cost two
// 4-channel runs (measured, see by_groups_of_four in src/diffusion/diffusion.cpp),
// where a kernel generalised to C channels could at best save the padding
// (a quarter of the work for 6, none for 4 and 8) and would give up the
// vector-per-pixel layout that the run and f16 schedules are built on. The
// reference path takes any C as is.
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
//      itself adds. Reaches the target variance exactly (docs/diffusion.md).
//
// Boundary rule: half-sample mirror (the image is reflected about its outer
// pixel edges: ... c b a | a b c ...), which is the zero-flux condition of
// the standard scheme and OpenCV's BORDER_REFLECT.
//
// Precision: f32 stores F in float between iterations; f16 rounds every
// stored value to IEEE binary16 after each iteration, exactly what an
// RGBA16F texture holds (the paper's 16-bit experiment).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

enum class Scheme { standard, invariant, invariant_exact };
enum class Precision { f32, f16 };
// How eq. 11's edge rate rho(x,u) is formed from the rates at the two ends
// (src/effects/haze/haze_math.glsl, brume_edge_rate): the paper's mean, or min or
// harmonic mean, which stop a blurred background from leaking into the edge
// of a sharp foreground object (measured by `brume study diffusion`).
enum class EdgeRate { mean = 0, min = 1, harmonic = 2 };

std::string to_string(Scheme s);
std::string to_string(Precision p);
std::string to_string(EdgeRate e);

constexpr double kDefaultMaxSigmaDiagonals = 8.0;  // see plan_diffusion

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
  // Refuse sigma_max past this many image diagonals (plan_diffusion below);
  // 0: no such bound, the rule records before schema 4 ran under (a stored
  // schema-3 record of a renderer's 1e10 background, read as a range, blurs
  // its sky at 2300 diagonals and must repeat).
  double max_sigma_diagonals = kDefaultMaxSigmaDiagonals;
};
// The names of the scheme, precision and edge-rate choices (flags, records,
// messages) and the block that declares every DiffusionParams field: scheme,
// precision, sigma0, rho-max, edge-rate, max-sigma-diagonals.
const EnumNames<Scheme>& scheme_names();
const EnumNames<Precision>& precision_names();
const EnumNames<EdgeRate>& edge_rate_names();
const ParamTable<DiffusionParams>& diffusion_param_table();

// The rate limit a run will use (resolves an unset rho_max to the scheme default).
double effective_rho_max(const DiffusionParams& p);

// Iteration count and the derived quantities of a run (for parameter records).
struct DiffusionPlan {
  int iterations = 0;
  double rho_max = 0.0;    // rate limit used
  double sigma_max = 0.0;  // [px] scale the iteration count was planned for
};

// N for a given largest target scale (eq. 13 / eq. 18). Never overflows: a
// count beyond kMaxDiffusionIterations is an Error (the bounded form below
// refuses far earlier, naming the flags).
DiffusionPlan plan_diffusion(const DiffusionParams& p, double sigma_max);

// ---- bounds decided after analysis (issue #51) ----
// sigma_max depends on the data (haze's sigma0 + lambda sqrt(kappa_s), with
// kappa_s from the range map's R_max), so no flag's range can bound it; the
// plan is checked instead, where it is decided: in each effect's analysis,
// which the CLI, Python, `brume run` and `brume view`'s plan all go through.
//  - sigma_max at most DiffusionParams::max_sigma_diagonals (default
//    kDefaultMaxSigmaDiagonals, --max-sigma-diagonals) times the image's
//    diagonal. The
//    slowest mode of the half-sample mirror boundary on a side of L pixels,
//    cos(pi (x + 1/2) / L), is damped by exp(-(pi sigma / L)^2 / 2), below
//    float's 2^-24 from sigma = 2 L: a pixel's blur past twice the image's
//    longer side leaves the image's mean, so a larger sigma changes nothing
//    there. Eight diagonals leave room for the sigma laws whose nearer pixels
//    get a fraction of sigma_max (haze's R'^{3/2}: a pixel at R' = 1/4 gets
//    sigma_max / 8). Real runs lie far below (1600 x 1120 demo scene,
//    diagonal 1953 px): the README's haze (visibility 3 km, lambda 6) and
//    fog (density 0.01/m, lambda 4) 0.004 diagonals, the sampler's densest
//    haze (visibility 50 m, lambda 8) 0.04.
//  - iterations x pixels at most kMaxDiffusionWork: the standard scheme
//    needs (sigma_max^2 - sigma0^2) / (2 rho_max) iterations (1248 at
//    sigma 25), the invariant ones ln(sigma_max / sigma0) / rho_max (17), so
//    only the standard scheme reaches it. 1e11 is ~100 s of the fast path on
//    one core of the 2-vCPU Xeon (2.2e9 pixel-iterations, sigma 25 on the
//    1600 x 1120 demo, took 2.3 s of CPU, 2026-12-05); the standard scheme
//    at sigma 25 on a 24-Mpx frame (6048 x 4032) is 3.0e10.
// Both are refused, never clamped: the message names the quantity, its
// value, the bound and `set_by`, the flags that set sigma_max for this run
// ("--lambda 1e4, --visibility 300 m, ..."), with the scheme's own flags.
constexpr double kMaxDiffusionWork = 1e11;
constexpr int kMaxDiffusionIterations = 2147483647;
DiffusionPlan plan_diffusion(const DiffusionParams& p, double sigma_max, std::int64_t width, std::int64_t height,
                             const std::string& set_by);

// Check a target-scale problem for the GPU backend (which takes exactly 4
// channels; the CPU takes any count) — sizes, every target scale finite and
// in [sigma0, sigma_max] — and plan it. Throws brume::Error.
DiffusionPlan validate_diffusion(const Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p);

// Diffuse `f` (any channel count >= 1, in place) to the per-pixel target
// scale `sigma` (1 channel, same size, every value finite and in [sigma0,
// sigma_max]). sigma_max sets the iteration count; pass the largest value of
// `sigma` or a larger a-priori bound (haze uses sigma0 + lambda sqrt(kappa_s)
// so that N does not depend on image content). Throws brume::Error on bad
// input. CPU only (the GPU entry point is diffuse_gpu in gpu.hpp).
DiffusionPlan diffuse(Image& f, const Image& sigma, double sigma_max,
                      const DiffusionParams& p, const Exec& exec = {});

// The same for one target scale everywhere (finite, >= sigma0): the result
// of diffuse(f, a map holding float(sigma) everywhere, sigma, p, exec), bit
// for bit, without the map (nor, on the fast path of the invariant schemes,
// the per-pixel rates): `brume blur --sigma`. A 3-channel f32 image is
// diffused as it is (no fourth channel added and removed).
DiffusionPlan diffuse(Image& f, double sigma, const DiffusionParams& p, const Exec& exec = {});

// Diffuse `f` (any channel count >= 1, in place) for `iterations` steps of
// the per-pixel rate `rho` (1 channel, same size, every value finite and in
// [0, 1/4], the 2-D stability limit; 0 = this pixel's own rate is zero, so
// with min or harmonic edge rates it exchanges nothing). Each standard step
// adds per-axis variance 2 rho where rho is locally constant; the invariant
// schemes sample their neighbours at +-h_k from sigma_k = sigma0 e^{k rho(x)}
// (so they still use p.sigma0). p.rho_max is not used: N is the caller's.
// Returns the plan: N, the largest rate, and the scale it reaches,
// sqrt(sigma0^2 + 2 N rho) (standard) or sigma0 e^{N rho} (invariant).
// Throws brume::Error naming the map, the pixel and the value.
DiffusionPlan diffuse_rates(Image& f, const Image& rho, int iterations, const DiffusionParams& p,
                            const Exec& exec = {});

// Diffuse `f` (any channel count >= 1, in place) for `iterations` explicit
// steps with one weight per edge: F(x) += sum over its 4 edges of
// w (F(neighbour) - F(x)). wx and wy are W x H, 1 channel: wx(x, y) is the
// weight of the edge between (x, y) and (x+1, y), wy(x, y) that between
// (x, y) and (x, y+1). The last column of wx and the last row of wy name
// edges onto the half-sample mirror, which carry no flux (the pixel's mirror
// neighbour is itself): they are unused, but still checked like every other
// value, so that maps filled from a per-pixel formula need no special case.
// Every weight finite and in [0, 1/4] (Bertalmio's w = g/4 with g in [0, 1];
// 1/4 is the stability limit). The flux is antisymmetric, so mass is
// conserved, and a pixel whose four edges have w = 0 never changes
// (leak-free). Where w is locally constant, N steps add per-axis variance
// 2 w N. `precision` f16 rounds F to binary16 after every step, as the other
// paths do. Throws brume::Error naming the map, the pixel and the value.
void diffuse_conductance(Image& f, const Image& wx, const Image& wy, int iterations,
                         Precision precision = Precision::f32, const Exec& exec = {});

// The CPU fast path reuses its buffers (the rate map, the invariant
// schemes' per-pixel constants, the rows its passes keep; a partner image
// for F only where offsets are large against the image: at most about twice
// the 4-channel float image) from one call to the next, so that a run
// of calls on same-sized images pays no allocation or first-touch page
// faults; at most one such set is kept by the process between calls. This
// frees it (e.g. after the last image of a batch). Thread-safe.
void release_diffusion_buffers();

}  // namespace brume
