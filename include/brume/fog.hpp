// brume — layered fog from a depth buffer (Zhou, Chen, Smith, "Scene depth
// reconstruction on the GPU: a post processing technique for layered fog";
// maths and the sign and limit corrections in docs/fog.md), with the scattering
// blur of haze driven by the fog actually crossed.
//
// A pixel (u, v) with range l [m] along its ray, seen from a camera at height
// y_c, lies at height y_f = y_c + l d_y (d_y: the world-up component of the
// pixel's unit ray; camera conventions in brume/camera.hpp). With a height
// density delta(y) [1/m] and its antiderivative D(y), the optical depth along
// the ray is
//
//   F = l (D(y_f) - D(y_c)) / (y_f - y_c) = l * mean_{[y_c, y_f]} delta      (Zhou eq. 5, corrected)
//
// -- the paper's l/|dy| integral is negative when looking down; the mean
// density has the right sign either way, and its limit as |y_f - y_c| -> 0 is
// delta(y_c), so a level ray needs no special case. Every profile evaluates
// the mean in camera-relative heights without forming D(y_f) - D(y_c)
// (brume/height_profile.hpp, src/media/height_profile.glsl), stable down to
// height differences of 1e-6 m.
//
//   exponential  delta = D0 exp(-B (y - Y0))
//   band         delta = D0 (1 + cos(pi (y - Yc) / Wb)) / 2 for |y - Yc| <= Wb, else 0
//   ramp         delta = D0 below y_b, linear to 0 at y_t, 0 above
//   constant     delta = D0 (Beer-Lambert on range; classic OpenGL GL_EXP fog)
//   table        piecewise linear through (height, density) rows of a CSV,
//                integrated exactly, the end values held outside its heights
//
//   f = exp(-F),   C = f C_scene + (1 - f) C_fog                           (Zhou eq. 1)
//
// Classic OpenGL fog on the Euclidean range, for comparison (--classic):
//   linear  f = clamp((end - l) / (end - start), 0, 1)   (F = -ln f)
//   exp2    f = exp(-(D0 l)^2)                            (F = (D0 l)^2)
//
// Sky (unknown range: NaN, inf, 0, a depth buffer's clear value; with
// --prepare auto the sky the preparation identifies beyond its horizon
// margin, holes being filled) is integrated to infinity along its ray: finite
// where the density vanishes upwards along it (exponential with B > 0 looking
// up: F = delta(y_c) / (B d_y); band, ramp, table ending at density 0: the
// integral to the top of the fog divided by d_y), and infinite where it
// diverges (the densities are in metres and the medium unbounded: F = +inf,
// f = 0, the sky is the fog colour; Koschmieder's horizon), unless
// --sky-distance M bounds it (F over M metres). Across the horizon margin
// the transmission blends the scene's (at the margin's harmonic range) and
// the sky's with the preparation's sky weight (brume/haze.hpp, "The sky").
// --sky-rule s-max gives the rule of records before schema 3: diverging sky
// rays over --sky-distance or S_max = s-max-factor R_max, the margin as sky.
//
// Scattering blur (--lambda > 0, default 0: Zhou's fog has none): haze's
// premultiplied diffusion (brume/haze.hpp, Hansard eq. 2-4) with the target scale
//
//   sigma = sigma0 + lambda sqrt(omega F) l / R_max                          [px]
//
// which is haze's sigma0 + lambda sqrt(kappa_s') R'^{3/2} when the density is
// constant (omega F = kappa_s' R'), but grows with the fog crossed rather than
// with range. Sky pixels blur as at --sky-distance or, without it, at S_max (F
// over that distance), so sigma_max is known before the diffusion is planned
// and the sky's blur stays bounded when its transmission is 0.
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include "brume/camera.hpp"
#include "brume/fog_params.hpp"
#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/haze.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/depth_source.hpp"
#include "brume/range_step.hpp"

namespace brume {

// The frame's fog as the per-pixel code sees it: its height profile
// relative to the camera height (brume/height_profile.hpp) and classic fog.
struct FogDensity : HeightDensity {
  ClassicFog classic = ClassicFog::none;
  double fog_start = 0.0, fog_end = 1.0;     // classic linear
  // The per-pixel code's kind (BrumeProfile.kind, src/effects/fog/fog_math.glsl):
  // 0 exponential, 1 band, 2 piecewise linear, 3 classic linear, 4 classic exp2.
  int kind() const;
};
// Needs cam.height_known() for the height profiles.
FogDensity fog_density(const FogParams& p, const DensityTable& table, double camera_height_m);

// Optical depth along one ray (CPU, float, the per-pixel path): range_m > 0
// with ray_y the unit ray's world-up component, or a sky ray (sky = true)
// integrated to infinity or over sky_distance_m as stated above.
float fog_optical_depth(const FogDensity& d, float range_m, float ray_y, bool sky, float sky_distance_m);

struct FogAnalysis {
  double range_max_m = 0.0, range_min_m = 0.0;
  std::size_t unknown_pixels = 0;
  double sky_distance_m = 0.0;       // the sky's blur distance, and diverging sky rays' unless sky_at_infinity
  std::string sky_distance_source;
  bool sky_at_infinity = false;      // diverging sky rays: F = +inf
  bool sky_blend = false;            // blend across the horizon margin with the sky weight (else margin = sky)
  Camera camera;                     // intrinsics and pose (height unknown for constant/classic)
  bool camera_used = false;
  DensityTable table;                // profile table only
  FogDensity density;
  double sigma_max = 0.0;            // [px] largest target scale over the frame (lambda > 0)
  std::array<float, 3> airlight{};
  std::string airlight_source;
  DiffusionPlan plan;                // iterations 0 without blur
};

// Image-wide statistics from the measured range (R_max, the sky's colour)
// and the effect's range (sky as unknown: sigma_max). Throws brume::Error.
FogAnalysis analyse_fog(DenseImageRef rgb, DenseImageRef measured_range, DenseImageRef range, const Camera& camera,
                        const FogParams& p, double s_max_factor = PrepareParams{}.s_max_factor);

struct FogResult {
  Image rgb;            // linear RGB with fog
  Image optical_depth;  // F along each pixel's ray (sky: as composited), 1 channel
  Image transmission;   // f = exp(-F), after the blur when lambda > 0, 1 channel
};

// The per-pixel apply on the CPU. `range` in metres; unknown (NaN, inf, 0) is
// sky. sky_weight: the preparation's, used when a.sky_blend (known pixels of
// weight > 0 are the horizon margin); empty: none.
FogResult apply_fog(DenseImageRef rgb, DenseImageRef range, const FogParams& p, const FogAnalysis& a,
                    const Exec& exec = {}, DenseImageRef sky_weight = {});
// The same into `out`, reusing its images when they already have the
// frame's size (a renderer's per-frame loop then allocates nothing: fresh
// output images cost more in page faults and zero-filling than the fog itself).
void apply_fog(DenseImageRef rgb, DenseImageRef range, const FogParams& p, const FogAnalysis& a, FogResult& out,
               const Exec& exec = {}, DenseImageRef sky_weight = {});

// ---- the pipeline -----------------------------------------------------------------
struct FogRun {
  FogResult result;
  FogAnalysis analysis;
  nlohmann::json record;  // {"fog": ..., "prepare": ..., "execution": ...}
};
// `depth` gives the intrinsics of the camera (and its KITTI camera 2);
// measured_range is what load_depth produced. window_depth (LoadedDepth's,
// for --depth-buffer): on the GPU backend with the range unprepared, the
// fog pass reads it and linearises it itself instead of the CPU's range
// (the analysis still takes R_max and the sky's colour from measured_range).
FogRun run_fog(DenseImageRef rgb, DenseImageRef measured_range, const DepthSource& depth, const FogParams& p,
               const RangeStep& prepare, const Exec& exec = {}, const std::set<std::string>& given = {},
               const Image* window_depth = nullptr);

}  // namespace brume
