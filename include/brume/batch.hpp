// brume — dataset-scale runs in one process (`brume batch`, issue #17).
//
// A dataset is a manifest: one frame per row (CSV with a header, or JSON
// Lines), each row naming its image, its depth source under the depth flags'
// names, its effect and the effect's parameters — fixed values, or
// distributions drawn per frame by the library's sampler (brume/sample.hpp).
// Nothing here declares a parameter: a column is looked up in the effect's
// own job table (the table that makes `brume haze`'s flags), parsed and
// range-checked by that declaration, and the frame runs through the effect's
// own run_<effect>_job, so a batch frame is exactly the `brume <effect>` run
// its record describes (and `brume run` repeats it).
//
//   manifest ─► plan_batch (columns → job, sampled values, output names; all rows checked up front)
//            ─► shard filter ─► workers: [skip if done] → run_<effect>_job → result line
//            ─► results manifest (JSON Lines, atomically at the end)
//
// Decisions (where the issue is silent):
//   - every row is planned and checked before any frame runs (unknown column,
//     bad value or spec, duplicate keys, two keys with one output name): a
//     manifest error costs milliseconds, not the hours of work before it.
//     What a frame's files do (missing, corrupt, sizes that disagree, a
//     preparation that refuses the range) fails that frame only.
//   - parameters a row does not give keep the effect's defaults; the
//     sampler's default ranges (`brume sample`) are NOT applied — a frame
//     gets a random value only where the manifest or --param asks for one.
//   - sampling key: (--seed, the frame key, the parameter's canonical name);
//     in a chain a later stage's parameter is hashed under its prefixed name
//     ("dof.focus-distance"), the first stage's under its plain name, so a
//     frame's haze is the same in `haze` and `haze+dof` rows.
//   - shards: n = the first 8 bytes, big-endian, of
//     SHA-256("brume-shard-v1\0" + key); the frame is in shard (n mod N) + 1.
//   - output names: the key's '/'-separated components become folders under
//     --out-dir; in each component a byte that is a control character or one
//     of \ : * ? " < > | becomes '_', and a leading '.' becomes '_' (no hidden
//     files, no clash with brume's temporaries); an empty, "." or ".."
//     component, or a key starting with '/', is an error. A known image
//     extension at the end of the key is replaced by the output's
//     (--format, else the input image's). The record is <name>.json, declared
//     maps <name>.<map>.exr. Two keys that map to one name are an error.
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/pipeline.hpp"

namespace brume {

inline constexpr const char* kShardHashName = "brume-shard-v1";

// One row of a manifest: its cells as written (CSV: strings, empty cells
// left out; JSON Lines: the object's values), and where it is, for messages.
struct ManifestRow {
  int line = 0;  // 1-based line in the file
  std::vector<std::pair<std::string, nlohmann::json>> cells;
};
struct Manifest {
  std::string path;
  std::string format;  // "csv" or "jsonl"
  std::vector<ManifestRow> rows;
};
// CSV (RFC 4180 quoting; a header row; '#' lines and blank lines skipped) or
// JSON Lines (one object per line), chosen by the extension (.csv; .jsonl,
// .ndjson, .json) or, for another extension, by the first character ('{').
Manifest read_manifest(const std::string& path);

// The effects a manifest row can name: haze, fog, aerial, dof, haze+dof.
const std::vector<std::string>& batch_effects();

// The compression of a batch's PNG frames when neither the row nor --param
// sets one: the Up filter with run-length deflate (io/formats/png.cpp),
// named so that a frame's record says it.
inline constexpr const char* kBatchPngCompression = "fast";

struct BatchOptions {
  std::string manifest;
  std::string out_dir;
  int workers = 0;             // frames in flight; 0 = one per core
  bool resume = false;         // skip frames already done (output and record present, inputs unchanged)
  int shard_index = 1, shard_count = 1;  // --shard I/N
  std::uint64_t seed = 0;
  std::string format;          // output extension ("png", "exr", ...); empty = the input image's
  std::string effect;          // for rows without an "effect" column
  std::vector<std::pair<std::string, std::string>> params;  // --param NAME=SPEC: for rows without that column
  std::vector<std::string> maps;  // declared map outputs to write for every frame (e.g. "transmission")
  ExecOptions exec;            // per frame; threads 0 = cores / workers
  bool progress = true;        // progress on stderr (a bar on a terminal, else plain lines)
};

// A frame ready to run: the effect's whole job as its table's JSON (outputs
// under out_dir), the names the row gave, and the record's "batch" block.
struct BatchFrame {
  std::string key;
  std::string effect;
  int line = 0;                // the manifest line
  nlohmann::json job;          // ParamTable<Job>::to_json of the job
  std::set<std::string> given; // job parameter names the row (or --param) set
  nlohmann::json batch;        // {"key", "seed", "effect", "sampling": {sampler, seed, key, specs}, "values"}
  std::string image;           // the input image (for messages)
  std::vector<std::string> outputs;  // every file the frame writes (main image first, record last)
};

// A frame as JSON and back (the Dask runner ships frames to its workers):
// {"key", "effect", "line", "job", "given": [...], "batch", "image", "outputs": [...]}.
nlohmann::json batch_frame_to_json(const BatchFrame& f);
BatchFrame batch_frame_from_json(const nlohmann::json& j);

// Every row of the manifest, planned and checked (all shards). Throws
// brume::Error listing the rows that are wrong (line, column, value, fix).
std::vector<BatchFrame> plan_batch(const BatchOptions& o);

// The shard (1..count) a key belongs to (kShardHashName above).
int shard_of(std::string_view key, int count);

// A frame is done when all its outputs exist, its record holds the same job
// and batch block, and every input the record names still has its SHA-256.
bool batch_frame_done(const BatchFrame& f);

struct BatchFrameResult {
  std::string status;   // "ok", "skipped" (done before, --resume) or "failed"
  double seconds = 0.0;
  std::string error;    // failed: the message
  std::vector<std::string> warnings;  // what the run warned about (also in its record)
  nlohmann::json line;  // the results manifest's line
};
// Runs one frame through its effect's pipeline; never throws for the frame's
// own failures (they are the result). `argv` goes into the record.
BatchFrameResult run_batch_frame(const BatchFrame& f, const ExecOptions& exec, const std::vector<std::string>& argv);

struct BatchSummary {
  std::size_t frames = 0;  // in this shard
  std::size_t ok = 0, skipped = 0, failed = 0;
  std::size_t warned = 0;  // frames run now that warned (their results lines say what)
  double seconds = 0.0;
  std::string results;     // the results manifest's path
};
// The whole run: plan, shard, resume, workers, progress, results manifest
// (<out_dir>/results.jsonl, or results.shard-I-of-N.jsonl).
BatchSummary run_batch(const BatchOptions& o);

// The record's argv for a batch frame: the options that decide its outputs
// (manifest, out-dir, seed, format, effect, params, maps), not --workers,
// --resume, --shard or execution flags, so a resumed or sharded run's
// records equal an uninterrupted run's apart from time and timings.
std::vector<std::string> batch_record_argv(const BatchOptions& o);

// `brume batch --dataset DIR --layout L`: a manifest of the dataset in DIR.
// Layouts: middlebury (2005/2006 folders Scene/view1.png, disp1.png,
// dmin.txt at third size), eth3d (Scene/im0.png, disp0.pfm, calib.txt),
// kitti (image_2/N.png, velodyne/N.bin, calib/N.txt), cityscapes
// (leftImg8bit/S/C/N_leftImg8bit.png, disparity/S/C/N_disparity.png with
// d = (p - 1)/256, camera/S/C/N_camera.json for fx, fy, u0, v0, baseline), pairs (image_glob and
// depth_glob relative to DIR, '*' within one path component, paired by what
// '*' matched; depth_kind the depth flag: range, z, disparity, ...).
// Paths are written relative to the manifest's folder; keys are the image
// path relative to DIR. Rows are sorted by key. Returns the rows as JSON
// objects (column: value); write_manifest writes them.
struct DatasetOptions {
  std::string dir, layout;
  std::string image_glob, depth_glob, depth_kind = "range";  // pairs
  std::string manifest_dir = ".";  // where the manifest will be (paths are relative to it)
  // kitti: also a "lidar" column, the frame's velodyne/N.bin, so that every
  // frame's scan is fogged with its image's medium and written beside it as
  // <key>.bin (a camera effect's --lidar/--lidar-out, brume/lidar_camera.hpp).
  bool lidar = false;
};
std::vector<nlohmann::json> dataset_manifest(const DatasetOptions& o);
// CSV or JSON Lines by the extension, written atomically.
void write_manifest(const std::string& path, const std::vector<nlohmann::json>& rows);

}  // namespace brume
