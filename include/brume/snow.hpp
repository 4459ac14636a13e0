// brume — snow (issue #58): the flakes' sizes from a water-equivalent
// snowfall rate, their volume fraction and number, and snow on a LiDAR scan
// by the footprint model. docs/snow.md. Implemented from the papers'
// equations; no code was read (LiDAR_snow_sim is non-commercial).
//
// Symbols and units:
//   S     water-equivalent snowfall rate [mm/h] >= 0 (the melted flakes' flux)
//   D_m   a flake's melted diameter [mm]; D_f its own diameter [mm]
//   ρ_s   the flakes' density [g/cm³]; ρ_w = 1 g/cm³ water's
//   v_t   their fall speed [m/s], one for all sizes
//   N(D)  flakes per volume per diameter [m⁻³ mm⁻¹]
//
// Melted sizes (exponential, N_m(D_m) = N0_m·e^{−Λ·D_m}), Λ [mm⁻¹]:
//   Gunn & Marshall 1958, "The distribution with size of aggregate
//     snowflakes", J. Meteor. 15:452:        Λ = 2.55·S^{−0.48}
//   Sekhon & Srivastava 1970, "Snow size spectra and radar reflectivity",
//     J. Atmos. Sci. 27:299:                 Λ = 2.29·S^{−0.45}
// A flake of density ρ_s holds the water of its melted drop in a sphere
// k = (ρ_w/ρ_s)^{1/3} times larger: D_f = k·D_m, so the flakes' distribution
// is N_f(D_f) = N0·e^{−Λ_f·D_f}, Λ_f = Λ/k = Λ·(ρ_s/ρ_w)^{1/3}, N0 = N0_m/k
// (the same flakes counted per mm of the other diameter).
// The intercept from the flux (the papers' N0 are not used; issue #58):
//   the flakes' volume fraction f_v = ∫(π/6)·D_f³·N_f dD_f = π·N0/Λ_f⁴
//   (mm³ per mm³), and their water flux ∫(π/6)·D_m³·N_m·v_t dD_m =
//   v_t·f_v·ρ_s/ρ_w must be S: f_v = ρ_w·S/(3.6·10⁶·ρ_s·v_t) (S in mm/h,
//   v_t in m/s: mm/h is 1/3.6·10⁶ m/s), N0 = f_v·Λ_f⁴/π [mm⁻⁴]
//   = 10⁹·f_v·Λ_f⁴/π [m⁻³ mm⁻¹].
// Number of flakes: n = N0/Λ_f [m⁻³] (the whole exponential; finite).
// Geometric extinction: σ = Q·(π/4)·∫D_f²·N_f dD_f = Q·(π/2)·N0/Λ_f³·10⁻⁶ m⁻¹.
//
// Snow on a LiDAR scan (the footprint model, issue #58): per beam from the
// sensor's origin (full divergence θ) to a point at range r of intensity i
// (apparent reflectance), the flakes whose centres lie in the beam's cone at
// ranges r′ in [r_min, r) (nearer, the sensor's blind zone: the cone from a
// point does not describe the beam there), met near to far, each occluding
// a = min((D_f/(θ·r′))², 1) of what the nearer ones leave of the footprint
// (their positions in it independent: the share it takes is a times the
// remaining share, in expectation over where it lies):
//   share_k = a_k·Π_{j<k}(1 − a_j),   share_target = Π_j(1 − a_j)
// (the shares sum to 1). Echo powers [1/m²]: a flake ρ_f·share_k/r′², the
// target i·share_target/r²; the strongest of them (ties: the target) is
// the return, through brume/medium.hpp's ScanDetection (a flake echo below
// the floor F is never detected; a target the flakes weaken may be lost by
// the speckle rule). The occlusion is the attenuation: no e^{−2σr} on top,
// over the whole beam (every flake is within the sampled range).
// Thinning: a flake with ρ_f·a/r′² < F (D_f < D_t(r′) = θ·r′²·√(F/ρ_f),
// below the cap) can never be detected, so only the flakes with D_f >= D_t(r′)
// are drawn, as a Poisson process along the beam of intensity
//   λ(x) = π(θx/2)²·(N0/Λ_f)·e^{−Λ_f·D_t(x)} [1/m],
// and the others occlude in expectation: the target's and each drawn flake's
// share carry the factor e^{−A(r′)}, A(x) = ∫_{r_min}^x (π/4)·∫_0^{D_t}
// min(D², (θx′)²)·N_f dD dx′ (for a Poisson field E[Π(1 − a_j)] =
// e^{−E[Σa_j]}, exactly; only the correlation between a beam's undetectable
// flakes and its decision is lost). Each beam's flakes are drawn from a
// counter-based hash of (seed, the point's coordinates' bits), independent
// from beam to beam.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/medium.hpp"
#include "brume/params.hpp"
#include "brume/rain.hpp"

namespace brume {

constexpr double kWaterDensityGcm3 = 1.0;  // [g/cm³] ρ_w
constexpr double kLidarSnowQ = 2.0;        // [1] a narrow beam's extinction efficiency (the record's σ)

// The snowfall every snow draws (the LiDAR's and, later, the camera's): block "snow".
struct SnowFlakes {
  std::optional<double> rate_mm_h;                 // [mm/h] in [0, 10], S (required)
  std::string distribution = "gunn-marshall";      // or "sekhon-srivastava"
  double flake_density_g_cm3 = 0.1;                // [g/cm³] in [0.005, 0.917], ρ_s
  double fall_speed_m_s = 1.0;                     // [m/s] in [0.1, 10], v_t
};
const ParamTable<SnowFlakes>& snow_flakes_param_table();
// The table's ranges and --rate given.
void validate_snow_flakes(const SnowFlakes& f);

// Λ [mm⁻¹] of the melted sizes at S > 0 by the named distribution.
double snow_melted_lambda_per_mm(const std::string& distribution, double rate_mm_h);

// The distribution of a snowfall (all zero at S = 0).
struct SnowSizes {
  double lambda_melted_per_mm = 0;  // Λ
  double scale = 1;                 // k = (ρ_w/ρ_s)^{1/3}: D_f = k·D_m
  double lambda_flake_per_mm = 0;   // Λ_f = Λ/k
  double volume_fraction = 0;       // f_v [1]
  double n0_flake = 0;              // N0 [m⁻³ mm⁻¹] of N_f(D_f)
  double n0_melted = 0;             // N0_m = k·N0 [m⁻³ mm⁻¹] of N_m(D_m)
  double flakes_per_m3 = 0;         // n = N0/Λ_f
  // N_f(D_f) and N_m(D_m) [m⁻³ mm⁻¹].
  double flake_density(double d_f_mm) const;
  double melted_density(double d_m_mm) const;
  // σ = Q·(π/2)·N0/Λ_f³·1e−6 [1/m].
  double extinction_per_m(double q = kLidarSnowQ) const;
};
SnowSizes snow_sizes(const SnowFlakes& f);

// The parameters of snow on a LiDAR scan.
struct LidarSnowParams {
  SnowFlakes flakes;               // --rate, --distribution, --flake-density, --fall-speed
  double divergence_mrad = 2.0;    // [mrad] in (0, 50], θ
  double flake_reflectance = 0.9;  // [1] in [0, 1], ρ_f
  double noise_floor = 5e-6;       // [1/m²] > 0, F
  double blind_range_m = 1.0;      // [m] >= 0, r_min
  std::uint64_t seed = 0;          // the flakes' and the speckle's seed
  // Which return a beam reports (docs/rain.md, "Which return"): "strongest" or "last".
  std::string return_mode = "strongest";
  // Frame K of a sequence: each beam's flakes drawn from (seed, K, beam) -- a fresh draw per
  // frame (a flake crosses a footprint, at most a few cm wide where flakes are detectable, in
  // a few ms of its fall; a scan of KITTI's 10 Hz comes 0.1 s later): docs/snow.md, "Frames".
  std::uint64_t frame = 0;
};
const ParamTable<LidarSnowParams>& lidar_snow_param_table();
void validate_lidar_snow(const LidarSnowParams& p);

struct LidarSnowStats {
  ScanRun run;
  std::size_t flakes_drawn = 0;  // flakes the thinned sampler drew (those whose echo can reach F)
};

// Snow on n points (x, y, z [m] in the sensor frame, intensity >= 0; float32
// each) from `in` into `out` (the points that return, in input order; may
// be `in`); `labels` (n bytes, may be null): ScanLabel per input point. A
// negative or non-finite value is refused naming `what` and the point.
LidarSnowStats lidar_snow(const float* in, float* out, std::size_t n, const LidarSnowParams& p,
                          std::uint8_t* labels = nullptr, const std::string& what = "the scan");
// The snow as a medium (brume/medium.hpp): its scan_optical_depths are each
// beam's −½·ln(share_target), its scan_echoes the strongest flake per beam;
// along another medium's echo (optical_depth) the expected occlusion
// ½·σ(Q = 1)·(t − r_min); no camera particles. Validated parameters.
std::unique_ptr<Medium> lidar_snow_as_medium(const LidarSnowParams& p);
nlohmann::json lidar_snow_record(const LidarSnowParams& p, const LidarSnowStats& st);

// `brume lidar snow`.
struct LidarSnowJob {
  std::string points;
  LidarSnowParams snow;
  std::string out, labels, record;
};
const ParamTable<LidarSnowJob>& lidar_snow_job_table();

// ---- snow on a camera's image (issue #58, the camera part) --------------------------------------
// `brume snow`; docs/snow.md, "The camera". Rain's camera pass (brume/rain.hpp, "rain on a
// camera's image": the field's cells and hash, the streaks over the exposure, the depth test, the
// lens's blur, the thinning rule and the analytic rest in haze's composite) with the flakes:
//   the field: N_f(D_f) = N0·e^{−Λ_f·D_f} truncated to [0, 40/Λ_f] (e^{−40} of the flakes beyond),
//     its own draws (another tag than rain's: the same seed, other particles);
//   the motion: u = (0, 0, −v_t) + wind − (s, 0, 0) in the vehicle frame (one fall speed);
//   a flake is opaque: its time-averaged coverage is its geometric image area (π/4)·D_f²·fx·fy·r/z³
//     spread over its path and its kernel (its width f·D_f/z and the lens's blur: wider, lower);
//   its radiance: a Lambertian sphere of albedo a under a sky of radiance L_s above and a ground of
//     L_g below, seen from the side: E = a·(L_s + L_g)/2 (the mean over its visible disc of
//     a·(L_s(1 + n_z) + L_g(1 − n_z))/2), L_s the image's mean over its sky (unknown range, or the
//     preparation's sky weight >= 1/2; without one its top tenth of rows), L_g its mean over the
//     bottom quarter of rows; E′ = T_f·E + (1 − T_f)·A through the analytic media in front;
//   extinction: σ_cam = (Q_eff/2)·σ(Q = 2) (rain's Q_eff), drawn flakes occlude with Q = 1, the rest
//     analytic (CameraRainOptics's rule).
struct CameraSnowParams {
  SnowFlakes flakes;                       // --rate, --distribution, --flake-density, --fall-speed
  double exposure_s = 1.0 / 60.0;          // [s] in (0, 10], T
  std::uint64_t seed = 0;                  // --snow-seed: the flakes' seed
  std::string wind = "0,0,0";              // [m/s] X,Y,Z in the vehicle frame (x forward, y left, z up)
  double ego_speed_m_s = 0.0;              // [m/s] the camera's speed along its forward axis
  std::uint64_t frame = 0;                 // K: the field at t = K·Δt (CameraRainParams' frame)
  double frame_interval_s = 0.1;           // [s] Δt
  std::string poses;                       // KITTI odometry poses (camera 0 to world, 12 numbers a line)
  std::optional<double> f_number;          // [1] the lens; unset: pinhole
  std::optional<double> focus_distance_m;  // [m] the plane in focus (with --f-number)
  double albedo = 0.9;                     // [1] in [0, 1], a
  double q_eff = 1.64;                     // [1] in [1, 2] (rain's kCameraRainQEff)
  double z_split_m = 20.0;                 // [m] flakes drawn up to this planar depth
  double z_near_m = 0.2;                   // [m] and from this one
  double epsilon = 0.01;                   // [1] thinning threshold ε (rain's 0.002: docs/snow.md, "Time")
  std::optional<double> visibility_m;      // [m] haze's Koschmieder visibility; unset: snow alone
  std::optional<Rgb> airlight;             // linear RGB; unset: haze's estimate
  std::string return_mode = "strongest";   // the scan's (--lidar): brume lidar snow's --return-mode
};
const ParamTable<CameraSnowParams>& camera_snow_param_table();
void validate_camera_snow(const CameraSnowParams& p);
// The scan's snow from the camera's: the same snowfall and seed, brume lidar snow's defaults.
LidarSnowParams camera_snow_lidar_params(const CameraSnowParams& p);

struct CameraSnowStats {
  double sigma_cam = 0.0;
  std::size_t cells = 0, flakes_seen = 0, flakes_drawn = 0, alpha_clamped = 0;
  double mean_streak_px = 0.0;
  std::array<double, 3> sky{}, ground{};  // L_s and L_g, linear RGB
  std::string sky_from;
};
// The flakes and the analytic snow (with haze's σ) over the image composed; `scene.drop_radiance`
// (tests) fixes the flakes' radiance E. `transmission`: the analytic media's (may be null).
Image render_camera_snow(const CameraRainScene& scene, const CameraSnowParams& p, const Exec& exec,
                         CameraSnowStats* stats = nullptr, Image* transmission = nullptr);
nlohmann::json camera_snow_record(const CameraSnowParams& p, const CameraSnowStats& st);

}  // namespace brume
