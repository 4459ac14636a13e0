// brume tests — shared helpers: data location, the command-line tool, scratch
// folders, the GPU context; and (engine_util.hpp) an independent Gaussian
// reference and comparison statistics.
#pragma once

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>

#include <cmath>
#include <filesystem>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "brume/depth_source.hpp"
#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/image.hpp"
#include "brume/io.hpp"
#include "engine_util.hpp"

namespace brume::test {

// The real third-party data folder: the environment variable BRUME_DATA_DIR
// when it is set and not empty, else the compiled-in BRUME_DATA_DIR
// (../shared/data beside the repository). .ci/run points it at an empty folder
// to run the tests labelled `data` (tests/labels.cmake) without the data.
inline std::string data_dir() {
  const char* env = std::getenv("BRUME_DATA_DIR");
  return env && *env ? std::string(env) : std::string(BRUME_DATA_DIR);
}

// A file or folder of the data. A test that reads one must use this,
// have_data or BRUME_REQUIRE_DATA (directly or through a helper of its file):
// that is how tests/data_tests.py finds it for the label `data`.
inline std::string data_path(const std::string& rel) { return data_dir() + "/" + rel; }

inline bool have_data(const std::string& rel) { return std::filesystem::exists(data_path(rel)); }

// Why a real-data test skips: what is missing, and where the folder comes from.
inline std::string data_absent(const std::string& rel) {
  return "real data '" + data_path(rel) + "' is absent: the data folder (BRUME_DATA_DIR, else ../shared/data " +
         "beside the repository) does not hold it";
}

// A file's bytes ("" when it cannot be read).
inline std::string file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

#define BRUME_REQUIRE_DATA(rel)                                                          \
  do {                                                                                   \
    if (!::brume::test::have_data(rel)) GTEST_SKIP() << ::brume::test::data_absent(rel); \
  } while (0)

// RGB -> RGBA with alpha 1 (the diffusion engine works on four channels).
inline Image to_rgba(const Image& rgb) {
  Image f(rgb.width, rgb.height, 4, 1.0f);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = rgb.data[i * rgb.channels + c];
  return f;
}

// Middlebury 2005 third-size disparity as a depth source: Z[mm] =
// 160 * 3740 / (I + dmin) (SOURCES.md); at third size f = 3740/3 px and
// d = (I + dmin)/3, i.e. --disparity-scale 1/3 --disparity-offset dmin/3.
inline DepthSource middlebury2005(const std::string& scene) {
  const std::string dir = "middlebury2005_thirdsize/" + scene + "/";
  double dmin = 0;
  std::ifstream(data_path(dir + "dmin.txt")) >> dmin;
  DepthSource s;
  s.disparity = data_path(dir + "disp1.png");
  s.k.fx = 3740.0 / 3.0;
  s.baseline_m = 0.160;
  s.disparity_scale = 1.0 / 3.0;
  s.disparity_offset = dmin / 3.0;
  return s;
}

// A real [0,1] test image: Middlebury 2005 "Art", linear light, 463x370.
inline const char* kArt = "middlebury2005_thirdsize/Art/view1.png";

// Built with AddressSanitizer or ThreadSanitizer (scripts/test-sanitize.sh):
// GCC says so with __SANITIZE_*__, clang with __has_feature.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kSanitizerBuild = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
inline constexpr bool kSanitizerBuild = true;
#else
inline constexpr bool kSanitizerBuild = false;
#endif
#else
inline constexpr bool kSanitizerBuild = false;
#endif

// The command-line tool (BRUME_CLI) run through the shell, stderr folded into
// the output: its exit status and everything it printed.
struct CliRun {
  int status;
  std::string output;
};
// With `cwd`, run from that folder.
inline CliRun run(const std::string& args, const std::string& cwd = "") {
  const std::string cli = "'" + std::string(BRUME_CLI) + "' " + args + " 2>&1";
  const std::string cmd = cwd.empty() ? cli : "cd '" + cwd + "' && " + cli;
  FILE* p = popen(cmd.c_str(), "r");
  CliRun r{-1, ""};
  if (!p) return r;
  std::array<char, 4096> buf;
  while (std::fgets(buf.data(), buf.size(), p)) r.output += buf.data();
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

// A fixture with a scratch folder per test (the CLI suites and others that
// write files): `dir`, <tmp>/brume_test_<suite>_<pid>_<test> (the process id
// keeps concurrent ctest runs apart), made empty before the fixture's SetUp
// and removed with its contents after its TearDown; p(name) is a path in it.
class ScratchDirTest : public ::testing::Test {
 protected:
  std::filesystem::path dir;
  ScratchDirTest() {
    const ::testing::TestInfo* t = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name =
        std::string("brume_test_") + t->test_suite_name() + "_" + std::to_string(::getpid()) + "_" + t->name();
    std::replace(name.begin(), name.end(), '/', '_');  // a parameterised suite's or test's name
    dir = std::filesystem::temp_directory_path() / name;
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
  }
  ~ScratchDirTest() override {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
    if (ec) ADD_FAILURE() << "could not remove " << dir << ": " << ec.message();
  }
  std::string p(const std::string& name) const { return (dir / name).string(); }
};

// One GPU context for the whole test binary (contexts belong to the thread
// that made them; gtest runs tests on the main thread), or null with the
// reason when none can be made.
inline GpuContext* shared_gpu_context(std::string* why) {
  static std::unique_ptr<GpuContext> ctx;
  static std::string reason;
  static bool tried = false;
  if (!tried) {
    tried = true;
    try {
      ctx = std::make_unique<GpuContext>();
    } catch (const Error& e) {
      reason = e.what();
    }
  }
  *why = reason;
  return ctx.get();
}

// BRUME_REQUIRE_GPU=1 (set by .ci/run, which has Mesa's llvmpipe): a test
// that finds no GPU context fails instead of skipping.
inline bool gpu_required() {
  const char* req = std::getenv("BRUME_REQUIRE_GPU");
  return req && std::string(req) == "1";
}

// No GPU context, for the reason `why`: the test fails under
// BRUME_REQUIRE_GPU=1 and skips otherwise (returns from the test either way).
#define BRUME_NO_GPU(why)                                                                  \
  do {                                                                                     \
    if (::brume::test::gpu_required()) FAIL() << "BRUME_REQUIRE_GPU=1 but " << (why);      \
    GTEST_SKIP() << (why);                                                                 \
  } while (0)

// Declares `GpuContext* ctx`, the test binary's shared context; without one
// the test skips, or fails under BRUME_REQUIRE_GPU=1 (BRUME_NO_GPU).
#define BRUME_REQUIRE_GPU(ctx)                                                             \
  std::string ctx##_why;                                                                   \
  ::brume::GpuContext* ctx = ::brume::test::shared_gpu_context(&ctx##_why);                \
  if (!ctx) BRUME_NO_GPU(ctx##_why)

// A random RGB-D scene for the aerial and insert tests.
struct Scene {
  Image rgb, range;
};
// Random colours in [0.05, 1] over ranges 10 .. 1000 m; the top `sky_rows` rows unknown.
inline Scene scene(int w, int h, int sky_rows, unsigned seed = 7) {
  Scene s{Image(w, h, 3), Image(w, h, 1)};
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> col(0.05f, 1.0f), rr(10.0f, 1000.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) s.rgb.at(x, y, c) = col(rng);
      s.range.at(x, y) = y < sky_rows ? NAN : rr(rng);
    }
  s.range.at(0, h - 1) = 1000.0f;  // R_max known exactly
  return s;
}

inline nlohmann::json read_json(const std::string& path) {
  std::ifstream f(path);
  return nlohmann::json::parse(f);
}

// Two image files hold the same pixels to the last bit (read as linear colour).
inline void expect_same_pixels(const std::string& a, const std::string& b) {
  const Image x = read_color(a), y = read_color(b);
  ASSERT_EQ(x.data.size(), y.data.size()) << a << " vs " << b;
  EXPECT_EQ(std::memcmp(x.data.data(), y.data.data(), x.data.size() * sizeof(float)), 0) << a << " vs " << b;
}

}  // namespace brume::test
