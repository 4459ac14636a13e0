// brume CLI — flags from parameter declarations (brume/params.hpp). A
// subcommand binds its job's table and the execution table; no flag is
// declared by hand, so flags, checks, records and `brume run` agree.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"

namespace brume::cli {

// The flags of one table on a subcommand. Values are kept as the text the
// user typed and applied after parsing, through the declaration's own parser
// and range check, so messages name the flag.
template <class P>
class Flags {
 public:
  Flags(CLI::App* app, const ParamTable<P>& table) : table_(table) {
    const P defaults{};
    for (const Param<P>& d : table.params()) {
      auto b = std::make_unique<Bound>();
      b->name = d.spec.name;
      std::string names = "--" + d.spec.name;
      for (const auto& a : d.spec.aliases) names += ",--" + a;
      if (d.spec.kind == ParamKind::boolean) {
        b->opt = app->add_flag(names, b->flag, d.spec.describe());
        b->is_flag = true;
      } else {
        b->opt = app->add_option(names, b->text, d.spec.describe())
                     ->type_name(type_name(d.spec))
                     ->default_str(d.spec.format(d.get(defaults)));
      }
      b->opt->group(group_name(d.spec.block));
      bound_.push_back(std::move(b));
    }
  }
  // Apply every given flag to p (parsed and range-checked); returns the names given.
  std::set<std::string> apply(P& p) const {
    std::set<std::string> given;
    for (const auto& b : bound_) {
      if (b->opt->count() == 0) continue;
      given.insert(b->name);
      if (b->is_flag) {
        table_.at(b->name).set(p, nlohmann::json(b->flag));
      } else {
        table_.set_text(p, b->name, b->text);
      }
    }
    return given;
  }

 private:
  struct Bound {
    std::string name, text;
    bool flag = false, is_flag = false;
    CLI::Option* opt = nullptr;
  };
  static std::string type_name(const ParamSpec& s) {
    switch (s.kind) {
      case ParamKind::real: return s.optional ? "NUM|" + s.unset_word : "NUM";
      case ParamKind::integer: return "INT";
      case ParamKind::rgb: return "R,G,B|" + s.unset_word;
      case ParamKind::choice: return "NAME";
      case ParamKind::text: return "TEXT";
      default: return "";
    }
  }
  static std::string group_name(const std::string& block) {
    if (block == "input") return "Input";
    if (block == "depth") return "Depth source and conventions";
    if (block == "prepare") return "Range preparation (Hansard 4.1)";
    if (block == "diffusion") return "Diffusion";
    if (block == "output") return "Output";
    if (block == "execution") return "Execution";
    std::string g = block;
    if (!g.empty()) g[0] = static_cast<char>(std::toupper(static_cast<unsigned char>(g[0])));
    return g + " parameters";
  }
  const ParamTable<P>& table_;
  std::vector<std::unique_ptr<Bound>> bound_;
};

// A subcommand and what it does once the command line has been parsed.
struct Command {
  CLI::App* app = nullptr;
  std::string name;  // "haze", "depth convert", ...
  std::function<int(const std::vector<std::string>& argv)> run;
};

// --timing's whole-run line on stderr, after the job: the process's start-up
// before main() (from /proc/self/stat: exec to main, at the kernel's 10 ms
// clock-tick resolution), reading the inputs, the effect, writing the
// outputs' temporaries, renaming them, and the rest (argument parsing, the
// checks, the record), from brume::run_phases().
void print_whole_run(const std::string& command);

// A subcommand running a job: its table's flags (plus the execution flags
// when with_exec), then `run(job, exec, ctx)`.
template <class Job>
Command job_command(CLI::App* app, const std::string& name, const ParamTable<Job>& table, bool with_exec,
                    std::function<int(const Job&, const ExecOptions&, const RunContext&)> run) {
  auto job = std::make_shared<Job>();
  auto exec = std::make_shared<ExecOptions>();
  auto flags = std::make_shared<Flags<Job>>(app, table);
  std::shared_ptr<Flags<ExecOptions>> eflags;
  if (with_exec) eflags = std::make_shared<Flags<ExecOptions>>(app, exec_param_table());
  return {app, name, [=](const std::vector<std::string>& argv) {
            RunContext ctx;
            ctx.argv = argv;
            ctx.given = flags->apply(*job);
            if (eflags) eflags->apply(*exec);
            const IoThreads io(exec->threads);  // --threads bounds the codecs too (0: OpenMP's count)
            const int status = run(*job, *exec, ctx);
            if (exec->timing) print_whole_run(name);
            return status;
          }};
}

// One file per subcommand registers it.
Command add_haze(CLI::App& app);
Command add_fog(CLI::App& app);
Command add_aerial(CLI::App& app);
Command add_insert(CLI::App& app);
Command add_blur(CLI::App& app);
Command add_dof(CLI::App& app);
Command add_compare(CLI::App& app);
std::vector<Command> add_depth(CLI::App& app);
Command add_run(CLI::App& app);
Command add_demo(CLI::App& app);
Command add_study(CLI::App& app);
Command add_sample(CLI::App& app);
Command add_batch(CLI::App& app);
// `brume aerial coefficients`, under the `aerial` parent subcommand.
Command add_aerial_coefficients(CLI::App* aerial);
// `brume sky render` and `brume sky fit`.
std::vector<Command> add_sky(CLI::App& app);

}  // namespace brume::cli
