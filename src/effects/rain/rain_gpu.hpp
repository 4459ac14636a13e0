// brume — the camera pass of the falling particles (rain's drops, snow's flakes) on the GPU: its
// per-pixel step, the scene through the analytic media (brume/rain.hpp, "Extinction counted
// once"), as haze's passes: haze's premultiply pass with the particles' optical depth
// (uParticles, haze_premultiply.frag), and with --visibility haze's rates, diffusion and
// composite, without it haze's composite alone. The streaks' enumeration and splat stay on the
// CPU, over the image read back. Internal.
#pragma once

#include <string>
#include <vector>

#include "brume/exec.hpp"
#include "brume/gpu_context.hpp"
#include "brume/haze.hpp"
#include "brume/rain.hpp"

namespace brume {

// The scene `s` through haze's medium (s.haze_sigma_per_m) and the particles' analytic part
// (`optics`) as streak_background makes it on the CPU: haze's airlight (s.airlight), its sky
// rule (transmission 0 where the range is unknown and there is a medium, blended by
// s.sky_weight); with `blur`, haze's scattering blur of `hp` (its diffusion and composite) with
// `ha`'s scale (its sigma_max, R_max, plan). `transmission`: the per-pixel transmission τ0.
// The passes' times go to `timing`.
Image streak_background_gpu(GpuContext& ctx, const CameraRainScene& s, const CameraRainOptics& optics,
                            const HazeParams& hp, const HazeAnalysis& ha, bool blur, GpuFilter filter,
                            Image* transmission, GpuTiming& timing);

// The passes `brume rain` and `brume snow` run on the GPU (CommandDef::gpu_passes), in order.
inline std::vector<std::string> streak_gpu_passes() {
  return {"haze.premultiply", "diffusion.rates", "diffusion.iterate", "haze.composite"};
}

// The record's "execution" note of what ran where (the splat on the CPU).
inline const char* streak_gpu_split() {
  return "on the GPU: the analytic media's transmission, haze's blur and composite (haze.premultiply with the "
         "particles' optical depth, diffusion.rates, diffusion.iterate, haze.composite); on the CPU: the "
         "particles' enumeration and their streaks' splat over the image read back";
}

}  // namespace brume
