// brume — the camera pass of the falling particles on the GPU (effects/rain/rain_gpu.hpp): haze's
// passes, its premultiply pass given the particles' optical depth along each pixel's ray.
#include "effects/rain/rain_gpu.hpp"

#if BRUME_HAVE_GPU
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"

namespace brume {

namespace {
constexpr int kTableWidth = 64;  // the table's texel i at (i % 64, i / 64): haze_premultiply.frag

GpuTexture tex(const gl::Texture& t, int w, int h) { return {t.id(), w, h}; }

const gpu::PassSpec& pass(const char* name) {
  const gpu::PassSpec* p = gpu::find_pass(name);
  if (!p) throw Error(std::string("internal: GPU pass '") + name + "' is not linked");
  return *p;
}
}  // namespace

Image streak_background_gpu(GpuContext& ctx, const CameraRainScene& s, const CameraRainOptics& optics,
                            const HazeParams& hp, const HazeAnalysis& ha, bool blur, GpuFilter filter,
                            Image* transmission, GpuTiming& timing) {
  const int W = s.rgb.width(), H = s.rgb.height();
  (void)ctx.impl();
  timing = {};
  gpu::ColorAndRange in =
      gpu::upload_color_and_range(copy_of(s.rgb), copy_of(s.range), "camera pass", &timing.upload_ms);
  const Image weight = s.sky_weight.empty() ? Image() : copy_of(s.sky_weight);
  const gl::Texture sky = gpu::upload_sky_weight(&weight, W, H, "camera pass", &timing.upload_ms);
  // The optical depth's table: step i = 1 .. n as (G at its start, σ_d on it, its start), in double
  // on the CPU, stored as float.
  const int n = kRainThinningSteps;
  const int rows = (n + 1 + kTableWidth - 1) / kTableWidth;
  std::vector<float> table(static_cast<std::size_t>(kTableWidth) * rows * 4, 0.0f);
  for (int i = 1; i <= n; ++i) {
    float* t = &table[static_cast<std::size_t>(i) * 4];
    t[0] = static_cast<float>(optics.g_start(i));
    t[1] = static_cast<float>(optics.sigma_drawn(i));
    t[2] = static_cast<float>(optics.z_start(i));
  }
  const gl::Texture steps = gpu::make_texture(GL_RGBA32F, kTableWidth, rows, GL_RGBA, GL_FLOAT, table.data());

  GpuContext::Impl& g = ctx.impl();
  timing.gpu_timer = g.info.timer_query;
  const double sigma_total = optics.sigma_cam() + s.haze_sigma_per_m;
  const float sky_tau = sigma_total > 0.0 ? 0.0f : 1.0f;  // the sky lies beyond the unbounded media
  const bool naive = blur && hp.composite == Composite::naive;
  gpu::ScatterTargets t;
  t.ensure(W, H, hp.diffusion.precision, GL_RG32F);
  const StreakPopulation& pop = optics.population();
  gpu::scatter_first_pass(
      ctx, t, pass("haze.premultiply"), "premultiply", in, sky, true,
      [&](const gpu::Program& pr) {
        glActiveTexture(GL_TEXTURE3);
        glBindTexture(GL_TEXTURE_2D, steps.id());
        glUniform1f(pr.loc("uInvRangeMax"), static_cast<float>(1.0 / ha.range_max_m));
        glUniform1f(pr.loc("uSigma0"), static_cast<float>(hp.diffusion.sigma0));
        glUniform1f(pr.loc("uSigmaMax"), static_cast<float>(ha.sigma_max));
        glUniform1i(pr.loc("uNaive"), naive ? 1 : 0);
        glUniform1f(pr.loc("uSkyTau"), sky_tau);
        glUniform1i(pr.loc("uParticles"), 1);
        glUniform4f(pr.loc("uRay"), static_cast<float>(s.k.fx), static_cast<float>(s.k.fy),
                    static_cast<float>(s.k.cx), static_cast<float>(s.k.cy));
        glUniform4f(pr.loc("uParticleDepth"), static_cast<float>(s.haze_sigma_per_m),
                    static_cast<float>(pop.sigma_cam), static_cast<float>(optics.step_m()),
                    static_cast<float>(pop.z_split_m));
        glUniform1i(pr.loc("uParticleStepCount"), n);
      },
      hp.diffusion, ha.plan, blur, timing);
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, 0);
  if (blur) {
    timing.iterations = ha.plan.iterations;
    gpu::scatter_diffuse_composite(ctx, t, hp.diffusion, ha.plan, filter, s.airlight, naive, timing);
  } else {
    t.last = 0;  // T·C + (1 − T)·A: the composite of F0 = T·(C, 1)
    gpu::scatter_composite(ctx, t, s.airlight, false, timing);
  }

  const auto t4 = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba(tex(t.out, W, H));
  std::vector<float> x;
  if (transmission) x = gpu::read_rgba(tex(t.aux, W, H));
  timing.readback_ms = gpu::ms_since(t4);
  Image out(W, H, 3);
  for (std::size_t i = 0; i < out.pixels(); ++i)
    for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = o[i * 4 + c];
  if (transmission) {
    *transmission = Image(W, H, 1);
    for (std::size_t i = 0; i < transmission->pixels(); ++i) transmission->data[i] = x[i * 4 + 1];  // aux.g: τ0
  }
  return out;
}

}  // namespace brume

#else  // a build without the GPU backend

namespace brume {
Image streak_background_gpu(GpuContext&, const CameraRainScene&, const CameraRainOptics&, const HazeParams&,
                            const HazeAnalysis&, bool, GpuFilter, Image*, GpuTiming&) {
  gpu_unavailable();
}
}  // namespace brume

#endif
