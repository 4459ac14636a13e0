// brume — `brume batch`'s planner: a manifest's rows made into frames
// (plan_batch). Each column is looked up in its effect's job table through
// the list of commands, a value is parsed or drawn by the sampler, the key
// names the outputs, and every row is checked before any frame runs. Also
// the effects a row can name, shards, and a frame as JSON and back (the Dask
// runner's). brume/batch.hpp says what and why.
#include "brume/batch.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"
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

// ---- the effects a row can name --------------------------------------------------------

// The commands a row can name: the batchable ones of the list of commands
// (brume/command.hpp), each with its job table, build, check and run.
bool is_batchable(const CommandDef& c) { return c.batchable; }

const CommandDef& effect_named(const std::string& name, const std::string& where) {
  std::string n = lower(trim(name));
  n.erase(std::remove_if(n.begin(), n.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); }),
          n.end());
  if (const CommandDef* c = find_command(n); c && c->batchable) return *c;
  throw Error(where + ": effect '" + name + "' is not available in brume batch; use one of: " +
              command_names(is_batchable) + " (chains: '+'-joined stages, the later stages' parameters prefixed with their name: dof.focus-distance)");
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
      if (c.batchable) n.push_back(c.name);
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
                    command_names(is_batchable) + ")");
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
            // An input whose output a declaration names (a camera effect's --lidar) is a file too.
            const bool is_file = is_input_file(*sp) ||
                                 std::any_of(e.specs.begin(), e.specs.end(),
                                             [&name = canon](const ParamSpec& s) { return s.output_of == name; });
            std::error_code fec;
            const std::string& pre = sp->input_file_prefix;
            if (!pre.empty())  // a file only after its prefix (table:FILE): that part is relative to the manifest
              value = t.rfind(pre, 0) == 0 ? pre + resolve_path(t.substr(pre.size())) : t;
            else
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
      // PNG frames are written with `fast` (the Up filter, run-length
      // deflate; io/formats/png.cpp) unless the row or --param says
      // otherwise: at zip:6 the encoder is the largest cost of a dataset
      // frame after the effect. Recorded like any value.
      if (ext == ".png" && !given.count("compression")) values.emplace_back("compression", std::string(kBatchPngCompression));
      f.outputs.push_back(out);
      for (const std::string& map : o.maps) {
        bool declared = false;
        for (const ParamSpec& s : e.specs)
          if (s.name == map && is_output_file(s) && s.output_of.empty() && map != "out" && map != "record")
            declared = true;
        if (!declared) {
          std::string all_maps;
          for (const ParamSpec& s : e.specs)
            if (is_output_file(s) && s.output_of.empty() && s.name != "out" && s.name != "record")
              all_maps += (all_maps.empty() ? "" : ", ") + s.name;
          throw Error("--map " + map + ": effect " + e.name + " has no such map; its maps: " + all_maps);
        }
        const std::string p = (od / (stem + "." + map + ".exr")).generic_string();
        values.emplace_back(map, p);
        f.outputs.push_back(p);
      }
      // Outputs that come with an input the row gives (a camera effect's
      // foggy scan with its --lidar): <name><ext> beside the image.
      for (const ParamSpec& s : e.specs)
        if (is_output_file(s) && !s.output_of.empty() && given.count(s.output_of)) {
          const std::string p = (od / (stem + s.output_ext)).generic_string();
          values.emplace_back(s.name, p);
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

}  // namespace brume
