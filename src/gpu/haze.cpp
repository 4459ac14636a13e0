// brume — haze on the GPU (Hansard §4.2): N + 3 full-screen passes over a
// colour image and a range map uploaded once per GpuHaze:
//   premultiply  F0 = tau (E, 1), aux = (sigma, tau0)       (eq. 1, 2, 7)
//   rates        rho from sigma                              (eq. 13 / 18)
//   N diffusion  F ping-pongs between two textures            (eq. 11)
//   composite    out = F.rgb + (1 - F.a) B                    (eq. 4)
// The last three are the diffusion layer's and the composite's passes; the
// render targets live on the GpuHaze so a re-render allocates nothing.
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {
namespace {

const gpu::PassSpec kPremultiplyPass{"haze.premultiply", {"haze_math"}, gpu::shaders::premultiply_frag};
const gpu::PassSpec kCompositePass{"haze.composite", {"haze_math"}, gpu::shaders::composite_frag};

GpuTexture tex(const gl::Texture& t, int w, int h) { return {t.id(), w, h}; }

}  // namespace

struct GpuHaze::State {
  gl::Texture image, range;  // inputs, uploaded once
  // Targets, made on the first render and remade when the precision changes.
  Precision precision = Precision::f32;
  gl::Texture f[2], aux, rates, out;
  gpu::Target premultiply, composite;
};

GpuHaze::GpuHaze(GpuContext& ctx, const Image& rgb, const Image& range)
    : ctx_(ctx), w_(rgb.width), h_(rgb.height), s_(std::make_unique<State>()) {
  const auto t0 = gpu::Clock::now();
  gpu::ColorAndRange in = gpu::upload_color_and_range(rgb, range, "haze");
  s_->image = std::move(in.image);
  s_->range = std::move(in.range);
  glFinish();
  timing_.upload_ms = gpu::ms_since(t0);
}

GpuHaze::~GpuHaze() = default;

HazeResult GpuHaze::render(const HazeParams& p, const HazeAnalysis& a, GpuFilter filter) {
  GpuContext::Impl& g = ctx_.impl();
  State& s = *s_;
  if (!s.composite.fbo || s.precision != p.diffusion.precision) {
    s.premultiply = {};
    s.composite = {};
    const GLenum fmt = p.diffusion.precision == Precision::f16 ? GL_RGBA16F : GL_RGBA32F;
    for (gl::Texture& t : s.f) t = gpu::make_texture(fmt, w_, h_);
    s.aux = gpu::make_texture(GL_RG32F, w_, h_);
    s.rates = gpu::make_texture(GL_R32F, w_, h_);
    s.out = gpu::make_texture(GL_RGBA32F, w_, h_);
    s.premultiply = gpu::make_target({tex(s.f[0], w_, h_), tex(s.aux, w_, h_)});
    s.composite = gpu::make_target({tex(s.out, w_, h_)});
    s.precision = p.diffusion.precision;
  }
  const bool naive = p.composite == Composite::naive;
  timing_.iterations = a.plan.iterations;
  timing_.gpu_timer = g.info.timer_query;

  gpu::StageTimer t1(g, &timing_.gpu_timer);
  const gpu::Program& pr = g.program(kPremultiplyPass);
  g.begin(s.premultiply);
  glUseProgram(pr.id());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, s.image.id());
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, s.range.id());
  glUniform1f(pr.loc("uInvRangeMax"), static_cast<float>(1.0 / a.range_max_m));
  glUniform1f(pr.loc("uKappa"), static_cast<float>(a.kappa_a + a.kappa_s));
  glUniform1f(pr.loc("uSigma0"), static_cast<float>(p.diffusion.sigma0));
  glUniform1f(pr.loc("uSigmaMax"), static_cast<float>(a.sigma_max));
  glUniform1i(pr.loc("uNaive"), naive ? 1 : 0);
  GpuContext::Impl::draw();
  gpu::check_gl("premultiply");
  gpu_diffusion_rates(ctx_, tex(s.aux, w_, h_), tex(s.rates, w_, h_), p.diffusion, a.plan);
  timing_.premultiply_ms = t1.stop();

  gpu::StageTimer t2(g, &timing_.gpu_timer);
  int last = 0;
  gpu_diffuse_textures(ctx_, tex(s.f[0], w_, h_), tex(s.f[1], w_, h_), tex(s.rates, w_, h_), p.diffusion, a.plan, filter,
                       &last);
  timing_.diffuse_ms = t2.stop();

  gpu::StageTimer t3(g, &timing_.gpu_timer);
  const gpu::Program& pc = g.program(kCompositePass);
  g.begin(s.composite);
  glUseProgram(pc.id());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, s.f[last].id());
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, s.aux.id());
  glUniform3f(pc.loc("uAirlight"), a.airlight[0], a.airlight[1], a.airlight[2]);
  glUniform1i(pc.loc("uNaive"), naive ? 1 : 0);
  GpuContext::Impl::draw();
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  gpu::check_gl("composite");
  timing_.composite_ms = t3.stop();

  const auto t4 = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba(tex(s.out, w_, h_)), x = gpu::read_rgba(tex(s.aux, w_, h_));
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
