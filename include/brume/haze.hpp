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
// Unknown range (NaN, +-inf or 0, e.g. lidar sky) that reaches apply_haze is
// treated as the far end of the scene, R = R_max: the largest blur and the far
// transmission. The pipeline (run_haze) prepares the range first
// (brume/prepare.hpp) unless told not to.
//
// The sky (the preparation's sky; --sky-rule auto). In normalised units
// (--kappa-a/--kappa-s) the sky lies at Hansard's S_max = s-max-factor R_max,
// as the paper has it: tau = exp(-kappa' S_max / R_max). With a visibility in
// metres the medium is physical and unbounded: a sky ray crosses it to
// infinity, so the sky's transmission is 0 and the sky becomes the airlight
// (Koschmieder's horizon; HazeRD places the sky at 2 V, tau = e^-7.8), or
// tau_sky = exp(-beta M) with --sky-distance M (beta = 3.912 / V). Across the
// horizon margin the transmission blends (brume_sky_blend):
//   tau = (1 - w) exp(-beta S) + w tau_sky,
// S the margin's harmonic range and w the preparation's sky weight, the
// harmonic function that is 0 on the scene and 1 on the sky beyond the margin
// (PrepareResult::sky_weight). The weight is solved, not derived from S: S
// runs from each boundary pixel's own range to S_max, so no one affine map of
// S is 0 on the whole scene side, while w is, and w is what the margin does to
// the ranges today (Laplace's interpolation between the two sides). Blending
// transmissions rather than optical depths keeps tau_sky = 0 finite. The
// scattering blur keeps sigma at S (sigma_max on the sky): bounded.
// --sky-rule s-max puts the sky at S_max whatever the units (the rule of
// records before schema 3, which `brume run` gives them).
#pragma once

#include <array>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/range_step.hpp"
#include "brume/sky_rule.hpp"

namespace brume {

enum class Composite { premultiplied, naive };
std::string to_string(Composite c);
const EnumNames<Composite>& composite_names();

// Where the sky lies (see above): auto, or Hansard's S_max whatever the units
// (SkyRule, brume/sky_rule.hpp).

struct HazeParams {
  double kappa_a = 0.0;      // [1] absorption, normalised kappa_a R_max, >= 0
  double kappa_s = 0.25;     // [1] scattering, normalised kappa_s R_max, >= 0
  double lambda = 15.0;      // [px] blur gain: sigma_max = sigma0 + lambda sqrt(kappa_s), >= 0
  std::optional<double> range_max_m;   // [m] R_max, > 0; unset: the largest finite range in the map
  std::optional<double> visibility_m;  // [m] meteorological visibility, > 0; unset: use kappa_a/kappa_s
  double albedo = 1.0;       // [1] single-scattering albedo with visibility, [0, 1]
  std::optional<Rgb> airlight;         // linear RGB, >= 0; unset: estimated (analyse_haze)
  Composite composite = Composite::premultiplied;
  SkyRule sky_rule = SkyRule::automatic;
  std::optional<double> sky_distance_m;  // [m] > 0: the sky's distance; unset: see sky_rule
  DiffusionParams diffusion;  // scheme, precision, sigma0 (the image's inner scale), rho_max, edge rate
};

// The declaration of HazeParams (with the diffusion block nested): flags,
// checks, record and `brume run`.
const ParamTable<HazeParams>& haze_param_table();

// Range checks of every field, and combinations a run would silently ignore
// (kappa with visibility, albedo without it). `given`: names set explicitly.
void validate_haze(const HazeParams& p, const std::set<std::string>& given = {});

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
  bool sky_beyond = false;    // the sky lies beyond the medium: blend with the sky weight (else S_max as range)
  float sky_transmission = 0.0f;  // tau_sky when sky_beyond (0: at infinity)
  std::string sky_rule;           // the rule in words, for the record
};

// Validates parameters and inputs (throws brume::Error) and gathers the
// image-wide statistics. `range` is in metres, 1 channel, same size as rgb.
HazeAnalysis analyse_haze(ConstImageView rgb, ConstImageView range, const HazeParams& p);
// The sky lies beyond the scene's range (HazeAnalysis::sky_beyond): --sky-rule
// auto with --visibility or --sky-distance.
inline bool haze_sky_beyond(const HazeParams& p) {
  return p.sky_rule == SkyRule::automatic && (p.sky_distance_m || p.visibility_m);
}

struct HazeResult {
  Image rgb;           // linear RGB with haze
  Image transmission;  // blurred tau (premultiplied alpha after diffusion), 1 channel
  Image scale;         // target scale sigma(x) in px, 1 channel
};

// The per-pixel apply on the CPU (exec.path: fast or reference). sky_weight:
// the preparation's (PreparedRange::sky_weight), used when a.sky_beyond; an
// empty view (none prepared) weighs nothing.
HazeResult apply_haze(ConstImageView rgb, ConstImageView range, const HazeParams& p,
                      const HazeAnalysis& a, const Exec& exec = {}, ConstImageView sky_weight = {});

// The airlight B when none is given (shared by the effects that take
// --airlight): the per-channel median colour of the unknown-range (sky)
// pixels of the measured range when they are >= 0.5 % of the frame, else an
// achromatic grey at the 99th percentile of luminance (bright overcast haze).
struct AirlightEstimate {
  std::array<float, 3> rgb{};  // linear RGB
  std::string source;
};
AirlightEstimate estimate_airlight(ConstImageView rgb, ConstImageView measured_range, std::size_t unknown_pixels);

// Hansard's scattering blur on given maps (eq. 2-4), shared by haze and
// layered fog: F0 = tau0 (E, 1) premultiplied (naive: (E, tau0)), diffused to
// sigma(x) (brume/diffusion.hpp), out = F.rgb + (1 - F.a) B (naive: tau0 F.rgb
// + (1 - tau0) B). Returns the composite and the blurred transmission F.a.
struct ScatterBlur {
  Image rgb;           // linear RGB
  Image transmission;  // 1 channel
};
ScatterBlur scatter_blur(ConstImageView rgb, const Image& tau0, const Image& sigma, double sigma_max,
                         const DiffusionParams& p, Composite composite, const std::array<float, 3>& airlight,
                         const Exec& exec = {});

// ---- the pipeline -----------------------------------------------------------------
// Everything `brume haze` does, as a library call: analysis on the measured
// range (R_max, airlight from the sky), preparation, the effect on the
// backend Exec chooses, the record. In memory; rgb and the range are views,
// read in place (an Image converts to one; a numpy array is wrapped without a
// copy): the CPU path's only copies are the engine's own working buffers
// (premultiplied RGBA, the prepared range); the GPU path uploads a dense copy.
struct HazeRun {
  HazeResult result;
  HazeAnalysis analysis;
  nlohmann::json record;  // {"haze": ..., "prepare": ..., "execution": ...}
};
HazeRun run_haze(ConstImageView rgb, ConstImageView measured_range, const HazeParams& p, const RangeStep& prepare,
                 const Exec& exec = {}, const std::set<std::string>& given = {});
// The same on a range the caller prepared (prepare_step of measured_range),
// e.g. once for a chain of effects (brume/chain.hpp); R_max and the airlight
// still come from the measured range.
HazeRun run_haze_prepared(ConstImageView rgb, ConstImageView measured_range, const PreparedRange& prepared,
                          const HazeParams& p, const Exec& exec = {}, const std::set<std::string>& given = {});

// The Image forms of the view functions above (source compatibility: an
// Image temporary cannot become a view, which would dangle once stored).
inline AirlightEstimate estimate_airlight(const Image& rgb, const Image& measured_range, std::size_t unknown_pixels) {
  return estimate_airlight(ConstImageView(rgb), ConstImageView(measured_range), unknown_pixels);
}
inline HazeAnalysis analyse_haze(const Image& rgb, const Image& range, const HazeParams& p) {
  return analyse_haze(ConstImageView(rgb), ConstImageView(range), p);
}
inline HazeResult apply_haze(const Image& rgb, const Image& range, const HazeParams& p, const HazeAnalysis& a,
                             const Exec& exec = {}, const Image& sky_weight = {}) {
  return apply_haze(ConstImageView(rgb), ConstImageView(range), p, a, exec, ConstImageView(sky_weight));
}
inline ScatterBlur scatter_blur(const Image& rgb, const Image& tau0, const Image& sigma, double sigma_max,
                                const DiffusionParams& p, Composite composite, const std::array<float, 3>& airlight,
                                const Exec& exec = {}) {
  return scatter_blur(ConstImageView(rgb), tau0, sigma, sigma_max, p, composite, airlight, exec);
}
inline HazeRun run_haze(const Image& rgb, const Image& measured_range, const HazeParams& p, const RangeStep& prepare,
                        const Exec& exec = {}, const std::set<std::string>& given = {}) {
  return run_haze(ConstImageView(rgb), ConstImageView(measured_range), p, prepare, exec, given);
}
inline HazeRun run_haze_prepared(const Image& rgb, const Image& measured_range, const PreparedRange& prepared,
                                 const HazeParams& p, const Exec& exec = {}, const std::set<std::string>& given = {}) {
  return run_haze_prepared(ConstImageView(rgb), ConstImageView(measured_range), prepared, p, exec, given);
}

// The medium's extinction [1/m] where the job is in metres: 3.912/V with a
// visibility (analyse_haze's, exactly), (kappa_a + kappa_s)/R_max with
// --range-max; nullopt in normalised units.
std::optional<double> haze_extinction_per_m(const HazeParams& p);
// The record's "haze" block: parameters, units, diffusion plan, derived values.
nlohmann::json haze_record(const HazeParams& p, const HazeAnalysis& a);

}  // namespace brume
