// brume — a medium between a sensor and the scene, the one interface that the
// camera effects and a LiDAR scan share (issue #53; docs/architecture.md,
// "The media layer" and "Adding a medium").
//
// A medium answers, from its own job (its parameters, its pose):
//   * the optical depth τ(r) = ∫_0^r σ(t) dt along a ray or a beam [1]: σ·r
//     for a constant medium, a profile's integral with the pose otherwise;
//   * for a particle medium (rain drops, snow), the particles a beam or a
//     pixel's ray meets nearer than the target: their LiDAR echoes and the
//     part of the pixel they cover;
//   * its own block of the scan's record.
//
// Composition (scan_through_media, image_through_media below) is defined once:
//   * extinctions add: τ = Σ_m τ_m along every ray;
//   * particle echoes are the union of the media's; the strongest of the
//     target's return and the echoes is the point the scan keeps (ties: the
//     target), every echo attenuated by the other media's optical depth to
//     its range;
//   * a particle medium draws its particles explicitly within its sampled
//     range r_s and is analytic beyond it: its τ_m counts only σ over
//     [r_s, r] (Medium::optical_depth's default), so no optical depth is
//     counted twice -- within r_s its particles occlude explicitly.
// A medium with a model of its own for a scan (the LiDAR fog's soft-return
// tables, Hahner et al. 2021) fogs a scan it is alone in by that model
// (Medium::scan_alone), bit for bit what its own command writes.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/image.hpp"

namespace brume {

// A ray or a beam: from `origin` [m] along the unit direction `dir`, in the
// medium's frame (a scan's beams: its sensor frame, origin 0; a camera's
// rays: the world of brume/camera.hpp).
struct MediumRay {
  Vec3 origin;
  Vec3 dir;
};

// A particle a ray meets nearer than its target.
struct Particle {
  double range_m = 0.0;             // [m] > 0 along the ray
  double echo = 0.0;                // LiDAR: the intensity of its return at the sensor through this medium
                                    // alone, on the scan's intensity scale, >= 0
  double coverage = 0.0;            // camera: the fraction of the pixel it covers, [0, 1]
  std::array<float, 3> radiance{};  // camera: its linear RGB radiance
};

// One point's return from a medium's particles (or its volume: the LiDAR
// fog's soft return): the point index in the scan, the return's range and
// intensity through this medium alone. `intensity` is on the target's scale:
// the intensity the point's target would have for the same received power
// (so its power is intensity/R0², R0 the target's range), which is what the
// strongest-return rule compares. `reported`: the intensity the point carries
// when this echo wins, where the medium reports another than `intensity`
// (rain: a drop's apparent reflectance at its own range); NaN: `intensity`.
struct ScanEcho {
  std::size_t point = 0;
  double range_m = 0.0;
  double intensity = 0.0;
  double reported = std::numeric_limits<double>::quiet_NaN();
};

// What fogging a scan did.
struct ScanRun {
  std::size_t points = 0;
  std::size_t echoes = 0;  // points that became a medium's return (moved along their beam)
  std::size_t lost = 0;    // points no return of which was detected (only with a ScanDetection)
};

// The labels of a scan's points (one uint8 per input point).
enum class ScanLabel : std::uint8_t { kept = 0, moved = 1, lost = 2 };

// The sensor's detection (issue #56): a point is lost when the media weaken
// its return below the noise floor. A return of mean power P (intensity/R²,
// the scan's intensity scale per m²) is detected with the probability
// p(P) = e^{−F/P} (fully developed speckle: exponential power, threshold F).
// A point of the scan was detected in clear air, and its clear mean power is
// taken as x = max(i/R², F) (its intensity says less than the floor where it
// is quantised to 0: KITTI's 8.5 % of reflectance-0 points); through the
// media (two-way transmittance T) it is detected again with the conditional
// probability p(x·T)/p(x) = e^{−(F/x)(1/T − 1)}, which is 1 at T = 1 and
// falls continuously as T does (≥ 1 − 2τ for a point at the floor): no
// point is lost at a vanishing rate. Echoes below F are never detected.
struct ScanDetection {
  double floor_per_m2 = 0.0;  // [intensity/m²] > 0, F
  std::uint64_t seed = 0;     // the speckle draws' seed (one uniform per point)
};

// A counter-based hash (issue #56): 64 bits from a seed and counters (a
// frame, a cell, a drop, a lane, a point), the same on every platform,
// thread and order of calls, so that a particle medium's particles depend on
// their counters only. Each word goes through the SplitMix64 finaliser
// (Steele, Lea & Flood, OOPSLA 2014: a bijection of 64 bits with full
// avalanche) and is folded into the state, which is mixed again.
inline std::uint64_t hash_mix(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
inline std::uint64_t hash_fold(std::uint64_t state, std::uint64_t word) {
  return hash_mix(state ^ hash_mix(word + 0x9e3779b97f4a7c15ull));
}
// A uniform draw in [0, 1) from a hash: its top 53 bits.
inline double hash_unit(std::uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

class Medium {
 public:
  virtual ~Medium() = default;

  // [1/m] σ where it is the same everywhere; NaN where it varies (the
  // optical depth then needs the ray's origin and direction: the pose).
  virtual double extinction_per_m() const = 0;
  // [m] the range within which the medium's particles are drawn explicitly;
  // 0 for an analytic medium (no particles).
  virtual double sampled_range_m() const { return 0.0; }
  // The analytic optical depth over [0, range_m] of the ray. The default:
  // σ over [sampled_range_m, range_m] (a constant medium, or a particle
  // medium whose particles stand for σ nearer than r_s).
  virtual double optical_depth(const MediumRay& ray, double range_m) const;
  // The particles the ray meets nearer than range_m (any order), appended;
  // `target` is the intensity of the target at range_m (the scan's point;
  // 0 for a pixel). Default: none.
  virtual void particles(const MediumRay& ray, double range_m, double target, std::vector<Particle>& out) const;

  // A scan's n points (x, y, z [m] in the sensor frame, intensity; 4 floats
  // each) at once, for media with per-scan tables. Defaults: per point, the
  // beam from the sensor's origin to it (the scan's frame is the medium's).
  virtual void scan_optical_depths(const float* points, std::size_t n, double* tau) const;
  virtual void scan_echoes(const float* points, std::size_t n, std::vector<ScanEcho>& out) const;

  // The scan through this medium alone by a model of its own, into `out`;
  // false when the medium has none (scan_through_media then composes it).
  virtual bool scan_alone(const float* in, float* out, std::size_t n, const std::string& what) const;
  // The scan record block of the last scan it fogged (`run`: what scan_through_media did).
  virtual nlohmann::json scan_record(const ScanRun& run) const = 0;
};

// Fogs n points (x, y, z, intensity as float32) from `in` into `out` (may be
// the same buffer) through `media`, composed as stated above: a lone medium
// with a model of its own uses it; otherwise every point keeps the strongest
// of its target's return i·e^{−2τ(R0)} and the media's echoes (moved along its
// beam to the echo's range). Refuses (brume::Error naming `what`) an echo
// whose intensity is not finite.
// With `detection` (a sensor's noise floor, above; a lone medium's own model,
// scan_alone, is then not used), echoes below the floor
// are not offered, a point whose target wins is kept with the conditional
// probability of ScanDetection (its speckle draw hashed from the seed and
// the point's index), else it takes the strongest echo or is lost; `out`
// then receives the points that return, in input order (ScanRun::points −
// ScanRun::lost of them). `labels` (n bytes, may be null): each input
// point's ScanLabel.
ScanRun scan_through_media(const std::vector<const Medium*>& media, const float* in, float* out, std::size_t n,
                           const std::string& what = "the scan", const ScanDetection* detection = nullptr,
                           std::uint8_t* labels = nullptr);

// An array form's scan (an (N, 4) array of x, y, z, intensity, read as an
// N x 4 map): its points, in place when its rows are dense, else gathered
// once into `buffer`. Another shape is refused naming `what`.
const float* scan_points(const ConstImageView& v, const std::string& what, std::vector<float>& buffer);

// An image through `media` seen by `camera` (its pose places the rays in the
// media's world): per pixel of range l [m] along its ray (unknown range --
// NaN, inf, 0 -- is left as it is: a sky rule is the effect's), from the
// scene outwards, the analytic media between successive particles and the
// particles over what lies behind them:
//   C ← T·C + (1 − T)·A over each segment (T = e^{−Δτ}, A the airlight),
//   C ← (1 − α)·C + α·E at each particle (α its coverage, E its radiance).
// `rgb` and `range` have the camera's size; the result is linear RGB.
Image image_through_media(const std::vector<const Medium*>& media, DenseImageRef rgb, DenseImageRef range,
                          const Camera& camera, const std::array<float, 3>& airlight);

}  // namespace brume
