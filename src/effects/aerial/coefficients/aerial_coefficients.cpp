// brume — `brume aerial coefficients` (brume/aerial_coefficients.hpp).
#include "brume/command.hpp"
#include "brume/aerial_coefficients.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/text.hpp"
#include "effects/aerial/coefficients/coefficients_job.hpp"

namespace brume {

const ParamTable<Atmosphere>& atmosphere_param_table() {
  static const ParamTable<Atmosphere> t = [] {
    ParamTable<Atmosphere> d("atmosphere");
    d.real("turbidity", &Atmosphere::turbidity, "1", Range::closed(1.0, 20.0),
           "atmospheric turbidity T: 1 pure air, ~2 clear, ~3-4.5 light haze, ~10 haze, ~19 fog (Morales Table "
           "3.1 as corrected in docs/aerial.md)")
        .real("altitude", &Atmosphere::altitude_m, "m", Range::closed(-500.0, 9000.0),
              "observer altitude above sea level (scales beta_R by e^{-h/7994 m}, beta_M by e^{-h/1200 m})");
    return d;
  }();
  return t;
}

const ParamTable<CoefficientsJob>& coefficients_job_table() {
  static const ParamTable<CoefficientsJob> t = [] {
    ParamTable<CoefficientsJob> d("coefficients");
    d.nest(&CoefficientsJob::atmosphere, atmosphere_param_table())
        .text("sensitivity", &CoefficientsJob::sensitivity,
              "camera spectral sensitivity: 'default' (CIE 1931 x, y, z, Wyman-Sloan-Shirley fit; columns "
              "gamma_x,gamma_y,gamma_z), a CSV of wavelength_nm,r,g,b rows, or DATABASE.txt#CAMERA NAME (camspec)")
        .reads_file("default", '#')
        .text("distances", &CoefficientsJob::distances, "distances in metres, comma-separated (each >= 0)")
        .text("out", &CoefficientsJob::out,
              "CSV distance_m,gamma_r,gamma_g,gamma_b (gamma_x,gamma_y,gamma_z for the default sensitivity)")
        .text("spectrum", &CoefficientsJob::spectrum,
              "also write a CSV wavelength_nm,beta_rayleigh_per_m,beta_mie_per_m, 380..780 nm at 1 nm");
    return d;
  }();
  return t;
}

std::vector<double> parse_distances(const std::string& text) {
  std::vector<double> d;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    const auto b = item.find_first_not_of(" \t"), e = item.find_last_not_of(" \t");
    const std::string t = b == std::string::npos ? "" : item.substr(b, e - b + 1);
    char* end = nullptr;
    const double v = std::strtod(t.c_str(), &end);
    if (t.empty() || end != t.c_str() + t.size() || !std::isfinite(v) || v < 0.0)
      throw Error("--distances '" + text + "': item '" + t +
                  "' is not a finite distance >= 0 in metres; write e.g. --distances 100,1000,10000");
    d.push_back(v);
  }
  if (d.empty()) throw Error("--distances is empty; give one or more distances in metres, e.g. 100,1000,10000");
  return d;
}

namespace {
}  // namespace

std::string attenuation_csv(const Atmosphere& a, const SpectralSensitivity& q, const std::vector<double>& distances_m) {
  std::string s = q.space == SensitivitySpace::xyz ? "distance_m,gamma_x,gamma_y,gamma_z\n"
                                                   : "distance_m,gamma_r,gamma_g,gamma_b\n";
  for (double d : distances_m) {
    const auto gm = attenuation_direct(a, q, d);
    s += text::g(d, 12) + "," + text::g(gm[0], 12) + "," + text::g(gm[1], 12) + "," + text::g(gm[2], 12) + "\n";
  }
  return s;
}

std::string spectrum_csv(const Atmosphere& a) {
  validate_atmosphere(a);
  std::string s = "wavelength_nm,beta_rayleigh_per_m,beta_mie_per_m\n";
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double l = kAerialLambdaMinNm + i;
    s += text::g(l, 12) + "," + text::g(rayleigh_beta_per_m(l, a.altitude_m), 12) + "," +
         text::g(mie_beta_per_m(l, a.turbidity, a.altitude_m), 12) + "\n";
  }
  return s;
}

nlohmann::json run_coefficients_job(const CoefficientsJob& job, const RunContext&) {
  // Every check before any file is touched.
  coefficients_job_table().validate(job);
  validate_atmosphere(job.atmosphere);
  if (job.out.empty()) throw Error("no output given: use --out FILE.csv");
  std::error_code e1, e2;
  if (!job.spectrum.empty() &&
      std::filesystem::weakly_canonical(job.spectrum, e1) == std::filesystem::weakly_canonical(job.out, e2))
    throw Error("--spectrum '" + job.spectrum + "' is the same file as --out; give two different files");
  const std::vector<double> distances = parse_distances(job.distances);
  const SpectralSensitivity q = load_sensitivity(job.sensitivity);

  const std::string table = attenuation_csv(job.atmosphere, q, distances);
  OutputSet outs;
  outs.write_text(job.out, table, "--out");
  if (!job.spectrum.empty()) outs.write_text(job.spectrum, spectrum_csv(job.atmosphere), "--spectrum");
  outs.commit();

  nlohmann::json r;
  r["turbidity"] = job.atmosphere.turbidity;
  r["altitude_m"] = job.atmosphere.altitude_m;
  r["sensitivity"] = {{"source", q.source}, {"sha256", q.sha256},
                      {"space", q.space == SensitivitySpace::xyz ? "xyz" : "camera_rgb"}};
  r["columns"] = table.substr(0, table.find('\n'));
  r["rows"] = distances.size();
  r["beta_550nm_per_m"] = {{"rayleigh", rayleigh_beta_per_m(550.0, job.atmosphere.altitude_m)},
                           {"mie", mie_beta_per_m(550.0, job.atmosphere.turbidity, job.atmosphere.altitude_m)}};
  return {{"aerial coefficients", r}};
}

CommandDef aerial_coefficients_command() {
  return make_command<CoefficientsJob>({
      .name = "aerial coefficients",
      .cli = "aerial coefficients",
      .summary = "write Gamma_c(s) at given distances (distance_m,gamma_r,gamma_g,gamma_b; gamma_x,gamma_y,gamma_z for "
                 "the default CIE sensitivity) and optionally beta_R, beta_M per wavelength",
      .table = &coefficients_job_table(),
      .run = [](const CoefficientsJob& j, const ExecOptions&, const RunContext& ctx) {
        return run_coefficients_job(j, ctx);
      },
      .report = [](const CoefficientsJob& job, const nlohmann::json& result) {
        const nlohmann::json& r = result["aerial coefficients"];
        std::fprintf(stderr,
                     "brume aerial coefficients: %s  T %.4g  h0 %.4g m  beta_R(550) %.4g /km  beta_M(550) %.4g /km  "
                     "%zu rows (%s)\n",
                     job.out.c_str(), job.atmosphere.turbidity, job.atmosphere.altitude_m,
                     1e3 * r["beta_550nm_per_m"]["rayleigh"].get<double>(),
                     1e3 * r["beta_550nm_per_m"]["mie"].get<double>(), r["rows"].get<std::size_t>(),
                     r["columns"].get<std::string>().c_str());
      },
  });
}

}  // namespace brume
