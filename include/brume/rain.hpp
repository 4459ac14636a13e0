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

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
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

 private:
  double rate_, d_min_, d_max_, lambda_ = 0.0, n_ = 0.0, tail_ = 0.0, scale_ = 0.0;
  std::uint64_t key_;
};

template <class F>
void RainField::for_each_drop_within(const RainCell& cell, double m, F&& f) const {
  if (!(m > 0.0)) return;
  const double c = kRainCellM;
  const std::uint64_t h = hash_fold(hash_fold(hash_fold(key_, static_cast<std::uint64_t>(cell.ix)),
                                              static_cast<std::uint64_t>(cell.iy)),
                                    static_cast<std::uint64_t>(cell.iz));
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

// The parameters of rain on a LiDAR scan, in physical units.
struct LidarRainParams {
  std::optional<double> rate_mm_h;   // [mm/h] in [0, 500], R (required)
  double divergence_mrad = 2.0;      // [mrad] in (0, 50], the beam's full divergence θ
  double drop_reflectance = 0.35;    // [1] in [0, 1], ρ_d = 2π/S with S = 18 sr (docs/rain.md)
  double noise_floor = 5e-6;         // [1/m²] > 0, F on the scan's intensity scale per m²
  double blind_range_m = 1.0;        // [m] >= 0, r_min: no drop echo nearer
  double drop_min_mm = 0.11;         // [mm] >= atlas_zero_speed_mm(), D_min
  double drop_max_mm = 8.0;          // [mm] > D_min, D_max
  std::uint64_t seed = 0;            // the drop field's and the speckle's seed
};
const ParamTable<LidarRainParams>& lidar_rain_param_table();
// The table's ranges and the cross-field rules (--rate given, D_max > D_min).
void validate_lidar_rain(const LidarRainParams& p);

// What a scan's rain did.
struct LidarRainStats {
  ScanRun run;
  std::size_t drops_drawn = 0;  // drops the thinned sampler drew over all beams
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

}  // namespace brume
