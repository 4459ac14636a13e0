// brume — effects' preview stages that a chain's preview joins
// (brume/preview.hpp): haze+dof's plan is haze's plan, then depth of field's
// steps on its result.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "brume/dof.hpp"
#include "brume/haze.hpp"
#include "brume/preview.hpp"

namespace brume {

// Haze's whole plan (GpuHaze::render's passes): result "out".
nlohmann::json haze_preview_plan(const HazeParams& p, const PreviewInputs& in);

// Depth of field's steps appended to `plan`, on the plan's texture `input`:
// the scale map from the CoC (a map of the plan's "data", formed on the host
// as run_dof_prepared's GPU path forms it, named by its contents), copied
// into target PREFIX0, diffused with PREFIX1 into the alias `last`. Returns
// the stage's derived values (sigma_max_px, coc_infinity_px, iterations).
nlohmann::json dof_preview_steps(nlohmann::json& plan, const DofParams& p, const Intrinsics& k, const PreviewInputs& in,
                                 const std::string& input, const std::string& prefix, const std::string& last);
// That scale map, when `name` is its name (else an Error).
Image dof_preview_map(const std::string& name, const DofParams& p, const Intrinsics& k, const PreviewInputs& in);

}  // namespace brume
