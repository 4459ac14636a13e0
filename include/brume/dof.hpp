// brume — depth of field by leak-free diffusion (Bertalmio, Fort,
// Sanchez-Crespo, "Real-time, accurate depth of field using anisotropic
// diffusion and programmable graphics cards", eq. 1-2, 14, 16, §3.4).
//
// Thin lens (eq. 1-2), Z planar depth along the optical axis (not range: a
// range source is converted with the camera's intrinsics), Zf the focus
// distance, F the focal length, n the f-number:
//   c(x)  = alpha |Z - Zf| / Z,   alpha = F^2 / (n (Zf - F))          (eq. 1-2)
// alpha is the CoC diameter at Z -> infinity, converted to pixels with the
// camera's sensor (px per mm = s / sensor, s the image side the sensor fit
// spans: brume/depth.hpp's LensCamera, Blender's meaning; records before
// schema 4: the width, --sensor-fit horizontal); artists give it directly
// (--coc-infinity PX). A disc of diameter c has per-axis second moment
// c^2/16, so the Gaussian standing for it has sigma = c/4, and the target
// scale of the diffusion, on an input of inner scale sigma0, is
//   sigma(x) = min( sqrt(sigma0^2 + (c/4)^2), coc_limit )
// (in-focus pixels keep sigma0; an impulse spreads by exactly c/4). c grows
// without bound as Z -> 0, so sigma is capped at --coc-limit (recorded with
// the count of capped pixels) to keep the iteration count independent of a
// stray near pixel. Unknown depth (NaN, inf, 0 after preparation) is taken as
// infinitely far: c = alpha (sky).
//
// Schemes (--scheme), all on brume's one diffusion stencil (brume/diffusion.hpp):
//  - invariant-exact (default): the engine's geometric-step scheme driven by
//    sigma(x), with its harmonic/min edge rates: O(log sigma) iterations (17
//    at sigma = 25 px), leak-free on all four sides of an in-focus object.
//  - standard: eq. 16 made symmetric, the engine's standard scheme with the
//    rate rho = g/4 on each edge formed from both ends (harmonic/min):
//    leak-free on all four sides, N = ceil(2 (sigma_max^2 - sigma0^2)).
//  - bertalmio: eq. 16 as published, I <- I + 1/4 div^-(g grad^+ I), i.e. the
//    edge (i, i+1) weighted by g_i alone (the pixel of the forward
//    difference). One iteration at g = 1 adds per-axis variance 1/2, so a
//    Gaussian of sigma needs N = 2 (sigma^2 - sigma0^2) iterations, not the
//    paper's sigma^2/(2 sqrt 2); g = 2 (sigma^2 - sigma0^2) / N <= 1. An
//    in-focus pixel (g = 0) still receives flux across its left and top
//    edges from a blurred neighbour: leak-free on two sides only (measured
//    by tests/test_dof.cpp). For reproduction; CPU only.
//  - leaky: eq. 14, I <- I + g/4 Delta I: an isotropic step weighted
//    afterwards by the pixel's g, so in-focus colour spreads into the blurred
//    side (the leakage the paper argues against). For comparison; CPU only.
//
// Foreground (§3.4): with g from the CoC alone a blurred object in front of
// an in-focus background keeps a sharp silhouette (its edge pixels exchange
// nothing with the in-focus pixels, whose rate is 0). Rule (--foreground
// soft, default): every near pixel (Z < Zf) spreads its scale over its
// neighbours by about that scale, as its blur disc covers them: the
// near-field scale map is split into octave bands of sigma, [2^j, 2^{j+1})
// px; band j (sigma0 outside it) is blurred isotropically by a Gaussian of
// 2^j px (a separable sampled Gaussian at 1/k resolution, k = floor(2^j / 2),
// read back bilinearly: it shapes a rim, not an image; within 0.2 px of the
// full-resolution definition, tests/test_dof.cpp); every pixel takes the largest of its own
// sigma and the blurred bands, still capped at --coc-limit. Pixels behind the focal plane never raise a
// neighbour's scale, so edges at the focal plane stay sharp and a near
// object's blur spreads over the background around it. `sharp` keeps the
// unprocessed map (the paper without §3.4's pre-processing).
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include "brume/depth.hpp"
#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/depth_source.hpp"
#include "brume/range_step.hpp"

namespace brume {

enum class DofScheme { invariant_exact, standard, bertalmio, leaky };
const EnumNames<DofScheme>& dof_scheme_names();
std::string to_string(DofScheme s);

enum class Foreground { soft, sharp };
const EnumNames<Foreground>& foreground_names();

struct DofParams {
  std::optional<double> focus_distance_m;  // [m] Zf, > 0; required
  std::optional<double> f_number;          // [1] n, > 0 (with the lens)
  std::optional<double> coc_infinity_px;   // [px] alpha, >= 0: instead of the lens
  double coc_limit_px = 64.0;              // [px] cap on the target scale sigma, > 0, >= sigma0
  DofScheme scheme = DofScheme::invariant_exact;
  Foreground foreground = Foreground::soft;
  DiffusionParams diffusion;  // precision, sigma0, rho_max, edge rate; the scheme follows `scheme`
  // The lens's focal length and sensor [mm]: not this block's parameters but
  // the camera's (the depth block's --focal-length, --sensor-width,
  // --sensor-fit: one declaration for every command), copied here by the
  // pipelines (dof_with_lens) for the CoC in pixels.
  LensCamera lens;
};
// The DOF parameters with the job's camera in millimetres.
inline DofParams dof_with_lens(DofParams p, const LensCamera& lens) {
  p.lens = lens;
  return p;
}

const ParamTable<DofParams>& dof_param_table();

// Range checks, and the combinations a run would ignore or cannot use: the
// lens (f-number, and the camera's focal length and sensor) or
// --coc-infinity (with which --f-number is refused); a focus distance beyond the focal length; --edge-rate or
// --rho-max with a scheme that does not use them. `given`: names set explicitly.
void validate_dof(const DofParams& p, const std::set<std::string>& given = {});

// The diffusion parameters a scheme runs the engine with.
DiffusionParams dof_diffusion_params(const DofParams& p);

// alpha, the CoC diameter at infinity, in pixels, for a W x H image.
double coc_infinity_px(const DofParams& p, int width, int height);

// The lens's focal length in pixels (F s / sensor), when the lens is given.
std::optional<double> lens_fx_px(const DofParams& p, int width, int height);

// Planar depth Z (m) from a range map (m along the ray) and the intrinsics.
// Unknown pixels (NaN, inf, 0) stay unknown (NaN).
Image planar_depth(const Image& range, const Intrinsics& k);

struct DofAnalysis {
  double alpha_px = 0.0;        // CoC diameter at infinity
  double sigma_max = 0.0;       // [px] largest target scale (after the cap and the foreground rule)
  std::size_t capped_pixels = 0;
  std::size_t unknown_pixels = 0;
  std::size_t near_pixels = 0;  // Z < Zf
  double z_min_m = 0.0, z_max_m = 0.0;
  DiffusionPlan plan;
};

struct DofResult {
  Image rgb;    // linear RGB, blurred
  Image scale;  // target scale sigma(x) in px, 1 channel
};

// The target-scale map from planar depth Z (the CoC, the cap and the
// foreground rule); fills the analysis except the plan.
Image dof_scale_map(const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec = {});

// The CPU apply: every scheme (exec.path: fast or reference).
DofResult apply_dof(DenseImageRef rgb, const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec = {});

// ---- the pipeline -----------------------------------------------------------------
struct DofRun {
  DofResult result;
  DofAnalysis analysis;
  nlohmann::json record;  // {"dof": ..., "prepare": ..., "execution": ...}
};
// In memory: `measured_range` in metres along the ray; `k` the intrinsics
// (resolved), needed to turn range into planar depth. Backend gpu: the
// invariant-exact and standard schemes through the engine's GPU passes.
DofRun run_dof(DenseImageRef rgb, DenseImageRef measured_range, const Intrinsics& k, const DofParams& p,
               const RangeStep& prepare, const Exec& exec = {}, const std::set<std::string>& given = {});
// The same on a range the caller prepared (prepare_step), e.g. once for a
// chain of effects (brume/chain.hpp).
DofRun run_dof_prepared(DenseImageRef rgb, const PreparedRange& prepared, const Intrinsics& k, const DofParams& p,
                        const Exec& exec = {}, const std::set<std::string>& given = {});

// The intrinsics a job's planar depth uses: the depth flags' (--fx.., --fov-x..,
// --calib), else the camera in millimetres (fx = F s / sensor, lens shift);
// when both are given they must agree within 1 % (depth_intrinsics). Throws
// when neither is.
// Whether the depth flags give the camera's pixel intrinsics (else the lens must).
bool depth_flags_give_intrinsics(const DepthSource& src);
Intrinsics dof_intrinsics(const DepthSource& src, int width, int height);
// The record's words for where those intrinsics came from.
std::string dof_intrinsics_source(const DepthSource& src, int width, int height);

}  // namespace brume
