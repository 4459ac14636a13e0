// brume fog — layered fog from a depth buffer (Zhou, Chen, Smith), with the
// optional scattering blur of haze.
#include <cstdio>

#include "brume/fog.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_fog(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("fog", "layered fog: height densities integrated along each pixel's ray "
                                            "(Zhou, Chen, Smith), optional scattering blur");
  return job_command<FogJob>(sub, "fog", fog_job_table(), true,
                             [](const FogJob& job, const ExecOptions& exec, const RunContext& ctx) {
                               const nlohmann::json rec = run_fog_job(job, exec, ctx);
                               const auto& d = rec["fog"]["derived"];
                               std::fprintf(stderr, "brume fog: %s  R_max %.4g m  sky distance %.4g m  sigma_max %.3g px (%s)\n",
                                            job.output.out.c_str(), d["range_max_m"].get<double>(),
                                            d["sky_distance_m"].get<double>(), d["sigma_max_px"].get<double>(),
                                            rec["execution"]["backend"].get<std::string>().c_str());
                               return 0;
                             });
}

}  // namespace brume::cli
