// brume — aerial perspective on the GPU (include/brume/aerial.hpp): N + 3
// full-screen passes over a colour image and a range map uploaded once:
//   premultiply  Gamma from the N x 1 ln-Gamma table(s), F0 = (rho E', rho_r),
//                F1 = (rho_g, rho_b, 0, 0), aux = sigma
//   rates        rho_diffusion from sigma (the diffusion layer's pass)
//   N diffusion  F0 and F1 each ping-pong with the SAME rates: together they
//                are the CPU's six channels diffused with one sigma map
//   composite    out = F + (1 - rho) A per channel, XYZ -> sRGB, sky kept
// Remove skips the diffusion (a blur cannot be undone).
#include "brume/gpu_aerial.hpp"

#if BRUME_HAVE_GPU
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {
namespace {

const gpu::PassSpec kAerialPremultiplyPass{"aerial.premultiply", {"haze_math", "aerial_math"},
                                     gpu::shaders::aerial_premultiply_frag};
const gpu::PassSpec kAerialCompositePass{"aerial.composite", {"haze_math", "aerial_math"},
                                   gpu::shaders::aerial_composite_frag};
const gpu::PassRegistration kAerialPasses{&kAerialPremultiplyPass, &kAerialCompositePass};

GpuTexture aerial_tex(const gl::Texture& t, int w, int h) { return {t.id(), w, h}; }

// ln Gamma as an N x 1 RGBA32F texture, read with texelFetch only.
gl::Texture table_texture(const AttenuationTable& t) {
  const std::size_t n = std::max<std::size_t>(2, t.log_gamma.size());
  std::vector<float> px(n * 4, 0.0f);
  for (std::size_t i = 0; i < t.log_gamma.size(); ++i)
    for (int c = 0; c < 3; ++c) px[i * 4 + c] = t.log_gamma[i][c];
  return gpu::make_texture(GL_RGBA32F, static_cast<int>(n), 1, GL_RGBA, GL_FLOAT, px.data());
}

// --path slant: ln Gamma over (s_R, s_M) as an nr x nm RGBA32F texture (row j
// holds s_M = j step_m), read with texelFetch only.
gl::Texture slant_table_texture(const SlantAttenuationTable& t) {
  std::vector<float> px(static_cast<std::size_t>(t.nr) * t.nm * 4, 0.0f);
  for (std::size_t i = 0; i < t.log_gamma.size(); ++i)
    for (int c = 0; c < 3; ++c) px[i * 4 + c] = t.log_gamma[i][c];
  return gpu::make_texture(GL_RGBA32F, t.nr, t.nm, GL_RGBA, GL_FLOAT, px.data());
}

}  // namespace

struct GpuAerial::State {
  gpu::ColorAndRange in;  // colour and range, uploaded once
  Precision precision = Precision::f32;
  gl::Texture f0[2], f1[2], aux, rates, out, att;
  gpu::Target premultiply, composite;
};

GpuAerial::GpuAerial(GpuContext& ctx, DenseImageRef rgb, const Image& range)
    : GpuEffect(ctx, rgb.width, rgb.height), s_(std::make_unique<State>()) {
  s_->in = gpu::upload_color_and_range(rgb, range, "aerial", &timing_.upload_ms);
}

GpuAerial::~GpuAerial() = default;

AerialResult GpuAerial::render(const AerialParams& p, const AerialAnalysis& a, GpuFilter filter) {
  GpuContext::Impl& g = ctx_.impl();
  State& s = *s_;
  if (!a.sky.data.empty() && (a.sky.width != w_ || a.sky.height != h_))
    throw Error("GPU aerial: the analysis was made for another image size (" + a.sky.size_string() + ")");
  if (!s.composite.fbo || s.precision != p.diffusion.precision) {
    s.premultiply = {};
    s.composite = {};
    const GLenum fmt = p.diffusion.precision == Precision::f16 ? GL_RGBA16F : GL_RGBA32F;
    for (int k = 0; k < 2; ++k) {
      s.f0[k] = gpu::make_texture(fmt, w_, h_);
      s.f1[k] = gpu::make_texture(fmt, w_, h_);
    }
    s.aux = gpu::make_texture(GL_RG32F, w_, h_);
    s.rates = gpu::make_texture(GL_R32F, w_, h_);
    s.out = gpu::make_texture(GL_RGBA32F, w_, h_);
    s.att = gpu::make_texture(GL_RGBA32F, w_, h_);
    s.premultiply = gpu::make_target({aerial_tex(s.f0[0], w_, h_), aerial_tex(s.f1[0], w_, h_), aerial_tex(s.aux, w_, h_)});
    s.composite = gpu::make_target({aerial_tex(s.out, w_, h_), aerial_tex(s.att, w_, h_)});
    s.precision = p.diffusion.precision;
  }
  // Per render: the tables and the sky mask belong to the analysis.
  const bool slant = p.path == AerialPath::slant;
  if (slant && (a.slant_dh.width != w_ || a.slant_dh.height != h_ || a.slant_gamma.log_gamma.empty() ||
                (a.mode == AerialMode::rerender && a.slant_gamma_from.log_gamma.empty())))
    throw Error("GPU aerial: --path slant, but the analysis holds no slant tables for this image (analyse it with "
                "--path slant and the geometry)");
  gl::Texture table = table_texture(a.gamma);
  gl::Texture table_from = table_texture(a.mode == AerialMode::rerender ? a.gamma_from : a.gamma);
  // The slant path's inputs (level: the level table stands in, never read).
  gl::Texture slant_dh, slant_table, slant_table_from;
  if (slant) {
    slant_dh = gpu::make_texture(GL_RG32F, w_, h_, GL_RG, GL_FLOAT, a.slant_dh.data.data());
    slant_table = slant_table_texture(a.slant_gamma);
    slant_table_from = slant_table_texture(a.mode == AerialMode::rerender ? a.slant_gamma_from : a.slant_gamma);
  }
  std::vector<float> sky(static_cast<std::size_t>(w_) * h_, 0.0f);
  if (!a.sky.data.empty()) sky = a.sky.data;
  gl::Texture sky_tex = gpu::make_texture(GL_R32F, w_, h_, GL_RED, GL_FLOAT, sky.data());

  const bool xyz = a.sensitivity.space == SensitivitySpace::xyz;
  const std::array<float, 3> A = aerial_working_colour(a, a.airlight), A1 = aerial_working_colour(a, a.from_airlight);
  const int mode = aerial_mode_index(a.mode);
  const bool blur = a.plan.iterations > 0 && a.mode != AerialMode::remove;
  timing_.iterations = blur ? a.plan.iterations : 0;
  timing_.gpu_timer = g.info.timer_query;

  gpu::StageTimer t1(g, &timing_.gpu_timer);
  const gpu::Program& pr = g.program(kAerialPremultiplyPass);
  g.begin(s.premultiply);
  glUseProgram(pr.id());
  const GLuint inputs[] = {s.in.image.id(),
                           s.in.range.id(),
                           table.id(),
                           table_from.id(),
                           slant ? slant_dh.id() : table.id(),
                           slant ? slant_table.id() : table.id(),
                           slant ? slant_table_from.id() : table.id()};
  for (int k = 0; k < 7; ++k) {
    glActiveTexture(GL_TEXTURE0 + k);
    glBindTexture(GL_TEXTURE_2D, inputs[k]);
  }
  const AttenuationTable& tf = a.mode == AerialMode::rerender ? a.gamma_from : a.gamma;
  glUniform1f(pr.loc("uStep"), static_cast<float>(a.gamma.step_m));
  glUniform1i(pr.loc("uLast"), static_cast<int>(a.gamma.log_gamma.size()) - 1);
  if (mode == 1) {
    glUniform1f(pr.loc("uStepFrom"), static_cast<float>(tf.step_m));
    glUniform1i(pr.loc("uLastFrom"), static_cast<int>(tf.log_gamma.size()) - 1);
    glUniform3f(pr.loc("uA1"), A1[0], A1[1], A1[2]);
  }
  glUniform1f(pr.loc("uDistanceScale"), static_cast<float>(p.distance_scale));
  glUniform1f(pr.loc("uFar"), static_cast<float>(a.range_max_m * p.distance_scale));
  glUniform1f(pr.loc("uInvRangeMax"), static_cast<float>(1.0 / a.range_max_m));
  glUniform1f(pr.loc("uSigma0"), static_cast<float>(p.diffusion.sigma0));
  glUniform1f(pr.loc("uSigmaMax"), static_cast<float>(a.sigma_max));
  glUniform1i(pr.loc("uMode"), mode);
  glUniform1i(pr.loc("uXyz"), xyz ? 1 : 0);
  glUniform3f(pr.loc("uA"), A[0], A[1], A[2]);
  glUniform1f(pr.loc("uFloor"), static_cast<float>(p.gamma_floor));
  glUniform1i(pr.loc("uSlant"), slant ? 1 : 0);
  glUniform2f(pr.loc("uInvScaleHeight"), static_cast<float>(1.0 / kRayleighScaleHeightM),
              static_cast<float>(1.0 / kMieScaleHeightM));
  glUniform2f(pr.loc("uSlantInvStep"), slant ? static_cast<float>(1.0 / a.slant_gamma.step_r_m) : 0.0f,
              slant ? static_cast<float>(1.0 / a.slant_gamma.step_m_m) : 0.0f);
  glUniform1i(pr.loc("uSlantNr"), slant ? a.slant_gamma.nr : 2);
  glUniform1i(pr.loc("uSlantNm"), slant ? a.slant_gamma.nm : 2);
  GpuContext::Impl::draw();
  gpu::check_gl("aerial premultiply");
  if (blur) gpu_diffusion_rates(ctx_, aerial_tex(s.aux, w_, h_), aerial_tex(s.rates, w_, h_), p.diffusion, a.plan);
  timing_.premultiply_ms = t1.stop();

  gpu::StageTimer t2(g, &timing_.gpu_timer);
  int last0 = 0, last1 = 0;
  if (blur) {
    gpu_diffuse_textures(ctx_, aerial_tex(s.f0[0], w_, h_), aerial_tex(s.f0[1], w_, h_), aerial_tex(s.rates, w_, h_), p.diffusion, a.plan,
                         filter, &last0);
    gpu_diffuse_textures(ctx_, aerial_tex(s.f1[0], w_, h_), aerial_tex(s.f1[1], w_, h_), aerial_tex(s.rates, w_, h_), p.diffusion, a.plan,
                         filter, &last1);
  }
  timing_.diffuse_ms = t2.stop();

  gpu::StageTimer t3(g, &timing_.gpu_timer);
  const gpu::Program& pc = g.program(kAerialCompositePass);
  g.begin(s.composite);
  glUseProgram(pc.id());
  const GLuint cin[] = {s.f0[last0].id(), s.f1[last1].id(), s.in.image.id(), s.in.range.id(), sky_tex.id()};
  for (int k = 0; k < 5; ++k) {
    glActiveTexture(GL_TEXTURE0 + k);
    glBindTexture(GL_TEXTURE_2D, cin[k]);
  }
  glUniform3f(pc.loc("uA"), A[0], A[1], A[2]);
  glUniform1i(pc.loc("uMode"), mode);
  glUniform1i(pc.loc("uXyz"), xyz ? 1 : 0);
  GpuContext::Impl::draw();
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  gpu::check_gl("aerial composite");
  timing_.composite_ms = t3.stop();

  const auto t4 = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba(aerial_tex(s.out, w_, h_)), at = gpu::read_rgba(aerial_tex(s.att, w_, h_)),
                           x = gpu::read_rgba(aerial_tex(s.aux, w_, h_));
  timing_.readback_ms = gpu::ms_since(t4);
  AerialResult res;
  res.rgb = Image(w_, h_, 3);
  res.attenuation = Image(w_, h_, 3);
  res.scale = Image(w_, h_, 1);
  const float floor_g = static_cast<float>(p.gamma_floor);
  for (std::size_t i = 0; i < res.rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) {
      res.rgb.data[i * 3 + c] = o[i * 4 + c];
      res.attenuation.data[i * 3 + c] = at[i * 4 + c];
    }
    res.scale.data[i] = x[i * 4];
  }
  // The floored count is a statistic of the record: the host's table gives
  // it (the same look-up the pass made), without a GPU reduction.
  if (a.mode != AerialMode::render)
    for (std::size_t i = 0; i < s.in.range_host.size(); ++i) {
      const float r = s.in.range_host[i];
      if (!(r > 0.0f) || (!a.sky.data.empty() && a.sky.data[i] > 0.0f)) continue;
      const double sd = static_cast<double>(r) * p.distance_scale;
      std::array<float, 3> gl{};
      if (slant) {  // the CPU row's look-up (aerial.cpp), in double up to the grid's cells
        const float* k = a.slant_dh.data.data() + 2 * i;
        const double dh = sd * static_cast<double>(k[0]) + static_cast<double>(k[1]);
        const SlantDistances d = slant_distances(sd, std::isfinite(dh) ? dh : 0.0);
        const SlantAttenuationTable& t = a.mode == AerialMode::rerender ? a.slant_gamma_from : a.slant_gamma;
        const std::array<float, 3> l = t.log_at(static_cast<float>(d.rayleigh_m / t.step_r_m),
                                                static_cast<float>(d.mie_m / t.step_m_m));
        for (int c = 0; c < 3; ++c) gl[c] = AttenuationTable::exp_f(l[c]);
      } else {
        gl = (a.mode == AerialMode::rerender ? a.gamma_from : a.gamma).at(sd);
      }
      res.floored_pixels += (gl[0] < floor_g || gl[1] < floor_g || gl[2] < floor_g) ? 1 : 0;
    }
  return res;
}

}  // namespace brume

#else  // a build without the GPU backend: every entry point says why

namespace brume {

struct GpuAerial::State {};
GpuAerial::GpuAerial(GpuContext& ctx, DenseImageRef, const Image&) : GpuEffect(ctx, 0, 0) { gpu_unavailable(); }
GpuAerial::~GpuAerial() = default;
AerialResult GpuAerial::render(const AerialParams&, const AerialAnalysis&, GpuFilter) { gpu_unavailable(); }

}  // namespace brume

#endif
