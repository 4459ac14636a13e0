// brume — `brume batch`: manifests, sampled parameters, shards, resume and
// workers over the effects' own pipelines (brume/batch.hpp says what and why).
#include "brume/batch.hpp"

#include <unistd.h>


#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/gpu_context.hpp"
#include "brume/io.hpp"
#include "brume/sample.hpp"
#include "core/text.hpp"
#include "jobs/batch_internal.hpp"

namespace fs = std::filesystem;

namespace brume {

namespace {

using text::lower;
using text::trim;
using detail::cell_text;
using detail::cell_where;

}  // namespace

// ---- the effects a row can name --------------------------------------------------------

namespace {

// The commands a row can name: the batchable ones of the list of commands
// (brume/command.hpp), each with its job table, build, check and run.
bool batchable(const CommandDef& c) { return c.batch; }

const CommandDef& effect_named(const std::string& name, const std::string& where) {
  std::string n = lower(trim(name));
  n.erase(std::remove_if(n.begin(), n.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); }),
          n.end());
  if (const CommandDef* c = find_command(n); c && c->batch) return *c;
  throw Error(where + ": effect '" + name + "' is not available in brume batch; use one of: " +
              command_names(batchable) + " (chains: '+'-joined stages, the later stages' parameters prefixed with their name: dof.focus-distance)");
}

// ---- names -----------------------------------------------------------------------------

const std::set<std::string>& image_extensions() {
  static const std::set<std::string> s = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".pfm", ".hdr"};
  return s;
}

// The key as a relative path under --out-dir (decisions in batch.hpp).
std::string output_stem(const std::string& key) {
  if (key.empty()) throw Error("the key is empty");
  if (key[0] == '/') throw Error("key '" + key + "' is absolute; keys name files under --out-dir");
  std::string out, comp;
  auto flush = [&] {
    if (comp.empty() || comp == "." || comp == "..")
      throw Error("key '" + key + "' has an empty, '.' or '..' path component; keys name files under --out-dir");
    if (comp[0] == '.') comp[0] = '_';
    out += (out.empty() ? "" : "/") + comp;
    comp.clear();
  };
  for (char c : key) {
    if (c == '/') {
      flush();
      continue;
    }
    const unsigned char u = static_cast<unsigned char>(c);
    const bool bad = u < 0x20 || u == 0x7f || std::string_view("\\:*?\"<>|").find(c) != std::string_view::npos;
    comp += bad ? '_' : c;
  }
  flush();
  const fs::path p(out);
  if (image_extensions().count(lower(p.extension().string()))) out = (p.parent_path() / p.stem()).generic_string();
  return out;
}

}  // namespace

const std::vector<std::string>& batch_effects() {
  static const std::vector<std::string> v = [] {
    std::vector<std::string> n;
    for (const CommandDef& c : commands())
      if (c.batch) n.push_back(c.name);
    return n;
  }();
  return v;
}

nlohmann::json batch_frame_to_json(const BatchFrame& f) {
  return {{"key", f.key},     {"effect", f.effect}, {"line", f.line},   {"job", f.job},
          {"given", f.given}, {"batch", f.batch},   {"image", f.image}, {"outputs", f.outputs}};
}

BatchFrame batch_frame_from_json(const nlohmann::json& j) {
  BatchFrame f;
  try {
    f.key = j.at("key").get<std::string>();
    f.effect = j.at("effect").get<std::string>();
    f.line = j.at("line").get<int>();
    f.job = j.at("job");
    f.given = j.at("given").get<std::set<std::string>>();
    f.batch = j.at("batch");
    f.image = j.at("image").get<std::string>();
    f.outputs = j.at("outputs").get<std::vector<std::string>>();
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("not a batch frame: ") + e.what());
  }
  effect_named(f.effect, "batch frame '" + f.key + "'");
  if (f.outputs.size() < 2) throw Error("batch frame '" + f.key + "' names fewer than two outputs (image, record)");
  return f;
}

int shard_of(std::string_view key, int count) {
  if (count < 1) throw Error("internal: shard count < 1");
  const std::uint64_t n = sha256_prefix64(std::string(kShardHashName) + '\0' + std::string(key));
  return static_cast<int>(n % static_cast<std::uint64_t>(count)) + 1;
}

std::vector<std::string> batch_record_argv(const BatchOptions& o) {
  std::vector<std::string> a = {"brume", "batch", "--manifest", o.manifest, "--out-dir", o.out_dir,
                                "--seed", std::to_string(o.seed)};
  if (!o.format.empty()) a.insert(a.end(), {"--format", o.format});
  if (!o.effect.empty()) a.insert(a.end(), {"--effect", o.effect});
  for (const auto& [n, s] : o.params) a.insert(a.end(), {"--param", n + "=" + s});
  for (const std::string& m : o.maps) a.insert(a.end(), {"--map", m});
  return a;
}

std::vector<BatchFrame> plan_batch(const BatchOptions& o) {
  if (o.out_dir.empty()) throw Error("--out-dir is required: the folder the outputs and records go to");
  std::string fmt = lower(trim(o.format));
  if (!fmt.empty() && fmt[0] == '.') fmt.erase(0, 1);
  if (!fmt.empty() && !image_extensions().count("." + fmt))
    throw Error("--format '" + o.format + "' is not an image format brume writes; use png, jpg, tif, exr, pfm or hdr");
  const Manifest m = read_manifest(o.manifest);
  const fs::path base = fs::path(o.manifest).parent_path();
  auto resolve_path = [&](const std::string& p) {
    if (p.empty() || fs::path(p).is_absolute()) return p;
    return (base / p).lexically_normal().generic_string();
  };

  std::vector<BatchFrame> frames;
  std::vector<std::string> errors;
  std::map<std::string, int> key_line;
  std::map<std::string, std::string> name_key;
  std::map<std::string, std::vector<int>> dup;
  for (const ManifestRow& r : m.rows) {
    try {
      // Reserved columns first: key, effect; the rest are the effect's parameters.
      std::string key, effect = o.effect;
      std::vector<std::pair<std::string, nlohmann::json>> cells;
      for (const auto& [col, v] : r.cells) {
        // Every cell ends in the frame's record and the results manifest (JSON).
        check_utf8(col, cell_where(m, r, "") + ": the column name");
        if (v.is_string()) check_utf8(v.get_ref<const std::string&>(), cell_where(m, r, col));
        const std::string c = lower(trim(col));
        if (c == "key") {
          key = cell_text(v);
        } else if (c == "effect") {
          effect = cell_text(v);
        } else {
          cells.emplace_back(col, v);
        }
      }
      if (trim(effect).empty())
        throw Error(cell_where(m, r, "") + ": no effect; add an 'effect' column or give --effect (" +
                    command_names(batchable) + ")");
      const CommandDef& e = effect_named(effect, cell_where(m, r, "effect"));
      // --param NAME=SPEC fills the columns a row does not have.
      std::vector<std::pair<std::string, nlohmann::json>> all = cells;
      // Resolve a column name to (job parameter, name hashed by the sampler).
      auto resolve = [&](const std::string& col) -> std::pair<std::string, std::string> {
        std::string n = trim(col);
        std::string prefix;  // the later stage's flag prefix when the column is prefixed with its name
        const std::string first = e.name.substr(0, e.name.find('+'));
        if (!e.stage_prefix.empty()) {
          const std::string stage = e.stage_prefix.substr(0, e.stage_prefix.size() - 1);  // "dof"
          for (const std::string sep : {".", "-", "_"})
            if (n.rfind(stage + sep, 0) == 0) {
              prefix = e.stage_prefix;
              n = n.substr(stage.size() + 1);
              break;
            }
        }
        if (prefix.empty() && n.rfind(first + ".", 0) == 0) n = n.substr(first.size() + 1);
        std::string canon;
        if (prefix.empty()) {
          canon = detail::canonical_param_name(e.specs, n, e.name);
          if (!e.stage_prefix.empty() && canon.rfind(e.stage_prefix, 0) == 0) prefix = e.stage_prefix;
        } else {
          canon = detail::canonical_param_name(e.specs, prefix + n, e.name);
        }
        const ParamSpec* sp = nullptr;
        for (const ParamSpec& s : e.specs)
          if (s.name == canon) sp = &s;
        if (is_output_file(*sp))
          throw Error("'" + col + "' is an output, named by brume batch from the key under --out-dir (maps: --map NAME)");
        const std::string hashed =
            prefix.empty() ? canon : prefix.substr(0, prefix.size() - 1) + "." + canon.substr(prefix.size());
        return {canon, hashed};
      };
      std::set<std::string> have;
      for (const auto& [col, v] : cells) have.insert(resolve(col).first);
      for (const auto& [n, s] : o.params) {
        std::pair<std::string, std::string> rn;
        try {
          rn = resolve(n);
        } catch (const Error& ex) {
          throw Error("--param " + n + "=" + s + " for effect " + e.name + ": " + ex.what());
        }
        if (!have.count(rn.first)) all.emplace_back(n, s), have.insert(rn.first);
      }

      std::vector<std::pair<std::string, nlohmann::json>> values;
      std::set<std::string> given;
      nlohmann::json specs = nlohmann::json::object(), drawn = nlohmann::json::object();
      std::string image_text;
      // The key must be known before any draw: the default key is the image as written.
      for (const auto& [col, v] : all)
        if (resolve(col).first == "image") image_text = cell_text(v);
      if (key.empty()) key = fs::path(image_text).lexically_normal().generic_string();
      if (key.empty()) throw Error(cell_where(m, r, "") + ": no 'image' column (and no key)");
      for (const auto& [col, v] : all) {
        const auto [canon, hashed] = resolve(col);
        if (!given.insert(canon).second)
          throw Error(cell_where(m, r, col) + ": the parameter '" + canon + "' is given twice");
        const ParamSpec* sp = nullptr;
        for (const ParamSpec& s : e.specs)
          if (s.name == canon) sp = &s;
        nlohmann::json value;
        try {
          if (sp->kind == ParamKind::text) {
            // Files: relative to the manifest's folder.
            std::string t = cell_text(v);
            // Files are relative to the manifest's folder: the input and depth
            // files always (a missing one is then reported where it was looked
            // for); other text (aerial's --sensitivity 'default' or a CSV, fog's
            // --table) when such a file exists there, else as written.
            const bool is_file = (sp->block == "input" || sp->block == "depth") && canon != "depth-channel";
            std::error_code fec;
            value = is_file || (!t.empty() && fs::exists(base / t, fec)) ? resolve_path(t) : t;
            sp->check(value);
          } else if (!v.is_string() && !v.is_null() && !v.is_array() && sp->kind != ParamKind::choice) {
            value = v;  // a JSON number or boolean: checked as it is
            if (sp->kind == ParamKind::integer && v.is_number_float() && std::floor(v.get<double>()) == v.get<double>())
              value = static_cast<long long>(v.get<double>());
            sp->check(value);
          } else {
            const Distribution d = parse_distribution(*sp, cell_text(v));
            if (d.kind == Distribution::Kind::fixed) {
              value = d.values.at(0);
            } else {
              value = draw(d, sample_unit(o.seed, key, hashed));
              specs[hashed] = d.text();
              drawn[hashed] = value;
            }
          }
        } catch (const Error& ex) {
          throw Error(cell_where(m, r, col) + ": " + ex.what());
        }
        values.emplace_back(canon, value);
      }

      BatchFrame f;
      f.key = key;
      f.effect = e.name;
      f.line = r.line;
      f.image = image_text.empty() ? "" : resolve_path(image_text);
      std::string stem;
      try {
        stem = output_stem(key);
      } catch (const Error& ex) {
        throw Error(cell_where(m, r, "key") + ": " + ex.what());
      }
      std::string ext = fmt.empty() ? lower(fs::path(image_text).extension().string()) : "." + fmt;
      if (!image_extensions().count(ext))
        throw Error(cell_where(m, r, "image") + ": the output would take the input's extension '" + ext +
                    "', which brume does not write; give --format");
      const fs::path od(o.out_dir);
      const std::string out = (od / (stem + ext)).generic_string();
      const std::string rec = (od / (stem + ".json")).generic_string();
      values.emplace_back("out", out);
      // PNG frames are written with `fast` (the Up filter, libdeflate's
      // level 1) unless the row or --param says otherwise: at the writer's
      // default zip:6 the encoder was the largest cost of a dataset frame
      // after the effect, for files ~6 % smaller than zip:1; rle writes
      // 1.9-2.4x faster than zip:1 and reads back 1.3-2.1x faster, for
      // files 27 % smaller to 5 % larger, and fast writes 1.2-1.5x faster
      // than rle, for files 9 % smaller to 2 % larger (io/png_direct.hpp).
      // Recorded like any value.
      if (ext == ".png" && !given.count("compression")) values.emplace_back("compression", std::string(kBatchPngCompression));
      f.outputs.push_back(out);
      for (const std::string& map : o.maps) {
        bool declared = false;
        for (const ParamSpec& s : e.specs)
          if (s.name == map && is_output_file(s) && map != "out" && map != "record")
            declared = true;
        if (!declared) {
          std::string all_maps;
          for (const ParamSpec& s : e.specs)
            if (is_output_file(s) && s.name != "out" && s.name != "record")
              all_maps += (all_maps.empty() ? "" : ", ") + s.name;
          throw Error("--map " + map + ": effect " + e.name + " has no such map; its maps: " + all_maps);
        }
        const std::string p = (od / (stem + "." + map + ".exr")).generic_string();
        values.emplace_back(map, p);
        f.outputs.push_back(p);
      }
      values.emplace_back("record", rec);
      f.outputs.push_back(rec);
      f.job = e.build(values);
      f.given = given;
      try {
        e.check(f.job, f.given, true);
        // The output's encoding (bits, compression) against its format, now
        // rather than when the frame's turn comes.
        WriteOptions wo;
        wo.bits = f.job["output"].value("bits", "auto");
        wo.compression = f.job["output"].value("compression", "auto");
        check_encoding(out, wo, "--out");
      } catch (const Error& ex) {
        throw Error(cell_where(m, r, "") + ": " + ex.what());
      }
      f.batch = {{"key", key},
                 {"effect", e.name},
                 {"seed", o.seed},
                 {"sampling", {{"sampler", kSamplerName}, {"seed", o.seed}, {"key", key}, {"specs", specs}}},
                 {"values", drawn}};
      if (key_line.count(key)) {
        dup[key].push_back(r.line);
        continue;
      }
      key_line[key] = r.line;
      const std::string name_lc = lower(stem);  // case-insensitive file systems
      if (name_key.count(name_lc))
        throw Error(cell_where(m, r, "key") + ": keys '" + name_key[name_lc] + "' and '" + key +
                    "' give the same output name '" + stem + "'; make the keys differ by more than the extension, "
                    "case or the characters mapped to '_'");
      name_key[name_lc] = key;
      frames.push_back(std::move(f));
    } catch (const Error& ex) {
      errors.push_back(ex.what());
    }
  }
  for (const auto& [key, lines] : dup) {
    std::string l = std::to_string(key_line[key]);
    for (int x : lines) l += ", " + std::to_string(x);
    errors.push_back("manifest '" + m.path + "': key '" + key + "' is on lines " + l +
                     "; keys name the outputs and must be unique (add a 'key' column)");
  }
  if (!errors.empty()) {
    std::string msg = std::to_string(errors.size()) + " manifest error" + (errors.size() > 1 ? "s" : "") +
                      " (nothing was run):";
    for (std::size_t i = 0; i < errors.size() && i < 20; ++i) msg += "\n  " + errors[i];
    if (errors.size() > 20) msg += "\n  ... and " + std::to_string(errors.size() - 20) + " more";
    throw Error(msg);
  }
  if (frames.empty()) throw Error("manifest '" + m.path + "' has no rows");
  return frames;
}

// ---- one frame ---------------------------------------------------------------------------

namespace {

void collect_inputs(const nlohmann::json& j, std::vector<std::pair<std::string, std::string>>& out) {
  if (j.is_object()) {
    if (j.contains("path") && j.contains("sha256") && j["path"].is_string() && j["sha256"].is_string())
      out.emplace_back(j["path"].get<std::string>(), j["sha256"].get<std::string>());
    for (const auto& [k, v] : j.items()) collect_inputs(v, out);
  } else if (j.is_array()) {
    for (const auto& v : j) collect_inputs(v, out);
  }
}

// Temporaries an earlier process left beside a frame's outputs (SIGKILL
// cannot be caught): .NAME.brume-tmp-PID-N. A frame belongs to one shard, so
// no other live process writes them.
void remove_stale_temporaries(const BatchFrame& f) {
  for (const std::string& o : f.outputs) {
    const fs::path p(o);
    const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    const std::string prefix = "." + p.filename().string() + ".brume-tmp-";
    for (const auto& ent : fs::directory_iterator(dir, ec))
      if (ent.path().filename().string().rfind(prefix, 0) == 0) fs::remove(ent.path(), ec);
  }
}

const CommandDef& def_of(const std::string& name) {
  if (const CommandDef* c = find_command(name); c && c->batch) return *c;
  throw Error("internal: batch effect '" + name + "'");
}

}  // namespace

bool batch_frame_done(const BatchFrame& f) {
  std::error_code ec;
  for (const std::string& o : f.outputs)
    if (!fs::is_regular_file(o, ec)) return false;
  nlohmann::json rec;
  try {
    std::ifstream in(f.outputs.back());
    rec = nlohmann::json::parse(in);
  } catch (const std::exception&) {
    return false;
  }
  if (!rec.is_object() || rec.value("job", nlohmann::json()) != f.job || rec.value("batch", nlohmann::json()) != f.batch)
    return false;
  std::vector<std::pair<std::string, std::string>> inputs;
  collect_inputs(rec.value("inputs", nlohmann::json()), inputs);
  if (inputs.empty()) return false;
  for (const auto& [path, sha] : inputs) {
    try {
      if (sha256_file(path) != sha) return false;
    } catch (const std::exception&) {
      return false;
    }
  }
  return true;
}

namespace {

// The results manifest's line for a frame.
nlohmann::json result_line(const BatchFrame& f, const BatchFrameResult& r) {
  nlohmann::json outputs = nlohmann::json::object();
  outputs["image"] = f.outputs.front();
  outputs["record"] = f.outputs.back();
  for (std::size_t i = 1; i + 1 < f.outputs.size(); ++i) outputs["maps"].push_back(f.outputs[i]);
  // The input files: the text parameters of the input and depth blocks that are set.
  nlohmann::json inputs = nlohmann::json::object();
  for (const ParamSpec& s : def_of(f.effect).specs) {
    if ((s.block != "input" && s.block != "depth") || s.kind != ParamKind::text || s.name == "depth-channel") continue;
    const nlohmann::json& v = f.job[s.block][s.name];
    if (v.is_string() && !v.get<std::string>().empty()) inputs[s.name] = v;
  }
  nlohmann::json params = nlohmann::json::object();
  // The parameters the row set (fixed and drawn), as the job holds them; a
  // chain's later stage by its stage name ("dof.focus-distance").
  const std::string& prefix = def_of(f.effect).stage_prefix;
  for (const std::string& n : f.given)
    for (const auto& [block, vals] : f.job.items())
      if (block != "input" && block != "depth" && block != "output" && vals.is_object() && vals.contains(n))
        params[!prefix.empty() && n.rfind(prefix, 0) == 0
                   ? prefix.substr(0, prefix.size() - 1) + "." + n.substr(prefix.size())
                   : n] = vals[n];
  nlohmann::json l = {{"key", f.key},        {"status", r.status},  {"effect", f.effect}, {"inputs", inputs},
                      {"outputs", outputs},  {"parameters", params}, {"sampling", f.batch["sampling"]},
                      {"seconds", r.seconds}};
  if (!r.error.empty()) l["error"] = r.error;
  return l;
}

}  // namespace

BatchFrameResult run_batch_frame(const BatchFrame& f, const ExecOptions& exec, const std::vector<std::string>& argv) {
  keep_freed_heap();  // a frame after another: the next reuses the last one's buffers
  BatchFrameResult r;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    remove_stale_temporaries(f);
    // The frame's folders are made as its outputs are written, so that a
    // frame that fails before writing leaves none behind.
    const CreateOutputFolders lazily;
    const IoThreads io(exec.threads);  // the worker's --threads bounds its codecs too
    RunContext ctx;
    ctx.argv = argv;
    ctx.given = f.given;
    ctx.extra = {{"batch", f.batch}};
    def_of(f.effect).run(f.job, exec, ctx);
    r.status = "ok";
  } catch (const std::exception& e) {
    r.status = "failed";
    r.error = e.what();
    // A failed frame leaves no output of its key behind (not even one from an
    // earlier run with other parameters): the folder never holds an output the
    // manifest no longer describes.
    std::error_code ec;
    for (const std::string& o : f.outputs) fs::remove(o, ec);
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.line = result_line(f, r);
  return r;
}

// ---- the whole run --------------------------------------------------------------------------

BatchSummary run_batch(const BatchOptions& o) {
  if (o.shard_count < 1 || o.shard_index < 1 || o.shard_index > o.shard_count)
    throw Error("--shard " + std::to_string(o.shard_index) + "/" + std::to_string(o.shard_count) +
                " is not allowed: I/N with 1 <= I <= N (I counts from 1, as Slurm's array index can)");
  if (o.workers < 0 || o.workers > 4096)
    throw Error("--workers " + std::to_string(o.workers) + " is not allowed: 0 (one per core) to 4096");
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<BatchFrame> all = plan_batch(o);
  std::vector<const BatchFrame*> frames;
  for (const BatchFrame& f : all)
    if (o.shard_count == 1 || shard_of(f.key, o.shard_count) == o.shard_index) frames.push_back(&f);
  std::error_code ec;
  fs::create_directories(o.out_dir, ec);
  if (!fs::is_directory(o.out_dir)) throw Error("--out-dir '" + o.out_dir + "' cannot be created: " + ec.message());
  check_output_dir((fs::path(o.out_dir) / "results.jsonl").string(), "--out-dir");

  const int hw = std::max(1u, std::thread::hardware_concurrency());
  const int asked = o.workers > 0 ? o.workers : hw;
  const int workers = std::max(1, std::min<int>(asked, static_cast<int>(frames.size())));
  ExecOptions exec = o.exec;
  // Results do not depend on threads; frames in flight share the cores. From
  // the workers asked for, not those a small shard uses, so that the records'
  // execution.threads is the same in every shard.
  if (exec.threads == 0) exec.threads = std::max(1, hw / asked);
  const std::vector<std::string> argv = batch_record_argv(o);

  BatchSummary s;
  s.frames = frames.size();
  std::vector<nlohmann::json> lines(frames.size());
  // The results manifest's name, and its journal: the same lines, appended
  // as frames finish (in the order they finish) and flushed one by one, so
  // that a running or killed batch shows what is done (`tail -f`). Each line
  // is one write of a whole line. The journal is removed once the manifest
  // (manifest order, written whole) is in place; a new run starts it afresh.
  const std::string name = o.shard_count == 1 ? "results.jsonl"
                                              : "results.shard-" + std::to_string(o.shard_index) + "-of-" +
                                                    std::to_string(o.shard_count) + ".jsonl";
  s.results = (fs::path(o.out_dir) / name).generic_string();
  const std::string journal_path = s.results + ".partial";
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> journal(std::fopen(journal_path.c_str(), "w"), &std::fclose);
  if (!journal)
    throw Error("--out-dir '" + o.out_dir + "': cannot create the results journal '" + journal_path +
                "': " + std::strerror(errno));
  std::atomic<std::size_t> next{0};
  std::mutex mu;
  std::size_t finished = 0, worked = 0;
  const bool tty = o.progress && isatty(STDERR_FILENO);
  auto last_print = std::chrono::steady_clock::now() - std::chrono::seconds(10);
  auto progress = [&](bool final) {
    // Rate and ETA over the frames that ran (skipped ones cost nothing).
    const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double rate = worked > 0 ? static_cast<double>(worked) / el : 0.0;
    const std::size_t left = s.frames - finished;
    char eta[32] = "?";
    if (rate > 0) std::snprintf(eta, sizeof eta, "%.0f s", static_cast<double>(left) / rate);
    char buf[256];
    std::snprintf(buf, sizeof buf, "brume batch: %zu/%zu frames (%zu ok, %zu skipped, %zu failed)  %.2f frames/s  ETA %s",
                  finished, s.frames, s.ok, s.skipped, s.failed, rate, final ? "0 s" : eta);
    if (tty) {
      const int width = 24;
      const int fill = s.frames ? static_cast<int>(width * finished / s.frames) : width;
      std::fprintf(stderr, "\r[%s%s] %s\033[K%s", std::string(fill, '#').c_str(), std::string(width - fill, '.').c_str(),
                   buf, final ? "\n" : "");
    } else {
      std::fprintf(stderr, "%s\n", buf);
    }
    std::fflush(stderr);
  };

  auto worker = [&] {
    // On a GPU backend each worker makes one context on its own thread (a
    // context belongs to the thread that made it) and runs all its frames on
    // it: a context per frame cost its creation and the compilation of every
    // pass again, per frame (README "Datasets"). Made before the first frame
    // that needs it; when it cannot be made, each frame decides as a single
    // run would (gpu: the frame fails, naming why; auto: the CPU, recorded).
    std::unique_ptr<GpuContext> gpu;
    bool gpu_tried = false;
    ExecOptions wexec = exec;
    for (;;) {
      const std::size_t i = next.fetch_add(1);
      if (i >= frames.size()) return;
      const BatchFrame& f = *frames[i];
      BatchFrameResult r;
      if (o.resume && batch_frame_done(f)) {
        r.status = "skipped";
        r.line = result_line(f, r);
      } else {
        if (exec.backend != Backend::cpu && !exec.reference && !gpu_tried) {
          gpu_tried = true;
          try {
            gpu = std::make_unique<GpuContext>();
            wexec.gpu = gpu.get();
          } catch (const Error&) {
          }
        }
        r = run_batch_frame(f, wexec, argv);
      }
      std::lock_guard<std::mutex> lock(mu);
      lines[i] = r.line;
      const std::string jl = r.line.dump() + "\n";
      std::fwrite(jl.data(), 1, jl.size(), journal.get());  // a full disk shows at the manifest's write
      std::fflush(journal.get());
      ++finished;
      if (r.status == "ok") ++s.ok, ++worked;
      if (r.status == "skipped") ++s.skipped;
      if (r.status == "failed") {
        ++s.failed, ++worked;
        // Frame, file, message: enough to find the bad input without the results file.
        std::fprintf(stderr, "%sbrume batch: frame '%s' (%s) failed: %s\n", tty ? "\r\033[K" : "", f.key.c_str(),
                     f.image.c_str(), r.error.c_str());
      }
      const auto now = std::chrono::steady_clock::now();
      // A terminal's bar is redrawn at most 10 times a second; plain lines (a log) once a second.
      if (o.progress && (now - last_print > std::chrono::milliseconds(tty ? 100 : 1000) || finished == s.frames)) {
        last_print = now;
        if (finished < s.frames) progress(false);
      }
    }
  };
  std::vector<std::thread> pool;
  for (int w = 1; w < workers; ++w) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (o.progress) progress(true);

  // The results manifest: one line per frame of this shard, in manifest
  // order, written whole at the end (a killed run leaves only the journal;
  // --resume writes it, with the frames done before as "skipped").
  std::string text;
  for (const nlohmann::json& l : lines) text += l.dump() + "\n";
  OutputSet outs;
  outs.write_text(s.results, text, "--out-dir");
  outs.commit();
  journal.reset();
  fs::remove(journal_path, ec);
  return s;
}

}  // namespace brume
