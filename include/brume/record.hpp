// brume — reproducible parameter records.
//
// Every run can write a JSON record of every parameter actually used, the
// derived values (iteration count, sigma_max, R_max, airlight, ...), the input
// files with their SHA-256, and the brume version, so that a dataset built
// with brume can be regenerated and audited. The same record is embedded in
// the output image's metadata (ImageDescription) where the format allows.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "brume/diffusion.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/prepare.hpp"

namespace brume {

// tool, version, command line, UTC time
nlohmann::json record_header(const std::string& command, const std::vector<std::string>& argv);

// path, size, format, bits, transfer applied, sha256
nlohmann::json file_record(const std::string& path, const FileInfo& info, const Image& img);

nlohmann::json diffusion_record(const DiffusionParams& p, const DiffusionPlan& plan);
nlohmann::json prepare_record(const PrepareParams& p, const PrepareResult& r);

}  // namespace brume
