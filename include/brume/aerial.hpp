// brume — spectral aerial perspective from atmospheric turbidity
// (Morales, "Rendering aerial perspective in mixed reality from atmospheric
// turbidity", ch. 3-4; ../shared/DESIGN.md for the corrections).
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
#include <functional>
#include <string>
#include <vector>

#include "brume/params.hpp"

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

// --sensitivity default | FILE.csv | DATABASE.txt#CAMERA NAME (see the README);
// throws brume::Error naming the file, the line and the value.
SpectralSensitivity load_sensitivity(const std::string& spec);

// ---- attenuation -------------------------------------------------------------------------
// The spectral integral itself, in double (the per-pixel peer of the table).
std::array<double, 3> attenuation_direct(const Atmosphere& a, const SpectralSensitivity& q, double s_m);

// Gamma_c(s) on a uniform grid of s, stored as ln Gamma and interpolated
// linearly in ln Gamma (exact for a single wavelength, where ln Gamma is
// linear in s; the spectral spread only bends it slightly). Beyond the grid,
// ln Gamma continues along its last slope.
struct AttenuationTable {
  double step_m = 0.0;                               // grid spacing, > 0
  std::vector<std::array<float, 3>> log_gamma;       // ln Gamma_c at s = i step_m; [0] = {0, 0, 0}

  std::array<float, 3> at(double s_m) const {
    if (!(s_m > 0.0) || log_gamma.size() < 2) return {1.0f, 1.0f, 1.0f};
    const double t = s_m / step_m;
    const std::size_t last = log_gamma.size() - 1;
    std::size_t i = t >= static_cast<double>(last) ? last - 1 : static_cast<std::size_t>(t);
    const double f = t - static_cast<double>(i);
    std::array<float, 3> g{};
    for (int c = 0; c < 3; ++c) {
      const double a = log_gamma[i][c], b = log_gamma[i + 1][c];
      g[c] = static_cast<float>(std::exp(a + f * (b - a)));
    }
    return g;
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
// attenuation_direct(a, q, i step) itself. Interpolation error (max |table -
// direct|, measured, tests/test_aerial_spectral.cpp) grows as step^2 and with
// T: over 0..100 km with 4096 samples 4.8e-8 (T 1) .. 2.0e-5 (T 20, near
// s = 0), with 16384 samples <= 1.3e-6; over a 2 km scene with 4096 samples
// <= 4.5e-8 for T = 1..20 (the float output's own rounding).
AttenuationTable attenuation_table(const Atmosphere& a, const SpectralSensitivity& q, double s_max_m,
                                   int samples = 4096);

}  // namespace brume
