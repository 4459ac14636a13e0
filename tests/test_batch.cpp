// `brume batch` (issue #17): manifests, sampled parameters, shards, resume
// after SIGKILL, failure isolation, dataset scans, chains. A batch frame must
// be exactly the single run it stands for, so most checks compare against
// `brume haze` runs and the documented hashes, computed here independently.
#include <openssl/evp.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "brume/batch.hpp"
#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/io.hpp"
#include "brume/sample.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace {

// The documented 64-bit prefix: the first 8 bytes, big-endian, of SHA-256(msg).
std::uint64_t sha_prefix(const std::string& msg) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_Digest(msg.data(), msg.size(), md, &len, EVP_sha256(), nullptr);
  std::uint64_t n = 0;
  for (int i = 0; i < 8; ++i) n = (n << 8) | md[i];
  return n;
}
double unit_of(std::uint64_t seed, const std::string& key, const std::string& name) {
  const std::string msg = std::string("brume-sample-v1") + '\0' + std::to_string(seed) + '\0' + key + '\0' + name;
  return static_cast<double>(sha_prefix(msg) >> 11) * 0x1p-53;
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

class Batch : public ScratchDirTest {
 protected:
  void SetUp() override { fs::create_directories(dir / "data"); }

  // n small RGB-D frames data/<sub>/fI.png + fI.exr, in two subfolders (keys with '/').
  std::vector<std::string> make_frames(int n, int w = 64, int h = 48) {
    std::vector<std::string> keys;
    for (int i = 0; i < n; ++i) {
      const std::string sub = i % 2 ? "b" : "a";
      fs::create_directories(dir / "data" / sub);
      const Scene s = scene(w, h, 0, 100 + i);
      const std::string stem = sub + "/f" + std::to_string(i);
      write_image(p("data/" + stem + ".png"), s.rgb, WriteOptions{});
      WriteOptions f;
      f.is_color = false;
      f.float_reason = "metres";
      write_image(p("data/" + stem + ".exr"), s.range, f);
      keys.push_back(stem + ".png");
    }
    return keys;
  }
  // A CSV manifest in data/ with the given extra columns per row.
  std::string csv(const std::vector<std::string>& keys, const std::string& cols, const std::string& vals,
                  const std::string& name = "m.csv") {
    std::string t = "image,range," + cols + "\n";
    for (const std::string& k : keys) t += k + "," + k.substr(0, k.size() - 4) + ".exr," + vals + "\n";
    std::ofstream(p("data/" + name)) << t;
    return p("data/" + name);
  }
  // Relative paths of every file under d, temporaries and results manifests excluded.
  std::set<std::string> files(const fs::path& d) const {
    std::set<std::string> s;
    for (const auto& e : fs::recursive_directory_iterator(d)) {
      if (!e.is_regular_file()) continue;
      const std::string r = e.path().lexically_relative(d).generic_string();
      if (r.rfind("results", 0) == 0) continue;
      s.insert(r);
    }
    return s;
  }
  // Two output folders hold the same files, the same pixels, and records equal
  // apart from the time and the timings.
  void expect_same_outputs(const fs::path& a, const fs::path& b) {
    const std::set<std::string> fa = files(a), fb = files(b);
    EXPECT_EQ(fa, fb);
    // The folders' own names (in argv and the job's output paths) are the one allowed difference.
    auto record_of = [](const fs::path& d, const std::string& f) {
      std::string t = slurp(d / f);
      const std::string name = d.string();
      for (std::size_t at = t.find(name); at != std::string::npos; at = t.find(name, at)) t.replace(at, name.size(), "OUT");
      return nlohmann::json::parse(t);
    };
    for (const std::string& f : fa) {
      if (!fb.count(f)) continue;
      if (fs::path(f).extension() == ".json") {
        nlohmann::json ra = record_of(a, f), rb = record_of(b, f);
        for (nlohmann::json* r : {&ra, &rb}) {
          r->erase("time_utc");
          (*r)["execution"].erase("timing");
        }
        EXPECT_EQ(ra, rb) << f;
      } else {
        expect_same_pixels((a / f).string(), (b / f).string());
      }
    }
  }
};

const char* kHaze = "effect,visibility,albedo,lambda";
const char* kHazeVals = "haze,\"loguniform(50, 5000)\",\"uniform(0.8, 1)\",\"choice(2, 4)\"";

}  // namespace

// Sampled values lie in their ranges, are the documented inverse CDFs of the
// documented hash (computed here with OpenSSL), reach the record, and do not
// change when the rows are reordered.
TEST_F(Batch, SampledParametersInRangeAndIndependentOfRowOrder) {
  std::vector<std::string> keys = make_frames(6);
  BatchOptions o;
  o.manifest = csv(keys, kHaze, kHazeVals);
  o.out_dir = p("out");
  o.seed = 11;
  const std::vector<BatchFrame> a = plan_batch(o);
  std::reverse(keys.begin(), keys.end());
  o.manifest = csv(keys, kHaze, kHazeVals, "reversed.csv");
  std::vector<BatchFrame> b = plan_batch(o);
  ASSERT_EQ(a.size(), 6u);
  std::set<double> vis;
  for (const BatchFrame& f : a) {
    const auto it = std::find_if(b.begin(), b.end(), [&](const BatchFrame& g) { return g.key == f.key; });
    ASSERT_NE(it, b.end());
    EXPECT_EQ(f.batch["values"], it->batch["values"]) << f.key;
    const double v = f.job["haze"]["visibility"].get<double>(), al = f.job["haze"]["albedo"].get<double>(),
                 la = f.job["haze"]["lambda"].get<double>();
    EXPECT_GE(v, 50.0);
    EXPECT_LT(v, 5000.0);
    EXPECT_GE(al, 0.8);
    EXPECT_LT(al, 1.0);
    EXPECT_TRUE(la == 2.0 || la == 4.0) << la;
    // The inverse CDFs at the documented u (1e-12 relative: exp/log rounding only).
    const double uv = unit_of(11, f.key, "visibility"), ua = unit_of(11, f.key, "albedo");
    EXPECT_NEAR(v, std::exp(std::log(50.0) + uv * (std::log(5000.0) - std::log(50.0))), 1e-12 * v);
    EXPECT_NEAR(al, 0.8 + ua * 0.2, 1e-15);
    EXPECT_EQ(la, unit_of(11, f.key, "lambda") < 0.5 ? 2.0 : 4.0);
    EXPECT_EQ(f.batch["sampling"]["specs"]["visibility"], "loguniform(50, 5000)");
    vis.insert(v);
  }
  EXPECT_EQ(vis.size(), 6u) << "six frames drew six visibilities";
  // Another seed draws other values.
  o.seed = 12;
  EXPECT_NE(plan_batch(o)[0].batch["values"], a.back().batch["values"]);

  // The values reach the record (two frames run through the CLI).
  o.seed = 11;
  const std::string two = csv({keys[0], keys[1]}, kHaze, kHazeVals, "two.csv");
  const CliRun r = run("batch --manifest " + two + " --out-dir " + p("out") + " --seed 11 --workers 2 --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("out/" + keys[0].substr(0, keys[0].size() - 4) + ".json"));
  const auto it = std::find_if(a.begin(), a.end(), [&](const BatchFrame& f) { return f.key == keys[0]; });
  EXPECT_EQ(rec["job"]["haze"]["visibility"], it->job["haze"]["visibility"]);
  EXPECT_EQ(rec["batch"]["sampling"]["sampler"], "brume-sample-v1");
  EXPECT_EQ(rec["command"], "haze");
}

// A batch frame is the `brume haze` run with the same values, to the last bit,
// and `brume run` repeats its record.
TEST_F(Batch, FrameEqualsSingleRunAndRecordRepeats) {
  const std::vector<std::string> keys = make_frames(2);
  const std::string m = csv(keys, "effect,visibility,albedo,lambda", "haze,300,0.9,4");
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("out") + " --quiet --map transmission");
  ASSERT_EQ(r.status, 0) << r.output;
  r = run("haze --image " + p("data/a/f0.png") + " --range " + p("data/a/f0.exr") +
          " --visibility 300 --albedo 0.9 --lambda 4 --out " + p("single.png") + " --transmission " + p("single_t.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("out/a/f0.png"), p("single.png"));
  // A batch's PNG frames are written with rle by default (a single run keeps the writer's zip:6).
  EXPECT_EQ(nlohmann::json::parse(slurp(p("out/a/f0.json")))["job"]["output"]["compression"], "fast");
  const Image t1 = read_scalar(p("out/a/f0.transmission.exr")), t2 = read_scalar(p("single_t.exr"));
  ASSERT_EQ(t1.data.size(), t2.data.size());
  EXPECT_EQ(std::memcmp(t1.data.data(), t2.data.data(), t1.data.size() * sizeof(float)), 0);
  r = run("run " + p("out/a/f0.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("out/a/f0.png"), p("again/f0.png"));
}

// On --backend gpu each worker runs its frames on one context of its own
// (made once, on its thread): the frames equal single `brume haze --backend
// gpu` runs bit for bit (one driver, the same passes), and their records say
// they ran on the GPU. Needs an OpenGL ES 3.2 context (llvmpipe in CI).
TEST_F(Batch, GpuFramesShareAWorkerContextAndEqualSingleRuns) {
  try {
    GpuContext probe;
  } catch (const Error& e) {
    BRUME_NO_GPU(e.what());
  }
  const std::vector<std::string> keys = make_frames(4);
  const std::string m = csv(keys, "effect,visibility,albedo", "haze,300,0.9");
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("out") + " --quiet --workers 2 --backend gpu");
  ASSERT_EQ(r.status, 0) << r.output;
  // In process, the contexts made: at most one per worker (one per frame
  // would be 4), at least one (the frames did run on the GPU).
  {
    BatchOptions o;
    o.manifest = m;
    o.out_dir = p("in_process");
    o.workers = 2;
    o.exec.backend = Backend::gpu;
    o.progress = false;
    const std::uint64_t before = gpu_contexts_made();
    const BatchSummary s = run_batch(o);
    const std::uint64_t made = gpu_contexts_made() - before;
    EXPECT_EQ(s.ok, 4u);
    EXPECT_GE(made, 1u);
    EXPECT_LE(made, 2u) << "contexts made for 4 frames on 2 workers";
  }
  for (int i : {0, 3}) {
    const std::string stem = std::string(i % 2 ? "b" : "a") + "/f" + std::to_string(i);
    r = run("haze --image " + p("data/" + stem + ".png") + " --range " + p("data/" + stem + ".exr") +
            " --visibility 300 --albedo 0.9 --backend gpu --out " + p("single.png"));
    ASSERT_EQ(r.status, 0) << r.output;
    expect_same_pixels(p("out/" + stem + ".png"), p("single.png"));
    EXPECT_EQ(nlohmann::json::parse(slurp(p("out/" + stem + ".json")))["execution"]["backend"], "gpu") << stem;
  }
}

// --compression is an output setting, not a file: a manifest column or
// --param sets it, the pixels are those of the default, the record holds it
// and `brume run` repeats it (the output block's other text parameters are
// files, which brume batch names and brume run moves).
TEST_F(Batch, CompressionIsASettingNotAFile) {
  const std::vector<std::string> keys = make_frames(2, 96, 64);
  const std::string m = csv(keys, "effect,visibility,compression", "haze,300,none");
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("none") + " --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  r = run("batch --manifest " + csv(keys, "effect,visibility", "haze,300", "d.csv") + " --out-dir " + p("dflt") +
          " --quiet --param compression=zip:9");
  ASSERT_EQ(r.status, 0) << r.output;
  for (const std::string stem : {"a/f0", "b/f1"}) {
    expect_same_pixels(p("none/" + stem + ".png"), p("dflt/" + stem + ".png"));
    // Stored deflate blocks hold at least the raw 8-bit samples; level 9 compresses.
    EXPECT_GE(fs::file_size(p("none/" + stem + ".png")), 96u * 64 * 3);
    EXPECT_LT(fs::file_size(p("dflt/" + stem + ".png")), fs::file_size(p("none/" + stem + ".png")));
    const nlohmann::json rec = nlohmann::json::parse(slurp(p("dflt/" + stem + ".json")));
    EXPECT_EQ(rec["job"]["output"]["compression"], "zip:9");
  }
  r = run("run " + p("none/a/f0.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_GE(fs::file_size(p("again/f0.png")), 96u * 64 * 3);  // stored again, not the default's deflate
  expect_same_pixels(p("none/a/f0.png"), p("again/f0.png"));
  // A compression the output format does not take is a manifest error, before any work.
  r = run("batch --manifest " + p("data/d.csv") + " --out-dir " + p("pfm") + " --quiet --format pfm --param compression=zip");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("auto, none"), std::string::npos) << r.output;
  r = run("batch --manifest " + csv(keys, "effect,compression", "haze,lzw", "bad.csv") + " --out-dir " + p("bad") +
          " --quiet");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("'lzw'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("line 2"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("bad"))) << r.output;
}

// Shards 1/3, 2/3, 3/3 together are the unsharded run: every frame in exactly
// one shard, by the documented hash, with the same files and bits.
TEST_F(Batch, ShardsTogetherEqualTheWhole) {
  const std::vector<std::string> keys = make_frames(9, 48, 32);
  const std::string m = csv(keys, kHaze, kHazeVals);
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("whole") + " --seed 3 --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  std::size_t lines = 0;
  std::set<int> used;
  for (int i = 1; i <= 3; ++i) {
    r = run("batch --manifest " + m + " --out-dir " + p("sharded") + " --seed 3 --quiet --shard " + std::to_string(i) +
            "/3");
    ASSERT_EQ(r.status, 0) << r.output;
    std::ifstream f(p("sharded/results.shard-" + std::to_string(i) + "-of-3.jsonl"));
    std::string l;
    while (std::getline(f, l)) {
      const nlohmann::json j = nlohmann::json::parse(l);
      const std::string key = j["key"];
      const int want = static_cast<int>(sha_prefix(std::string("brume-shard-v1") + '\0' + key) % 3) + 1;
      EXPECT_EQ(want, i) << key;
      EXPECT_EQ(shard_of(key, 3), i) << key;
      used.insert(i);
      ++lines;
    }
  }
  EXPECT_EQ(lines, keys.size());
  EXPECT_GE(used.size(), 2u) << "nine keys fell into one shard: the split would be untested";
  expect_same_outputs(p("whole"), p("sharded"));
}

// SIGKILL at several moments, then --resume: the same files, pixel bits and
// records (apart from times) as an uninterrupted run, and frames finished
// before the kill are skipped, not redone.
TEST_F(Batch, ResumeAfterSigkillEqualsUninterruptedRun) {
  const std::vector<std::string> keys = make_frames(8, 160, 120);
  const std::string m = csv(keys, kHaze, "haze,\"loguniform(100, 1000)\",0.9,\"uniform(4, 8)\"");
  const std::string common = " --seed 5 --workers 2 --threads 1 --quiet";
  const auto t0 = std::chrono::steady_clock::now();
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("whole") + common);
  ASSERT_EQ(r.status, 0) << r.output;
  const double whole_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();

  // Kill moments: early (a fixed fraction of the uninterrupted time, likely
  // before any frame ends), and as soon as 1 and then 4 records exist (polled
  // every 2 ms, so the kill lands while other frames are in flight).
  auto count_records = [](const std::string& out) {
    std::size_t n = 0;
    std::error_code ec;
    if (fs::exists(out, ec))
      for (const auto& e : fs::recursive_directory_iterator(out, ec))
        n += e.path().extension() == ".json" && e.path().filename().string()[0] != '.';
    return n;
  };
  bool interrupted_midway = false;
  int round = 0;
  for (const int after_records : {0, 1, 4}) {
    const std::string out = p("killed" + std::to_string(round++));
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      execl(BRUME_CLI, BRUME_CLI, "batch", "--manifest", m.c_str(), "--out-dir", out.c_str(), "--seed", "5",
            "--workers", "2", "--threads", "1", "--quiet", static_cast<char*>(nullptr));
      _exit(127);
    }
    if (after_records == 0) {
      std::this_thread::sleep_for(std::chrono::microseconds(static_cast<long>(0.1 * whole_ms * 1000)));
    } else {
      const auto start = std::chrono::steady_clock::now();
      while (count_records(out) < static_cast<std::size_t>(after_records) &&
             std::chrono::steady_clock::now() - start < std::chrono::seconds(60))
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    kill(pid, SIGKILL);
    int st = 0;
    waitpid(pid, &st, 0);
    const std::size_t records = count_records(out);
    if (records > 0 && records < keys.size()) interrupted_midway = true;
    // The killed run's journal: whole JSON lines, one per finished frame,
    // each naming a record that exists (a frame's line follows its outputs).
    {
      std::ifstream jf(out + "/results.jsonl.partial", std::ios::binary);
      const std::string all((std::istreambuf_iterator<char>(jf)), std::istreambuf_iterator<char>());
      std::size_t lines = 0, start = 0;
      for (std::size_t nl; (nl = all.find('\n', start)) != std::string::npos; start = nl + 1, ++lines) {
        const nlohmann::json j = nlohmann::json::parse(all.substr(start, nl - start));
        EXPECT_EQ(j["status"], "ok") << j.dump();
        EXPECT_TRUE(fs::exists(j["outputs"]["record"].get<std::string>())) << j.dump();
      }
      EXPECT_LE(lines, records) << "round " << round;
      EXPECT_FALSE(fs::exists(out + "/results.jsonl")) << "a killed run writes no results manifest";
    }
    r = run("batch --manifest " + m + " --out-dir " + out + common + " --resume");
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_FALSE(fs::exists(out + "/results.jsonl.partial")) << "the journal outlived a finished run";
    expect_same_outputs(p("whole"), out);
    // Frames done before the kill were skipped, the others run.
    std::size_t skipped = 0;
    std::ifstream f(out + "/results.jsonl");
    std::string l;
    while (std::getline(f, l)) skipped += nlohmann::json::parse(l)["status"] == "skipped";
    EXPECT_EQ(skipped, records) << "round " << round;
  }
  EXPECT_TRUE(interrupted_midway) << "no kill landed between the first and the last frame (uninterrupted run: "
                                  << whole_ms << " ms); the test did not exercise a partial batch";
  // A changed input is not skipped: its record's SHA-256 no longer matches
  // (a trailing byte after the EXR's data: the same pixels, other bytes).
  {
    std::ofstream f(p("data/a/f0.exr"), std::ios::app);
    f << ' ';
  }
  r = run("batch --manifest " + m + " --out-dir " + p("whole") + common + " --resume");
  EXPECT_EQ(r.status, 0) << r.output;
  std::ifstream f(p("whole/results.jsonl"));
  std::string l;
  std::size_t skipped = 0;
  while (std::getline(f, l)) skipped += nlohmann::json::parse(l)["status"] == "skipped";
  EXPECT_EQ(skipped, keys.size() - 1);
}

// --resume across an upgrade: a record written by an earlier brume lacks the
// blocks and parameters added since (the camera effects' "lidar" block, whose
// default -- no scan -- is the older behaviour); its frame is the same job and
// is skipped, as `brume run` would run that record's job. Run again: a
// recorded value that differs from the manifest's; a schema-2 record without
// haze's sky-rule (introduced with a new rule: the older one, s-max, is not
// today's default); a malformed record (a block that is no object).
TEST_F(Batch, ResumeSkipsFramesAnEarlierVersionRecordedAndRerunsChangedOnes) {
  const std::vector<std::string> keys = make_frames(4, 64, 48);
  const std::string m = csv(keys, kHaze, "haze,300,0.9,2");
  const std::string common = " --seed 5 --workers 1 --threads 1 --quiet";
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("out") + common);
  ASSERT_EQ(r.status, 0) << r.output;
  std::vector<std::string> records;
  for (const auto& e : fs::recursive_directory_iterator(p("out")))
    if (e.path().extension() == ".json") records.push_back(e.path().string());
  std::sort(records.begin(), records.end());
  ASSERT_EQ(records.size(), keys.size());
  auto edit = [](const std::string& path, const std::function<void(nlohmann::json&)>& f) {
    nlohmann::json j = nlohmann::json::parse(slurp(path));
    f(j);
    std::ofstream(path) << j.dump(2);
  };
  // As an earlier brume wrote it: no "lidar" block, no "rho-max" in its diffusion block.
  edit(records[0], [](nlohmann::json& j) {
    ASSERT_TRUE(j["job"].contains("lidar"));
    j["job"].erase("lidar");
    j["job"]["diffusion"].erase("rho-max");
  });
  edit(records[1], [](nlohmann::json& j) { j["job"]["haze"]["albedo"] = 0.5; });
  edit(records[2], [](nlohmann::json& j) {
    ASSERT_NE(j["job"]["haze"]["sky-rule"], "s-max") << "the case needs today's default to differ from the older rule";
    j["schema_version"] = 2;
    j["job"]["haze"].erase("sky-rule");
  });
  edit(records[3], [](nlohmann::json& j) { j["job"]["prepare"] = 5; });
  r = run("batch --manifest " + m + " --out-dir " + p("out") + common + " --resume");
  ASSERT_EQ(r.status, 0) << r.output;
  std::map<std::string, std::string> status;
  std::ifstream f(p("out/results.jsonl"));
  for (std::string l; std::getline(f, l);) {
    const nlohmann::json j = nlohmann::json::parse(l);
    status[j["outputs"]["record"].get<std::string>()] = j["status"];
  }
  EXPECT_EQ(status[records[0]], "skipped") << "a record lacking what a later version added is the same job";
  EXPECT_EQ(status[records[1]], "ok") << "a record with another value is run again";
  EXPECT_EQ(status[records[2]], "ok") << "a schema-2 record ran under sky-rule s-max: run again";
  EXPECT_EQ(status[records[3]], "ok") << "a malformed record is run again";
  EXPECT_EQ(nlohmann::json::parse(slurp(records[1]))["job"]["haze"]["albedo"], 0.9);
}

// A corrupt frame is reported (key, file, message) and skipped; the others are
// written; the exit status and the summary say how many failed. A failed
// frame alone in its folder leaves no folder behind (folders are made when
// a frame writes its first output).
TEST_F(Batch, CorruptFrameIsReportedAndOthersWritten) {
  std::vector<std::string> keys = make_frames(4);
  std::ofstream(p("data/b/f1.png"), std::ios::binary) << "not a png at all";
  fs::create_directories(p("data/c/d"));
  std::ofstream(p("data/c/d/lone.png"), std::ios::binary) << "not a png either";
  fs::copy_file(p("data/a/f0.exr"), p("data/c/d/lone.exr"));
  keys.push_back("c/d/lone.png");
  const std::string m = csv(keys, "effect,visibility", "haze,400");
  const CliRun r = run("batch --manifest " + m + " --out-dir " + p("out") + " --workers 2");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("frame 'b/f1.png'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(p("data/b/f1.png")), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("2 failed"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("out/b/f1.png")));
  EXPECT_FALSE(fs::exists(p("out/b/f1.json")));
  EXPECT_FALSE(fs::exists(p("out/c"))) << "a failed frame's folder was left behind";
  for (const std::string k : {"a/f0", "a/f2", "b/f3"}) {
    EXPECT_TRUE(fs::exists(p("out/" + k + ".png"))) << k;
    EXPECT_TRUE(fs::exists(p("out/" + k + ".json"))) << k;
  }
  std::ifstream f(p("out/results.jsonl"));
  std::string l;
  std::map<std::string, nlohmann::json> res;
  while (std::getline(f, l)) {
    const nlohmann::json j = nlohmann::json::parse(l);
    res[j["key"]] = j;
  }
  ASSERT_EQ(res.size(), 5u);
  EXPECT_EQ(res["b/f1.png"]["status"], "failed");
  EXPECT_EQ(res["c/d/lone.png"]["status"], "failed");
  EXPECT_FALSE(res["b/f1.png"].value("error", "").empty());
  EXPECT_EQ(res["a/f0.png"]["status"], "ok");
  EXPECT_EQ(res["a/f0.png"]["outputs"]["image"], p("out/a/f0.png"));
  EXPECT_EQ(res["a/f0.png"]["inputs"]["image"], p("data/a/f0.png"));
  EXPECT_EQ(res["a/f0.png"]["parameters"]["visibility"], 400.0);
  EXPECT_TRUE(res["a/f0.png"]["seconds"].is_number());
}

// A frame's warnings name it on stderr (frames in flight print side by
// side: a bare "brume haze: warning" did not say which of a thousand frames
// it was) and join its results line, as its record holds them; a frame
// without one has no "warnings" key. b/f1's range is unknown in its left
// half but for row 2 (a table): the preparation takes the hole below it as
// sky (>= 5 % of the frame), under a measured surface, and warns.
TEST_F(Batch, WarningsNameTheirFrameAndJoinItsResultsLine) {
  const std::vector<std::string> keys = make_frames(2);
  Image r = read_scalar(p("data/b/f1.exr"));
  for (int y = 0; y < r.height; ++y)
    for (int x = 0; x < r.width / 2; ++x)
      if (y != 2) r.at(x, y) = NAN;
  WriteOptions f;
  f.is_color = false;
  f.float_reason = "metres";
  write_image(p("data/b/f1.exr"), r, f);
  const std::string m = csv(keys, "effect,visibility", "haze,400");
  const CliRun out = run("batch --manifest " + m + " --out-dir " + p("out") + " --workers 2");
  ASSERT_EQ(out.status, 0) << out.output;
  EXPECT_NE(out.output.find("brume haze: frame 'b/f1.png': warning: the range's unknown regions"), std::string::npos)
      << out.output;
  EXPECT_EQ(out.output.find("frame 'a/f0.png': warning"), std::string::npos) << out.output;
  EXPECT_NE(out.output.find("1 with warnings"), std::string::npos) << out.output;
  std::ifstream in(p("out/results.jsonl"));
  std::map<std::string, nlohmann::json> res;
  for (std::string l; std::getline(in, l);) {
    const nlohmann::json j = nlohmann::json::parse(l);
    res[j["key"]] = j;
  }
  ASSERT_EQ(res.size(), 2u);
  EXPECT_FALSE(res["a/f0.png"].contains("warnings"));
  const nlohmann::json rec = nlohmann::json::parse(slurp(p("out/b/f1.json")));
  const nlohmann::json::json_pointer at("/prepare/complete/warnings");
  ASSERT_TRUE(rec.contains(at)) << rec.dump();
  EXPECT_EQ(res["b/f1.png"]["warnings"], rec[at]);
}

// Issue #51: a FIFO in a manifest hung the batch. An entry that is not a
// regular file fails its frame, naming it, and the batch goes on (exit 1).
TEST_F(Batch, FifoInTheManifestFailsItsFrameOnly) {
  std::vector<std::string> keys = make_frames(2);
  fs::remove(p("data/b/f1.png"));
  ASSERT_EQ(::mkfifo(p("data/b/f1.png").c_str(), 0600), 0);
  const std::string m = csv(keys, "effect,visibility", "haze,400");
  // Bounded in time: a hang is status 124, not a stuck suite.
  FILE* f = popen(("timeout 60 " + std::string(BRUME_CLI) + " batch --manifest " + m + " --out-dir " + p("out") +
                   " --workers 1 2>&1").c_str(), "r");
  ASSERT_TRUE(f);
  CliRun r{-1, ""};
  char buf[4096];
  while (std::fgets(buf, sizeof buf, f)) r.output += buf;
  const int st = pclose(f);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("frame 'b/f1.png'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("FIFO"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(p("out/a/f0.png")));
  EXPECT_FALSE(fs::exists(p("out/b")));
}

// Issue #51: a batch on a full disk left empty s0/ s1/ s2/ folders and a
// 0-byte journal. Here the disk is "full" for the batch by a file-size limit
// (writes fail with EFBIG as with ENOSPC): every frame fails, the results
// manifest cannot be written, and nothing is left behind.
TEST_F(Batch, FullDiskLeavesNoEmptyFoldersOrJournal) {
#if defined(__clang__) && defined(_OPENMP)
  // LLVM's OpenMP runtime (a clang build: the sanitizer runs) sizes a file in
  // /dev/shm when it starts, and `ulimit -f 0` makes that fatal ("OMP: Error
  // #179: Can't set size of SHM", then SIGBUS) before brume runs; a limit
  // large enough for it lets the journal through, which is another case
  // (a frame that fails). The GCC build (libgomp) runs this one.
  GTEST_SKIP() << "ulimit -f 0 stops LLVM's OpenMP runtime at start (clang build); the GCC build runs this case";
#endif
  std::vector<std::string> keys;
  for (const char* sub : {"s0", "s1", "s2"}) {
    fs::create_directories(dir / "data" / sub);
    const Scene s = scene(64, 48, 0, 7);
    write_image(p(std::string("data/") + sub + "/f.png"), s.rgb, WriteOptions{});
    WriteOptions f;
    f.is_color = false;
    f.float_reason = "metres";
    write_image(p(std::string("data/") + sub + "/f.exr"), s.range, f);
    keys.push_back(std::string(sub) + "/f.png");
  }
  const std::string m = csv(keys, "effect,visibility", "haze,400");
  const std::string cmd = "sh -c 'ulimit -f 0; exec " + std::string(BRUME_CLI) + " batch --manifest " + m +
                          " --out-dir " + p("out") + "' 2>&1";
  FILE* f = popen(cmd.c_str(), "r");
  ASSERT_TRUE(f);
  std::string out;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, f)) out += buf;
  const int st = pclose(f);
  EXPECT_TRUE(WIFEXITED(st) && WEXITSTATUS(st) == 2) << out;
  EXPECT_NE(out.find("file-size limit"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(p("out"))) << "the batch made --out-dir and left it: "
                                     << (fs::exists(p("out")) ? files(p("out")).size() : 0) << " files";
  // An --out-dir that was there stays, without empty folders or a journal.
  fs::create_directories(p("out"));
  const int st2 = std::system(cmd.c_str());
  EXPECT_TRUE(WIFEXITED(st2) && WEXITSTATUS(st2) == 2);
  EXPECT_TRUE(fs::is_directory(p("out")));
  EXPECT_TRUE(fs::is_empty(p("out"))) << "left in --out-dir: " << fs::directory_iterator(p("out"))->path();
}

// Manifest errors are found before anything runs: duplicate keys (named, with
// their lines), an unknown column (the nearest name), a value out of range
// (line, column, what is allowed), a key leaving --out-dir.
TEST_F(Batch, ManifestErrorsBeforeAnyWork) {
  const std::vector<std::string> keys = make_frames(2);
  auto err = [&](const std::string& text) {
    std::ofstream(p("data/bad.csv")) << text;
    const CliRun r = run("batch --manifest " + p("data/bad.csv") + " --out-dir " + p("out") + " --effect haze");
    EXPECT_EQ(r.status, 2) << r.output;
    EXPECT_FALSE(fs::exists(p("out/a"))) << r.output;
    return r.output;
  };
  std::string o = err("key,image,range\nx,a/f0.png,a/f0.exr\nx,b/f1.png,b/f1.exr\n");
  EXPECT_NE(o.find("key 'x' is on lines 2, 3"), std::string::npos) << o;
  o = err("image,range,visibilty\na/f0.png,a/f0.exr,300\n");
  EXPECT_NE(o.find("did you mean 'visibility'"), std::string::npos) << o;
  o = err("image,range,albedo\na/f0.png,a/f0.exr,\"uniform(0.5, 1.5)\"\n");
  EXPECT_NE(o.find("line 2, column 'albedo'"), std::string::npos) << o;
  o = err("key,image,range\n../escape,a/f0.png,a/f0.exr\n");
  EXPECT_NE(o.find("'..'"), std::string::npos) << o;
  o = err("image,range,out\na/f0.png,a/f0.exr,x.png\n");
  EXPECT_NE(o.find("named by brume batch from the key"), std::string::npos) << o;
}

// haze+dof with the DOF stage's parameters prefixed (dof.focus-distance),
// sampled under the prefixed name, equals `brume haze ... --dof-...`.
TEST_F(Batch, ChainWithPrefixedParameters) {
  const std::vector<std::string> keys = make_frames(2);
  const std::string j = p("data/m.jsonl");
  {
    std::ofstream f(j);
    for (const std::string& k : keys)
      f << nlohmann::json{{"image", k},
                          {"range", k.substr(0, k.size() - 4) + ".exr"},
                          {"effect", "haze+dof"},
                          {"visibility", 500},
                          {"dof.focus_distance", "loguniform(20, 200)"},
                          {"dof.coc-infinity", 6},
                          {"fov-y", 50}}
               .dump()
        << "\n";
  }
  const CliRun r = run("batch --manifest " + j + " --out-dir " + p("out") + " --seed 9 --quiet --format exr");
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json rec = read_json(p("out/a/f0.json"));
  EXPECT_EQ(rec["command"], "haze+dof");
  const double fd = rec["job"]["dof"]["dof-focus-distance"].get<double>();
  const double u = unit_of(9, "a/f0.png", "dof.focus-distance");
  EXPECT_NEAR(fd, std::exp(std::log(20.0) + u * (std::log(200.0) - std::log(20.0))), 1e-12 * fd);
  EXPECT_EQ(rec["batch"]["values"]["dof.focus-distance"], rec["job"]["dof"]["dof-focus-distance"]);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", fd);
  const CliRun s = run("haze --image " + p("data/a/f0.png") + " --range " + p("data/a/f0.exr") +
                       " --visibility 500 --fov-y 50 --dof-focus-distance " + buf +
                       " --dof-coc-infinity 6 --out " + p("single.exr"));
  ASSERT_EQ(s.status, 0) << s.output;
  expect_same_pixels(p("out/a/f0.exr"), p("single.exr"));
}

// --dataset on ../shared/data: the rows each layout must give, with the
// datasets' conventions as depth flags; the Middlebury manifest then runs.
TEST_F(Batch, ScanSharedData) {
  BRUME_REQUIRE_DATA("middlebury2005_thirdsize");
  DatasetOptions s;
  s.dir = data_path("middlebury2005_thirdsize");
  s.layout = "middlebury";
  s.manifest_dir = dir.string();
  std::vector<nlohmann::json> rows = dataset_manifest(s);
  ASSERT_EQ(rows.size(), 6u);
  std::vector<std::string> ks;
  for (const auto& r : rows) ks.push_back(r["key"]);
  EXPECT_EQ(ks, (std::vector<std::string>{"Art/view1.png", "Books/view1.png", "Dolls/view1.png", "Laundry/view1.png",
                                          "Moebius/view1.png", "Reindeer/view1.png"}));
  double dmin = 0;
  std::ifstream(data_path("middlebury2005_thirdsize/Art/dmin.txt")) >> dmin;
  EXPECT_EQ(rows[0]["disparity-offset"].get<double>(), dmin / 3.0);
  EXPECT_EQ(rows[0]["fx"].get<double>(), 3740.0 / 3.0);
  EXPECT_TRUE(fs::exists(dir / rows[0]["image"].get<std::string>()));
  EXPECT_TRUE(fs::exists(dir / rows[0]["disparity"].get<std::string>()));

  // Through the CLI into a CSV, then run: Art equals `brume haze` on the same flags.
  CliRun r = run("batch --dataset " + data_path("middlebury2005_thirdsize") + " --layout middlebury --manifest " +
                 p("mb.csv") + " --out-dir " + p("out") + " --effect haze --param visibility=5 --quiet");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(files(p("out")).size(), 12u);
  char off[64];
  std::snprintf(off, sizeof off, "%.17g", dmin / 3.0);
  r = run("haze --image " + data_path("middlebury2005_thirdsize/Art/view1.png") + " --disparity " +
          data_path("middlebury2005_thirdsize/Art/disp1.png") +
          " --fx 1246.6666666666667 --baseline 0.16 --disparity-scale 0.33333333333333331 --disparity-offset " + off +
          " --visibility 5 --out " + p("art.png"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("out/Art/view1.png"), p("art.png"));

  if (have_data("eth3d_two_view")) {
    s.dir = data_path("eth3d_two_view");
    s.layout = "eth3d";
    rows = dataset_manifest(s);
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(rows[0]["key"], "playground_1l/im0.png");
    EXPECT_EQ(rows[1]["key"], "terrace/im0.png");
    EXPECT_TRUE(fs::exists(dir / rows[1]["calib"].get<std::string>()));
  }
  if (have_data("kitti_object_000001")) {
    s.dir = data_path("kitti_object_000001");
    s.layout = "kitti";
    rows = dataset_manifest(s);
    ASSERT_EQ(rows.size(), 1u);
    EXPECT_EQ(rows[0]["key"], "image_2/000001.png");
    EXPECT_TRUE(fs::exists(dir / rows[0]["velodyne"].get<std::string>()));
    EXPECT_TRUE(fs::exists(dir / rows[0]["kitti-calib"].get<std::string>()));
    // Without completion (--complete off) the lidar scan is refused by the
    // preparation, with its own message, as a frame failure (test_complete.cpp
    // runs it with completion).
    write_manifest(p("kitti.jsonl"), rows);
    r = run("batch --manifest " + p("kitti.jsonl") + " --out-dir " + p("kout") +
            " --effect haze --param complete=off --quiet");
    EXPECT_EQ(r.status, 1) << r.output;
    EXPECT_NE(r.output.find("frame 'image_2/000001.png'"), std::string::npos) << r.output;
    const CliRun single = run("haze --image " + data_path("kitti_object_000001/image_2/000001.png") + " --velodyne " +
                              data_path("kitti_object_000001/velodyne/000001.bin") + " --kitti-calib " +
                              data_path("kitti_object_000001/calib/000001.txt") + " --complete off --out " +
                              p("k.png"));
    ASSERT_EQ(single.status, 2) << single.output;
    const std::string msg = single.output.substr(single.output.find("error: ") + 7);
    EXPECT_NE(r.output.find(msg.substr(0, msg.find('\n'))), std::string::npos) << r.output << "\nvs\n" << msg;
  }
}

// --layout pairs: images and depth files paired by what '*' matched, paths
// relative to the manifest's folder, keys relative to the scanned folder.
TEST_F(Batch, ScanPairs) {
  make_frames(3);
  DatasetOptions s;
  s.dir = p("data");
  s.layout = "pairs";
  s.image_glob = "*/*.png";
  s.depth_glob = "*/*.exr";
  s.manifest_dir = dir.string();
  const std::vector<nlohmann::json> rows = dataset_manifest(s);
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0], (nlohmann::json{{"key", "a/f0.png"}, {"image", "data/a/f0.png"}, {"range", "data/a/f0.exr"}}));
  EXPECT_EQ(rows[1]["key"], "a/f2.png");
  EXPECT_EQ(rows[2]["range"], "data/b/f1.exr");
  s.depth_glob = "*/f*.exr";  // two '*': both captures must agree
  s.image_glob = "*/f*.png";
  EXPECT_EQ(dataset_manifest(s).size(), 3u);
  s.depth_kind = "depth";
  EXPECT_NE(error_of([&] { dataset_manifest(s); }).find("--depth-kind 'depth' is not allowed"), std::string::npos);
}

// --layout cityscapes on a folder of Cityscapes' shape (no Cityscapes data in
// ../shared/data): the row carries the camera JSON's values, and the range
// the batch's depth flags give at the principal point is f B / ((p - 1)/256)
// (closed form; float32 storage, so 1e-6 relative).
TEST_F(Batch, ScanCityscapes) {
  const fs::path city = dir / "cs";
  for (const char* d : {"leftImg8bit/train/aachen", "disparity/train/aachen", "camera/train/aachen"})
    fs::create_directories(city / d);
  const std::string n = "aachen_000000_000019";
  write_image((city / "leftImg8bit/train/aachen" / (n + "_leftImg8bit.png")).string(), scene(8, 6, 0).rgb, WriteOptions{});
  Image disp(8, 6, 1);
  for (std::size_t i = 0; i < disp.data.size(); ++i) disp.data[i] = (1 + 256 * 20 + 37 * static_cast<float>(i)) / 65535.0f;
  disp.at(0, 0) = 0.0f;  // invalid
  WriteOptions w;
  w.bits = "16";
  w.is_color = false;
  write_image((city / "disparity/train/aachen" / (n + "_disparity.png")).string(), disp, w);
  std::ofstream((city / "camera/train/aachen" / (n + "_camera.json")).string())
      << R"({"extrinsic": {"baseline": 0.209313, "pitch": 0.038}, "intrinsic": {"fx": 2262.52, "fy": 2265.3017905988554, "u0": 3.0, "v0": 2.0}})";
  DatasetOptions s;
  s.dir = city.string();
  s.layout = "cityscapes";
  s.manifest_dir = dir.string();
  const std::vector<nlohmann::json> rows = dataset_manifest(s);
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0]["key"], "leftImg8bit/train/aachen/" + n + "_leftImg8bit.png");
  EXPECT_EQ(rows[0]["fx"].get<double>(), 2262.52);
  EXPECT_EQ(rows[0]["cx"].get<double>(), 3.0);
  EXPECT_EQ(rows[0]["baseline"].get<double>(), 0.209313);
  EXPECT_EQ(rows[0]["disparity-offset"].get<double>(), -1.0 / 256.0);
  // The row's depth flags through `brume depth convert`.
  std::string flags;
  for (const auto& [k, v] : rows[0].items()) {
    if (k == "key" || k == "image") continue;
    char b[64];
    if (v.is_number()) std::snprintf(b, sizeof b, "%.17g", v.get<double>());
    flags += " --" + k + " " + (v.is_string() ? p(v.get<std::string>()) : std::string(b));
  }
  const CliRun r = run("depth convert" + flags + " --out " + p("cs_range.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  const Image range = read_scalar(p("cs_range.exr"));
  const double pv = 1 + 256 * 20 + 37 * (2 * 8 + 3);  // the count at (3, 2), the principal point
  const double z = 2262.52 * 0.209313 / ((pv - 1) / 256.0);
  EXPECT_NEAR(range.at(3, 2), z, 1e-6 * z);
  EXPECT_TRUE(std::isnan(range.at(0, 0)));
}

// Rain in a batch (issue #56): each frame draws its own drop field (rain-seed=seed(): the
// sampler's top 53 bits for the frame's key), a lidar column rains on the frame's scan, written
// beside the image as <key stem>.bin (brume lidar rain's bytes with the drawn seed), and `brume
// run` of a frame's record repeats its image and its scan bit for bit.
TEST_F(Batch, RainFramesDrawTheirDropsAndRepeatWithTheirScans) {
  const std::vector<std::string> keys = make_frames(2);
  std::vector<float> pts;
  for (int i = 0; i < 300; ++i) {
    const double a = 0.01 * i, r = 2.0 + 0.05 * i;
    pts.insert(pts.end(), {static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)), -1.0f,
                           static_cast<float>((i % 5) / 5.0)});
  }
  std::ofstream(p("data/s.bin"), std::ios::binary)
      .write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  const std::string m = csv(keys, "effect,fx,lidar", "rain,60,s.bin");
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("out") + " --seed 5 --quiet --param rate=50" +
                 " --param 'rain-seed=seed()'");
  ASSERT_EQ(r.status, 0) << r.output;
  std::set<std::uint64_t> seeds;
  for (const std::string& k : keys) {
    const std::string stem = k.substr(0, k.size() - 4);
    const nlohmann::json rec = nlohmann::json::parse(slurp(p("out/" + stem + ".json")));
    const auto seed = rec["job"]["rain"]["rain-seed"].get<std::uint64_t>();
    EXPECT_EQ(seed, static_cast<std::uint64_t>(sample_unit(5, k, "rain-seed") * 0x1p53)) << k;
    EXPECT_EQ(rec["batch"]["sampling"]["specs"]["rain-seed"], "seed()");
    seeds.insert(seed);
    r = run("lidar rain --points " + p("data/s.bin") + " --rate 50 --seed " + std::to_string(seed) + " --out " +
            p("alone.bin"));
    ASSERT_EQ(r.status, 0) << r.output;
    const std::string scan = slurp(p("out/" + stem + ".bin"));
    EXPECT_TRUE(!scan.empty() && scan == slurp(p("alone.bin"))) << k;
  }
  EXPECT_EQ(seeds.size(), keys.size());  // no two frames share their drops
  r = run("run " + p("out/a/f0.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("out/a/f0.png"), p("again/f0.png"));
  EXPECT_EQ(slurp(p("out/a/f0.bin")), slurp(p("again/f0.bin")));
}

// Wet ground in a batch (issue #57): each frame draws its film and its scan's detection seed
// (scan-seed=seed()); a lidar column wets the frame's scan, written beside the image as <key
// stem>.bin with its labels as <key stem>.labels.u8 (brume lidar wet's bytes with the drawn values),
// and `brume run` of a frame's record repeats its image and its scan bit for bit.
TEST_F(Batch, WetFramesDrawTheirFilmAndRepeatWithTheirScans) {
  const std::vector<std::string> keys = make_frames(2);
  std::vector<float> pts;
  for (int i = 0; i < 1000; ++i) {  // every other point on the ground 1.73 m below the sensor
    const double a = 0.01 * i, r = 2.0 + 0.015 * i;
    pts.insert(pts.end(), {static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)),
                           i % 2 ? -1.73f : 0.5f, static_cast<float>((i % 5 + 1) / 50.0)});
  }
  std::ofstream(p("data/s.bin"), std::ios::binary)
      .write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  const std::string m = csv(keys, "effect,fx,camera-height,lidar", "wet,60,1.5,s.bin");
  CliRun r = run("batch --manifest " + m + " --out-dir " + p("out") + " --seed 5 --quiet --param " +
                 "'film=loguniform(0.05, 2)' --param 'scan-seed=seed()' --param noise-floor=0.01");
  ASSERT_EQ(r.status, 0) << r.output;
  std::set<std::uint64_t> seeds;
  for (const std::string& k : keys) {
    const std::string stem = k.substr(0, k.size() - 4);
    const nlohmann::json rec = nlohmann::json::parse(slurp(p("out/" + stem + ".json")));
    const double film = rec["job"]["wet"]["film"].get<double>();
    const auto seed = rec["job"]["scan"]["scan-seed"].get<std::uint64_t>();
    EXPECT_EQ(seed, static_cast<std::uint64_t>(sample_unit(5, k, "scan-seed") * 0x1p53)) << k;
    EXPECT_TRUE(film >= 0.05 && film < 2.0) << film;
    EXPECT_EQ(rec["batch"]["sampling"]["specs"]["scan-seed"], "seed()");
    seeds.insert(seed);
    std::ostringstream f;
    f.precision(17);
    f << film;
    r = run("lidar wet --points " + p("data/s.bin") + " --film " + f.str() + " --noise-floor 0.01 --scan-seed " +
            std::to_string(seed) + " --out " + p("alone.bin") + " --labels " + p("alone.u8"));
    ASSERT_EQ(r.status, 0) << r.output;
    const std::string scan = slurp(p("out/" + stem + ".bin"));
    EXPECT_TRUE(!scan.empty() && scan == slurp(p("alone.bin"))) << k;
    EXPECT_EQ(slurp(p("out/" + stem + ".labels.u8")), slurp(p("alone.u8"))) << k;
    EXPECT_GT(rec["lidar_wet"]["lost"].get<std::size_t>(), 0u) << k;  // (so that the seed matters)
  }
  EXPECT_EQ(seeds.size(), keys.size());
  r = run("run " + p("out/a/f0.json") + " --out-dir " + p("again"));
  ASSERT_EQ(r.status, 0) << r.output;
  expect_same_pixels(p("out/a/f0.png"), p("again/f0.png"));
  EXPECT_EQ(slurp(p("out/a/f0.bin")), slurp(p("again/f0.bin")));
}
