// brume — the GPU API in a build without EGL/GLES 3.2: every entry point
// reports why there is no context, so callers need no #ifdefs.
#include "brume/error.hpp"
#include "brume/gpu.hpp"

namespace brume {

namespace {
[[noreturn]] void unavailable() {
  throw GpuUnavailable("no OpenGL ES 3.2 context: this brume was built without the GPU backend (EGL/GLES 3.2 headers were "
              "missing at build time: apt libegl-dev libgles-dev); use --backend cpu");
}
}  // namespace

struct GpuContext::Impl {};
struct GpuHaze::State {};
struct GpuAerial::State {};
struct GpuFog::State {};
GpuContext::GpuContext() { unavailable(); }
GpuContext::~GpuContext() = default;
const GpuInfo& GpuContext::info() const { unavailable(); }
GpuObjectCounts gpu_live_objects() { return {}; }  // nothing can have been made
std::uint64_t gpu_contexts_made() { return 0; }
GpuImage::GpuImage(GpuContext&, const Image&, Precision) { unavailable(); }
GpuImage::GpuImage(GpuContext&, int, int, int, Precision) { unavailable(); }
GpuImage::GpuImage(GpuImage&&) noexcept {}
GpuImage& GpuImage::operator=(GpuImage&&) noexcept { return *this; }
GpuImage::~GpuImage() = default;
Image GpuImage::read() const { unavailable(); }
void gpu_diffusion_rates(GpuContext&, GpuTexture, GpuTexture, const DiffusionParams&, const DiffusionPlan&) {
  unavailable();
}
DiffusionPlan gpu_diffuse_textures(GpuContext&, GpuTexture, GpuTexture, GpuTexture, const DiffusionParams&,
                                   const DiffusionPlan&, GpuFilter, int*) {
  unavailable();
}
GpuHaze::GpuHaze(GpuContext& ctx, const Image&, const Image&) : ctx_(ctx), w_(0), h_(0) { unavailable(); }
GpuHaze::~GpuHaze() = default;
HazeResult GpuHaze::render(const HazeParams&, const HazeAnalysis&, GpuFilter) { unavailable(); }
GpuAerial::GpuAerial(GpuContext& ctx, DenseImageRef, const Image&) : ctx_(ctx), w_(0), h_(0) { unavailable(); }
GpuAerial::~GpuAerial() = default;
AerialResult GpuAerial::render(const AerialParams&, const AerialAnalysis&, GpuFilter) { unavailable(); }
GpuFog::GpuFog(GpuContext& ctx, DenseImageRef, const Image&) : ctx_(ctx), w_(0), h_(0) { unavailable(); }
GpuFog::~GpuFog() = default;
FogResult GpuFog::render(const FogParams&, const FogAnalysis&, GpuFilter) { unavailable(); }
Image render_sky_gpu(GpuContext&, const SkyRenderParams&, const SkyDirection&, const SkyGeometry&, GpuTiming*) {
  unavailable();
}
DiffusionPlan diffuse_gpu(GpuContext&, Image&, const Image&, double, const DiffusionParams&, GpuFilter, GpuTiming*) {
  unavailable();
}

}  // namespace brume
