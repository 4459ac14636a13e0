// brume — the haze passes on the GPU (brume/haze.hpp, Hansard §4.2): premultiply, rates,
// diffusion and composite over a frame uploaded once.
#pragma once

#include <memory>

#include "brume/gpu_context.hpp"
#include "brume/haze.hpp"

namespace brume {

// The haze passes over a colour image and a range map uploaded once: change
// the parameters and call render() again without re-uploading (the paper's
// interactive control).
class GpuHaze : public GpuEffect {
 public:
  // sky_weight: the preparation's (brume/prepare.hpp), uploaded when the
  // sky lies beyond the medium (HazeAnalysis::sky_beyond); null: none.
  GpuHaze(GpuContext& ctx, const Image& rgb, const Image& range, const Image* sky_weight = nullptr);
  ~GpuHaze();
  // Render targets are kept between renders (remade when the precision
  // changes); `a` must come from analyse_haze for these inputs and `p`.
  HazeResult render(const HazeParams& p, const HazeAnalysis& a, GpuFilter filter = GpuFilter::automatic);
  struct State;

 private:
  std::unique_ptr<State> s_;
};

}  // namespace brume
