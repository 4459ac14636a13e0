// brume haze — haze and fog with scattering blur (Hansard eq. 1-7).
#include <cstdio>

#include "brume/haze.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_haze(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("haze", "haze and fog with scattering blur (Hansard eq. 1-7)");
  return job_command<HazeJob>(sub, "haze", haze_job_table(), true,
                              [](const HazeJob& job, const ExecOptions& exec, const RunContext& ctx) {
                                const nlohmann::json rec = run_haze_job(job, exec, ctx);
                                const auto& d = rec["haze"]["derived"];
                                std::fprintf(stderr, "brume haze: %s  R_max %.4g m  sigma_max %.3g px  %d iterations (%s, %s)\n",
                                             job.output.out.c_str(), d["range_max_m"].get<double>(),
                                             d["sigma_max_px"].get<double>(),
                                             rec["haze"]["diffusion"]["iterations"].get<int>(),
                                             rec["haze"]["diffusion"]["scheme"].get<std::string>().c_str(),
                                             rec["execution"]["backend"].get<std::string>().c_str());
                                return 0;
                              });
}

}  // namespace brume::cli
