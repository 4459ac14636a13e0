// brume — the GPU backend's ground: a headless OpenGL ES 3.2 context over
// EGL, textures, and the diffusion engine as passes (Hansard §4.2): one rate
// pass (sigma -> rho, R32F) and N diffusion passes ping-ponging between two
// full-resolution RGBA32F (f32) or RGBA16F (f16) textures. The per-pixel
// maths is src/diffusion/diffusion_math.glsl, the same text the CPU backend
// compiles as C++. No effect is named here: each effect's passes have their
// own header over GpuEffect (brume/gpu_haze.hpp, gpu_aerial.hpp, gpu_fog.hpp,
// gpu_sky.hpp; brume/gpu.hpp includes them all).
//
// Two levels: the engine over Images (diffuse_gpu), and the engine as passes
// over textures (gpu_diffusion_rates, gpu_diffuse_textures) for a renderer
// that already holds its frame on the GPU; GpuImage uploads and reads back
// textures for callers without GL code.
//
// Context: EGL's Mesa surfaceless platform (llvmpipe in CI, any Mesa driver)
// or the EGL device platform (NVIDIA), no window system. All calls must come
// from the thread that created the GpuContext.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"

namespace brume {

struct GpuInfo {
  std::string platform;  // "surfaceless" or "device"
  std::string renderer;  // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string version;   // GL_VERSION
  bool float_linear = false;  // OES_texture_float_linear: hardware filtering of 32-bit float textures
  bool timer_query = false;   // EXT_disjoint_timer_query
  // A software rasteriser (Mesa llvmpipe/softpipe, SwiftShader): --backend
  // auto does not pick it, because it measured 1.7-30x slower than the CPU
  // backend (README, GPU timings); --backend gpu still runs on it.
  bool software = false;
};

// Per-pass times of the last render: GPU time from timer queries where
// available, otherwise glFinish-bracketed wall time. The rate pass (sigma ->
// rho) counts in premultiply_ms for haze and in diffuse_ms for diffuse_gpu.
struct GpuTiming {
  bool gpu_timer = false;
  double upload_ms = 0.0, premultiply_ms = 0.0, diffuse_ms = 0.0, composite_ms = 0.0, readback_ms = 0.0;
  int iterations = 0;
};

class GpuContext {
 public:
  GpuContext();  // throws brume::Error("no OpenGL ES 3.2 context: ... use --backend cpu")
  ~GpuContext();
  GpuContext(const GpuContext&) = delete;
  GpuContext& operator=(const GpuContext&) = delete;
  const GpuInfo& info() const;
  struct Impl;
  // The context's state for the passes, made current on the calling thread
  // first when another context was made current there since (a second
  // GpuContext created or destroyed on this thread: a batch's, a test's).
  Impl& impl();

 private:
  std::unique_ptr<Impl> impl_;
};

// GL objects brume holds right now, by kind, over every context of the
// process (contexts, GpuHaze, GpuImage, and the temporaries of a render):
// a render that throws must leave these as they were before it.
struct GpuObjectCounts {
  int textures = 0, framebuffers = 0, programs = 0, queries = 0, samplers = 0, vertex_arrays = 0;
  bool operator==(const GpuObjectCounts&) const = default;
};
GpuObjectCounts gpu_live_objects();
// GpuContexts this process has made so far (constructions that succeeded,
// the ones a call makes for itself when given none included): how a test
// sees that a batch worker's frames share one context.
std::uint64_t gpu_contexts_made();

// A texture as the pass layer sees it: a GL texture name on the context's
// thread and its size in texels. The caller owns it (or a GpuImage does).
struct GpuTexture {
  unsigned id = 0;
  int width = 0, height = 0;
};

// A texture brume owns: an Image uploaded, or an uninitialised render target;
// read() returns it as an Image with the same channel count. Channels 1, 2, 4
// are stored R32F, RG32F, RGBA32F (RGBA16F for 4 channels in f16: every value
// rounded to binary16 on upload, as the diffusion passes store it).
// Move-only; read and deleted in the context it was made in, whichever
// context is current then (that one is current again after), on the
// context's thread and before the GpuContext goes.
class GpuImage {
 public:
  GpuImage(GpuContext& ctx, const Image& img, Precision storage = Precision::f32);
  GpuImage(GpuContext& ctx, int width, int height, int channels, Precision storage = Precision::f32);
  GpuImage(GpuImage&& o) noexcept;
  GpuImage& operator=(GpuImage&& o) noexcept;
  GpuImage(const GpuImage&) = delete;
  GpuImage& operator=(const GpuImage&) = delete;
  ~GpuImage();
  GpuTexture texture() const { return tex_; }
  int channels() const { return channels_; }
  Image read() const;

 private:
  GpuTexture tex_;
  int channels_ = 0;
  void* egl_display_ = nullptr;  // the context it was made in, where its texture is deleted
  void* egl_context_ = nullptr;
};

// Pass: the per-pixel diffusion rate rho(x) (eq. 13 standard, eq. 18
// invariant schemes) into rates.r from the target scale sigma(x) in sigma.r
// (px). This pass is the one place the GPU computes rates, for GpuHaze,
// diffuse_gpu and any caller. `rates` must be colour-renderable float (R32F
// is enough) and sigma's size. The sigma values are on the GPU and are not
// checked: keep them in [p.sigma0, plan.sigma_max] (validate_diffusion checks
// an Image on the host). `plan` must be plan_diffusion(p, plan.sigma_max).
void gpu_diffusion_rates(GpuContext& ctx, GpuTexture sigma, GpuTexture rates, const DiffusionParams& p,
                         const DiffusionPlan& plan);

// The diffusion engine on textures the caller owns: plan.iterations passes of
// eq. 11 ping-ponging from f_ping (the input; four channels, RGBA32F, or
// RGBA16F for p.precision == f16) through f_pong, with rates from
// gpu_diffusion_rates. The result is in f_ping when the iteration count is
// even, else in f_pong; *result_index (when not null) says which: 0 or 1.
// The other texture holds the previous iteration. Every texture must be
// size-equal and distinct; the pass samples through its own samplers, so the
// textures' filter and wrap parameters are neither needed nor changed.
// Throws brume::Error on mismatched sizes, a plan that does not match p, or
// hardware filtering where the GPU cannot filter float textures.
DiffusionPlan gpu_diffuse_textures(GpuContext& ctx, GpuTexture f_ping, GpuTexture f_pong, GpuTexture rates,
                                   const DiffusionParams& p, const DiffusionPlan& plan,
                                   GpuFilter filter = GpuFilter::automatic, int* result_index = nullptr);

// The diffusion engine alone on the GPU (same contract as brume::diffuse).
DiffusionPlan diffuse_gpu(GpuContext& ctx, Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p,
                          GpuFilter filter = GpuFilter::automatic, GpuTiming* timing = nullptr);


// What every effect's passes hold (upload a frame once, render it many
// times): the context they run on, the frame's size and the
// last render's per-pass times. An effect's class adds its GL state (State,
// defined in its src/gpu file) and its render().
class GpuEffect {
 public:
  GpuEffect(const GpuEffect&) = delete;
  GpuEffect& operator=(const GpuEffect&) = delete;
  const GpuTiming& timing() const { return timing_; }

 protected:
  // (the context made current on this thread before the derived class uploads)
  GpuEffect(GpuContext& ctx, int width, int height) : ctx_(ctx), w_(width), h_(height) { (void)ctx.impl(); }
  ~GpuEffect() = default;
  GpuContext& ctx_;
  int w_, h_;
  GpuTiming timing_;
};

// Thrown by every entry point of a build without the GPU backend.
[[noreturn]] void gpu_unavailable();

}  // namespace brume
