// brume — execution options shared by every effect (the same trailing
// argument on every apply function, as in OpenImageIO's ImageBufAlgo).
// Every effect dispatches on Exec once: the CPU's fast or reference path, or
// the GPU backend over an OpenGL ES 3.2 context.
#pragma once

#include <string>

#include "brume/params.hpp"

namespace brume {

class GpuContext;

enum class Path {
  fast,       // multithreaded, vectorised float path (default)
  reference,  // plain scalar double-precision path, kept forever as the oracle
};

enum class Backend {
  cpu,        // always available; bit-reproducible across thread counts
  gpu,        // any OpenGL ES 3.2 context, software rasterisers included (CI runs llvmpipe)
  automatic,  // the GPU only when its renderer is hardware, else the CPU (see GpuInfo::software)
};
std::string to_string(Backend b);  // cpu | gpu | auto
const EnumNames<Backend>& backend_names();

// How samples between texels are interpolated in the GPU diffusion passes.
enum class GpuFilter {
  automatic,  // hardware where float textures can be filtered linearly, else shader
  hardware,   // texture() with LINEAR + MIRRORED_REPEAT (the half-sample mirror)
  shader,     // texelFetch + mix in the shader (exact float weights)
};
std::string to_string(GpuFilter f);  // auto | hardware | shader
const EnumNames<GpuFilter>& gpu_filter_names();

struct Exec {
  int threads = 0;         // 0 = all hardware threads; results never depend on it
  Path path = Path::fast;
  Backend backend = Backend::cpu;
  GpuFilter gpu_filter = GpuFilter::automatic;
  // An existing GPU context to run on (contexts belong to the thread that
  // made them); null: the effect makes one when the backend asks for it.
  GpuContext* gpu = nullptr;
};

}  // namespace brume
