// brume <command> — every command of the list (brume/command.hpp) as a
// subcommand. Nothing here names a command: the flags come from its job
// table, the run and the summary line from its definition.
#include <array>
#include <memory>

#include "brume_study/sky_plot.hpp"
#include "cli.hpp"

namespace brume::cli {

namespace {

std::string group_summary(const std::string& name) {
  for (const CommandGroup& g : command_groups())
    if (g.name == name) return g.summary;
  return "";
}

// The subcommand for the words of `path`, made (with its parents) when new.
CLI::App* subcommand_at(CLI::App& app, const std::vector<std::string>& path, const std::string& summary) {
  CLI::App* parent = &app;
  for (std::size_t i = 0; i < path.size(); ++i) {
    const bool last = i + 1 == path.size();
    CLI::App* sub = nullptr;
    for (CLI::App* s : parent->get_subcommands([](CLI::App*) { return true; }))
      if (s->get_name() == path[i]) sub = s;
    if (!sub) {
      sub = parent->add_subcommand(path[i], last ? summary : group_summary(path[i]));
      // A group (depth, sky) needs one of its commands.
      if (!last) sub->require_subcommand(1);
    } else if (!last) {
      // A command that is also a parent (aerial, aerial coefficients) runs itself without a child.
      if (sub->get_require_subcommand_min() == 0) sub->require_subcommand(0, 1);
    }
    parent = sub;
  }
  return parent;
}

}  // namespace

std::vector<Command> add_commands(CLI::App& app) {
  std::vector<Command> out;
  for (const CommandDef& c : commands()) {
    if (c.cli.empty()) continue;
    CLI::App* sub = subcommand_at(app, c.cli_words(), c.summary);
    auto flags = std::make_shared<SpecFlags>(sub, c.specs, c.defaults);
    std::shared_ptr<Flags<ExecOptions>> eflags;
    if (c.takes_exec_flags) eflags = std::make_shared<Flags<ExecOptions>>(sub, exec_param_table());
    const CommandDef* def = &c;
    // An image command without the LiDAR block (brume/lidar_camera.hpp) says
    // why it takes no --lidar, instead of CLI11's "not expected".
    auto no_lidar = std::make_shared<std::array<std::string, 2>>();
    if (c.takes_exec_flags && c.writes_record && !c.spec("lidar")) {
      sub->add_option("--lidar", (*no_lidar)[0])->group("");
      sub->add_option("--lidar-out", (*no_lidar)[1])->group("");
    }
    out.push_back({sub, c.cli, [def, flags, eflags, no_lidar](const std::vector<std::string>& argv) {
                     if (!(*no_lidar)[0].empty() || !(*no_lidar)[1].empty())
                       throw Error("--lidar: brume " + def->cli + " does not fog a LiDAR scan: only an effect whose "
                                   "output is the scene the scan saw, through a medium, has an extinction to fog it "
                                   "with (" + command_names([](const CommandDef& d) { return d.spec("lidar") != nullptr; }) +
                                   "); depth of field and blur model no medium, insert adds an object the scan "
                                   "lacks. Fog the scan with `brume lidar fog --points IN.bin --alpha A` or one of those");
                     RunContext ctx;
                     ctx.argv = argv;
                     ctx.plot = &brume::study::sky_fit_scatter;  // sky fit's --plot
                     const JobValues values = flags->values();
                     for (const auto& [name, v] : values) ctx.given.insert(name);
                     const nlohmann::json job = def->build(values);
                     ExecOptions exec;
                     if (eflags) eflags->apply(exec);
                     refuse_gpu_without_passes(*def, exec.backend, "--backend");
                     const IoThreads io(exec.threads);  // --threads bounds the codecs too (0: OpenMP's count)
                     const nlohmann::json result = def->cli_run ? def->cli_run(job, exec, ctx) : def->run(job, exec, ctx);
                     if (def->report) def->report(job, result);
                     if (exec.timing) print_whole_run(def->cli);
                     return 0;
                   }});
  }
  return out;
}

}  // namespace brume::cli
