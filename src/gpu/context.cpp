// brume — the GPU context over headless EGL + OpenGL ES 3.2, the program
// cache and the texture/target plumbing every pass shares (src/gpu/context.hpp).
#if BRUME_HAVE_GPU  // a build without EGL/GLES compiles gpu_unavailable.cpp instead
#include "gpu/context.hpp"

#include <atomic>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {
namespace shaders = gpu::shaders;

namespace {

// The shared topic files a pass can declare (the families' *_math.glsl), by name:
// generated from the brume_part() declarations (CMakeLists.txt).
struct Topic {
  const char* name;
  const char* text;
};
constexpr Topic kTopics[] = {
#include "gpu/topics.inc"
};

std::string hex(unsigned v) {
  char b[16];
  std::snprintf(b, sizeof b, "%x", v);
  return b;
}

void compile(const gl::Shader& s, const std::string& src, const char* pass) {
  const char* p = src.c_str();
  glShaderSource(s.id(), 1, &p, nullptr);
  glCompileShader(s.id());
  GLint ok = 0;
  glGetShaderiv(s.id(), GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetShaderInfoLog(s.id(), sizeof log, nullptr, log);
    throw Error(std::string("GPU backend: shader of pass '") + pass +
                "' failed to compile (a brume bug; use --backend cpu): " + log);
  }
}

}  // namespace

GpuObjectCounts gpu_live_objects() {
  GpuObjectCounts c;
  c.textures = gl::live(gl::kTexture);
  c.framebuffers = gl::live(gl::kFramebuffer);
  c.programs = gl::live(gl::kProgram);
  c.queries = gl::live(gl::kQuery);
  c.samplers = gl::live(gl::kSampler);
  c.vertex_arrays = gl::live(gl::kVertexArray);
  return c;
}

// ---------------------------------------------------------------- context

namespace {
// EGL hands out one EGLDisplay per device (or platform) and process, and
// eglTerminate ends it for every context on it (no reference count before
// EGL_KHR_display_reference): two GpuContexts on one device -- a batch's
// workers, an application's two renderers -- share it, so the first one
// destroyed would leave the other unable to render ("cannot render to the
// float texture (framebuffer status 0x0)"). Initialisations are counted here
// and the display is terminated when the last context lets it go.
std::mutex g_displays_mu;
std::map<EGLDisplay, int> g_displays;

bool acquire_display(EGLDisplay d) {
  std::lock_guard<std::mutex> lock(g_displays_mu);
  EGLint major = 0, minor = 0;
  if (d == EGL_NO_DISPLAY || !eglInitialize(d, &major, &minor)) return false;
  ++g_displays[d];
  return true;
}

void release_display(EGLDisplay d) {
  std::lock_guard<std::mutex> lock(g_displays_mu);
  auto it = g_displays.find(d);
  if (it == g_displays.end()) return;
  if (--it->second == 0) {
    g_displays.erase(it);
    eglTerminate(d);
  }
}
}  // namespace

GpuContext::Impl::~Impl() {
  if (dpy == EGL_NO_DISPLAY) return;
  if (ctx != EGL_NO_CONTEXT) {
    programs.clear();
    nearest.reset();
    linear.reset();
    vao.reset();
    eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(dpy, ctx);
  }
  release_display(dpy);
  // The context that was current before this one, again (it may be gone: then EGL refuses, and none is current).
  if (prev.ctx != EGL_NO_CONTEXT) prev.make();
}

// Try one display: initialise, make an ES 3.2 context current without a surface.
bool GpuContext::Impl::try_display(EGLDisplay d, const char* platform, std::string& why) {
  if (!acquire_display(d)) {
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
    why += std::string(platform) + ": no OpenGL ES 3.2 context (EGL error 0x" + hex(static_cast<unsigned>(eglGetError())) +
           "); ";
    release_display(d);
    return false;
  }
  if (!eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, c)) {
    why += std::string(platform) + ": cannot make the context current without a surface; ";
    eglDestroyContext(d, c);
    release_display(d);
    return false;
  }
  dpy = d;
  ctx = c;
  info.platform = platform;
  return true;
}

void GpuContext::Impl::create() {
  prev = gl::Current::now();
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
    throw GpuUnavailable("no OpenGL ES 3.2 context: " +
                (why.empty() ? std::string("no headless EGL platform (device or Mesa surfaceless); ") : why) +
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
  vao = gl::VertexArray::make();
  nearest = gl::Sampler::make();
  linear = gl::Sampler::make();
  for (GLuint s : {nearest.id(), linear.id()}) {
    const GLint f = s == linear.id() ? GL_LINEAR : GL_NEAREST;
    glSamplerParameteri(s, GL_TEXTURE_MIN_FILTER, f);
    glSamplerParameteri(s, GL_TEXTURE_MAG_FILTER, f);
    glSamplerParameteri(s, GL_TEXTURE_WRAP_S, GL_MIRRORED_REPEAT);
    glSamplerParameteri(s, GL_TEXTURE_WRAP_T, GL_MIRRORED_REPEAT);
  }
  gpu::check_gl("context creation");
}

const gpu::Program& GpuContext::Impl::program(const gpu::PassSpec& spec) {
  if (auto it = programs.find(spec.name); it != programs.end()) return *it->second;
  const std::string fs = gpu::fragment_source(spec);
  gl::Shader vs(GL_VERTEX_SHADER), frag(GL_FRAGMENT_SHADER);
  compile(vs, gpu::vertex_source(), spec.name);
  compile(frag, fs, spec.name);
  gl::Program p = gl::Program::make();
  glAttachShader(p.id(), vs.id());
  glAttachShader(p.id(), frag.id());
  glLinkProgram(p.id());
  GLint ok = 0;
  glGetProgramiv(p.id(), GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096];
    glGetProgramInfoLog(p.id(), sizeof log, nullptr, log);
    throw Error(std::string("GPU backend: program of pass '") + spec.name + "' failed to link (a brume bug): " + log);
  }
  // Sampler i takes texture unit i (GLSL ES 3.00 has no layout(binding)).
  glUseProgram(p.id());
  const std::vector<std::string> samplers = gpu::sampler_names(spec.body);
  for (std::size_t i = 0; i < samplers.size(); ++i) {
    const GLint loc = glGetUniformLocation(p.id(), samplers[i].c_str());
    if (loc >= 0) glUniform1i(loc, static_cast<GLint>(i));
  }
  glUseProgram(0);
  auto prog = std::make_unique<gpu::Program>(std::move(p), spec.name);
  return *programs.emplace(spec.name, std::move(prog)).first->second;
}

void GpuContext::Impl::begin(const gpu::Target& t) const {
  glBindVertexArray(vao.id());
  t.bind();
  glViewport(0, 0, t.width, t.height);
}

namespace {
std::atomic<std::uint64_t> g_contexts_made{0};
}  // namespace
std::uint64_t gpu_contexts_made() { return g_contexts_made.load(std::memory_order_relaxed); }

GpuContext::GpuContext() : impl_(std::make_unique<Impl>()) {
  impl_->create();
  g_contexts_made.fetch_add(1, std::memory_order_relaxed);
}
GpuContext::~GpuContext() = default;
const GpuInfo& GpuContext::info() const { return impl_->info; }
GpuContext::Impl& GpuContext::impl() {
  Impl& i = *impl_;
  if (i.ctx != EGL_NO_CONTEXT && eglGetCurrentContext() != i.ctx && !gl::Current{i.dpy, i.ctx}.make())
    throw Error("GPU backend: cannot make this GPU context current on the calling thread (EGL error 0x" +
                hex(static_cast<unsigned>(eglGetError())) +
                "; a context belongs to one thread at a time): use it on the thread that made it, or --backend cpu");
  return i;
}

namespace gpu {

// ---------------------------------------------------------------- pass sources

std::string fragment_source(const PassSpec& spec) {
  std::string fs = "#version 300 es\nprecision highp float;\nprecision highp int;\nprecision highp sampler2D;\n"
                   "#define BRUME_FN\n#define BRUME_STENCIL_FN\n#define BRUME_IN(T) in T\n#define brume_vec vec4\n"
                   "#define brume_weight float\n";
  for (const char* topic : spec.topics) {
    const Topic* found = nullptr;
    for (const Topic& t : kTopics)
      if (std::strcmp(t.name, topic) == 0) found = &t;
    if (!found)
      throw Error(std::string("GPU backend: pass '") + spec.name + "' needs unknown shared topic '" + topic +
                  "' (a brume bug: declare it in its part's brume_part(... TOPICS) in CMakeLists.txt)");
    fs += found->text;
    fs += "\n";
  }
  fs += spec.body;
  return fs;
}

const char* vertex_source() { return shaders::fullscreen_vert; }

std::vector<std::string> sampler_names(const char* body) {
  // `uniform [precision] sampler2D NAME;` at the start of a line, in order.
  std::vector<std::string> names;
  const std::string b = body;
  std::size_t pos = 0;
  while ((pos = b.find("sampler2D ", pos)) != std::string::npos) {
    const std::size_t line = b.rfind('\n', pos);
    const std::string head = b.substr(line == std::string::npos ? 0 : line + 1, pos - (line == std::string::npos ? 0 : line + 1));
    pos += 10;
    if (head.rfind("uniform ", 0) != 0) continue;  // a function parameter, not a declaration
    std::size_t e = pos;
    while (e < b.size() && (std::isalnum(static_cast<unsigned char>(b[e])) || b[e] == '_')) ++e;
    names.push_back(b.substr(pos, e - pos));
  }
  return names;
}

namespace {
std::vector<const PassSpec*>& pass_registry() {
  static std::vector<const PassSpec*> r;
  return r;
}
}  // namespace

PassRegistration::PassRegistration(std::initializer_list<const PassSpec*> specs) {
  for (const PassSpec* s : specs) pass_registry().push_back(s);
}

const PassSpec* find_pass(std::string_view name) {
  for (const PassSpec* s : pass_registry())
    if (name == s->name) return s;
  return nullptr;
}

// ---------------------------------------------------------------- programs

Program::Program(gl::Program p, std::string name) : prog_(std::move(p)), name_(std::move(name)) {
  GLint count = 0;
  glGetProgramiv(prog_.id(), GL_ACTIVE_UNIFORMS, &count);
  for (GLint i = 0; i < count; ++i) {
    char buf[256];
    GLsizei len = 0;
    GLint size = 0;
    GLenum type = 0;
    glGetActiveUniform(prog_.id(), static_cast<GLuint>(i), sizeof buf, &len, &size, &type, buf);
    std::string n(buf, static_cast<std::size_t>(len));
    if (n.size() > 3 && n.compare(n.size() - 3, 3, "[0]") == 0) n.resize(n.size() - 3);
    locations_[n] = glGetUniformLocation(prog_.id(), n.c_str());
  }
}

GLint Program::loc(const char* uniform) const {
  auto it = locations_.find(uniform);
  if (it == locations_.end())
    throw Error("GPU backend: pass '" + name_ + "' has no active uniform '" + uniform + "' (a brume bug)");
  return it->second;
}

// ---------------------------------------------------------------- textures and targets

BoundTextures::BoundTextures(std::initializer_list<GLuint> ids) : count_(static_cast<int>(ids.size())) {
  int unit = 0;
  for (GLuint id : ids) {
    glActiveTexture(GL_TEXTURE0 + unit++);
    glBindTexture(GL_TEXTURE_2D, id);
  }
}

BoundTextures::~BoundTextures() {
  for (int unit = count_ - 1; unit >= 0; --unit) {
    glActiveTexture(GL_TEXTURE0 + unit);
    glBindTexture(GL_TEXTURE_2D, 0);
  }
}

gl::Texture make_texture(GLenum internal, int w, int h, GLenum format, GLenum type, const void* data) {
  gl::Texture t = gl::Texture::make();
  glBindTexture(GL_TEXTURE_2D, t.id());
  glTexStorage2D(GL_TEXTURE_2D, 1, internal, w, h);
  if (data) {
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, format, type, data);
  }
  // Sampled through texelFetch (or the diffusion pass's own samplers); NEAREST
  // keeps the one-level texture complete for either.
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  check_gl("texture allocation");
  return t;
}

void Target::bind() const { glBindFramebuffer(GL_FRAMEBUFFER, fbo.id()); }

Target make_target(std::initializer_list<GpuTexture> colour) {
  Target t;
  t.fbo = gl::Framebuffer::make();
  t.width = colour.begin()->width;
  t.height = colour.begin()->height;
  glBindFramebuffer(GL_FRAMEBUFFER, t.fbo.id());
  GLenum bufs[4];
  GLsizei n = 0;
  for (const GpuTexture& c : colour) {
    bufs[n] = GL_COLOR_ATTACHMENT0 + static_cast<GLenum>(n);
    glFramebufferTexture2D(GL_FRAMEBUFFER, bufs[n], GL_TEXTURE_2D, c.id, 0);
    ++n;
  }
  glDrawBuffers(n, bufs);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (status != GL_FRAMEBUFFER_COMPLETE)
    throw Error("GPU backend: this GPU cannot render to the float texture (framebuffer status 0x" + hex(status) +
                "); use --backend cpu");
  return t;
}

ColorAndRange upload_color_and_range(DenseImageRef rgb, const Image& range, const char* what, double* upload_ms) {
  const auto t0 = Clock::now();
  const int w = rgb.width, h = rgb.height;
  if (rgb.channels != 3 || range.channels != 1 || range.width != w || range.height != h)
    throw Error(std::string("GPU ") + what + ": range map " + range.size_string() + " does not match image " +
                rgb.size_string());
  std::vector<float> px(static_cast<std::size_t>(w) * h * 4, 1.0f);
  ColorAndRange c;
  c.range_host.resize(range.pixels());
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    for (int k = 0; k < 3; ++k) px[i * 4 + k] = rgb.data[i * 3 + k];
    const float v = range.data[i];
    c.range_host[i] = std::isfinite(v) && v != 0.0f ? v : -1.0f;
  }
  c.image = make_texture(GL_RGBA32F, w, h, GL_RGBA, GL_FLOAT, px.data());
  c.range = make_texture(GL_R32F, w, h, GL_RED, GL_FLOAT, c.range_host.data());
  glFinish();
  *upload_ms = ms_since(t0);
  return c;
}

gl::Texture upload_sky_weight(const Image* sky_weight, int w, int h, const char* what, double* upload_ms) {
  if (!sky_weight || sky_weight->empty()) return {};
  if (sky_weight->channels != 1 || sky_weight->width != w || sky_weight->height != h)
    throw Error(std::string("GPU ") + what + ": sky weight " + sky_weight->size_string() + " does not match the image " +
                std::to_string(w) + "x" + std::to_string(h));
  const auto t0 = Clock::now();
  gl::Texture t = make_texture(GL_R32F, w, h, GL_RED, GL_FLOAT, sky_weight->data.data());
  glFinish();
  *upload_ms += ms_since(t0);
  return t;
}

std::vector<float> read_rgba(GpuTexture tex) {
  Target t = make_target({tex});
  t.bind();
  std::vector<float> out(static_cast<std::size_t>(tex.width) * tex.height * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  // RGBA/FLOAT is the read format every float colour buffer accepts.
  glReadPixels(0, 0, tex.width, tex.height, GL_RGBA, GL_FLOAT, out.data());
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  check_gl("read back");
  return out;
}

void check_gl(const char* where) {
  const GLenum e = glGetError();
  if (e != GL_NO_ERROR) throw Error(std::string("GPU backend: OpenGL error 0x") + hex(e) + " in " + where);
}

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// ---------------------------------------------------------------- timing

StageTimer::StageTimer(GpuContext::Impl& g, bool* used_query) : g_(g), used_query_(used_query) {
  glFinish();
  t0_ = Clock::now();
  if (g_.info.timer_query) {
    q_ = gl::Query::make();
    glBeginQuery(GL_TIME_ELAPSED_EXT, q_.id());
    running_ = true;
  }
}

StageTimer::~StageTimer() {
  // Only one time query may be active: end an abandoned one before the next
  // stage (or render) begins its own.
  if (running_) glEndQuery(GL_TIME_ELAPSED_EXT);
}

double StageTimer::stop() {
  if (running_) glEndQuery(GL_TIME_ELAPSED_EXT);
  running_ = false;
  glFinish();
  const double wall = ms_since(t0_);
  double ms = wall;
  bool ok = false;
  if (q_) {
    GLuint64 ns = 0;
    g_.get_query_ui64(q_.id(), GL_QUERY_RESULT, &ns);
    GLint disjoint = 0;
    glGetIntegerv(GL_GPU_DISJOINT_EXT, &disjoint);
    q_.reset();
    const double gpu = static_cast<double>(ns) * 1e-6;
    ok = !disjoint && gpu > 0.0 && gpu <= wall * 1.05 + 0.05;
    if (ok) ms = gpu;
  }
  *used_query_ = ok && *used_query_;
  return ms;
}

}  // namespace gpu

// ---------------------------------------------------------------- GpuImage

namespace {
GLenum float_format(int channels, Precision p) {
  const bool h = p == Precision::f16;
  switch (channels) {
    case 1: return h ? GL_R16F : GL_R32F;
    case 2: return h ? GL_RG16F : GL_RG32F;
    case 4: return h ? GL_RGBA16F : GL_RGBA32F;
    default:
      throw Error("GpuImage: " + std::to_string(channels) +
                  " channels cannot be a float render target; use 1, 2 or 4 (to_rgba for RGB)");
  }
}
GLenum pixel_format(int channels) { return channels == 1 ? GL_RED : channels == 2 ? GL_RG : GL_RGBA; }
}  // namespace

GpuImage::GpuImage(GpuContext& ctx, int width, int height, int channels, Precision storage) : channels_(channels) {
  (void)ctx.impl();  // textures belong to the current context: ctx's, made current here
  if (width <= 0 || height <= 0)
    throw Error("GpuImage: size " + std::to_string(width) + "x" + std::to_string(height) + " must be positive");
  gl::Texture t = gpu::make_texture(float_format(channels, storage), width, height);
  egl_display_ = t.owner().dpy;
  egl_context_ = t.owner().ctx;
  tex_ = {t.release(), width, height};
}

GpuImage::GpuImage(GpuContext& ctx, const Image& img, Precision storage) : channels_(img.channels) {
  (void)ctx.impl();
  if (img.width <= 0 || img.height <= 0) throw Error("GpuImage: image " + img.size_string() + " is empty");
  gl::Texture t = gpu::make_texture(float_format(img.channels, storage), img.width, img.height,
                                    pixel_format(img.channels), GL_FLOAT, img.data.data());
  egl_display_ = t.owner().dpy;
  egl_context_ = t.owner().ctx;
  tex_ = {t.release(), img.width, img.height};
}

GpuImage::GpuImage(GpuImage&& o) noexcept
    : tex_(std::exchange(o.tex_, {})), channels_(o.channels_), egl_display_(o.egl_display_), egl_context_(o.egl_context_) {}

GpuImage& GpuImage::operator=(GpuImage&& o) noexcept {
  // o takes our texture and deletes it when it goes.
  std::swap(tex_, o.tex_);
  std::swap(channels_, o.channels_);
  std::swap(egl_display_, o.egl_display_);
  std::swap(egl_context_, o.egl_context_);
  return *this;
}

GpuImage::~GpuImage() {
  if (tex_.id) {
    const gl::AsCurrent in(gl::Current{egl_display_, egl_context_});
    if (in.ok()) glDeleteTextures(1, &tex_.id);
    --gl::live(gl::kTexture);
    tex_ = {};
  }
}

Image GpuImage::read() const {
  const gl::AsCurrent in(gl::Current{egl_display_, egl_context_});  // its own context, whichever is current
  if (!in.ok())
    throw Error("GpuImage::read: the context it was made in cannot be made current here (destroyed, or current "
                "on another thread); read it on its own thread while its GpuContext lives");
  const std::vector<float> px = gpu::read_rgba(tex_);
  Image out(tex_.width, tex_.height, channels_);
  for (std::size_t i = 0; i < out.pixels(); ++i)
    for (int c = 0; c < channels_; ++c) out.data[i * channels_ + c] = px[i * 4 + c];
  return out;
}

}  // namespace brume
#endif  // BRUME_HAVE_GPU
