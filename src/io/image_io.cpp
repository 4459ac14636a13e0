// brume — reading image and range-map files: the table of formats
// (io/formats/format.hpp) picks a row by the file's first bytes; what no row
// takes goes to OpenImageIO, in the module loaded on first use
// (io/codec.hpp). Values: integer files give the count times 1/(2^bits - 1)
// (or, for read_scalar, the counts), float files their values; read_color
// then applies the transfer (brume/io.hpp).
#include <omp.h>
#include <unistd.h>

#include <openssl/evp.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/text.hpp"
#include "io/codec.hpp"
#include "io/formats/exr.hpp"
#include "io/formats/format.hpp"
#include "io/io_internal.hpp"
#include "io/srgb.hpp"

namespace brume {

const EnumNames<Transfer>& transfer_names() {
  static const EnumNames<Transfer> n = {{Transfer::automatic, "auto"}, {Transfer::srgb, "srgb"}, {Transfer::linear, "linear"}};
  return n;
}

namespace fs = std::filesystem;

Transfer parse_transfer(const std::string& s, const std::string& flag) { return parse_enum(transfer_names(), s, flag); }
std::string to_string(Transfer t) {
  if (t == Transfer::gamma) return "gamma";
  if (t == Transfer::table) return "table";
  return enum_name(transfer_names(), t);
}

// ---- transfers with a parameter (gamma:G, table:FILE) -----------------------------------
namespace {
constexpr double kMaxGamma = 10.0;
constexpr std::size_t kMaxTableEntries = 65536;  // one entry per 16-bit code

std::string transfer_fix() {
  return "allowed: auto, srgb, linear, gamma:G (0 < G <= 10, e.g. gamma:2.2) or table:FILE (a camera response: "
         "N >= 2 non-decreasing linear values at equally spaced codes from 0 to 1)";
}

std::vector<double> read_transfer_table(const std::string& path, const std::string& flag, const std::string& text) {
  const std::string what = flag + " table:";
  std::string body;
  try {
    body = read_input_file(path, what, {4u << 20, "a transfer table is at most 65536 numbers"});
  } catch (const Error& e) {
    throw Error(std::string(e.what()) + " (" + flag + " '" + text + "')");
  }
  std::vector<double> v;
  std::istringstream lines(body);
  std::string line;
  int line_no = 0;
  while (std::getline(lines, line)) {
    ++line_no;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    for (char& c : line)
      if (c == ',' || c == ';' || c == '\t' || c == '\r') c = ' ';
    std::istringstream items(line);
    std::string item;
    while (items >> item) {
      double x = 0.0;
      if (!text::parse_number(item, x) || !std::isfinite(x))
        throw Error(flag + " '" + text + "': line " + std::to_string(line_no) + " of '" + path + "' holds '" +
                    item + "', not a finite number; a transfer table is numbers only (the linear values "
                    "at equally spaced codes from 0 to 1), with '#' comments");
      if (v.size() == kMaxTableEntries)
        throw Error(flag + " '" + text + "': '" + path + "' holds more than " + std::to_string(kMaxTableEntries) +
                    " values; a transfer table has one per code at most (65536 for 16-bit files)");
      v.push_back(x);
    }
  }
  if (v.size() < 2)
    throw Error(flag + " '" + text + "': '" + path + "' holds " + std::to_string(v.size()) + " value" +
                (v.size() == 1 ? "" : "s") + "; a transfer table needs at least 2 (the linear values at codes 0 "
                "and 1, and any number equally spaced between)");
  for (std::size_t i = 1; i < v.size(); ++i)
    if (v[i] < v[i - 1])
      throw Error(flag + " '" + text + "': '" + path + "' decreases at entry " + std::to_string(i) + " (" +
                  text::g(v[i - 1]) + " then " + text::g(v[i]) +
                  "); a camera's response is non-decreasing: fix the table (entry i is the linear value at code "
                  "i / (N - 1))");
  return v;
}
}  // namespace

double TransferFunction::apply(double v) const {
  if (kind == Transfer::gamma) return v < 0.0 ? -std::pow(-v, gamma) : std::pow(v, gamma);
  if (kind != Transfer::table) return v;
  const std::size_t n = table.size();
  const double x = v * static_cast<double>(n - 1);
  const double i0 = std::floor(x);
  const std::size_t i = static_cast<std::size_t>(std::clamp(i0, 0.0, static_cast<double>(n - 2)));
  const double f = x - static_cast<double>(i);
  return f == 0.0 ? table[i] : table[i] + f * (table[i + 1] - table[i]);
}

TransferFunction parse_transfer_function(const std::string& text, const std::string& flag) {
  for (const auto& [e, n] : transfer_names())
    if (text == n) return TransferFunction(e);
  const auto colon = text.find(':');
  const std::string head = text.substr(0, colon), arg = colon == std::string::npos ? "" : text.substr(colon + 1);
  TransferFunction t;
  if (head == "gamma" && colon != std::string::npos) {
    double g = 0.0;
    if (!text::parse_number(arg, g) || !(g > 0.0 && g <= kMaxGamma))
      throw Error(flag + " '" + text + "': the gamma must be a number in (0, 10] (linear = v^G: 2.2 for a "
                  "plain 1/2.2 encoding, 1 for linear); " + transfer_fix());
    if (g == 1.0) return TransferFunction(Transfer::linear);  // v^1: the linear read, bit for bit
    t.kind = Transfer::gamma;
    t.gamma = g;
    return t;
  }
  if (head == "table" && colon != std::string::npos) {
    if (arg.empty())
      throw Error(flag + " '" + text + "' names no file; " + transfer_fix());
    t.kind = Transfer::table;
    t.table_path = arg;
    t.table = read_transfer_table(arg, flag, text);
    t.table_sha256 = sha256_file(arg);
    return t;
  }
  throw Error(flag + " '" + text + "' is not allowed; " + transfer_fix());
}

std::string transfer_help() {
  return "auto (integer files sRGB, float files linear), srgb, linear, gamma:G (linear = v^G, 0 < G <= 10, e.g. "
         "gamma:2.2 for a plain 1/2.2 encoding) or table:FILE (a camera's measured response: N >= 2 non-decreasing "
         "linear values at equally spaced codes from 0 to 1, linear between; docs/conventions.md)";
}

std::string to_string(const TransferFunction& t) {
  // The shortest text that reads back as the same double (JSON's): records repeat.
  if (t.kind == Transfer::gamma) return "gamma:" + nlohmann::json(t.gamma).dump();
  if (t.kind == Transfer::table) return "table:" + t.table_path;
  return to_string(t.kind);
}

namespace {
thread_local int t_io_threads = 0;  // an IoThreads scope's count (0: none)
thread_local const char* t_last_reader = "";
thread_local const char* t_last_writer = "";
}  // namespace

IoThreads::IoThreads(int n) : outer_(t_io_threads) { t_io_threads = n > 0 ? n : 0; }
IoThreads::~IoThreads() { t_io_threads = outer_; }

namespace io {
// The scope's count (--threads), else OpenMP's (the cores, or OMP_NUM_THREADS).
int io_threads() { return t_io_threads > 0 ? t_io_threads : omp_get_max_threads(); }
const char* last_reader() { return t_last_reader; }
const char* last_writer() { return t_last_writer; }
void note_reader(const char* row) { t_last_reader = row; }
void note_writer(const char* row) { t_last_writer = row; }
}  // namespace io

namespace {
// A regular file (not a directory, device or FIFO: brume/io.hpp), before a
// codec opens it by name.
void check_readable(const std::string& path) { check_input_file(path, ""); }

// The file opened by OpenImageIO (its header parsed), or an error naming it.
// A file with OpenEXR's magic reaches it only after the OpenEXR row, whose
// every open runs the attribute guard first (io/formats/exr.hpp).
std::unique_ptr<codec::Input> open_image(const std::string& path) {
  check_readable(path);
  std::string e;
  auto in = codec::api("reading '" + path + "'").open_input(path, false, &e);
  if (!in) throw Error("cannot read '" + path + "': " + (e.empty() ? "unknown or unsupported image format" : e));
  return in;
}

}  // namespace

ImageHeader read_header(const std::string& path) {
  check_readable(path);
  if (const io::Format* f = io::format_of_file(path)) {
    io::Header h;
    if (f->header(path, h)) {
      check_declared_size(path, h.width, h.height, h.channels);
      return {h.width, h.height, h.channels, f->name};
    }
  }
  auto in = open_image(path);
  const codec::InputSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.channels <= 0) throw Error("cannot read '" + path + "': empty image");
  check_declared_size(path, spec.width, spec.height, spec.channels);
  return {spec.width, spec.height, spec.channels, spec.format};
}

namespace {

// What a reader asks for: the values (the count over 2^bits - 1 for integer
// files), the counts themselves (read_scalar), or the values decoded from
// sRGB where a row can do that during its decode (per count: bit for bit
// what decoding them after gives); with_alpha keeps alpha unassociated.
enum class Want { values, counts, srgb_linear, with_alpha };

// Every channel of the first subimage as float, by the file's row or else
// OpenImageIO. `name` names the file in messages; `extra`: the channels of
// the caller's copy, for the memory check before any allocation.
io::Decoded decode(const std::string& path, const std::string& name, Want want, int extra, float pad = 0.0f,
                   const TransferFunction* curve = nullptr) {
  const auto check_size = [&](int w, int h, int c) {
    check_declared_size(path, w, h, c);
    const std::uint64_t px = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
    check_memory(px * 4 * static_cast<std::uint64_t>(c + extra), "reading " + name);
  };
  io::Decoded d;
  if (const io::Format* f = io::format_of_file(path)) {
    io::ReadRequest req;
    req.path = path;
    req.check = check_size;
    if (want == Want::counts)
      req.map = [](float v, int bits) { return static_cast<float>(std::nearbyint(v * (std::ldexp(1.0, bits) - 1.0))); };
    if (want == Want::srgb_linear) req.map = [](float v, int) { return srgb_to_linear(v); };
    // A gamma or table of the count's exact value (the float value is its nearest float).
    if (want == Want::values && curve)
      req.map = [curve](float v, int bits) {
        const double max = std::ldexp(1.0, bits) - 1.0;
        return static_cast<float>(curve->apply(std::nearbyint(v * max) / max));
      };
    req.with_alpha = want == Want::with_alpha;
    req.threads = std::min(io::io_threads(), 64);
    req.pad = pad;
    if (f->read(req, d)) {
      io::note_reader(f->name);
      d.info.path = path;
      return d;
    }
    d = {};
  }
  std::string e;  // (an OpenEXR file has passed the row's attribute guard: open_image)
  auto in = codec::api("reading " + name).open_input(path, want == Want::with_alpha, &e);
  if (!in) throw Error("cannot read " + name + ": " + (e.empty() ? "unknown or unsupported image format" : e));
  const codec::InputSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.channels <= 0) throw Error("cannot read " + name + ": empty image");
  check_size(spec.width, spec.height, spec.channels);  // refused before any allocation: the header decides
  d.img = Image(spec.width, spec.height, spec.channels);
  if (!in->read_float(d.img.data.data())) {
    e = in->error();
    throw Error("cannot read " + name + ": " + (e.empty() ? "read failed (truncated or corrupt file?)" : e));
  }
  in->close();
  io::note_reader("oiio");
  d.info.path = path;
  d.info.format = spec.format;
  d.info.integer = !spec.floating;
  d.info.bits = spec.bits_per_sample > 0 ? spec.bits_per_sample : spec.container_bits;
  d.info.channel_names = spec.channel_names;
  d.info.description = spec.description;
  d.alpha = spec.alpha_channel;
  d.unassociated = spec.unassociated_alpha;
  if (want == Want::with_alpha) return d;
  const int container = spec.container_bits;
  const int stored = std::min(d.info.bits, container);
  if (d.info.integer && stored < container && container <= 16) {
    // Fewer bits than the container (a 12-bit TIFF in 16 bits): OpenImageIO
    // widens a count k by bit replication ((k << 4) | (k >> 8)), so the float
    // it returns is not k/4095 (2048 reads as 0.500114, not 0.500122). The top
    // `stored` bits of the widened count are k — also for readers that scale
    // by 65535/4095 instead — and k/(2^stored − 1) is the true value.
    const double wide = std::ldexp(1.0, container) - 1.0, narrow = std::ldexp(1.0, stored) - 1.0;
    const int shift = container - stored;
    for (float& v : d.img.data) {
      const auto k = static_cast<std::uint32_t>(std::nearbyint(v * wide)) >> shift;
      v = static_cast<float>(k / narrow);
    }
  }
  if (want == Want::counts && d.info.integer) {
    // Counts of the stored bit depth: a 12-bit depth map's 4095 is 4095.
    const double maxval = std::ldexp(1.0, stored) - 1.0;
    for (float& v : d.img.data) v = static_cast<float>(std::nearbyint(v * maxval));
  }
  return d;
}

std::string channel_list(const std::vector<std::string>& names) {
  std::string all;
  for (const std::string& n : names) all += (all.empty() ? "" : ", ") + n;
  return all;
}

}  // namespace

ChannelImage read_unassociated(const std::string& path, const std::string& what) {
  const std::string name = what + " '" + path + "'";
  check_input_file(path, what);
  io::Decoded d = decode(path, name, Want::with_alpha, 4);  // and the caller's RGBA copy
  return {std::move(d.img), std::move(d.info), d.alpha, d.unassociated};
}

// ---- layers --------------------------------------------------------------------------
namespace {

std::string lower(std::string t) {
  for (char& c : t) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return t;
}
// "ViewLayer.Depth.Z" -> "Z" and "ViewLayer.Depth"; "R" -> "R" and "".
std::string last_component(const std::string& n) {
  const auto d = n.rfind('.');
  return d == std::string::npos ? n : n.substr(d + 1);
}
std::string prefix_of(const std::string& n) {
  const auto d = n.rfind('.');
  return d == std::string::npos ? std::string() : n.substr(0, d);
}
std::string join(const std::string& prefix, const std::string& c) { return prefix.empty() ? c : prefix + "." + c; }

// A colour layer found in a file: the part and the channels to read.
struct FoundLayer {
  std::string name;  // what the user names it by (a prefix, or a part's name for its plain R, G, B)
  int part = 0;
  std::vector<std::string> colour;  // R, G, B (or one grey channel)
  std::string alpha;                // empty: none
};

// The colour layers of every part (colour_layers), with their channels.
std::vector<FoundLayer> found_layers(const io::ExrLayout& L) {
  std::vector<FoundLayer> out;
  for (std::size_t p = 0; p < L.parts.size(); ++p) {
    const auto& ch = L.parts[p].channels;
    for (const std::string& prefix : colour_layers(ch)) {
      FoundLayer f;
      f.part = static_cast<int>(p);
      f.name = prefix.empty() && L.multipart ? L.parts[p].name : prefix;
      const auto has = [&](const char* c) { return std::find(ch.begin(), ch.end(), join(prefix, c)) != ch.end(); };
      if (has("R")) f.colour = {join(prefix, "R"), join(prefix, "G"), join(prefix, "B")};
      else f.colour = {join(prefix, "red"), join(prefix, "green"), join(prefix, "blue")};
      if (has("A")) f.alpha = join(prefix, "A");
      else if (has("alpha")) f.alpha = join(prefix, "alpha");
      out.push_back(std::move(f));
    }
  }
  return out;
}

std::string quoted_list(const std::vector<std::string>& names) {
  std::string all;
  for (const std::string& n : names) all += (all.empty() ? "" : ", ") + (n.empty() ? std::string("(unnamed)") : n);
  return all;
}

// Every channel of a layout, qualified by its part's name in a multi-part file.
std::vector<std::string> all_channels(const io::ExrLayout& L) {
  std::vector<std::string> all;
  for (const auto& p : L.parts)
    for (const std::string& c : p.channels)
      all.push_back(L.multipart && !p.name.empty() && c.rfind(p.name + ".", 0) != 0 ? p.name + "." + c : c);
  return all;
}

// The layout of an OpenEXR file, or false for any other file (and for a
// file OpenEXR's headers cannot be read from: the row's read then says why).
bool layout_of(const std::string& path, io::ExrLayout& L) {
  try {
    return io::exr_layout(path, L);
  } catch (const Error&) {
    return false;
  }
}

// A file with layers, or a multi-part one: read by name.
bool layered(const io::ExrLayout& L) { return L.multipart || !plain_channels(L.parts.front().channels); }

FoundLayer choose_layer(const std::string& path, const io::ExrLayout& L, const ColorRead& how) {
  const std::vector<FoundLayer> found = found_layers(L);
  std::vector<std::string> names;
  for (const auto& f : found) names.push_back(f.name);
  if (!how.layer.empty()) {
    std::vector<FoundLayer> match;
    for (const auto& f : found)
      if (f.name == how.layer) match.push_back(f);
    if (match.empty()) {
      // A layer of grey (NAME.Y) named explicitly.
      for (std::size_t p = 0; p < L.parts.size(); ++p) {
        const auto& ch = L.parts[p].channels;
        const bool part_named = L.multipart && L.parts[p].name == how.layer;
        const std::string prefix = part_named ? "" : how.layer;
        if (!part_named && std::find(ch.begin(), ch.end(), join(prefix, "Y")) == ch.end()) continue;
        if (std::find(ch.begin(), ch.end(), join(prefix, "Y")) == ch.end()) continue;
        FoundLayer f;
        f.name = how.layer;
        f.part = static_cast<int>(p);
        f.colour = {join(prefix, "Y")};
        if (std::find(ch.begin(), ch.end(), join(prefix, "A")) != ch.end()) f.alpha = join(prefix, "A");
        match.push_back(f);
      }
    }
    if (match.size() == 1) return match.front();
    if (match.size() > 1)
      throw Error(how.layer_flag + " '" + how.layer + "' names " + std::to_string(match.size()) + " layers of '" +
                  path + "' (in several of its parts); brume cannot tell them apart: extract one first (oiiotool " +
                  "IN --subimage N -o OUT)");
    throw Error("'" + path + "' has no colour layer named '" + how.layer + "'" +
                (names.empty() ? std::string("; it has no colour layer at all (no NAME.R, NAME.G, NAME.B)")
                               : "; its colour layers are: " + quoted_list(names)) +
                " (its channels: " + quoted_list(all_channels(L)) + "); give one of them to " + how.layer_flag);
  }
  if (found.size() == 1) return found.front();
  if (found.empty())
    throw Error("'" + path + "' holds no colour layer (no R, G, B or NAME.R, NAME.G, NAME.B); its channels are: " +
                quoted_list(all_channels(L)) + ". Give a colour image, or extract three channels as R, G, B first "
                "(oiiotool IN --ch R=NAME.X,G=NAME.Y,B=NAME.Z -o OUT)");
  throw Error("'" + path + "' holds " + std::to_string(found.size()) + " colour layers (" + quoted_list(names) +
              ") and none was named; say which is the image with " + how.layer_flag + " NAME (a render's beauty "
              "pass: Blender's is ViewLayer.Combined)");
}

// The plain path's channel names read as colour (and alpha).
std::vector<std::string> plain_colour_channels(const FileInfo& info, int channels, int alpha) {
  std::vector<std::string> n = info.channel_names;
  std::vector<std::string> read;
  const auto name = [&](int c) { return c < static_cast<int>(n.size()) ? n[static_cast<std::size_t>(c)] : "channel" + std::to_string(c); };
  if (channels >= 3) read = {name(0), name(1), name(2)};
  else read = {name(0)};
  if (alpha >= 0) read.push_back(name(alpha));
  return read;
}

}  // namespace

bool is_depth_pass_name(const std::string& c) {
  if (c == "Z") return true;
  const std::string last = last_component(c);
  if (lower(last) == "depth") return true;
  return last == "Z" && lower(last_component(prefix_of(c))) == "depth";
}

bool is_mist_pass_name(const std::string& c) {
  std::string rest = prefix_of(c);
  while (!rest.empty()) {
    if (lower(last_component(rest)) == "mist") return true;
    rest = prefix_of(rest);
  }
  return false;
}

std::vector<std::string> colour_layers(const std::vector<std::string>& channels) {
  std::vector<std::string> prefixes;
  for (const std::string& c : channels) {
    const std::string p = prefix_of(c);
    if (std::find(prefixes.begin(), prefixes.end(), p) == prefixes.end()) prefixes.push_back(p);
  }
  std::vector<std::string> out;
  for (const std::string& p : prefixes) {
    const auto has = [&](const char* c) { return std::find(channels.begin(), channels.end(), join(p, c)) != channels.end(); };
    if ((has("R") && has("G") && has("B")) || (has("red") && has("green") && has("blue"))) out.push_back(p);
  }
  return out;
}

bool plain_channels(const std::vector<std::string>& channels) {
  if (channels.size() == 1) return true;
  std::vector<std::string> s = channels;
  std::sort(s.begin(), s.end());
  using V = std::vector<std::string>;
  return s == V{"B", "G", "R"} || s == V{"A", "B", "G", "R"} || s == V{"Y"} || s == V{"A", "Y"};
}

ExrChannels exr_channels(const std::string& path) {
  ExrChannels out;
  io::ExrLayout L;
  if (!io::exr_layout(path, L)) return out;
  out.exr = true;
  out.multipart = L.multipart;
  out.blender = L.blender;
  if (!L.multipart) {
    out.names = L.parts.front().channels;
    out.bits = L.parts.front().bits;
  }
  return out;
}

namespace {
// The named channels of one part of an OpenEXR file, its declared size and
// the memory checked before anything is allocated (`extra`: the channels of
// the caller's own copies); a channel the part lacks reads as `missing`.
io::Decoded decode_exr_channels(const std::string& path, int part, const std::vector<std::string>& names,
                                float missing, int extra) {
  io::ReadRequest req;
  req.path = path;
  req.threads = std::min(io::io_threads(), 64);
  req.check = [&](int w, int h, int c) {
    check_declared_size(path, w, h, c);
    check_memory(static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h) * 4 *
                     static_cast<std::uint64_t>(c + extra),
                 "reading '" + path + "'");
  };
  io::Decoded d;
  io::exr_read_channels(req, part, names, missing, d);
  return d;
}
}  // namespace

Image read_exr_channels(const std::string& path, const std::vector<std::string>& names) {
  return std::move(decode_exr_channels(path, 0, names, 0.0f, 0).img);
}

Image read_color(const std::string& path, Transfer transfer, FileInfo* info) {
  ColorRead how;
  how.transfer = transfer;
  return read_color(path, how, info, nullptr);
}

namespace {
bool is_curve(const TransferFunction& t) { return t.kind == Transfer::gamma || t.kind == Transfer::table; }

// A gamma or table transfer on the colour channels of `s` (channel `alpha_ch`
// untouched; -1: none), for the values a row did not map during its decode
// (float files; integer files with alpha, which OpenImageIO reads associated:
// the curve then meets the associated values, as the sRGB decode does). A
// table says nothing outside [0, 1]: a value there is refused.
void apply_curve(Image& s, const TransferFunction& t, int alpha_ch, const std::string& path) {
  const int C = s.channels;
  if (t.kind == Transfer::table) {
    for (std::size_t i = 0; i < s.pixels(); ++i)
      for (int k = 0; k < C; ++k) {
        const float v = s.data[i * C + k];
        if (k == alpha_ch || !std::isfinite(v) || (v >= 0.0f && v <= 1.0f)) continue;
        throw Error("'" + path + "' holds " + text::g(v) + " at x " + std::to_string(i % s.width) + ", y " +
                    std::to_string(i / s.width) + ", channel " + std::to_string(k) + ", outside [0, 1], where the "
                    "transfer table:" + t.table_path + " says nothing (its entries are the linear values at codes "
                    "0 to 1); a float file is usually linear already: use the transfer linear or auto, or gamma:G");
      }
  }
  for (std::size_t i = 0; i < s.pixels(); ++i)
    for (int k = 0; k < C; ++k) {
      if (k == alpha_ch) continue;
      float& v = s.data[i * C + k];
      if (std::isfinite(v)) v = static_cast<float>(t.apply(v));
    }
}
}  // namespace

Image read_color(const std::string& path, const ColorRead& how, FileInfo* info, Image* alpha) {
  check_readable(path);
  const TransferFunction& transfer = how.transfer;
  if (alpha) *alpha = Image();
  io::ExrLayout L;
  const bool exr = layout_of(path, L);
  if (exr && layered(L) && (how.rule == LayerRule::names || !how.layer.empty())) {
    const FoundLayer f = choose_layer(path, L, how);
    std::vector<std::string> names = f.colour;
    if (!f.alpha.empty()) names.push_back(f.alpha);
    io::Decoded d = decode_exr_channels(path, f.part, names, 0.0f, 3);
    io::note_reader("openexr");
    d.info.path = path;
    d.info.layer = f.name;
    d.info.channel_rule = how.layer.empty() ? "the file's one colour layer" : "named by " + how.layer_flag;
    const TransferFunction t = transfer == Transfer::automatic ? TransferFunction(Transfer::linear) : transfer;
    d.info.transfer = t;
    if (is_curve(t)) apply_curve(d.img, t, f.alpha.empty() ? -1 : d.img.channels - 1, path);
    const Image& s = d.img;
    const int C = s.channels, grey = static_cast<int>(f.colour.size()) == 1;
    Image out(s.width, s.height, 3);
    for (std::size_t i = 0; i < s.pixels(); ++i)
      for (int k = 0; k < 3; ++k) {
        const float v = s.data[i * C + (grey ? 0 : k)];
        out.data[i * 3 + k] = t == Transfer::srgb ? srgb_to_linear(v) : v;
      }
    if (alpha && !f.alpha.empty()) {
      *alpha = Image(s.width, s.height, 1);
      for (std::size_t i = 0; i < s.pixels(); ++i) alpha->data[i] = s.data[i * C + (C - 1)];
    }
    if (info) *info = d.info;
    return out;
  }
  if (!how.layer.empty())
    throw Error(how.layer_flag + " '" + how.layer + "' names a layer of a file with layers (a multilayer OpenEXR), "
                "but '" + path + "' has none" +
                (exr ? " (its channels are " + quoted_list(L.parts.front().channels) + ")" : std::string()) +
                "; drop " + how.layer_flag);
  // An integer file's automatic transfer is sRGB, which a row decodes during
  // its read.
  // A gamma or table: the rows map each count as they decode (once per count).
  io::Decoded d = decode(path, "'" + path + "'",
                         transfer == Transfer::linear || is_curve(transfer) ? Want::values : Want::srgb_linear, 3, 0.0f,
                         is_curve(transfer) ? &transfer : nullptr);
  TransferFunction t = transfer;
  if (t == Transfer::automatic) t = d.info.integer ? Transfer::srgb : Transfer::linear;
  d.info.transfer = t;
  Image& s = d.img;
  if (t == Transfer::srgb && !(d.mapped && d.info.integer)) {
    // In place (a fresh 960x672 RGB float buffer costs ~15 ms of page faults
    // on a VM); integer files through a table of their distinct values.
    if (d.info.integer && d.info.bits <= 16) {
      io::SrgbDecodeTable decode_value(d.info.bits <= 8 ? 8 : 16);
      for (float& v : s.data) v = decode_value(v);
    } else {
      for (float& v : s.data) v = srgb_to_linear(v);
    }
  }
  // The alpha channel: the row's, or the last of 2 or 4.
  int a = d.alpha;
  if (a < 0 && (s.channels == 2 || s.channels == 4)) a = s.channels - 1;
  if (a >= s.channels || (s.channels != 2 && s.channels != 4)) a = -1;
  if (is_curve(t) && !(d.mapped && d.info.integer)) apply_curve(s, t, a, path);
  d.info.channels_read = plain_colour_channels(d.info, s.channels, alpha ? a : -1);
  d.info.channel_rule = how.rule == LayerRule::first && !plain_channels(d.info.channel_names)
                            ? "the file's first channels, in its order (layer rule 'first': records before schema 4)"
                            : "the file's colour channels";
  if (alpha && a >= 0) {
    *alpha = Image(s.width, s.height, 1);
    const double maxval = std::ldexp(1.0, d.info.bits <= 8 ? 8 : 16) - 1.0;
    for (std::size_t i = 0; i < s.pixels(); ++i) {
      float v = s.data[i * s.channels + a];
      // An integer file's alpha is a count over 2^bits - 1, never sRGB: undo the decode given to every channel.
      if (d.info.integer && t == Transfer::srgb)
        v = static_cast<float>(std::nearbyint(linear_to_srgb(v) * maxval) / maxval);
      alpha->data[i] = v;
    }
  }
  if (info) *info = d.info;
  if (s.channels == 3) return std::move(s);
  Image out(s.width, s.height, 3);  // grey: the one channel three times; alpha dropped
  const int c = s.channels;
  for (std::size_t i = 0; i < s.pixels(); ++i)
    for (int k = 0; k < 3; ++k) out.data[i * 3 + k] = s.data[i * c + (c >= 3 ? k : 0)];
  return out;
}

Image read_scalar(const std::string& path, const std::string& channel, FileInfo* info) {
  ScalarRead how;
  how.channel = channel;
  how.channel_flag = "--range-channel";
  return read_scalar(path, how, info);
}

namespace {
// A channel of a layered file by name: its part and name in that part.
bool find_channel(const io::ExrLayout& L, const std::string& want, int& part, std::string& name,
                  std::vector<std::string>& matches) {
  for (std::size_t p = 0; p < L.parts.size(); ++p)
    for (const std::string& c : L.parts[p].channels) {
      const std::string& pn = L.parts[p].name;
      if (c == want || (L.multipart && !pn.empty() && pn + "." + c == want)) {
        if (matches.empty()) part = static_cast<int>(p), name = c;
        matches.push_back(L.multipart && !pn.empty() ? pn + "." + c : c);
      }
    }
  return matches.size() == 1;
}
}  // namespace

Image read_scalar(const std::string& path, const ScalarRead& how, FileInfo* info) {
  check_readable(path);
  const std::string& channel = how.channel;
  io::ExrLayout L;
  if (layout_of(path, L) && layered(L) && (how.rule == LayerRule::names || !channel.empty())) {
    int part = 0;
    std::string name, rule;
    const std::vector<std::string> all = all_channels(L);
    if (!channel.empty()) {
      std::vector<std::string> matches;
      if (!find_channel(L, channel, part, name, matches)) {
        if (matches.empty())
          throw Error("'" + path + "' has no channel named '" + channel + "'; its channels are: " + quoted_list(all));
        throw Error("'" + path + "' has a channel '" + channel + "' in " + std::to_string(matches.size()) +
                    " parts; name it with its part: " + quoted_list(matches));
      }
      rule = "named by " + how.channel_flag;
    } else if (!how.depth) {
      throw Error("'" + path + "' has " + std::to_string(all.size()) + " channels in layers (" + quoted_list(all) +
                  "), and this map must be one channel; extract the one that holds it first (oiiotool IN --ch NAME "
                  "-o OUT)");
    } else {
      std::vector<std::string> depth, mist;
      for (const std::string& c : all) {
        if (is_mist_pass_name(c)) mist.push_back(c);
        else if (is_depth_pass_name(c)) depth.push_back(c);
      }
      if (depth.empty() && !mist.empty())
        throw Error("'" + path + "' holds no depth pass, only a Mist pass (" + quoted_list(mist) +
                    "): Blender's Mist is 0 to 1 between the World's mist start and start + depth, not metres, and "
                    "brume never reads it as depth. Render the Z pass (View Layer Properties > Passes > Data > Z: "
                    "the channel ViewLayer.Depth.Z) and give the file with --z, or name a channel with " +
                    how.channel_flag);
      if (depth.empty())
        throw Error("'" + path + "' has " + std::to_string(all.size()) + " channels (" + quoted_list(all) +
                    ") and none is named like a depth pass (Z, depth, *.depth, *.Depth.Z); say which holds the "
                    "depth with " + how.channel_flag + " NAME");
      if (depth.size() > 1)
        throw Error("'" + path + "' holds " + std::to_string(depth.size()) + " channels named like depth passes (" +
                    quoted_list(depth) + "); say which with " + how.channel_flag + " NAME");
      std::vector<std::string> matches;
      find_channel(L, depth.front(), part, name, matches);
      rule = "the file's one channel named like a depth pass";
    }
    io::Decoded d = decode_exr_channels(path, part, {name}, NAN, 3);
    io::note_reader("openexr");
    d.info.path = path;
    d.info.transfer = Transfer::linear;
    d.info.channel_rule = rule;
    if (info) *info = d.info;
    return std::move(d.img);
  }
  io::Decoded d = decode(path, "'" + path + "'", Want::counts, 3, NAN);
  const Image& s = d.img;
  int pick = 0;
  const auto& names = d.info.channel_names;
  if (!channel.empty()) {
    const auto it = std::find(names.begin(), names.end(), channel);
    if (it == names.end())
      throw Error("'" + path + "' has no channel named '" + channel + "'; its channels are: " + channel_list(names));
    pick = static_cast<int>(it - names.begin());
    d.info.channel_rule = "named by " + how.channel_flag;
  } else if (s.channels > 1) {
    // A grey picture stored as RGB is one channel in disguise (files of plain
    // R, G, B (A) only); anything else is ambiguous.
    const bool plain = how.rule == LayerRule::first ||
                       (names.size() == static_cast<std::size_t>(s.channels) ? plain_channels(names) : true);
    const auto differ = [&] {
      return Error("'" + path + "' has " + std::to_string(s.channels) + " channels (" + channel_list(names) +
                   ") that differ; say which one holds the values with " + how.channel_flag + " NAME");
    };
    if (!plain) throw differ();
    const int nc = std::min(s.channels, 3);
    for (std::size_t i = 0; i < s.pixels(); ++i)
      for (int k = 1; k < nc; ++k) {
        const float a = s.data[i * s.channels], b = s.data[i * s.channels + k];
        if (!(a == b || (std::isnan(a) && std::isnan(b)))) throw differ();
      }
    d.info.channel_rule = "grey stored as RGB: the first channel (all equal)";
  } else {
    d.info.channel_rule = "the file's one channel";
  }
  d.info.channels_read = {pick < static_cast<int>(names.size()) ? names[static_cast<std::size_t>(pick)]
                                                                : "channel" + std::to_string(pick)};
  d.info.transfer = Transfer::linear;
  if (info) *info = d.info;
  if (s.channels == 1) return std::move(d.img);  // the file's one channel, no copy
  Image out(s.width, s.height, 1);
  for (std::size_t i = 0; i < s.pixels(); ++i) out.data[i] = s.data[i * s.channels + pick];
  return out;
}

std::string sha256_file(const std::string& path) {
  InputFile in(path, "");  // a regular file: a device or FIFO would never end, or block
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr);
  std::vector<char> chunk(1 << 16);
  for (;;) {
    const ssize_t n = ::read(in.fd(), chunk.data(), chunk.size());
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      EVP_MD_CTX_free(ctx);
      throw Error("cannot read '" + path + "' to hash it: " + std::strerror(errno));
    }
    if (n == 0) break;
    EVP_DigestUpdate(ctx, chunk.data(), static_cast<std::size_t>(n));
  }
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_DigestFinal_ex(ctx, md, &len);
  EVP_MD_CTX_free(ctx);
  std::ostringstream hex;
  for (unsigned int i = 0; i < len; ++i) {
    char b[3];
    std::snprintf(b, sizeof b, "%02x", md[i]);
    hex << b;
  }
  return hex.str();
}

}  // namespace brume
