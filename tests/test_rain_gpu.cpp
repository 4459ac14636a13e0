// Rain's and snow's camera pass on the GPU (effects/rain/rain_gpu.hpp; issues #56 and #58, "GPU
// for the per-pixel passes"): brume.rain's and brume.snow's array forms (in process) with
// backend gpu against backend cpu on the same inputs, a synthetic scene and the demo scene at
// 160x120, with and without haze's medium (visibility, its blur). The particles are enumerated
// and splatted on the CPU in both runs (the same particles: the record's block is equal); only
// the scene through the analytic media differs, by the GPU's float arithmetic:
//  - per pixel (the transmission map, and the image without visibility): tau = exp(-(sigma_haze
//    r + sigma r - G/cos theta)) in float on the GPU, in double on the CPU (G's table stored as
//    float). GLSL ES 3.00 lets exp be off by (3 + 2|x|) ULP, and the optical depths here stay
//    below 10: within 1e-5 of values <= 1 (measured on llvmpipe: 1.8e-7; the image, whose streaks
//    mix over it with weights <= 1: 1.2e-7);
//  - with visibility the ~20 diffusion passes run in f32 on both sides, in different orders: max
//    1e-4, RMS 1e-5 (measured on llvmpipe: max 1.3e-5, RMS 1.3e-7; haze's own GPU test holds the
//    GPU to the CPU's double path within RMS 1e-3, tests/test_gpu.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "brume/command.hpp"
#include "brume/demo_scene.hpp"
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
  EXPECT_NE(b.gpu.record["execution"]["split"].get<std::string>().find("on the CPU"), std::string::npos) << what;
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

}  // namespace rain_gpu_tests
