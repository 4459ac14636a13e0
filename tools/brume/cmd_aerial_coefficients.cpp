// brume aerial coefficients — the spectral model's Gamma per distance and
// beta per wavelength as CSV (brume/aerial_coefficients.hpp).
#include <cstdio>

#include "brume/aerial_coefficients.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_aerial_coefficients(CLI::App* aerial) {
  CLI::App* sub = aerial->add_subcommand(
      "coefficients",
      "write Gamma_c(s) at given distances (distance_m,gamma_r,gamma_g,gamma_b; gamma_x,gamma_y,gamma_z for the "
      "default CIE sensitivity) and optionally beta_R, beta_M per wavelength");
  return job_command<CoefficientsJob>(
      sub, "aerial coefficients", coefficients_job_table(), false,
      [](const CoefficientsJob& job, const ExecOptions&, const RunContext& ctx) {
        const nlohmann::json r = run_coefficients_job(job, ctx)["aerial coefficients"];
        std::fprintf(stderr, "brume aerial coefficients: %s  T %.4g  h0 %.4g m  beta_R(550) %.4g /km  beta_M(550) %.4g /km  %zu rows (%s)\n",
                     job.out.c_str(), job.atmosphere.turbidity, job.atmosphere.altitude_m,
                     1e3 * r["beta_550nm_per_m"]["rayleigh"].get<double>(),
                     1e3 * r["beta_550nm_per_m"]["mie"].get<double>(), r["rows"].get<std::size_t>(),
                     r["columns"].get<std::string>().c_str());
        return 0;
      });
}

}  // namespace brume::cli
