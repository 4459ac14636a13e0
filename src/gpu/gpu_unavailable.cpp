// brume — the GPU API in a build without EGL/GLES 3.2: every entry point
// reports why there is no context, so callers need no #ifdefs.
#include "brume/error.hpp"
#include "brume/gpu.hpp"

namespace brume {

namespace {
[[noreturn]] void unavailable() {
  throw Error("no OpenGL ES 3.2 context: this brume was built without the GPU backend (EGL/GLES 3.2 headers were "
              "missing at build time: apt libegl-dev libgles-dev); use --backend cpu");
}
}  // namespace

struct GpuContext::Impl {};
GpuContext::GpuContext() { unavailable(); }
GpuContext::~GpuContext() = default;
const GpuInfo& GpuContext::info() const { unavailable(); }
GpuHaze::GpuHaze(GpuContext& ctx, const Image&, const Image&) : ctx_(ctx), w_(0), h_(0) { unavailable(); }
GpuHaze::~GpuHaze() = default;
HazeResult GpuHaze::render(const HazeParams&, const HazeAnalysis&, GpuFilter) { unavailable(); }
DiffusionPlan diffuse_gpu(GpuContext&, Image&, const Image&, double, const DiffusionParams&, GpuFilter, GpuTiming*) {
  unavailable();
}

}  // namespace brume
