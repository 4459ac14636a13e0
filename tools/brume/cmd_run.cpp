// brume run — repeat a run from its parameter record.
#include <cstdio>
#include <fstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/rerun.hpp"
#include "cli.hpp"
#include "brume_study/sky_plot.hpp"

namespace brume::cli {

Command add_run(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "run", "repeat the run a parameter record describes (the --record FILE.json of " +
                 command_names([](const CommandDef& c) { return c.writes_record; }) + "; a sky fit's JSON)");
  auto path = std::make_shared<std::string>();
  auto out_dir = std::make_shared<std::string>();
  sub->add_option("record", *path, "the JSON record (or a record embedded in nothing else: the file itself)")->required();
  sub->add_option("--out-dir", *out_dir, "write every output into this directory under its recorded file name "
                                         "(default: the recorded paths)");
  auto rehash = std::make_shared<bool>(false);
  sub->add_flag("--rehash", *rehash,
                "run a record that lacks the SHA-256 of a file its job reads (deleted, or edited out) on the file as it "
                "is now, with a warning; without it such a record is refused");
  auto exec = std::make_shared<ExecOptions>();
  auto eflags = std::make_shared<Flags<ExecOptions>>(sub, exec_param_table());
  return {sub, "run", [=](const std::vector<std::string>& argv) {
            eflags->apply(*exec);
            // A regular file (brume/io.hpp) of at most 64 MiB: a record is a
            // few kB (a batch frame's ~10 kB), a sky fit's JSON with its
            // samples tens of kB.
            const std::string text = read_input_file(*path, "record", {64u << 20, "a record is a few kB of JSON"});
            nlohmann::json rec;
            try {
              rec = nlohmann::json::parse(text);
            } catch (const nlohmann::json::exception& e) {
              throw Error("record '" + *path + "' is not JSON: " + e.what());
            }
            const IoThreads io(exec->threads);
            RerunInputs ri;
            ri.rehash = *rehash;
            ri.warn = [](const std::string& w) { std::fprintf(stderr, "brume run: warning: %s\n", w.c_str()); };
            const nlohmann::json out = rerun(rec, *exec, *out_dir, argv, &brume::study::sky_fit_scatter, ri);
            std::fprintf(stderr, "brume run: repeated '%s' from %s\n", out.value("command", "?").c_str(), path->c_str());
            return 0;
          }};
}

}  // namespace brume::cli
