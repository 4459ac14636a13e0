// brume — `brume run`: repeat the run a parameter record describes. The
// record's "command" is looked up in the list of commands
// (brume/command.hpp) and its "job" read back through that command's table.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/image.hpp"
#include "brume/pipeline.hpp"

namespace brume {

// The checks rerun makes before it runs anything, without running or reading
// a file: the record is brume's, of the schema brume run reads, its command
// can be repeated and its job reads back through that command's parameter
// table (every key declared, every value type- and range-checked). Returns
// the command ("haze", "sky fit", ...); throws brume::Error as rerun does.
std::string check_record(const nlohmann::json& record);

// The record's job as `brume run` runs it: a parameter introduced with a new
// rule (ParamSpec::since_schema), absent from the record's job, set to the
// value that gives the rule the record ran under — also in a record that
// states the parameter's schema but was written before the parameter was
// added (a schema is raised once for a wave of such changes).
// Throws brume::Error as check_record does for a record of no known schema.
nlohmann::json record_job(const nlohmann::json& record);

// `brume run`: repeat the run a record describes (schema_version
// kOldestRecordSchemaVersion to kRecordSchemaVersion, brume/pipeline.hpp). Inputs
// must still have the SHA-256 the record names; with a non-empty out_dir,
// every output goes into out_dir under its recorded file name. Returns the
// new record. A `brume sky fit` JSON is repeated too (its record is under
// "record"); its --plot is drawn by `plot` (the command line's plotter;
// a library caller without one gets an error naming --plot).
// Every file the job reads (a parameter declared reads_file) must have its
// SHA-256 in the record, or rerun refuses it; with `rehash` it hashes the
// file now and goes on, telling `warn`.
struct RerunInputs {
  bool rehash = false;
  std::function<void(const std::string&)> warn;
};
nlohmann::json rerun(const nlohmann::json& record, const ExecOptions& exec, const std::string& out_dir,
                     const std::vector<std::string>& argv, Image (*plot)(const nlohmann::json& result) = nullptr,
                     const RerunInputs& inputs = {});

}  // namespace brume
