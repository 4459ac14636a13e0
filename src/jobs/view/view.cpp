// brume — `brume view`: a live preview of an effect in the browser (issue
// #43, docs/view.md). A local HTTP server (cpp-httplib) serves one page whose
// ES modules run the command's GPU passes in WebGL2 from the same GLSL the
// native backend compiles (src/gpu/passes.hpp), on the image and prepared
// range sent once as float data; each change of a control asks the server
// for the frame's plan (the command's `preview`, brume/preview.hpp: the
// analysis the CLI would make, as uniforms), so what the page shows is what
// `brume <effect>` renders. Nothing here names an effect: the command comes
// from the list by name, its controls from its table.
//
// Security (a server on a user's machine): loopback only unless --listen; a
// random token as the first path segment, checked first on every request
// (403); Host and Origin must name the address and port served (403: DNS
// rebinding); with the token only the page, its modules and the one view's
// data exist (404 for anything else: no file paths, no listing); the
// request rate is bounded; SIGINT/SIGTERM end it (set explicitly: a shell's
// background job inherits SIGINT ignored), and so does --idle-exit. It
// writes nothing.
//
// Peers without the token (issue #51): connections are accepted and read by
// the front (http_front.hpp: heads and bodies within byte bounds and
// deadlines, idle connections evicted first at the cap, 403 for a target
// without the token before anything else is read); cpp-httplib parses and
// routes only complete requests, from memory (RequestStream), and writes
// the response through the front.
#include <httplib.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"
#include "brume/record.hpp"
#include "jobs/view/http_front.hpp"
#include "jobs/view/view_embedded.hpp"
#if BRUME_HAVE_GPU
#include "gpu/passes.hpp"
#endif

namespace fs = std::filesystem;
using nlohmann::json;

namespace brume {

namespace {

// The answer to a request without the token (the front's and the routes' alike).
const char* const kNoToken = "forbidden: the URL needs the token brume view printed\n";

struct ViewParams {
  std::string effect = "haze";
  int port = 0;
  std::string listen;
  double idle_exit_min = 60.0;
};
struct ViewJob {
  InputFiles input;
  RangeStep prepare;
  ViewParams view;
};

// The effects --effect names; a run checks that the command has a preview
// (CommandDef::preview). A fixed list: the table is made while the list of
// commands is being built, so it cannot ask that list.
// The commands with a preview (CommandDef::preview), by hand: the view is a
// command of the list itself, and its table would read the list while the
// list is built. Commands.TheViewOffersEveryPreview fails when it is stale.
const std::vector<const char*>& preview_names() {
  static const std::vector<const char*> n = {"haze", "fog", "aerial", "dof", "haze+dof"};
  return n;
}

const ParamTable<ViewParams>& view_param_table() {
  static const ParamTable<ViewParams> t = [] {
    ParamTable<ViewParams> d("view");
    d.choice("effect", &ViewParams::effect, preview_names(), "the effect shown (its controls come from its table)")
        .integer("port", &ViewParams::port, "1", Range::closed(0, 65535), "TCP port; 0 picks a free one")
        .text("listen", &ViewParams::listen,
              "address to bind instead of the loopback (127.0.0.1 and ::1); the token still guards every request")
        .real("idle-exit", &ViewParams::idle_exit_min, "min", Range::at_least(0.0),
              "exit after this many minutes without a request; 0: never");
    return d;
  }();
  return t;
}

const ParamTable<ViewJob>& view_job_table() {
  static const ParamTable<ViewJob> t = [] {
    ParamTable<ViewJob> d("view");
    d.nest(&ViewJob::input, input_param_table(true))
        .nest(&ViewJob::prepare, range_step_param_table())
        .nest(&ViewJob::view, view_param_table());
    return d;
  }();
  return t;
}

// ---------------------------------------------------------------- the view's data

// The parameters the page edits: the effect's own (and its diffusion's),
// not the files, the depth source, the preparation (the view's own blocks,
// which its command line fixed) or the outputs; no text parameter (a file
// or a database entry: the page names no file) and none of the blocks or
// parameters the command keeps from the page (CommandDef::preview_fixed).
bool page_param(const CommandDef& c, const ParamSpec& s) {
  if (s.block == "output" || s.kind == ParamKind::text) return false;
  for (const std::string& b : c.preview_fixed)
    if (s.block == b || s.name == b) return false;
  for (const Param<ViewJob>& d : view_job_table().params())
    if (d.spec.block == s.block) return false;
  return true;
}

// The depth flags the page sets too: the camera's intrinsics (the field of
// view, the focal length in pixels, the principal point), which a height
// profile and planar depth need. Changing one re-reads the inputs when their
// conversion to range uses it (a z map, a disparity).
bool camera_param(const CommandDef& c, const ParamSpec& s) {
  if (s.block != "depth" || s.kind == ParamKind::text || !c.spec(s.name)) return false;
  for (const std::string& n : camera_intrinsics_params())
    if (n == s.name) return true;
  return false;
}

std::string kind_name(ParamKind k) {
  switch (k) {
    case ParamKind::real: return "real";
    case ParamKind::integer: return "integer";
    case ParamKind::boolean: return "boolean";
    case ParamKind::choice: return "choice";
    case ParamKind::rgb: return "rgb";
    case ParamKind::text: return "text";
    case ParamKind::pair: return "pair";
  }
  return "text";
}

json finite_or_null(double v) { return std::isfinite(v) ? json(v) : json(); }

// A declaration for the page's controls, with a plausible span for the
// slider: the command's sampling range where it has one.
json spec_json(const CommandDef& c, const ParamSpec& s) {
  json j = {{"name", s.name},       {"block", s.block},   {"kind", kind_name(s.kind)},
            {"unit", s.unit},       {"help", s.describe()}, {"min", finite_or_null(s.range.min)},
            {"max", finite_or_null(s.range.max)}, {"min_open", s.range.min_open}, {"max_open", s.range.max_open},
            {"choices", s.choices}, {"optional", s.optional}, {"unset_word", s.unset_word}, {"words", s.words},
            {"default", s.format(c.defaults.at(s.block).at(s.name))}};
  if (c.sampling)
    for (const SampleDefault& d : c.sampling->defaults)
      if (d.name == s.name) j["sampling"] = d.spec;
  return j;
}

// The inputs at 1/k of their size (a box average of the colour, every
// k-th range sample), completed and prepared as the command's run would.
struct ViewData {
  int k = 1;
  Image rgb, measured;  // measured: completed, when the step completes
  CompletedRange done;
  PreparedRange prep;
  std::string rgba, range, sky;  // float32 little-endian texture data
};

Image shrink(const Image& in, int k, bool average) {
  if (k == 1) return in;
  const int w = in.width / k, h = in.height / k, c = in.channels;
  Image out(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int ch = 0; ch < c; ++ch) {
        if (!average) {
          out.data[(static_cast<std::size_t>(y) * w + x) * c + ch] =
              in.data[(static_cast<std::size_t>(y * k + k / 2) * in.width + x * k + k / 2) * c + ch];
          continue;
        }
        double s = 0.0;
        for (int v = 0; v < k; ++v)
          for (int u = 0; u < k; ++u) s += in.data[(static_cast<std::size_t>(y * k + v) * in.width + x * k + u) * c + ch];
        out.data[(static_cast<std::size_t>(y) * w + x) * c + ch] = static_cast<float>(s / (k * k));
      }
  return out;
}

std::string floats(const std::vector<float>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float));
}

std::unique_ptr<ViewData> make_data(const LoadedInputs& in, const RangeStep& step, const std::set<std::string>& given,
                                    int k) {
  auto d = std::make_unique<ViewData>();
  d->k = k;
  d->rgb = shrink(in.rgb, k, true);
  d->measured = shrink(in.depth.range, k, false);
  d->done = complete_step(d->measured, d->rgb, step, given, 0);
  if (d->done.applied) d->measured = d->done.range;
  d->prep = prepare_step(d->measured, step, given, 0, /*sky_weight=*/true);
  const std::size_t n = d->rgb.pixels();
  std::vector<float> rgba(n * 4, 1.0f), sky(n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) rgba[i * 4 + c] = d->rgb.data[i * 3 + c];
    if (!d->prep.sky_weight.empty()) sky[i] = d->prep.sky_weight.data[i];
  }
  d->rgba = floats(rgba);
  d->range = floats(preview_unknown_negative(d->prep.range).data);  // as upload_color_and_range
  d->sky = floats(sky);
  return d;
}

// A word for a POSIX shell.
std::string shell_word(const std::string& s) {
  const bool plain = !s.empty() && std::all_of(s.begin(), s.end(), [](char ch) {
    return std::isalnum(static_cast<unsigned char>(ch)) || std::strchr("_./,:+=-@%", ch);
  });
  if (plain) return s;
  std::string q = "'";
  for (char ch : s) q += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
  return q + "'";
}

std::string random_token() {
  std::random_device rd;  // /dev/urandom on Linux
  std::string t;
  for (int i = 0; i < 4; ++i) {
    char b[9];
    std::snprintf(b, sizeof b, "%08x", static_cast<unsigned>(rd()));
    t += b;
  }
  return t;
}

std::atomic<int> g_signal{0};
extern "C" void on_view_signal(int sig) { g_signal.store(sig); }

struct Server {
  Server(const CommandDef& cmd, RangeStep s, std::set<std::string> g)
      : c(cmd), step(std::move(s)), cli_given(std::move(g)), token(random_token()) {}
  const CommandDef& c;
  LoadedInputs in;
  InputFiles files;  // the command line's input and depth flags, paths absolute (what `in` was read from)
  RangeStep step;
  std::set<std::string> cli_given;
  JobValues cli_values;  // the command line's input and preparation flags, for the effect's job
  std::string token, host_ok[4];
  int port = 0;
  std::mutex mu;
  // The inputs at each scale the page asked for (1/k: the browser's texture
  // limit, or a draft while a control moves), the last few kept.
  std::map<int, std::unique_ptr<ViewData>> data;
  // The camera values the inputs were read with (the page's camera controls),
  // and a count the page compares, so that it fetches the data again when a
  // new camera re-read them (a z map's or a disparity's conversion to range).
  nlohmann::json loaded_camera = nlohmann::json::object();
  int data_version = 0;
  PreviewScene scene;
  // The maps of the last two frames (PreviewFrame::maps): the page fetches a
  // frame's maps right after its plan; the one before covers a plan that
  // overtook a fetch.
  std::map<std::string, Image> maps, maps_before;
  std::atomic<long long> last_request_ms{0};
  std::atomic<int> window_count{0};
  std::atomic<long long> window_start{0};

  static long long now_ms() {
    return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }

  ViewData& at(int k) {
    auto it = data.find(k);
    if (it != data.end()) return *it->second;
    while (data.size() >= 4) {  // the largest other scale goes first (the full size and the drafts stay)
      auto drop = std::prev(data.end());
      if (drop->first == k) --drop;
      data.erase(drop);
    }
    return *data.emplace(k, make_data(in, step, cli_given, k)).first->second;
  }

  // The command line's depth flags with the page's camera values: re-reads
  // the inputs when the conversion to range depends on them (not a range map).
  void use_camera(const nlohmann::json& camera) {
    if (camera == loaded_camera) return;
    loaded_camera = camera;
    if (!files.depth.range.empty()) return;  // a range map is range whatever the camera
    InputFiles f = files;
    for (const auto& [name, v] : camera.items()) depth_param_table().at(name).set(f.depth, v);
    in = load_inputs(f, true);
    data.clear();
    ++data_version;
  }

  const ParamSpec* page_spec(const std::string& name) const {
    const ParamSpec* s = c.spec(name);
    return s && (page_param(c, *s) || camera_param(c, *s)) ? s : nullptr;
  }

  // The job of the defaults and the command line's flags.
  json cli_job() const {
    JobValues iv = cli_values;
    iv.emplace_back("out", json("brume-view.png"));
    return c.build(iv);
  }

  // Whether the page offers the camera's intrinsics: where the inputs'
  // conversion to range uses them (a z map, a disparity), or the command does
  // (it takes them as keywords on arrays: fog's height profile, depth of
  // field's planar depth); not for haze on a range map, which no camera changes.
  bool camera_matters() const {
    if (files.depth.range.empty()) return true;
    if (!c.arrays) return false;
    return std::any_of(c.arrays->specs.begin(), c.arrays->specs.end(),
                       [](const ParamSpec& s) { return s.block == "depth" && s.name == "fov-x"; });
  }

  json meta() {
    json specs = json::array();
    for (const ParamSpec& s : c.specs)
      if (page_param(c, s) || (camera_param(c, s) && camera_matters())) specs.push_back(spec_json(c, s));
    // Where the page starts: the command's values for this scene (shown and
    // spelled out in the command), each with its reason.
    json start = json::array();
    if (c.preview_start)
      for (const PreviewStart& p : c.preview_start(cli_job(), cli_given, scene)) {
        const ParamSpec* s = c.spec(p.name);
        if (!s || !page_spec(p.name))
          throw Error("internal: the preview starts " + c.name + " at --" + p.name + ", which the page does not set");
        start.push_back({{"name", p.name}, {"value", s->format(p.value)}, {"why", p.why}});
      }
    json passes = json::object();
#if BRUME_HAVE_GPU
    for (const std::string& name : c.gpu_passes) {
      const gpu::PassSpec* p = gpu::find_pass(name);
      if (!p) throw Error("internal: pass '" + name + "' of " + c.name + " is not linked");
      passes[name] = {{"fragment", gpu::fragment_source(*p)}, {"samplers", gpu::sampler_names(p->body)}};
    }
    const std::string vertex = gpu::vertex_source();
#else
    const std::string vertex;
#endif
    return {{"effect", c.name},
            {"width", in.rgb.width},
            {"height", in.rgb.height},
            {"image", in.record.value("image", json::object()).value("path", json(""))},
            {"specs", specs},
            {"start", start},
            {"scene",
             {{"median_range_m", finite_or_null(scene.median_range_m)},
              {"centre_range_m", finite_or_null(scene.centre_range_m)},
              {"range_min_m", finite_or_null(scene.range_min_m)},
              {"range_max_m", finite_or_null(scene.range_max_m)},
              {"camera_given", scene.camera_given}}},
            {"passes", passes},
            {"vertex", vertex},
            {"version", BRUME_VERSION}};
  }

  // The page parameter a refusal's message is about: the first --NAME in it
  // that the page sets (a cross-field check names the flag it refuses first).
  json mentioned(const std::string& message) const {
    for (std::size_t i = message.find("--"); i != std::string::npos; i = message.find("--", i + 2)) {
      std::size_t j = i + 2;
      while (j < message.size() && (std::isalnum(static_cast<unsigned char>(message[j])) || message[j] == '-')) ++j;
      const std::string name = message.substr(i + 2, j - i - 2);
      if (page_spec(name)) return name;
    }
    return nullptr;
  }

  // The frame for the page's values ({name: text as typed}): the job as the
  // command line would build it, checked, its plan, command line and record.
  // "scale": the inputs at 1/k; "pixel_factor": the preview's pixel lengths
  // (every px parameter: the blur, sigma0, the CoC) times this, so that a
  // draft at 1/k blurs at the full frame's physical scale. A refused value
  // throws Refusal naming it (`param`, when the message is about one).
  struct Refusal : Error {
    Refusal(const std::string& m, json p) : Error(m), param(std::move(p)) {}
    json param;
  };
  json frame(const json& body) {
    if (!body.is_object() || !body.contains("values") || !body["values"].is_object())
      throw Error("the request needs {\"values\": {name: text}}");
    // Range-checked before it is narrowed (4294967297 once read as 1).
    const json scale = body.contains("scale") ? body["scale"] : json(1);
    const bool whole = scale.is_number_integer();
    if (!whole || (scale.is_number_unsigned() ? scale.get<std::uint64_t>() > 64
                                              : scale.get<std::int64_t>() < 1 || scale.get<std::int64_t>() > 64))
      throw Error("scale " + scale.dump() + " must be a whole number in [1, 64]");
    const int k = scale.get<int>();
    double pixel_factor = 1.0;
    if (body.contains("pixel_factor")) {
      if (!body["pixel_factor"].is_number() || !(body["pixel_factor"].get<double>() > 0.0) ||
          !(body["pixel_factor"].get<double>() <= 1.0))
        throw Error("pixel_factor must be a number in (0, 1]");
      pixel_factor = body["pixel_factor"].get<double>();
    }
    // The command line's values, then the page's (a camera value replaces the command line's).
    std::vector<std::pair<std::string, std::pair<json, std::string>>> merged;
    std::set<std::string> given = cli_given;
    for (const auto& [name, v] : cli_values) merged.push_back({name, {v, c.spec(name)->format(v)}});
    json camera = json::object();
    for (const auto& [name, text] : body["values"].items()) {
      const ParamSpec* s = c.spec(name);
      if (!s || !page_spec(name))
        throw Error("'" + name + "' is not a parameter of " + c.name + " the page sets" +
                    (s && s->kind == ParamKind::text ? " (it names a file or an entry, which the page never does)" : ""));
      if (!text.is_string()) throw Refusal("--" + name + ": the value must be text as typed", name);
      json v;
      try {
        v = s->parse(text.get<std::string>());
        s->check(v);
      } catch (const Error& e) {
        throw Refusal(e.what(), name);
      }
      if (camera_param(c, *s)) camera[name] = v;
      given.insert(name);
      const auto same = std::find_if(merged.begin(), merged.end(), [&key = name](const auto& m) { return m.first == key; });
      if (same != merged.end()) same->second = {v, text.get<std::string>()};
      else merged.push_back({name, {v, text.get<std::string>()}});
    }
    JobValues values;
    std::vector<std::string> words = {"brume"};
    for (const std::string& w : c.cli_words().empty() ? std::vector<std::string>{c.name} : c.cli_words())
      words.push_back(w);
    for (const auto& [name, vt] : merged) {
      values.emplace_back(name, vt.first);
      if (c.spec(name)->kind == ParamKind::boolean) {
        if (vt.first.get<bool>()) words.push_back("--" + name);
      } else {
        words.push_back("--" + name);
        words.push_back(vt.second);
      }
    }
    values.emplace_back("out", json("brume-view.png"));
    words.push_back("--out");
    words.push_back("brume-view.png");
    json job = c.build(values);
    try {
      c.check(job, given, true);
    } catch (const Error& e) {
      throw Refusal(e.what(), mentioned(e.what()));
    }
    // The preview's job: the pixel lengths at the draft's scale (the command and the record keep the values
    // given). Those the job uses: a length the job would ignore (sigma0 with lambda 0) stays its default, which
    // the checks read as not given -- each scaled one is kept only where the command's checks still pass.
    json preview_job = job;
    if (pixel_factor != 1.0)
      for (const ParamSpec& s : c.specs) {
        if (s.unit != "px" || s.block == "depth" || !preview_job.contains(s.block) ||
            !preview_job[s.block].contains(s.name) || !preview_job[s.block][s.name].is_number())
          continue;
        json trial = preview_job;
        trial[s.block][s.name] = preview_job[s.block][s.name].get<double>() * pixel_factor;
        try {
          s.check(trial[s.block][s.name]);
          c.check(trial, given, true);
          preview_job = std::move(trial);
        } catch (const Error&) {  // unused here, or below its lower bound: kept as given
        }
      }
    std::lock_guard<std::mutex> lock(mu);
    use_camera(camera);
    ViewData& d = at(k);
    PreviewFrame f;
    try {
      f = c.preview(preview_job, PreviewInputs{d.rgb, d.measured, d.prep, k, in.rgb.width, in.rgb.height});
    } catch (const Error& e) {
      throw Refusal(e.what(), mentioned(e.what()));
    }
    json plan = std::move(f.plan);
    maps_before = std::move(maps);
    maps = std::move(f.maps);
    std::string line;
    for (const std::string& w : words) line += (line.empty() ? "" : " ") + shell_word(w);
    json record = run_record_header(c.name, words);
    record["job"] = job;
    record["inputs"] = in.record;
    record["preview"] = {{"tool", "brume view"}, {"scale", k}, {"pixel_factor", pixel_factor}};
    return {{"plan", plan},
            {"command", line},
            {"record", record},
            {"width", d.rgb.width},
            {"height", d.rgb.height},
            {"scale", k},
            {"pixel_factor", pixel_factor},
            {"data_version", data_version}};
  }

  // Whether a path (or a request target) begins with /TOKEN/, compared in
  // time independent of where a guess first differs (every byte of the
  // token's length is read), so response times reveal nothing.
  bool has_token(std::string_view path) const {
    const std::string prefix = "/" + token + "/";
    unsigned char diff = path.size() < prefix.size() ? 1 : 0;
    for (std::size_t i = 0; i < prefix.size(); ++i)
      diff |= static_cast<unsigned char>(prefix[i] ^ (i < path.size() ? path[i] : '\0'));
    return diff == 0;
  }

  // Every request: the token first, then Host and Origin, then the rate. (The
  // front has already refused a target without the token; this is the same
  // rule on the decoded path.)
  httplib::Server::HandlerResponse guard(const httplib::Request& req, httplib::Response& res) {
    if (!has_token(req.path)) {
      res.status = 403;
      res.set_content(kNoToken, "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    const std::string host = req.get_header_value("Host");
    const bool host_ok_ = std::find(std::begin(host_ok), std::end(host_ok), host) != std::end(host_ok) && !host.empty();
    bool origin_ok = true;
    if (req.has_header("Origin")) {
      const std::string o = req.get_header_value("Origin");
      origin_ok = o.rfind("http://", 0) == 0 &&
                  std::find(std::begin(host_ok), std::end(host_ok), o.substr(7)) != std::end(host_ok);
    }
    if (!host_ok_ || !origin_ok) {
      res.status = 403;
      res.set_content("forbidden: Host or Origin is not the address brume view serves\n", "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    // At most 600 requests a minute: the page asks for a frame per change.
    const long long t = now_ms();
    if (t - window_start.load() > 60000) {
      window_start.store(t);
      window_count.store(0);
    }
    if (++window_count > 600) {
      res.status = 429;
      res.set_content("too many requests\n", "text/plain");
      return httplib::Server::HandlerResponse::Handled;
    }
    last_request_ms.store(t);
    res.set_header("Cache-Control", "no-store");
    res.set_header("X-Content-Type-Options", "nosniff");
    res.set_header("Referrer-Policy", "no-referrer");
    res.set_header("X-Frame-Options", "DENY");
    res.set_header("Content-Security-Policy",
                   "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; frame-ancestors 'none'");
    return httplib::Server::HandlerResponse::Unhandled;
  }

  void routes(httplib::Server& s) {
    const std::string p = "/" + token + "/";
    s.set_pre_routing_handler([this](const httplib::Request& q, httplib::Response& r) { return guard(q, r); });
    // The front bounds bodies, keep-alive and the requests per connection
    // (FrontLimits); these only set what cpp-httplib writes in its headers.
    s.set_payload_max_length(1 << 20);
    s.set_keep_alive_max_count(100);
    s.set_keep_alive_timeout(1);
    // No exception's text in a response (cpp-httplib's default puts it in an
    // EXCEPTION_WHAT header): printed here, a plain 500 there.
    s.set_exception_handler([](const httplib::Request&, httplib::Response& r, std::exception_ptr ep) {
      try {
        if (ep) std::rethrow_exception(ep);
      } catch (const std::exception& e) {
        std::fprintf(stderr, "brume view: %s\n", e.what());
      } catch (...) {
      }
      r.status = 500;
      r.set_content("internal error (brume view printed it)\n", "text/plain");
    });
    s.Get(p, [](const httplib::Request&, httplib::Response& r) {
      r.set_content(view::web::view_html, "text/html; charset=utf-8");
    });
    s.Get(p + "view.js", [](const httplib::Request&, httplib::Response& r) {
      r.set_content(view::web::view_js, "text/javascript; charset=utf-8");
    });
    s.Get(p + "render.js", [](const httplib::Request&, httplib::Response& r) {
      r.set_content(view::web::render_js, "text/javascript; charset=utf-8");
    });
    s.Get(p + "meta.json", [this](const httplib::Request&, httplib::Response& r) {
      r.set_content(meta().dump(), "application/json");
    });
    for (const char* what : {"image", "range", "sky"}) {
      const std::string w = what;
      s.Get(p + w + ".bin", [this, w](const httplib::Request& q, httplib::Response& r) {
        // Digits only, at most two, before anything is converted ("4294967298" and "2x" are 400).
        int k = 1;
        if (q.has_param("scale")) {
          const std::string v = q.get_param_value("scale");
          const bool digits = !v.empty() && v.size() <= 2 && std::all_of(v.begin(), v.end(), [](char ch) {
            return ch >= '0' && ch <= '9';
          });
          k = digits ? std::stoi(v) : 0;
        }
        if (k < 1 || k > 64) {
          r.status = 400;
          return;
        }
        std::lock_guard<std::mutex> lock(mu);
        ViewData& d = at(k);
        r.set_content(w == "image" ? d.rgba : w == "range" ? d.range : d.sky, "application/octet-stream");
      });
    }
    // A map of the last frames (PreviewFrame::maps), its shape in X-Brume-Shape.
    s.Get(p + "data.bin", [this](const httplib::Request& q, httplib::Response& r) {
      const std::string name = q.get_param_value("name");
      std::lock_guard<std::mutex> lock(mu);
      const Image* found = nullptr;
      for (const auto* ms : {&maps, &maps_before})
        if (const auto it = ms->find(name); it != ms->end() && !found) found = &it->second;
      if (!found) {
        r.status = 404;
        return;
      }
      const Image& m = *found;
      // Sent as its texture holds it: 3 channels padded to RGBA (alpha 1).
      const int tc = m.channels == 3 ? 4 : m.channels;
      std::vector<float> v(m.pixels() * tc, 1.0f);
      for (std::size_t i = 0; i < m.pixels(); ++i)
        for (int ch = 0; ch < m.channels; ++ch) v[i * tc + ch] = m.data[i * m.channels + ch];
      r.set_header("X-Brume-Shape", std::to_string(m.width) + " " + std::to_string(m.height) + " " + std::to_string(tc));
      r.set_content(floats(v), "application/octet-stream");
    });
    s.Post(p + "frame", [this](const httplib::Request& q, httplib::Response& r) {
      // brume's own messages go back (they name the flag and the rule); no
      // other exception's text does (a JSON library's, an allocator's).
      auto refuse = [&](int status, const std::string& message) {
        r.status = status;
        r.set_content(json{{"error", message}}.dump(-1, ' ', false, json::error_handler_t::replace),
                      "application/json");
      };
      if (const std::size_t bad = first_invalid_utf8(q.body); bad != std::string::npos)
        return refuse(400,
                      "the frame request is not UTF-8 text (an invalid byte at offset " + std::to_string(bad) + ")");
      const json body = json::parse(q.body, nullptr, /*allow_exceptions=*/false);
      if (body.is_discarded()) return refuse(400, "the frame request is not JSON: {\"values\": {name: text}}");
      // The page asks for a value's refusal as an answer of its own ("refusal": "inline": 200 with
      // {"refused": {"param", "message"}}), so that a value the table refuses is shown beside its field and no
      // failed request reaches the browser's console; other clients get the 400.
      const bool inline_refusal = body.is_object() && body.value("refusal", json("")) == json("inline");
      try {
        r.set_content(frame(body).dump(-1, ' ', false, json::error_handler_t::replace), "application/json");
      } catch (const Refusal& e) {
        if (!inline_refusal) return refuse(400, e.what());
        r.set_content(json{{"refused", {{"param", e.param}, {"message", e.what()}}}}.dump(
                          -1, ' ', false, json::error_handler_t::replace),
                      "application/json");
      } catch (const Error& e) {
        refuse(400, e.what());
      } catch (const json::exception&) {
        refuse(400, "the frame request is malformed: {\"values\": {name: text}, \"scale\": k}");
      } catch (const std::exception& e) {
        std::fprintf(stderr, "brume view: frame: %s\n", e.what());
        refuse(500, "internal error (brume view printed it)");
      }
    });
  }
};

// cpp-httplib's request parsing and routing, on a request the front read
// whole (process_request is its entry point for one request on a stream).
struct RouteServer : httplib::Server {
  using httplib::Server::process_request;
};

// One complete request, from memory; the response goes out through the
// front's writer.
class RequestStream final : public httplib::Stream {
 public:
  RequestStream(const std::string& in, const view::FrontPeer& peer, const view::FrontWrite& out)
      : in_(in), peer_(peer), out_(out) {}
  bool is_readable() const override { return at_ < in_.size(); }
  bool is_writable() const override { return !failed_; }
  ssize_t read(char* ptr, size_t size) override {
    const std::size_t n = std::min(size, in_.size() - at_);
    std::memcpy(ptr, in_.data() + at_, n);
    at_ += n;
    return static_cast<ssize_t>(n);
  }
  ssize_t write(const char* ptr, size_t size) override {
    if (failed_ || !out_(ptr, size)) {
      failed_ = true;
      return -1;
    }
    return static_cast<ssize_t>(size);
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = peer_.remote_ip;
    port = peer_.remote_port;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    ip = peer_.local_ip;
    port = peer_.local_port;
  }
  // Only compared with FD_SETSIZE by cpp-httplib (its select() guard); the
  // front does the socket's I/O.
  socket_t socket() const override { return 0; }
  bool failed() const { return failed_; }

 private:
  const std::string& in_;
  std::size_t at_ = 0;
  const view::FrontPeer& peer_;
  const view::FrontWrite& out_;
  bool failed_ = false;
};

json run_view_job(const ViewJob& job, const ExecOptions&, const RunContext& ctx) {
#if !BRUME_HAVE_GPU
  (void)job;
  (void)ctx;
  throw Error("brume view serves the GPU passes' shaders, which this brume was built without (no EGL/GLES 3 headers "
              "at build time); rebuild with libegl-dev libgles-dev");
#endif
  const CommandDef* c = find_command(job.view.effect);
  if (!c || !c->preview)
    throw Error("--effect '" + job.view.effect + "': its preview is not built yet (" +
                command_names([](const CommandDef& d) { return static_cast<bool>(d.preview); }) + " have one)");
  Server sv(*c, job.prepare, ctx.given);
  // The command line's input and preparation flags go into the effect's job,
  // paths made absolute, so that the copied command and the record run from
  // any directory.
  json vj = view_job_table().to_json(job);
  for (const Param<ViewJob>& d : view_job_table().params()) {
    const ParamSpec& s = d.spec;
    if (!ctx.given.count(s.name) || s.block == "view") continue;
    if (!c->spec(s.name)) throw Error("--" + s.name + " is not a flag of " + c->name + ", which the view shows");
    json& v = vj.at(s.block).at(s.name);
    std::error_code ec;
    if (s.kind == ParamKind::text && v.is_string() && !v.get<std::string>().empty() &&
        fs::exists(v.get<std::string>(), ec))
      v = fs::absolute(v.get<std::string>()).lexically_normal().string();
    sv.cli_values.emplace_back(s.name, v);
  }
  {
    JobValues iv = sv.cli_values;
    iv.emplace_back("out", json("brume-view.png"));
    // Each flag's type and range before any file is read; the command's
    // cross-field checks (dof's required --focus-distance) wait for the
    // page's values, and their messages are shown there.
    c->check(c->build(iv), ctx.given, false);
  }
  ViewJob absolute;
  view_job_table().from_json(absolute, vj, "job");
  sv.files = absolute.input;
  if (absolute.input.depth.fused())  // the preview's drafts are shrunk frames; the fusion is full-size
    throw Error("--stereo-right beside another depth source is fused by the completion, which the "
                "preview does not run; fuse first (brume depth complete ... --stereo-right R --out fused.exr) and "
                "view --range fused.exr, or drop one of the two sources");
  sv.in = load_inputs(absolute.input, true);  // the record's inputs by absolute path, as the command's
  // The scene the page starts on (brume/preview.hpp): the measured range's
  // statistics, and whether the command line gave the camera.
  bool camera_given = true;
  try {
    (void)depth_camera(absolute.input.depth, sv.in.rgb.width, sv.in.rgb.height);
  } catch (const Error&) {
    camera_given = false;
  }
  sv.scene = preview_scene(sv.in.depth.range, camera_given);

  // Bound here, served by the front (http_front.hpp); cpp-httplib parses and
  // routes the complete requests it hands on.
  const bool loopback = job.view.listen.empty();
  const std::string addr = loopback ? "127.0.0.1" : job.view.listen;
  std::string bind_error;
  const int fd4 = view::listen_socket(addr, job.view.port, bind_error);
  if (fd4 < 0) {
    if (job.view.port == 0) throw Error("--listen '" + addr + "': cannot bind a port there (" + bind_error + ")");
    throw Error("--port " + std::to_string(job.view.port) + ": cannot bind " + addr + ":" +
                std::to_string(job.view.port) + " (" + bind_error + "); use --port 0 for a free one");
  }
  sv.port = view::socket_port(fd4);
  const std::string ps = std::to_string(sv.port);
  sv.host_ok[0] = "127.0.0.1:" + ps;
  sv.host_ok[1] = "[::1]:" + ps;
  sv.host_ok[2] = "localhost:" + ps;
  sv.host_ok[3] = (addr.find(':') != std::string::npos ? "[" + addr + "]" : addr) + ":" + ps;
  std::vector<int> listeners = {fd4};
  if (loopback) {  // where the host has IPv6 loopback
    std::string e6;
    if (const int fd6 = view::listen_socket("::1", sv.port, e6); fd6 >= 0) listeners.push_back(fd6);
  }
  const bool v6 = listeners.size() == 2;

  // Explicit handlers: a background job of a shell inherits SIGINT ignored.
  struct sigaction sa {};
  sa.sa_handler = on_view_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  signal(SIGPIPE, SIG_IGN);

  RouteServer routes;
  sv.routes(routes);
  view::HttpFront front(
      std::move(listeners), view::FrontLimits{}, [&sv](std::string_view target) { return sv.has_token(target); },
      kNoToken,
      [&routes](const std::string& request, bool last, const view::FrontPeer& peer, const view::FrontWrite& write) {
        RequestStream strm(request, peer, write);
        bool closed = false;
        const bool ok = routes.process_request(strm, last, closed, nullptr);
        return ok && !closed && !strm.failed();
      });
  sv.last_request_ms.store(Server::now_ms());
  front.start();
  std::fprintf(stderr, "brume view: %s on http://%s/%s/  (Ctrl-C to stop)\n", c->name.c_str(), sv.host_ok[loopback ? 0 : 3].c_str(),
               sv.token.c_str());
  if (loopback && !v6)
    std::fprintf(stderr, "brume view: [::1]:%d not bound (no IPv6 loopback here, or the port is taken there): "
                 "open the 127.0.0.1 URL, not localhost\n", sv.port);
  std::fflush(stderr);
  const double idle_ms = job.view.idle_exit_min * 60000.0;
  std::string why;
  while (why.empty()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (int sig = g_signal.load()) why = sig == SIGINT ? "SIGINT" : "SIGTERM";
    else if (idle_ms > 0 && static_cast<double>(Server::now_ms() - sv.last_request_ms.load()) > idle_ms)
      why = "idle for " + ParamSpec{}.format(json(job.view.idle_exit_min)) + " min";
  }
  front.stop();
  std::fprintf(stderr, "brume view: stopped (%s)\n", why.c_str());
  return json::object();
}

}  // namespace

CommandDef view_command() {
  CommandDef c = make_command<ViewJob>({
      .name = "view",
      .cli = "view",
      .summary = "a live preview in the browser: the effect's GPU passes in WebGL2, its controls from its table",
      .table = &view_job_table(),
      .run = &run_view_job,
      .report = [](const ViewJob&, const json&) {},  // its lines are printed as it serves
  });
  return c;
}

}  // namespace brume
