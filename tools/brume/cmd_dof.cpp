// brume dof — depth of field by leak-free diffusion (Bertalmio et al. eq. 1-2, 16).
#include <cstdio>

#include "brume/dof.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_dof(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("dof", "depth of field by leak-free diffusion (thin-lens CoC, Bertalmio eq. 1-2, 16)");
  return job_command<DofJob>(sub, "dof", dof_job_table(), true,
                             [](const DofJob& job, const ExecOptions& exec, const RunContext& ctx) {
                               const nlohmann::json rec = run_dof_job(job, exec, ctx);
                               const auto& d = rec["dof"]["derived"];
                               std::fprintf(stderr,
                                            "brume dof: %s  CoC at infinity %.3g px  sigma_max %.3g px (%zu capped)  "
                                            "%d iterations (%s, %s)\n",
                                            job.output.out.c_str(), d["coc_infinity_px"].get<double>(),
                                            d["sigma_max_px"].get<double>(), d["capped_pixels"].get<std::size_t>(),
                                            rec["dof"]["diffusion"]["iterations"].get<int>(),
                                            rec["dof"]["diffusion"]["dof_scheme"].get<std::string>().c_str(),
                                            rec["execution"]["backend"].get<std::string>().c_str());
                               return 0;
                             });
}

}  // namespace brume::cli
