// brume — the aerial-perspective passes on the GPU (brume/aerial.hpp).
#pragma once

#include <memory>

#include "brume/aerial.hpp"
#include "brume/gpu_context.hpp"

namespace brume {

// The aerial passes (brume/aerial.hpp) over a colour image and a range map
// uploaded once: the Gamma table(s) as N x 1 RGBA32F textures read with the
// CPU's own interpolation in ln Gamma (AttenuationTable::at), a premultiply
// pass writing the six channels as two RGBA targets F0 = (rho E', rho_r),
// F1 = (rho_g, rho_b, 0, 0), the rate pass and the diffusion passes on both
// with the same rates, and a composite pass. Render, re-render and remove.
class GpuAerial : public GpuEffect {
 public:
  GpuAerial(GpuContext& ctx, DenseImageRef rgb, const Image& range);
  ~GpuAerial();
  // `a` must come from analyse_aerial for these inputs and `p`.
  AerialResult render(const AerialParams& p, const AerialAnalysis& a, GpuFilter filter = GpuFilter::automatic);
  struct State;

 private:
  std::unique_ptr<State> s_;
};

}  // namespace brume
