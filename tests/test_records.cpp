// brume tests — the stored records (tests/records/README.md): records of every
// earlier schema, each written by the brume of its schema on the committed
// inputs, with the outputs that brume wrote stored beside it. `brume run` of
// today must repeat each one bit for bit: the same output bytes (images as
// PFM, scans as .bin, a sky fit's JSON less its record), and a new record of
// today's schema holding the job as it ran (an older schema's job completed
// with the values that give its rules, ParamTable::since).
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/rerun.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

// A namespace of its own: the unity build joins this file with others.
namespace stored_records {

const fs::path kRecords = BRUME_RECORDS_DIR;

struct Stored {
  int schema;
  std::string file;  // schema-N/NAME.json, relative to kRecords
};

// Every record stored under schema-N/ (a sky fit's JSON holds its record under "record").
std::vector<Stored> all_stored() {
  std::vector<Stored> v;
  for (int s = kOldestRecordSchemaVersion; s <= kRecordSchemaVersion; ++s) {
    const fs::path d = kRecords / ("schema-" + std::to_string(s));
    if (!fs::is_directory(d)) continue;
    std::set<std::string> names;
    for (const auto& e : fs::directory_iterator(d))
      if (e.path().extension() == ".json") names.insert(e.path().filename().string());
    for (const std::string& n : names) v.push_back({s, "schema-" + std::to_string(s) + "/" + n});
  }
  return v;
}

// The parameter as ctest lists it ("schema-2/haze-visibility.json").
void PrintTo(const Stored& s, std::ostream* os) { *os << s.file; }

std::string test_name(const ::testing::TestParamInfo<Stored>& i) {
  std::string n = "schema" + std::to_string(i.param.schema) + "_" + fs::path(i.param.file).stem().string();
  for (char& c : n)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return n;
}

// Every string of the job that names a file in the record's own folder: the
// run's outputs (its inputs are under inputs/).
void outputs_of(const nlohmann::json& j, const std::string& folder, std::set<std::string>& out) {
  if (j.is_object() || j.is_array())
    for (const auto& v : j) outputs_of(v, folder, out);
  else if (j.is_string() && j.get<std::string>().rfind(folder + "/", 0) == 0)
    out.insert(j.get<std::string>());
}

// Every {"path", "sha256"} a record names: the inputs brume run checks.
void hashed_inputs(const nlohmann::json& j, std::set<std::pair<std::string, std::string>>& out) {
  if (j.is_object() && j.contains("path") && j.contains("sha256") && j["path"].is_string() && j["sha256"].is_string())
    out.insert({j["path"].get<std::string>(), j["sha256"].get<std::string>()});
  if (j.is_object() || j.is_array())
    for (const auto& v : j) hashed_inputs(v, out);
}

// Where two files of 32-bit floats differ (PFM after its three header lines,
// a KITTI scan from the start): how many values, and by how much at most.
std::string float_difference(const std::string& a, const std::string& b, bool pfm) {
  if (a.size() != b.size()) return "sizes " + std::to_string(a.size()) + " and " + std::to_string(b.size());
  std::size_t start = 0;
  for (int lines = 0; pfm && lines < 3 && start < a.size(); ++start)
    if (a[start] == '\n') ++lines;
  if (a.compare(0, start, b, 0, start) != 0) return "headers differ";
  std::size_t n = 0, differ = 0;
  double worst = 0;
  for (std::size_t i = start; i + 4 <= a.size(); i += 4, ++n) {
    float x, y;
    std::memcpy(&x, a.data() + i, 4);
    std::memcpy(&y, b.data() + i, 4);
    if (std::memcmp(&x, &y, 4) != 0) {
      ++differ;
      const double d = std::abs(static_cast<double>(x) - y);
      if (!(d <= worst)) worst = d;
    }
  }
  return std::to_string(differ) + " of " + std::to_string(n) + " values differ, by up to " + std::to_string(worst);
}

// A job with its output paths reduced to file names (the replay writes them into --out-dir).
nlohmann::json file_names(nlohmann::json job, const std::set<std::string>& outputs) {
  for (auto& [block, values] : job.items())
    if (values.is_object())
      for (auto& [name, v] : values.items())
        if (v.is_string() && (outputs.count(v.get<std::string>()) || fs::path(v.get<std::string>()).is_absolute()))
          v = fs::path(v.get<std::string>()).filename().string();
  return job;
}

// Every file under inputs/ and schema-N/, relative to kRecords.
std::set<std::string> listed_files() {
  std::set<std::string> v;
  for (const auto& e : fs::recursive_directory_iterator(kRecords)) {
    const std::string rel = fs::relative(e.path(), kRecords).generic_string();
    if (e.is_regular_file() && (rel.rfind("inputs/", 0) == 0 || rel.rfind("schema-", 0) == 0)) v.insert(rel);
  }
  return v;
}

TEST(StoredRecords, AreTheFilesTheirBuildsWrote) {
  // SHA256SUMS lists every input and every stored record and output with the
  // hash it had when its build wrote it (make_records.sh): a file edited,
  // added or removed since is a record that no longer shows what its build
  // did. Exact set, exact hashes.
  std::ifstream f(kRecords / "SHA256SUMS");
  ASSERT_TRUE(f) << (kRecords / "SHA256SUMS");
  std::map<std::string, std::string> sums;
  for (std::string line; std::getline(f, line);) {
    if (line.empty()) continue;
    ASSERT_GT(line.size(), 66u) << line;
    sums[line.substr(66)] = line.substr(0, 64);
  }
  const std::set<std::string> files = listed_files();
  for (const std::string& name : files) {
    auto it = sums.find(name);
    if (it == sums.end()) {
      ADD_FAILURE() << name << " is not in SHA256SUMS";
      continue;
    }
    EXPECT_EQ(sha256_file((kRecords / name).string()), it->second) << name << " changed since its build wrote it";
  }
  for (const auto& [name, sum] : sums) EXPECT_TRUE(files.count(name)) << name << " is in SHA256SUMS but missing";
}

TEST(StoredRecords, AParameterAbsentFromAJobTakesItsOlderRule) {
  // A record holds every parameter of each block its job has, so a
  // since-parameter absent from a block was not there when the record was
  // written: it takes its older value even in a record that states the
  // parameter's schema or a later one (a schema is raised once for a wave of
  // changes; records written in between state it and lack the later
  // parameters). Here haze's sky-rule, since(3, "s-max"), in a schema-4
  // record. A record of the parameter's schema or later without the block
  // gets no block (a Python record holds only its array form's blocks).
  nlohmann::json rec = read_json((kRecords / "schema-4/haze-visibility.json").string());
  ASSERT_EQ(rec["schema_version"], 4);
  ASSERT_EQ(record_job(rec)["haze"]["sky-rule"], rec["job"]["haze"]["sky-rule"]) << "a parameter present is kept";
  ASSERT_NE(rec["job"]["haze"]["sky-rule"], "s-max");
  rec["job"]["haze"].erase("sky-rule");
  EXPECT_EQ(record_job(rec)["haze"]["sky-rule"], "s-max");
  rec["job"].erase("haze");
  EXPECT_FALSE(record_job(rec).contains("haze"));
  rec["schema_version"] = 2;
  EXPECT_EQ(record_job(rec)["haze"]["sky-rule"], "s-max") << "an older schema's record gets the block";
}

TEST(StoredRecords, AHashOlderBuildsDidNotWriteIsNotRequired) {
  // brume run refuses a record whose job reads a file without its SHA-256
  // (issue #51: a deleted hash ran a replaced input) — but a record written
  // before brume hashed that file never had one: calibrations were hashed
  // from schema 4 (reads_file(..., hashed_since 4)). The stored schema-2
  // record of a projected scan lacks its calibration's hash and repeats
  // (RepeatsBitForBit); the same record of schema 4 with the hash deleted is
  // refused, and runs with --rehash.
  const fs::path scratch = fs::temp_directory_path() / ("brume-records-hash-" + std::to_string(::getpid()));
  fs::remove_all(scratch);
  fs::create_directories(scratch);
  nlohmann::json rec = read_json((kRecords / "schema-4/depth-convert-velodyne.json").string());
  ASSERT_EQ(rec["depth"]["kitti_calib"]["path"], "inputs/kitti-calib.txt");
  rec["depth"]["kitti_calib"].erase("sha256");
  std::ofstream((scratch / "v4.json").string()) << rec.dump(2);
  CliRun r = run("run " + (scratch / "v4.json").string() + " --out-dir " + (scratch / "a").string(), kRecords.string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--kitti-calib 'inputs/kitti-calib.txt' but the record holds no SHA-256"), std::string::npos)
      << r.output;
  r = run("run " + (scratch / "v4.json").string() + " --rehash --out-dir " + (scratch / "b").string(), kRecords.string());
  EXPECT_EQ(r.status, 0) << r.output;
  rec["schema_version"] = 3;  // as a schema-3 build wrote it
  std::ofstream((scratch / "v3.json").string()) << rec.dump(2);
  r = run("run " + (scratch / "v3.json").string() + " --out-dir " + (scratch / "c").string(), kRecords.string());
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("written before brume recorded the SHA-256 of --kitti-calib"), std::string::npos) << r.output;
  fs::remove_all(scratch);
}

class StoredRecord : public ScratchDirTest, public ::testing::WithParamInterface<Stored> {};

TEST(StoredRecords, EveryEarlierSchemaHasRecords) {
  // A record of each schema brume run reads, from the oldest to the one
  // before today's, is stored (make_records.sh writes them with the build
  // of that schema; tests/records/README.md).
  for (int s = kOldestRecordSchemaVersion; s < kRecordSchemaVersion; ++s) {
    int n = 0;
    for (const Stored& r : all_stored()) n += r.schema == s;
    EXPECT_GE(n, 10) << "schema " << s << ": tests/records/schema-" << s << " holds " << n << " records";
  }
}

TEST_P(StoredRecord, RepeatsBitForBit) {
  const Stored& s = GetParam();
  const std::string folder = "schema-" + std::to_string(s.schema);
  const nlohmann::json stored = read_json((kRecords / s.file).string());
  const bool sky_fit = stored.contains("record") && !stored.contains("tool");
  const nlohmann::json& record = sky_fit ? stored["record"] : stored;
  // Genuine: written by the brume of that schema.
  ASSERT_EQ(record.value("schema_version", 0), s.schema) << s.file;
  std::set<std::string> outputs;
  outputs_of(record["job"], folder, outputs);
  // A record and at least one output (a sky fit's JSON is both).
  ASSERT_GE(outputs.size(), sky_fit ? 1u : 2u) << s.file;
  ASSERT_TRUE(outputs.count(s.file)) << s.file << " does not name itself as the run's record or output";

  // brume run from tests/records, where the record's relative input paths lead.
  const CliRun r = run("run " + s.file + " --out-dir " + p("again"), kRecords.string());
  ASSERT_EQ(r.status, 0) << r.output;

  for (const std::string& o : outputs) {
    SCOPED_TRACE(o);
    const std::string again = p("again/" + fs::path(o).filename().string());
    ASSERT_TRUE(fs::exists(again)) << "brume run did not write it";
    if (o == s.file) {
      // The record the replay wrote: today's schema, the job as it ran.
      const nlohmann::json now = read_json(again);
      const nlohmann::json& now_record = sky_fit ? now["record"] : now;
      EXPECT_EQ(now_record["schema_version"], kRecordSchemaVersion);
      EXPECT_EQ(now_record["command"], record["command"]);
      std::set<std::pair<std::string, std::string>> read_then, read_now;
      hashed_inputs(record, read_then);
      hashed_inputs(now_record, read_now);
      for (const auto& in : read_then) EXPECT_TRUE(read_now.count(in)) << in.first << " " << in.second;
      const nlohmann::json ran = file_names(record_job(record), outputs), job = file_names(now_record["job"], outputs);
      for (const auto& [block, values] : ran.items())
        for (const auto& [name, v] : values.items())
          EXPECT_EQ(job[block][name], v) << "the replay's record has " << block << "." << name << " = "
                                        << job[block][name].dump() << ", the stored job " << v.dump();
      if (sky_fit) {
        // The fit itself, every number of it, without the record (its time and timings).
        nlohmann::json a = stored, b = now;
        a.erase("record");
        b.erase("record");
        EXPECT_EQ(a, b) << "the fit differs";
      }
      continue;
    }
    const std::string want = file_bytes((kRecords / o).string()), got = file_bytes(again);
    ASSERT_FALSE(want.empty()) << "the stored output is missing";
    EXPECT_TRUE(want == got) << "the replay's bytes differ from those stored: "
                             << float_difference(want, got, fs::path(o).extension() == ".pfm");
  }
}

INSTANTIATE_TEST_SUITE_P(Records, StoredRecord, ::testing::ValuesIn(all_stored()), test_name);

}  // namespace stored_records
