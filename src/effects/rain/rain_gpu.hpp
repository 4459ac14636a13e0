// brume — the camera pass of the falling particles (rain's drops, snow's flakes) on the GPU: its
// per-pixel step, the scene through the analytic media (brume/rain.hpp, "Extinction counted
// once"), as haze's passes: haze's premultiply pass with the particles' optical depth
// (uParticles, haze_premultiply.frag), and with --visibility haze's rates, diffusion and
// composite, without it haze's composite alone; and their streaks' splat (rain_splat.frag: the
// CPU's splat_streaks pixel by pixel, the same taps in the same order) over that image. The
// particles' enumeration and binning stay on the CPU. Internal.
#pragma once

#include <string>
#include <vector>

#include "brume/exec.hpp"
#include "brume/gpu_context.hpp"
#include "brume/haze.hpp"
#include "brume/rain.hpp"
#include "effects/rain/streaks.hpp"

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

// The streaks' splat on the GPU (rain.splat): splat_streaks' image within float rounding. The
// streaks are binned on the CPU (bin_streaks, kStreakGpuTile pixels square: on llvmpipe 8 made
// the pass 1.6x faster than 16), uploaded with the image and the range, splatted a pixel per
// fragment and read back; `timing` takes the stages' times (binning and packing, upload, the
// pass, read back) of the last splat. Lives on the context's thread.
constexpr int kStreakGpuTile = 8;
struct StreakSplatTiming {
  bool gpu_timer = false;
  double bin_ms = 0.0, upload_ms = 0.0, splat_ms = 0.0, readback_ms = 0.0;
  std::size_t list_entries = 0;  // the tiles' lists' length, all together
};
class GpuStreakSplatter : public StreakSplatter {
 public:
  GpuStreakSplatter(GpuContext& ctx, StreakSplatTiming& timing) : ctx_(ctx), timing_(timing) {}
  StreakSplat splat(const StreakSlabs& streaks, ConstImageView range, Image& out, const StreakCamera& cam,
                    int threads) const override;

 private:
  GpuContext& ctx_;
  StreakSplatTiming& timing_;
};
nlohmann::json streak_splat_timing_record(const StreakSplatTiming& t);

// The passes `brume rain` and `brume snow` run on the GPU (CommandDef::gpu_passes), in order.
inline std::vector<std::string> streak_gpu_passes() {
  return {"haze.premultiply", "diffusion.rates", "diffusion.iterate", "haze.composite", "rain.splat"};
}

// The record's "execution" note of what ran where.
inline std::string streak_gpu_split() {
  const std::string tile = std::to_string(kStreakGpuTile);
  return "on the GPU: the analytic media's transmission, haze's blur and composite (haze.premultiply with the "
         "particles' optical depth, diffusion.rates, diffusion.iterate, haze.composite), and the streaks' splat "
         "over the image read back and uploaded again (rain.splat: each pixel takes the CPU's taps in the CPU's "
         "order, in float); on the CPU: the particles' enumeration, their order far to near and their lists by "
         "tiles of " + tile + " x " + tile + " pixels";
}

}  // namespace brume
