// Wet ground's camera pass on the GPU (effects/wet/wet_gpu.hpp, issue #57 "GPU for the per-pixel
// passes") against the CPU's render_wet on the same scene: the float Fresnel of the pass's topic
// against wet.cpp's double one; on the demo scene (160x120, camera 1.6 m up, 5 deg down) pixels
// off the ground unchanged bit for bit, film 0 the identity, the darkening and the mirror within
// float rounding, and the mirrored rays' source pixels, read from an image that carries each
// pixel's coordinates as its colour, the same but for a small bounded share.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <cstring>

#include "brume/camera.hpp"
#include "brume/demo_scene.hpp"
#include "brume/wet.hpp"
#include "effects/wet/wet_gpu.hpp"
#include "shared/prelude_cpp.h"
#include "test_util.hpp"
#include "wet_demo.hpp"

using namespace brume;

namespace wet_gpu_tests {

WetFilm film(double mm) {
  WetFilm w;
  w.film_mm = mm;
  return w;
}

// The topic's float R_F (compiled as C++ here, as the GPU compiles it) against the double one the
// CPU's camera and LiDAR use, over cos theta in [0, 1] and the index's range: within 2e-6, float
// rounding of a few operations on values <= 1 (the reflectance is at most 1).
TEST(WetGpu, FresnelInFloatIsTheDoubleOne) {
  double worst = 0.0;
  for (double n : {1.2, 1.333, 1.5})
    for (int i = 0; i <= 1000; ++i) {
      const double c = i / 1000.0;
      worst = std::max(worst, std::fabs(static_cast<double>(shared::brume_wet_fresnel(static_cast<float>(c),
                                                                                       static_cast<float>(n))) -
                                        fresnel_reflectance(c, n)));
    }
  EXPECT_LE(worst, 2e-6);
}

// The demo scene, real colours and then each pixel's coordinates as its colour.
TEST(WetGpu, DemoSceneMatchesTheCpu) {
  BRUME_REQUIRE_GPU(ctx);
  const int W = 160, H = 120;
  const DemoScene d = render_demo_scene(W, H);
  WetScene sc = test::demo_wet_scene(d, W, H);
  Exec exec;
  exec.threads = 2;
  const WetFilm w = film(1.5);
  const WetOptics o(w);
  Image g_cpu, g_gpu;
  WetStats s_cpu, s_gpu;
  GpuTiming t;
  const Image cpu = render_wet(sc, w, exec, &s_cpu, &g_cpu);
  const Image gpu = render_wet_gpu(*ctx, sc, w, &s_gpu, &g_gpu, t);
  // The ground: the same pixels (the plane's test in float against double could only flip a
  // pixel within ~1e-6 m of the tolerance; none does here).
  ASSERT_GT(s_cpu.ground, 3000u);
  EXPECT_EQ(std::memcmp(g_cpu.data.data(), g_gpu.data.data(), g_cpu.data.size() * sizeof(float)), 0);
  EXPECT_EQ(s_gpu.ground, s_cpu.ground);
  // Off the ground: the input bit for bit. On it: K_eff dry + f R_F L within float rounding where
  // the mirrored ray took the same pixel (below, with coordinates for colours), 1e-5.
  std::size_t changed = 0, far = 0;
  for (std::size_t i = 0; i < g_gpu.pixels(); ++i)
    for (int c = 0; c < 3; ++c) {
      const float a = gpu.data[i * 3 + c], b = d.rgb.data[i * 3 + c];
      if (g_gpu.data[i] == 0.0f) changed += std::memcmp(&a, &b, sizeof a) != 0;
      else far += std::fabs(a - cpu.data[i * 3 + c]) > 1e-5f;
    }
  EXPECT_EQ(changed, 0u);
  // Film 0: the identity.
  GpuTiming t0;
  const Image dry = render_wet_gpu(*ctx, sc, film(0.0), nullptr, nullptr, t0);
  EXPECT_EQ(std::memcmp(dry.data.data(), d.rgb.data.data(), d.rgb.data.size() * sizeof(float)), 0);
  // A ground mask (the plane's ground on the right half only): the mask's ground on both.
  Image mask = g_cpu;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W / 2; ++x) mask.at(x, y) = 0.0f;
  WetScene masked = sc;
  masked.mask = mask;
  Image gm_cpu, gm_gpu;
  const Image m_cpu = render_wet(masked, w, exec, nullptr, &gm_cpu);
  const Image m_gpu = render_wet_gpu(*ctx, masked, w, nullptr, &gm_gpu, t0);
  EXPECT_EQ(std::memcmp(gm_cpu.data.data(), gm_gpu.data.data(), gm_cpu.data.size() * sizeof(float)), 0);
  std::size_t m_ground = 0, m_changed = 0, m_far = 0;
  for (std::size_t i = 0; i < gm_gpu.pixels(); ++i) {
    m_ground += gm_gpu.data[i] != 0.0f;
    for (int c = 0; c < 3; ++c) {
      const float a = m_gpu.data[i * 3 + c], b = d.rgb.data[i * 3 + c];
      if (gm_gpu.data[i] == 0.0f) m_changed += std::memcmp(&a, &b, sizeof a) != 0;
      else m_far += std::fabs(a - m_cpu.data[i * 3 + c]) > 1e-5f;
    }
  }
  EXPECT_GT(m_ground, 1000u);
  EXPECT_LT(m_ground, s_cpu.ground);
  EXPECT_EQ(m_changed, 0u);
  EXPECT_LE(m_far, far);  // a subset of the ground above: its pixels that took another pixel at most

  // Each pixel's colour its coordinates ((x + 1/2)/W, (y + 1/2)/H, 1/2): the mirror's L, (wet −
  // K_eff dry)/(f R_F), names the pixel the ray took (the sky: 4, 4, 4, out of [0, 1]).
  Image coded(W, H, 3);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) coded.at(x, y, 0) = (x + 0.5f) / W, coded.at(x, y, 1) = (y + 0.5f) / H, coded.at(x, y, 2) = 0.5f;
  sc.rgb = coded;
  sc.sky = {4.0f, 4.0f, 4.0f};
  const Image c_cpu = render_wet(sc, w, exec);
  const Image c_gpu = render_wet_gpu(*ctx, sc, w, nullptr, nullptr, t);
  const auto source = [&](const Image& out, int x, int y) {
    const double m = o.mirror(-sc.camera.world_ray(x, y).y);
    const double lu = (out.at(x, y, 0) - o.k_eff * coded.at(x, y, 0)) / m;
    const double lv = (out.at(x, y, 1) - o.k_eff * coded.at(x, y, 1)) / m;
    if (lu > 2.0) return std::array<long, 2>{-1, -1};  // the sky
    return std::array<long, 2>{std::lround(lu * W - 0.5), std::lround(lv * H - 0.5)};
  };
  std::size_t ground = 0, hits = 0, differ = 0, same_far = 0;
  long worst = 0;  // the largest difference of a source pixel's coordinates (the sky, -1, against a pixel: more)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (g_cpu.at(x, y) == 0.0f) continue;
      ++ground;
      const auto a = source(c_cpu, x, y), b = source(c_gpu, x, y);
      hits += a[0] >= 0;
      if (a != b) {
        worst = std::max({worst, std::labs(a[0] - b[0]), std::labs(a[1] - b[1])});
        ++differ;
        continue;
      }
      for (int c = 0; c < 3; ++c) same_far += std::fabs(c_gpu.at(x, y, c) - c_cpu.at(x, y, c)) > 1e-5f;
    }
  ASSERT_GT(hits, 1000u) << "the mirror must take scene pixels, not only the sky";
  // Where the two took the same pixel the values agree within 1e-5 (float arithmetic on values
  // <= 1), and a differing source pixel accounts for every larger difference of the real image.
  EXPECT_EQ(same_far, 0u);
  EXPECT_LE(far, 3 * differ);
  // Rays whose source pixel differs, by one pixel: the march's samples lie on whole pixels of the
  // major axis, so the bisection's first midpoint of a step lies exactly halfway between two
  // pixels. The GPU's march reaches it exactly and rounds half away from zero; the CPU's
  // u_inf + w c_u (two terms ~1/D_z that cancel) lands a rounding error to either side. Where the
  // depth test differs between those two pixels (a grazing ray over the far ground, or entering
  // a wall), the crossing, and the pixel taken, moves by one along the ray: 0.7 % of the ground
  // here (the same in a double emulation of the GPU's march: not float against double). Bound:
  // one pixel per axis, in at most 2 % of the ground.
  EXPECT_LE(worst, 1);
  EXPECT_LE(static_cast<double>(differ), 0.02 * static_cast<double>(ground)) << differ << " of " << ground;
  std::printf("wet GPU vs CPU, demo 160x120: %zu ground pixels, %zu mirror hits, %zu differ in source pixel "
              "(%.3f %%); the pass %.1f ms (%s)\n",
              ground, hits, differ, 100.0 * static_cast<double>(differ) / static_cast<double>(ground),
              t.composite_ms, ctx->info().renderer.c_str());
}

}  // namespace wet_gpu_tests
