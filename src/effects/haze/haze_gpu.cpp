// brume — haze on the GPU (Hansard §4.2): N + 3 full-screen passes over a
// colour image and a range map uploaded once per GpuHaze:
//   premultiply  F0 = tau (E, 1), aux = (sigma, tau0)       (eq. 1, 2, 7)
//   rates        rho from sigma                              (eq. 13 / 18)
//   N diffusion  F ping-pongs between two textures            (eq. 11)
//   composite    out = F.rgb + (1 - F.a) B                    (eq. 4)
// The last three are the diffusion layer's and the composite's passes; the
// render targets live on the GpuHaze so a re-render allocates nothing.
#include "brume/gpu_haze.hpp"

#if BRUME_HAVE_GPU
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {
namespace {

const gpu::PassSpec kPremultiplyPass{"haze.premultiply", {"haze_math"}, gpu::shaders::haze_premultiply_frag};
const gpu::PassSpec kCompositePass{"haze.composite", {"haze_math"}, gpu::shaders::haze_composite_frag};
const gpu::PassRegistration kHazePasses{&kPremultiplyPass, &kCompositePass};

GpuTexture tex(const gl::Texture& t, int w, int h) { return {t.id(), w, h}; }

}  // namespace

namespace gpu {

void ScatterTargets::ensure(int width, int height, Precision p, GLenum aux_format) {
  if (composite.fbo && precision == p && w == width && h == height) return;
  first = {};
  composite = {};
  w = width, h = height;
  const GLenum fmt = p == Precision::f16 ? GL_RGBA16F : GL_RGBA32F;
  for (gl::Texture& t : f) t = make_texture(fmt, w, h);
  aux = make_texture(aux_format, w, h);
  rates = make_texture(GL_R32F, w, h);
  out = make_texture(GL_RGBA32F, w, h);
  first = make_target({tex(f[0], w, h), tex(aux, w, h)});
  composite = make_target({tex(out, w, h)});
  precision = p;
}

void scatter_rates(GpuContext& ctx, ScatterTargets& s, const DiffusionParams& d, const DiffusionPlan& plan) {
  gpu_diffusion_rates(ctx, tex(s.aux, s.w, s.h), tex(s.rates, s.w, s.h), d, plan);
}

void scatter_first_pass(GpuContext& ctx, ScatterTargets& s, const PassSpec& pass, const char* what,
                        const ColorAndRange& in, const gl::Texture& sky_weight, bool sky_blend,
                        const std::function<void(const Program&)>& uniforms, const DiffusionParams& d,
                        const DiffusionPlan& plan, bool rates, GpuTiming& timing) {
  GpuContext::Impl& g = ctx.impl();
  StageTimer t1(g, &timing.gpu_timer);
  const Program& pr = g.program(pass);
  g.begin(s.first);
  glUseProgram(pr.id());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, in.image.id());
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, in.range.id());
  const bool blend = sky_blend && sky_weight.id() != 0;
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, blend ? sky_weight.id() : 0);
  glUniform1i(pr.loc("uSkyBlend"), blend ? 1 : 0);
  uniforms(pr);
  GpuContext::Impl::draw();
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, 0);
  check_gl(what);
  if (rates) scatter_rates(ctx, s, d, plan);
  timing.premultiply_ms = t1.stop();
}

void scatter_diffuse_composite(GpuContext& ctx, ScatterTargets& s, const DiffusionParams& d, const DiffusionPlan& plan,
                               GpuFilter filter, const std::array<float, 3>& airlight, bool naive, GpuTiming& timing) {
  GpuContext::Impl& g = ctx.impl();
  StageTimer t2(g, &timing.gpu_timer);
  s.last = 0;
  gpu_diffuse_textures(ctx, tex(s.f[0], s.w, s.h), tex(s.f[1], s.w, s.h), tex(s.rates, s.w, s.h), d, plan, filter,
                       &s.last);
  timing.diffuse_ms = t2.stop();
  scatter_composite(ctx, s, airlight, naive, timing);
}

void scatter_composite(GpuContext& ctx, ScatterTargets& s, const std::array<float, 3>& airlight, bool naive,
                       GpuTiming& timing) {
  GpuContext::Impl& g = ctx.impl();
  StageTimer t3(g, &timing.gpu_timer);
  const Program& pc = g.program(kCompositePass);
  g.begin(s.composite);
  glUseProgram(pc.id());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, s.f[s.last].id());
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, s.aux.id());
  glUniform3f(pc.loc("uAirlight"), airlight[0], airlight[1], airlight[2]);
  glUniform1i(pc.loc("uNaive"), naive ? 1 : 0);
  GpuContext::Impl::draw();
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  check_gl("composite");
  timing.composite_ms = t3.stop();
}

}  // namespace gpu

struct GpuHaze::State {
  gpu::ColorAndRange in;  // colour and range, uploaded once
  gl::Texture sky_weight;  // the preparation's sky weight (R32F), when given
  gpu::ScatterTargets t;
};

GpuHaze::GpuHaze(GpuContext& ctx, const Image& rgb, const Image& range, const Image* sky_weight)
    : GpuEffect(ctx, rgb.width, rgb.height), s_(std::make_unique<State>()) {
  s_->in = gpu::upload_color_and_range(rgb, range, "haze", &timing_.upload_ms);
  s_->sky_weight = gpu::upload_sky_weight(sky_weight, w_, h_, "haze", &timing_.upload_ms);
}

GpuHaze::~GpuHaze() = default;

HazeResult GpuHaze::render(const HazeParams& p, const HazeAnalysis& a, GpuFilter filter) {
  GpuContext::Impl& g = ctx_.impl();
  State& s = *s_;
  s.t.ensure(w_, h_, p.diffusion.precision, GL_RG32F);
  const bool naive = p.composite == Composite::naive;
  timing_.iterations = a.plan.iterations;
  timing_.gpu_timer = g.info.timer_query;

  gpu::scatter_first_pass(
      ctx_, s.t, kPremultiplyPass, "premultiply", s.in, s.sky_weight, a.sky_beyond,
      [&](const gpu::Program& pr) {
        glUniform1f(pr.loc("uInvRangeMax"), static_cast<float>(1.0 / a.range_max_m));
        glUniform1f(pr.loc("uKappa"), static_cast<float>(a.kappa_a + a.kappa_s));
        glUniform1f(pr.loc("uSigma0"), static_cast<float>(p.diffusion.sigma0));
        glUniform1f(pr.loc("uSigmaMax"), static_cast<float>(a.sigma_max));
        glUniform1i(pr.loc("uNaive"), naive ? 1 : 0);
        glUniform1f(pr.loc("uSkyTau"), a.sky_transmission);
        glUniform1i(pr.loc("uParticles"), 0);  // the program is shared with rain's and snow's pass
      },
      p.diffusion, a.plan, true, timing_);
  gpu::scatter_diffuse_composite(ctx_, s.t, p.diffusion, a.plan, filter, a.airlight, naive, timing_);

  const auto t4 = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba(tex(s.t.out, w_, h_)), x = gpu::read_rgba(tex(s.t.aux, w_, h_));
  timing_.readback_ms = gpu::ms_since(t4);
  HazeResult res;
  res.rgb = Image(w_, h_, 3);
  res.transmission = Image(w_, h_, 1);
  res.scale = Image(w_, h_, 1);
  for (std::size_t i = 0; i < res.rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) res.rgb.data[i * 3 + c] = o[i * 4 + c];
    res.transmission.data[i] = o[i * 4 + 3];
    res.scale.data[i] = x[i * 4];
  }
  return res;
}

}  // namespace brume

#else  // a build without the GPU backend: every entry point says why

namespace brume {

struct GpuHaze::State {};
GpuHaze::GpuHaze(GpuContext& ctx, const Image&, const Image&, const Image*) : GpuEffect(ctx, 0, 0) {
  gpu_unavailable();
}
GpuHaze::~GpuHaze() = default;
HazeResult GpuHaze::render(const HazeParams&, const HazeAnalysis&, GpuFilter) { gpu_unavailable(); }

}  // namespace brume

#endif
