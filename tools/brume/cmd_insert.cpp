// brume insert — a virtual object (RGBA + its range) composited into a photo
// with aerial perspective for the object's own range (Morales ch. 4), depth-
// tested against the scene, with the optional scattering blur (--lambda).
#include <cstdio>

#include "brume/insert.hpp"
#include "cli.hpp"

namespace brume::cli {

Command add_insert(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "insert", "insert a virtual object (RGBA + range) into a photo with aerial perspective at its own range");
  return job_command<InsertJob>(sub, "insert", insert_job_table(), true,
                                [](const InsertJob& job, const ExecOptions& exec, const RunContext& ctx) {
                                  const nlohmann::json rec = run_insert_job(job, exec, ctx);
                                  const auto& d = rec["insert"]["derived"];
                                  const auto& g = d["gamma_at"]["1000_m"];
                                  std::fprintf(stderr,
                                               "brume insert: %s  object %zu px: %zu visible, %zu hidden  "
                                               "range %.4g..%.4g m  Gamma(1 km) %.4f %.4f %.4f  sigma_max %.3g px\n",
                                               job.output.out.c_str(), d["object_pixels"].get<std::size_t>(),
                                               d["visible_pixels"].get<std::size_t>(),
                                               d["hidden_pixels"].get<std::size_t>(),
                                               d["object_range_min_m"].get<double>(),
                                               d["object_range_max_m"].get<double>(), g[0].get<double>(),
                                               g[1].get<double>(), g[2].get<double>(),
                                               d["sigma_max_px"].get<double>());
                                  return 0;
                                });
}

}  // namespace brume::cli
