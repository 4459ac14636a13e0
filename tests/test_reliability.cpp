// Reliability (issue #15): hostile headers refused before allocation, the
// memory check, integer files of fewer bits than their container, non-finite
// colour, and outputs that fail or are interrupted while being written
// (all-or-nothing, no temporaries left behind), and names that are not UTF-8.
#include <OpenImageIO/imageio.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include "brume/batch.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;
namespace fs = std::filesystem;

namespace {

class Reliability : public ScratchDirTest {
 protected:
  void TearDown() override { set_max_pixels(default_max_pixels); }
  int temporaries() const {
    int n = 0;
    for (auto& e : fs::directory_iterator(dir)) n += e.path().filename().string().find(".brume-tmp-") != std::string::npos;
    return n;
  }
};

// A PFM header declaring 100 000 x 100 000 RGB pixels (120 GB of floats) over a
// few bytes of data: reading it must fail on the header, before allocating.
void write_hostile_pfm(const std::string& path) {
  std::ofstream f(path, std::ios::binary);
  f << "PF\n100000 100000\n-1.0\n";
  const float v[6] = {0, 0, 0, 0, 0, 0};
  f.write(reinterpret_cast<const char*>(v), sizeof v);
}

}  // namespace

TEST_F(Reliability, HugeHeaderIsRefusedBeforeAllocation) {
  write_hostile_pfm(p("huge.pfm"));
  for (auto read : std::vector<std::function<void()>>{[&] { read_color(p("huge.pfm")); },
                                                      [&] { read_scalar(p("huge.pfm")); },
                                                      [&] { read_header(p("huge.pfm")); }}) {
    const std::string e = error_of(read);
    EXPECT_NE(e.find("100000 x 100000"), std::string::npos) << e;
    EXPECT_NE(e.find("10000.0 Mpx"), std::string::npos) << e;
    EXPECT_NE(e.find("--max-pixels"), std::string::npos) << e;
  }
  // The CLI says the same, exits 2 (not "internal error: std::bad_alloc") and writes nothing.
  CliRun r = run("blur --image " + p("huge.pfm") + " --sigma 2 --out " + p("o.exr"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("over the limit of 500.0 Mpx"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("o.exr")));
}

TEST_F(Reliability, MaxPixelsIsALimitBothWays) {
  Image img(8, 6, 3, 0.25f);
  write_image(p("small.exr"), img, WriteOptions{});
  set_max_pixels(47);  // one pixel short
  EXPECT_NE(error_of([&] { read_color(p("small.exr")); }).find("8 x 6 pixels"), std::string::npos);
  set_max_pixels(48);  // exactly enough
  EXPECT_EQ(read_color(p("small.exr")).width, 8);
  // From the command line, before or after the subcommand.
  CliRun lo = run("--max-pixels 47 blur --image " + p("small.exr") + " --sigma 1 --out " + p("o.exr"));
  EXPECT_EQ(lo.status, 2) << lo.output;
  EXPECT_NE(lo.output.find("--max-pixels 48"), std::string::npos) << lo.output;
  CliRun hi = run("blur --image " + p("small.exr") + " --sigma 1 --out " + p("o.exr") + " --max-pixels 48");
  EXPECT_EQ(hi.status, 0) << hi.output;
  EXPECT_THROW(set_max_pixels(0), Error);
}

TEST_F(Reliability, HeaderOnlyReadGivesTheSize) {
  Image img(13, 7, 1, 0.5f);
  WriteOptions data;
  data.is_color = false;
  write_image(p("h.exr"), img, data);
  ImageHeader h = read_header(p("h.exr"));
  EXPECT_EQ(h.width, 13);
  EXPECT_EQ(h.height, 7);
  EXPECT_EQ(h.channels, 1);
  EXPECT_EQ(h.format, "openexr");
}

TEST_F(Reliability, MemoryCheck) {
  const std::uint64_t avail = memory_available();
  EXPECT_GT(avail, 1u << 20);  // this test process can allocate a megabyte
  EXPECT_NO_THROW(check_memory(1u << 20, "a small job"));
  const std::string e = error_of([] { check_memory(UINT64_MAX / 2, "a huge job"); });
  EXPECT_NE(e.find("a huge job needs about"), std::string::npos) << e;
  // An effect's estimate names the effect and the frame.
  const std::string w = error_of([] { check_working_memory("haze", Image(100, 50, 3), 1e15); });
  EXPECT_NE(w.find("haze on a 100"), std::string::npos) << w;
  // RLIMIT_AS is one of the limits: with 1 GiB above the current size, 2 GiB is refused.
  struct rlimit old {};
  ASSERT_EQ(getrlimit(RLIMIT_AS, &old), 0);
  std::uint64_t vm = 0;
  {
    std::ifstream f("/proc/self/status");
    std::string line;
    while (std::getline(f, line))
      if (line.rfind("VmSize:", 0) == 0) vm = std::stoull(line.substr(7)) * 1024;
  }
  ASSERT_GT(vm, 0u);
  struct rlimit lim = old;
  lim.rlim_cur = vm + (1ull << 30);
  if (old.rlim_max != RLIM_INFINITY && lim.rlim_cur > old.rlim_max) GTEST_SKIP() << "hard RLIMIT_AS too low";
  ASSERT_EQ(setrlimit(RLIMIT_AS, &lim), 0);
  const std::uint64_t under = memory_available();
  const std::string e2 = error_of([] { check_memory(2ull << 30, "a 2 GiB job"); });
  setrlimit(RLIMIT_AS, &old);
  EXPECT_LE(under, 1ull << 30);
  EXPECT_NE(e2.find("a 2 GiB job needs about 2048 MiB"), std::string::npos) << e2;
}

// OpenImageIO reads a 12-bit TIFF in a 16-bit container normalised by 4095:
// colour gets k/4095, and depth counts are k itself, not k·65535/4095.
TEST_F(Reliability, TwelveBitTiffReadsByItsRealDepth) {
  const int w = 5;
  std::vector<std::uint16_t> counts = {0, 1, 2048, 4000, 4095};
  {
    auto out = OIIO::ImageOutput::create(p("d12.tif"));
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(w, 1, 1, OIIO::TypeDesc::UINT16);
    spec.attribute("oiio:BitsPerSample", 12);
    ASSERT_TRUE(out->open(p("d12.tif"), spec));
    // Written through OpenImageIO's own scaling: a 12-bit count k is k/4095 of full scale.
    std::vector<float> v;
    for (auto k : counts) v.push_back(k / 4095.0f);
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, v.data()));
    out->close();
  }
  FileInfo info;
  Image d = read_scalar(p("d12.tif"), "", &info);
  EXPECT_EQ(info.bits, 12);
  for (int x = 0; x < w; ++x) EXPECT_EQ(d.at(x, 0), static_cast<float>(counts[static_cast<std::size_t>(x)])) << x;
  Image c = read_color(p("d12.tif"), Transfer::linear);
  // k/4095 to float rounding (OpenImageIO's own bit replication is off by up to 1e-5).
  for (int x = 0; x < w; ++x)
    EXPECT_EQ(c.at(x, 0, 1), static_cast<float>(counts[static_cast<std::size_t>(x)] / 4095.0)) << x;
}

TEST_F(Reliability, NonFiniteColourIsAnErrorOrReplaced) {
  Image img(6, 4, 3, 0.5f), r(6, 4, 1, 10.0f);
  img.at(4, 2, 1) = NAN;
  img.at(5, 3, 0) = INFINITY;
  img.at(0, 0, 2) = -0.25f;  // negative linear values are legitimate and pass
  write_image(p("nan.exr"), img, WriteOptions{});
  InputFiles in;
  in.image = p("nan.exr");
  const std::string e = error_of([&] { load_inputs(in, false); });
  EXPECT_NE(e.find("2 non-finite values"), std::string::npos) << e;
  EXPECT_NE(e.find("NaN at x 4, y 2"), std::string::npos) << e;
  EXPECT_NE(e.find("--nonfinite zero"), std::string::npos) << e;
  in.nonfinite = NonFinite::zero;
  LoadedInputs L = load_inputs(in, false);
  EXPECT_EQ(L.rgb.at(4, 2, 1), 0.0f);
  EXPECT_EQ(L.rgb.at(5, 3, 0), 0.0f);
  EXPECT_EQ(L.rgb.at(0, 0, 2), -0.25f);
  EXPECT_EQ(L.record["image"]["nonfinite_replaced"], 2);
  // Through the CLI: the default refuses, `--nonfinite zero` runs.
  CliRun bad = run("blur --image " + p("nan.exr") + " --sigma 1 --out " + p("o.exr"));
  EXPECT_EQ(bad.status, 2) << bad.output;
  EXPECT_FALSE(fs::exists(p("o.exr")));
  CliRun ok = run("blur --image " + p("nan.exr") + " --sigma 1 --nonfinite zero --out " + p("o.exr"));
  EXPECT_EQ(ok.status, 0) << ok.output;
  Image o = read_color(p("o.exr"));
  for (float v : o.data) ASSERT_TRUE(std::isfinite(v));
}

TEST_F(Reliability, AbsurdSigmaIsRefused) {
  Image img(8, 8, 3, 0.5f);
  write_image(p("i.exr"), img, WriteOptions{});
  CliRun r = run("blur --image " + p("i.exr") + " --sigma 1e9 --out " + p("o.exr"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--sigma"), std::string::npos) << r.output;
  CliRun t = run("blur --image " + p("i.exr") + " --sigma 1 --threads -1 --out " + p("o.exr"));
  EXPECT_NE(t.status, 0) << t.output;
  EXPECT_NE(t.output.find("--threads"), std::string::npos) << t.output;
}

// A file-size limit (ulimit -f): the kernel would kill the process with
// SIGXFSZ and leave its temporary behind; brume ignores the signal, reports
// EFBIG and removes the temporary. The previous output stays as it was.
TEST_F(Reliability, FileSizeLimitFailsCleanly) {
  // Noise, so that no format's compression fits it under the limit.
  Image img(256, 256, 3);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (float& v : img.data) v = u(rng);
  write_image(p("i.exr"), img, WriteOptions{});
  {
    std::ofstream prev(p("o.pfm"));
    prev << "previous";
  }
  for (const char* out : {"o.pfm", "o.exr", "o.tif"}) {
    // 64 blocks of 512 bytes (POSIX sh's ulimit unit): the 786 kB float image cannot fit.
    const std::string cmd = "sh -c 'ulimit -f 64; exec " + std::string(BRUME_CLI) + " blur --image " + p("i.exr") +
                            " --sigma 1 --out " + p(out) + "' 2>&1";
    FILE* f = popen(cmd.c_str(), "r");
    ASSERT_TRUE(f);
    std::string output;
    char buf[4096];
    while (std::fgets(buf, sizeof buf, f)) output += buf;
    const int st = pclose(f);
    ASSERT_TRUE(WIFEXITED(st)) << out << ": killed by signal " << (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
    EXPECT_EQ(WEXITSTATUS(st), 2) << output;
    EXPECT_NE(output.find("file-size limit"), std::string::npos) << out << ": " << output;
    EXPECT_EQ(temporaries(), 0) << out;
  }
  std::ifstream prev(p("o.pfm"));
  std::string s;
  prev >> s;
  EXPECT_EQ(s, "previous");
  EXPECT_FALSE(fs::exists(p("o.exr")));
  EXPECT_FALSE(fs::exists(p("o.tif")));
}

// SIGINT/SIGTERM at random moments while a run writes: the output is either
// absent or complete (renamed whole), and no temporary is left behind.
// SIGKILL cannot be caught: there the destination is still absent or whole
// (rename is atomic); only a temporary may remain, named .NAME.brume-tmp-PID-N.
TEST_F(Reliability, InterruptedRunsLeaveWholeFilesOnly) {
  Image img(512, 384, 3);
  for (std::size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<float>(i % 89) / 89.0f;
  write_image(p("i.exr"), img, WriteOptions{});
  std::mt19937 rng(15);
  // Learn how long a run takes, then kill at uniform moments within it.
  auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(run("blur --image " + p("i.exr") + " --sigma 3 --out " + p("ref.exr")).status, 0);
  const double full_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const Image ref = read_color(p("ref.exr"));
  for (int round = 0; round < 12; ++round) {
    const int sig = round % 3 == 0 ? SIGKILL : round % 3 == 1 ? SIGTERM : SIGINT;
    // Appended piecewise: GCC 12's -Wrestrict misfires on "o" + to_string(...) (GCC bug 105329).
    std::string name = "o";
    name += std::to_string(round);
    name += ".exr";
    const std::string out = p(name);
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      execl(BRUME_CLI, BRUME_CLI, "blur", "--image", p("i.exr").c_str(), "--sigma", "3", "--out", out.c_str(),
            static_cast<char*>(nullptr));
      _exit(127);
    }
    std::uniform_real_distribution<double> when(0.0, full_ms * 1.1);
    std::this_thread::sleep_for(std::chrono::microseconds(static_cast<long>(when(rng) * 1000)));
    kill(pid, sig);
    int st = 0;
    waitpid(pid, &st, 0);
    if (fs::exists(out)) {
      Image o = read_color(out);  // complete: decodes, and equals the uninterrupted run
      ASSERT_EQ(o.data.size(), ref.data.size());
      EXPECT_EQ(o.data, ref.data) << "round " << round;
    }
    if (sig != SIGKILL) {
      EXPECT_EQ(temporaries(), 0) << "round " << round << " signal " << sig;
    }
    for (auto& e : fs::directory_iterator(dir))
      if (e.path().filename().string().find(".brume-tmp-") != std::string::npos) fs::remove(e.path());
  }
}

// The output's directory is removed while the effect runs (a cleanup job, a
// user's rm -r): the write fails with the directory named, exit 2, and
// nothing is left behind, not even the record bound for a directory that
// still exists (outputs are all or nothing).
TEST_F(Reliability, OutputDirectoryRemovedMidRun) {
  Image img(384, 288, 3);
  for (std::size_t i = 0; i < img.data.size(); ++i) img.data[i] = static_cast<float>(i % 97) / 97.0f;
  write_image(p("i.exr"), img, WriteOptions{});
  const fs::path out_dir = dir / "out";
  const std::string out = (out_dir / "o.exr").string();
  // Learn how long a run takes; the removal then lands in its middle, long
  // after the outputs were checked (before any work) and before the write.
  // The double-precision reference path (~0.2 s of work here) keeps that
  // middle wide: the fast path's whole run of this image is ~30 ms, most of
  // it process start-up and exit, and a removal timed at its half often
  // came before the work or after the outputs were in place.
  fs::create_directories(out_dir);
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(run("blur --reference --image " + p("i.exr") + " --sigma 24 --out " + out).status, 0);
  const double full_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  fs::remove(out);
  int removed_mid_run = 0;
  for (int attempt = 0; attempt < 8 && removed_mid_run == 0; ++attempt) {
    fs::create_directories(out_dir);
    int pipefd[2];
    ASSERT_EQ(pipe(pipefd), 0);
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      dup2(pipefd[1], 2);
      close(pipefd[0]);
      execl(BRUME_CLI, BRUME_CLI, "blur", "--reference", "--image", p("i.exr").c_str(), "--sigma", "24", "--out",
            out.c_str(), "--record", p("rec.json").c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    close(pipefd[1]);
    std::this_thread::sleep_for(std::chrono::microseconds(static_cast<long>(full_ms * 500)));
    int st = 0;
    const bool still_running = waitpid(pid, &st, WNOHANG) == 0;
    fs::remove_all(out_dir);
    if (still_running) waitpid(pid, &st, 0);
    std::string err;
    char buf[4096];
    for (ssize_t k; (k = read(pipefd[0], buf, sizeof buf)) > 0;) err.append(buf, static_cast<std::size_t>(k));
    close(pipefd[0]);
    // The run beat the removal (a fast or idle machine), or was still
    // exiting when the directory went, its outputs already in place (exit
    // status 0): try again, later on.
    if (!still_running || (WIFEXITED(st) && WEXITSTATUS(st) == 0)) {
      fs::remove(p("rec.json"));
      continue;
    }
    ++removed_mid_run;
    ASSERT_TRUE(WIFEXITED(st)) << err;
    EXPECT_EQ(WEXITSTATUS(st), 2) << err;
    EXPECT_NE(err.find("directory '" + out_dir.string() + "' does not exist"), std::string::npos) << err;
    EXPECT_FALSE(fs::exists(out_dir)) << "the output directory was recreated";
    EXPECT_FALSE(fs::exists(p("rec.json"))) << "the record was written without its image";
    EXPECT_EQ(temporaries(), 0);
  }
  ASSERT_EQ(removed_mid_run, 1) << "every run (" << full_ms << " ms) ended before the directory was removed";
}

// Error text is printable UTF-8 even when it quotes a damaged file: an
// OpenEXR header whose attribute name holds byte 0xFD (and whose size field
// is absurd) is refused naming the attribute with that byte as \xFD, from
// the library and from the CLI; control characters in a message are escaped
// too, newlines and tabs kept (issue #38's example). The file has two
// channels, which the direct EXR reader leaves to the guarded OpenImageIO
// path (the header scan of image_io.cpp that quotes the name).
TEST_F(Reliability, ErrorTextQuotingADamagedFileIsPrintableUtf8) {
  Image img(8, 6, 2);
  for (float& v : img.data) v = 0.5f;
  write_image(p("ok.exr"), img, WriteOptions{}, "");
  std::string bytes;
  {
    std::ifstream in(p("ok.exr"), std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::size_t at = bytes.find(std::string("compression\0compression\0", 24));
  ASSERT_NE(at, std::string::npos);
  bytes[at + 9] = static_cast<char>(0xFD);                         // "compressi\xFDn"
  const std::uint32_t huge = 1690501120u;                          // the declared size, past the file's end
  std::memcpy(&bytes[at + 24], &huge, 4);
  {
    std::ofstream out(p("bad.exr"), std::ios::binary);
    out << bytes;
  }
  const std::string e = error_of([&] { read_color(p("bad.exr")); });
  EXPECT_NE(e.find("attribute 'compressi\\xFDn' declares 1690501120 bytes"), std::string::npos) << e;
  EXPECT_EQ(first_invalid_utf8(e), std::string::npos);
  const CliRun r = run("blur --image " + p("bad.exr") + " --sigma 1 --out " + p("o.exr"));
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("compressi\\xFDn"), std::string::npos) << r.output;
  EXPECT_EQ(first_invalid_utf8(r.output), std::string::npos);
  EXPECT_FALSE(fs::exists(p("o.exr"))) << r.output;
  EXPECT_STREQ(Error(std::string("a\x01" "b\x1B[31m\nc\td\x7F\xC3\xA9\xC3")).what(), "a\\x01b\\x1B[31m\nc\td\\x7F\xC3\xA9\\xC3");
}

// Paths, keys and arguments go into JSON records and manifests, which hold
// UTF-8 only; Linux file names may hold any bytes. A name that is not UTF-8
// is refused before any work, by name, with its bad bytes shown as \xHH
// (before, the record's JSON dump threw after the effect had run: "internal
// error", exit 3). The validator is checked against an independent one,
// nlohmann::json's own UTF-8 check in dump(), on every 1- and 2-byte string
// and 200 000 random ones of up to 6 bytes drawn mostly from 0x80-0xFF.
TEST_F(Reliability, TextThatIsNotUtf8IsRefusedByName) {
  auto json_accepts = [](const std::string& s) {
    try {
      (void)nlohmann::json(s).dump();
      return true;
    } catch (const nlohmann::json::type_error&) {
      return false;
    }
  };
  auto agree = [&](const std::string& s) { return (first_invalid_utf8(s) == std::string::npos) == json_accepts(s); };
  for (int a = 0; a < 256; ++a) {
    ASSERT_TRUE(agree(std::string(1, static_cast<char>(a)))) << a;
    for (int b = 0; b < 256; ++b) ASSERT_TRUE(agree(std::string{static_cast<char>(a), static_cast<char>(b)})) << a << " " << b;
  }
  std::mt19937 rng(15);
  std::uniform_int_distribution<int> len(1, 6), high(0x80, 0xFF), any(0, 255), pick(0, 3);
  int valid = 0;
  for (int i = 0; i < 200000; ++i) {
    std::string s;
    for (int k = len(rng); k > 0; --k) s += static_cast<char>(pick(rng) == 0 ? any(rng) : high(rng));
    ASSERT_TRUE(agree(s)) << ::testing::PrintToString(s);
    valid += first_invalid_utf8(s) == std::string::npos;
  }
  EXPECT_GT(valid, 100);  // the draw reaches well-formed multi-byte sequences too
  EXPECT_EQ(first_invalid_utf8("Z\xC3\xBCrich/\xE6\x9D\xB1\xE4\xBA\xAC/\xF0\x9F\x98\x80.png"), std::string::npos);
  EXPECT_EQ(first_invalid_utf8("ab\xC0\x80"), 2u);          // overlong NUL
  EXPECT_EQ(first_invalid_utf8("\xED\xA0\x80"), 0u);        // a UTF-16 surrogate
  EXPECT_EQ(first_invalid_utf8("x\xF4\x90\x80\x80"), 1u);   // above U+10FFFF
  EXPECT_EQ(first_invalid_utf8("\xE2\x82"), 0u);            // cut short

  // A text parameter (a path) refuses it, naming the flag and the bytes.
  ParamSpec image;
  image.name = "image";
  image.kind = ParamKind::text;
  const std::string msg = error_of([&] { image.check(nlohmann::json(std::string("im\xFF.png"))); });
  EXPECT_NE(msg.find("--image 'im\\xFF.png' is not valid UTF-8 (byte 0xFF at offset 2)"), std::string::npos) << msg;
  EXPECT_NO_THROW(image.check(nlohmann::json(std::string("Z\xC3\xBCrich.png"))));

  // The CLI: refused before any work, exit 2, nothing written; a UTF-8 name
  // that is not ASCII runs as any other.
  Image img(16, 12, 3, 0.5f);
  write_image(p("im\xFF.exr"), img, WriteOptions{});
  write_image(p("Z\xC3\xBCrich.exr"), img, WriteOptions{});
  CliRun r = run("blur --image '" + p("im\xFF.exr") + "' --sigma 1 --out " + p("o.exr") + " --record " + p("o.json"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("im\\xFF.exr' is not valid UTF-8"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("rename the file"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("o.exr")));
  EXPECT_FALSE(fs::exists(p("o.json")));
  r = run("blur --image '" + p("Z\xC3\xBCrich.exr") + "' --sigma 1 --out '" + p("\xC3\xBC.exr") + "' --record " +
          p("o.json"));
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::exists(p("\xC3\xBC.exr")));

  // A batch manifest cell: a manifest error (nothing run) naming its line.
  {
    std::ofstream m(p("m.csv"));
    m << "key,image,range\nok,Z\xC3\xBCrich.exr,Z\xC3\xBCrich.exr\nbad,im\xFF.exr,Z\xC3\xBCrich.exr\n";
  }
  r = run("batch --manifest " + p("m.csv") + " --effect haze --param visibility=1000 --out-dir " + p("out"));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("line 3"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("im\\xFF.exr' is not valid UTF-8"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(p("out/ok.exr")));

  // A scanned file name: the manifest is not written.
  const std::string scan_msg =
      error_of([&] { write_manifest(p("scan.csv"), {nlohmann::json{{"key", "a"}, {"image", "d/im\xFF.png"}}}); });
  EXPECT_NE(scan_msg.find("--dataset: the 'image' file 'd/im\\xFF.png' is not valid UTF-8"), std::string::npos) << scan_msg;
  EXPECT_FALSE(fs::exists(p("scan.csv")));
}
