// brume — `brume batch`'s manifests: a CSV (RFC 4180 quoting) or JSON Lines
// file read into rows of cells (read_manifest), and the cell helpers the
// planner uses (batch_internal.hpp). brume/batch.hpp says what and why.
#include "brume/batch.hpp"

#include <cctype>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/text.hpp"
#include "jobs/batch_internal.hpp"

namespace fs = std::filesystem;

namespace brume {

namespace {

using text::lower;
using text::trim;

// RFC 4180 records: fields separated by ',', quoted with '"' ('""' inside
// quotes is a quote); a quoted field may span lines. Returns the records with
// the line each starts on.
std::vector<std::pair<int, std::vector<std::string>>> parse_csv(const std::string& text, const std::string& path) {
  std::vector<std::pair<int, std::vector<std::string>>> out;
  std::vector<std::string> rec;
  std::string field;
  bool quoted = false, any = false, was_quoted = false;
  int line = 1, start = 1;
  auto end_field = [&] {
    rec.push_back(was_quoted ? field : trim(field));
    field.clear();
    was_quoted = false;
  };
  auto end_record = [&] {
    end_field();
    // Blank lines and '#' comment lines are not records.
    const bool blank = rec.size() == 1 && rec[0].empty() && !any;
    const bool comment = !rec.empty() && !rec[0].empty() && rec[0][0] == '#';
    if (!blank && !comment) out.emplace_back(start, rec);
    rec.clear();
    any = false;
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (quoted) {
      if (c == '"') {
        if (i + 1 < text.size() && text[i + 1] == '"') {
          field += '"';
          ++i;
        } else {
          quoted = false;
        }
      } else {
        if (c == '\n') ++line;
        field += c;
      }
      continue;
    }
    if (c == '"' && trim(field).empty()) {
      quoted = was_quoted = any = true;
      field.clear();
    } else if (c == ',') {
      end_field();
      any = true;
    } else if (c == '\n' || c == '\r') {
      if (c == '\r' && i + 1 < text.size() && text[i + 1] == '\n') ++i;
      end_record();
      ++line;
      start = line;
    } else {
      field += c;
      if (!std::isspace(static_cast<unsigned char>(c))) any = true;
    }
  }
  if (quoted) throw Error("manifest '" + path + "' line " + std::to_string(start) + ": a quoted field is not closed");
  if (!field.empty() || !rec.empty() || any) end_record();
  return out;
}

}  // namespace

Manifest read_manifest(const std::string& path) {
  // A regular file (brume/io.hpp) of at most 1 GiB: ~5 M rows of 200 bytes,
  // beyond any dataset brume's scans write (KITTI's 7 481 frames: 1.2 MB).
  const std::string text =
      read_input_file(path, "--manifest", {1ull << 30, "a manifest of a few million frames"});
  Manifest m;
  m.path = path;
  const std::string ext = lower(fs::path(path).extension().string());
  if (ext == ".csv") {
    m.format = "csv";
  } else if (ext == ".jsonl" || ext == ".ndjson" || ext == ".json") {
    m.format = "jsonl";
  } else {
    const std::string t = trim(text);
    m.format = !t.empty() && t[0] == '{' ? "jsonl" : "csv";
  }
  if (m.format == "jsonl") {
    std::istringstream ls(text);
    std::string l;
    int line = 0;
    while (std::getline(ls, l)) {
      ++line;
      const std::string t = trim(l);
      if (t.empty() || t[0] == '#') continue;
      nlohmann::json j;
      try {
        j = nlohmann::json::parse(t);
      } catch (const nlohmann::json::exception& e) {
        throw Error("manifest '" + path + "' line " + std::to_string(line) + " is not JSON: " + e.what());
      }
      if (!j.is_object())
        throw Error("manifest '" + path + "' line " + std::to_string(line) +
                    ": a JSON Lines manifest holds one object per line ({\"image\": ..., ...}), got " + j.dump());
      ManifestRow r;
      r.line = line;
      for (const auto& [k, v] : j.items()) r.cells.emplace_back(k, v);
      m.rows.push_back(std::move(r));
    }
    return m;
  }
  const auto recs = parse_csv(text, path);
  if (recs.empty()) throw Error("manifest '" + path + "' is empty; a CSV manifest needs a header row (key,image,...)");
  const std::vector<std::string>& header = recs[0].second;
  std::set<std::string> seen;
  for (const std::string& h : header) {
    if (h.empty()) throw Error("manifest '" + path + "': the header has an empty column name");
    if (!seen.insert(h).second) throw Error("manifest '" + path + "': the header names column '" + h + "' twice");
  }
  for (std::size_t i = 1; i < recs.size(); ++i) {
    const auto& [line, fields] = recs[i];
    if (fields.size() != header.size())
      throw Error("manifest '" + path + "' line " + std::to_string(line) + " has " + std::to_string(fields.size()) +
                  " fields, the header " + std::to_string(header.size()) +
                  "; quote a value that holds a comma (\"loguniform(50, 5000)\")");
    ManifestRow r;
    r.line = line;
    for (std::size_t c = 0; c < header.size(); ++c)
      if (!fields[c].empty()) r.cells.emplace_back(header[c], fields[c]);
    m.rows.push_back(std::move(r));
  }
  return m;
}

namespace detail {

// A cell as the text a flag takes (CSV cells are text already).
std::string cell_text(const nlohmann::json& v) {
  if (v.is_string()) return v.get<std::string>();
  if (v.is_array()) {
    std::string s;
    for (const auto& x : v) {  // (appended in two steps: GCC 12's -Wrestrict misfires on "," + string&&)
      if (!s.empty()) s += ',';
      s += x.is_string() ? x.get<std::string>() : x.dump();
    }
    return s;
  }
  if (v.is_null()) return "auto";
  return v.dump();
}

std::string cell_where(const Manifest& m, const ManifestRow& r, const std::string& col) {
  return "manifest '" + m.path + "' line " + std::to_string(r.line) + (col.empty() ? "" : ", column '" + col + "'");
}

}  // namespace detail

}  // namespace brume
