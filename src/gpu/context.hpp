// brume — the GPU pass layer (private to src/gpu): the context, its program
// cache, render targets and stage timers. An effect on the GPU is a set of
// passes: each pass is a fragment shader body (<family>_<pass>.frag in the family's folder) run
// over one full-screen triangle, plus the list of shared topic files
// (the families' *_math.glsl) whose per-pixel maths it calls. Adding an effect means
// writing its passes and their PassSpecs, not copying this plumbing.
//
// Conventions every pass follows: pixel (x, y) of an Image is texel (x, y) of
// its texture and fragment (x + 0.5, y + 0.5) — rows are never flipped, so no
// pass needs to know which way is up; a pass's samplers take texture units
// in the order it declares them (set once with glUniform1i when the program
// is linked: GLSL ES 3.00 has no layout(binding)), value uniforms through
// locations cached at link.
//
// Every pass is GLSL ES 3.00 (`#version 300 es`: no layout(binding), texture
// gather, image load/store or compute), so that one source serves this ES 3.2
// context and WebGL2 in the browser preview (`brume view`, docs/view.md),
// which takes the same text from fragment_source().
#pragma once

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl32.h>

// gl2ext.h after gl32.h: it needs GL_APIENTRYP (EXT_disjoint_timer_query).
#include <GLES2/gl2ext.h>

#include <array>
#include <chrono>
#include <functional>
#include <initializer_list>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "brume/gpu_context.hpp"
#include "gpu/gl.hpp"
#include "gpu/passes.hpp"

namespace brume {
namespace gpu {

// A linked program and its active uniforms' locations, found once at link.
class Program {
 public:
  Program(gl::Program p, std::string name);
  GLuint id() const { return prog_.id(); }
  // The location of an active uniform; a name the shader does not use is a
  // brume bug (a typo, or a uniform the compiler dropped) and throws, rather
  // than silently setting nothing.
  GLint loc(const char* uniform) const;

 private:
  gl::Program prog_;
  std::string name_;
  std::map<std::string, GLint, std::less<>> locations_;
};

// A framebuffer with its colour attachments fixed: attached, draw buffers set
// and completeness checked once, when it is made; a pass then only binds it.
struct Target {
  gl::Framebuffer fbo;
  int width = 0, height = 0;
  void bind() const;
};
Target make_target(std::initializer_list<GpuTexture> colour);

// A texture with immutable storage (one level). data: width * height texels
// of `format`/`type`, or null for a render target.
gl::Texture make_texture(GLenum internal, int w, int h, GLenum format = GL_RGBA, GLenum type = GL_FLOAT,
                         const void* data = nullptr);

// An effect's inputs on the GPU: linear RGB as RGBA32F (alpha 1) and the
// range as R32F with unknown (NaN, inf, 0) mapped to -1, because GLSL
// compilers may fold isnan() away. Checks the sizes; `what` names the effect.
struct ColorAndRange {
  gl::Texture image, range;
  std::vector<float> range_host;  // the uploaded range values (-1 = unknown)
};
// Finishes the upload (glFinish) and stores its wall time in *upload_ms.
ColorAndRange upload_color_and_range(DenseImageRef rgb, const Image& range, const char* what, double* upload_ms);
// The preparation's sky weight (brume/prepare.hpp) as R32F, its upload time
// added to *upload_ms; an empty texture (id 0) for null or an empty image.
gl::Texture upload_sky_weight(const Image* sky_weight, int w, int h, const char* what, double* upload_ms);

// A pass's input textures bound to units 0, 1, ... in order (an id of 0
// leaves its unit empty), unbound (the last unit first) when the pass ends.
class BoundTextures {
 public:
  explicit BoundTextures(std::initializer_list<GLuint> ids);
  ~BoundTextures();
  BoundTextures(const BoundTextures&) = delete;
  BoundTextures& operator=(const BoundTextures&) = delete;

 private:
  int count_;
};

// Reads `tex` (any float colour format) back as RGBA floats, w * h * 4.
std::vector<float> read_rgba(GpuTexture tex);

// Throws brume::Error naming `where` if GL has recorded an error.
void check_gl(const char* where);

}  // namespace gpu

struct GpuContext::Impl {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  // What was current on the creating thread before (another GpuContext's, or
  // an application's): made current again when this one is destroyed.
  gl::Current prev;
  GpuInfo info;
  PFNGLGETQUERYOBJECTUI64VEXTPROC get_query_ui64 = nullptr;
  // The GL objects below must go before the context: members are destroyed
  // after ~Impl's body, so the body releases them first.
  gl::VertexArray vao;
  // Samplers for the diffusion passes, bound to their texture units so that
  // the caller's own texture parameters are neither needed nor changed:
  // MIRRORED_REPEAT is exactly the half-sample mirror boundary; `linear`
  // filters in hardware, `nearest` serves texelFetch (which ignores
  // filtering but needs a complete texture, which NEAREST guarantees).
  gl::Sampler nearest, linear;
  std::map<std::string, std::unique_ptr<gpu::Program>, std::less<>> programs;

  ~Impl();
  void create();
  bool try_display(EGLDisplay d, const char* platform, std::string& why);

  // The program of a pass, compiled and linked on first use.
  const gpu::Program& program(const gpu::PassSpec& spec);
  // Binds the empty VAO and the target, sets the viewport: ready to draw().
  void begin(const gpu::Target& t) const;
  static void draw() { glDrawArrays(GL_TRIANGLES, 0, 3); }
};

namespace gpu {

using Clock = std::chrono::steady_clock;

// Stage timer: GPU time from a GL_TIME_ELAPSED_EXT query where the driver has
// one, checked against the glFinish-bracketed wall time of the same stage (a
// query can be disjoint or, as seen on llvmpipe, return garbage); the wall
// time is used when the query is missing or implausible. The query is owned,
// so a stage that throws leaves none behind.
class StageTimer {
 public:
  StageTimer(GpuContext::Impl& g, bool* used_query);
  ~StageTimer();
  double stop();

 private:
  GpuContext::Impl& g_;
  gl::Query q_;
  Clock::time_point t0_;
  bool* used_query_;
  bool running_ = false;
};

// The textures of a premultiplied scattering blur (Hansard), shared by every
// effect that blurs by scattering (haze, fog): the effect's own first pass
// draws into `first` -- the premultiplied colour F0 into f[0] and its
// per-pixel terms into aux, sigma in aux.x for the rate pass -- and
// scatter_rates / scatter_diffuse_composite finish: sigma -> rates, the N
// diffusion passes, and haze's composite out = F.rgb + (1 - F.a) B (eq. 4).
// Made on the first render and remade when the precision changes.
struct ScatterTargets {
  Precision precision = Precision::f32;
  int w = 0, h = 0;
  gl::Texture f[2], aux, rates, out;
  Target first, composite;
  int last = 0;  // which of f[] holds the diffused colour
  void ensure(int width, int height, Precision p, GLenum aux_format);
};
void scatter_rates(GpuContext& ctx, ScatterTargets& s, const DiffusionParams& d, const DiffusionPlan& plan);
// The effect's first pass, drawn into s.first (haze's premultiply, fog's
// pass): the colour on texture unit 0, the range on 1, the sky weight on 2
// where `sky_blend` and one was uploaded (uSkyBlend says which); `uniforms`
// sets the pass's own. With `rates`, the rate pass follows (scatter_rates).
// Timed into timing.premultiply_ms; `what` names the pass in GL errors.
void scatter_first_pass(GpuContext& ctx, ScatterTargets& s, const PassSpec& pass, const char* what,
                        const ColorAndRange& in, const gl::Texture& sky_weight, bool sky_blend,
                        const std::function<void(const Program&)>& uniforms, const DiffusionParams& d,
                        const DiffusionPlan& plan, bool rates, GpuTiming& timing);
// The diffusion and the composite, timed into timing.diffuse_ms and composite_ms.
void scatter_diffuse_composite(GpuContext& ctx, ScatterTargets& s, const DiffusionParams& d, const DiffusionPlan& plan,
                               GpuFilter filter, const std::array<float, 3>& airlight, bool naive, GpuTiming& timing);
// Haze's composite alone, of f[last] (no blur: f[0] with last = 0), timed into timing.composite_ms.
void scatter_composite(GpuContext& ctx, ScatterTargets& s, const std::array<float, 3>& airlight, bool naive,
                       GpuTiming& timing);

double ms_since(Clock::time_point t0);

}  // namespace gpu
}  // namespace brume
