// brume haze — haze and fog with scattering blur (Hansard eq. 1-7), and with
// any --dof-... flag the chain haze then depth of field (brume/chain.hpp).
#include <cstdio>

#include "brume/chain.hpp"
#include "brume/haze.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_haze(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "haze", "haze and fog with scattering blur (Hansard eq. 1-7); any --dof-... flag adds depth of field after it");
  return job_command<HazeDofJob>(
      sub, "haze", haze_dof_job_table(), true, [](const HazeDofJob& job, const ExecOptions& exec, const RunContext& ctx) {
        // A DOF flag given enables the DOF stage; without one the run, its
        // record and `brume run` are plain haze's.
        const bool chain = dof_stage_requested(ctx.given);
        const nlohmann::json rec =
            chain ? run_haze_dof_job(job, exec, ctx) : run_haze_job(haze_part(job, ctx.given), exec, ctx);
        const auto& d = rec["haze"]["derived"];
        std::fprintf(stderr, "brume haze: %s  R_max %.4g m  sigma_max %.3g px  %d iterations (%s, %s)\n",
                     job.output.out.c_str(), d["range_max_m"].get<double>(), d["sigma_max_px"].get<double>(),
                     rec["haze"]["diffusion"]["iterations"].get<int>(),
                     rec["haze"]["diffusion"]["scheme"].get<std::string>().c_str(),
                     rec["execution"]["backend"].get<std::string>().c_str());
        if (chain) {
          const auto& f = rec["dof"]["derived"];
          std::fprintf(stderr, "  then dof: CoC at infinity %.3g px  sigma_max %.3g px (%zu capped)  %d iterations (%s)\n",
                       f["coc_infinity_px"].get<double>(), f["sigma_max_px"].get<double>(),
                       f["capped_pixels"].get<std::size_t>(), rec["dof"]["diffusion"]["iterations"].get<int>(),
                       rec["dof"]["diffusion"]["dof_scheme"].get<std::string>().c_str());
        }
        return 0;
      });
}

}  // namespace brume::cli
