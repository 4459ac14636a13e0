// brume — the camera pass of the falling particles on the GPU (effects/rain/rain_gpu.hpp): haze's
// passes, its premultiply pass given the particles' optical depth along each pixel's ray.
#include "effects/rain/rain_gpu.hpp"

#if BRUME_HAVE_GPU
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {

namespace {
constexpr int kTableWidth = 64;  // the table's texel i at (i % 64, i / 64): haze_premultiply.frag

GpuTexture tex(const gl::Texture& t, int w, int h) { return {t.id(), w, h}; }

const gpu::PassSpec kSplatPass{"rain.splat", {}, gpu::shaders::rain_splat_frag};
const gpu::PassRegistration kRainPasses{&kSplatPass};

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

StreakSplat GpuStreakSplatter::splat(const StreakSlabs& slabs, ConstImageView range, Image& out,
                                     const StreakCamera& cam, int threads) const {
  const int W = cam.width, H = cam.height;
  if (out.width != W || out.height != H || out.channels != 3 || range.width() != W || range.height() != H)
    throw Error("internal: the GPU's splat takes a " + std::to_string(W) + "x" + std::to_string(H) +
                " RGB image and range, got " + out.size_string());
  StreakSplatTiming& tm = timing_;
  tm = {};
  const auto t_bin = gpu::Clock::now();
  const StreakBins bins = bin_streaks(slabs, cam, kStreakGpuTile, kStreakGpuTile, threads);
  const std::size_t n = bins.drops.size();
  StreakSplat done;
  done.drawn = n;
  done.mean_streak_px = bins.mean_streak_px;
  if (n == 0) return done;
  // The streaks' texels (rain_splat.frag): in double here, stored as float.
  GpuContext::Impl& g = ctx_.impl();
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  const int width = std::max(1, std::min(4096, static_cast<int>(max_size)));
  const auto rows_of = [&](std::size_t texels, const char* what) {
    const std::size_t rows = std::max<std::size_t>(1, (texels + width - 1) / width);
    if (rows > static_cast<std::size_t>(max_size))
      throw Error(std::string("the GPU's splat: ") + std::to_string(texels) + " texels of " + what +
                  " exceed this GPU's textures (" + std::to_string(max_size) + " x " + std::to_string(max_size) +
                  "); give a smaller --z-split or a larger --epsilon, or use --backend cpu");
    return static_cast<int>(rows);
  };
  constexpr std::size_t kTexels = 5;  // a streak's (rain_splat.frag)
  const int s_rows = rows_of(kTexels * n, "streaks");
  std::vector<float> st(static_cast<std::size_t>(width) * s_rows * 4, 0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    const Streak& k = *bins.drops[i];
    const StreakSampling smp = streak_sampling(k, cam);
    const double nd = smp.n, dt = k.t1 - k.t0;
    float* t = &st[i * kTexels * 4];
    for (int q = 0; q < 3; ++q) {
      t[q] = static_cast<float>(k.c[q] + k.u[q] * k.t0);
      t[4 + q] = static_cast<float>(k.u[q] * dt / nd);
      t[8 + q] = k.e[q];
    }
    t[3] = static_cast<float>(smp.n);
    t[7] = static_cast<float>(smp.rad);
    t[11] = static_cast<float>(k.area / nd);
    t[12] = smp.gauss ? static_cast<float>(1.0 / (2.0 * k.sigma_px * k.sigma_px)) : 0.0f;
    t[13] = smp.gauss ? 1.0f : 0.0f;
    t[16] = static_cast<float>(k.u_lo), t[17] = static_cast<float>(k.u_hi);
    t[18] = static_cast<float>(k.v_lo), t[19] = static_cast<float>(k.v_hi);
  }
  const std::size_t n_tiles = static_cast<std::size_t>(bins.tiles_x) * bins.tiles_y;
  const std::size_t entries = bins.in_tile.size();
  if (entries > std::numeric_limits<std::uint32_t>::max())
    throw Error("internal: " + std::to_string(entries) + " tile entries, more than the GPU's splat counts");
  tm.list_entries = entries;
  const int f_rows = rows_of(n_tiles + 1, "tile starts"), l_rows = rows_of(std::max<std::size_t>(1, entries), "tile lists");
  std::vector<std::uint32_t> first(static_cast<std::size_t>(width) * f_rows, 0u),
      list(static_cast<std::size_t>(width) * l_rows, 0u);
  for (std::size_t t = 0; t <= n_tiles; ++t) first[t] = static_cast<std::uint32_t>(bins.first[t]);
  std::copy(bins.in_tile.begin(), bins.in_tile.end(), list.begin());
  std::vector<float> depth(static_cast<std::size_t>(W) * H);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = range.at(x, y);
      depth[static_cast<std::size_t>(y) * W + x] = streak_range_known(r) ? r : -1.0f;
    }
  std::vector<float> rgba(static_cast<std::size_t>(W) * H * 4, 1.0f);
  for (std::size_t i = 0; i < out.pixels(); ++i)
    for (int c = 0; c < 3; ++c) rgba[i * 4 + c] = out.data[i * 3 + c];
  tm.bin_ms = gpu::ms_since(t_bin);

  const auto t_up = gpu::Clock::now();
  const gl::Texture image = gpu::make_texture(GL_RGBA32F, W, H, GL_RGBA, GL_FLOAT, rgba.data());
  const gl::Texture rtex = gpu::make_texture(GL_R32F, W, H, GL_RED, GL_FLOAT, depth.data());
  const gl::Texture stex = gpu::make_texture(GL_RGBA32F, width, s_rows, GL_RGBA, GL_FLOAT, st.data());
  const gl::Texture ftex = gpu::make_texture(GL_R32UI, width, f_rows, GL_RED_INTEGER, GL_UNSIGNED_INT, first.data());
  const gl::Texture ltex = gpu::make_texture(GL_R32UI, width, l_rows, GL_RED_INTEGER, GL_UNSIGNED_INT, list.data());
  const gl::Texture result = gpu::make_texture(GL_RGBA32F, W, H);
  const gpu::Target target = gpu::make_target({{result.id(), W, H}});
  glFinish();
  tm.upload_ms = gpu::ms_since(t_up);

  tm.gpu_timer = g.info.timer_query;
  {
    gpu::StageTimer timer(g, &tm.gpu_timer);
    const gpu::Program& pr = g.program(kSplatPass);
    g.begin(target);
    glUseProgram(pr.id());
    const gpu::BoundTextures bound{image.id(), rtex.id(), stex.id(), ftex.id(), ltex.id()};
    glUniform4f(pr.loc("uK"), static_cast<float>(cam.fx), static_cast<float>(cam.fy), static_cast<float>(cam.cx),
                static_cast<float>(cam.cy));
    glUniform2i(pr.loc("uTile"), kStreakGpuTile, kStreakGpuTile);
    glUniform1i(pr.loc("uTilesX"), bins.tiles_x);
    glUniform1i(pr.loc("uStreakWidth"), width);
    glUniform1i(pr.loc("uIndexWidth"), width);
    glUniform1f(pr.loc("uSoftness"), static_cast<float>(kRainDepthSoftness));
    GpuContext::Impl::draw();
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    gpu::check_gl("rain.splat");
    tm.splat_ms = timer.stop();
  }
  const auto t_read = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba({result.id(), W, H});
  tm.readback_ms = gpu::ms_since(t_read);
  double clamped = 0.0;  // each pixel's count is exact in float (< 2^24)
  for (std::size_t i = 0; i < out.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = o[i * 4 + c];
    clamped += o[i * 4 + 3];
  }
  done.alpha_clamped = static_cast<std::size_t>(clamped);
  return done;
}

}  // namespace brume

#else  // a build without the GPU backend

namespace brume {
Image streak_background_gpu(GpuContext&, const CameraRainScene&, const CameraRainOptics&, const HazeParams&,
                            const HazeAnalysis&, bool, GpuFilter, Image*, GpuTiming&) {
  gpu_unavailable();
}
StreakSplat GpuStreakSplatter::splat(const StreakSlabs&, ConstImageView, Image&, const StreakCamera&, int) const {
  gpu_unavailable();
}
}  // namespace brume

#endif

namespace brume {
nlohmann::json streak_splat_timing_record(const StreakSplatTiming& t) {
  return {{"clock", t.gpu_timer ? "timer queries (the pass); wall (the rest)" : "glFinish wall time"},
          {"bin_ms", t.bin_ms},
          {"upload_ms", t.upload_ms},
          {"splat_ms", t.splat_ms},
          {"read_back_ms", t.readback_ms},
          {"tile_px", kStreakGpuTile},
          {"list_entries", t.list_entries}};
}
}  // namespace brume
