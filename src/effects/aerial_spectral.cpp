// STAND-IN, replaced by the spectral branch: the minimum of include/brume/aerial.hpp's
// spectral contract that lets the aerial render, its pipeline and its tests
// link and run. beta_R and beta_M are the header's formulas; the only
// sensitivity is a flat q = 1 in camera_rgb space; Gamma is a plain sum over
// the 1 nm grid. Tests of the render must not depend on these numbers.
#include <cmath>
#include <sstream>

#include "brume/aerial.hpp"
#include "brume/error.hpp"

namespace brume {

void validate_atmosphere(const Atmosphere& a) {
  if (!(a.turbidity >= 1.0 && a.turbidity <= 20.0)) {
    std::ostringstream m;
    m << "--turbidity " << a.turbidity << " is outside [1, 20]; give a turbidity between 1 (pure air) and 20";
    throw Error(m.str());
  }
  if (!(a.altitude_m >= -500.0 && a.altitude_m <= 9000.0)) {
    std::ostringstream m;
    m << "--altitude " << a.altitude_m << " m is outside [-500, 9000] m; give the observer's altitude in metres";
    throw Error(m.str());
  }
}

double rayleigh_beta_per_m(double lambda_nm, double altitude_m) {
  const double pi = 3.14159265358979323846, n = 1.0003, pn = 0.035, N = 2.545e25, KR = 1.0396;
  const double l = lambda_nm * 1e-9, n2 = n * n - 1.0;
  return 8.0 * pi * pi * pi * n2 * n2 / (3.0 * N * l * l * l * l) * (6.0 + 3.0 * pn) / (6.0 - 7.0 * pn) * KR *
         std::exp(-altitude_m / 7994.0);
}

double mie_beta_per_m(double lambda_nm, double turbidity, double altitude_m) {
  const double pi = 3.14159265358979323846, nu = 4.0, KM = 0.0092;
  const double l = lambda_nm * 1e-9, c = (0.65 * turbidity - 0.65) * 1e-16;
  return 0.434 * c * pi * std::pow(2.0 * pi / l, nu - 2.0) * KM * std::exp(-altitude_m / 1200.0);
}

SpectralSensitivity load_sensitivity(const std::string& spec) {
  if (spec != "default")
    throw Error("--sensitivity '" + spec + "': this build's stand-in knows only 'default' (flat q = 1)");
  SpectralSensitivity s;
  s.source = "default (STAND-IN: flat q = 1)";
  s.space = SensitivitySpace::camera_rgb;
  s.q.assign(kSensitivitySamples, {1.0, 1.0, 1.0});
  return s;
}

std::array<double, 3> attenuation_direct(const Atmosphere& a, const SpectralSensitivity& q, double s_m) {
  std::array<double, 3> num{}, den{};
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double l = kAerialLambdaMinNm + i;
    const double t =
        std::exp(-(rayleigh_beta_per_m(l, a.altitude_m) + mie_beta_per_m(l, a.turbidity, a.altitude_m)) * s_m);
    for (int c = 0; c < 3; ++c) num[c] += t * q.q[i][c], den[c] += q.q[i][c];
  }
  for (int c = 0; c < 3; ++c) num[c] = den[c] > 0.0 ? num[c] / den[c] : 1.0;
  return num;
}

AttenuationTable attenuation_table(const Atmosphere& a, const SpectralSensitivity& q, double s_max_m, int samples) {
  return AttenuationTable::from_function([&](double s) { return attenuation_direct(a, q, s); }, s_max_m, samples);
}

}  // namespace brume
