// brume — GPU backend over headless EGL + OpenGL ES 3.2 (see brume/gpu.hpp).
//
// Schedule (Hansard §4.2): N + 2 full-screen fragment passes. Inputs are
// uploaded once per GpuHaze; F ping-pongs between two textures; the composite
// writes an RGBA32F target that is read back. Pixel (x, y) of an Image is
// texel (x, y) of its texture and fragment (x + 0.5, y + 0.5): rows are not
// flipped anywhere, so no pass needs to know which way is up.
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl32.h>
#include <GLES2/gl2ext.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "gpu/shaders_embedded.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace shaders = gpu::shaders;

struct GpuContext::Impl {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  GpuInfo info;
  GLuint vao = 0, fbo = 0;
  GLuint prog_premultiply = 0, prog_diffuse = 0, prog_composite = 0;
  PFNGLGETQUERYOBJECTUI64VEXTPROC get_query_ui64 = nullptr;

  ~Impl() {
    if (dpy != EGL_NO_DISPLAY) {
      if (ctx != EGL_NO_CONTEXT) {
        glDeleteProgram(prog_premultiply);
        glDeleteProgram(prog_diffuse);
        glDeleteProgram(prog_composite);
        glDeleteFramebuffers(1, &fbo);
        glDeleteVertexArrays(1, &vao);
        eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        eglDestroyContext(dpy, ctx);
      }
      eglTerminate(dpy);
    }
  }

  // Try one display: initialise, make an ES 3.2 context current without a surface.
  bool try_display(EGLDisplay d, const char* platform, std::string& why) {
    EGLint major = 0, minor = 0;
    if (d == EGL_NO_DISPLAY || !eglInitialize(d, &major, &minor)) {
      why += std::string(platform) + ": eglInitialize failed; ";
      return false;
    }
    eglBindAPI(EGL_OPENGL_ES_API);
    const EGLint cfg_attr[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_NONE};
    EGLConfig cfg = nullptr;
    EGLint n = 0;
    eglChooseConfig(d, cfg_attr, &cfg, 1, &n);
    const EGLint ctx_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 2, EGL_NONE};
    EGLContext c = eglCreateContext(d, n > 0 ? cfg : EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, ctx_attr);
    if (c == EGL_NO_CONTEXT) {
      why += std::string(platform) + ": no OpenGL ES 3.2 context (EGL error 0x" + hex(eglGetError()) + "); ";
      eglTerminate(d);
      return false;
    }
    if (!eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, c)) {
      why += std::string(platform) + ": cannot make the context current without a surface; ";
      eglDestroyContext(d, c);
      eglTerminate(d);
      return false;
    }
    dpy = d;
    ctx = c;
    info.platform = platform;
    return true;
  }

  static std::string hex(EGLint v) {
    char b[16];
    std::snprintf(b, sizeof b, "%x", static_cast<unsigned>(v));
    return b;
  }

  void create() {
    std::string why;
    const char* client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    const std::string ext = client ? client : "";
    auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    const char* want = std::getenv("BRUME_EGL_PLATFORM");  // device | surfaceless: force one
    // The EGL device platform (NVIDIA, and Mesa's devices): prefer hardware
    // devices over Mesa's software device.
    if (get_display && ext.find("EGL_EXT_platform_device") != std::string::npos &&
        (!want || std::string(want) == "device")) {
      auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
      auto query_device_string =
          reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(eglGetProcAddress("eglQueryDeviceStringEXT"));
      EGLDeviceEXT devices[16];
      EGLint count = 0;
      if (query_devices && query_devices(16, devices, &count)) {
        for (int pass = 0; pass < 2 && ctx == EGL_NO_CONTEXT; ++pass)
          for (int i = 0; i < count && ctx == EGL_NO_CONTEXT; ++i) {
            const char* dext = query_device_string ? query_device_string(devices[i], EGL_EXTENSIONS) : nullptr;
            const bool software = dext && std::strstr(dext, "EGL_MESA_device_software");
            if (software != (pass == 1)) continue;
            if (try_display(get_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr), "device", why))
              info.software = software;
          }
      }
    }
    if (ctx == EGL_NO_CONTEXT && get_display && ext.find("EGL_MESA_platform_surfaceless") != std::string::npos &&
        (!want || std::string(want) == "surfaceless"))
      try_display(get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr), "surfaceless", why);
    if (ctx == EGL_NO_CONTEXT)
      throw Error("no OpenGL ES 3.2 context: " + (why.empty() ? std::string("no headless EGL platform (device or Mesa surfaceless)") : why) +
                  "install Mesa (libegl-mesa0, libgl1-mesa-dri) or a GPU driver, or use --backend cpu");
    info.renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    info.version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
    for (const char* sw : {"llvmpipe", "softpipe", "SwiftShader", "swrast"})
      if (info.renderer.find(sw) != std::string::npos) info.software = true;
    GLint n = 0;
    glGetIntegerv(GL_NUM_EXTENSIONS, &n);
    for (GLint i = 0; i < n; ++i) {
      const std::string e = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, static_cast<GLuint>(i)));
      if (e == "GL_OES_texture_float_linear") info.float_linear = true;
      if (e == "GL_EXT_disjoint_timer_query") info.timer_query = true;
    }
    if (info.timer_query)
      get_query_ui64 = reinterpret_cast<PFNGLGETQUERYOBJECTUI64VEXTPROC>(eglGetProcAddress("glGetQueryObjectui64vEXT"));
    info.timer_query = info.timer_query && get_query_ui64;
    glGenVertexArrays(1, &vao);
    glGenFramebuffers(1, &fbo);
    prog_premultiply = program(shaders::premultiply_frag);
    prog_diffuse = program(shaders::diffuse_frag);
    prog_composite = program(shaders::composite_frag);
  }

  static GLuint shader(GLenum type, const std::string& src) {
    GLuint s = glCreateShader(type);
    const char* p = src.c_str();
    glShaderSource(s, 1, &p, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      char log[4096];
      glGetShaderInfoLog(s, sizeof log, nullptr, log);
      throw Error(std::string("GPU backend: shader compilation failed (a brume bug; use --backend cpu): ") + log);
    }
    return s;
  }

  static GLuint program(const char* frag_body) {
    const std::string head = "#version 320 es\nprecision highp float;\nprecision highp int;\nprecision highp sampler2D;\n#define BRUME_FN\n";
    GLuint vs = shader(GL_VERTEX_SHADER, shaders::fullscreen_vert);
    GLuint fs = shader(GL_FRAGMENT_SHADER, head + shaders::haze_math_glsl + "\n" + frag_body);
    GLuint p = glCreateProgram();
    glAttachShader(p, vs);
    glAttachShader(p, fs);
    glLinkProgram(p);
    glDeleteShader(vs);
    glDeleteShader(fs);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
      char log[4096];
      glGetProgramInfoLog(p, sizeof log, nullptr, log);
      throw Error(std::string("GPU backend: program link failed: ") + log);
    }
    return p;
  }
};

GpuContext::GpuContext() : impl_(std::make_unique<Impl>()) { impl_->create(); }
GpuContext::~GpuContext() = default;
const GpuInfo& GpuContext::info() const { return impl_->info; }

namespace {

using Clock = std::chrono::steady_clock;

GLuint make_texture(GLenum internal, int w, int h, GLenum format, GLenum type, const void* data) {
  GLuint t = 0;
  glGenTextures(1, &t);
  glBindTexture(GL_TEXTURE_2D, t);
  glTexStorage2D(GL_TEXTURE_2D, 1, internal, w, h);
  if (data) {
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, format, type, data);
  }
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_MIRRORED_REPEAT);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_MIRRORED_REPEAT);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  return t;
}

void set_filter(GLuint t, bool linear) {
  glBindTexture(GL_TEXTURE_2D, t);
  const GLint f = linear ? GL_LINEAR : GL_NEAREST;
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, f);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, f);
}

void check_gl(const char* where) {
  const GLenum e = glGetError();
  if (e != GL_NO_ERROR) {
    char b[96];
    std::snprintf(b, sizeof b, "GPU backend: OpenGL error 0x%x in %s", e, where);
    throw Error(b);
  }
}

// Stage timer: GPU time from a GL_TIME_ELAPSED_EXT query where the driver has
// one, checked against the glFinish-bracketed wall time of the same stage (a
// query can be disjoint or, as seen on llvmpipe, return garbage); the wall
// time is used when the query is missing or implausible.
struct StageTimer {
  GpuContext::Impl& g;
  GLuint q = 0;
  Clock::time_point t0;
  bool* used_query;
  StageTimer(GpuContext::Impl& gi, bool* used) : g(gi), used_query(used) {
    glFinish();
    t0 = Clock::now();
    if (g.info.timer_query) {
      glGenQueries(1, &q);
      glBeginQuery(GL_TIME_ELAPSED_EXT, q);
    }
  }
  double stop() {
    if (g.info.timer_query) glEndQuery(GL_TIME_ELAPSED_EXT);
    glFinish();
    const double wall = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    double ms = wall;
    bool ok = false;
    if (g.info.timer_query) {
      GLuint64 ns = 0;
      g.get_query_ui64(q, GL_QUERY_RESULT, &ns);
      GLint disjoint = 0;
      glGetIntegerv(GL_GPU_DISJOINT_EXT, &disjoint);
      glDeleteQueries(1, &q);
      const double gpu = ns * 1e-6;
      ok = !disjoint && gpu > 0.0 && gpu <= wall * 1.05 + 0.05;
      if (ok) ms = gpu;
    }
    *used_query = ok && (*used_query);
    return ms;
  }
};

bool use_hardware(const GpuContext::Impl& g, GpuFilter f) {
  if (f == GpuFilter::shader) return false;
  // The rate texture is RGBA32F in either precision and is filtered too, so
  // hardware filtering needs OES_texture_float_linear even for f16 (RGBA16F
  // filtering alone, which is core, is not enough).
  const bool can = g.info.float_linear;
  if (f == GpuFilter::hardware && !can)
    throw Error("--gpu-filter hardware: this GPU cannot filter RGBA32F textures (no OES_texture_float_linear), "
                "which the rate texture needs in f32 and f16; use --gpu-filter shader");
  return can;
}

void attach(GpuContext::Impl& g, GLuint t0, GLuint t1 = 0) {
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, t0, 0);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, t1, 0);
  const GLenum bufs[2] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
  glDrawBuffers(t1 ? 2 : 1, bufs);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw Error("GPU backend: the float render target is not supported by this GPU (incomplete framebuffer); use --backend cpu");
}

void bind(GLuint prog, const char* name, int unit, GLuint tex) {
  glActiveTexture(GL_TEXTURE0 + unit);
  glBindTexture(GL_TEXTURE_2D, tex);
  glUniform1i(glGetUniformLocation(prog, name), unit);
}

// N diffusion passes from f[0]; returns the index of the texture holding the result.
int run_diffusion(GpuContext::Impl& g, GLuint f[2], GLuint aux, int w, int h, int iterations, Scheme scheme,
                  EdgeRate edge, double sigma0, bool hardware) {
  set_filter(f[0], hardware);
  set_filter(f[1], hardware);
  set_filter(aux, hardware);
  glUseProgram(g.prog_diffuse);
  glUniform1i(glGetUniformLocation(g.prog_diffuse, "uScheme"), static_cast<int>(scheme));
  glUniform1f(glGetUniformLocation(g.prog_diffuse, "uSigma0"), static_cast<float>(sigma0));
  glUniform1i(glGetUniformLocation(g.prog_diffuse, "uHardware"), hardware ? 1 : 0);
  glUniform1i(glGetUniformLocation(g.prog_diffuse, "uEdgeRate"), static_cast<int>(edge));
  const GLint loc_k = glGetUniformLocation(g.prog_diffuse, "uK");
  glViewport(0, 0, w, h);
  int src = 0;
  for (int k = 0; k < iterations; ++k) {
    attach(g, f[1 - src]);
    bind(g.prog_diffuse, "uF", 0, f[src]);
    bind(g.prog_diffuse, "uAux", 1, aux);
    glUniform1i(loc_k, k);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    src = 1 - src;
  }
  set_filter(f[0], false);
  set_filter(f[1], false);
  set_filter(aux, false);
  check_gl("diffusion");
  return src;
}

void read_rgba(GpuContext::Impl& g, GLuint tex, int w, int h, std::vector<float>& out) {
  attach(g, tex);
  out.resize(static_cast<std::size_t>(w) * h * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glReadPixels(0, 0, w, h, GL_RGBA, GL_FLOAT, out.data());
  check_gl("read back");
}

}  // namespace

GpuHaze::GpuHaze(GpuContext& ctx, const Image& rgb, const Image& range) : ctx_(ctx), w_(rgb.width), h_(rgb.height) {
  if (rgb.channels != 3 || range.channels != 1 || range.width != w_ || range.height != h_)
    throw Error("GPU haze: range map " + range.size_string() + " does not match image " + rgb.size_string());
  const auto t0 = Clock::now();
  std::vector<float> px(static_cast<std::size_t>(w_) * h_ * 4, 1.0f);
  std::vector<float> r(range.pixels());
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) px[i * 4 + c] = rgb.data[i * 3 + c];
    const float v = range.data[i];
    r[i] = std::isfinite(v) && v != 0.0f ? v : -1.0f;  // unknown sentinel (see premultiply.frag)
  }
  tex_image_ = make_texture(GL_RGBA32F, w_, h_, GL_RGBA, GL_FLOAT, px.data());
  tex_range_ = make_texture(GL_R32F, w_, h_, GL_RED, GL_FLOAT, r.data());
  glFinish();
  check_gl("upload");
  timing_.upload_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

GpuHaze::~GpuHaze() {
  glDeleteTextures(1, &tex_image_);
  glDeleteTextures(1, &tex_range_);
}

HazeResult GpuHaze::render(const HazeParams& p, const HazeAnalysis& a, GpuFilter filter) {
  GpuContext::Impl& g = ctx_.impl();
  const bool f16 = p.diffusion.precision == Precision::f16;
  const GLenum fmt = f16 ? GL_RGBA16F : GL_RGBA32F;
  GLuint f[2] = {make_texture(fmt, w_, h_, GL_RGBA, GL_FLOAT, nullptr), make_texture(fmt, w_, h_, GL_RGBA, GL_FLOAT, nullptr)};
  GLuint aux = make_texture(GL_RGBA32F, w_, h_, GL_RGBA, GL_FLOAT, nullptr);
  GLuint out = make_texture(GL_RGBA32F, w_, h_, GL_RGBA, GL_FLOAT, nullptr);
  glBindVertexArray(g.vao);
  glViewport(0, 0, w_, h_);
  const bool naive = p.composite == Composite::naive;
  timing_.iterations = a.plan.iterations;
  timing_.gpu_timer = g.info.timer_query;

  StageTimer t1(g, &timing_.gpu_timer);
  attach(g, f[0], aux);
  GLuint pr = g.prog_premultiply;
  glUseProgram(pr);
  bind(pr, "uImage", 0, tex_image_);
  bind(pr, "uRange", 1, tex_range_);
  glUniform1f(glGetUniformLocation(pr, "uInvRangeMax"), static_cast<float>(1.0 / a.range_max_m));
  glUniform1f(glGetUniformLocation(pr, "uKappa"), static_cast<float>(a.kappa_a + a.kappa_s));
  glUniform1f(glGetUniformLocation(pr, "uSigma0"), static_cast<float>(p.diffusion.sigma0));
  glUniform1f(glGetUniformLocation(pr, "uSigmaMax"), static_cast<float>(a.sigma_max));
  glUniform1f(glGetUniformLocation(pr, "uIterations"), static_cast<float>(a.plan.iterations));
  glUniform1i(glGetUniformLocation(pr, "uScheme"), static_cast<int>(p.diffusion.scheme));
  glUniform1i(glGetUniformLocation(pr, "uNaive"), naive ? 1 : 0);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  check_gl("premultiply");
  timing_.premultiply_ms = t1.stop();

  StageTimer t2(g, &timing_.gpu_timer);
  const int last = run_diffusion(g, f, aux, w_, h_, a.plan.iterations, p.diffusion.scheme, p.diffusion.edge_rate, p.diffusion.sigma0,
                                 use_hardware(g, filter));
  timing_.diffuse_ms = t2.stop();

  StageTimer t3(g, &timing_.gpu_timer);
  attach(g, out);
  GLuint pc = g.prog_composite;
  glUseProgram(pc);
  bind(pc, "uF", 0, f[last]);
  bind(pc, "uAux", 1, aux);
  glUniform3f(glGetUniformLocation(pc, "uAirlight"), a.airlight[0], a.airlight[1], a.airlight[2]);
  glUniform1i(glGetUniformLocation(pc, "uNaive"), naive ? 1 : 0);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  check_gl("composite");
  timing_.composite_ms = t3.stop();

  const auto t4 = Clock::now();
  std::vector<float> o, x;
  read_rgba(g, out, w_, h_, o);
  read_rgba(g, aux, w_, h_, x);
  timing_.readback_ms = std::chrono::duration<double, std::milli>(Clock::now() - t4).count();
  HazeResult res;
  res.rgb = Image(w_, h_, 3);
  res.transmission = Image(w_, h_, 1);
  res.scale = Image(w_, h_, 1);
  for (std::size_t i = 0; i < res.rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) res.rgb.data[i * 3 + c] = o[i * 4 + c];
    res.transmission.data[i] = o[i * 4 + 3];
    res.scale.data[i] = x[i * 4 + 1];
  }
  GLuint all[4] = {f[0], f[1], aux, out};
  glDeleteTextures(4, all);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  return res;
}

DiffusionPlan diffuse_gpu(GpuContext& ctx, Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p,
                          GpuFilter filter, GpuTiming* timing) {
  const DiffusionPlan plan = validate_diffusion(f, sigma, sigma_max, p);
  GpuContext::Impl& g = ctx.impl();
  const int w = f.width, h = f.height;
  const bool f16 = p.precision == Precision::f16;
  GpuTiming t;
  t.gpu_timer = g.info.timer_query;
  t.iterations = plan.iterations;
  const auto t0 = Clock::now();
  std::vector<float> aux(f.pixels() * 4, 0.0f);
  const float s0 = static_cast<float>(p.sigma0), n = static_cast<float>(std::max(plan.iterations, 1));
  for (std::size_t i = 0; i < f.pixels(); ++i) {
    const float s = sigma.data[i];
    aux[i * 4] = p.scheme == Scheme::standard ? shared::brume_standard_rate(s, s0, n) : shared::brume_invariant_rate(s, s0, n);
    aux[i * 4 + 1] = s;
  }
  const GLenum fmt = f16 ? GL_RGBA16F : GL_RGBA32F;
  GLuint tex[2] = {make_texture(fmt, w, h, GL_RGBA, GL_FLOAT, f.data.data()), make_texture(fmt, w, h, GL_RGBA, GL_FLOAT, nullptr)};
  GLuint ta = make_texture(GL_RGBA32F, w, h, GL_RGBA, GL_FLOAT, aux.data());
  glFinish();
  t.upload_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  glBindVertexArray(g.vao);
  StageTimer st(g, &t.gpu_timer);
  const int last = run_diffusion(g, tex, ta, w, h, plan.iterations, p.scheme, p.edge_rate, p.sigma0, use_hardware(g, filter));
  t.diffuse_ms = st.stop();
  const auto t1 = Clock::now();
  std::vector<float> out;
  read_rgba(g, tex[last], w, h, out);
  t.readback_ms = std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
  std::memcpy(f.data.data(), out.data(), out.size() * sizeof(float));
  GLuint all[3] = {tex[0], tex[1], ta};
  glDeleteTextures(3, all);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (timing) *timing = t;
  return plan;
}

}  // namespace brume
