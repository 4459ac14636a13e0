// Batch manifests (brume batch --manifest, brume.dask): the first byte picks
// the file's extension (.csv, .jsonl, or .txt, whose format is sniffed) and
// the effect for rows without an 'effect' column; the rest is the manifest,
// read and planned as brume batch plans it (columns -> jobs, sampled values,
// output names, key uniqueness). Nothing is run. A planned frame must
// survive the JSON round trip the Dask runner ships it through, and dump as
// JSON (its record's and the results manifest's text).
#include <cstdlib>

#include "brume/batch.hpp"
#include "brume/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const char* kExt[] = {".csv", ".jsonl", ".txt"};
  const auto& effects = brume::batch_effects();
  brume::BatchOptions o;
  o.manifest = brume::fuzz::write_file(brume::fuzz::temp_path(kExt[data[0] % 3]), data + 1, size - 1);
  o.effect = effects[(data[0] / 3) % effects.size()];
  o.out_dir = brume::fuzz::temp_path("-out");
  o.seed = 7;
  o.progress = false;
  std::vector<brume::BatchFrame> frames;
  try {
    frames = brume::plan_batch(o);
  } catch (const brume::Error&) {
    return 0;
  }
  for (const brume::BatchFrame& f : frames) {
    const nlohmann::json j = brume::batch_frame_to_json(f);
    if (brume::batch_frame_to_json(brume::batch_frame_from_json(j)) != j) std::abort();
    (void)j.dump();  // a string that is not UTF-8 would throw here: planning must have refused it
  }
  return 0;
}
