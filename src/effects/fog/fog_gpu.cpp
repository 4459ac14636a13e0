// brume — layered fog on the GPU: one fragment pass (fog_apply.frag) over a
// colour image and a range map uploaded once; with the scattering blur
// (lambda > 0) it writes the premultiplied F0 = f (C, 1) and sigma, and
// haze's passes finish: rates (sigma -> rho), N diffusion passes, composite
// out = F.rgb + (1 - F.a) B. The per-pixel maths is src/effects/fog/fog_math.glsl,
// the text the CPU compiles.
#include "brume/gpu_fog.hpp"

#if BRUME_HAVE_GPU
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {
namespace {

constexpr int kMaxKnots = 32;  // BRUME_PROFILE_MAX_KNOTS in GLSL
const gpu::PassSpec kFogPass{"fog.apply", {"haze_math", "height_profile", "fog_math", "depth_math"}, gpu::shaders::fog_apply_frag};
const gpu::PassRegistration kFogPasses{&kFogPass};

GpuTexture fog_tex(const gl::Texture& t, int w, int h) { return {t.id(), w, h}; }

}  // namespace

struct GpuFog::State {
  gpu::ColorAndRange in;  // colour and range (or window depth), uploaded once
  gl::Texture sky_weight;  // the preparation's sky weight (R32F), when given
  gpu::ScatterTargets t;     // haze's blur textures; aux holds sigma, F0 alpha, F
  bool depth_buffer = false;  // in.range holds window depth (NaN set to the clear value)
  DepthBufferLinear lin;
};

GpuFog::GpuFog(GpuContext& ctx, DenseImageRef rgb, const Image& range, const Image* sky_weight)
    : GpuEffect(ctx, rgb.width, rgb.height), s_(std::make_unique<State>()) {
  s_->in = gpu::upload_color_and_range(rgb, range, "fog", &timing_.upload_ms);
  s_->sky_weight = gpu::upload_sky_weight(sky_weight, w_, h_, "fog", &timing_.upload_ms);
}

GpuFog::GpuFog(GpuContext& ctx, DenseImageRef rgb, const Image& window_depth, DepthBufferConvention c, double near_m,
               double far_m)
    : GpuEffect(ctx, rgb.width, rgb.height), s_(std::make_unique<State>()) {
  s_->depth_buffer = true;
  s_->lin = depth_buffer_linear(c, near_m, far_m);
  // Window depth as stored: the pass linearises it. NaN (an unknown stored
  // value) becomes the clear value, because GLSL compilers may fold isnan() away.
  if (rgb.channels != 3 || window_depth.channels != 1 || window_depth.width != w_ || window_depth.height != h_)
    throw Error("GPU fog: depth buffer " + window_depth.size_string() + " does not match image " +
                rgb.size_string() + " (one channel of window depth, the image's size)");
  Image d = window_depth;
  for (std::size_t i = 0; i < d.data.size(); ++i) {
    float& v = d.data[i];
    if (!std::isfinite(v)) v = s_->lin.clear;
    if (v < 0.0f || v > 1.0f)
      throw Error("depth-buffer pixel (" + std::to_string(i % d.width) + ", " + std::to_string(i / d.width) + ") is " +
                  std::to_string(v) + "; window depth must be in [0, 1] (for a 16/24-bit integer buffer give --scale "
                  "1/65535 or 1/16777215)");
  }
  const auto t0 = gpu::Clock::now();
  std::vector<float> px(rgb.pixels() * 4, 1.0f);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int k = 0; k < 3; ++k) px[i * 4 + k] = rgb.data[i * 3 + k];
  s_->in.image = gpu::make_texture(GL_RGBA32F, w_, h_, GL_RGBA, GL_FLOAT, px.data());
  s_->in.range = gpu::make_texture(GL_R32F, w_, h_, GL_RED, GL_FLOAT, d.data.data());
  s_->in.range_host = std::move(d.data);
  glFinish();
  timing_.upload_ms = gpu::ms_since(t0);
}

GpuFog::~GpuFog() = default;

FogResult GpuFog::render(const FogParams& p, const FogAnalysis& a, GpuFilter filter) {
  const FogDensity& d = a.density;
  if (d.knot_u.size() > static_cast<std::size_t>(kMaxKnots))
    throw Error("--table '" + a.table.path + "' has " + std::to_string(d.knot_u.size()) +
                " rows; the GPU pass holds at most " + std::to_string(kMaxKnots) +
                " (uniform arrays): resample the table or use --backend cpu");
  GpuContext::Impl& g = ctx_.impl();
  State& s = *s_;
  const bool blur = p.lambda > 0.0;
  s.t.ensure(w_, h_, p.diffusion.precision, GL_RGBA32F);
  const double upload_ms = timing_.upload_ms;
  timing_ = {};
  timing_.upload_ms = upload_ms;
  timing_.iterations = blur ? a.plan.iterations : 0;
  timing_.gpu_timer = g.info.timer_query;

  gpu::scatter_first_pass(
      ctx_, s.t, kFogPass, "fog", s.in, s.sky_weight, a.sky_blend,
      [&](const gpu::Program& pr) {
        const Mat3 R = a.camera.world_from_camera().rotation;
        glUniform3f(pr.loc("uRayRow"), static_cast<float>(R.m[1][0]), static_cast<float>(R.m[1][1]),
                    static_cast<float>(R.m[1][2]));
        glUniform4f(pr.loc("uK"), static_cast<float>(a.camera.k.cx), static_cast<float>(a.camera.k.cy),
                    static_cast<float>(1.0 / a.camera.k.fx), static_cast<float>(1.0 / a.camera.k.fy));
        glUniform1i(pr.loc("uKind"), d.kind());
        glUniform3f(pr.loc("uExp"), static_cast<float>(d.d0), static_cast<float>(d.falloff),
                    static_cast<float>(d.exponent_c));
        glUniform2f(pr.loc("uBand"), static_cast<float>(d.band_offset), static_cast<float>(d.band_half_width));
        glUniform2f(pr.loc("uClassic"), static_cast<float>(d.fog_start), static_cast<float>(d.fog_end));
        std::vector<float> ku(kMaxKnots, 0.0f), kd(kMaxKnots, 0.0f);
        for (std::size_t i = 0; i < d.knot_u.size(); ++i) {
          ku[i] = static_cast<float>(d.knot_u[i]);
          kd[i] = static_cast<float>(d.knot_density[i]);
        }
        glUniform1i(pr.loc("uKnots"), static_cast<int>(d.knot_u.size()));
        glUniform1fv(pr.loc("uKnotU"), kMaxKnots, ku.data());
        glUniform1fv(pr.loc("uKnotD"), kMaxKnots, kd.data());
        glUniform1f(pr.loc("uSkyDistance"), a.sky_at_infinity ? -1.0f : static_cast<float>(a.sky_distance_m));
        glUniform1f(pr.loc("uSkyBlurDistance"), static_cast<float>(a.sky_distance_m));
        glUniform3f(pr.loc("uAirlight"), a.airlight[0], a.airlight[1], a.airlight[2]);
        glUniform1i(pr.loc("uBlur"), blur ? 1 : 0);
        glUniform4f(pr.loc("uScale"), static_cast<float>(p.diffusion.sigma0), static_cast<float>(p.lambda),
                    static_cast<float>(p.albedo), static_cast<float>(1.0 / a.range_max_m));
        glUniform1f(pr.loc("uSigmaMax"), static_cast<float>(a.sigma_max));
        glUniform1i(pr.loc("uDepthBuffer"), s.depth_buffer ? 1 : 0);
        glUniform3f(pr.loc("uDepthLinear"), static_cast<float>(s.lin.a), static_cast<float>(s.lin.b), s.lin.clear);
      },
      p.diffusion, a.plan, blur, timing_);

  const gl::Texture* result = &s.t.f[0];
  if (blur) {
    gpu::scatter_diffuse_composite(ctx_, s.t, p.diffusion, a.plan, filter, a.airlight, false, timing_);
    result = &s.t.out;
  }

  const auto t4 = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba(fog_tex(*result, w_, h_)), x = gpu::read_rgba(fog_tex(s.t.aux, w_, h_));
  timing_.readback_ms = gpu::ms_since(t4);
  FogResult res;
  res.rgb = Image(w_, h_, 3);
  res.transmission = Image(w_, h_, 1);
  res.optical_depth = Image(w_, h_, 1);
  for (std::size_t i = 0; i < res.rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) res.rgb.data[i * 3 + c] = o[i * 4 + c];
    res.transmission.data[i] = o[i * 4 + 3];
    res.optical_depth.data[i] = x[i * 4 + 2];
  }
  return res;
}

}  // namespace brume

#else  // a build without the GPU backend: every entry point says why

namespace brume {

struct GpuFog::State {};
GpuFog::GpuFog(GpuContext& ctx, DenseImageRef, const Image&, const Image*) : GpuEffect(ctx, 0, 0) {
  gpu_unavailable();
}
GpuFog::GpuFog(GpuContext& ctx, DenseImageRef, const Image&, DepthBufferConvention, double, double)
    : GpuEffect(ctx, 0, 0) {
  gpu_unavailable();
}
GpuFog::~GpuFog() = default;
FogResult GpuFog::render(const FogParams&, const FogAnalysis&, GpuFilter) { gpu_unavailable(); }

}  // namespace brume

#endif
