// brume — `brume run record.json`: repeat the run a parameter record
// describes. The record's "job" holds every declared parameter of the
// command (brume/params.hpp), so the same declaration that made the flags
// reads it back; nothing here knows an effect's parameters.
#include <filesystem>
#include <functional>
#include <map>

#include "brume/blur.hpp"
#include "brume/chain.hpp"
#include "brume/depth_pipeline.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/aerial.hpp"
#include "brume/sky.hpp"
#include "brume/haze.hpp"
#include "brume/insert.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"

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

// Outputs are the text parameters of the "output" block (and depth
// prepare's --masks directory): moved into out_dir under their file names.
template <class J>
void redirect_outputs(J& job, const ParamTable<J>& t, const std::string& out_dir) {
  if (out_dir.empty()) return;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir)) throw Error("--out-dir '" + out_dir + "' cannot be created: " + ec.message());
  for (const auto& d : t.params()) {
    if (!is_output_file(d.spec)) continue;
    const std::string v = d.get(job).template get<std::string>();
    if (v.empty()) continue;
    fs::path p(v);
    d.set(job, (fs::path(out_dir) / p.filename()).string());
  }
}

// Every parameter is recorded, so none counts as "given": conflicts are
// judged against the defaults, as for a library caller.
template <class J>
J job_from(const nlohmann::json& record, const ParamTable<J>& t, const std::string& out_dir) {
  J job;
  t.from_json(job, record.at("job"), "record 'job'");
  redirect_outputs(job, t, out_dir);
  return job;
}

Error unknown_command(const std::string& cmd) {
  return Error("the record's command '" + cmd + "' cannot be repeated by brume run (haze, haze+dof, aerial, insert, "
               "fog, dof, blur, sky render, sky fit, depth convert, depth prepare can)");
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

// The record's command, after the checks every record must pass.
std::string record_command(const nlohmann::json& record) {
  if (text_field(record, "tool") != "brume") throw Error("not a brume parameter record (no \"tool\": \"brume\")");
  const auto v = record.find("schema_version");
  const bool integral = v == record.end() || v->is_number_integer();
  const long long version = v == record.end() ? 1 : integral ? v->get<long long>() : -1;
  if (version != kRecordSchemaVersion || !record.contains("job"))
    throw Error("this record has schema_version " + (integral ? std::to_string(version) : v->dump()) +
                "; brume run reads version " + std::to_string(kRecordSchemaVersion) +
                " (records written by brume " BRUME_VERSION " and later, which hold the whole job)");
  return text_field(record, "command");
}

}  // namespace

std::string check_record(const nlohmann::json& record) {
  if (is_sky_fit_json(record)) return check_record(record["record"]);
  const std::string cmd = record_command(record);
  if (cmd == "haze") job_from(record, haze_job_table(), "");
  else if (cmd == "aerial") job_from(record, aerial_job_table(), "");
  else if (cmd == "insert") job_from(record, insert_job_table(), "");
  else if (cmd == "fog") job_from(record, fog_job_table(), "");
  else if (cmd == "dof") job_from(record, dof_job_table(), "");
  else if (cmd == "haze+dof") job_from(record, haze_dof_job_table(), "");
  else if (cmd == "blur") job_from(record, blur_job_table(), "");
  else if (cmd == "sky render") job_from(record, sky_render_job_table(), "");
  else if (cmd == "sky fit") job_from(record, sky_fit_job_table(), "");
  else if (cmd == "depth convert") job_from(record, depth_convert_job_table(), "");
  else if (cmd == "depth prepare") job_from(record, depth_prepare_job_table(), "");
  else throw unknown_command(cmd);
  return cmd;
}

nlohmann::json rerun(const nlohmann::json& record, const ExecOptions& exec, const std::string& out_dir,
                     const std::vector<std::string>& argv, Image (*sky_plot)(const nlohmann::json& fit)) {
  if (is_sky_fit_json(record)) return rerun(record["record"], exec, out_dir, argv, sky_plot);
  const std::string cmd = record_command(record);
  if (record.contains("inputs")) verify_inputs(record["inputs"]);
  if (record.contains("depth")) verify_inputs(record["depth"]);
  if (record.contains("fog")) verify_inputs(record["fog"]);  // the density table (fog.derived.table)
  RunContext ctx;
  ctx.argv = argv;
  if (cmd == "haze") return run_haze_job(job_from(record, haze_job_table(), out_dir), exec, ctx);
  if (cmd == "aerial") return run_aerial_job(job_from(record, aerial_job_table(), out_dir), exec, ctx);
  if (cmd == "insert") return run_insert_job(job_from(record, insert_job_table(), out_dir), exec, ctx);
  if (cmd == "fog") return run_fog_job(job_from(record, fog_job_table(), out_dir), exec, ctx);
  if (cmd == "dof") return run_dof_job(job_from(record, dof_job_table(), out_dir), exec, ctx);
  if (cmd == "haze+dof") return run_haze_dof_job(job_from(record, haze_dof_job_table(), out_dir), exec, ctx);
  if (cmd == "blur") return run_blur_job(job_from(record, blur_job_table(), out_dir), exec, ctx);
  if (cmd == "sky render") return run_sky_render_job(job_from(record, sky_render_job_table(), out_dir), exec, ctx);
  if (cmd == "sky fit") {
    // --out and --plot are the fit's own flags (not the output block's): moved here.
    SkyFitJob job = job_from(record, sky_fit_job_table(), out_dir);
    if (!out_dir.empty()) {
      job.out = (fs::path(out_dir) / fs::path(job.out).filename()).string();
      if (!job.plot.empty()) job.plot = (fs::path(out_dir) / fs::path(job.plot).filename()).string();
    }
    return run_sky_fit_job(job, ctx, sky_plot).at("record");
  }
  if (cmd == "depth convert")
    return run_depth_convert_job(job_from(record, depth_convert_job_table(), out_dir), ctx);
  if (cmd == "depth prepare")
    return run_depth_prepare_job(job_from(record, depth_prepare_job_table(), out_dir), ctx);
  throw unknown_command(cmd);
}

}  // namespace brume
