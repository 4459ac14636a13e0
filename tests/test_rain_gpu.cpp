// Rain's and snow's camera pass on the GPU (effects/rain/rain_gpu.hpp; issues #56 and #58, "GPU
// for the per-pixel passes", and the streaks' splat): brume.rain's and brume.snow's array forms (in process) with
// backend gpu against backend cpu on the same inputs, a synthetic scene and the demo scene at
// 160x120, with and without haze's medium (visibility, its blur). The particles are enumerated
// on the CPU in both runs (the same particles: the record's block is equal) and splatted on the
// GPU in the GPU's run (its bounds: SplatMatchesTheCpuSplat below, within 7e-6 there, 1e-6 on
// these scenes); the scene through the analytic media differs by the GPU's float arithmetic:
//  - per pixel (the transmission map, and the image without visibility): tau = exp(-(sigma_haze
//    r + sigma r - G/cos theta)) in float on the GPU, in double on the CPU (G's table stored as
//    float). GLSL ES 3.00 lets exp be off by (3 + 2|x|) ULP, and the optical depths here stay
//    below 10: within 1e-5 of values <= 1 (measured on llvmpipe: 1.8e-7; the image, whose streaks
//    mix over it with weights <= 1, splatted on the GPU: 1.8e-7);
//  - with visibility the ~20 diffusion passes run in f32 on both sides, in different orders: max
//    1e-4, RMS 1e-5 (measured on llvmpipe: max 1.3e-5, RMS 1.3e-7; haze's own GPU test holds the
//    GPU to the CPU's double path within RMS 1e-3, tests/test_gpu.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "brume/command.hpp"
#include "brume/demo_scene.hpp"
#include "effects/rain/rain_gpu.hpp"
#include "effects/rain/streaks.hpp"
#include "engine_util.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace rain_gpu_tests {

// `command`'s array form (brume.rain, brume.snow: in process, the test binary's GPU context) with
// `values` on the same rgb and range on both backends: the images and records.
struct Both {
  ArrayResult cpu, gpu;
};
Both both(const std::string& command, const Image& rgb, const Image& range, const JobValues& values,
          GpuContext* ctx) {
  const ArrayForm& a = *find_command(command)->arrays;
  std::set<std::string> given;
  for (const auto& v : values) given.insert(v.first);
  const nlohmann::json call = a.build(values);
  std::vector<ArrayIn> in(a.args.size());
  for (int i = 0; i < 2; ++i) {
    const Image& im = i == 0 ? rgb : range;
    in[i].present = true;
    in[i].view = ConstImageView(im);
    in[i].dense = DenseImageRef(im);
  }
  Both b;
  Exec e;
  e.threads = 2;
  b.cpu = a.run(in, call, e, given);
  e.backend = Backend::gpu;
  e.gpu = ctx;
  b.gpu = a.run(in, call, e, given);
  return b;
}

// The GPU's run against the CPU's: the bounds of the file's head, the record's backend and the
// particles' block (the same particles on both; `drawn` names their count).
void expect_match(const Both& b, const std::string& block, const std::string& drawn, bool blur,
                  const std::string& what) {
  const Diff d = compare(b.gpu.images.at("rgb"), b.cpu.images.at("rgb")),
             dt = compare(b.gpu.images.at("transmission"), b.cpu.images.at("transmission"));
  std::printf("%s: image %s; transmission max %.3g\n", what.c_str(), (std::ostringstream() << d).str().c_str(),
              dt.max_abs);
  EXPECT_LE(d.max_abs, blur ? 1e-4 : 1e-5) << what << ": " << d;
  EXPECT_LE(d.rms, 1e-5) << what << ": " << d;
  EXPECT_LE(dt.max_abs, 1e-5) << what << " transmission: " << dt;
  EXPECT_EQ(b.cpu.record["execution"]["backend"], "cpu") << what;
  EXPECT_EQ(b.gpu.record["execution"]["backend"], "gpu") << what;
  const std::string split = b.gpu.record["execution"]["split"];
  EXPECT_NE(split.find("on the CPU: the particles' enumeration"), std::string::npos) << what;
  EXPECT_NE(split.find("rain.splat"), std::string::npos) << what;  // the splat on the GPU
  EXPECT_GT(b.gpu.record["execution"]["gpu_splat_timing"]["list_entries"].get<std::size_t>(), 0u) << what;
  EXPECT_GT(b.cpu.record[block][drawn].get<std::size_t>(), 0u) << what;
  EXPECT_EQ(b.cpu.record[block], b.gpu.record[block]) << what;
}

// A synthetic scene (random colours over 10-1000 m, a band of sky): rain alone, and snow in haze.
TEST(RainGpu, SyntheticSceneMatchesTheCpu) {
  BRUME_REQUIRE_GPU(ctx);
  const Scene s = scene(160, 120, 24);
  expect_match(both("rain", s.rgb, s.range, {{"fx", 120.0}, {"rate", 25.0}, {"rain-seed", 3}, {"wind", "0,2,0"}, {"z-split", 5.0}, {"prepare", "off"}}, ctx),
               "rain", "drops_drawn", false, "synthetic rain");
  expect_match(both("snow", s.rgb, s.range, {{"fx", 120.0}, {"rate", 2.0}, {"visibility", 300.0}, {"z-split", 5.0}, {"prepare", "off"}}, ctx), "snow",
               "flakes_drawn", true, "synthetic snow");
}

// The demo scene (ground, walls, sky; 55 deg vertical field of view): rain in haze, snow alone.
TEST(RainGpu, DemoSceneMatchesTheCpu) {
  BRUME_REQUIRE_GPU(ctx);
  const DemoScene s = render_demo_scene(160, 120);
  expect_match(both("rain", s.rgb, s.range, {{"fov-y", s.fov_y_deg}, {"rate", 50.0}, {"visibility", 500.0}, {"z-split", 5.0}}, ctx),
               "rain", "drops_drawn", true, "demo rain");
}

// The splat alone (GpuStreakSplatter against splat_streaks on the same streaks and image): a
// 96x64 scene with a wall at 2 m over its left third, the sky (unknown range) over its top rows
// and a surface at 30 m elsewhere; 600 streaks placed as the camera pass places them
// (place_streak) at depths 0.15-12 m, diameters 0.5-6 mm, moving 0.01-10 m/s (mostly down; one in
// twenty nearly still at 0.3-0.8 m, whose coverage clamps), some
// defocused by a thin lens (the Gaussian kernel, up to rad 18 px) and some not (bilinear), eight
// at one place (ties: the enumeration's order), at 1/60 s and 1/8 s (long streaks over many
// tiles). Order matters: they overlap, with radiances from 0 to 2 on a grey of 0.3, and the
// near ones clamp their coverage to 1.
// Tolerance: the GPU runs the CPU's arithmetic (double) in float. A sample's image position
// u = fx X.x/X.z + cx is off by a few float roundings of |u - cx| <= 60 px here: about 1e-5 px,
// which moves a bilinear weight by as much and a Gaussian one (sigma >= 0.5 px) by at most 1.2x
// that; the coverage's other factors are off by a few 1e-7 relative, and each update
// I += a (E - I) rounds as on the CPU. A pixel's error is then at most about 1.5e-5 x the sum of
// its taps' coverages x |E - I| (<= 2 here): bound 1e-4 for a sum up to ~3, RMS 2e-6 (measured on
// llvmpipe: max 6.9e-6, RMS 2.5e-7). The count of clamped coverages may differ where a lands
// within float rounding of 1: by at most 1 in 1000 (measured: equal). The window of samples a
// pixel walks (rain_splat.frag) skipping one with a tap would move a pixel by that tap's
// a |E - I|, far beyond the bound: the near, long and defocused streaks here test it.
StreakSlabs random_streaks(const StreakCamera& cam, int n, double T, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  StreakSlabs slabs(1);
  std::size_t order = 0;
  const StreakLens pinhole{}, lens{4.0, 1.0};
  while (slabs[0].size() < static_cast<std::size_t>(n)) {
    const bool still = order % 20 == 0;  // near and nearly still: their coverage clamps to 1
    const double z = still ? 0.3 + 0.5 * U(rng) : 0.15 + 12.0 * U(rng) * U(rng);
    const Vec3 at{z, (U(rng) - 0.5) * z * cam.width / cam.fx * 1.2, (U(rng) - 0.5) * z * cam.height / cam.fy * 1.2};
    const double d = still ? 4.0 + 2.0 * U(rng) : 0.5 + 5.5 * U(rng);
    const double speed = still ? 1e-3 : std::pow(10.0, -2.0 + 3.0 * U(rng));  // 0.01-10 m/s
    const double u[3] = {speed * (U(rng) - 0.5) * 0.4, speed, speed * (U(rng) - 0.5) * 0.6};
    const int copies = order == 40 ? 8 : 1;  // one place taken eight times: ties
    for (int c = 0; c < copies; ++c) {
      Streak k;
      if (!place_streak(k, at, d, u, U(rng) < 0.4 ? lens : pinhole, T, 0.1, cam)) break;
      k.order = order++;
      for (int q = 0; q < 3; ++q) k.e[q] = static_cast<float>(2.0 * U(rng));
      slabs[0].push_back(k);
    }
  }
  return slabs;
}

TEST(RainGpu, SplatMatchesTheCpuSplat) {
  BRUME_REQUIRE_GPU(ctx);
  const int W = 96, H = 64;
  const StreakCamera cam{W, H, 300.0, 300.0, (W - 1) / 2.0, (H - 1) / 2.0};
  Image range(W, H, 1), base(W, H, 3, 0.3f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) range.data[static_cast<std::size_t>(y) * W + x] = x < W / 3 ? 2.0f : y < 10 ? NAN : 30.0f;
  for (const double T : {1.0 / 60.0, 1.0 / 8.0}) {
    const StreakSlabs slabs = random_streaks(cam, 600, T, 7);
    Image cpu = base, gpu = base;
    const StreakSplat a = splat_streaks(slabs, range, cpu, cam, 2);
    StreakSplatTiming tm;
    const GpuStreakSplatter splatter(*ctx, tm);
    const StreakSplat b = splatter.splat(slabs, range, gpu, cam, 2);
    const Diff d = compare(gpu, cpu), moved = compare(cpu, base);
    std::printf("GPU stages: bin %.1f, upload %.1f, pass %.1f, read back %.1f ms\n", tm.bin_ms, tm.upload_ms,
                tm.splat_ms, tm.readback_ms);
    std::printf("T = %.4f s: %zu streaks, %zu list entries, %zu clamped (CPU %zu); the splat moved the image by "
                "max %.3g; GPU - CPU %s\n",
                T, a.drawn, tm.list_entries, b.alpha_clamped, a.alpha_clamped, moved.max_abs,
                (std::ostringstream() << d).str().c_str());
    EXPECT_GT(moved.max_abs, 0.5) << "the streaks must change the image";
    EXPECT_GT(a.alpha_clamped, 0u) << "some coverages must clamp";
    EXPECT_LE(d.max_abs, 1e-4) << d;
    EXPECT_LE(d.rms, 2e-6) << d;
    EXPECT_EQ(a.drawn, b.drawn);
    EXPECT_EQ(a.mean_streak_px, b.mean_streak_px);
    EXPECT_LE(std::abs(static_cast<double>(b.alpha_clamped) - static_cast<double>(a.alpha_clamped)),
              1e-3 * static_cast<double>(a.alpha_clamped) + 1.0);
    // Bit for bit on the same GPU and driver.
    Image again = base;
    (void)splatter.splat(slabs, range, again, cam, 1);
    EXPECT_EQ(again.data, gpu.data);
  }
}

}  // namespace rain_gpu_tests
