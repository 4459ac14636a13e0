// brume — fog on a LiDAR scan: the homogeneous model of Hahner, Sakaridis,
// Dai, Van Gool, "Fog Simulation on Real LiDAR Point Clouds for 3D Object
// Detection in Adverse Weather", ICCV 2021, §3, implemented from its
// equations (their code is CC BY-NC and was not read). Issue #41,
// docs/lidar.md.
//
// Symbols and units (SI throughout; c = 299 792 458 m/s):
//   α    extinction coefficient of the fog [1/m]: --alpha, or 3.912/V from
//        --visibility V (Koschmieder, 2 % contrast: the camera effects' rule)
//   MOR  meteorological optical range ln 20/α [m] (5 % contrast)
//   β_b  backscatter coefficient of the fog [1/(m·sr)], default 0.046/MOR
//   β0   = Γ/π, the hard target's backscatter [1/sr] (Γ: --gamma)
//   τ_H  half-power pulse width [s]; P0 peak power [W]
//   A_r  receiver aperture [m²]; l_r  receiver efficiency [1]
//   C_A  = c·l_r·A_r/2, the system constant [m³/s]
//   R1, R2  the transmitter–receiver overlap ξ(R): 0 below R1, 1 above R2,
//        (R − R1)/(R2 − R1) between [m]
//
// Pulse (paper §3.1):   P_T(t) = P0·sin²(πt/(2τ_H)) for 0 ≤ t ≤ 2τ_H, else 0
// Channel (eqs. 4–7):   H_C(R) = ξ(R)·e^{−2αR}/R²;  H = H_C·H_T
// Hard target (eq. 9):  H_T = β0·δ(R − R0): the surface's return is attenuated
//                       by e^{−2αR0}; its clear-weather peak (eq. 12, as the
//                       paper writes it) is P_hard,clear(R0) = C_A·P0·β0·ξ(R0)/R0².
// Soft target (§3.2):   H_T = β_b·U(R0 − R) (fog in front of the surface, none
//                       behind it), received power
//   P_soft(R; R0) = C_A·∫ P_T(t)·H(R − ct/2) dt
//                 = C_A·P0·β_b·(2/c)·∫_{R−L}^{min(R, R0)} sin²(π(R − r)/L)·g(r) dr,
//   g(r) = ξ(r)·e^{−2αr}/r², L = c·τ_H (r = R − ct/2: the range of the fog
//   that scatters, t ∈ [0, 2τ_H] ↔ r ∈ [R − L, R]).
//
// Per point (x, y, z, i) at range R0 (paper's Algorithm 1, our reading):
//   i_hard = i·e^{−2αR0}
//   i_soft = i·max_R P_soft(R; R0) / P_hard,clear(R0)   (0 for R0 ≤ R1: ξ = 0)
//   i_soft > i_hard: the point moves along its beam to the soft peak's range
//   (plus seeded Gaussian range noise, --range-noise, redrawn below R1) with
//   intensity i_soft; else it stays with i_hard. The point count never changes;
//   a zero-reflectance point never becomes fog. Both intensities are
//   proportional to i, so --intensity-scale cancels from the model: it only
//   puts the input on the model's [0, 255] to check that the scan is on the
//   scale it claims (most scaled values above 255 are refused, the trap of
//   mixing KITTI's [0, 1] reflectance with [0, 255] intensities).
//
// Numerics (one table per run, built in O(table) and searched in O(1) per point):
//   * sin² = ½ − ½cos(2π(R − r)/L) splits the soft integral into three
//     cumulative integrals G_f(r) = ∫_0^r g(x)·f(x) dx with f ∈ {1, cos 2πx/L,
//     sin 2πx/L}, tabulated at r_j = j·h, h = L/kLidarStepsPerPulse (≈ 1 cm at
//     20 ns) by composite Simpson on each cell, cells split at R1 and R2 (ξ's
//     kinks). The uncut curve and the curve cut at any node are then O(1) a
//     node: P(R_j; R0=r_k) from G at nodes min(j, k) and j − n.
//   * For R ≥ R2 + L the window lies where g strictly decreases, so the uncut
//     curve does too: its maximum P* (at R*) is in [0, R2 + L]. A cut at
//     R0 ≥ R* keeps the uncut curve up to R* and lowers it beyond, so its peak
//     is P* at R*. For R0 < R* the peak of the cut curve is the larger of the
//     uncut curve's prefix maximum up to R0 and the cut tail's maximum on
//     (R0, R0 + L), tabulated at the nodes below R* and interpolated in R0
//     (the power quadratically through three nodes, the range linearly).
//   * Peaks are the tables' node maxima: the range within h/2, the power
//     within O(h²·P'') of the continuous peak.
//
// Height-layered fog (--profile; docs/lidar.md "Height-layered fog"): the
// medium is a height profile δ(y) [1/m] of the media layer
// (brume/height_profile.hpp: exponential, band, ramp, table, constant, the
// flags and HeightMedium fields that brume fog takes too), and
// the scan is placed in the fog's world (y up) by a LidarPose. A beam from
// the scan's origin at height y_s with world-up component s = sin θ (θ its
// elevation) meets the density δ(y_s + r·s) at range r, and
//   F(r) = ∫_0^r δ(y_s + t·s) dt = r · mean δ over [y_s, y_s + r·s]
// (the media layer's integral, height_optical_depths: the camera effects' own maths);
//   i_hard = i·e^{−2F(R0)}                       (αR0 → F(R0))
//   β_b(r) = δ(y_s + r·s)/S                       (S = --lidar-ratio, the
//            extinction-to-backscatter ratio; auto ln 20/0.046 = 65.1 sr, the
//            paper's β_b = 0.046/MOR with MOR = ln 20/δ, now local)
//   P_soft(R; R0) = C_A·P0·(2/c)·∫_{R−L}^{min(R, R0)} sin²(π(R − r)/L)·g(r) dr,
//   g(r) = ξ(r)·β_b(r)·e^{−2F(r)}/r²,
// and the per-point rule above. The density along a beam depends on s and
// y_s only: beams are binned by s in bins of Δ = --elevation-step (in
// radians), one table per occupied bin at the middle s_c of its beams' s
// (|s − s_c| ≤ Δ/2; exact for a bin whose beams share one elevation), each
// built as the homogeneous table (same step, same Simpson cells) to its
// farthest point (at most kLidarLayeredRangeMax), or less: once no later
// node can exceed the curve's maximum so far (P(R') ≤ K·e^{−2F(R−L)}/(R−L)²
// ·min(δ_max·L/2, ½) for R' ≥ R, K = C_A·P0·(2/c)/S, δ_max the largest
// density along the bin's beams), the cut peak of every farther point is
// that maximum. The cut tails are searched only at the
// nodes the points use, and only where the uncut curve still rises within
// one pulse length. The hard attenuation is each point's own F (no bin).
// The bin's error (docs/lidar.md): with Λ the density's largest slope
// |dδ/dy| over the beams' heights and δ_max its largest value,
//   |P_peak(s) − P_peak(s_c)| ≤ C_A·P0·(2/c)/S·Λ·(Δ/2)·(L/2)·(1/R1 + δ_max).
// A constant profile is the homogeneous model with α = --density, bit for
// bit (the same code).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/depth.hpp"
#include "brume/height_profile.hpp"
#include "brume/image.hpp"
#include "brume/medium.hpp"
#include "brume/params.hpp"

namespace brume {

constexpr double kSpeedOfLight = 299792458.0;  // [m/s]
constexpr int kLidarStepsPerPulse = 600;         // table steps per pulse length L = c·τ_H
constexpr double kLidarLayeredRangeMax = 2000.0;  // [m] the farthest point a height-layered run tabulates
constexpr double kLidarPaperRatioSr = 65.12460617192603;  // [sr] ln 20/0.046: the paper's β_b = 0.046/MOR as α/β_b

// Where the scan lies in the fog's world (brume/camera.hpp: x east, y up,
// z south; heights are y). With a KITTI calibration the scan goes through
// Tr_velo_to_cam and R0_rect into the rectified camera frame, to camera 2's
// centre (P2's translation), and through the fog's camera pose
// (HeightMedium::camera: --camera-height, --pitch, --roll, as the camera
// effects take them) into the world, so a camera effect and the LiDAR see
// the same fog. Without one the scan's z axis is up and its origin is at
// --sensor-height.
struct LidarPose {
  std::string kitti_calib;                // --kitti-calib FILE (P2, R0_rect, Tr_velo_to_cam)
  std::optional<double> sensor_height_m;  // [m] finite; world height of the scan's origin (no calib)
};
const ParamTable<LidarPose>& lidar_pose_param_table();

// The parameters of the LiDAR fog, in physical units (the paper's defaults).
struct LidarFogParams {
  std::optional<double> visibility_m;  // [m] > 0; α = 3.912/V (exactly one of visibility, alpha)
  std::optional<double> alpha_per_m;   // [1/m] >= 0, the extinction coefficient
  double tau_h_ns = 20.0;              // [ns] > 0, half-power pulse width τ_H
  double p0_w = 80.0;                  // [W] > 0, peak pulse power P0
  double a_r_m2 = 0.25;                // [m²] > 0, receiver aperture A_r
  double l_r = 0.05;                   // [1] (0, 1], receiver efficiency l_r
  double gamma = 1e-6;                 // [1] > 0, hard-target reflectivity Γ (β0 = Γ/π)
  double r1_m = 0.9;                   // [m] > 0, overlap starts
  double r2_m = 1.0;                   // [m] > R1, full overlap
  std::optional<double> beta_b;        // [1/(m·sr)] >= 0; unset: 0.046/MOR, MOR = ln 20/α
  double intensity_scale = 255.0;      // [1] > 0, input intensity × scale = the model's [0, 255]
  std::string noise = "on";            // on | off: the soft points' range noise
  double range_noise_m = 0.5;          // [m] >= 0, σ of that noise (brume's choice, docs/lidar.md)
  std::uint64_t seed = 0;              // the noise's seed (same seed, same scan)
  std::optional<double> lidar_ratio_sr;  // [sr] > 0, S = extinction/backscatter; unset: β_b as above
  // ---- height-layered fog (unset profile: the homogeneous fog above) ----
  std::optional<HeightProfile> profile;  // --profile exponential|band|ramp|table|constant
  HeightMedium fog;                    // the profile's fields (--density, --falloff, --base-height, --band-*,
                                       // --ramp-*, --table) and camera 2's pose (--camera-height, --pitch,
                                       // --roll, --yaw, --camera-x/z, --view-matrix); fog.profile is ignored
  LidarPose pose;                      // --kitti-calib or --sensor-height
  double elevation_step_deg = 0.1;     // [deg] [0.001, 1], the width Δ of the elevation bins (in sin θ)
};
const ParamTable<LidarFogParams>& lidar_fog_param_table();
// Cross-field rules: exactly one of visibility and alpha, or a profile
// without them; R2 > R1; at most one of --beta-b and --lidar-ratio (and no
// --beta-b with a profile); the profile's fields (validate_height_medium);
// the pose its profile needs (--kitti-calib with a camera height, or
// --sensor-height), and nothing the run would ignore.
void validate_lidar_fog(const LidarFogParams& p);

// The layered LiDAR fog of a camera effect's height medium (its profile,
// density fields and camera pose: CommandDef::height_medium) with the scan's
// pose; `base` gives the LiDAR's own parameters (pulse, receiver, noise,
// seed). A constant profile needs no pose (it is dropped).
LidarFogParams lidar_params_from_profile(const HeightMedium& medium, const LidarPose& pose,
                                         LidarFogParams base = {});

// The scan's frame in the fog's world (needs a height-layered p): x_world =
// rotation·x_scan + translation; reads --kitti-calib. Errors name the flag.
RigidTransform lidar_world_from_scan(const LidarFogParams& p);

// The constants a run derives from its parameters.
struct LidarFogMedium {
  double alpha = 0.0;       // [1/m]
  double mor_m = INFINITY;  // [m] ln 20/α
  double beta_b = 0.0;      // [1/(m·sr)]
  double beta0 = 0.0;       // [1/sr] Γ/π
  double c_a = 0.0;         // [m³/s] c·l_r·A_r/2
  double pulse_m = 0.0;     // [m] L = c·τ_H
};
// Homogeneous fog (or a constant profile, α = its density); a layered p
// gives α = NaN and MOR = NaN, the other constants as for any fog.
LidarFogMedium lidar_fog_medium(const LidarFogParams& p);

// The uncut soft-target power P_soft(R) [W] at R_j = j·step_m, j = 0..n-1,
// and its maximum (the table's node maximum).
struct SoftCurve {
  double step_m = 0.0;
  std::vector<double> power_w;
  double peak_w = 0.0, peak_range_m = 0.0;
};
// The table from 0 to at least `range_end_m` (and at least R2 + L). With a
// height-layered p: the level beam's (s = 0 from the scan's origin).
SoftCurve lidar_soft_curve(const LidarFogParams& p, double range_end_m);
// "range_m,power_w\n" and one row a node (%.9g).
std::string soft_curve_csv(const SoftCurve& c);

// What a run did.
struct LidarFogStats {
  std::size_t points = 0, soft = 0;  // all points, those turned into fog
  std::size_t zero_range = 0;        // points at R0 ≤ R1 (no overlap: attenuated only)
  double peak_w = 0.0, peak_range_m = 0.0;  // the uncut soft curve's maximum
  double table_ms = 0.0, points_ms = 0.0;
  // Height-layered runs: the tables (one an occupied elevation bin), their
  // nodes, the largest |s − s_c| of a beam from its table's s_c, and the
  // scan's origin height and density there.
  std::size_t tables = 0, table_nodes = 0;
  double bin_offset_max = 0.0, origin_height_m = NAN, origin_density_per_m = NAN;
  nlohmann::json record() const;
};

// A run's "lidar" record block: alpha_per_m and how it was given, the
// derived constants, the seed and noise, and the stats (shared by `brume
// lidar fog` and the camera effects' --lidar, brume/lidar_camera.hpp).
nlohmann::json lidar_fog_record(const LidarFogParams& p, const LidarFogStats& st);

// Fogs n points (x, y, z, i as float32, 16 bytes each) from `in` into `out`
// (may be the same buffer). Refuses (brume::Error naming `what`) non-finite
// values, negative intensities and a scan whose intensities × scale mostly
// exceed 255, before writing anything. α = 0 copies the points bit for bit.
LidarFogStats lidar_fog(const float* in, float* out, std::size_t n, const LidarFogParams& p,
                        const std::string& what = "the scan");
// The same on an array form's scan (an (N, 4) array of x, y, z, intensity,
// read as an N x 4 map: brume.lidar.fog's points, a camera effect's lidar=),
// read in place when its rows are dense, gathered once when strided; the
// foggy points as a new N x 4 Image. Another shape is refused naming `what`.
Image lidar_fog_array(const ConstImageView& points, const LidarFogParams& p, const std::string& what,
                      LidarFogStats& stats);

// The LiDAR fog as a medium (brume/medium.hpp), from validated parameters:
// its extinction (α, or NaN and the profile along each beam with the scan's
// pose: the medium's frame is the scan's), its soft returns as echoes (the
// points its own model moves: a soft return that loses to the target
// through this medium alone is not offered), a scan it is alone in fogged
// by lidar_fog (bit for bit), and its record block: lidar_fog_record of
// that run with the model's parameters under "parameters".
std::unique_ptr<Medium> lidar_fog_as_medium(const LidarFogParams& p);

// The working memory of fogging a scan read from a file, per point: the
// points read, the foggy points and their bytes for the file (16 each), and
// the layered fog's per-beam ranges, climbs, optical depths and flags (29).
constexpr double kLidarFogBytesPerPoint = 80.0;

}  // namespace brume
