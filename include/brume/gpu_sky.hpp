// brume — the Preetham sky in one GPU pass (brume/sky.hpp).
#pragma once

#include <memory>

#include "brume/gpu_context.hpp"
#include "brume/sky.hpp"

namespace brume {

// The Preetham sky (brume/sky.hpp) in one fragment pass: the same image as
// render_sky (same conventions, NaN or --ground below the horizon, the disc
// when p.sun_disc) to float rounding -- the pass evaluates the gamma term
// directly where the CPU interpolates a per-image table (RMS difference
// <= 1e-3 relative, tests/test_sky.cpp). Times land in timing->composite_ms
// (the pass) and readback_ms.
Image render_sky_gpu(GpuContext& ctx, const SkyRenderParams& p, const SkyDirection& sun, const SkyGeometry& g,
                     GpuTiming* timing = nullptr);

}  // namespace brume
