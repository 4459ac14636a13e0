// brume — the GPU context and the diffusion passes in a build without EGL/GLES
// 3.2: every entry point reports why there is no context, so callers need no
// #ifdefs (each family's *_gpu.cpp has its own stubs).
#if !BRUME_HAVE_GPU  // the build with EGL/GLES compiles context.cpp and the passes instead
#include "brume/error.hpp"
#include "brume/gpu_context.hpp"

namespace brume {

struct GpuContext::Impl {};
GpuContext::GpuContext() { gpu_unavailable(); }
GpuContext::~GpuContext() = default;
const GpuInfo& GpuContext::info() const { gpu_unavailable(); }
GpuContext::Impl& GpuContext::impl() { gpu_unavailable(); }
GpuObjectCounts gpu_live_objects() { return {}; }  // nothing can have been made
std::uint64_t gpu_contexts_made() { return 0; }
GpuImage::GpuImage(GpuContext&, const Image&, Precision) { gpu_unavailable(); }
GpuImage::GpuImage(GpuContext&, int, int, int, Precision) { gpu_unavailable(); }
GpuImage::GpuImage(GpuImage&&) noexcept {}
GpuImage& GpuImage::operator=(GpuImage&&) noexcept { return *this; }
GpuImage::~GpuImage() = default;
Image GpuImage::read() const { gpu_unavailable(); }
void gpu_diffusion_rates(GpuContext&, GpuTexture, GpuTexture, const DiffusionParams&, const DiffusionPlan&) {
  gpu_unavailable();
}
DiffusionPlan gpu_diffuse_textures(GpuContext&, GpuTexture, GpuTexture, GpuTexture, const DiffusionParams&,
                                   const DiffusionPlan&, GpuFilter, int*) {
  gpu_unavailable();
}
DiffusionPlan diffuse_gpu(GpuContext&, Image&, const Image&, double, const DiffusionParams&, GpuFilter, GpuTiming*) {
  gpu_unavailable();
}

}  // namespace brume
#endif  // !BRUME_HAVE_GPU
