// brume — command-line tool: one subcommand per effect, one file per
// subcommand (cmd_*.cpp). The flags of every effect come from its parameter
// declarations (brume/params.hpp, bound in cli.hpp) and each subcommand calls
// its library pipeline; this file only parses and reports errors.
//
// Errors name the file or flag, the value, what is allowed and the fix; the
// exit status is 2 (3 for an internal error) and no output file is left behind.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "cli.hpp"

int main(int argc, char** argv) {
  using namespace brume::cli;
  const std::vector<std::string> args(argv, argv + argc);
  CLI::App app{"brume: physically based, depth-aware haze, fog and lens effects for RGB-D images"};
  app.set_version_flag("--version", std::string("brume ") + BRUME_VERSION);
  app.require_subcommand(1);
  // Process limits, not effect parameters (they change no output, so no record
  // holds them): accepted before or after the subcommand.
  app.fallthrough();
  double max_pixels = static_cast<double>(brume::default_max_pixels);
  app.add_option("--max-pixels", max_pixels,
                 "largest image or depth map read, in pixels (width x height); a header declaring more is refused "
                 "before any allocation")
      ->default_str("500000000")
      ->check(CLI::Range(1.0, 1e12));
  brume::install_output_signal_handlers();

  // A parsed subcommand marks its parent parsed too: `aerial coefficients`
  // comes before `aerial` so that the first parsed command is the one asked for.
  Command aerial = add_aerial(app);
  std::vector<Command> commands = {add_haze(app), add_aerial_coefficients(aerial.app), aerial, add_blur(app)};
  for (Command& c : add_depth(app)) commands.push_back(std::move(c));
  commands.push_back(add_insert(app));
  commands.push_back(add_fog(app));
  commands.push_back(add_dof(app));
  commands.push_back(add_compare(app));
  for (Command& c : add_sky(app)) commands.push_back(std::move(c));
  commands.push_back(add_run(app));
  commands.push_back(add_demo(app));
  commands.push_back(add_study(app));
  commands.push_back(add_sample(app));
  commands.push_back(add_batch(app));

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  brume::set_max_pixels(static_cast<std::uint64_t>(max_pixels));
  for (const Command& c : commands) {
    if (!c.app->parsed()) continue;
    try {
      return c.run(args);
    } catch (const brume::Error& e) {
      std::fprintf(stderr, "brume %s: error: %s\n", c.name.c_str(), e.what());
      return 2;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "brume %s: internal error: %s\n", c.name.c_str(), e.what());
      return 3;
    }
  }
  return 0;
}
