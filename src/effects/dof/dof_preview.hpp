// brume — depth of field's preview steps, for the previews that join them
// (brume/preview.hpp): haze+dof's plan is haze's plan, then these steps on its
// result (src/effects/dof/chain/chain_pipeline.cpp).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "brume/dof.hpp"
#include "brume/preview.hpp"

namespace brume {

// Depth of field's steps appended to `frame`, on the plan's texture `input`:
// the scale map from the CoC (a map of the frame, formed on the host as
// run_dof_prepared's GPU path forms it), copied into target PREFIX0,
// diffused with PREFIX1 into the alias `last`. Returns the stage's derived
// values (sigma_max_px, coc_infinity_px, iterations).
nlohmann::json dof_preview_steps(PreviewFrame& frame, const DofParams& p, const Intrinsics& k, const PreviewInputs& in,
                                 const std::string& input, const std::string& prefix, const std::string& last);
// Throws dof_intrinsics' message when neither the depth flags nor the lens
// give the camera (a check before any pixel; the size is not known yet).
void check_dof_camera(const DepthSource& src);
// Where the preview's page starts on a scene (CommandDef::preview_start);
// `camera_given`: the depth flags give the intrinsics; `p` carries the depth
// source's lens (dof_with_lens).
std::vector<PreviewStart> dof_preview_start(const DofParams& p, bool camera_given, const PreviewScene& s);
// The parameter of depth of field that --scene-scale scales.
const std::vector<std::string>& dof_scene_lengths();

}  // namespace brume
