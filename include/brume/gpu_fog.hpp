// brume — the layered-fog passes on the GPU (brume/fog.hpp).
#pragma once

#include <memory>

#include "brume/depth.hpp"
#include "brume/fog.hpp"
#include "brume/gpu_context.hpp"

namespace brume {

// The layered-fog passes (brume/fog.hpp) over a colour image and a range
// map (unknown = sky) uploaded once: one fragment pass (fog_apply.frag:
// ray, optical depth, transmission, and the composite or, with lambda > 0,
// the premultiplied F0 and sigma), then for the blur the rate pass, the
// diffusion passes and haze's composite pass. Density tables hold at most
// 32 rows here (uniform arrays); longer ones are refused (use the CPU).
//
// Or over a renderer's depth buffer: the pass reads the window depth d in
// [0, 1] and linearises it itself (src/depth/depth_math.glsl, the CPU
// conversion's expression: 1/z = (1 - d) a + d b, range = z |ray|), the
// cleared value (and NaN) being sky. Values outside [0, 1] are refused as by
// `brume depth convert`. `analyse_fog` still needs the range for its
// image-wide statistics (R_max, the sky's colour).
class GpuFog : public GpuEffect {
 public:
  // sky_weight: the preparation's, for the horizon margin's blend; null or empty: none.
  GpuFog(GpuContext& ctx, DenseImageRef rgb, const Image& range, const Image* sky_weight = nullptr);
  GpuFog(GpuContext& ctx, DenseImageRef rgb, const Image& window_depth, DepthBufferConvention c, double near_m,
         double far_m);
  ~GpuFog();
  // `a` must come from analyse_fog for these inputs and `p`.
  FogResult render(const FogParams& p, const FogAnalysis& a, GpuFilter filter = GpuFilter::automatic);
  struct State;

 private:
  std::unique_ptr<State> s_;
};

}  // namespace brume
