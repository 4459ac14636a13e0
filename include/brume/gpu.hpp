// brume — the whole GPU backend in one include: the context and the
// diffusion engine (brume/gpu_context.hpp) and every effect's passes. Code
// below the effects includes gpu_context.hpp alone; an effect includes its own
// header.
#pragma once

#include "brume/gpu_aerial.hpp"
#include "brume/gpu_context.hpp"
#include "brume/gpu_fog.hpp"
#include "brume/gpu_haze.hpp"
#include "brume/gpu_sky.hpp"
