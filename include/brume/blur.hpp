// brume — the diffusion engine as a command: a Gaussian (constant target
// scale) or a space-variant blur (a scale map) of a colour image, in the
// pipeline shape of every effect (brume/pipeline.hpp; the job from files to
// files is the library's, src/effects/blur/blur_job.hpp).
//
// With a constant --sigma S the result is a Gaussian of sqrt(S^2 - sigma0^2)
// per axis (diffusion cannot sharpen: S < sigma0 is an error, never a clamp).
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/diffusion.hpp"
#include "brume/image.hpp"

namespace brume {

// In memory (the Python module's brume.blur): `rgb` is any view of linear RGB
// pixels (a numpy array, an RGBA buffer's RGB) read in place -- the only copy
// is the engine's own working buffer (RGB for a constant scale in f32 on the
// CPU, else RGBA), which becomes the result; either a constant `sigma` or a
// per-pixel `scale_map` (1 channel, rgb's size, px), not both. Checks as
// `brume blur` (sigma >= sigma0). Pixels equal `brume blur`'s bit for bit.
struct BlurRun {
  Image rgb;              // linear RGB, 3 channels
  DiffusionPlan plan;
  nlohmann::json record;  // {"diffusion", "execution", "effective_gaussian_px" | "sigma_px"}
};
BlurRun run_blur(ConstImageView rgb, std::optional<double> sigma, const Image* scale_map, const DiffusionParams& dp,
                 const Exec& exec = {});
// The same for an image the caller gives up (3 channels): where the engine
// works on RGB rows it blurs that buffer itself, with no copy (`brume blur`
// hands over the decoded file). The same pixels as the view form.
BlurRun run_blur(Image&& rgb, std::optional<double> sigma, const Image* scale_map, const DiffusionParams& dp,
                 const Exec& exec = {});

}  // namespace brume
