// brume — the Preetham sky on the GPU (include/brume/sky.hpp): one
// full-screen pass, src/effects/sky/sky_render.frag, over the shared maths of
// src/effects/sky/sky_math.glsl. The per-image constants (Perez coefficients,
// zenith values over F(0, theta_s)) are computed here with the very shared
// functions the CPU renderer calls, so both backends start from the same floats.
#include "brume/gpu_sky.hpp"

#if BRUME_HAVE_GPU
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "core/math_constants.hpp"
#include "brume/sky.hpp"
#include "gpu/context.hpp"
#include "gpu/shaders_embedded.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace {

const gpu::PassSpec kSkyPass{"sky.render", {"aerial_math", "sky_math"}, gpu::shaders::sky_render_frag};
const gpu::PassRegistration kSkyPasses{&kSkyPass};

}  // namespace

Image render_sky_gpu(GpuContext& ctx, const SkyRenderParams& p, const SkyDirection& sun, const SkyGeometry& g,
                     GpuTiming* timing) {
  namespace sh = brume::shared;
  check_sky_turbidity(p.turbidity);
  if (!(sun.zenith_deg >= 0.0 && sun.zenith_deg < 90.0))
    throw Error("the sun's zenith angle " + std::to_string(sun.zenith_deg) +
                " deg is not above the horizon; the Preetham model has no twilight: use a sun zenith in [0, 90)");
  GpuContext::Impl& gi = ctx.impl();
  GpuTiming tm;
  tm.gpu_timer = gi.info.timer_query;
  const int w = g.width, h = g.height;
  // The CPU renderer's per-image constants, computed identically (render_sky).
  const float t = static_cast<float>(p.turbidity);
  const float ts = static_cast<float>(sun.zenith_deg * kDeg);
  const float ps = static_cast<float>(sun.azimuth_deg * kDeg);
  float cf[15];
  for (int k = 0; k < 5; ++k) {
    cf[k] = sh::brume_perez_coef_Y(k, t);
    cf[5 + k] = sh::brume_perez_coef_x(k, t);
    cf[10 + k] = sh::brume_perez_coef_y(k, t);
  }
  const float zen[3] = {sh::brume_sky_zenith_Y(t, ts), sh::brume_sky_zenith_x(t, ts), sh::brume_sky_zenith_y(t, ts)};
  float scale[3];
  for (int c = 0; c < 3; ++c)
    scale[c] = zen[c] / (sh::brume_perez_theta(cf[5 * c], cf[5 * c + 1], 1.0f) *
                         sh::brume_perez_gamma(cf[5 * c + 2], cf[5 * c + 3], cf[5 * c + 4], ts, std::cos(ts)));
  scale[0] *= static_cast<float>(p.exposure);
  // Pinhole: d_world = R_cv K^-1 (u, v, 1), R_cv = orientation diag(1, -1, -1)
  // (brume/camera.hpp: Camera::world_ray, without its normalisation).
  double m[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  if (g.projection == Projection::pinhole) {
    const Intrinsics& k = g.camera.k;
    const double kinv[3][3] = {{1.0 / k.fx, 0.0, -k.cx / k.fx}, {0.0, 1.0 / k.fy, -k.cy / k.fy}, {0.0, 0.0, 1.0}};
    const double sgn[3] = {1.0, -1.0, -1.0};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int l = 0; l < 3; ++l) m[i][j] += g.camera.orientation.m[i][l] * sgn[l] * kinv[l][j];
  }
  const int proj = g.projection == Projection::fisheye ? 0 : (g.projection == Projection::equirectangular ? 1 : 2);

  gpu::StageTimer st(gi, &tm.gpu_timer);
  gl::Texture out = gpu::make_texture(GL_RGBA32F, w, h);
  gpu::Target target = gpu::make_target({GpuTexture{out.id(), w, h}});
  const gpu::Program& pr = gi.program(kSkyPass);
  gi.begin(target);
  glUseProgram(pr.id());
  glUniform1i(pr.loc("uProjection"), proj);
  glUniform2f(pr.loc("uSize"), static_cast<float>(w), static_cast<float>(h));
  glUniform3f(pr.loc("uFisheye"), static_cast<float>(g.cx), static_cast<float>(g.cy), static_cast<float>(g.radius_px));
  glUniform1f(pr.loc("uOffset"), static_cast<float>(g.azimuth_offset_deg * kDeg));
  glUniform3f(pr.loc("uRay0"), static_cast<float>(m[0][0]), static_cast<float>(m[0][1]), static_cast<float>(m[0][2]));
  glUniform3f(pr.loc("uRay1"), static_cast<float>(m[1][0]), static_cast<float>(m[1][1]), static_cast<float>(m[1][2]));
  glUniform3f(pr.loc("uRay2"), static_cast<float>(m[2][0]), static_cast<float>(m[2][1]), static_cast<float>(m[2][2]));
  glUniform1fv(pr.loc("uCoef"), 15, cf);
  glUniform3f(pr.loc("uScale"), scale[0], scale[1], scale[2]);
  glUniform3f(pr.loc("uSun"), std::sin(ts), std::cos(ts), ps);
  // No disc: a cosine no direction reaches.
  glUniform1f(pr.loc("uCosDisc"), p.sun_disc ? static_cast<float>(std::cos(p.sun_disc_radius_deg * kDeg)) : 2.0f);
  glUniform1f(pr.loc("uSunY"), static_cast<float>(p.sun_luminance_kcd * p.exposure));
  if (p.ground)
    glUniform4f(pr.loc("uGround"), static_cast<float>((*p.ground)[0]), static_cast<float>((*p.ground)[1]),
                static_cast<float>((*p.ground)[2]), 1.0f);
  else
    glUniform4f(pr.loc("uGround"), 0.0f, 0.0f, 0.0f, 0.0f);
  GpuContext::Impl::draw();
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  gpu::check_gl("sky render");
  tm.composite_ms = st.stop();

  const auto t0 = gpu::Clock::now();
  const std::vector<float> o = gpu::read_rgba({out.id(), w, h});
  tm.readback_ms = gpu::ms_since(t0);
  Image img(w, h, 3, NAN);
  for (std::size_t i = 0; i < img.pixels(); ++i)
    if (o[i * 4 + 3] > 0.5f)
      for (int c = 0; c < 3; ++c) img.data[i * 3 + c] = o[i * 4 + c];
  if (timing) *timing = tm;
  return img;
}

}  // namespace brume

#else  // a build without the GPU backend: every entry point says why

namespace brume {

Image render_sky_gpu(GpuContext&, const SkyRenderParams&, const SkyDirection&, const SkyGeometry&, GpuTiming*) {
  gpu_unavailable();
}

}  // namespace brume

#endif
