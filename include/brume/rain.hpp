// brume — rain (issue #56, first part): the drop sizes, their fall speed,
// the extinction they cause, a drop field that does not depend on the scene,
// and rain on a LiDAR scan as a particle medium (brume/medium.hpp).
// docs/rain.md. Implemented from the papers' equations; no code was read
// (LISA is GPL, LiDAR_snow_sim and LiDAR_fog_sim are non-commercial).
//
// Symbols and units:
//   R     rain rate [mm/h] >= 0
//   D     drop diameter [mm]
//   N(D)  drops per volume per diameter [m⁻³ mm⁻¹]
//   Λ     the distribution's slope [mm⁻¹]; N0 its intercept [m⁻³ mm⁻¹]
//   σ     extinction coefficient [1/m]; Q the extinction efficiency [1]
//
// Drop sizes (Marshall & Palmer 1948, "The distribution of raindrops with
// size", J. Meteor. 5:165, their fit to Ottawa's summer rain):
//   N(D) = N0·e^{−ΛD},  N0 = 8000 m⁻³ mm⁻¹,  Λ = 4.1·R^{−0.21} mm⁻¹
//   (R = 0: no drops; Λ → ∞).
// Fall speed (Atlas, Srivastava & Sekhon 1973, "Doppler radar
// characteristics of precipitation at vertical incidence", Rev. Geophys.
// Space Phys. 11:1, their fit to Gunn & Kinzer's measurements, sea level):
//   v(D) = 9.65 − 10.3·e^{−0.6·D} m/s  (D in mm),
// negative below D0 = ln(10.3/9.65)/0.6 = 0.1087 mm: the drawn drops start at
// D_min >= D0 (--drop-min, default 0.11 mm, recorded), and end at D_max
// (--drop-max, default 8 mm: larger drops break up; Marshall–Palmer gives
// e^{−8Λ} < 4e−6 of the drops above it at 100 mm/h).
// Extinction (geometric optics: a drop removes Q times its cross-section
// πD²/4 from a beam; Q = 2 counts the diffraction lobe, which a narrow beam
// loses), over the whole distribution:
//   σ = Q·(π/4)·∫_0^∞ D²·N(D) dD = Q·(π/4)·2·N0/Λ³ · 1e−6 m⁻¹
//   (1e−6: mm² of cross-section per m³ is 1e−6 m⁻¹);
//   for Q = 2, σ = π·N0/Λ³·1e−6 ≈ 3.65·10⁻⁴·R^{0.63} m⁻¹.
// Number of drawn drops per volume: n = ∫_{D_min}^{D_max} N dD
//   = N0/Λ·(e^{−Λ·D_min} − e^{−Λ·D_max}) [m⁻³].
//
// The drop field (RainField): space is cut into cubes of kRainCellM; cell
// (ix, iy, iz) of frame f holds a Poisson number of drops of mean n·c³,
// iid diameters from N(D) truncated to [D_min, D_max], positions uniform in
// the cell, all drawn from a counter-based hash of (seed, f, ix, iy, iz, k)
// (brume/medium.hpp's hash_fold), so any sensor enumerates only the cells its
// rays cross, and the field does not depend on the scene. The drops of a
// cell are drawn largest first, as the points of a Poisson process in the
// cumulative measure M(D) = c³·N0/Λ·(e^{−ΛD} − e^{−Λ·D_max}): the k-th
// largest has M(D_k) = E_1 + … + E_k (unit exponentials), and the count is
// the number of sums below M(D_min) — Poisson with mean n·c³, the diameters
// iid truncated-exponential given it. Drawn largest first, the drops above
// any diameter D_t are a prefix, the same whatever D_t: thinning by diameter
// draws fewer, never other, drops.
//
// Rain on a LiDAR scan (the model of Kilic et al. 2021, "Lidar Light
// Scattering Augmentation (LISA)", §3, from its equations; brume's choices
// stated): per beam from the sensor's origin (full divergence θ) to a point
// at range r of intensity i (apparent reflectance: KITTI's [0, 1]),
//   a drop meets the beam when its centre lies in the beam's cone (within
//   r′·θ/2 of the axis) at a range r′ ∈ [r_min, r) (r_min: the blind zone);
//   its echo power  P_d = ρ_d·e^{−2σr′}·min((D/(θ·r′))², 1)/r′²  [1/m²]
//     (the drop's cross-section over the beam's, at most 1; ρ_d its
//     backscatter as a Lambertian reflectance of its cross-section);
//   the target's    P_t = i·e^{−2σr}/r²;
//   the strongest return wins, ties to the target; a drop below the noise
//   floor F is never detected, and a target the rain weakens is lost by
//   brume/medium.hpp's ScanDetection rule (speckle: continuous as R → 0).
// The kept points carry i·e^{−2σr}; a point moved to a drop carries the
// drop's apparent reflectance ρ_d·e^{−2σr′}·min((D/(θr′))², 1). A KITTI
// .bin holds only beams that returned: beams into the sky cannot gain a drop
// echo here.
// Thinning (exact): a drop matters only when its echo reaches F, which needs
// D >= θ·r′²·√(F/ρ_d) (e^{−2σr′} <= 1 dropped: conservative), and no drop
// beyond r_reach = √(D_max/(θ·√(F/ρ_d))) does; per cell only the drops above
// that diameter at the cell's nearest range are drawn.
// Optical depth counted once: in a scan the drops are echoes only. A drop in
// the cone that does not win blocks the fraction min((D/(θr′))², 1) of the
// beam, whose mean over the field is what σ holds; the target's attenuation
// is σ over the whole beam (Medium::sampled_range_m() = 0), and no drawn drop
// attenuates it again.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/medium.hpp"
#include "brume/params.hpp"

namespace brume {

constexpr double kMarshallPalmerN0 = 8000.0;  // [m⁻³ mm⁻¹]
constexpr double kRainCellM = 0.125;          // [m] the drop field's cell edge (exact in binary)
constexpr double kLidarRainQ = 2.0;           // [1] the LiDAR's extinction efficiency (narrow beam)
// [mm] below it Atlas's v(D) is negative: ln(10.3/9.65)/0.6.
double atlas_zero_speed_mm();

// Λ [mm⁻¹] of Marshall–Palmer at rate R [mm/h] (> 0).
double marshall_palmer_lambda_per_mm(double rate_mm_h);
// N(D) [m⁻³ mm⁻¹]; 0 at R = 0.
double marshall_palmer_density(double rate_mm_h, double d_mm);
// v(D) [m/s] of Atlas et al. 1973.
double atlas_terminal_velocity_m_per_s(double d_mm);
// σ [1/m] = Q·(π/4)·∫D²N(D)dD over the whole distribution; 0 at R = 0.
double rain_extinction_per_m(double rate_mm_h, double q = kLidarRainQ);
// n [m⁻³]: the drops with D in [d_min, d_max]; 0 at R = 0.
double rain_drops_per_m3(double rate_mm_h, double d_min_mm, double d_max_mm);

// A drop of the field: its centre [m] in the field's frame and diameter [mm].
struct RainDrop {
  Vec3 at;
  double d_mm = 0.0;
};

// A cell of the field.
struct RainCell {
  std::int64_t ix = 0, iy = 0, iz = 0;
  bool operator<(const RainCell& o) const { return ix != o.ix ? ix < o.ix : iy != o.iy ? iy < o.iy : iz < o.iz; }
  bool operator==(const RainCell& o) const { return ix == o.ix && iy == o.iy && iz == o.iz; }
};

class RainField {
 public:
  RainField(double rate_mm_h, double d_min_mm, double d_max_mm, std::uint64_t seed, std::uint64_t frame = 0);
  // Any exponential N(D) = n0·e^{−λD} [m⁻³ mm⁻¹] truncated to [d_min, d_max] (snow's flakes), its
  // draws keyed by `tag` (another tag, other particles): the same cells, hash and order.
  RainField(double n0, double lambda_per_mm, double d_min_mm, double d_max_mm, std::uint64_t seed,
            std::uint64_t frame, std::uint64_t tag);
  double drops_per_m3() const { return n_; }
  // The drops of `cell` with D >= d_floor_mm (clamped up to D_min), largest
  // first, appended to `out`. With d_floor_mm <= D_min: every drop of the
  // cell (the unthinned sampler).
  void cell_drops(const RainCell& cell, double d_floor_mm, std::vector<RainDrop>& out) const;
  // The same drops as f(centre, s), s the drop's cumulative measure (the sum
  // of unit exponentials above), whose diameter is diameter_mm(s): a caller
  // that tests the position first takes the logarithm only for the drops it keeps.
  template <class F>
  void for_each_drop(const RainCell& cell, double d_floor_mm, F&& f) const {
    for_each_drop_within(cell, measure_above(d_floor_mm), f);
  }
  double diameter_mm(double s) const;
  // M(max(D, D_min)): a cell's mean count of drops of at least D (0 above
  // D_max or without rain); a drop's diameter is at least D iff its s <= M(D).
  double measure_above(double d_mm) const;
  // The drops of the cell whose s <= m, largest first, as f(centre, s).
  template <class F>
  void for_each_drop_within(const RainCell& cell, double m, F&& f) const;
  // The cells a cone about the ray (apex at its origin, radius t·half_width
  // at range t) meets over [t0, t1]: a 3-D DDA along the axis (Amanatides &
  // Woo 1987), each visited cell widened by the cone's radius at the far end
  // of its segment; each once, in the order the DDA meets them.
  static void cone_cells(const MediumRay& ray, double t0, double t1, double half_width, std::vector<RainCell>& out);
  // The hash of a cell's draws, in two folds for callers that walk a column
  // of cells (ix, iy fixed): cell_hash(column_hash(ix, iy), iz).
  std::uint64_t column_hash(std::int64_t ix, std::int64_t iy) const {
    return hash_fold(hash_fold(key_, static_cast<std::uint64_t>(ix)), static_cast<std::uint64_t>(iy));
  }
  static std::uint64_t cell_hash(std::uint64_t column, std::int64_t iz) {
    return hash_fold(column, static_cast<std::uint64_t>(iz));
  }
  // The cell's first uniform draw u: it holds a drop within measure m iff −ln(1 − u) <= m.
  static double first_unit(std::uint64_t cell_hash) { return hash_unit(hash_mix(hash_fold(cell_hash, 0))); }
  // for_each_drop_within with the cell's hash given (cell_hash of its column's).
  template <class F>
  void for_each_drop_hashed(const RainCell& cell, std::uint64_t h, double m, F&& f) const;

 private:
  double d_min_, d_max_, lambda_ = 0.0, n_ = 0.0, tail_ = 0.0, scale_ = 0.0;
  std::uint64_t key_;
};

template <class F>
void RainField::for_each_drop_within(const RainCell& cell, double m, F&& f) const {
  if (!(m > 0.0)) return;
  for_each_drop_hashed(cell, cell_hash(column_hash(cell.ix, cell.iy), cell.iz), m, f);
}

template <class F>
void RainField::for_each_drop_hashed(const RainCell& cell, std::uint64_t h, double m, F&& f) const {
  if (!(m > 0.0)) return;
  const double c = kRainCellM;
  double s = 0.0;  // E_1 + … + E_k
  for (std::uint64_t k = 0;; ++k) {
    const std::uint64_t hk = hash_fold(h, k);
    const double u = hash_unit(hash_mix(hk));
    // A unit exponential E = −ln(1 − u). The first draw of a cell that
    // expects few drops is compared without the logarithm: E > m ⟺
    // u > 1 − e^{−m} = m·(1 − m/2·(1 − m/3)) to 1e−17 relative for m < 1e−4.
    if (k == 0 && m < 1e-4 && u > m * (1.0 - m / 2.0 * (1.0 - m / 3.0))) break;
    s += -std::log1p(-u);
    if (s > m) break;
    f(Vec3{(static_cast<double>(cell.ix) + hash_unit(hash_fold(hk, 1))) * c,
           (static_cast<double>(cell.iy) + hash_unit(hash_fold(hk, 2))) * c,
           (static_cast<double>(cell.iz) + hash_unit(hash_fold(hk, 3))) * c},
      s);
  }
}

// The drops every rain draws (the LiDAR's and the camera's): declared once,
// nested in both commands' tables (block "rain").
struct RainDrops {
  std::optional<double> rate_mm_h;  // [mm/h] in [0, 500], R (required)
  double drop_min_mm = 0.11;        // [mm] >= atlas_zero_speed_mm(), D_min
  double drop_max_mm = 8.0;         // [mm] > D_min, D_max
};
const ParamTable<RainDrops>& rain_drops_param_table();
// The table's ranges and the cross-field rules (--rate given, D_max > D_min).
void validate_rain_drops(const RainDrops& d);

// The parameters of rain on a LiDAR scan, in physical units.
struct LidarRainParams {
  RainDrops drops;                   // --rate, --drop-min, --drop-max
  double divergence_mrad = 2.0;      // [mrad] in (0, 50], the beam's full divergence θ
  double drop_reflectance = 0.35;    // [1] in [0, 1], ρ_d = 2π/S with S = 18 sr (docs/rain.md)
  double noise_floor = 5e-6;         // [1/m²] > 0, F on the scan's intensity scale per m²
  double blind_range_m = 1.0;        // [m] >= 0, r_min: no drop echo nearer
  std::uint64_t seed = 0;            // the drop field's and the speckle's seed
  // Which return a beam reports (docs/rain.md): "strongest" (the target or the strongest drop
  // echo above the floor), "last" (the farthest return above the floor: the target when it is
  // detected, else the farthest drop echo).
  std::string return_mode = "strongest";
  // The field's time and the sensor's pose (docs/rain.md, "Sequences"): frame K of a sequence is
  // the field at t = K·Δt, every drop advected in closed form from its hashed centre c (its place
  // at t = 0) by its fall, the wind and the sensor's motion:
  //   p(t) = c + (w_x·t, w_y·t, wrap(c_z + (w_z − v(D))·t))  [world: the field's frame at frame 0]
  // (wrap: within its layer of kRainLayerM, below); the sensor at frame K sits at its pose
  // (--poses line K relative to line 0, or x = s·t for --ego-speed s).
  std::uint64_t frame = 0;           // K
  double frame_interval_s = 0.1;     // [s] Δt (KITTI's scans: 10 Hz)
  std::string wind = "0,0,0";        // [m/s] X,Y,Z in the field's frame (x forward, y left, z up)
  double ego_speed_m_s = 0.0;        // [m/s] the sensor's speed along its x axis (no --poses)
  std::string poses;                 // KITTI odometry poses (camera 0 to world, 12 numbers a line)
  // KITTI calibration (Tr_velo_to_cam, R0_rect, P2): the field's frame becomes camera 2's, the
  // frame `brume rain` draws its streaks in (x forward, y left, z up, origin at camera 2's centre),
  // so that a drop the camera draws is one the scan sees; empty: the scan's own frame.
  std::string kitti_calib;
};
// The layers the falling drops wrap in (the field stays a homogeneous Poisson field at every t:
// a drop leaving a layer's bottom re-enters at its top): [kRainLayerBaseM + j·kRainLayerM,
// kRainLayerBaseM + (j + 1)·kRainLayerM), multiples of the cell.
constexpr double kRainLayerM = 32.0;
constexpr double kRainLayerBaseM = -16.0;
// The hashed centre c [m] of a drop of diameter d_mm at time t [s] in the world frame, advected by
// its fall v(D) and the wind w (m/s), wrapped in c's layer.
Vec3 rain_drop_at(const Vec3& c, double d_mm, double t_s, const Vec3& wind);
// The scan's beams in the drop field's world (its frame at frame 0) at the frame's time, from
// --kitti-calib, --poses or --ego-speed and --frame (reads the files; errors name the flags).
struct LidarRainPose {
  RigidTransform world_from_sensor;  // x_world = rotation·x_scan + translation
  double t_s = 0.0;                  // K·Δt
  Vec3 wind;                         // [m/s]
  bool general = false;              // not the identity at t = 0 (the scan's frame, the field as hashed)
  std::string frame;                 // the field's frame, in words
};
LidarRainPose lidar_rain_pose(const LidarRainParams& p);
const ParamTable<LidarRainParams>& lidar_rain_param_table();
// The table's ranges and the drops' rules (validate_rain_drops).
void validate_lidar_rain(const LidarRainParams& p);

// What a scan's rain did.
struct LidarRainStats {
  ScanRun run;
  std::size_t drops_drawn = 0;  // drops the thinned sampler drew: each cell's once (and again for a beam redone alone)
  std::string field_frame;      // LidarRainPose::frame
};

// Rain on n points (x, y, z [m] in the sensor frame, intensity >= 0; float32
// each) from `in` into `out` (the points that return, in input order; may be
// `in`); `labels` (n bytes, may be null): ScanLabel per input point. A
// negative or non-finite value is refused naming `what` and the point.
LidarRainStats lidar_rain(const float* in, float* out, std::size_t n, const LidarRainParams& p,
                          std::uint8_t* labels = nullptr, const std::string& what = "the scan");
// The rain as a medium (brume/medium.hpp) for compositions (validated
// parameters; one thread at a time: it keeps a cache of the cells' drops).
std::unique_ptr<Medium> lidar_rain_as_medium(const LidarRainParams& p);
// The record's block: the model, its constants with their sources, the run's counts.
nlohmann::json lidar_rain_record(const LidarRainParams& p, const LidarRainStats& st);

// `brume lidar rain`: a KITTI .bin in, the points that return out.
struct LidarRainJob {
  std::string points;
  LidarRainParams rain;
  std::string out, labels, record;
};
const ParamTable<LidarRainJob>& lidar_rain_job_table();

// ---- rain on a camera's image (issue #56, the camera part) -----------------------------------
// `brume rain`; docs/rain.md, "The camera". The same drop field (RainField: its cells, its hash,
// drawn largest first) seen by a pinhole camera (brume/camera.hpp's intrinsics), over an exposure
// T [s]:
//
// The field's frame is the vehicle's (the LiDAR's axes: x forward, y left, z up) with its origin
// at the camera, the camera level and looking along +x: a point (x, y, z) of the field is at
// (−y, −z, x) in the camera's cv frame (x right, y down, z forward). A drop of the field, at its
// hashed centre at mid-exposure, moves in closed form by
//   u = (0, 0, −v(D)) + wind − (s, 0, 0)  [m/s, vehicle frame]
// (Atlas's fall speed, the wind, and the ego speed s along +x), over t in [−T/2, T/2].
//
// Its streak (Garg & Nayar 2004/2007, "Vision and rain"): the segment its image sweeps, of
// length f·|u⊥|·T/z px on the axis (for a fall alone f·v·T/(z·p), p the pixel pitch, f/p = fx);
// its time-averaged coverage integrates over the image to the time average of the drop's image
// area
//   m = (π/4)·D²·fx·fy·r/z³  [px²]  (D in m, r its range, z its depth: the solid angle πD²/(4r²)
//                                    over the pixel's, cos³θ/(fx·fy))
// whatever T (the dwell time on a pixel, footprint/speed, is what spreads it: α ∝ 1/L): the path
// is sampled uniformly in time, each sample carrying m at its position over the sample count, and
// each sample spread across a kernel of the drop's width f·D/z and the thin lens's
// blur b(z) (brume/dof.hpp's circle of confusion, from --f-number, --focus-distance and the
// camera's --focal-length/--sensor-width; a disc of diameter c has σ = c/4): wider, lower, the
// same m. Each pixel it covers mixes
//   I ← (1 − α)·I + α·E′,  E′ = T_f·E + (1 − T_f)·A,
// E the drop's radiance (what it refracts: 0.94 of the image averaged over a window of half the
// image's height about the drop, plus 0.06 reflected, taken as the whole image's mean), T_f the
// analytic media's transmittance in front of it, A the airlight; drops are composited far to near.
// A drop is hidden where the scene's range at the pixel is nearer: its weight there is
// clamp((r_scene − r_drop)/(δ·r_drop), 0, 1), δ = kRainDepthSoftness (soft where drop and surface
// meet, anti-aliased at depth edges by the splat's sub-pixel weights).
//
// Thinning: a drop of diameter D at depth z is drawn when D >= D_t(z), the smallest diameter
// whose on-axis estimate of the change it makes to a pixel,
//   p(D, z) = (π/4)(fx·D/z)² / (max(1, w)·max(1, fx·v(D)·T/z)),  w = √((fx·D/z)² + b(z)²),
// reaches ε (--epsilon; for an image in [0, 1] a change of at most ε·|E − I|), made non-decreasing
// in z (tabulated on kRainThinningSteps depths); drops nearer than z_near or beyond z_split (planar
// depth at mid-exposure) are not drawn.
//
// Extinction counted once: the camera's σ_cam = (Q_eff/2)·σ_lidar (rain_extinction_per_m's
// ∫D²N, bit for bit). A drawn drop occludes its geometric cross-section (Q = 1): in expectation
// the drawn drops' optical depth per metre at depth z is
//   σ_d(z) = (π/4)·1e−6·∫_{D_t(z)}^{D_max} D²N(D) dD,
// and the rest is analytic: along a pixel's ray (cos θ = z/r) to range r,
//   τ_rain(r) = σ_cam·r − G(min(r·cos θ, z_split))/cos θ,  G(z) = ∫_0^z σ_d,
// so that drawn and analytic transmittance make e^{−σ_cam·r} in expectation (a Poisson field:
// E[Π(1 − α_i)] = e^{−E Σα_i}). Beyond z_split that is σ_cam alone. With --visibility V the
// haze's σ = 3.912/V joins in haze's composite (brume/haze.hpp: its airlight, sky rule and
// scattering blur, on τ_haze + τ_rain); without it rain is the only medium (no blur).
constexpr double kRainDepthSoftness = 0.01;   // [1] δ above
constexpr int kRainThinningSteps = 2048;      // depths of the D_t(z) and G(z) tables
// Q_eff's default: the least-squares fit in ln V of Koschmieder's 3.912/σ_cam to the
// international visibility code's rain rows (2.5, 12.5, 25, 100 mm/h: 5.9, 2.8, 1.9, 0.77 km),
// docs/rain.md.
constexpr double kCameraRainQEff = 1.64;

// σ_cam [1/m] = (q_eff/2)·rain_extinction_per_m(R) (the LiDAR's Q = 2 σ, scaled).
double camera_rain_extinction_per_m(double rate_mm_h, double q_eff = kCameraRainQEff);
// ∫_a^b D²N(D) dD [mm² m⁻³] (0 at R = 0 or b <= a).
double rain_d2_between(double rate_mm_h, double a_mm, double b_mm);

struct CameraRainParams {
  RainDrops drops;                         // --rate, --drop-min, --drop-max
  double exposure_s = 1.0 / 60.0;          // [s] in (0, 10], T
  std::uint64_t seed = 0;                  // --rain-seed: the drop field's seed
  std::string wind = "0,0,0";              // [m/s] X,Y,Z in the vehicle frame (x forward, y left, z up)
  double ego_speed_m_s = 0.0;              // [m/s] the camera's speed along its forward axis
  // The field at frame K of a sequence (docs/rain.md, "Frames of a sequence"): the scan's drops at
  // t = K·Δt (LidarRainParams' frame, rain_drop_at), the camera at its frame-K pose (x = s·t for
  // --ego-speed s, or --poses line K relative to line 0, camera 2 placed by the depth block's
  // --kitti-calib); the exposure is centred on t.
  std::uint64_t frame = 0;                 // K
  double frame_interval_s = 0.1;           // [s] Δt
  std::string poses;                       // KITTI odometry poses (camera 0 to world, 12 numbers a line)
  std::optional<double> f_number;          // [1] the lens (with --focal-length, --sensor-width); unset: pinhole
  std::optional<double> focus_distance_m;  // [m] the plane in focus (with --f-number)
  double q_eff = kCameraRainQEff;          // [1] in [1, 2]
  double z_split_m = 20.0;                 // [m] drops drawn up to this planar depth
  double z_near_m = 0.2;                   // [m] and from this one
  double epsilon = 0.002;                  // [1] thinning threshold ε
  std::optional<double> visibility_m;      // [m] haze's Koschmieder visibility; unset: rain alone
  std::optional<Rgb> airlight;             // linear RGB; unset: haze's estimate
  std::string return_mode = "strongest";   // the scan's (--lidar): LidarRainParams::return_mode
  // The frame the scan (--lidar, lidar=) draws its drops in: "camera" (camera 2's, placed by the
  // KITTI calibration: the image's drops) or "scan" (its own).
  std::string lidar_frame = "camera";
};
const ParamTable<CameraRainParams>& camera_rain_param_table();
void validate_camera_rain(const CameraRainParams& p);
// --wind parsed (X,Y,Z, finite); throws naming --wind.
Vec3 camera_rain_wind(const CameraRainParams& p);
Vec3 parse_wind_m_s(const std::string& wind);
// The camera pass's cross-field rules (rain's, snow's): z_split > z_near, the lens's two flags
// together, the wind parsed; `particles` names what is drawn ("drops").
void validate_streak_camera(double z_split_m, double z_near_m, const std::optional<double>& f_number,
                            const std::optional<double>& focus_distance_m, const std::string& wind,
                            const std::string& particles);

class CameraRainOptics;
class StreakSplatter;  // the camera pass's splat elsewhere (internal: effects/rain/streaks.hpp)

// What the renderer takes besides the parameters.
struct CameraRainScene {
  ConstImageView rgb;          // linear RGB
  ConstImageView range;        // [m] along the ray, dense (prepared); NaN, inf, 0: unknown (the sky)
  ConstImageView sky_weight;   // the preparation's sky weight, or empty
  Intrinsics k;                // resolved
  double coc_infinity_px = 0;  // α of the thin lens (0: pinhole)
  std::array<float, 3> airlight{};
  double haze_sigma_per_m = 0;  // haze's σ (0: none)
  // For tests: without the analytic media, and a fixed drop radiance.
  bool analytic = true;
  std::optional<std::array<float, 3>> drop_radiance;
  // The KITTI calibration that places camera 2 (the image's) relative to camera 0 for --poses (the
  // depth block's --kitti-calib); empty: none.
  std::string kitti_calib;
  // The scene through the analytic media from their transmission τ0 (haze's composite with its
  // scattering blur); unset: T·C + (1 − T)·A per pixel.
  std::function<Image(const Image& tau0)> composite;
  // Step 1 of the pass (the scene through the analytic media, and their transmission) done
  // elsewhere, from the population's optics (the GPU's passes: src/effects/rain/rain_gpu.hpp);
  // unset: on the CPU, with `composite`.
  std::function<Image(const CameraRainOptics& optics, Image* transmission)> background;
  // Step 3 of the pass (the streaks' splat over the image) done elsewhere (the GPU's pass:
  // src/effects/rain/rain_gpu.hpp); null: on the CPU. Not owned.
  const StreakSplatter* splatter = nullptr;
};
struct CameraRainStats {
  double sigma_cam = 0.0, sigma_lidar = 0.0;
  std::size_t cells = 0, drops_seen = 0, drops_drawn = 0, alpha_clamped = 0;
  double mean_streak_px = 0.0;
};
// The streaks and the analytic rain (and haze's σ, without its blur: the pipeline blurs) over
// the image composed: returns the rainy image; `transmission`: the analytic media's (may be null).
Image render_camera_rain(const CameraRainScene& s, const CameraRainParams& p, const Exec& exec,
                         CameraRainStats* stats = nullptr, Image* transmission = nullptr);
// What the thinning rule and the analytic part need of a population of falling particles (rain's
// drops; snow's flakes, brume/snow.hpp, by the same rule).
struct StreakPopulation {
  bool any = false;                     // false: none (rate 0)
  double d_min_mm = 0, d_max_mm = 0;    // the drawn diameters
  double exposure_s = 0, z_near_m = 0, z_split_m = 0, epsilon = 0;
  double focus_distance_m = 0;          // the lens's plane in focus (0: none)
  double sigma_cam = 0;                 // [1/m] the whole population's extinction for the camera
  std::function<double(double d_mm)> speed_m_s;                // the fall speed v(D)
  std::function<double(double a_mm, double b_mm)> d2_between;  // ∫_a^b D²·N dD [mm² m⁻³]
};
// The thinning table and the analytic optical depth of a ray (exposed for tests): D_t [mm] at
// planar depth z, and τ_rain to range r along a ray whose cos θ = z/r is `cos_theta`.
class CameraRainOptics {
 public:
  CameraRainOptics(const CameraRainParams& p, const Intrinsics& k, double coc_infinity_px);
  CameraRainOptics(StreakPopulation pop, const Intrinsics& k, double coc_infinity_px);
  double threshold_mm(double z) const;
  double tau(double r, double cos_theta) const;
  double sigma_cam() const { return pop_.sigma_cam; }
  // p(D, z) of the thinning rule.
  double estimate(double d_mm, double z) const;
  // tau's table (the GPU's pass reads it, src/effects/rain/rain_gpu.cpp): kRainThinningSteps
  // steps of dz = z_split / kRainThinningSteps; on step i (1-based: ((i − 1)·dz, i·dz]) G is
  // g_start(i) + sigma_drawn(i)·(z − z_start(i)) for z >= z_start(i) = max((i − 1)·dz, z_near).
  double step_m() const { return dz_; }
  double g_start(int i) const { return g_[i - 1]; }
  double sigma_drawn(int i) const { return sd_[i]; }
  double z_start(int i) const { return std::max((i - 1) * dz_, pop_.z_near_m); }
  const StreakPopulation& population() const { return pop_; }

 private:
  StreakPopulation pop_;
  double fx_, alpha_, zf_, dz_;
  std::vector<double> dt_, g_, sd_;  // D_t, G and σ_d at the nodes
};
nlohmann::json camera_rain_record(const CameraRainParams& p, const CameraRainStats& st);

}  // namespace brume
