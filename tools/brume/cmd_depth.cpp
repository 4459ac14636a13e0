// brume depth convert / depth prepare — every depth source to a range map,
// and the range preparation of Hansard 4.1.
#include <cstdio>

#include "brume/depth_pipeline.hpp"
#include "cli.hpp"

namespace brume::cli {

namespace {

void print_convert(const DepthConvertJob& job, const nlohmann::json& rec) {
  const auto& d = rec["depth"];
  const double w = rec["result"]["width"].get<double>(), h = rec["result"]["height"].get<double>();
  const std::size_t unknown = rec["result"]["unknown_pixels"].get<std::size_t>();
  std::fprintf(stderr, "brume depth convert: %s  %s  %.0fx%.0f  %.2f %% unknown", job.out.c_str(), job.kind.c_str(), w,
               h, w * h > 0 ? 100.0 * unknown / (w * h) : 0.0);
  if (!job.depth.velodyne.empty())
    std::fprintf(stderr, "  (lidar: %zu of %zu points in view, coverage %.2f %% of pixels)",
                 d["points_in_view"].get<std::size_t>(), d["points"].get<std::size_t>(),
                 100.0 * d["coverage"].get<double>());
  std::fprintf(stderr, "\n");
}

}  // namespace

std::vector<Command> add_depth(CLI::App& app) {
  CLI::App* depth = app.add_subcommand("depth", "depth maps: convert any depth source to range or planar z, prepare it");
  depth->require_subcommand(1);
  CLI::App* conv = depth->add_subcommand("convert", "convert a depth source to a range (or z) map in metres");
  CLI::App* prep = depth->add_subcommand("prepare", "fill holes, identify the sky and matte the horizon (Hansard 4.1)");
  return {
      job_command<DepthConvertJob>(conv, "depth convert", depth_convert_job_table(), false,
                                   [](const DepthConvertJob& job, const ExecOptions&, const RunContext& ctx) {
                                     print_convert(job, run_depth_convert_job(job, ctx));
                                     return 0;
                                   }),
      job_command<DepthPrepareJob>(
          prep, "depth prepare", depth_prepare_job_table(), false,
          [](const DepthPrepareJob& job, const ExecOptions&, const RunContext& ctx) {
            const auto p = run_depth_prepare_job(job, ctx)["prepare"];
            std::fprintf(stderr,
                         "brume depth prepare: %s  known %.1f %%, %zu holes (%.2f %%), sky %.1f %% at S_max %.4g m "
                         "(R_max %.4g m), margin %.2f %% solved to residual %.2g in %d iterations\n",
                         job.out.c_str(), 100 * p["known_fraction"].get<double>(), p["holes"].get<std::size_t>(),
                         100 * p["hole_fraction"].get<double>(), 100 * p["sky_fraction"].get<double>(),
                         p["s_max_m"].get<double>(), p["range_max_m"].get<double>(),
                         100 * p["margin_fraction"].get<double>(), p["margin_residual"].get<double>(),
                         p["solver_iterations"].get<int>());
            return 0;
          }),
  };
}

}  // namespace brume::cli
