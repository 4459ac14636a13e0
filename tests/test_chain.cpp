// Haze then depth of field in one run (brume/chain.hpp): the chain equals
// `brume haze` then `brume dof` run separately through float files, its
// record repeats it bit for bit, the DOF stage's errors name the prefixed
// flags, plain haze is unchanged without --dof-..., and the GPU chain
// matches the CPU one.
#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include "brume/chain.hpp"
#include "brume/io.hpp"
#include "effects/dof/chain/chain_job.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

// A checkered scene (edges for both blurs to act on): ground receding from
// 3 m (bottom) to 60 m, a box at 2.5 m, the top rows unknown (sky), so the
// preparation runs and both stages share what it made.
struct ChainScene {
  Image rgb, range;
};
ChainScene chain_scene(int w, int h, int sky_rows) {
  ChainScene s{Image(w, h, 3), Image(w, h, 1)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool box = x >= w / 3 && x < w / 2 && y >= h / 2 && y < h - 6;
      const bool check = ((x / 4) + (y / 4)) % 2 == 0;
      s.rgb.at(x, y, 0) = check ? 0.9f : 0.1f;
      s.rgb.at(x, y, 1) = box ? 0.8f : 0.3f;
      s.rgb.at(x, y, 2) = 0.05f + 0.9f * static_cast<float>(x) / w;
      const float t = static_cast<float>(h - 1 - y) / static_cast<float>(h - 1 - sky_rows);  // 0 bottom, 1 horizon
      s.range.at(x, y) = y < sky_rows ? NAN : box ? 2.5f : 3.0f / (1.0f - 0.95f * t);
    }
  return s;
}

}  // namespace

TEST(Params, ChainIsDeclaredCompletelyWithPrefixedDofFlags) {
  const auto& t = haze_dof_job_table();
  // Every DOF parameter appears once, prefixed, in block "dof"; haze's keep their names.
  for (const auto& d : dof_param_table().params()) {
    const Param<HazeDofJob>* q = t.find(std::string(kDofPrefix) + d.spec.name);
    ASSERT_NE(q, nullptr) << d.spec.name;
    EXPECT_EQ(q->spec.block, "dof");
    EXPECT_EQ(q->spec.unit, d.spec.unit);
  }
  for (const auto& d : haze_job_table().params()) EXPECT_NE(t.find(d.spec.name), nullptr) << d.spec.name;
  EXPECT_NE(t.find("dof-scale-map"), nullptr);
  EXPECT_EQ(t.params().size(), haze_job_table().params().size() + dof_param_table().params().size() + 1);
  // Range errors name the prefixed flag.
  HazeDofJob j;
  const std::string m = error_of([&] { t.set_text(j, "dof-f-number", "0"); });
  EXPECT_NE(m.find("--dof-f-number"), std::string::npos) << m;
  // Help texts name the flags as this command spells them: the DOF's own
  // mentions gain the prefix, haze's (and unknown words) keep theirs.
  const std::string h = t.at("dof-f-number").spec.help;
  // (the lens is the camera's, shared: its help names --focal-length, no prefix)
  EXPECT_NE(h.find("--focal-length"), std::string::npos) << h;
  EXPECT_EQ(h.find("--dof-focal-length"), std::string::npos) << h;
  for (const auto& q : t.params()) {
    if (q.spec.block != "dof") continue;
    for (std::size_t i = q.spec.help.find("--"); i != std::string::npos; i = q.spec.help.find("--", i + 2)) {
      // The DOF's own flags with the prefix; the camera's (--focal-length, shared) as the chain spells them.
      const bool camera = q.spec.help.compare(i, 14, "--focal-length") == 0 ||
                          q.spec.help.compare(i, 14, "--sensor-width") == 0;
      EXPECT_TRUE(camera || q.spec.help.compare(i, 6, "--dof-") == 0) << q.spec.name << ": " << q.spec.help;
    }
  }
  EXPECT_EQ(prefix_flag_mentions("use --scheme, not --visibility-", "dof-",
                                 [](const std::string& n) { return n == "scheme" || n == "visibility"; }),
            "use --dof-scheme, not --dof-visibility-");
  EXPECT_TRUE(dof_stage_requested({"visibility", "dof-focus-distance"}));
  EXPECT_FALSE(dof_stage_requested({"visibility", "scale-map", "scheme"}));
}

TEST(ChainHazeDof, InMemoryEqualsTheTwoStages) {
  // The chain is a composition, nothing more: haze on the prepared range,
  // then depth of field on the hazy linear RGB with the same preparation.
  // Bit-identical (same code, same inputs, same thread-independent CPU path).
  const ChainScene s = chain_scene(96, 64, 10);
  HazeParams h;
  h.kappa_s = 0.5;
  h.lambda = 6.0;
  DofParams d;
  d.focus_distance_m = 4.0;
  d.f_number = 1.4;
  d.lens.focal_length_mm = 50.0;
  d.lens.sensor_width_mm = 12.0;  // alpha = 2500/(1.4 x 3950) mm x 96/12 = 3.6 px
  Intrinsics k;
  k.fx = k.fy = 50.0 * 96 / 12.0;
  k = resolve(k, 96, 64);
  const RangeStep prep;  // auto: the sky rows are unknown, so it prepares
  const HazeDofRun c = run_haze_dof(s.rgb, s.range, k, h, d, prep);
  const HazeRun a = run_haze(s.rgb, s.range, h, prep);
  const DofRun b = run_dof(a.result.rgb, s.range, k, d, prep);
  EXPECT_TRUE(c.record["prepare"]["applied"].get<bool>());
  EXPECT_EQ(compare(c.haze.result.rgb, a.result.rgb).max_abs, 0.0);
  EXPECT_EQ(compare(c.dof.result.rgb, b.result.rgb).max_abs, 0.0);
  EXPECT_EQ(compare(c.dof.result.scale, b.result.scale).max_abs, 0.0);
  // The DOF stage did something (the lens blur is not the identity here).
  EXPECT_GT(compare(c.dof.result.rgb, a.result.rgb).max_abs, 0.05);
  EXPECT_TRUE(c.record.contains("haze") && c.record.contains("dof"));
  EXPECT_TRUE(c.record["execution"]["timing"].contains("haze"));
  EXPECT_TRUE(c.record["execution"]["timing"].contains("dof"));
}

TEST(ChainHazeDof, ErrorsOfTheDofStageNameThePrefixedFlags) {
  const ChainScene s = chain_scene(32, 24, 0);
  Intrinsics k;
  k.fx = k.fy = 40.0;
  k = resolve(k, 32, 24);
  HazeParams h;
  DofParams d;  // no focus distance
  std::string m = error_of([&] { run_haze_dof(s.rgb, s.range, k, h, d, RangeStep{}); });
  EXPECT_NE(m.find("--dof-focus-distance is required"), std::string::npos) << m;
  d.focus_distance_m = 3.0;
  d.coc_infinity_px = 8.0;
  d.scheme = DofScheme::bertalmio;
  d.diffusion.edge_rate = EdgeRate::min;
  m = error_of([&] { run_haze_dof(s.rgb, s.range, k, h, d, RangeStep{}, {}, {"dof-edge-rate"}); });
  EXPECT_NE(m.find("--dof-edge-rate is not used by --dof-scheme bertalmio"), std::string::npos) << m;
  EXPECT_EQ(m.find(" --edge-rate"), std::string::npos) << m;
  // Haze's own flags keep their names.
  d = DofParams{};
  d.focus_distance_m = 3.0;
  d.coc_infinity_px = 8.0;
  h.albedo = 0.5;
  m = error_of([&] { run_haze_dof(s.rgb, s.range, k, h, d, RangeStep{}, {}, {"albedo"}); });
  EXPECT_NE(m.find("--albedo"), std::string::npos) << m;
  EXPECT_EQ(m.find("--dof-"), std::string::npos) << m;
}

TEST(ChainHazeDof, GpuMatchesCpu) {
  BRUME_REQUIRE_GPU(ctx);
  const ChainScene s = chain_scene(96, 64, 10);
  HazeParams h;
  h.kappa_s = 0.5;
  h.lambda = 6.0;
  DofParams d;
  d.focus_distance_m = 4.0;
  d.coc_infinity_px = 20.0;
  Intrinsics k;
  k.fx = k.fy = 80.0;
  k = resolve(k, 96, 64);
  Exec gpu;
  gpu.backend = Backend::gpu;
  gpu.gpu = ctx;
  const HazeDofRun a = run_haze_dof(s.rgb, s.range, k, h, d, RangeStep{});
  const HazeDofRun b = run_haze_dof(s.rgb, s.range, k, h, d, RangeStep{}, gpu);
  const Diff e = compare(a.dof.result.rgb, b.dof.result.rgb);
  std::printf("  chain GPU vs CPU: %s\n", ::testing::PrintToString(e.rms).c_str());
  EXPECT_LE(e.rms, 1e-3) << e;  // f32 on both stages (the bound of haze's and dof's own GPU tests)
  EXPECT_EQ(b.record["execution"]["backend"], "gpu");
  EXPECT_TRUE(b.record["execution"].contains("handoff"));
  EXPECT_TRUE(b.record["execution"]["timing"]["dof"].contains("upload_ms"));
  // A CPU-only DOF scheme is refused on --backend gpu, before any work.
  d.scheme = DofScheme::bertalmio;
  const std::string m = error_of([&] { run_haze_dof(s.rgb, s.range, k, h, d, RangeStep{}, gpu); });
  EXPECT_NE(m.find("--dof-scheme bertalmio"), std::string::npos) << m;
}

// ---- the command line -------------------------------------------------------------
class CliChain : public ScratchDirTest {
 protected:
  void SetUp() override {
    const ChainScene s = chain_scene(96, 64, 10);
    write_image(p("img.exr"), s.rgb, WriteOptions{});
    WriteOptions data;
    data.is_color = false;
    write_image(p("range.exr"), s.range, data);
  }
  std::string depth() const { return " --range " + p("range.exr") + " --fx 80"; }
  std::string haze_flags() const { return " --kappa-s 0.5 --lambda 6"; }
  std::string dof_flags(const std::string& pre) const {
    return " --" + pre + "focus-distance 4 --" + pre + "coc-infinity 16 --" + pre + "scheme invariant-exact";
  }
  std::size_t files() const {
    std::size_t n = 0;
    for (auto& e : fs::directory_iterator(dir)) (void)e, ++n;
    return n;
  }
};

TEST_F(CliChain, EqualsHazeThenDofThroughFloatFiles) {
  // Separately: haze to a float EXR (linear, no encoding), then dof reading it.
  CliRun r = run("haze --image " + p("img.exr") + depth() + haze_flags() + " --out " + p("hazy.exr") +
                 " --transmission " + p("t1.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = run("dof --image " + p("hazy.exr") + depth() + dof_flags("") + " --out " + p("sep.pfm") + " --scale-map " +
          p("s1.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  // In one run.
  r = run("haze --image " + p("img.exr") + depth() + haze_flags() + dof_flags("dof-") + " --out " + p("chain.pfm") +
          " --transmission " + p("t2.exr") + " --dof-scale-map " + p("s2.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("then dof"), std::string::npos) << r.output;
  const Image sep = read_color(p("sep.pfm")), chain = read_color(p("chain.pfm"));
  const Diff d = compare(sep, chain);
  std::printf("  chain vs haze then dof through files: %s\n", ::testing::PrintToString(d.max_abs).c_str());
  // Float files keep every float bit, so the only room is the 1e-6.
  EXPECT_LE(d.max_abs, 1e-6) << d;
  EXPECT_GT(compare(read_color(p("hazy.exr")), chain).max_abs, 0.05);  // the DOF stage acted
  EXPECT_LE(compare(read_scalar(p("t1.exr")), read_scalar(p("t2.exr"))).max_abs, 1e-6);
  EXPECT_LE(compare(read_scalar(p("s1.exr")), read_scalar(p("s2.exr"))).max_abs, 1e-6);
}

TEST_F(CliChain, RecordHoldsBothBlocksAndRepeatsBitForBit) {
  const CliRun r = run("haze --image " + p("img.exr") + depth() + haze_flags() + dof_flags("dof-") +
                       " --dof-sigma0 0.8 --out " + p("out.exr") + " --scale-map " + p("s.exr") + " --dof-scale-map " +
                       p("ds.exr") + " --record " + p("r.json") + " --timing");
  ASSERT_EQ(r.status, 0) << r.output;
  // --timing prints both stages.
  EXPECT_NE(r.output.find("\"haze\":{"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"dof\":{"), std::string::npos) << r.output;
  const nlohmann::json rec = read_json(p("r.json"));
  EXPECT_EQ(rec["command"], "haze+dof");
  EXPECT_EQ(rec["job"]["dof"]["dof-focus-distance"], 4.0);
  EXPECT_EQ(rec["job"]["dof"]["dof-sigma0"], 0.8);
  EXPECT_EQ(rec["job"]["diffusion"]["sigma0"], 1.0);  // haze's own inner scale, untouched
  EXPECT_EQ(rec["job"]["haze"]["kappa-s"], 0.5);
  EXPECT_EQ(rec["job"]["output"]["dof-scale-map"], p("ds.exr"));
  EXPECT_TRUE(rec.contains("haze") && rec.contains("dof"));
  EXPECT_EQ(rec["dof"]["derived"]["intrinsics"]["source"], "depth flags");
  fs::create_directories(dir / "again");
  const CliRun again = run("run " + p("r.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  expect_same_pixels(p("out.exr"), p("again/out.exr"));
  expect_same_pixels(p("s.exr"), p("again/s.exr"));
  expect_same_pixels(p("ds.exr"), p("again/ds.exr"));
  const nlohmann::json rec2 = read_json(p("again/r.json"));
  EXPECT_EQ(rec2["command"], "haze+dof");
  EXPECT_EQ(rec2["job"]["dof"], rec["job"]["dof"]);
}

TEST_F(CliChain, WithoutDofFlagsHazeIsUnchanged) {
  const CliRun r =
      run("haze --image " + p("img.exr") + depth() + haze_flags() + " --out " + p("h.exr") + " --record " + p("r.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("r.json"));
  EXPECT_EQ(rec["command"], "haze");
  EXPECT_FALSE(rec["job"].contains("dof"));
  EXPECT_FALSE(rec.contains("dof"));
  EXPECT_FALSE(rec["job"]["output"].contains("dof-scale-map"));
}

TEST_F(CliChain, ErrorsNameThePrefixedFlagsAndLeaveNothing) {
  const std::size_t before = files();
  const std::string base = "haze --image " + p("img.exr") + depth() + haze_flags();
  const std::string out = " --out " + p("o.exr") + " --dof-scale-map " + p("ds.exr") + " --record " + p("r.json");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "--dof-focus-distance is required"},  // --dof-scale-map alone enables the stage
      {" --dof-focus-distance 4", "--dof-f-number"},  // no lens, no CoC at infinity
      {dof_flags("dof-") + " --dof-f-number 2", "--dof-coc-infinity"},
      {dof_flags("dof-") + " --dof-f-number 0", "--dof-f-number"},
      {dof_flags("dof-") + " --dof-coc-limit 0.5", "--dof-coc-limit"},
      // (the lens is the camera's: --dof-focal-length is --focal-length's alias, named so in its errors)
      {" --dof-focus-distance 4 --dof-f-number 2 --dof-focal-length 50 --dof-sensor-width 36", "--focal-length"},
      {" --dof-focus-distance 4 --dof-coc-infinity 16 --dof-scheme bertalmio --dof-edge-rate min", "--dof-edge-rate"},
      {" --dof-focus-distance 4 --dof-coc-infinity 16 --dof-scheme bertalmio --backend gpu", "--dof-scheme"},
  };
  for (const auto& [flags, expect] : cases) {
    const CliRun r = run(base + flags + out);
    EXPECT_NE(r.status, 0) << flags;
    EXPECT_NE(r.output.find(expect), std::string::npos) << flags << ": " << r.output;
    EXPECT_EQ(files(), before) << flags;
  }
}
