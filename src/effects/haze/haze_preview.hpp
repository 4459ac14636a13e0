// brume — haze's preview frame, for the previews that join it (brume/preview.hpp):
// haze+dof's plan is haze's plan, then depth of field's steps on its result
// (src/effects/dof/chain/chain_pipeline.cpp).
#pragma once

#include "brume/haze.hpp"
#include "brume/preview.hpp"

namespace brume {

// Haze's whole frame (GpuHaze::render's passes): result "out".
PreviewFrame haze_preview_frame(const HazeParams& p, const PreviewInputs& in);
// Where the preview's page starts on a scene (CommandDef::preview_start).
std::vector<PreviewStart> haze_preview_start(const HazeParams& p, const std::set<std::string>& given,
                                             const PreviewScene& s);
// The parameters of haze that --scene-scale scales.
const std::vector<std::string>& haze_scene_lengths();

}  // namespace brume
