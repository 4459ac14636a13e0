// brume — the camera's wet ground on the GPU (effects/wet/wet_gpu.hpp): one pass, wet_apply.frag.
#include "effects/wet/wet_gpu.hpp"

#if BRUME_HAVE_GPU
#include <vector>

#include "brume/error.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"

namespace brume {

namespace {
const gpu::PassSpec kWetPass{"wet.apply", {"wet_math"}, gpu::shaders::wet_apply_frag};
const gpu::PassRegistration kWetPasses{&kWetPass};
}  // namespace

Image render_wet_gpu(GpuContext& ctx, const WetScene& s, const WetFilm& w, WetStats* stats, Image* ground_out,
                     GpuTiming& timing) {
  check_wet_scene(s);
  const int W = s.rgb.width(), H = s.rgb.height();
  const WetOptics o(w);
  (void)ctx.impl();
  timing = {};
  const Image rgb = copy_of(s.rgb);
  const gpu::ColorAndRange in = gpu::upload_color_and_range(rgb, copy_of(s.range), "wet", &timing.upload_ms);
  const bool masked = s.mask.width() > 0;
  WetStats st;
  st.march = wet_march_that_runs(s);
  gl::Texture mask;
  if (masked) {
    const Image m = copy_of(s.mask);
    mask = gpu::make_texture(GL_R32F, W, H, GL_RED, GL_FLOAT, m.data.data());
  }
  const gl::Texture out = gpu::make_texture(GL_RGBA32F, W, H), info = gpu::make_texture(GL_RGBA32F, W, H);
  const gpu::Target target = gpu::make_target({{out.id(), W, H}, {info.id(), W, H}});

  GpuContext::Impl& g = ctx.impl();
  timing.gpu_timer = g.info.timer_query;
  const Camera& cam = s.camera;
  const Mat3 R = cam.world_from_camera().rotation;  // world_from_cv: row 1 is the plane's normal in cv
  {
    gpu::StageTimer t(g, &timing.gpu_timer);
    const gpu::Program& pr = g.program(kWetPass);
    g.begin(target);
    glUseProgram(pr.id());
    const gpu::BoundTextures bound{in.image.id(), in.range.id(), masked ? mask.id() : 0u};
    glUniform1i(pr.loc("uMasked"), masked ? 1 : 0);
    glUniform4f(pr.loc("uK"), static_cast<float>(cam.k.fx), static_cast<float>(cam.k.fy), static_cast<float>(cam.k.cx),
                static_cast<float>(cam.k.cy));
    glUniform3f(pr.loc("uNormal"), static_cast<float>(R.m[1][0]), static_cast<float>(R.m[1][1]),
                static_cast<float>(R.m[1][2]));
    glUniform1f(pr.loc("uHeight"), static_cast<float>(cam.position_m.y));
    glUniform1f(pr.loc("uTolerance"), static_cast<float>(s.ground_tolerance_m));
    glUniform1f(pr.loc("uKEff"), static_cast<float>(o.k_eff));
    glUniform1f(pr.loc("uWetted"), static_cast<float>(o.f));
    glUniform1f(pr.loc("uWaterIndex"), static_cast<float>(o.n));
    glUniform3f(pr.loc("uSky"), s.sky[0], s.sky[1], s.sky[2]);
    glUniform1f(pr.loc("uFrontK"), static_cast<float>(1.0 + kWetHitMargin));
    glUniform1f(pr.loc("uThickK"), static_cast<float>(1.0 + kWetHitMargin + kWetThickness));
    glUniform1i(pr.loc("uMaxSteps"), 4 * (W + H));
    glUniform1i(pr.loc("uMarch"), st.march == WetMarch::above_ground ? 1 : 0);
    GpuContext::Impl::draw();
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    gpu::check_gl("wet");
    timing.composite_ms = t.stop();
  }
  const auto t4 = gpu::Clock::now();
  const std::vector<float> o_px = gpu::read_rgba({out.id(), W, H}), i_px = gpu::read_rgba({info.id(), W, H});
  timing.readback_ms = gpu::ms_since(t4);

  Image result(W, H, 3), ground(W, H, 1);
  for (std::size_t i = 0; i < result.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) result.data[i * 3 + c] = o_px[i * 4 + c];
    if (i_px[i * 4] != 1.0f) continue;
    ground.data[i] = 1.0f;
    ++st.ground;
    const float end = i_px[i * 4 + 1];
    if (end == 1.0f) ++st.hits;
    else if (end == 2.0f) ++st.sky_pixels;
    else ++st.left_frame;
  }
  if (o.f == 0.0) result = rgb;  // a dry film: the input, bit for bit (as the CPU)
  st.march_ms = timing.composite_ms;
  if (stats) *stats = st;
  if (ground_out) *ground_out = std::move(ground);
  return result;
}

}  // namespace brume

#else  // a build without the GPU backend

namespace brume {
Image render_wet_gpu(GpuContext&, const WetScene&, const WetFilm&, WetStats*, Image*, GpuTiming&) {
  gpu_unavailable();
}
}  // namespace brume

#endif
