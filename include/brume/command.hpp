// brume — the one list of commands (issue #37).
//
// A command is a job table (brume/params.hpp: its flags, checks, record and
// Python keywords) and what is done with a job of it. Everything that joins
// commands together walks one list, commands(), and names no effect:
//
//   commands() ──► brume --help, the subcommands and their flags (tools/brume)
//              ──► check_record / brume run (a record's "command" looked up)
//              ──► brume batch (batchable ones), brume sample / random_params (sampleable ones)
//              ──► the Python module's list of commands, the generated reference
//
// Each command's definition lives in its own pipeline file (haze's in
// src/effects/haze/haze_pipeline.cpp: `CommandDef haze_command()`), built with
// make_command below; the list itself is one line per command in
// src/jobs/commands.cpp, an explicit list rather than self-registering statics
// (libbrume.a is static: the linker drops objects nothing references).
//
// Jobs travel type-erased as their table's JSON ({"block": {"name": value}},
// ParamTable::to_json): exact for every value (doubles stay doubles), so a job
// built from flags, a record or a manifest row runs bit for bit as the typed
// job would.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"
#include "brume/preview.hpp"

namespace brume {

struct HeightMedium;  // brume/height_profile.hpp: the media layer

// A default plausible distribution of one sampled parameter (brume/sample.hpp):
// its canonical name, the spec text, and the parameters whose explicit
// value drops it (haze's visibility when kappa-s is given): "name" drops it
// whatever the value, "name=v" when name is given as the fixed value v,
// "name!=v" when it is given as anything else (fog's falloff with a profile
// other than exponential).
struct SampleDefault {
  std::string name, spec;
  std::vector<std::string> dropped_by;
};

// How a command's parameters are sampled: the effect's own block (the names
// random_params returns), the default ranges, and the effect's cross-field
// check of a drawn set ({canonical name: value} applied to default parameters).
struct CommandSampling {
  std::vector<ParamSpec> specs;
  std::vector<SampleDefault> defaults;
  std::function<void(const nlohmann::json& values)> validate;
};

using JobValues = std::vector<std::pair<std::string, nlohmann::json>>;

// ---- a command on arrays: the Python module's brume.<function>(rgb, range, **keywords) ----
// The keywords of an array form: the effect's parameters and the shared
// blocks it takes (no files: the arrays stand for the input, the Result for
// the outputs).
template <class P>
struct ArrayCall {
  P p;
  RangeStep prepare;
  DepthSource depth;  // intrinsics only (fog, dof): fx, fy, cx, cy, fov-x, fov-y, calib
  SceneScale scene;   // --scene-scale (haze, fog, dof)
  ExecOptions exec;
};
enum ArrayBlocks : unsigned {
  kArrayNone = 0,
  kArrayPrepare = 1,
  kArrayIntrinsics = 2,
  kArrayExec = 4,
  kArrayScene = 8
};
// The call's table: `own` (less `skip`) with the blocks asked for.
template <class P>
ParamTable<ArrayCall<P>> array_call_table(const ParamTable<P>& own, unsigned blocks,
                                          const std::set<std::string>& skip = {});

// An array argument of an array form (brume.haze(rgb, range)): its name,
// its channels (3: colour, read with the transfer= keyword when integer; 1: a
// map), whether it may be None, how the run reads it, whether it is a
// keyword rather than positional (brume.haze(rgb, range, lidar=points): after
// the positional ones, optional), and whether it is a LiDAR scan: an (N, 4)
// array of x, y, z, intensity (KITTI's layout), read as an N x 4 map.
struct ArrayArg {
  enum class As { view, dense, image };  // a strided view in place; dense (in place when C-contiguous); an owned Image
  std::string name;
  int channels = 1;
  bool optional = false;
  As as = As::view;
  bool keyword = false;
  bool points = false;
  // A mask (brume.wet's ground_mask=): an H x W bool array or a float one
  // whose values above 1/2 mark it, taken as an owned Image of 0 and 1 (As::image).
  bool mask = false;
};
// One array as the run gets it, filled as its ArrayArg asks: `view` always,
// `dense` for As::dense, `image` (the call's own copy, free to change) for
// As::image; `present` false for an optional one not given; `integer` for a
// uint8/uint16 array (its counts were decoded by the transfer keyword).
struct ArrayIn {
  bool present = false;
  bool integer = false;
  ConstImageView view;
  DenseImageRef dense;
  Image* image = nullptr;
};
struct ArrayResult {
  std::map<std::string, Image> images;  // the Result's arrays by field (empty Image: None)
  nlohmann::json record;                 // the run's blocks; "inputs" (files it read) and a "sky_image" block go
                                         // under the record's "inputs"
  nlohmann::json job;                    // the call as recorded (less the execution block)
  nlohmann::json more = nlohmann::json::object();  // the Result's other fields (sky fit's turbidity, fit)
  // Its 1-D uint8 arrays by field (a scan's point labels). Last: the effects
  // build a Result positionally ({images, record, job, more}).
  std::map<std::string, std::vector<std::uint8_t>> bytes = {};
};
// A scan's array form (brume.lidar.wet; rain's may follow): `points` an (N, 4) float32 view (read in
// place when dense, brume/medium.hpp's scan_points, refused naming `what` otherwise); `run`(src, out, n,
// labels) writes the points that return into out, in input order, one label per input point, and
// answers how many were lost; the Result's "points" ((K, 4)) and "labels" (N bytes).
ArrayResult scan_array_result(const ConstImageView& points, const std::string& what,
                              const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*)>& run);
struct ArrayForm {
  std::string function;            // the module's name (haze, depth_convert)
  std::string public_name;         // as users call it (brume.haze, brume.depth.convert)
  std::string summary;             // the docstring's first paragraph
  std::vector<ArrayArg> args;      // the positional arrays, in order
  std::vector<ParamSpec> specs;    // the keywords' declarations
  nlohmann::json defaults;         // the default call as its table's JSON
  std::vector<std::string> fields; // the Result's fields, "record" last
  bool replays = false;            // takes job= (a record's job, as brume run reads it)
  // The default call with `values` set, each checked by its declaration.
  std::function<nlohmann::json(const JobValues& values)> build;
  // The call's checks that need no pixels, as its run makes them before any
  // work: every value's range, the combinations the run would refuse or
  // ignore, and what the call needs besides its keywords (fog's camera
  // height, depth of field's intrinsics). `given`: the keywords set. The
  // transforms check every value their distributions can draw with it when
  // they are made. Throws brume::Error.
  std::function<void(const nlohmann::json& call, const std::set<std::string>& given)> check;
  // Runs the call on the arrays (one per ArrayArg; `exec` from the call's
  // execution block, with the caller's GPU context); `given`: the keywords
  // set explicitly.
  std::function<ArrayResult(const std::vector<ArrayIn>&, const nlohmann::json& call, const Exec& exec,
                            const std::set<std::string>& given)>
      run;
};

struct CommandDef {
  // ---- what it is ------------------------------------------------------------------
  std::string name;      // as recorded and as typed after `brume`: "haze", "sky render", "haze+dof"
  std::string cli;       // the subcommand that runs it ("sky render"), "" when none of its own
                         // (plain haze is `brume haze` without --dof-... flags: haze+dof's subcommand)
  std::string summary;   // one line for --help and the reference
  std::vector<ParamSpec> specs;  // the job table's declarations, nested blocks included, in order
  nlohmann::json defaults;       // the default job as the table's JSON
  bool takes_exec_flags = false;  // takes the execution flags (--threads, --backend, ...)
  bool writes_record = false;     // writes a parameter record that `brume run` repeats
  bool batchable = false;         // a `brume batch` manifest row can name it
  std::string stage_prefix;      // a chain: the later stage's flag prefix ("dof-"), else ""
  std::optional<CommandSampling> sampling;  // `brume sample`, random_params, batch distributions
  std::vector<std::string> gpu_passes;      // its GPU passes (PassSpec names, "haze.premultiply"), in order
  // Its frame for the browser preview (`brume view`; brume/preview.hpp): the
  // plan of gpu_passes for a job (the table's JSON, checked) on the inputs,
  // with the maps it names. Empty for commands the preview does not show.
  std::function<PreviewFrame(const nlohmann::json& job, const PreviewInputs& in)> preview;
  // Where the page starts on a scene (brume/preview.hpp): values that
  // replace the table's defaults where those would show nothing (haze's
  // visibility at the scene's median range, depth of field's focus at the
  // image centre's depth, the camera a height profile needs), for a job of
  // the defaults and the command line's flags (`given`).
  std::function<std::vector<PreviewStart>(const nlohmann::json& job, const std::set<std::string>& given,
                                          const PreviewScene& scene)>
      preview_start;
  // The blocks or parameters the preview's page leaves out (those of a file
  // the page cannot name, a LiDAR scan's). Text parameters (files,
  // databases) are never the page's.
  std::vector<std::string> preview_fixed;
  std::optional<ArrayForm> arrays;          // the command on arrays (the Python module), where it has one

  // ---- what is done with a job (the table's JSON) --------------------------------------
  // The default job with `values` set, each checked by its declaration.
  std::function<nlohmann::json(const JobValues& values)> build;
  // Reads a job (every key declared, every value type- and range-checked);
  // with `full`, also every value's range as a whole and the command's
  // cross-field checks (`given`: the names set explicitly).
  std::function<void(const nlohmann::json& job, const std::set<std::string>& given, bool full)> check;
  // Runs it from files to files; returns its result: the record it wrote
  // (sky fit: the fit's JSON, its record under "record").
  std::function<nlohmann::json(const nlohmann::json& job, const ExecOptions& exec, const RunContext& ctx)> run;
  // The command line's run where it differs from `run` (haze+dof's subcommand
  // runs plain haze unless a --dof-... flag is given).
  std::function<nlohmann::json(const nlohmann::json& job, const ExecOptions& exec, const RunContext& ctx)> cli_run;
  // The command line's summary of a result: one line on stderr, or the
  // product on stdout (compare, sky fit).
  std::function<void(const nlohmann::json& job, const nlohmann::json& result)> report;
  // The medium it models, for effects that read another's (the LiDAR fog):
  // the extinction coefficient [1/m] at a world height [m] (camera
  // conventions of brume/camera.hpp), or nullopt where the job has no
  // physical units (haze in normalised kappa without --visibility or
  // --range-max) or models no medium. Empty for commands that model none.
  std::function<std::optional<double>(const nlohmann::json& job, double height_m)> extinction_per_m;
  // A spectral medium's extinction [1/m] at a wavelength [nm] (aerial's
  // Rayleigh + Mie at the observer), nullopt where the job cannot give one.
  // Empty for grey media (extinction_per_m holds at every wavelength).
  std::function<std::optional<double>(const nlohmann::json& job, double wavelength_nm)> spectral_extinction_per_m;
  // The job's medium where it varies with height (fog's height profiles):
  // the profile and the camera pose that places it in the world
  // (brume/height_profile.hpp), which a LiDAR integrates along each beam
  // rather than taking one extinction; null where the job's medium is the
  // same at every height or is no medium. Empty: never.
  std::function<std::shared_ptr<const HeightMedium>(const nlohmann::json& job)> height_medium;
  // Steps that complete the definition from its other fields (a camera
  // effect's LiDAR scan wraps its run, check, summary and array form, and
  // reads its medium's hooks): the list of commands runs them, in order,
  // once the definition function has returned, so that the function may
  // add them before or after the fields they read (brume/lidar_camera.hpp).
  std::vector<std::function<void(CommandDef& c)>> finish;

  // A declaration by name (not an alias); null when there is none.
  const ParamSpec* spec(std::string_view param) const;
  // The words of `cli` ({"sky", "render"}): the path of subcommands.
  std::vector<std::string> cli_words() const;
};

// Every command, in --help's order.
const std::vector<CommandDef>& commands();
// The parents of nested commands that are no command themselves ("depth" of
// "depth convert"): name and --help line.
struct CommandGroup {
  std::string name, summary;
};
const std::vector<CommandGroup>& command_groups();
// The command named `name`, or null.
const CommandDef* find_command(std::string_view name);
// The names of the commands for which `pred` holds, ", "-joined (messages).
std::string command_names(const std::function<bool(const CommandDef&)>& pred);
// A command that declares no GPU pass runs on the CPU: asked for the GPU
// (`flag`: "--backend", Python's "backend="), it refuses rather than run
// on the CPU without a word. Every caller of CommandDef::run and of an
// ArrayForm checks this first (the CLI, brume run, batch, Python).
void refuse_gpu_without_passes(const CommandDef& c, Backend requested, const std::string& flag);

// ---- building a definition from a typed job -------------------------------------------
// What a command's own file gives: its table, its typed run and (optional)
// its cross-field check and summary line; make_command fills the JSON forms.
template <class Job>
struct CommandParts {
  std::string name = {}, cli = {}, summary = {};
  const ParamTable<Job>* table = nullptr;
  bool takes_exec_flags = false, writes_record = false, batchable = false;
  std::function<void(const Job&, const std::set<std::string>& given)> check = {};  // beyond the table's range checks
  std::function<nlohmann::json(const Job&, const ExecOptions&, const RunContext&)> run = {};
  std::function<void(const Job&, const nlohmann::json& result)> report = {};
};

template <class Job>
CommandDef make_command(CommandParts<Job> parts) {
  const ParamTable<Job>& t = *parts.table;
  CommandDef c;
  c.name = parts.name;
  c.cli = parts.cli;
  c.summary = parts.summary;
  for (const Param<Job>& d : t.params()) c.specs.push_back(d.spec);
  c.defaults = t.to_json(Job{});
  c.takes_exec_flags = parts.takes_exec_flags;
  c.writes_record = parts.writes_record;
  c.batchable = parts.batchable;
  c.build = [&t](const JobValues& values) {
    Job j;
    for (const auto& [n, v] : values) {
      const Param<Job>& d = t.at(n);
      d.spec.check(v);
      d.set(j, v);
    }
    return t.to_json(j);
  };
  c.check = [&t, check = parts.check](const nlohmann::json& job, const std::set<std::string>& given, bool full) {
    Job j;
    t.from_json(j, job, "job");
    if (!full) return;
    t.validate(j);
    if (check) check(j, given);
  };
  c.run = [&t, run = parts.run](const nlohmann::json& job, const ExecOptions& eo, const RunContext& ctx) {
    Job j;
    t.from_json(j, job, "job");
    return run(j, eo, ctx);
  };
  if (parts.report)
    c.report = [&t, report = parts.report](const nlohmann::json& job, const nlohmann::json& result) {
      Job j;
      t.from_json(j, job, "job");
      report(j, result);
    };
  return c;
}

template <class P>
ParamTable<ArrayCall<P>> array_call_table(const ParamTable<P>& own, unsigned blocks, const std::set<std::string>& skip) {
  ParamTable<ArrayCall<P>> t(own.block());
  t.nest_except(&ArrayCall<P>::p, own, skip);
  if (blocks & kArrayPrepare) t.nest(&ArrayCall<P>::prepare, range_step_param_table());
  if (blocks & kArrayIntrinsics) t.nest_except(&ArrayCall<P>::depth, depth_param_table(), depth_file_params());
  if (blocks & kArrayScene) t.nest(&ArrayCall<P>::scene, scene_scale_param_table());
  if (blocks & kArrayExec) t.nest(&ArrayCall<P>::exec, exec_param_table());
  return t;
}

// The array form of a command whose keywords are the call table `t` (kept
// alive by the caller: a function-local static), run by `run` on the typed
// call (which it may change for the record: aerial's fitted turbidity is
// recorded as auto). `function` is the module's name, `public_name` the one
// users call ("" : brume.<function>).
template <class P>
ArrayForm make_array_form(
    std::string function, std::string public_name, std::string summary, std::vector<ArrayArg> args,
    const ParamTable<ArrayCall<P>>& t, std::vector<std::string> fields, bool replays,
    std::function<ArrayResult(const std::vector<ArrayIn>&, ArrayCall<P>&, const Exec&, const std::set<std::string>&)>
        run,
    std::function<void(const ArrayCall<P>&, const std::set<std::string>&)> check = {}) {
  ArrayForm a;
  a.public_name = public_name.empty() ? "brume." + function : std::move(public_name);
  a.function = std::move(function);
  a.summary = std::move(summary);
  a.args = std::move(args);
  for (const Param<ArrayCall<P>>& d : t.params()) a.specs.push_back(d.spec);
  a.defaults = t.to_json(ArrayCall<P>{});
  a.fields = std::move(fields);
  a.replays = replays;
  a.build = [&t](const JobValues& values) {
    ArrayCall<P> c;
    for (const auto& [n, v] : values) {
      const Param<ArrayCall<P>>& d = t.at(n);
      d.spec.check(v);
      d.set(c, v);
    }
    return t.to_json(c);
  };
  a.check = [&t, check](const nlohmann::json& call, const std::set<std::string>& given) {
    ArrayCall<P> c;
    t.from_json(c, call, "call");
    t.validate(c);
    (void)c.exec.exec();  // --reference with another backend
    if (check) check(c, given);
  };
  a.run = [&t, run](const std::vector<ArrayIn>& in, const nlohmann::json& call, const Exec& exec,
                    const std::set<std::string>& given) {
    ArrayCall<P> c;
    t.from_json(c, call, "call");
    ArrayResult r = run(in, c, exec, given);
    r.job = t.to_json(c);
    r.job.erase("execution");
    return r;
  };
  return a;
}

// The (rgb, range) arguments of the effects: colour and range as views, or both dense.
std::vector<ArrayArg> rgb_range_args(ArrayArg::As as);

// The sampling of an effect whose parameters live in one block P (its
// table's names are the names random_params returns).
template <class P>
CommandSampling make_sampling(const ParamTable<P>& table, std::vector<SampleDefault> defaults,
                              void (*validate)(const P&, const std::set<std::string>&)) {
  CommandSampling s;
  for (const Param<P>& d : table.params()) s.specs.push_back(d.spec);
  s.defaults = std::move(defaults);
  s.validate = [&table, validate](const nlohmann::json& values) {
    P p{};
    std::set<std::string> given;
    for (const auto& [name, v] : values.items()) {
      const Param<P>& d = table.at(name);
      d.spec.check(v);
      d.set(p, v);
      given.insert(name);
    }
    validate(p, given);
  };
  return s;
}

}  // namespace brume
