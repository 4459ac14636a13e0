// brume — wet ground (issue #57): one water film on the ground plane, seen by
// the camera (darker diffuse ground, a mirror image of the scene) and by the
// LiDAR (weaker ground returns, some lost). docs/wet-ground.md, with sources.
//
// Symbols and units:
//   n     the water's refractive index relative to air [1] (1.333)
//   θ     incidence angle on the ground plane (from its normal)
//   R_F   the flat film's specular reflectance, air → water, unpolarised
//   r_e   the water's diffuse external reflectance: R_F averaged over a
//         Lambertian (cosine-weighted) hemisphere of incidence
//   r_i   its diffuse internal reflectance (light leaving the ground inside
//         the film and sent back by the water–air interface)
//   a     the ground's albedo [1] (dry, diffuse; --ground-albedo)
//   h     the film's thickness [mm]; d the surface's roughness depth [mm]
//   f     the wetted fraction [1]
//
// Fresnel (air → water, Born & Wolf §1.5.2), cos θ_t = √(1 − sin²θ/n²):
//   r_s = (cos θ − n cos θ_t)/(cos θ + n cos θ_t),
//   r_p = (n cos θ − cos θ_t)/(n cos θ + cos θ_t),
//   R_s = r_s², R_p = r_p², T_s = 4 n cos θ cos θ_t/(cos θ + n cos θ_t)²,
//   T_p = 4 n cos θ cos θ_t/(n cos θ + cos θ_t)²  (R + T = 1 each; computed
//   apart, so the identity tests them), R_F = (R_s + R_p)/2.
// r_e = ∫_0^{π/2} R_F(θ)·2 sin θ cos θ dθ (Gauss–Legendre in cos²θ, 1e−12).
// r_i = 1 − (1 − r_e)/n²: the light the ground sends up inside the water is
//   Lambertian; what leaves it is, by reciprocity, (1 − r_e)/n² of it (the
//   rest, total internal reflection beyond the critical angle included, goes
//   back down). Lekner & Dorf 1988, "Why some things are darker when wet",
//   Appl. Opt. 27:1278.
//
// The film's transfer (ONE function, `film_transfer`): light that enters with
// transmittance t_in reaches the ground, which reflects a, the water sends
// r_i back, and so on; what leaves with transmittance t_out, relative to the
// dry ground's reflection:
//   Q(t_in, t_out) = t_in·t_out / (n²·(1 − a·r_i))
// The camera's darkening (Lekner & Dorf's albedo ratio, diffuse light in and
// out): K = Q(1 − r_e, 1 − r_e) = (1 − r_e)(1 − r_i)/(1 − a·r_i).
// The monostatic LiDAR at incidence θ (the beam in and its return out along
// the same direction; the radiance leaving water into air is T/n² of the
// radiance in the water): Q_L(θ) = Q(1 − R_F(θ), 1 − R_F(θ)); the specular
// part R_F(θ) leaves the beam (mirrored away from the sensor).
//
// The wetted fraction (a decision, docs/wet-ground.md): the surface's
// asperity heights are taken uniform over [0, d]; a film of thickness h
// fills the part of the surface below its level: f = min(h/d, 1). Where it is
// wet the ground takes the film's factors, elsewhere it stays dry:
//   K_eff = 1 − f·(1 − K),  Q_eff(θ) = 1 − f·(1 − Q_L(θ)),
// and the specular mirror covers the wetted fraction: f·R_F(θ).
// The camera pixel: wet = K_eff·dry + f·R_F(θ)·L_mirror. h = 0: f = 0, the identity.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

constexpr double kWaterIndex = 1.333;  // [1] water at 20 °C, 589 nm

// Fresnel's reflectances and transmittances per polarisation, air → a medium of index n.
struct Fresnel {
  double rs = 0.0, rp = 0.0, ts = 0.0, tp = 0.0;
  double r() const { return 0.5 * (rs + rp); }  // unpolarised
};
// cos_theta in [0, 1] (clamped from a slightly negative or above-one rounding); n >= 1.
Fresnel fresnel_air_to(double cos_theta, double n);
// Unpolarised R_F(θ).
double fresnel_reflectance(double cos_theta, double n);
// r_e: R_F averaged over a Lambertian hemisphere of incidence.
double water_diffuse_external_reflectance(double n);
// r_i = 1 − (1 − r_e)/n².
double water_diffuse_internal_reflectance(double n);
// The film's transfer Q(t_in, t_out) for a ground of albedo a (above), r_i the water's
// diffuse internal reflectance (water_diffuse_internal_reflectance(n), computed once by the caller).
double film_transfer(double t_in, double t_out, double n, double albedo, double r_i);

// The film, in physical units (block "wet").
struct WetFilm {
  std::optional<double> film_mm;  // [mm] in [0, 100], h (required); 0: dry, the input back
  double ground_albedo = 0.12;    // [1] in (0, 1), a: dense asphalt's dry albedo
  double roughness_mm = 1.0;      // [mm] in (0, 20], d: the roughness (mean texture) depth
  double water_index = kWaterIndex;  // [1] in [1.2, 1.5], n
};
const ParamTable<WetFilm>& wet_film_param_table();
void validate_wet_film(const WetFilm& w);

// The film's derived constants (once per run).
struct WetOptics {
  double n = kWaterIndex, a = 0.12, f = 0.0;
  double r_e = 0.0, r_i = 0.0, k = 1.0, k_eff = 1.0;
  explicit WetOptics(const WetFilm& w);
  // f·R_F(θ): the mirror's weight at a pixel whose ray meets the ground at cos θ.
  double mirror(double cos_theta) const;
  // Q_eff(θ): the LiDAR's ground return through the film (double pass).
  double lidar(double cos_theta) const;
};
// f = min(h/d, 1).
double wetted_fraction(double film_mm, double roughness_mm);
nlohmann::json wet_optics_record(const WetFilm& w, const WetOptics& o);

// ---- the camera -------------------------------------------------------------------------
// The ground: pixels of known range whose world point lies within `ground_tolerance_m` of
// the plane y = 0 (the camera's pose), or the user's mask. The mirrored ray of a ground
// pixel (its world ray reflected about the plane's normal, from its ground point) is
// marched through the range map in screen space, about kWetMarchStepPx pixels a step; it
// hits the first pixel whose range it passes (by more than kWetHitMargin of that range, and
// by less than kWetThickness more: surfaces are taken that thick, a ray further behind passed
// behind an occluder as the camera sees it and goes on) and takes that pixel's colour; a ray that leaves the frame, or reaches the vanishing
// point of its direction over the sky, takes the sky: the sky pixel there, else the airlight.
constexpr double kWetMarchStepPx = 1.0;
constexpr double kWetHitMargin = 0.01;
constexpr double kWetThickness = 0.05;
// Which pixels a mirrored ray can meet. `blocks` (records before it): every pixel, the march
// skipping the stretches whose min-depth blocks it clears. `above_ground`: once the ray is higher
// above the plane than ground_tolerance_m, the plane's own pixels (within the tolerance of it,
// seen from above) no longer occlude it — a ray above the plane cannot pass behind the plane's
// surface, which those pixels are — and its min-depth blocks leave them out, so a ray over open
// ground crosses it a block at a time. Needs the camera's height (else `blocks` runs, recorded).
enum class WetMarch { blocks, above_ground };
const EnumNames<WetMarch>& wet_march_names();
struct WetScene {
  ConstImageView rgb;    // linear RGB
  ConstImageView range;  // [m] along the ray; NaN, inf, <= 0: unknown (the sky)
  Camera camera;         // intrinsics and pose (height needed without a mask)
  ConstImageView mask;   // 1 channel in [0, 1]: the ground (where > 1/2); empty: from the plane
  double ground_tolerance_m = 0.15;
  std::array<float, 3> sky{};  // the airlight: what a ray leaving the frame sees
  WetMarch march = WetMarch::above_ground;
};
struct WetStats {
  std::size_t ground = 0, hits = 0, sky_pixels = 0, left_frame = 0;
  WetMarch march = WetMarch::blocks;  // the rule that ran
  double maps_ms = 0.0, march_ms = 0.0;  // the phases' wall time: depth map and pyramids; the ground and its march
};
// The wet image; `ground` (may be null): 1 on the ground, 0 elsewhere.
Image render_wet(const WetScene& s, const WetFilm& w, const Exec& exec, WetStats* stats = nullptr,
                 Image* ground = nullptr);

// ---- the LiDAR --------------------------------------------------------------------------
// The scan's ground: points (sensor frame: x forward, y left, z up) within
// `ground_tolerance_m` of the plane z = −lidar_height_m. Their intensity i becomes
// i·Q_eff(θ), cos θ = |z|/r; a point the film weakens is kept with ScanDetection's
// conditional probability e^{−(F/x)(1/Q_eff − 1)}, x = max(i/r², F) (brume/medium.hpp),
// else lost. Points off the ground are unchanged.
struct WetScan {
  double lidar_height_m = 1.73;      // [m] > 0: the sensor above the ground (KITTI's Velodyne)
  double scan_tolerance_m = 0.2;     // [m] > 0: a point within it of the plane is ground
  double noise_floor = 5e-6;         // [1/m^2] > 0, F
  std::uint64_t seed = 0;            // the detection draws' seed
};
const ParamTable<WetScan>& wet_scan_param_table();
struct LidarWetParams {
  WetFilm film;
  WetScan scan;
};
const ParamTable<LidarWetParams>& lidar_wet_param_table();
void validate_lidar_wet(const LidarWetParams& p);
struct LidarWetStats {
  std::size_t points = 0, ground = 0, lost = 0;
};
// n points (float32 x, y, z, intensity) from `in` to `out` (the points that return, in input
// order; may be `in`); labels (n bytes, may be null): 0 off the ground, 1 wet ground kept, 2 lost.
LidarWetStats lidar_wet(const float* in, float* out, std::size_t n, const LidarWetParams& p,
                        std::uint8_t* labels = nullptr, const std::string& what = "the scan");
nlohmann::json lidar_wet_record(const LidarWetParams& p, const LidarWetStats& st);

// `brume lidar wet`.
struct LidarWetJob {
  std::string points;
  LidarWetParams wet;
  std::string out, labels, record;
};
const ParamTable<LidarWetJob>& lidar_wet_job_table();

}  // namespace brume
