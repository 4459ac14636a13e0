// Parameter records read by `brume run` (and a sky fit's JSON, which holds
// one): JSON as the CLI parses it, then every check rerun makes before it
// runs anything (check_record: tool, schema, command, and the job read back
// through the command's parameter table). Nothing is run and no file is read.
#include "brume/error.hpp"
#include "brume/pipeline.hpp"
#include "brume/rerun.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nlohmann::json rec;
  try {
    rec = nlohmann::json::parse(data, data + size);
  } catch (const nlohmann::json::exception&) {
    return 0;  // the CLI reports "is not JSON" (tools/brume/cmd_run.cpp)
  }
  try {
    brume::check_record(rec);
  } catch (const brume::Error&) {
  }
  return 0;
}
