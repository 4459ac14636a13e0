// brume blur — the diffusion engine alone: Gaussian or space-variant blur.
#include <cstdio>

#include "brume/blur.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_blur(CLI::App& app) {
  CLI::App* sub = app.add_subcommand("blur", "the diffusion engine alone: Gaussian or space-variant blur");
  return job_command<BlurJob>(sub, "blur", blur_job_table(), true,
                              [](const BlurJob& job, const ExecOptions& exec, const RunContext& ctx) {
                                const nlohmann::json rec = run_blur_job(job, exec, ctx);
                                std::fprintf(stderr, "brume blur: %s  sigma_max %.3g px  %d iterations (%s, %s)\n",
                                             job.output.out.c_str(), rec["diffusion"]["sigma_max_px"].get<double>(),
                                             rec["diffusion"]["iterations"].get<int>(),
                                             rec["diffusion"]["scheme"].get<std::string>().c_str(),
                                             rec["diffusion"]["precision"].get<std::string>().c_str());
                                return 0;
                              });
}

}  // namespace brume::cli
