// brume — command-line tool: one subcommand per command of the library's
// list (brume/command.hpp; cmd_commands.cpp binds them) and one file per tool
// around them (run, demo, study, sample, batch). The flags come from the
// parameter declarations (brume/params.hpp, bound in cli.hpp); this file only
// parses and reports errors.
//
// Errors name the file or flag, the value, what is allowed and the fix; the
// exit status is 2 (3 for an internal error) and no output file is left behind.
#include <CLI/CLI.hpp>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <new>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "cli.hpp"

namespace {
const auto g_main_entry = std::chrono::steady_clock::now();  // set before main() by static initialisation

// Seconds from the process's exec to now, or -1: /proc/self/stat's field 22
// (start time in clock ticks since boot) against CLOCK_BOOTTIME.
double seconds_since_exec() {
  std::ifstream f("/proc/self/stat");
  std::string stat((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const auto close = stat.rfind(')');  // the command name may hold spaces
  if (close == std::string::npos) return -1.0;
  std::istringstream rest(stat.substr(close + 2));
  std::string field;
  unsigned long long start = 0;
  for (int i = 3; i <= 22 && rest >> field; ++i)
    if (i == 22) start = std::stoull(field);
  timespec now{};
  if (start == 0 || clock_gettime(CLOCK_BOOTTIME, &now) != 0) return -1.0;
  const double s = static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec) -
                   static_cast<double>(start) / static_cast<double>(sysconf(_SC_CLK_TCK));
  return s >= 0.0 && s < 3600.0 ? s : -1.0;
}
}  // namespace

namespace brume::cli {
void print_whole_run(const std::string& command) {
  using clock = std::chrono::steady_clock;
  const clock::time_point now = clock::now();
  const double since_main = std::chrono::duration<double, std::milli>(now - g_main_entry).count();
  const double since_exec = seconds_since_exec() * 1000.0;
  const double startup = since_exec > since_main ? since_exec - since_main : -1.0;
  const RunPhases& p = run_phases();
  const double effect = p.write_begin > p.read_end && p.read_end != clock::time_point{}
                            ? std::chrono::duration<double, std::milli>(p.write_begin - p.read_end).count()
                            : 0.0;
  const double rest = since_main - p.read_ms - effect - p.write_ms - p.rename_ms;
  std::string s = "brume " + command + ": whole run ";
  char b[256];
  std::snprintf(b, sizeof b, "%.0f ms: ", (startup >= 0.0 ? startup : 0.0) + since_main);
  s += b;
  if (startup >= 0.0) {
    std::snprintf(b, sizeof b, "start-up %.0f ms (exec to main, 10 ms ticks), ", startup);
    s += b;
  }
  std::snprintf(b, sizeof b,
                "read %.1f ms (decode, depth conversion), effect %.1f ms, write %.1f ms (encode to temporaries), "
                "rename %.2f ms, other %.1f ms (parsing, checks, record)",
                p.read_ms, effect, p.write_ms, p.rename_ms, rest);
  s += b;
  if (p.codec_load_ms > 0.0) {
    // Inside the read or write that first needed a codec (src/io/codec.hpp).
    std::snprintf(b, sizeof b, "; of which loading the OpenImageIO codec module %.0f ms", p.codec_load_ms);
    s += b;
  }
  std::fprintf(stderr, "%s\n", s.c_str());
}
}  // namespace brume::cli

int main(int argc, char** argv) {
  using namespace brume::cli;
  (void)g_main_entry;
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
  brume::keep_freed_heap();  // a run frees and allocates image-sized buffers: reuse them (pipeline.hpp)

  // Every command of the list (brume/command.hpp), then the tools around them.
  std::vector<Command> commands = add_commands(app);
  for (auto add : {add_run, add_demo, add_study, add_sample, add_batch, add_reference}) commands.push_back(add(app));
  // A parsed subcommand marks its parent parsed too (`aerial coefficients`
  // parses `aerial`): the command asked for is the deepest one parsed.
  std::stable_sort(commands.begin(), commands.end(), [](const Command& a, const Command& b) {
    return std::count(a.name.begin(), a.name.end(), ' ') > std::count(b.name.begin(), b.name.end(), ' ');
  });

  // Every argument goes into the run's record (JSON, UTF-8 only): refuse one
  // that is not UTF-8 before any work, naming it, instead of failing at the
  // record after the effect has run.
  for (int i = 1; i < argc; ++i) {
    try {
      const bool after_flag = i > 1 && argv[i - 1][0] == '-';
      brume::check_utf8(argv[i], "argument " + std::to_string(i) +
                                     (after_flag ? std::string(" (after ") + argv[i - 1] + ")" : std::string()));
    } catch (const brume::Error& e) {
      std::fprintf(stderr, "brume: error: %s\n", e.what());
      return 2;
    }
  }
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
    } catch (const std::bad_alloc&) {
      // Memory is checked before work; another process can still take it.
      std::fprintf(stderr, "brume %s: error: %s\n", c.name.c_str(), brume::out_of_memory_message().c_str());
      return 2;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "brume %s: internal error: %s\n", c.name.c_str(), brume::printable_text(e.what()).c_str());
      return 3;
    }
  }
  return 0;
}
