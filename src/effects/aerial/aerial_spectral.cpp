// brume — the spectral core of aerial perspective (Morales 2014, ch. 3;
// docs/aerial.md): scattering coefficients, camera sensitivities and the
// camera-weighted attenuation Gamma_c(s) of eq. 3.10, directly and as a table.
//
// Integration: Gamma_c(s) = sum_i w_i e^{-beta(l_i) s} q_c(l_i) / sum_i w_i q_c(l_i)
// on the 1 nm grid l_i = 380 + i nm (401 nodes, 400 intervals), with the
// composite Simpson weights w = (1, 4, 2, 4, ..., 2, 4, 1)/3. Why Simpson and not
// the trapezoid or the plain grid sum: for a flat q the trapezoid's end
// correction h^2/12 (f'(b) - f'(a)) / 400 is 3.7e-9 at s = 1 km and 2.6e-7 at
// 100 km (T = 1), while Simpson's h^4 error stays below 1e-9 out to 100 km for
// T = 1..20 (tested against a 0.01 nm integral). The weights are positive, so
// Gamma stays in (0, 1] and is non-increasing in s and T for any q >= 0; the
// same sum gives the normaliser, so Gamma(0) = 1 exactly. Sensitivities on a
// 10 nm grid (camspec) have their kinks at even nodes, i.e. on Simpson's panel
// boundaries, so the rule integrates their piecewise-linear q without loss.
#include <omp.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/text.hpp"

namespace brume {

namespace {

std::string spectral_num(double v) {
  std::ostringstream o;
  o.precision(10);
  o << v;
  return o.str();
}

void check_lambda(double lambda_nm) {
  if (!(lambda_nm >= kAerialLambdaMinNm && lambda_nm <= kAerialLambdaMaxNm))
    throw Error("wavelength " + spectral_num(lambda_nm) + " nm is outside the model's range [380, 780] nm");
}

}  // namespace

// ---- scattering coefficients ------------------------------------------------------

void validate_atmosphere(const Atmosphere& a) {
  if (!(a.turbidity >= 1.0 && a.turbidity <= 20.0))
    throw Error("--turbidity " + spectral_num(a.turbidity) +
                " is outside [1, 20]: T = 1 is a pure Rayleigh sky, T = 20 thick haze near fog (the range of the "
                "Preetham/Morales model); give a value in [1, 20]");
  if (!(a.altitude_m >= -500.0 && a.altitude_m <= 9000.0))
    throw Error("--altitude " + spectral_num(a.altitude_m) +
                " m is outside [-500, 9000] m (observer altitude above sea level, from the Dead Sea shore to "
                "above Everest); give the observer's altitude in metres");
}

namespace {
double rayleigh_beta(double lambda_nm, double altitude_m);
double mie_beta(double lambda_nm, double turbidity, double altitude_m);
}  // namespace

double rayleigh_beta_per_m(double lambda_nm, double altitude_m) {
  check_lambda(lambda_nm);
  return rayleigh_beta(lambda_nm, altitude_m);
}

double mie_beta_per_m(double lambda_nm, double turbidity, double altitude_m) {
  check_lambda(lambda_nm);
  return mie_beta(lambda_nm, turbidity, altitude_m);
}

double aerial_extinction_per_m(double lambda_nm, const Atmosphere& a) {
  if (!(lambda_nm >= kAerialLambdaMinNm && lambda_nm <= kAerialExtinctionLambdaMaxNm))
    throw Error("wavelength " + spectral_num(lambda_nm) +
                " nm is outside [380, 2000] nm, where the model's extinction is taken (the LiDAR's --lidar-wavelength)");
  return rayleigh_beta(lambda_nm, a.altitude_m) + mie_beta(lambda_nm, a.turbidity, a.altitude_m);
}

namespace {

double rayleigh_beta(double lambda_nm, double altitude_m) {
  validate_atmosphere({1.0, altitude_m});
  // Molecular scattering of air (Preetham 1999 / Morales eq. 3.4): n the
  // refractive index, N the molecular density at sea level, p_n the
  // depolarisation factor; K_R = 1.0396 is the thesis' calibration giving
  // 0.0141 /km at 550 nm. Density falls off with the 7994 m scale height.
  constexpr double n = 1.0003, pn = 0.035, N = 2.545e25, K_R = 1.0396, H_R = 7994.0;
  const double l = lambda_nm * 1e-9;
  const double n2 = n * n - 1.0;
  return 8.0 * M_PI * M_PI * M_PI * n2 * n2 / (3.0 * N * l * l * l * l) * (6.0 + 3.0 * pn) / (6.0 - 7.0 * pn) * K_R *
         std::exp(-altitude_m / H_R);
}

double mie_beta(double lambda_nm, double turbidity, double altitude_m) {
  validate_atmosphere({turbidity, altitude_m});
  // Aerosol (Mie) scattering with Junge exponent nu = 4, so beta_M ~ lambda^-2;
  // the concentration c(T) vanishes at T = 1 (no aerosol) and grows linearly
  // with T. Aerosols sit low: 1200 m scale height.
  constexpr double nu = 4.0, K_M = 0.0092, H_M = 1200.0;
  const double c = (0.65 * turbidity - 0.65) * 1e-16;  // [m^2]
  const double l = lambda_nm * 1e-9;
  return 0.434 * c * M_PI * std::pow(2.0 * M_PI / l, nu - 2.0) * K_M * std::exp(-altitude_m / H_M);
}

}  // namespace

// ---- camera spectral sensitivities -------------------------------------------------

namespace {

// CIE 1931 2-degree colour-matching functions, the multi-lobe fit of Wyman,
// Sloan & Shirley, "Simple analytic approximations to the CIE XYZ color
// matching functions", JCGT 2(2), 2013, eq. 4: sums of piecewise Gaussians
// with a different width either side of the peak. Formulas, not a table: no
// data licence. Against the CIE table on 380-780 nm at 1 nm the fit's largest
// error is 0.015 (x, 631 nm), 0.0076 (y, 528 nm), 0.024 (z, 425 nm; peak 1.78);
// it stays positive (x's small negative lobe never wins: min 4.9e-8 at 1 nm).
double lobe(double l, double mu, double s_below, double s_above) {
  const double t = (l - mu) / (l < mu ? s_below : s_above);
  return std::exp(-0.5 * t * t);
}
std::array<double, 3> cie1931_wyman(double l) {
  return {1.056 * lobe(l, 599.8, 37.9, 31.0) + 0.362 * lobe(l, 442.0, 16.0, 26.7) - 0.065 * lobe(l, 501.1, 20.4, 26.2),
          0.821 * lobe(l, 568.8, 46.9, 40.5) + 0.286 * lobe(l, 530.9, 16.3, 31.1),
          1.217 * lobe(l, 437.0, 11.8, 36.0) + 0.681 * lobe(l, 459.0, 26.0, 13.8)};
}

// A number that is the whole field (white space around it allowed); false
// for text, NaN, infinity or overflow.
bool spectral_parse_number(const std::string& field, double& v) {
  errno = 0;
  return text::parse_number(text::trim(field), v) && errno != ERANGE && std::isfinite(v);
}

std::string where(const std::string& path, int line) { return "--sensitivity '" + path + "' line " + std::to_string(line); }

// Samples (wavelength ascending) -> the 1 nm grid: linear between samples,
// zero outside the data (a camera does not respond where it was not measured).
std::vector<std::array<double, 3>> to_grid(const std::vector<double>& wl, const std::vector<std::array<double, 3>>& v) {
  std::vector<std::array<double, 3>> q(kSensitivitySamples, {0.0, 0.0, 0.0});
  std::size_t k = 0;
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double l = kAerialLambdaMinNm + i;
    if (l < wl.front() || l > wl.back()) continue;
    while (k + 1 < wl.size() && wl[k + 1] < l) ++k;
    if (k + 1 == wl.size() || wl[k] == l) {
      q[i] = v[k];
      continue;
    }
    const double f = (l - wl[k]) / (wl[k + 1] - wl[k]);
    for (int c = 0; c < 3; ++c) q[i][c] = v[k][c] + f * (v[k + 1][c] - v[k][c]);
  }
  return q;
}

void check_channels(const SpectralSensitivity& s) {
  static const char* names[3] = {"r", "g", "b"};
  for (int c = 0; c < 3; ++c) {
    double sum = 0.0;
    for (const auto& q : s.q) sum += q[c];
    if (!(sum > 0.0))
      throw Error("--sensitivity '" + s.source + "': channel " + names[c] +
                  " is zero everywhere in 380-780 nm, so its attenuation is undefined; give a curve with data in "
                  "that range");
  }
}

std::vector<std::string> read_lines(const std::string& path) {
  // A regular file (brume/io.hpp) of at most 16 MiB (the camspec database is 28 kB).
  std::string text;
  try {
    text = read_input_file(path, "--sensitivity", {16u << 20, "a table of camera sensitivities"});
  } catch (const FileNotFound& e) {
    throw FileNotFound(std::string(e.what()) + "; give a CSV of wavelength_nm,r,g,b rows, DATABASE.txt#CAMERA NAME, "
                       "or 'default' (the CIE 1931 observer)");
  }
  std::istringstream f(text);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(f, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(line);
  }
  return lines;
}

SpectralSensitivity load_csv(const std::string& path) {
  const std::vector<std::string> lines = read_lines(path);
  std::vector<double> wl;
  std::vector<std::array<double, 3>> v;
  bool header_allowed = true;
  for (std::size_t n = 0; n < lines.size(); ++n) {
    const int ln = static_cast<int>(n) + 1;
    const std::string t = text::trim(lines[n]);
    if (t.empty() || t[0] == '#') continue;
    std::vector<std::string> f;
    std::stringstream ss(t);
    std::string field;
    while (std::getline(ss, field, ',')) f.push_back(field);
    double w = 0.0;
    // One header line (a first field that is not a number) may precede the data.
    if (header_allowed && !f.empty() && !spectral_parse_number(f[0], w)) {
      header_allowed = false;
      continue;
    }
    header_allowed = false;
    if (f.size() != 4)
      throw Error(where(path, ln) + ": '" + t + "' has " + std::to_string(f.size()) +
                  " fields; each data row is wavelength_nm,r,g,b");
    if (!spectral_parse_number(f[0], w)) throw Error(where(path, ln) + ": wavelength '" + text::trim(f[0]) + "' is not a number");
    if (w < 0.0) throw Error(where(path, ln) + ": wavelength " + spectral_num(w) + " nm is negative");
    if (!wl.empty() && !(w > wl.back()))
      throw Error(where(path, ln) + ": wavelength " + spectral_num(w) + " nm does not increase (previous row " +
                  spectral_num(wl.back()) + " nm); sort the rows by wavelength, one row per wavelength");
    std::array<double, 3> q{};
    for (int c = 0; c < 3; ++c) {
      if (!spectral_parse_number(f[1 + c], q[c]))
        throw Error(where(path, ln) + ": value '" + text::trim(f[1 + c]) + "' is not a number");
      if (q[c] < 0.0)
        throw Error(where(path, ln) + ": value " + spectral_num(q[c]) +
                    " is negative; a sensitivity is a response, >= 0 (clip a measurement's noise floor to 0 "
                    "yourself if that is what it is)");
    }
    wl.push_back(w);
    v.push_back(q);
  }
  if (wl.empty())
    throw Error("--sensitivity '" + path + "' has no data rows; expected rows wavelength_nm,r,g,b (an optional "
                "header line and # comments are allowed)");
  SpectralSensitivity s;
  s.source = path;
  s.sha256 = sha256_file(path);
  s.space = SensitivitySpace::camera_rgb;
  s.q = to_grid(wl, v);
  check_channels(s);
  return s;
}

// The camspec database (Jiang, Liu, Gu & Susstrunk, WACV 2013): a header
// ending with a line of dashes, then per camera a name line and the R, G and
// B rows, 33 values each at 400, 410, ..., 720 nm (the rows carry no
// wavelengths).
SpectralSensitivity load_database(const std::string& path, const std::string& camera) {
  const std::vector<std::string> lines = read_lines(path);
  std::size_t n = 0;
  while (n < lines.size() && text::trim(lines[n]).rfind("---", 0) != 0) ++n;
  if (n == lines.size())
    throw Error("--sensitivity '" + path +
                "' is not a camspec database (no '---------' line ending its header); give the "
                "camspec_database.txt file, or a CSV without '#CAMERA'");
  ++n;
  std::vector<std::string> names;
  auto next = [&](std::size_t& i) {
    while (i < lines.size() && text::trim(lines[i]).empty()) ++i;
    return i < lines.size();
  };
  while (next(n)) {
    const std::string name = text::trim(lines[n]);
    const int name_line = static_cast<int>(n) + 1;
    ++n;
    names.push_back(name);
    std::array<std::vector<double>, 3> rows;
    for (int c = 0; c < 3; ++c) {
      if (!next(n))
        throw Error(where(path, name_line) + ": camera '" + name + "' has " + std::to_string(c) +
                    " of its 3 rows (R, G, B)");
      const int ln = static_cast<int>(n) + 1;
      std::stringstream ss(lines[n++]);
      std::string field;
      while (ss >> field) {
        double v = 0.0;
        if (!spectral_parse_number(field, v)) throw Error(where(path, ln) + ": value '" + field + "' is not a number");
        if (v < 0.0) throw Error(where(path, ln) + ": value " + spectral_num(v) + " is negative");
        rows[c].push_back(v);
      }
      if (rows[c].size() != 33)
        throw Error(where(path, ln) + ": camera '" + name + "' row has " + std::to_string(rows[c].size()) +
                    " values; the database has 33 (400-720 nm in 10 nm steps)");
    }
    if (name != camera) continue;
    std::vector<double> wl(33);
    std::vector<std::array<double, 3>> v(33);
    for (int k = 0; k < 33; ++k) {
      wl[k] = 400.0 + 10.0 * k;
      v[k] = {rows[0][k], rows[1][k], rows[2][k]};
    }
    SpectralSensitivity s;
    s.source = path + "#" + camera;
    s.sha256 = sha256_file(path);
    s.space = SensitivitySpace::camera_rgb;
    s.q = to_grid(wl, v);
    check_channels(s);
    return s;
  }
  std::string all;
  for (const auto& nm : names) all += (all.empty() ? "" : ", ") + nm;
  throw Error("--sensitivity '" + path + "#" + camera + "': no camera named '" + camera + "' in the database; " +
              "it has: " + all);
}

}  // namespace

SpectralSensitivity load_sensitivity(const std::string& spec) {
  if (spec == "default") {
    SpectralSensitivity s;
    s.source = "default (CIE 1931 2-degree colour-matching functions, multi-lobe fit of Wyman, Sloan & Shirley, "
               "JCGT 2013)";
    s.space = SensitivitySpace::xyz;
    s.q.resize(kSensitivitySamples);
    for (int i = 0; i < kSensitivitySamples; ++i) s.q[i] = cie1931_wyman(kAerialLambdaMinNm + i);
    return s;
  }
  // FILE#CAMERA names a database entry when FILE exists; otherwise the whole
  // text is a CSV path (which may itself contain '#').
  const auto hash = spec.rfind('#');
  if (hash != std::string::npos && hash > 0) {
    const std::string file = spec.substr(0, hash);
    std::error_code ec;
    if (std::filesystem::is_regular_file(file, ec)) {
      const std::string camera = text::trim(spec.substr(hash + 1));
      if (camera.empty())
        throw Error("--sensitivity '" + spec + "': no camera name after '#'; write DATABASE.txt#CAMERA NAME");
      return load_database(file, camera);
    }
  }
  if (spec.empty())
    throw Error("--sensitivity is empty; give 'default', a CSV of wavelength_nm,r,g,b rows, or "
                "DATABASE.txt#CAMERA NAME");
  return load_csv(spec);
}

// ---- attenuation -------------------------------------------------------------------------

namespace {

// beta(l_i) and the Simpson-weighted q on the grid: the part of Gamma that
// does not depend on s, computed once per table. The normaliser is divided
// out last, after a sum in the same order as its own: Gamma(0) is then
// exactly 1, and since every term e^{-beta s} w q <= w q and rounded addition
// is monotone, Gamma <= 1 holds in floating point too.
struct Integrand {
  std::array<double, kSensitivitySamples> beta{};               // [1/m] beta_R + beta_M
  std::array<double, kSensitivitySamples> beta_r{}, beta_m{};   // [1/m] each alone (the slant path)
  std::array<std::array<double, 3>, kSensitivitySamples> wq{};  // w_i q_c(l_i)
  std::array<double, 3> norm{};                                 // sum_i w_i q_c(l_i)
};

Integrand make_integrand(const Atmosphere& a, const SpectralSensitivity& q) {
  validate_atmosphere(a);
  if (q.q.size() != static_cast<std::size_t>(kSensitivitySamples))
    throw Error("sensitivity '" + q.source + "' has " + std::to_string(q.q.size()) + " samples; expected " +
                std::to_string(kSensitivitySamples) + " (380-780 nm at 1 nm; use load_sensitivity)");
  Integrand in;
  std::array<double, 3>& norm = in.norm;
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double l = kAerialLambdaMinNm + i;
    in.beta_r[i] = rayleigh_beta_per_m(l, a.altitude_m);
    in.beta_m[i] = mie_beta_per_m(l, a.turbidity, a.altitude_m);
    in.beta[i] = in.beta_r[i] + in.beta_m[i];
    const double w = (i == 0 || i == kSensitivitySamples - 1) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    for (int c = 0; c < 3; ++c) {
      if (!(q.q[i][c] >= 0.0) || !std::isfinite(q.q[i][c]))
        throw Error("sensitivity '" + q.source + "' has value " + spectral_num(q.q[i][c]) + " at " + spectral_num(l) +
                    " nm; sensitivities are finite and >= 0");
      in.wq[i][c] = w * q.q[i][c];
      norm[c] += in.wq[i][c];
    }
  }
  for (int c = 0; c < 3; ++c) {
    if (!(norm[c] > 0.0))
      throw Error("sensitivity '" + q.source + "': channel " + std::to_string(c) +
                  " is zero everywhere in 380-780 nm, so its attenuation is undefined");
  }
  return in;
}

std::array<double, 3> gamma_at(const Integrand& in, double s_m) {
  std::array<double, 3> g{};
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double t = std::exp(-in.beta[i] * s_m);
    for (int c = 0; c < 3; ++c) g[c] += t * in.wq[i][c];
  }
  for (int c = 0; c < 3; ++c) g[c] /= in.norm[c];
  return g;
}

}  // namespace

std::array<double, 3> attenuation_direct(const Atmosphere& a, const SpectralSensitivity& q, double s_m) {
  if (!(s_m >= 0.0))
    throw Error("distance " + spectral_num(s_m) + " m is not >= 0; attenuation is defined for distances from the camera");
  return gamma_at(make_integrand(a, q), s_m);
}

AttenuationTable attenuation_table(const Atmosphere& a, const SpectralSensitivity& q, double s_max_m, int samples,
                                   int threads) {
  if (!(s_max_m > 0.0) || !std::isfinite(s_max_m))
    throw Error("attenuation table: the largest distance " + spectral_num(s_max_m) + " m must be finite and > 0");
  if (samples < 2) throw Error("attenuation table: " + std::to_string(samples) + " samples; at least 2 are needed");
  // The same integrand and sum as attenuation_direct (same order over lambda,
  // so Gamma <= 1 still holds in floating point), but e^{-beta(l) i step} by a
  // recurrence over the nodes instead of 401 exp per node:
  //   e_l(i + 1) = e_l(i) e^{-beta(l) step},
  // re-seeded with the exact exp every kReseed nodes (and at each thread's
  // first node). m products of the rounded ratio drift by <= 2 m 1.1e-16
  // relative (<= 1.4e-14 for m < 64), far below the f32 storage of ln Gamma
  // (6e-8 relative): node i holds attenuation_direct(a, q, i step) to that.
  constexpr int kReseed = 64;
  const Integrand in = make_integrand(a, q);
  AttenuationTable t;
  t.step_m = s_max_m / (samples - 1);
  t.log_gamma.resize(samples);
  std::array<double, kSensitivitySamples> ratio{};
  for (int l = 0; l < kSensitivitySamples; ++l) ratio[l] = std::exp(-in.beta[l] * t.step_m);
  // Chunks of kReseed nodes, each starting on a re-seed node: every node is
  // then the same product whatever the thread count or which thread ran it
  // (the table, and so the render, no longer depends on the team size), and a
  // preempted thread on a shared host holds up one chunk, not half the table.
#pragma omp parallel num_threads(threads > 0 ? threads : omp_get_max_threads())
  {
    std::array<double, kSensitivitySamples> e{};
    int seeded = -2;  // the node e holds, if this thread's previous node
#pragma omp for schedule(dynamic, kReseed)
    for (int i = 0; i < samples; ++i) {
      if (i == 0) {
        t.log_gamma[0] = {0.0f, 0.0f, 0.0f};  // Gamma(0) = 1 exactly
        continue;
      }
      if (seeded != i - 1 || i % kReseed == 0) {
        const double s = i * t.step_m;
        for (int l = 0; l < kSensitivitySamples; ++l) e[l] = std::exp(-in.beta[l] * s);
      } else {
        for (int l = 0; l < kSensitivitySamples; ++l) e[l] *= ratio[l];
      }
      seeded = i;
      std::array<double, 3> g{};
      for (int l = 0; l < kSensitivitySamples; ++l)
        for (int c = 0; c < 3; ++c) g[c] += e[l] * in.wq[l][c];
      for (int c = 0; c < 3; ++c) t.log_gamma[i][c] = static_cast<float>(std::log(std::max(g[c] / in.norm[c], 1e-300)));
    }
  }
  return t;
}

// ---- the slant path ---------------------------------------------------------------------

const EnumNames<AerialPath>& aerial_path_names() {
  static const EnumNames<AerialPath> n = {{AerialPath::level, "level"}, {AerialPath::slant, "slant"}};
  return n;
}

double slant_factor(double x) { return x == 0.0 ? 1.0 : -std::expm1(-x) / x; }

SlantDistances slant_distances(double s_m, double dh_m) {
  return {s_m * slant_factor(dh_m / kRayleighScaleHeightM), s_m * slant_factor(dh_m / kMieScaleHeightM)};
}

std::array<double, 3> attenuation_slant_direct(const Atmosphere& a, const SpectralSensitivity& q, double s_rayleigh_m,
                                               double s_mie_m) {
  if (!(s_rayleigh_m >= 0.0) || !(s_mie_m >= 0.0))
    throw Error("slant distances " + spectral_num(s_rayleigh_m) + " m (Rayleigh), " + spectral_num(s_mie_m) +
                " m (Mie) are not both >= 0; attenuation is defined for paths from the camera");
  const Integrand in = make_integrand(a, q);
  std::array<double, 3> g{};
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double t = std::exp(-in.beta_r[i] * s_rayleigh_m - in.beta_m[i] * s_mie_m);
    for (int c = 0; c < 3; ++c) g[c] += t * in.wq[i][c];
  }
  for (int c = 0; c < 3; ++c) g[c] /= in.norm[c];
  return g;
}

SlantAttenuationTable slant_attenuation_table(const Atmosphere& a, const SpectralSensitivity& q, double sr_max_m,
                                              double sm_max_m, int nr, int nm, int threads) {
  for (double v : {sr_max_m, sm_max_m})
    if (!(v > 0.0) || !std::isfinite(v))
      throw Error("slant attenuation table: the largest distance " + spectral_num(v) + " m must be finite and > 0");
  if (nr < 2 || nm < 2)
    throw Error("slant attenuation table: " + std::to_string(nr) + " x " + std::to_string(nm) +
                " nodes; at least 2 x 2 are needed");
  const Integrand in = make_integrand(a, q);
  SlantAttenuationTable t;
  t.nr = nr, t.nm = nm;
  t.step_r_m = sr_max_m / (nr - 1), t.step_m_m = sm_max_m / (nm - 1);
  t.log_gamma.resize(static_cast<std::size_t>(nr) * nm);
  // Node (i, j) is sum_l e^{-beta_R(l) i dr} e^{-beta_M(l) j dm} w q_c(l): the
  // Rayleigh factors of every i once (nr x 401 exp), the Mie factor of the
  // row once per row; each node is then products and sums only, in the order
  // of attenuation_slant_direct's sum (its exp of the sum differs from the
  // product of the two exps by <= 2 ulp: far below the f32 storage).
  std::vector<double> er(static_cast<std::size_t>(nr) * kSensitivitySamples);
  for (int i = 0; i < nr; ++i)
    for (int l = 0; l < kSensitivitySamples; ++l)
      er[static_cast<std::size_t>(i) * kSensitivitySamples + l] = std::exp(-in.beta_r[l] * (i * t.step_r_m));
#pragma omp parallel num_threads(threads > 0 ? threads : omp_get_max_threads())
  {
    std::array<std::array<double, 3>, kSensitivitySamples> em{};  // e^{-beta_M j dm} w q_c
#pragma omp for schedule(dynamic, 1)
    for (int j = 0; j < nm; ++j) {
      for (int l = 0; l < kSensitivitySamples; ++l) {
        const double e = std::exp(-in.beta_m[l] * (j * t.step_m_m));
        for (int c = 0; c < 3; ++c) em[l][c] = e * in.wq[l][c];
      }
      for (int i = 0; i < nr; ++i) {
        const double* r = er.data() + static_cast<std::size_t>(i) * kSensitivitySamples;
        double g0 = 0.0, g1 = 0.0, g2 = 0.0;
        for (int l = 0; l < kSensitivitySamples; ++l) {
          g0 += r[l] * em[l][0];
          g1 += r[l] * em[l][1];
          g2 += r[l] * em[l][2];
        }
        const double g[3] = {g0, g1, g2};
        std::array<float, 3>& o = t.log_gamma[static_cast<std::size_t>(j) * nr + i];
        for (int c = 0; c < 3; ++c)
          o[c] = (i == 0 && j == 0) ? 0.0f : static_cast<float>(std::log(std::max(g[c] / in.norm[c], 1e-300)));
      }
    }
  }
  return t;
}

}  // namespace brume
