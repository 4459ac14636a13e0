// brume — the diffusion engine as GPU passes (Hansard §3, §4.2): the rate
// pass (sigma -> rho) and N ping-pong passes of eq. 11, over textures the
// caller owns; diffuse_gpu is their user for Images.
//
// Rates are made on the GPU, by one pass, for every caller. The host could
// compute them for diffuse_gpu (it has sigma as an Image), but GpuHaze's
// sigma depends on the render's parameters and exists only on the GPU (the
// premultiply pass makes it from the uploaded range), and so does a
// renderer's; a host path would cost haze a readback and re-upload per render.
#if BRUME_HAVE_GPU  // a build without EGL/GLES: src/gpu/gpu_unavailable.cpp
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {
namespace {

const gpu::PassSpec kRatesPass{"diffusion.rates", {"diffusion_math"}, gpu::shaders::diffusion_rates_frag};
const gpu::PassSpec kDiffusePass{"diffusion.iterate", {"diffusion_math"}, gpu::shaders::diffusion_iterate_frag};
const gpu::PassRegistration kDiffusionPasses{&kRatesPass, &kDiffusePass};

std::string describe(GpuTexture t) {
  return "texture " + std::to_string(t.id) + " (" + std::to_string(t.width) + "x" + std::to_string(t.height) + ")";
}

// A texture argument must name a texture of the stated size: GL would
// otherwise render garbage or nothing without an error.
void check_texture(GpuTexture t, const char* role, const char* fn) {
  if (t.id == 0 || !glIsTexture(t.id))
    throw Error(std::string(fn) + ": " + role + " " + describe(t) + " is not a texture of this context; pass a texture "
                "made on the GpuContext's thread (GpuImage::texture(), or your renderer's)");
  glBindTexture(GL_TEXTURE_2D, t.id);
  GLint w = 0, h = 0;
  glGetTexLevelParameteriv(GL_TEXTURE_2D, 0, GL_TEXTURE_WIDTH, &w);
  glGetTexLevelParameteriv(GL_TEXTURE_2D, 0, GL_TEXTURE_HEIGHT, &h);
  if (w != t.width || h != t.height || w <= 0)
    throw Error(std::string(fn) + ": " + role + " " + describe(t) + " is " + std::to_string(w) + "x" + std::to_string(h) +
                " on the GPU; give its true size");
}

void check_same_size(GpuTexture a, GpuTexture b, const char* role_b, const char* fn) {
  if (a.width != b.width || a.height != b.height)
    throw Error(std::string(fn) + ": " + role_b + " " + describe(b) + " does not match the image size " +
                std::to_string(a.width) + "x" + std::to_string(a.height) + "; give textures of one size");
}

// The rates and offsets are functions of N, so a plan from other parameters
// would diffuse to the wrong scale without any visible failure.
void check_plan(const DiffusionParams& p, const DiffusionPlan& plan, const char* fn) {
  if (!(p.sigma0 > 0.0) || !std::isfinite(p.sigma0))
    throw Error(std::string(fn) + ": sigma0 " + std::to_string(p.sigma0) + " px must be finite and > 0");
  const DiffusionPlan want = plan_diffusion(p, plan.sigma_max);
  if (plan.iterations != want.iterations)
    throw Error(std::string(fn) + ": the plan's " + std::to_string(plan.iterations) + " iterations do not match " +
                std::to_string(want.iterations) + " for these parameters at sigma_max " + std::to_string(plan.sigma_max) +
                " px; pass plan_diffusion(params, sigma_max) (or the plan analyse_haze made for these parameters)");
}

bool use_hardware(const GpuContext::Impl& g, GpuFilter f) {
  if (f == GpuFilter::shader) return false;
  // The rate texture is 32-bit float in either precision and is filtered
  // too, so hardware filtering needs OES_texture_float_linear even for f16
  // (RGBA16F filtering alone, which is core, is not enough).
  const bool can = g.info.float_linear;
  if (f == GpuFilter::hardware && !can)
    throw Error("--gpu-filter hardware: this GPU cannot filter 32-bit float textures (no OES_texture_float_linear), "
                "which the rate texture needs in f32 and f16; use --gpu-filter shader");
  return can;
}

}  // namespace

void gpu_diffusion_rates(GpuContext& ctx, GpuTexture sigma, GpuTexture rates, const DiffusionParams& p,
                         const DiffusionPlan& plan) {
  const char* fn = "gpu_diffusion_rates";
  check_texture(sigma, "sigma", fn);
  check_texture(rates, "rates", fn);
  check_same_size(sigma, rates, "rates", fn);
  if (sigma.id == rates.id) throw Error(std::string(fn) + ": sigma and rates are one texture; give two");
  check_plan(p, plan, fn);
  GpuContext::Impl& g = ctx.impl();
  const gpu::Program& prog = g.program(kRatesPass);
  gpu::Target target = gpu::make_target({rates});
  g.begin(target);
  glUseProgram(prog.id());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, sigma.id);
  glBindSampler(0, g.nearest.id());
  glUniform1f(prog.loc("uSigma0"), static_cast<float>(p.sigma0));
  glUniform1f(prog.loc("uIterations"), static_cast<float>(plan.iterations));
  glUniform1i(prog.loc("uScheme"), static_cast<int>(p.scheme));
  GpuContext::Impl::draw();
  glBindSampler(0, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  gpu::check_gl("rate pass");
}

DiffusionPlan gpu_diffuse_textures(GpuContext& ctx, GpuTexture f_ping, GpuTexture f_pong, GpuTexture rates,
                                   const DiffusionParams& p, const DiffusionPlan& plan, GpuFilter filter,
                                   int* result_index) {
  const char* fn = "gpu_diffuse_textures";
  check_texture(f_ping, "f_ping", fn);
  check_texture(f_pong, "f_pong", fn);
  check_texture(rates, "rates", fn);
  check_same_size(f_ping, f_pong, "f_pong", fn);
  check_same_size(f_ping, rates, "rates", fn);
  if (f_ping.id == f_pong.id || f_ping.id == rates.id || f_pong.id == rates.id)
    throw Error(std::string(fn) + ": f_ping, f_pong and rates must be three distinct textures");
  check_plan(p, plan, fn);
  GpuContext::Impl& g = ctx.impl();
  const bool hardware = use_hardware(g, filter);
  const gpu::Program& prog = g.program(kDiffusePass);
  // One framebuffer per target, attached and checked once; each iteration
  // only binds it and the source texture (a re-attachment invalidates the
  // framebuffer's completeness, which the driver then validates again at
  // the next draw).
  const gpu::Target to[2] = {gpu::make_target({f_pong}), gpu::make_target({f_ping})};
  const GLuint from[2] = {f_ping.id, f_pong.id};
  glUseProgram(prog.id());
  glUniform1i(prog.loc("uScheme"), static_cast<int>(p.scheme));
  glUniform1f(prog.loc("uSigma0"), static_cast<float>(p.sigma0));
  glUniform1i(prog.loc("uHardware"), hardware ? 1 : 0);
  glUniform1i(prog.loc("uEdgeRate"), static_cast<int>(p.edge_rate));
  const GLint loc_k = prog.loc("uK");
  const GLuint sampler = hardware ? g.linear.id() : g.nearest.id();
  glBindSampler(0, sampler);
  glBindSampler(1, sampler);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, rates.id);
  glActiveTexture(GL_TEXTURE0);
  g.begin(to[0]);
  int src = 0;
  for (int k = 0; k < plan.iterations; ++k) {
    to[src].bind();
    glBindTexture(GL_TEXTURE_2D, from[src]);
    glUniform1i(loc_k, k);
    GpuContext::Impl::draw();
    src = 1 - src;
  }
  glBindSampler(0, 0);
  glBindSampler(1, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  gpu::check_gl("diffusion");
  if (result_index) *result_index = src;
  return plan;
}

DiffusionPlan diffuse_gpu(GpuContext& ctx, Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p,
                          GpuFilter filter, GpuTiming* timing) {
  const DiffusionPlan plan = validate_diffusion(f, sigma, sigma_max, p);
  GpuContext::Impl& g = ctx.impl();
  GpuTiming t;
  t.gpu_timer = g.info.timer_query;
  t.iterations = plan.iterations;
  const auto t0 = gpu::Clock::now();
  GpuImage tex[2] = {GpuImage(ctx, f, p.precision), GpuImage(ctx, f.width, f.height, 4, p.precision)};
  GpuImage sig(ctx, sigma), rates(ctx, f.width, f.height, 1);
  glFinish();
  t.upload_ms = gpu::ms_since(t0);
  gpu::StageTimer st(g, &t.gpu_timer);
  gpu_diffusion_rates(ctx, sig.texture(), rates.texture(), p, plan);
  int last = 0;
  gpu_diffuse_textures(ctx, tex[0].texture(), tex[1].texture(), rates.texture(), p, plan, filter, &last);
  t.diffuse_ms = st.stop();
  const auto t1 = gpu::Clock::now();
  const std::vector<float> out = gpu::read_rgba(tex[last].texture());
  t.readback_ms = gpu::ms_since(t1);
  std::memcpy(f.data.data(), out.data(), out.size() * sizeof(float));
  if (timing) *timing = t;
  return plan;
}

}  // namespace brume
#endif  // BRUME_HAVE_GPU
