// The one list of commands (brume/command.hpp, issue #37): every command of
// the list reaches every place that iterates it -- `brume --help` and its
// flags, `brume run` (check_record), `brume batch` and `brume sample` -- and
// the media the effects model give their extinction in closed form.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "brume/batch.hpp"
#include "brume/command.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/rerun.hpp"
#include "brume/sample.hpp"
#include "test_util.hpp"
#if BRUME_HAVE_GPU
#include "gpu/passes.hpp"
#endif

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace {

std::string join(const std::vector<std::string>& w, std::size_t n) {
  std::string s;
  for (std::size_t i = 0; i < n; ++i) s += (i ? " " : "") + w[i];
  return s;
}

// A command's help line in its parent's --help: two spaces, the name, then its summary.
bool lists(const std::string& help, const std::string& name) {
  std::istringstream in(help);
  for (std::string line; std::getline(in, line);) {
    std::istringstream l(line);
    std::string first;
    if (l >> first && first == name && line.rfind("  ", 0) == 0) return true;
  }
  return false;
}

}  // namespace

// The list is well formed: unique names, each command's table declared with
// defaults for every parameter, every function present, the CLI names unique.
TEST(Commands, ListIsWellFormed) {
  std::set<std::string> names, clis;
  ASSERT_GE(commands().size(), 10u);
  for (const CommandDef& c : commands()) {
    SCOPED_TRACE(c.name);
    EXPECT_TRUE(names.insert(c.name).second) << "two commands named " << c.name;
    if (!c.cli.empty()) {
      EXPECT_TRUE(clis.insert(c.cli).second) << "two commands on `brume " << c.cli << "`";
    }
    EXPECT_FALSE(c.summary.empty());
    EXPECT_FALSE(c.specs.empty());
    ASSERT_TRUE(c.build && c.check && c.run && c.report);
    for (const ParamSpec& s : c.specs) {
      ASSERT_TRUE(c.defaults.contains(s.block) && c.defaults[s.block].contains(s.name)) << s.block << "." << s.name;
      EXPECT_EQ(c.spec(s.name), &s);
    }
    // The default job reads back (every value is its declaration's).
    EXPECT_NO_THROW(c.check(c.defaults, {}, false));
    EXPECT_EQ(c.build({}), c.defaults);
    EXPECT_EQ(find_command(c.name), &c);
    if (c.sampling) {
      for (const SampleDefault& d : c.sampling->defaults) EXPECT_TRUE(c.spec(d.name)) << d.name;
    }
    if (!c.stage_prefix.empty()) {
      EXPECT_EQ(c.stage_prefix.back(), '-');
    }
  }
  EXPECT_EQ(find_command("no such command"), nullptr);
}

// A command with no GPU pass refuses --backend gpu (it ran on the CPU
// without a word: rain and wet, issue #56, before they had passes); one with
// passes takes it (the context is another matter); cpu and auto pass everywhere.
TEST(Commands, OnlyCommandsWithGpuPassesTakeTheGpu) {
  int cpu_only = 0;
  for (const CommandDef& c : commands()) {
    SCOPED_TRACE(c.name);
    EXPECT_NO_THROW(refuse_gpu_without_passes(c, Backend::cpu, "--backend"));
    EXPECT_NO_THROW(refuse_gpu_without_passes(c, Backend::automatic, "--backend"));
    if (!c.gpu_passes.empty()) {
      EXPECT_NO_THROW(refuse_gpu_without_passes(c, Backend::gpu, "--backend"));
      continue;
    }
    ++cpu_only;
    try {
      refuse_gpu_without_passes(c, Backend::gpu, "backend=");
      ADD_FAILURE() << "took the GPU";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(c.name + " runs on the CPU only"), std::string::npos) << m;
      EXPECT_NE(m.find("use backend= cpu or auto"), std::string::npos) << m;
      EXPECT_NE(m.find("haze"), std::string::npos) << m;  // the list of those that have passes
    }
  }
  EXPECT_GE(cpu_only, 3);  // insert and the LiDAR's commands at least
}

// Every command with a subcommand is listed by its parent's --help, and its
// own --help shows every flag of its table (and the execution flags when it
// takes them).
TEST(Commands, EveryCommandIsOnTheCommandLine) {
  for (const CommandDef& c : commands()) {
    if (c.cli.empty()) continue;
    SCOPED_TRACE(c.name);
    const std::vector<std::string> w = c.cli_words();
    const CliRun parent = run(join(w, w.size() - 1) + " --help");
    ASSERT_EQ(parent.status, 0) << parent.output;
    EXPECT_TRUE(lists(parent.output, w.back())) << parent.output;
    const CliRun own = run(c.cli + " --help");
    ASSERT_EQ(own.status, 0) << own.output;
    for (const ParamSpec& s : c.specs) {
      // "--name TYPE", "--name,--alias TYPE" or "--alias,--name TYPE".
      const std::string f = "--" + s.name;
      bool shown = false;
      for (std::size_t at = own.output.find(f); at != std::string::npos && !shown; at = own.output.find(f, at + 1))
        shown = at + f.size() < own.output.size() && std::string(" ,=").find(own.output[at + f.size()]) != std::string::npos;
      EXPECT_TRUE(shown) << s.name;
    }
    EXPECT_EQ(own.output.find("--threads") != std::string::npos, c.takes_exec_flags);
  }
  // A command without a subcommand of its own is reached through one that has
  // every one of its flags (plain haze through haze+dof's `brume haze`).
  for (const CommandDef& c : commands()) {
    if (!c.cli.empty()) continue;
    bool reached = false;
    for (const CommandDef& d : commands())
      if (d.cli == c.name && std::all_of(c.specs.begin(), c.specs.end(), [&](const ParamSpec& s) { return d.spec(s.name); }))
        reached = true;
    EXPECT_TRUE(reached) << c.name << " has no subcommand that takes its flags";
  }
}

// `brume run` accepts the record of every command that writes one (its
// default job, read back through the command's table) and refuses the others
// naming those it repeats.
TEST(Commands, EveryRecordCommandIsAcceptedByRun) {
  for (const CommandDef& c : commands()) {
    SCOPED_TRACE(c.name);
    const nlohmann::json rec = {
        {"tool", "brume"}, {"schema_version", kRecordSchemaVersion}, {"command", c.name}, {"job", c.defaults}};
    if (c.writes_record) {
      EXPECT_EQ(check_record(rec), c.name);
      // A key the command does not declare is refused by its table.
      nlohmann::json bad = rec;
      bad["job"][c.specs.front().block]["no-such-flag"] = 1;
      EXPECT_NE(error_of([&] { check_record(bad); }).find("no-such-flag"), std::string::npos);
    } else {
      const std::string e = error_of([&] { check_record(rec); });
      EXPECT_NE(e.find("cannot be repeated by brume run"), std::string::npos) << e;
      for (const CommandDef& d : commands())
        if (d.writes_record) {
          EXPECT_NE(e.find(d.name), std::string::npos) << e;
        }
    }
  }
}

// Every batchable command is planned by `brume batch` from a manifest row
// naming it, with its sampled parameters (a chain: each stage's, the later
// ones under "<stage>."), and every sampleable one draws its defaults through
// random_params and `brume sample`.
class CommandsInFiles : public ScratchDirTest {};

TEST_F(CommandsInFiles, ManifestRowsAndTheSamplerTakeEveryOne) {
  const Scene s = scene(24, 16, 4);
  write_image((dir / "a.pfm").string(), s.rgb, WriteOptions{}, "");
  write_image((dir / "a.range.pfm").string(), s.range, WriteOptions{}, "");
  std::vector<std::string> batchable;
  std::ofstream m(dir / "m.jsonl");
  for (const CommandDef& c : commands()) {
    if (c.sampling) {
      SCOPED_TRACE(c.name);
      const nlohmann::json v = random_params(c.name, 3, "frame", {});
      for (const SampleDefault& d : c.sampling->defaults)
        if (d.dropped_by.empty()) {
          EXPECT_TRUE(v.contains(d.name)) << d.name;
        }
      const CliRun r = run("sample --effect '" + c.name + "' --seed 3 --key frame");
      EXPECT_EQ(r.status, 0) << r.output;
      EXPECT_EQ(nlohmann::json::parse(r.output.substr(r.output.find('{')))["params"], v);
    }
    if (!c.batchable) continue;
    batchable.push_back(c.name);
    nlohmann::json row = {{"key", c.name + "/f.pfm"}, {"image", (dir / "a.pfm").string()},
                          {"range", (dir / "a.range.pfm").string()}, {"effect", c.name}};
    const std::vector<std::string> stages = [&] {
      std::vector<std::string> st;
      std::string n = c.name;
      for (std::size_t at; (at = n.find('+')) != std::string::npos; n = n.substr(at + 1)) st.push_back(n.substr(0, at));
      st.push_back(n);
      return st;
    }();
    for (std::size_t i = 0; i < stages.size(); ++i) {
      const CommandDef* stage = find_command(stages[i]);
      ASSERT_TRUE(stage) << stages[i];
      if (!stage->sampling) continue;
      for (const SampleDefault& d : stage->sampling->defaults) row[(i ? stages[i] + "." : "") + d.name] = d.spec;
    }
    // What a command needs beyond its sampled values, as its own check says (wet ground: the plane's height).
    if (c.name == "wet") row["camera-height"] = 1.6;
    m << row.dump() << "\n";
  }
  m.close();
  ASSERT_FALSE(batchable.empty());
  BatchOptions o;
  o.manifest = (dir / "m.jsonl").string();
  o.out_dir = (dir / "out").string();
  o.seed = 5;
  std::vector<BatchFrame> frames;
  try {
    frames = plan_batch(o);
  } catch (const Error& e) {
    FAIL() << e.what();
  }
  ASSERT_EQ(frames.size(), batchable.size());
  for (std::size_t i = 0; i < frames.size(); ++i) EXPECT_EQ(frames[i].effect, batchable[i]);
  EXPECT_EQ(batch_effects(), batchable);
  std::vector<std::string> sampleable;
  for (const CommandDef& c : commands())
    if (c.sampling) sampleable.push_back(c.name);
  EXPECT_EQ(sample_effects(), sampleable);
}

// The medium of a camera effect, as the LiDAR fog reads it: haze's is
// Koschmieder's 3.912 / V (or the normalised kappas over a given R_max, none
// without), fog's exponential profile D0 exp(-B (y - Y0)) in closed form.
// Tolerance: the same double expression, 1e-15 relative.
TEST(Commands, ExtinctionOfTheModelledMedium) {
  const CommandDef* haze = find_command("haze");
  const CommandDef* fog = find_command("fog");
  ASSERT_TRUE(haze && fog && haze->extinction_per_m && fog->extinction_per_m);
  EXPECT_EQ(haze->extinction_per_m(haze->defaults, 0.0), std::nullopt);
  EXPECT_NEAR(*haze->extinction_per_m(haze->build({{"visibility", 1000.0}}), 12.0), 3.912e-3, 1e-18);
  EXPECT_NEAR(*haze->extinction_per_m(haze->build({{"kappa-a", 0.1}, {"kappa-s", 0.3}, {"range-max", 200.0}}), 0.0),
              0.4 / 200.0, 1e-18);
  const nlohmann::json f = fog->build({{"density", 0.03}, {"falloff", 0.1}, {"base-height", 5.0}});
  for (double y : {-10.0, 0.0, 5.0, 42.0})
    EXPECT_NEAR(*fog->extinction_per_m(f, y), 0.03 * std::exp(-0.1 * (y - 5.0)), 1e-15 * 0.03 * std::exp(1.5)) << y;
  EXPECT_EQ(fog->extinction_per_m(fog->build({{"classic", "linear"}}), 0.0), std::nullopt);
  // Commands that model no medium have none.
  for (const char* n : {"blur", "depth convert", "compare"}) EXPECT_FALSE(find_command(n)->extinction_per_m) << n;
}

// A preview of an image above the browser's largest texture runs on inputs
// at 1/k (brume view): intrinsics given in the files' pixels (--fx, --cx,
// --calib) must give each smaller pixel the ray of the full-size pixel its
// range was sampled at. Checked through planar depth: at 1/2 and 1/3 it
// equals the full image's planar depth at pixel (k x' + k/2), computed with
// the full-size intrinsics.
TEST(Commands, PreviewIntrinsicsGiveTheSampledPixelsRays) {
  const int W = 61, H = 41;
  Image range(W, H, 1);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) range.at(x, y) = 3.0f + 0.05f * static_cast<float>(x) + 0.11f * static_cast<float>(y);
  const Intrinsics full{70.0, 64.0, 27.3, 22.9};
  const Image z_full = planar_depth(range, full);
  for (const int k : {2, 3}) {
    const int w = W / k, h = H / k;
    Image small(w, h, 1);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) small.at(x, y) = range.at(k * x + k / 2, k * y + k / 2);
    const Image z_small = planar_depth(small, preview_intrinsics(full, k));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        ASSERT_NEAR(z_small.at(x, y), z_full.at(k * x + k / 2, k * y + k / 2), 2e-6f * z_full.at(k * x + k / 2, k * y + k / 2))
            << "k " << k << " at " << x << "," << y;  // float32 rounding of the same ray
  }
}

#if BRUME_HAVE_GPU
// The non-sampler uniforms a pass's body declares ("uniform float uA, uB;",
// "uniform vec3 uK[4];"), for the plan checks below.
std::set<std::string> declared_uniforms(const char* body) {
  std::set<std::string> out;
  const std::regex decl(R"(uniform\s+(?:(?:highp|mediump|lowp)\s+)?(\w+)\s+([^;]+);)");
  const std::string text = body;
  for (std::sregex_iterator it(text.begin(), text.end(), decl), end; it != end; ++it) {
    if ((*it)[1].str().find("sampler") != std::string::npos) continue;
    std::stringstream names((*it)[2].str());
    for (std::string n; std::getline(names, n, ',');) {
      n = std::regex_replace(n, std::regex(R"(\[.*\]|\s)"), "");
      if (!n.empty()) out.insert(n);
    }
  }
  return out;
}
#endif

// Every command with a browser preview (brume view, docs/view.md): its plan on
// a small scene draws only passes of its gpu_passes, every one of them
// linked (the page compiles their text), from textures the plan declares or
// maps the frame holds; each step binds as many textures as its pass has
// samplers and sets every uniform its pass declares (the page skips a name a
// pass lacks and leaves an unset one 0, so a misspelt or missing uniform
// would draw quietly wrong). Modes: each command's job, and the variants
// below (aerial's re-render and removal, no blur).
TEST(Commands, EveryPreviewPlanDrawsItsOwnLinkedPasses) {
  const int w = 24, h = 16;
  Image rgb(w, h, 3), range(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) rgb.data[(y * w + x) * 3 + c] = 0.1f + 0.03f * static_cast<float>(x + c);
      range.data[y * w + x] = y < 4 ? NAN : 5.0f + static_cast<float>(x + y);  // a sky band
    }
  const PreparedRange prep = prepare_step(range, RangeStep{}, {}, 1, true);
  const std::map<std::string, std::vector<JobValues>> variants = {
      {"aerial", {{{"from-turbidity", 6.0}}, {{"remove", true}, {"lambda", 0.0}}, {{"lambda", 0.0}}}},
      {"haze", {{{"lambda", 0.0}}}},
      {"fog", {{{"lambda", 0.0}}}},
  };
  int shown = 0;
  for (const CommandDef& c : commands()) {
    if (!c.preview) continue;
    ++shown;
    JobValues base = {{"image", "x.png"}, {"range", "r.exr"}, {"out", "o.png"}, {"fov-x", 60.0}};
    if (c.spec("camera-height")) base.emplace_back("camera-height", 1.6);
    if (c.spec("visibility")) base.emplace_back("visibility", 40.0);
    if (c.spec("focus-distance")) base.emplace_back("focus-distance", 10.0);
    if (c.spec("coc-infinity")) base.emplace_back("coc-infinity", 8.0);
    if (c.spec("dof-focus-distance")) base.emplace_back("dof-focus-distance", 10.0);
    if (c.spec("dof-coc-infinity")) base.emplace_back("dof-coc-infinity", 8.0);
    if (c.spec("lambda")) base.emplace_back("lambda", 4.0);  // the blur's steps too
    std::vector<JobValues> jobs = {base};
    if (const auto it = variants.find(c.name); it != variants.end())
      for (const JobValues& extra : it->second) {
        JobValues v = base;
        for (const auto& e : extra) {
          v.erase(std::remove_if(v.begin(), v.end(), [&](const auto& x) { return x.first == e.first; }), v.end());
          v.push_back(e);
        }
        jobs.push_back(v);
      }
    for (const JobValues& v : jobs) {
      const nlohmann::json job = c.build(v);
      SCOPED_TRACE(c.name + " variant " + std::to_string(&v - jobs.data()));
      const PreviewFrame frame = c.preview(job, PreviewInputs{rgb, range, prep});
      const nlohmann::json& plan = frame.plan;
      std::set<std::string> textures = {"image", "range", "sky"};
      for (const auto& [name, fmt] : plan.at("targets").items()) textures.insert(name);
      std::set<std::string> data;
      for (const auto& d : plan.value("data", nlohmann::json::array())) data.insert(d.get<std::string>());
      EXPECT_EQ(data.size(), frame.maps.size()) << "every map the plan names, and no other";
      for (const auto& [name, m] : frame.maps) {
        EXPECT_TRUE(data.count(name)) << name;
        EXPECT_TRUE(m.channels >= 1 && m.channels <= 4 && m.pixels() > 0) << name;
        textures.insert(name);
      }
      for (const auto& step : plan.at("steps")) {
        if (step.contains("copy")) {
          EXPECT_TRUE(textures.count(step["copy"].at("from").get<std::string>()));
          continue;
        }
        const std::string pass = step.at("pass");
        EXPECT_NE(std::find(c.gpu_passes.begin(), c.gpu_passes.end(), pass), c.gpu_passes.end()) << pass;
        for (const auto& t : step.at("in"))
          EXPECT_TRUE(t == "$src" || textures.count(t.get<std::string>())) << pass << " reads " << t;
#if BRUME_HAVE_GPU
        const gpu::PassSpec* spec = gpu::find_pass(pass);
        ASSERT_NE(spec, nullptr) << pass;
        EXPECT_EQ(step.at("in").size(), gpu::sampler_names(spec->body).size()) << pass << ": one texture per sampler";
        EXPECT_FALSE(declared_uniforms(spec->body).empty()) << pass << ": every pass has uniforms (the parser read none)";
        std::set<std::string> set;
        for (const auto& [u, value] : step.at("uniforms").items()) set.insert(u);
        if (step.contains("iterate")) set.insert(step["iterate"].at("uniform").get<std::string>());
        for (const std::string& u : declared_uniforms(spec->body)) EXPECT_TRUE(set.count(u)) << pass << " leaves " << u << " unset";
        for (const std::string& u : set) EXPECT_TRUE(declared_uniforms(spec->body).count(u)) << pass << " has no " << u;
#endif
        if (step.contains("iterate")) textures.insert(step["iterate"].at("last").get<std::string>());
      }
      EXPECT_TRUE(textures.count(plan.at("result").get<std::string>()));
    }
  }
  EXPECT_GE(shown, 5);  // haze, fog, aerial, dof, haze+dof at least
}

// `brume view --effect` names exactly the commands that have a preview. The
// view's choice list is kept by hand (src/jobs/view/view.cpp, preview_names:
// the view is itself a command of the list, so its table cannot read the list
// while the list is built); this fails when a command gains or loses its
// preview without the view's list following.
TEST(Commands, TheViewOffersEveryPreview) {
  std::set<std::string> previewed;
  for (const CommandDef& c : commands())
    if (c.preview) previewed.insert(c.name);
  const CommandDef* view = find_command("view");
  ASSERT_NE(view, nullptr);
  const ParamSpec* effect = view->spec("effect");
  ASSERT_NE(effect, nullptr);
  EXPECT_EQ(std::set<std::string>(effect->choices.begin(), effect->choices.end()), previewed);
  EXPECT_EQ(effect->choices.size(), previewed.size()) << "a name offered twice";
}
