// brume — GPU backend: the haze pipeline as OpenGL ES 3.2 fragment passes
// over a headless EGL context (Hansard §4.2): one premultiply pass, N
// diffusion passes ping-ponging between two full-resolution RGBA32F (f32) or
// RGBA16F (f16) textures, one composite pass. The per-pixel maths is
// src/shared/haze_math.glsl, the same text the CPU backend compiles as C++.
//
// Context: EGL's Mesa surfaceless platform (llvmpipe in CI, any Mesa driver)
// or the EGL device platform (NVIDIA), no window system. All calls must come
// from the thread that created the GpuContext.
#pragma once

#include <memory>
#include <string>

#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/haze.hpp"
#include "brume/image.hpp"

namespace brume {

struct GpuInfo {
  std::string platform;  // "surfaceless" or "device"
  std::string renderer;  // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string version;   // GL_VERSION
  bool float_linear = false;  // OES_texture_float_linear: hardware filtering of RGBA32F
  bool timer_query = false;   // EXT_disjoint_timer_query
  // A software rasteriser (Mesa llvmpipe/softpipe, SwiftShader): --backend
  // auto does not pick it, because it measured 1.7-30x slower than the CPU
  // backend (README, GPU timings); --backend gpu still runs on it.
  bool software = false;
};

// Per-pass times of the last render: GPU time from timer queries where
// available, otherwise glFinish-bracketed wall time.
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
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

// The haze passes over a colour image and a range map uploaded once: change
// the parameters and call render() again without re-uploading (the paper's
// interactive control).
class GpuHaze {
 public:
  GpuHaze(GpuContext& ctx, const Image& rgb, const Image& range);
  ~GpuHaze();
  HazeResult render(const HazeParams& p, const HazeAnalysis& a, GpuFilter filter = GpuFilter::automatic);
  const GpuTiming& timing() const { return timing_; }

 private:
  GpuContext& ctx_;
  int w_, h_;
  unsigned tex_image_ = 0, tex_range_ = 0;
  GpuTiming timing_;
};

// The diffusion engine alone on the GPU (same contract as brume::diffuse).
DiffusionPlan diffuse_gpu(GpuContext& ctx, Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p,
                          GpuFilter filter = GpuFilter::automatic, GpuTiming* timing = nullptr);

}  // namespace brume
