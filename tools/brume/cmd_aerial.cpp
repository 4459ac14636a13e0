// brume aerial — spectral aerial perspective from turbidity (Morales eq. 3.11-3.13):
// render, re-render (--from-turbidity) or remove (--remove), with the optional
// per-channel scattering blur (--lambda).
#include <cstdio>

#include "brume/aerial.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_aerial(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "aerial", "spectral aerial perspective from turbidity: render, re-render, remove (Morales eq. 3.11-3.13)");
  // `brume aerial coefficients` is a subcommand of this one; without it,
  // `brume aerial` runs itself.
  sub->require_subcommand(0, 1);
  return job_command<AerialJob>(sub, "aerial", aerial_job_table(), true,
                                [](const AerialJob& job, const ExecOptions& exec, const RunContext& ctx) {
                                  const nlohmann::json rec = run_aerial_job(job, exec, ctx);
                                  const auto& d = rec["aerial"]["derived"];
                                  const auto& g = d["gamma_at"]["1000_m"];
                                  std::fprintf(stderr,
                                               "brume aerial: %s  %s  R_max %.4g m  Gamma(1 km) %.4f %.4f %.4f  "
                                               "sigma_max %.3g px (%s)\n",
                                               job.output.out.c_str(), d["mode"].get<std::string>().c_str(),
                                               d["range_max_m"].get<double>(), g[0].get<double>(), g[1].get<double>(),
                                               g[2].get<double>(), d["sigma_max_px"].get<double>(),
                                               rec["execution"]["backend"].get<std::string>().c_str());
                                  return 0;
                                });
}

}  // namespace brume::cli
