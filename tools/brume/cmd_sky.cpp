// brume sky — the Preetham sky: `brume sky render` (a sky image from T and the
// sun) and `brume sky fit` (T from a photo of the sky, Morales ch. 2).
#include <cstdio>

#include "brume/sky.hpp"
#include "cli.hpp"
#include "brume_study/sky_plot.hpp"

namespace brume::cli {


std::vector<Command> add_sky(CLI::App& app) {
  CLI::App* sky = app.add_subcommand("sky", "the Preetham sky: render one, or fit the turbidity of a sky photo (Morales ch. 2)");
  sky->require_subcommand(1);
  CLI::App* render = sky->add_subcommand("render", "render a Preetham sky (linear sRGB, kcd/m^2) for a turbidity and a sun");
  CLI::App* fit = sky->add_subcommand("fit", "estimate the turbidity of a sky photo (RANSAC + Levenberg-Marquardt), JSON out");
  std::vector<Command> c;
  c.push_back(job_command<SkyRenderJob>(render, "sky render", sky_render_job_table(), true,
                                        [](const SkyRenderJob& job, const ExecOptions& exec, const RunContext& ctx) {
                                          const nlohmann::json rec = run_sky_render_job(job, exec, ctx);
                                          const auto& s = rec["sky"]["sun"];
                                          std::fprintf(stderr, "brume sky render: %s  T %.4g  sun zenith %.3f azimuth %.3f (%s)\n",
                                                       job.output.out.c_str(), job.sky.turbidity,
                                                       s["zenith_deg"].get<double>(), s["azimuth_deg"].get<double>(),
                                                       s["source"].get<std::string>().c_str());
                                          return 0;
                                        }));
  c.push_back(job_command<SkyFitJob>(fit, "sky fit", sky_fit_job_table(), false,
                                     [](const SkyFitJob& job, const ExecOptions&, const RunContext& ctx) {
                                       const nlohmann::json j = run_sky_fit_job(job, ctx, &brume::study::sky_fit_scatter);
                                       // The result is this command's product: stdout.
                                       std::printf("turbidity %.4f  spread %.4f  sun zenith %.3f azimuth %.3f (%s)  "
                                                   "inliers %.0f %%  residual %.4f  %s\n",
                                                   j["turbidity"].get<double>(), j["turbidity_spread"].get<double>(),
                                                   j["sun"]["zenith_deg"].get<double>(), j["sun"]["azimuth_deg"].get<double>(),
                                                   j["sun"]["source"].get<std::string>().c_str(),
                                                   100 * j["inlier_fraction"].get<double>(), j["residual"].get<double>(),
                                                   j["reliable"].get<bool>() ? "reliable" : "UNRELIABLE");
                                       for (const auto& w : j["unreliable_because"])
                                         std::printf("  unreliable: %s\n", w.get<std::string>().c_str());
                                       return 0;
                                     }));
  return c;
}

}  // namespace brume::cli
