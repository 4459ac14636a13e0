// brume study — entry point of `brume study` (the accuracy/speed study of the
// diffusion engine against its peers). Not part of the installed library.
#pragma once

#include <string>

// what: the study to run ("diffusion"); out_dir: directory for the CSV, PNG
// and Markdown outputs (created if missing); quick: a small, fast variant;
// backend: "cpu", "gpu" or "all"; image_path: the accuracy image ("" = the
// mosaic of ../shared/data photographs); part: "all", or "leakage" for the
// leakage experiment alone (leakage.csv and leakage.png). Returns the process exit status;
// throws brume::Error on bad arguments or unreadable inputs.
int run_study(const std::string& what, const std::string& out_dir, bool quick, const std::string& backend,
              const std::string& image_path, const std::string& part = "all");
