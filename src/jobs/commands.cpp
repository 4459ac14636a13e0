// brume — the list of commands (brume/command.hpp): one line a command, in
// --help's order. A command's definition is in its own files
// (`CommandDef <name>_command()` beside its pipeline); adding a command is
// one line here and its files in CMakeLists.txt.
#include "brume/command.hpp"

#include <algorithm>
#include <sstream>

namespace brume {

// X(definition function). The order is --help's (a parent's own command, as
// aerial, before its children; haze has no subcommand of its own, haze+dof's
// is `brume haze`) and that of every list a message gives.
#define BRUME_COMMANDS(X) \
  X(haze_command) \
  X(haze_dof_command) \
  X(aerial_command) \
  X(aerial_coefficients_command) \
  X(blur_command) \
  X(depth_convert_command) \
  X(depth_prepare_command) \
  X(depth_complete_command) \
  X(depth_stereo_command) \
  X(insert_command) \
  X(fog_command) \
  X(dof_command) \
  X(rain_command) \
  X(snow_command) \
  X(wet_command) \
  X(compare_command) \
  X(sky_render_command) \
  X(sky_fit_command) \
  X(lidar_fog_command) \
  X(lidar_rain_command) \
  X(lidar_snow_command) \
  X(lidar_wet_command) \
  X(view_command)

#define BRUME_DECLARE(f) CommandDef f();
BRUME_COMMANDS(BRUME_DECLARE)
#undef BRUME_DECLARE

namespace {
// A definition with its finishing steps run (CommandDef::finish).
CommandDef finished(CommandDef c) {
  std::vector<std::function<void(CommandDef&)>> steps;
  steps.swap(c.finish);
  for (const auto& step : steps) step(c);
  return c;
}
}  // namespace

const std::vector<CommandDef>& commands() {
#define BRUME_LIST(f) finished(f()),
  static const std::vector<CommandDef> all = {BRUME_COMMANDS(BRUME_LIST)};
#undef BRUME_LIST
  return all;
}

const std::vector<CommandGroup>& command_groups() {
  static const std::vector<CommandGroup> g = {
      {"depth", "depth maps: convert any depth source to range or planar z, prepare it, complete a sparse one, match a stereo pair"},
      {"sky", "the Preetham sky: render one, or fit the turbidity of a sky photo (Morales ch. 2)"},
      {"lidar", "LiDAR scans: fog one (attenuation and fog returns, Hahner et al. 2021), rain or snow on one (drop or flake echoes, lost points) or wet its ground (weaker ground returns, lost points)"},
  };
  return g;
}

void refuse_gpu_without_passes(const CommandDef& c, Backend requested, const std::string& flag) {
  if (requested != Backend::gpu || !c.gpu_passes.empty()) return;
  throw Error(flag + " gpu: " + c.name + " runs on the CPU only (it has no GPU pass yet; those that have: " +
              command_names([](const CommandDef& d) { return !d.gpu_passes.empty(); }) + "); use " + flag +
              " cpu or auto");
}

const CommandDef* find_command(std::string_view name) {
  for (const CommandDef& c : commands())
    if (c.name == name) return &c;
  return nullptr;
}

std::string command_names(const std::function<bool(const CommandDef&)>& pred) {
  std::string all;
  for (const CommandDef& c : commands())
    if (pred(c)) all += (all.empty() ? "" : ", ") + c.name;
  return all;
}

const ParamSpec* CommandDef::spec(std::string_view param) const {
  const auto it = std::find_if(specs.begin(), specs.end(), [&](const ParamSpec& s) { return s.name == param; });
  return it == specs.end() ? nullptr : &*it;
}

std::vector<std::string> CommandDef::cli_words() const {
  std::vector<std::string> w;
  std::istringstream in(cli);
  for (std::string x; in >> x;) w.push_back(x);
  return w;
}

}  // namespace brume
