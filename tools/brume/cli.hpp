// brume CLI — flags from parameter declarations (brume/params.hpp). A
// command's subcommand binds its job's declarations and the execution table;
// no flag is declared by hand, so flags, checks, records and `brume run`
// agree.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "brume/command.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"

namespace brume::cli {

// The flags of a list of declarations on a subcommand. Values are kept as
// the text the user typed and parsed after parsing, through the
// declaration's own parser and range check, so messages name the flag.
class SpecFlags {
 public:
  // `defaults`: the table's JSON of a default job (for --help's defaults).
  SpecFlags(CLI::App* app, const std::vector<ParamSpec>& specs, const nlohmann::json& defaults) {
    for (const ParamSpec& s : specs) {
      auto b = std::make_unique<Bound>();
      b->spec = s;
      std::string names = "--" + s.name;
      for (const auto& a : s.aliases) names += ",--" + a;
      if (s.kind == ParamKind::boolean) {
        b->opt = app->add_flag(names, b->flag, s.describe());
        b->is_flag = true;
      } else {
        b->opt = app->add_option(names, b->text, s.describe())
                     ->type_name(type_name(s))
                     ->default_str(s.format(defaults.at(s.block).at(s.name)));
      }
      b->opt->group(group_name(s.block));
      bound_.push_back(std::move(b));
    }
  }
  // Every given flag's value (parsed and range-checked), in declaration order.
  JobValues values() const {
    JobValues v;
    for (const auto& b : bound_) {
      if (b->opt->count() == 0) continue;
      if (b->is_flag) {
        v.emplace_back(b->spec.name, nlohmann::json(b->flag));
      } else {
        nlohmann::json x = b->spec.parse(b->text);
        b->spec.check(x);
        v.emplace_back(b->spec.name, std::move(x));
      }
    }
    return v;
  }

 private:
  struct Bound {
    ParamSpec spec;
    std::string text;
    bool flag = false, is_flag = false;
    CLI::Option* opt = nullptr;
  };
  static std::string type_name(const ParamSpec& s) {
    switch (s.kind) {
      case ParamKind::real: return s.optional ? "NUM|" + s.unset_word : "NUM";
      case ParamKind::integer: return "INT";
      case ParamKind::rgb: return "R,G,B|" + s.unset_word;
      case ParamKind::pair: return "X,Y";
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
  std::vector<std::unique_ptr<Bound>> bound_;
};

// The same on one table's struct (the execution flags of run and batch).
template <class P>
class Flags {
 public:
  Flags(CLI::App* app, const ParamTable<P>& table)
      : table_(table), flags_(app, specs_of(table), table.to_json(P{})) {}
  // Apply every given flag to p; returns the names given.
  std::set<std::string> apply(P& p) const {
    std::set<std::string> given;
    for (const auto& [name, v] : flags_.values()) {
      table_.at(name).set(p, v);
      given.insert(name);
    }
    return given;
  }

 private:
  static std::vector<ParamSpec> specs_of(const ParamTable<P>& t) {
    std::vector<ParamSpec> s;
    for (const Param<P>& d : t.params()) s.push_back(d.spec);
    return s;
  }
  const ParamTable<P>& table_;
  SpecFlags flags_;
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

// Every command of the list (brume/command.hpp) as a subcommand: its
// table's flags (plus the execution flags when it takes them), then its
// run and its summary line. Parents that are not commands themselves
// (depth, sky) are made on the way.
std::vector<Command> add_commands(CLI::App& app);

// The tools around the commands, one file each.
Command add_run(CLI::App& app);
Command add_demo(CLI::App& app);
Command add_study(CLI::App& app);
Command add_sample(CLI::App& app);
Command add_batch(CLI::App& app);
// `brume reference --out-dir docs/cli` (hidden): the command-line reference as Markdown.
Command add_reference(CLI::App& app);

}  // namespace brume::cli
