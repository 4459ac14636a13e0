// Wet ground's camera pass on the GPU (effects/wet/wet_gpu.hpp, issue #57 "GPU for the per-pixel
// passes") against the CPU's render_wet on the same scene: the float Fresnel of the pass's topic
// against wet.cpp's double one; on the demo scene (160x120, camera 1.6 m up, 5 deg down) pixels
// off the ground unchanged bit for bit, film 0 the identity, the darkening and the mirror within
// float rounding, and the mirrored rays' source pixels, read from an image that carries each
// pixel's coordinates as its colour, the same but for a small bounded share; each mirror march
// (blocks, above-ground) against the CPU's same march, the above-ground lift where the CPU's, and
// the record's mirror_march from a GPU run.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <set>
#include <string>
#include <vector>

#include "brume/camera.hpp"
#include "brume/command.hpp"
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

// The scene's size in these tests (cheap on llvmpipe) and the CPU's threads.
constexpr int W = 160, H = 120;
Exec two_threads() {
  Exec e;
  e.threads = 2;
  return e;
}

// The source pixels' comparison of one march on one scene (below).
struct SourceCompare {
  std::size_t ground = 0, hits = 0, differ = 0, same_far = 0;
  long worst = 0;  // the largest difference of a source pixel's coordinates (the sky, -1, against a pixel: more)
  WetStats cpu, gpu;
  std::vector<std::array<long, 2>> src_cpu, src_gpu;  // each ground pixel's source pixel (row by row; the sky -1)
};

// The scene with each pixel's colour its coordinates ((x + 1/2)/W, (y + 1/2)/H, 1/2): the mirror's
// L, (wet − K_eff dry)/(f R_F), names the pixel the ray took (the sky: 4, 4, 4, out of [0, 1]), on
// the CPU and on the GPU with the scene's march (a scene of W x H).
SourceCompare compare_sources(GpuContext& ctx, WetScene sc, const WetFilm& w, const Exec& exec) {
  const WetOptics o(w);
  Image coded(W, H, 3), g_cpu;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) coded.at(x, y, 0) = (x + 0.5f) / W, coded.at(x, y, 1) = (y + 0.5f) / H, coded.at(x, y, 2) = 0.5f;
  sc.rgb = coded;
  sc.sky = {4.0f, 4.0f, 4.0f};
  SourceCompare r;
  GpuTiming t;
  const Image c_cpu = render_wet(sc, w, exec, &r.cpu, &g_cpu);
  const Image c_gpu = render_wet_gpu(ctx, sc, w, &r.gpu, nullptr, t);
  const auto source = [&](const Image& out, int x, int y) {
    const double m = o.mirror(-sc.camera.world_ray(x, y).y);
    const double lu = (out.at(x, y, 0) - o.k_eff * coded.at(x, y, 0)) / m;
    const double lv = (out.at(x, y, 1) - o.k_eff * coded.at(x, y, 1)) / m;
    if (lu > 2.0) return std::array<long, 2>{-1, -1};  // the sky
    return std::array<long, 2>{std::lround(lu * W - 0.5), std::lround(lv * H - 0.5)};
  };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (g_cpu.at(x, y) == 0.0f) continue;
      ++r.ground;
      const auto a = source(c_cpu, x, y), b = source(c_gpu, x, y);
      r.src_cpu.push_back(a), r.src_gpu.push_back(b);
      r.hits += a[0] >= 0;
      if (a != b) {
        r.worst = std::max({r.worst, std::labs(a[0] - b[0]), std::labs(a[1] - b[1])});
        ++r.differ;
        continue;
      }
      for (int c = 0; c < 3; ++c) r.same_far += std::fabs(c_gpu.at(x, y, c) - c_cpu.at(x, y, c)) > 1e-5f;
    }
  std::printf("wet GPU vs CPU, %s march, %dx%d, tolerance %.2f m: %zu ground pixels, %zu mirror hits, %zu differ in "
              "source pixel (%.3f %%); the pass %.1f ms (%s)\n",
              enum_name(wet_march_names(), sc.march).c_str(), W, H, sc.ground_tolerance_m, r.ground, r.hits, r.differ,
              100.0 * static_cast<double>(r.differ) / static_cast<double>(r.ground), t.composite_ms,
              ctx.info().renderer.c_str());
  return r;
}

// Rays whose source pixel differs, by one pixel: the march's samples lie on whole pixels of the
// major axis, so the bisection's first midpoint of a step lies exactly halfway between two
// pixels. The GPU's march reaches it exactly and rounds half away from zero; the CPU's
// u_inf + w c_u (two terms ~1/D_z that cancel) lands a rounding error to either side. Where the
// depth test differs between those two pixels (a grazing ray over the far ground, or entering
// a wall), the crossing, and the pixel taken, moves by one along the ray: 0.7 % of the ground
// on the demo (the same in a double emulation of the GPU's march: not float against double).
// Bound: one pixel per axis, in at most 2 % of the ground; where the two took the same pixel the
// values agree within 1e-5 (float arithmetic on values <= 1). Both ran the scene's march.
void expect_sources_match(const SourceCompare& r, WetMarch march) {
  EXPECT_EQ(r.cpu.march, march);
  EXPECT_EQ(r.gpu.march, march);
  EXPECT_EQ(r.gpu.ground, r.cpu.ground);
  ASSERT_GT(r.hits, 1000u) << "the mirror must take scene pixels, not only the sky";
  EXPECT_EQ(r.same_far, 0u);
  EXPECT_LE(r.worst, 1);
  EXPECT_LE(static_cast<double>(r.differ), 0.02 * static_cast<double>(r.ground)) << r.differ << " of " << r.ground;
}

// The demo scene with real colours, on each march: the ground, the pixels off it, film 0, a mask.
TEST(WetGpu, DemoSceneMatchesTheCpu) {
  BRUME_REQUIRE_GPU(ctx);
  const DemoScene d = render_demo_scene(W, H);
  const Exec exec = two_threads();
  const WetFilm w = film(1.5);
  for (const WetMarch march : {WetMarch::blocks, WetMarch::above_ground}) {
    SCOPED_TRACE(enum_name(wet_march_names(), march));
    WetScene sc = test::demo_wet_scene(d, W, H);
    sc.march = march;
    Image g_cpu, g_gpu;
    WetStats s_cpu, s_gpu;
    GpuTiming t;
    const Image cpu = render_wet(sc, w, exec, &s_cpu, &g_cpu);
    const Image gpu = render_wet_gpu(*ctx, sc, w, &s_gpu, &g_gpu, t);
    EXPECT_EQ(s_cpu.march, march);
    EXPECT_EQ(s_gpu.march, march);
    // The ground: the same pixels (the plane's test in float against double could only flip a
    // pixel within ~1e-6 m of the tolerance; none does here).
    ASSERT_GT(s_cpu.ground, 3000u);
    EXPECT_EQ(std::memcmp(g_cpu.data.data(), g_gpu.data.data(), g_cpu.data.size() * sizeof(float)), 0);
    EXPECT_EQ(s_gpu.ground, s_cpu.ground);
    // Off the ground: the input bit for bit. On it: K_eff dry + f R_F L within float rounding where
    // the mirrored ray took the same pixel (with coordinates for colours, compare_sources), 1e-5;
    // a differing source pixel accounts for every larger difference of the real image.
    std::size_t changed = 0, far = 0;
    for (std::size_t i = 0; i < g_gpu.pixels(); ++i)
      for (int c = 0; c < 3; ++c) {
        const float a = gpu.data[i * 3 + c], b = d.rgb.data[i * 3 + c];
        if (g_gpu.data[i] == 0.0f) changed += std::memcmp(&a, &b, sizeof a) != 0;
        else far += std::fabs(a - cpu.data[i * 3 + c]) > 1e-5f;
      }
    EXPECT_EQ(changed, 0u);
    const SourceCompare r = compare_sources(*ctx, sc, w, exec);
    expect_sources_match(r, march);
    EXPECT_LE(far, 3 * r.differ);
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
    WetStats sm_cpu, sm_gpu;
    const Image m_cpu = render_wet(masked, w, exec, &sm_cpu, &gm_cpu);
    const Image m_gpu = render_wet_gpu(*ctx, masked, w, &sm_gpu, &gm_gpu, t0);
    EXPECT_EQ(sm_gpu.march, march);  // the camera's height is known: the mask's ground, the scene's march
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
    // The mask without the camera's height: the plane's pixels are unknown, both run blocks (the
    // GPU as the CPU: the blocks march's image on the mask's ground).
    masked.camera.position_m.y = NAN;
    WetStats sn_cpu, sn_gpu;
    const Image n_gpu = render_wet_gpu(*ctx, masked, w, &sn_gpu, nullptr, t0);
    (void)render_wet(masked, w, exec, &sn_cpu);
    EXPECT_EQ(sn_cpu.march, WetMarch::blocks);
    EXPECT_EQ(sn_gpu.march, WetMarch::blocks);
    EXPECT_EQ(sn_gpu.ground, sm_gpu.ground);
    if (march == WetMarch::blocks) EXPECT_EQ(n_gpu.data, m_gpu.data);
  }
}

// The lift point of the above-ground march. Above the tolerance a ray cannot pass behind one of
// the plane's pixels (the pixel's ray goes down: behind its point lies lower), so the two marches
// differ only where a sample's nearest pixel is not the ray's own column: a few rays, on the
// demo at brume wet's default tolerance (0.15 m; measured on llvmpipe: the CPU's marches differ
// in 9 of 9 506 ground pixels, the GPU's in 4). There the GPU's above-ground march takes the CPU
// above-ground march's pixel (measured 9 of 9; bound 3/4), and the GPU's two marches do differ
// (the uniform reaches the march). Checked by breaking the shader's lift: never lifting (or at
// twice the tolerance) takes the CPU's pixel in 5 of 9, one ray 8 px away; lifting too early (the
// tolerance taken as 0: the plane's pixels left out while the ray is still among them) moves
// 379 rays here, and 171 at DemoSceneMatchesTheCpu's 0.02 m, by up to 158 px.
TEST(WetGpu, AboveGroundLiftsWhereTheCpuDoes) {
  BRUME_REQUIRE_GPU(ctx);
  const DemoScene d = render_demo_scene(W, H);
  const Exec exec = two_threads();
  WetScene sc = test::demo_wet_scene(d, W, H);
  sc.ground_tolerance_m = 0.15;
  sc.march = WetMarch::blocks;
  const SourceCompare b = compare_sources(*ctx, sc, film(1.5), exec);
  sc.march = WetMarch::above_ground;
  const SourceCompare a = compare_sources(*ctx, sc, film(1.5), exec);
  expect_sources_match(b, WetMarch::blocks);
  expect_sources_match(a, WetMarch::above_ground);
  ASSERT_EQ(a.src_cpu.size(), b.src_cpu.size());
  std::size_t cpu_differ = 0, gpu_as_cpu = 0, gpu_differ = 0;
  for (std::size_t i = 0; i < a.src_cpu.size(); ++i) {
    gpu_differ += a.src_gpu[i] != b.src_gpu[i];
    if (a.src_cpu[i] == b.src_cpu[i]) continue;
    ++cpu_differ;
    gpu_as_cpu += a.src_gpu[i] == a.src_cpu[i];
  }
  std::printf("marches at 0.15 m: the CPU's differ in %zu ground pixels, the GPU's above-ground takes the CPU's "
              "pixel in %zu of them; the GPU's marches differ in %zu\n",
              cpu_differ, gpu_as_cpu, gpu_differ);
  ASSERT_GE(cpu_differ, 4u) << "the scene must hold rays the lift changes";
  EXPECT_GE(4 * gpu_as_cpu, 3 * cpu_differ);
  EXPECT_GE(gpu_differ, 1u);
}

// The record of a GPU run (brume.wet's array form, in process) names the march that ran, as the
// CPU's does: above-ground by default, blocks when asked, and blocks with its reason for a ground
// mask without the camera's height.
TEST(WetGpu, RecordNamesTheMarchThatRan) {
  BRUME_REQUIRE_GPU(ctx);
  const DemoScene d = render_demo_scene(W, H);
  Image mask(W, H, 1);  // the lower half
  for (int y = H / 2; y < H; ++y)
    for (int x = 0; x < W; ++x) mask.at(x, y) = 1.0f;
  const ArrayForm& a = *find_command("wet")->arrays;
  struct Case {
    JobValues values;
    bool masked;
    std::string march;
  };
  const JobValues pose = {{"fov-y", d.fov_y_deg}, {"film", 1.5}, {"pitch", -5.0}};
  JobValues with_height = pose, blocks = pose;
  with_height.emplace_back("camera-height", 1.6);
  blocks.emplace_back("camera-height", 1.6);
  blocks.emplace_back("mirror-march", "blocks");
  for (const Case& c : {Case{with_height, false, "above-ground"}, Case{blocks, false, "blocks"},
                        Case{pose, true, "blocks"}}) {
    SCOPED_TRACE(nlohmann::json(c.values).dump());
    std::set<std::string> given;
    for (const auto& v : c.values) given.insert(v.first);
    const nlohmann::json call = a.build(c.values);
    std::vector<ArrayIn> in(a.args.size());
    for (int i = 0; i < 2; ++i) {
      const Image& im = i == 0 ? d.rgb : d.range;
      in[i].present = true;
      in[i].view = ConstImageView(im);
      in[i].dense = DenseImageRef(im);
    }
    if (c.masked) in[3].present = true, in[3].view = ConstImageView(mask);
    Exec e = two_threads();
    const ArrayResult cpu = a.run(in, call, e, given);
    e.backend = Backend::gpu;
    e.gpu = ctx;
    const ArrayResult gpu = a.run(in, call, e, given);
    EXPECT_EQ(gpu.record["execution"]["backend"], "gpu");
    EXPECT_EQ(gpu.record["wet"]["mirror_march"], c.march);
    EXPECT_EQ(cpu.record["wet"]["mirror_march"], c.march);
    EXPECT_EQ(gpu.record["wet"].value("mirror_march_because", ""), cpu.record["wet"].value("mirror_march_because", ""));
    EXPECT_EQ(gpu.record["wet"].contains("mirror_march_because"), c.masked);
    EXPECT_EQ(gpu.record["wet"]["ground_pixels"], cpu.record["wet"]["ground_pixels"]);
  }
}

}  // namespace wet_gpu_tests
