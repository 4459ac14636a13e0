// brume — what the files of `brume batch` share (internal): a manifest's cell
// as the text a flag takes, and where a row or cell is, for messages.
// batch_manifest.cpp defines them; batch_plan.cpp turns cells into jobs.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "brume/batch.hpp"

namespace brume::detail {

// A cell as the text a flag takes (CSV cells are text already; a JSON array
// is its items joined by ',', null is "auto", other JSON its dump).
std::string cell_text(const nlohmann::json& v);

// "manifest 'PATH' line N" and, with a column, ", column 'COL'".
std::string cell_where(const Manifest& m, const ManifestRow& r, const std::string& col);

}  // namespace brume::detail
