// brume — `brume run record.json`: repeat the run a parameter record
// describes. The record's "job" holds every declared parameter of the
// command (brume/params.hpp), so the same declaration that made the flags
// reads it back; nothing here knows an effect's parameters.
#include <filesystem>
#include <functional>
#include <map>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/rerun.hpp"

namespace fs = std::filesystem;

namespace brume {

namespace {

// Every {"path", "sha256"} below `j` must still match the file on disk: a
// record describes a run on those bytes, not on whatever now has the name.
void verify_inputs(const nlohmann::json& j) {
  if (j.is_object()) {
    if (j.contains("path") && j.contains("sha256") && j["path"].is_string() && j["sha256"].is_string()) {
      const std::string path = j["path"].get<std::string>();
      std::error_code ec;
      if (!fs::exists(path, ec))
        throw Error("the record's input '" + path + "' does not exist; run from the directory the record was made "
                    "in, or restore the file");
      if (sha256_file(path) != j["sha256"].get<std::string>())
        throw Error("the record's input '" + path + "' has changed since the record was made (SHA-256 differs); "
                    "the run would not be the one recorded");
    }
    for (const auto& [k, v] : j.items()) verify_inputs(v);
  } else if (j.is_array()) {
    for (const auto& v : j) verify_inputs(v);
  }
}

// The {path, sha256} pairs anywhere in the record but its job (a
// sensitivity's {source, sha256} with its file before '#'): path -> hash.
void collect_hashes(const nlohmann::json& j, std::map<std::string, std::string>& out) {
  if (j.is_object()) {
    const auto sha = j.find("sha256");
    if (sha != j.end() && sha->is_string()) {
      for (const char* key : {"path", "source"}) {
        const auto p = j.find(key);
        if (p == j.end() || !p->is_string()) continue;
        std::string path = p->get<std::string>();
        if (std::string(key) == "source") path = path.substr(0, path.rfind('#'));
        out.emplace(path, sha->get<std::string>());
      }
    }
    for (const auto& [k, v] : j.items()) collect_hashes(v, out);
  } else if (j.is_array()) {
    for (const auto& v : j) collect_hashes(v, out);
  }
}

// Every file the job reads (the parameters declared reads_file) must have
// its SHA-256 in the record, matching the file now: a record whose hash was
// deleted (or whose inputs block was) used to run on whatever the name held,
// exit 0, no word (issue #51). With `rehash` such a file is hashed now and
// the run goes on, with a warning.
int record_version(const nlohmann::json& record);

void require_input_hashes(const CommandDef& c, const nlohmann::json& job, const nlohmann::json& record,
                          const RerunInputs& opts) {
  std::map<std::string, std::string> hashes;
  for (const auto& [k, v] : record.items())
    if (k != "job") collect_hashes(v, hashes);
  for (const ParamSpec& s : c.specs) {
    if (!s.input_file) continue;
    const auto b = job.find(s.block);
    if (b == job.end() || !b->is_object()) continue;
    const auto v = b->find(s.name);
    if (v == b->end() || !v->is_string()) continue;
    std::string path = v->get<std::string>();
    if (path.empty() || path == s.input_file_none) continue;
    if (!s.input_file_prefix.empty()) {
      if (path.rfind(s.input_file_prefix, 0) != 0) continue;  // a value that names no file ("gamma:2.2")
      path = path.substr(s.input_file_prefix.size());
    }
    if (s.input_file_cut) path = path.substr(0, path.rfind(s.input_file_cut));
    const auto h = hashes.find(path);
    if (h == hashes.end()) {
      if (record_version(record) < s.input_hashed_since) {
        // Written before brume hashed this file: not a deleted hash.
        if (opts.warn)
          opts.warn("the record (schema " + std::to_string(record_version(record)) + ") was written before brume "
                    "recorded the SHA-256 of --" + s.name + "; running on '" + path + "' as it is now (the new record "
                    "hashes it)");
        continue;
      }
      if (!opts.rehash)
        throw Error("the record's job reads --" + s.name + " '" + path + "' but the record holds no SHA-256 for it "
                    "(deleted, or the record was edited), so brume run cannot check that the file is the one the "
                    "record describes; restore the record, or pass --rehash to run on the file as it is now (the "
                    "new record hashes it)");
      const std::string now = sha256_file(path);
      if (opts.warn)
        opts.warn("the record holds no SHA-256 for --" + s.name + " '" + path + "'; hashed now (" + now.substr(0, 16) +
                  "...): the run may not be the recorded one");
      continue;
    }
    if (sha256_file(path) != h->second)
      throw Error("the record's input '" + path + "' (--" + s.name + ") has changed since the record was made "
                  "(SHA-256 differs); the run would not be the one recorded");
  }
}

// Outputs are the parameters that name files the run writes (the output
// block's, depth prepare's --masks directory, sky fit's --out and --plot):
// moved into out_dir under their file names.
void redirect_outputs(const CommandDef& c, nlohmann::json& job, const std::string& out_dir) {
  if (out_dir.empty()) return;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir)) throw Error("--out-dir '" + out_dir + "' cannot be created: " + ec.message());
  for (const ParamSpec& s : c.specs) {
    if (!is_output_file(s)) continue;
    auto b = job.find(s.block);
    if (b == job.end() || !b->is_object()) continue;
    auto v = b->find(s.name);
    if (v == b->end() || !v->is_string() || v->get<std::string>().empty()) continue;
    *v = (fs::path(out_dir) / fs::path(v->get<std::string>()).filename()).string();
  }
}

nlohmann::json job_as_recorded(const CommandDef& c, const nlohmann::json& record);

// The command that repeats a record's, with its job read back through that
// command's table (every key declared, every value type- and range-checked).
// Every parameter is recorded, so none counts as "given": conflicts are
// judged against the defaults, as for a library caller.
const CommandDef& repeatable(const std::string& cmd, const nlohmann::json& record) {
  const CommandDef* c = find_command(cmd);
  if (!c || !c->writes_record)
    throw Error("the record's command '" + cmd + "' cannot be repeated by brume run (" +
                command_names([](const CommandDef& d) { return d.writes_record; }) + " can)");
  c->check(job_as_recorded(*c, record), {}, false);
  return *c;
}

// A record's text field, or "" when absent or not a string: a hand-edited or
// corrupt record must end in brume's message, not in a JSON type error
// ("internal error"; found by fuzz/fuzz_record.cpp: {"tool": 1}).
std::string text_field(const nlohmann::json& j, const char* key) {
  if (!j.is_object()) return "";
  const auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

// A `brume sky fit` JSON holds its record under "record".
bool is_sky_fit_json(const nlohmann::json& record) {
  return record.is_object() && !record.contains("tool") && record.contains("record") &&
         record["record"].is_object() && text_field(record["record"], "command") == "sky fit";
}

// The record's schema version, after the checks every record must pass.
int record_version(const nlohmann::json& record) {
  if (text_field(record, "tool") != "brume") throw Error("not a brume parameter record (no \"tool\": \"brume\")");
  const auto v = record.find("schema_version");
  const bool integral = v == record.end() || v->is_number_integer();
  const long long version = v == record.end() ? 1 : integral ? v->get<long long>() : -1;
  if (version < kOldestRecordSchemaVersion || version > kRecordSchemaVersion || !record.contains("job"))
    throw Error("this record has schema_version " + (integral ? std::to_string(version) : v->dump()) +
                "; brume run reads versions " + std::to_string(kOldestRecordSchemaVersion) + " to " +
                std::to_string(kRecordSchemaVersion) + " (records that hold the whole job; this is brume " BRUME_VERSION
                ")");
  return static_cast<int>(version);
}

// The record's command, after the checks every record must pass.
std::string record_command(const nlohmann::json& record) {
  record_version(record);
  return text_field(record, "command");
}

// The job as this brume runs it: a parameter introduced with a new rule
// (ParamSpec::since_schema), absent from the record's job, takes the value
// that gives the rule the record ran under, so that the record repeats as it
// ran. Absent means written before the parameter existed: a record holds
// every parameter of each block its job has (nulls included). That is so
// for a record of an older schema, and also for one that states the
// parameter's own schema but was written before the parameter was added (a
// schema is raised once for a wave of changes, each of which adds its
// since() parameters later: a record written in between states the new
// schema and lacks them). An older schema's record also gets a block its job
// lacks; a record of the parameter's schema or later that lacks the whole
// block has no such block (a Python record's job holds only its array form's).
nlohmann::json job_as_recorded(const CommandDef& c, const nlohmann::json& record) {
  nlohmann::json job = record.at("job");
  const int version = record_version(record);
  if (!job.is_object()) return job;
  // A parameter that an older schema kept elsewhere ("dof.focal-length", now
  // the depth block's lens: ParamSpec::formerly) is read, and recorded, where
  // it is now.
  for (const ParamSpec& s : c.specs)
    for (const std::string& f : s.formerly) {
      const auto dot = f.find('.');
      auto b = job.find(f.substr(0, dot));
      if (b == job.end() || !b->is_object() || !b->contains(f.substr(dot + 1))) continue;
      nlohmann::json v = (*b)[f.substr(dot + 1)];
      b->erase(f.substr(dot + 1));
      if (!job.contains(s.block) || !job[s.block].is_object() || !job[s.block].contains(s.name))
        job[s.block][s.name] = std::move(v);
    }
  for (const ParamSpec& s : c.specs) {
    if (s.since_schema == 0) continue;
    auto b = job.find(s.block);
    if (b != job.end() && (!b->is_object() || b->contains(s.name))) continue;
    if (b == job.end() && s.since_schema <= version) continue;
    job[s.block][s.name] = s.before_schema;  // the block too, where an older record has none
  }
  return job;
}

}  // namespace

nlohmann::json record_job(const nlohmann::json& record) {
  const std::string cmd = record_command(record);
  const CommandDef* c = find_command(cmd);
  if (!c) throw Error("the record's command '" + cmd + "' is not a brume command");
  return job_as_recorded(*c, record);
}

std::string check_record(const nlohmann::json& record) {
  if (is_sky_fit_json(record)) return check_record(record["record"]);
  const std::string cmd = record_command(record);
  repeatable(cmd, record);
  return cmd;
}

nlohmann::json rerun(const nlohmann::json& record, const ExecOptions& exec, const std::string& out_dir,
                     const std::vector<std::string>& argv, Image (*plot)(const nlohmann::json& result),
                     const RerunInputs& inputs) {
  if (is_sky_fit_json(record)) return rerun(record["record"], exec, out_dir, argv, plot, inputs);
  const std::string cmd = record_command(record);
  // A record of a Python call on arrays ({"source": "numpy"} inputs) names no files to read again.
  if (record.contains("inputs") && record["inputs"].is_object()) {
    std::string arrays;
    for (const auto& [name, in] : record["inputs"].items())
      if (in.is_object() && text_field(in, "source") == "numpy") arrays += (arrays.empty() ? "" : ", ") + name;
    if (!arrays.empty()) {
      // The call that repeats it: brume.rerun for the effects on rgb and range that take a job
      // (python/brume/_rerun.py), job= for other forms that take one, else the same call.
      const CommandDef* c = find_command(cmd);
      const ArrayForm* a = c && c->arrays ? &*c->arrays : nullptr;
      std::string how = "the same " + (a ? a->public_name : "brume " + cmd) + " call with the record's values";
      if (a && a->replays)
        how = a->args.size() >= 2 && a->args[0].name == "rgb" && a->args[1].name == "range"
                  ? "brume.rerun(record, rgb, range, ...) on the same arrays (a scan as lidar=)"
                  : a->public_name + "(..., job=record[\"job\"]) on the same arrays";
      throw Error("this record's inputs (" + arrays + ") were numpy arrays of a Python call, not files: repeat it "
                  "in Python with " + how + ", or write the arrays to files and run its job blocks in a record of "
                  "those files (docs/python.md, \"Repeating a run\")");
    }
  }
  // Every {"path", "sha256"} input the record names (the density table of fog under "fog").
  for (const char* block : {"inputs", "depth", "fog"})
    if (record.contains(block)) verify_inputs(record[block]);
  const CommandDef& c = repeatable(cmd, record);
  refuse_gpu_without_passes(c, exec.backend, "--backend");
  nlohmann::json job = job_as_recorded(c, record);
  require_input_hashes(c, job, record, inputs);
  redirect_outputs(c, job, out_dir);
  RunContext ctx;
  ctx.argv = argv;
  ctx.plot = plot;
  const nlohmann::json out = c.run(job, exec, ctx);
  // A command whose product holds its record (sky fit's JSON) returns the record.
  return is_sky_fit_json(out) ? out["record"] : out;
}

}  // namespace brume
