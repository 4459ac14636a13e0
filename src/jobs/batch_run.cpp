// brume — running `brume batch`: one frame through its effect's pipeline
// (run_batch_frame) and its results line, resume (batch_frame_done), and the
// whole run (run_batch): shard filter, workers, progress, the results
// manifest and its journal; the records' argv (batch_record_argv).
// brume/batch.hpp says what and why.
#include "brume/batch.hpp"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/gpu_context.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "brume/rerun.hpp"
#include "core/warnings.hpp"

namespace fs = std::filesystem;

namespace brume {

std::vector<std::string> batch_record_argv(const BatchOptions& o) {
  std::vector<std::string> a = {"brume", "batch", "--manifest", o.manifest, "--out-dir", o.out_dir,
                                "--seed", std::to_string(o.seed)};
  if (!o.format.empty()) a.insert(a.end(), {"--format", o.format});
  if (!o.effect.empty()) a.insert(a.end(), {"--effect", o.effect});
  for (const auto& [n, s] : o.params) a.insert(a.end(), {"--param", n + "=" + s});
  for (const std::string& m : o.maps) a.insert(a.end(), {"--map", m});
  return a;
}

// ---- one frame ---------------------------------------------------------------------------

namespace {

void collect_inputs(const nlohmann::json& j, std::vector<std::pair<std::string, std::string>>& out) {
  if (j.is_object()) {
    if (j.contains("path") && j.contains("sha256") && j["path"].is_string() && j["sha256"].is_string())
      out.emplace_back(j["path"].get<std::string>(), j["sha256"].get<std::string>());
    for (const auto& [k, v] : j.items()) collect_inputs(v, out);
  } else if (j.is_array()) {
    for (const auto& v : j) collect_inputs(v, out);
  }
}

// Temporaries an earlier process left beside a frame's outputs (SIGKILL
// cannot be caught): .NAME.brume-tmp-PID-N. A frame belongs to one shard, so
// no other live process writes them.
void remove_stale_temporaries(const BatchFrame& f) {
  for (const std::string& o : f.outputs) {
    const fs::path p(o);
    const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    const std::string prefix = "." + p.filename().string() + ".brume-tmp-";
    for (const auto& ent : fs::directory_iterator(dir, ec))
      if (ent.path().filename().string().rfind(prefix, 0) == 0) fs::remove(ent.path(), ec);
  }
}

const CommandDef& def_of(const std::string& name) {
  if (const CommandDef* c = find_command(name); c && c->batchable) return *c;
  throw Error("internal: batch effect '" + name + "'");
}

// The record's job as `brume run` runs it: a parameter a later schema
// introduced with a new rule at the older rule (record_job), and what an
// earlier brume did not record -- a block or a parameter added since -- at
// this command's default, as ParamTable::from_json leaves a key a job lacks
// (a parameter whose default is not the older behaviour carries
// ParamTable::since). So a resume across an upgrade skips a frame whose job
// is the same. (Records cannot tell builds apart: brume's version has been
// 0.1.0 throughout.)
nlohmann::json recorded_job_now(const nlohmann::json& rec, const CommandDef& c) {
  if (rec.value("command", "") != c.name) return nullptr;
  nlohmann::json job = record_job(rec);
  if (!job.is_object()) return job;
  for (const ParamSpec& s : c.specs) {
    auto b = job.find(s.block);
    if (b != job.end() && !b->is_object()) return nullptr;  // malformed: not the same job
    if (b == job.end() || !b->contains(s.name)) job[s.block][s.name] = c.defaults.at(s.block).at(s.name);
  }
  return job;
}

}  // namespace

bool batch_frame_done(const BatchFrame& f) {
  std::error_code ec;
  for (const std::string& o : f.outputs)
    if (!fs::is_regular_file(o, ec)) return false;
  nlohmann::json rec;
  try {
    std::ifstream in(f.outputs.back());
    rec = nlohmann::json::parse(in);
  } catch (const std::exception&) {
    return false;
  }
  if (!rec.is_object() || rec.value("batch", nlohmann::json()) != f.batch) return false;
  try {
    if (recorded_job_now(rec, def_of(f.effect)) != f.job) return false;
  } catch (const std::exception&) {
    return false;  // a record of no schema this brume reads, or malformed: the frame runs again
  }
  std::vector<std::pair<std::string, std::string>> inputs;
  collect_inputs(rec.value("inputs", nlohmann::json()), inputs);
  if (inputs.empty()) return false;
  for (const auto& [path, sha] : inputs) {
    try {
      if (sha256_file(path) != sha) return false;
    } catch (const std::exception&) {
      return false;
    }
  }
  return true;
}

namespace {

// The results manifest's line for a frame.
nlohmann::json result_line(const BatchFrame& f, const BatchFrameResult& r) {
  nlohmann::json outputs = nlohmann::json::object();
  outputs["image"] = f.outputs.front();
  outputs["record"] = f.outputs.back();
  for (std::size_t i = 1; i + 1 < f.outputs.size(); ++i) outputs["maps"].push_back(f.outputs[i]);
  // The input files: the text parameters of the input and depth blocks that are set.
  nlohmann::json inputs = nlohmann::json::object();
  for (const ParamSpec& s : def_of(f.effect).specs) {
    if (!is_input_file(s)) continue;
    const nlohmann::json& v = f.job[s.block][s.name];
    if (v.is_string() && !v.get<std::string>().empty()) inputs[s.name] = v;
  }
  nlohmann::json params = nlohmann::json::object();
  // The parameters the row set (fixed and drawn), as the job holds them; a
  // chain's later stage by its stage name ("dof.focus-distance").
  const std::string& prefix = def_of(f.effect).stage_prefix;
  for (const std::string& n : f.given)
    for (const auto& [block, vals] : f.job.items())
      if (block != "input" && block != "depth" && block != "output" && vals.is_object() && vals.contains(n))
        params[!prefix.empty() && n.rfind(prefix, 0) == 0
                   ? prefix.substr(0, prefix.size() - 1) + "." + n.substr(prefix.size())
                   : n] = vals[n];
  nlohmann::json l = {{"key", f.key},        {"status", r.status},  {"effect", f.effect}, {"inputs", inputs},
                      {"outputs", outputs},  {"parameters", params}, {"sampling", f.batch["sampling"]},
                      {"seconds", r.seconds}};
  if (!r.error.empty()) l["error"] = r.error;
  if (!r.warnings.empty()) l["warnings"] = r.warnings;
  return l;
}

}  // namespace

BatchFrameResult run_batch_frame(const BatchFrame& f, const ExecOptions& exec, const std::vector<std::string>& argv) {
  keep_freed_heap();  // a frame after another: the next reuses the last one's buffers
  BatchFrameResult r;
  const auto t0 = std::chrono::steady_clock::now();
  // The frame's warnings name it on stderr (frames in flight print side by
  // side) and join its results line, failed or not.
  const FrameWarnings warned(f.key);
  try {
    remove_stale_temporaries(f);
    // The frame's folders are made as its outputs are written, so that a
    // frame that fails before writing leaves none behind.
    const CreateOutputFolders lazily;
    const IoThreads io(exec.threads);  // the worker's --threads bounds its codecs too
    RunContext ctx;
    ctx.argv = argv;
    ctx.given = f.given;
    ctx.extra = {{"batch", f.batch}};
    def_of(f.effect).run(f.job, exec, ctx);
    r.status = "ok";
  } catch (const std::exception& e) {
    r.status = "failed";
    r.error = dynamic_cast<const std::bad_alloc*>(&e) ? out_of_memory_message() : e.what();
    // A failed frame leaves no output of its key behind (not even one from an
    // earlier run with other parameters): the folder never holds an output the
    // manifest no longer describes.
    std::error_code ec;
    for (const std::string& o : f.outputs) fs::remove(o, ec);
  }
  r.warnings = warned.texts();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.line = result_line(f, r);
  return r;
}

// ---- the whole run --------------------------------------------------------------------------

BatchSummary run_batch(const BatchOptions& o) {
  if (o.shard_count < 1 || o.shard_index < 1 || o.shard_index > o.shard_count)
    throw Error("--shard " + std::to_string(o.shard_index) + "/" + std::to_string(o.shard_count) +
                " is not allowed: I/N with 1 <= I <= N (I counts from 1, as Slurm's array index can)");
  if (o.workers < 0 || o.workers > 4096)
    throw Error("--workers " + std::to_string(o.workers) + " is not allowed: 0 (one per core) to 4096");
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<BatchFrame> all = plan_batch(o);
  std::vector<const BatchFrame*> frames;
  for (const BatchFrame& f : all)
    if (o.shard_count == 1 || shard_of(f.key, o.shard_count) == o.shard_index) frames.push_back(&f);
  std::error_code ec;
  const bool made_out_dir = !fs::exists(o.out_dir, ec);
  fs::create_directories(o.out_dir, ec);
  if (!fs::is_directory(o.out_dir)) throw Error("--out-dir '" + o.out_dir + "' cannot be created: " + ec.message());
  check_output_dir((fs::path(o.out_dir) / "results.jsonl").string(), "--out-dir");

  const int hw = std::max(1u, std::thread::hardware_concurrency());
  const int asked = o.workers > 0 ? o.workers : hw;
  const int workers = std::max(1, std::min<int>(asked, static_cast<int>(frames.size())));
  ExecOptions exec = o.exec;
  for (const BatchFrame* f : frames) refuse_gpu_without_passes(def_of(f->effect), exec.backend, "--backend");
  // Results do not depend on threads; frames in flight share the cores. From
  // the workers asked for, not those a small shard uses, so that the records'
  // execution.threads is the same in every shard.
  if (exec.threads == 0) exec.threads = std::max(1, hw / asked);
  const std::vector<std::string> argv = batch_record_argv(o);

  BatchSummary s;
  s.frames = frames.size();
  std::vector<nlohmann::json> lines(frames.size());
  // The results manifest's name, and its journal: the same lines, appended
  // as frames finish (in the order they finish) and flushed one by one, so
  // that a running or killed batch shows what is done (`tail -f`). Each line
  // is one write of a whole line. The journal is removed once the manifest
  // (manifest order, written whole) is in place; a new run starts it afresh.
  const std::string name = o.shard_count == 1 ? "results.jsonl"
                                              : "results.shard-" + std::to_string(o.shard_index) + "-of-" +
                                                    std::to_string(o.shard_count) + ".jsonl";
  s.results = (fs::path(o.out_dir) / name).generic_string();
  const std::string journal_path = s.results + ".partial";
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> journal(std::fopen(journal_path.c_str(), "w"), &std::fclose);
  if (!journal)
    throw Error("--out-dir '" + o.out_dir + "': cannot create the results journal '" + journal_path +
                "': " + std::strerror(errno));
  bool journal_whole = true;  // every line reached the file whole (a full disk: not)
  std::size_t journal_lines = 0;
  std::atomic<std::size_t> next{0};
  std::mutex mu;
  std::size_t finished = 0, worked = 0;
  const bool tty = o.progress && isatty(STDERR_FILENO);
  auto last_print = std::chrono::steady_clock::now() - std::chrono::seconds(10);
  auto progress = [&](bool final) {
    // Rate and ETA over the frames that ran (skipped ones cost nothing).
    const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double rate = worked > 0 ? static_cast<double>(worked) / el : 0.0;
    const std::size_t left = s.frames - finished;
    char eta[32] = "?";
    if (rate > 0) std::snprintf(eta, sizeof eta, "%.0f s", static_cast<double>(left) / rate);
    char buf[256];
    std::snprintf(buf, sizeof buf, "brume batch: %zu/%zu frames (%zu ok, %zu skipped, %zu failed)  %.2f frames/s  ETA %s",
                  finished, s.frames, s.ok, s.skipped, s.failed, rate, final ? "0 s" : eta);
    if (tty) {
      const int width = 24;
      const int fill = s.frames ? static_cast<int>(width * finished / s.frames) : width;
      std::fprintf(stderr, "\r[%s%s] %s\033[K%s", std::string(fill, '#').c_str(), std::string(width - fill, '.').c_str(),
                   buf, final ? "\n" : "");
    } else {
      std::fprintf(stderr, "%s\n", buf);
    }
    std::fflush(stderr);
  };

  auto worker = [&] {
    // On a GPU backend each worker makes one context on its own thread (a
    // context belongs to the thread that made it) and runs all its frames on
    // it: a context per frame cost its creation and the compilation of every
    // pass again, per frame (docs/datasets.md). Made before the first frame
    // that needs it; when it cannot be made, each frame decides as a single
    // run would (gpu: the frame fails, naming why; auto: the CPU, recorded).
    std::unique_ptr<GpuContext> gpu;
    bool gpu_tried = false;
    ExecOptions wexec = exec;
    for (;;) {
      const std::size_t i = next.fetch_add(1);
      if (i >= frames.size()) return;
      const BatchFrame& f = *frames[i];
      BatchFrameResult r;
      if (o.resume && batch_frame_done(f)) {
        r.status = "skipped";
        r.line = result_line(f, r);
      } else {
        if (exec.backend != Backend::cpu && !exec.reference && !gpu_tried) {
          gpu_tried = true;
          try {
            gpu = std::make_unique<GpuContext>();
            wexec.gpu = gpu.get();
          } catch (const Error&) {
          }
        }
        r = run_batch_frame(f, wexec, argv);
      }
      std::lock_guard<std::mutex> lock(mu);
      lines[i] = r.line;
      const std::string jl = r.line.dump() + "\n";
      // A full disk shows at the manifest's write; the journal notes whether
      // its lines reached the file whole.
      if (std::fwrite(jl.data(), 1, jl.size(), journal.get()) != jl.size() || std::fflush(journal.get()) != 0)
        journal_whole = false;
      else
        ++journal_lines;
      ++finished;
      if (r.status == "ok") ++s.ok, ++worked;
      if (!r.warnings.empty()) ++s.warned;
      if (r.status == "skipped") ++s.skipped;
      if (r.status == "failed") {
        ++s.failed, ++worked;
        // Frame, file, message: enough to find the bad input without the results file.
        std::fprintf(stderr, "%sbrume batch: frame '%s' (%s) failed: %s\n", tty ? "\r\033[K" : "", f.key.c_str(),
                     f.image.c_str(), r.error.c_str());
      }
      const auto now = std::chrono::steady_clock::now();
      // A terminal's bar is redrawn at most 10 times a second; plain lines (a log) once a second.
      if (o.progress && (now - last_print > std::chrono::milliseconds(tty ? 100 : 1000) || finished == s.frames)) {
        last_print = now;
        if (finished < s.frames) progress(false);
      }
    }
  };
  std::vector<std::thread> pool;
  for (int w = 1; w < workers; ++w) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (o.progress) progress(true);

  // The results manifest: one line per frame of this shard, in manifest
  // order, written whole at the end (a killed run leaves only the journal;
  // --resume writes it, with the frames done before as "skipped").
  std::string text;
  for (const nlohmann::json& l : lines) text += l.dump() + "\n";
  try {
    OutputSet outs;
    outs.write_text(s.results, text, "--out-dir");
    outs.commit();
  } catch (const Error&) {
    // The manifest could not be written (a full disk): the journal stays as
    // the record of what was done only when it holds every line whole; an
    // empty or torn one goes, and so does an --out-dir this run made that
    // holds nothing (issue #51: a 0-byte journal and empty folders stayed).
    journal.reset();
    if (!journal_whole || journal_lines == 0) fs::remove(journal_path, ec);
    if (made_out_dir) fs::remove(o.out_dir, ec);  // only when empty
    throw;
  }
  journal.reset();
  fs::remove(journal_path, ec);
  return s;
}

}  // namespace brume
