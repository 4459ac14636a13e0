// brume — spectral aerial perspective from atmospheric turbidity
// (Morales, "Rendering aerial perspective in mixed reality from atmospheric
// turbidity", ch. 3-4; docs/aerial.md for the model and the correction of Table 3.1).
//
// Scattering coefficients (per metre), lambda in 380-780 nm, turbidity T in
// [1, 20], observer altitude h0 in [-500, 9000] m:
//   Rayleigh  beta_R(lambda, h0) = 8 pi^3 (n^2-1)^2 / (3 N lambda^4) (6+3p)/(6-7p) K_R e^{-h0/7994 m}
//             n = 1.0003, p = 0.035, N = 2.545e25 m^-3, K_R = 1.0396      (beta_R(550) = 0.0141 /km)
//   Mie       beta_M(lambda, T, h0) = 0.434 c(T) pi (2 pi/lambda)^{nu-2} K_M e^{-h0/1200 m}
//             c(T) = (0.65 T - 0.65) 1e-16 m^2, nu = 4, K_M = 0.0092       (beta_M(550, 1.6) = 0.0639 /km)
// Camera-weighted attenuation over a distance s (eq. 3.10):
//   Gamma_c(s) = int e^{-(beta_R + beta_M)(lambda) s} q_c(lambda) dlambda / int q_c(lambda) dlambda
// Gamma depends on s alone for fixed (T, h0, q): it is tabulated once per run
// (AttenuationTable), so a render costs a table look-up per pixel, not a
// spectral integral.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/range_step.hpp"
#include "brume/sky.hpp"

namespace brume {

// ---- scattering coefficients ------------------------------------------------------
constexpr double kAerialLambdaMinNm = 380.0, kAerialLambdaMaxNm = 780.0;

struct Atmosphere {
  double turbidity = 2.0;   // [1] T, [1, 20]
  double altitude_m = 0.0;  // [m] observer altitude h0, [-500, 9000]
};
// Throws brume::Error naming --turbidity / --altitude.
void validate_atmosphere(const Atmosphere& a);
double rayleigh_beta_per_m(double lambda_nm, double altitude_m);
double mie_beta_per_m(double lambda_nm, double turbidity, double altitude_m);
// beta_R + beta_M at the observer [1/m], the same formulas on [380, 2000] nm:
// beyond the visible for a LiDAR (905, 1550 nm; brume/lidar_camera.hpp).
// Rayleigh's lambda^-4 holds there; the Mie term's lambda^-2 (Junge nu = 4,
// K_M constant) is the model's own law extended, not fitted data (docs/lidar.md).
constexpr double kAerialExtinctionLambdaMaxNm = 2000.0;
double aerial_extinction_per_m(double lambda_nm, const Atmosphere& a);

// ---- camera spectral sensitivities -------------------------------------------------
// q_c(lambda) on the 1 nm integration grid 380..780 nm (401 samples), zero
// outside the source's data, linearly interpolated onto the grid.
enum class SensitivitySpace {
  camera_rgb,  // q are the camera's own r, g, b: Gamma applies to the image's channels directly
  xyz,         // q are CIE 1931 x, y, z (non-negative): the image is taken to XYZ (linear sRGB
               // primaries, D65), attenuated per X, Y, Z and brought back, i.e. M diag(Gamma) M^-1
};
struct SpectralSensitivity {
  std::string source;  // "default (...)", a file path, or "FILE#camera name"
  std::string sha256;  // of the source file; empty for the built-in default
  SensitivitySpace space = SensitivitySpace::xyz;
  std::vector<std::array<double, 3>> q;  // 401 samples, lambda = 380 + i nm
};
constexpr int kSensitivitySamples = 401;

// --sensitivity default | FILE.csv | DATABASE.txt#CAMERA NAME (see docs/aerial.md);
// throws brume::Error naming the file, the line and the value.
SpectralSensitivity load_sensitivity(const std::string& spec);

// ---- attenuation -------------------------------------------------------------------------
// The spectral integral itself, in double (the per-pixel peer of the table).
std::array<double, 3> attenuation_direct(const Atmosphere& a, const SpectralSensitivity& q, double s_m);

// Gamma_c(s) on a uniform grid of s, stored as ln Gamma and interpolated
// linearly in ln Gamma (exact for a single wavelength, where ln Gamma is
// linear in s; the spectral spread only bends it slightly). Beyond the grid,
// ln Gamma continues along its last slope.
//
// at() is the one definition of the look-up, in f32 so that a render can run
// it as vector code (apply_aerial calls log_at per pixel, then exp_f over a
// row: the same operations, bit for bit): t = s/step rounded to f32, the cell
// i and f = t - i (exact), x = a + f (b - a) in f32, Gamma = exp_f(x). Against
// the same interpolation in double (the pre-speed at()), the f32 rounding of t
// and x moves ln Gamma by ~2 ulp of |ln Gamma| and exp_f adds <= 1e-7
// relative: |at - double| <= 1e-7 + 1.2e-7 Gamma |ln Gamma| <= 1.5e-7 absolute
// for Gamma in [0, 1]; measured <= 6.7e-8 on spectral tables (T 1 .. 20, 2 and
// 100 km, tests/test_aerial_spectral.cpp), below the f32 output's own rounding.
// The GPU (src/effects/aerial/aerial_premultiply.frag) runs the same
// interpolation in highp with GLSL's exp.
struct AttenuationTable {
  double step_m = 0.0;                               // grid spacing, > 0
  std::vector<std::array<float, 3>> log_gamma;       // ln Gamma_c at s = i step_m; [0] = {0, 0, 0}

  // e^x in f32 without a library call and without float comparisons (so that
  // a loop of it vectorises under the default -ftrapping-math): Cody-Waite
  // reduction x = k ln2 + r, |r| <= ln2/2, Cephes' degree-6 polynomial for
  // e^r, 2^k by the exponent bits with k clamped in integers: x below about
  // -87.3 gives 0 (not a denormal), above about 88.4 gives inf. Relative
  // error <= 1e-7 elsewhere (8.0e-8 measured against double exp over
  // [-87, 88], tests/test_aerial_spectral.cpp). Needs |x| < 2.9e6 (the
  // rounding trick and the int conversion); log_at's result always is.
  static float exp_f(float x) {
    const float kf = (x * 1.44269504088896341f + 12582912.0f) - 12582912.0f;  // round(x / ln2): 1.5 2^23 trick
    float r = x - kf * 0.693359375f;
    r = r - kf * -2.12194440e-4f;
    const float z = r * r;
    float y = 1.9875691500e-4f;
    y = y * r + 1.3981999507e-3f;
    y = y * r + 8.3334519073e-3f;
    y = y * r + 4.1665795894e-2f;
    y = y * r + 1.6666665459e-1f;
    y = y * r + 5.0000001201e-1f;
    y = y * z + r + 1.0f;
    std::int32_t k = static_cast<std::int32_t>(kf);
    k = k < -127 ? -127 : k;  // 2^-127 -> bits 0: the result 0
    k = k > 128 ? 128 : k;    // 2^128 -> bits of inf
    const std::int32_t bits = (k + 127) << 23;
    float p;
    std::memcpy(&p, &bits, sizeof p);
    return y * p;
  }
  // The cell position t = s / step, in f32 (inv_step = 1 / step_m).
  static float cell(double s_m, double inv_step) { return static_cast<float>(s_m * inv_step); }
  // ln Gamma_c at cell position t (t <= 0 or NaN: s = 0, Gamma = 1).
  std::array<float, 3> log_at(float t) const {
    if (!(t > 0.0f) || log_gamma.size() < 2) return {0.0f, 0.0f, 0.0f};
    const auto last = static_cast<std::int32_t>(log_gamma.size() - 1);
    const std::int32_t i = t >= static_cast<float>(last) ? last - 1 : static_cast<std::int32_t>(t);
    const float f = t - static_cast<float>(i);
    const std::array<float, 3>& a = log_gamma[static_cast<std::size_t>(i)];
    const std::array<float, 3>& b = log_gamma[static_cast<std::size_t>(i) + 1];
    std::array<float, 3> x = {a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])};
    // Tables hold ln Gamma >= ln 1e-300 = -690.8, so only extrapolation far
    // beyond the grid can leave exp_f's domain: bound it there (e^-1e4 and
    // e^-690.8 are both 0 in f32).
    if (f > 1.0f)
      for (float& v : x) v = std::min(std::max(v, -1.0e4f), 1.0e4f);
    return x;
  }
  std::array<float, 3> at(double s_m) const {
    if (!(s_m > 0.0) || log_gamma.size() < 2) return {1.0f, 1.0f, 1.0f};
    const std::array<float, 3> x = log_at(cell(s_m, 1.0 / step_m));
    return {exp_f(x[0]), exp_f(x[1]), exp_f(x[2])};
  }
  // Tabulate any Gamma(s) (tests use closed forms such as e^{-beta_c s}).
  static AttenuationTable from_function(const std::function<std::array<double, 3>(double)>& gamma, double s_max_m,
                                        int samples = 4096) {
    AttenuationTable t;
    t.step_m = s_max_m / (samples - 1);
    t.log_gamma.resize(samples);
    for (int i = 0; i < samples; ++i) {
      const std::array<double, 3> g = i == 0 ? std::array<double, 3>{1.0, 1.0, 1.0} : gamma(i * t.step_m);
      for (int c = 0; c < 3; ++c) t.log_gamma[i][c] = static_cast<float>(std::log(std::max(g[c], 1e-300)));
    }
    return t;
  }
};
// Gamma for (T, h0, q) tabulated over [0, s_max_m]; node i holds
// attenuation_direct(a, q, i step) rounded to f32 (within 1 ulp: the nodes
// come from a recurrence over s whose drift is <= 1.4e-14 relative; ~2 ms for
// 4096 nodes on one core instead of 401 exp per node). Error of at() against
// the direct integral (max |at - direct|, measured, tests/test_aerial_spectral.cpp)
// grows as step^2 and with T: over 0..100 km with 16384 samples <= 1.3e-6
// (4096 samples: 2.0e-5 at T 20 near s = 0); over a 2 km scene with 4096
// samples <= 6.3e-8 for T = 1..20 (the float output's own rounding).
// threads: OpenMP threads of the tabulation (0 = all, as Exec::threads; the
// table does not depend on it).
inline constexpr int kAttenuationSamples = 4096;  // the effects' table size
AttenuationTable attenuation_table(const Atmosphere& a, const SpectralSensitivity& q, double s_max_m,
                                   int samples = kAttenuationSamples, int threads = 0);

// ---- the slant path (issue #59; docs/aerial.md, "Paths that climb") -------------------
// The coefficients above hold at the observer's altitude h0; the air thins
// with height as e^{-h/H} (H_R = 7994 m, H_M = 1200 m: the same scale heights).
// Along a straight path of length s from h0 to a target at h1 = h0 + dh (flat
// Earth), the optical depth of either kind is its coefficient at h0 times an
// equivalent level distance:
//   tau = beta(h0) int_0^s e^{-(dh t/s)/H} dt = beta(h0) s g(dh/H),
//   g(x) = (1 - e^{-x})/x = -expm1(-x)/x,  g(0) = 1,
// exact for the exponential atmosphere over a flat Earth (expm1 keeps it exact
// near level: g(1e-12) is 1 - 5e-13, not the 1 +- 1e-4 of 1 - e^{-x} in
// double). Gamma_c is then the spectral integral of
// e^{-beta_R(l) s_R - beta_M(l) s_M}, s_R = s g(dh/H_R), s_M = s g(dh/H_M):
// a function of two distances, tabulated on a 2-D grid (SlantAttenuationTable).
// --path level (every record before it) takes dh = 0: s_R = s_M = s.
// Validity: the flat Earth drops below a straight path by s^2/(2 R_E), 71 m at
// 30 km, where the Mie density along a level path would be off by e^{71/1200}
// = 6 % at its end (2 % of its optical depth): paths longer than 30 km and
// targets below -500 m are refused.
constexpr double kRayleighScaleHeightM = 7994.0, kMieScaleHeightM = 1200.0;
constexpr double kSlantPathMaxM = 30000.0, kSlantTargetMinAltitudeM = -500.0;
enum class AerialPath { level, slant };
const EnumNames<AerialPath>& aerial_path_names();
// g(x) = -expm1(-x)/x, 1 at x = 0.
double slant_factor(double x);
struct SlantDistances {
  double rayleigh_m = 0.0, mie_m = 0.0;  // s g(dh/H_R), s g(dh/H_M)
};
SlantDistances slant_distances(double s_m, double dh_m);
// The spectral integral at two equivalent distances (the slant path's peer of
// attenuation_direct, which it equals at s_R = s_M = s).
std::array<double, 3> attenuation_slant_direct(const Atmosphere& a, const SpectralSensitivity& q, double s_rayleigh_m,
                                               double s_mie_m);
// ln Gamma_c on the grid (i step_r_m, j step_m_m), i < nr, j < nm, stored
// row-major [j nr + i] in f32, interpolated bilinearly in ln Gamma (exact for
// one wavelength, where ln Gamma is linear in both distances); positions
// beyond the grid take its edge (the grid spans every known pixel's
// distances; only the prepared sky beyond R_max reaches past it, and the sky
// is left unchanged). Error against attenuation_slant_direct: docs/aerial.md
// and tests/test_aerial_slant.cpp.
struct SlantAttenuationTable {
  double step_r_m = 0.0, step_m_m = 0.0;
  int nr = 0, nm = 0;
  std::vector<std::array<float, 3>> log_gamma;
  std::array<float, 3> log_at(float tr, float tm) const {
    tr = std::min(std::max(tr, 0.0f), static_cast<float>(nr - 1));  // NaN -> 0 (max(NaN, 0) is 0)
    tm = std::min(std::max(tm, 0.0f), static_cast<float>(nm - 1));
    const int i = std::min(static_cast<int>(tr), nr - 2), j = std::min(static_cast<int>(tm), nm - 2);
    const float fr = tr - static_cast<float>(i), fm = tm - static_cast<float>(j);
    const std::size_t k = static_cast<std::size_t>(j) * nr + i;
    const std::array<float, 3>&a = log_gamma[k], &b = log_gamma[k + 1], &c = log_gamma[k + nr],
                                  &d = log_gamma[k + nr + 1];
    std::array<float, 3> x{};
    for (int ch = 0; ch < 3; ++ch) {
      const float lo = a[ch] + fr * (b[ch] - a[ch]), hi = c[ch] + fr * (d[ch] - c[ch]);
      x[ch] = lo + fm * (hi - lo);
    }
    return x;
  }
};
inline constexpr int kSlantSamples = 256;  // per axis
// sr_max, sm_max > 0 and finite [m]; nr, nm >= 2. threads as attenuation_table.
SlantAttenuationTable slant_attenuation_table(const Atmosphere& a, const SpectralSensitivity& q, double sr_max_m,
                                              double sm_max_m, int nr = kSlantSamples, int nm = kSlantSamples,
                                              int threads = 0);

// ==== brume aerial: render, re-render, remove (Morales eq. 3.11-3.13) =================
// With s = R distance_scale the physical distance of a pixel and Gamma_c(s)
// its table look-up (per channel c of the sensitivity's space):
//   render     I_c  = I0_c Gamma_c + Iinf_c (1 - Gamma_c)                   (eq. 3.11)
//   re-render  I2_c = I1_c (Iinf2_c Gamma2_c)/(Iinf1_c Gamma1_c)
//                     + Iinf2_c (1 - Gamma2_c/Gamma1_c)                       (eq. 3.13)
//              Gamma1 at --from-turbidity, Gamma2 at --turbidity; the photo's
//              own horizon Iinf1 (--from-horizon) and the new one Iinf2
//              (--horizon). Exact for the model: it equals rendering the clean
//              image, its illumination scaled by Iinf2/Iinf1, at T2.
//   remove     I0_c = (I_c - Iinf_c (1 - Gamma_c)) / max(Gamma_c, gamma_floor)
// Every mode is "rho E' + (1 - rho) A" except remove: render rho = Gamma,
// E' = I0, A = Iinf; re-render rho = Gamma2 / max(Gamma1, gamma_floor),
// E' = I1 Iinf2/Iinf1, A = Iinf2. That is the form the scattering blur
// (Hansard eq. 2-4, as haze) diffuses, premultiplied PER CHANNEL:
//   F = (rho_r E'_r, rho_g E'_g, rho_b E'_b, rho_r, rho_g, rho_b)   six channels,
//   F diffused with one sigma map,  out_c = F_c + (1 - F_{3+c}) A_c,
// so distant objects blur and take the sky's colour together. The sigma law
// is haze's: sigma = sigma0 + R'^{3/2} (sigma_max - sigma0), R' = R/R_max,
// sigma_max = sigma0 + lambda sqrt(kappa_s'), kappa_s' = (beta_R + beta_M)(550 nm)
// R_max distance_scale (the optical depth at the far end). Remove cannot
// undo a blur: --lambda > 0 with --remove is refused.
// In XYZ sensitivity space the image (and Iinf) are taken to XYZ with the
// IEC 61966-2-1 matrix M (linear sRGB, D65) first and back after, so the
// operator on linear sRGB is M diag(Gamma) M^-1.
// Sky pixels -- unknown in the MEASURED range (NaN, inf, 0), whether or not
// preparation later gave them S_max -- are left exactly as they are by every
// mode: the sky already is the horizon colour; in the blur they still
// contribute F at the far end, so the edge of distant land fades smoothly.
struct AerialParams {
  Atmosphere atmosphere;                 // --turbidity [1, 20], --altitude [m] [-500, 9000]
  std::string turbidity_rule;            // "contrast" (--turbidity contrast): atmosphere.turbidity is fitted on
                                         // the image by run_aerial (fit_turbidity_contrast), NaN until then;
                                         // "": T as given
  std::string sensitivity = "default";   // --sensitivity default | FILE.csv | DATABASE#CAMERA
  std::optional<Rgb> airlight;           // Iinf, linear RGB, >= 0; unset: estimated (analyse_aerial)
  std::string airlight_rule;             // "horizon" (--airlight horizon): estimated just above the far
                                         // skyline; "" with airlight unset: the sky's median (auto)
  double distance_scale = 1.0;           // [1] s = R distance_scale (models, miniatures), > 0
  std::optional<double> from_turbidity;  // [1] T1 of the photo for a re-render, [1, 20]; unset: render
  std::optional<Rgb> from_airlight;      // Iinf1, linear RGB, > 0; unset: the same as airlight
  bool remove = false;                   // recover I0 instead of rendering
  double gamma_floor = 1e-3;             // [1] smallest Gamma divided by (remove, Gamma1), (0, 1)
  double lambda = 0.0;                   // [px] blur gain, >= 0 (0: the thesis, no blur)
  DiffusionParams diffusion;             // sigma0, scheme, precision, rho-max, edge-rate
  AerialPath path = AerialPath::level;   // --path: level (h0's coefficients all along) or slant
  CameraPose camera;                     // --pitch, --roll (--yaw, --view-matrix: its rotation): the rays'
                                         // elevations for --path slant; the position is not declared
};
const ParamTable<AerialParams>& aerial_param_table();

// Range checks, and combinations a run would ignore or cannot do (remove
// with --from-turbidity or --lambda; --from-horizon without --from-turbidity).
void validate_aerial(const AerialParams& p, const std::set<std::string>& given = {});

// What --path slant needs besides the parameters: each pixel's target
// altitude, either from the camera (its intrinsics and pose: h1 = h0 + s
// sin(elevation of the pixel's ray)) or per pixel (metres above sea level, 1
// channel, the image's size; e.g. from a DEM). One of the two.
struct AerialGeometry {
  std::optional<Camera> camera;
  DenseImageRef target_altitude;  // empty: from the camera
  std::string target_altitude_name = "--target-altitude";  // named in errors
};

enum class AerialMode { render, rerender, remove };
std::string to_string(AerialMode m);

struct AerialAnalysis {
  AerialMode mode = AerialMode::render;
  double range_max_m = 0.0, range_min_m = 0.0;  // of the measured range's known pixels
  std::size_t unknown_pixels = 0;
  Image sky;                                // 1 where the measured range is unknown: left unchanged
  SpectralSensitivity sensitivity;
  AttenuationTable gamma;                   // at T, over [0, R_max distance_scale]
  AttenuationTable gamma_from;              // at T1 (re-render only)
  std::array<float, 3> airlight{};          // Iinf (Iinf2 of a re-render), linear RGB
  std::string airlight_source;
  nlohmann::json airlight_where;            // --airlight horizon: the pixels it took (null otherwise)
  std::array<float, 3> from_airlight{};     // Iinf1 (re-render only), linear RGB
  std::string from_airlight_source;
  double beta_550_per_m = 0.0;              // (beta_R + beta_M)(550 nm, T, h0)
  double kappa_s = 0.0;                     // kappa_s' = beta_550 R_max distance_scale
  double sigma_max = 0.0;                   // [px]
  DiffusionPlan plan;
  // --path slant: per pixel dh = s slope + offset [m] (2 channels: slope =
  // sin(elevation) from the camera, or 0 with offset = h1 - h0 from
  // --target-altitude), the tables over (s_R, s_M), and what the record says.
  Image slant_dh;
  SlantAttenuationTable slant_gamma, slant_gamma_from;
  nlohmann::json slant_record;
};
// --airlight horizon (issue #59): Iinf from the sky just above the far
// skyline, where a photo's horizon colour is: per column the topmost known
// pixel is the skyline; the columns whose skyline is among the farthest
// quarter (by its range) give their sky pixels 3 to 8 rows above it (a DEM's
// skyline is often a few pixels off the photo's), less those darker than the
// sky 9 to 28 rows above the skyline in that column (land the DEM calls sky)
// and near-black ones (a panorama's stitch borders); the per-channel median of
// the rest. At least 16 such pixels, else refused (give --airlight R,G,B).
// `where` gets the columns, rows, pixels and skyline range it used.
std::array<float, 3> horizon_airlight(DenseImageRef rgb, DenseImageRef range, nlohmann::json& where);

// --turbidity contrast (issue #59): the turbidity a photograph shows, from
// how its terrain's contrast falls with distance. With I = J Gamma + Iinf (1 -
// Gamma), the difference of two neighbouring pixels on one surface (ranges
// within kContrastSameSurface) is Gamma times the clean scene's difference:
// the airlight cancels. Per distance bin (log-spaced, ratio kContrastBinRatio,
// at least kContrastMinPairs pairs), the mean |difference| per channel c of
// the working space (XYZ or the camera's RGB, as Gamma) gives y_c = ln of it;
// the model is y_c = a_c + ln Gamma_c(bin; T) with a_c free per channel (the
// scene's own contrast, assumed the same at every distance: the fit's one
// assumption, said in docs/aerial.md), and T minimises the squared misfit on
// [1, 20] (a 0.25 grid, then golden-section search to 1e-5). Pairs with a
// channel <= 0 (crushed shadows, stitch borders) or within 0.1 % of a
// channel's clipped plateau (its brightest value held by >= 0.1 % of the
// pixels: snow at the encoding's maximum) are left out, counted; so are bins
// whose contrast in a channel is below kContrastFloor of that channel's
// highest bin (the noise floor of an 8-bit photo, ~1/255). Needs
// kContrastMinBins bins spanning kContrastMinSpan in distance, else refused.
// --path slant: each bin's mean equivalent distances (slant_distances of each
// pair's range and target altitude). The record gives every bin, the
// jackknife spread over bins and whether T sits on a bound (then `warning`).
constexpr double kContrastSameSurface = 0.01, kContrastBinRatio = 1.189207115002721;  // 2^(1/4)
constexpr float kContrastClippedFraction = 0.999f;
constexpr double kContrastMinPairs = 200.0, kContrastMinSpan = 2.0, kContrastFloor = 0.05;
constexpr int kContrastMinBins = 4;
struct TurbidityContrastFit {
  double turbidity = 0.0;
  bool at_lower_bound = false, at_upper_bound = false;
  std::string warning;     // non-empty on a bound
  nlohmann::json record;   // the record's "turbidity_fit"
};
TurbidityContrastFit fit_turbidity_contrast(DenseImageRef rgb, DenseImageRef range, const AerialParams& p,
                                            const AerialGeometry* geometry = nullptr, int threads = 0);

// Validates parameters and inputs (throws brume::Error), loads the
// sensitivity, tabulates Gamma, estimates Iinf. `range` is the MEASURED
// range in metres (1 channel, rgb's size). Iinf auto: the per-channel median
// of the sky pixels (unknown range) when they are >= 0.5 % of the frame, else
// the per-channel median of the brightest 10 % (by luminance) of the 1 %
// most distant known pixels -- the thesis' "brightest pixels near the horizon".
// threads: OpenMP threads of its passes (0 = all, as Exec::threads; the
// analysis does not depend on it).
AerialAnalysis analyse_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, int threads = 0);
// The same analysis into `a`, reusing a.sky's buffer when it already has the
// frame's size (a video or batch caller keeps `a` between frames and so pays
// no 7 MB allocation, zero-fill and page faults per 1600x1120 frame for the
// mask). Every field of `a` is overwritten; the result equals the returning
// form's, bit for bit. If it throws, `a` is left valid but unspecified.
void analyse_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, AerialAnalysis& a,
                    int threads = 0, const AerialGeometry* geometry = nullptr);
// --path slant: the geometry is required (throws naming --path, the
// intrinsics, the pose and --target-altitude otherwise); --path level ignores it.

// A linear sRGB colour (Iinf) in the analysis' working space: XYZ when the
// sensitivity is XYZ (M diag(Gamma) M^-1), else as it is. The CPU apply, the
// GPU passes and the preview's uniforms take Iinf from here.
std::array<float, 3> aerial_working_colour(const AerialAnalysis& a, const std::array<float, 3>& c);
// The GPU passes' uMode: 0 render, 1 re-render, 2 remove.
int aerial_mode_index(AerialMode m);

struct AerialResult {
  Image rgb;          // linear RGB
  Image attenuation;  // 3 channels: rho per channel after the blur (Gamma; Gamma2/Gamma1 for a
                      // re-render; the unfloored Gamma divided out by remove); 1 on sky pixels
  Image scale;        // target scale sigma(x) in px, 1 channel
  std::size_t floored_pixels = 0;  // pixels where a Gamma below gamma_floor was floored
};
// The per-pixel apply on the CPU. `range` is the range the effect runs on
// (the prepared one in the pipeline); unknown pixels in it are sky too.
AerialResult apply_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, const AerialAnalysis& a,
                          const Exec& exec = {});
// The optional maps of the buffer-reusing apply below: null = not computed,
// not written (a caller that writes neither saves ~28 MB of stores per
// 1600x1120 frame; the blur computes its sigma map internally either way).
struct AerialMaps {
  Image* attenuation = nullptr;  // 3 channels, as AerialResult::attenuation
  Image* scale = nullptr;        // 1 channel, as AerialResult::scale
};
// The same apply into caller-provided buffers: `out` (3 channels) and the
// maps asked for are (re)allocated only when their size differs from the
// frame's, so a caller that keeps them between frames pays no allocation,
// zero-fill or first-touch page faults. `out` may be `rgb` itself (in place);
// the maps must be distinct images other than rgb and range. Pixels equal the
// returning form's bit for bit. Returns AerialResult::floored_pixels.
std::size_t apply_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, const AerialAnalysis& a,
                         Image& out, const AerialMaps& maps = {}, const Exec& exec = {});

// ---- the pipeline ---------------------------------------------------------------------
struct AerialRun {
  AerialResult result;
  AerialAnalysis analysis;
  nlohmann::json record;  // {"aerial": ..., "prepare": ..., "execution": ...}
};
AerialRun run_aerial(DenseImageRef rgb, DenseImageRef measured_range, const AerialParams& p, const RangeStep& prepare,
                     const Exec& exec = {}, const std::set<std::string>& given = {},
                     const AerialGeometry* geometry = nullptr);

}  // namespace brume
