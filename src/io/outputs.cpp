// brume — writing outputs: the checks before any work (extension, --bits,
// --compression, the folder), encoding by the output's row of the table of
// formats (io/formats/format.hpp; a shape the row does not hold is an error
// naming it), to a temporary beside the target, and the renames that commit a run's
// outputs together; the signal handlers that remove temporaries.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <climits>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "io/formats/format.hpp"
#include "io/io_internal.hpp"

namespace brume {
namespace fs = std::filesystem;

namespace {
thread_local bool t_create_folders = false;  // inside a CreateOutputFolders scope
}  // namespace

CreateOutputFolders::CreateOutputFolders() : outer_(t_create_folders) { t_create_folders = true; }
CreateOutputFolders::~CreateOutputFolders() { t_create_folders = outer_; }

void check_output_dir(const std::string& path, const std::string& flag) {
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  std::error_code ec;
  if (t_create_folders && !fs::exists(dir, ec)) {
    // Created when an output is written there (ensure_output_folder): the
    // nearest existing ancestor must be a writable directory.
    fs::path up = dir;
    while (up.has_parent_path() && up.parent_path() != up && !fs::exists(up, ec)) up = up.parent_path();
    if (!fs::exists(up, ec)) up = ".";
    if (!fs::is_directory(up, ec))
      throw Error(flag + " '" + path + "': '" + up.string() + "' is not a directory, so '" + dir.string() +
                  "' cannot be created in it");
    if (::access(up.c_str(), W_OK) != 0)
      throw Error(flag + " '" + path + "': directory '" + up.string() + "' is not writable, so '" + dir.string() +
                  "' cannot be created in it");
    return;
  }
  if (!fs::is_directory(dir, ec))
    // Checked before any work and again at each write: the second time, the
    // directory was there when the run started and has since been removed.
    throw Error(flag + " '" + path + "': directory '" + dir.string() +
                "' does not exist (or was removed while brume ran); create it and run again");
  if (::access(dir.c_str(), W_OK) != 0)
    throw Error(flag + " '" + path + "': directory '" + dir.string() + "' is not writable");
}

std::string lower_ext(const std::string& path) {
  std::string e = fs::path(path).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}


namespace {

std::string temp_path_for(const std::string& path) {
  fs::path p(path);
  // Appended piecewise: GCC 12's -Wrestrict misfires on the chained operator+ here (GCC bug 105329).
  std::string name = ".";
  name += p.filename().string();
  name += ".brume-tmp-";
  name += std::to_string(::getpid());
  // A per-process counter as well: threads of one process (Python, a batch
  // run) writing the same destination must not share a temporary.
  static std::atomic<unsigned> counter{0};
  name += "-";
  name += std::to_string(counter.fetch_add(1, std::memory_order_relaxed));
  name += p.extension().string();
  return (p.parent_path() / name).string();
}

// Temporaries being written, for the signal handler: fixed slots, since a
// handler may only call async-signal-safe functions (unlink, raise) and read
// what was published before the signal.
constexpr int kTempSlots = 64;
struct TempSlot {
  std::atomic<bool> used{false};
  char path[PATH_MAX];
};
std::array<TempSlot, kTempSlots> g_temps;

int register_temp(const std::string& path) {
  if (path.size() >= PATH_MAX) return -1;
  for (int i = 0; i < kTempSlots; ++i) {
    bool expected = false;
    TempSlot& t = g_temps[static_cast<std::size_t>(i)];
    if (t.used.load(std::memory_order_acquire)) continue;
    std::memcpy(t.path, path.c_str(), path.size() + 1);
    if (t.used.compare_exchange_strong(expected, true, std::memory_order_acq_rel)) return i;
  }
  return -1;  // more than 64 outputs in flight: still removed by ~OutputSet, only not on a signal
}

void unregister_temp(int slot) {
  if (slot >= 0) g_temps[static_cast<std::size_t>(slot)].used.store(false, std::memory_order_release);
}

extern "C" void remove_temps_and_reraise(int sig) {
  for (TempSlot& t : g_temps)
    if (t.used.load(std::memory_order_acquire)) ::unlink(t.path);
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

// A failed write's reason from errno (EFBIG: a file-size limit; ENOSPC: a full disk).
std::string write_failure(int err) {
  if (err == EFBIG) return "the file-size limit was reached (ulimit -f); raise it or write a smaller format";
  if (err == ENOSPC) return "the disk is full; free space or write elsewhere";
  if (err == EDQUOT) return "the disk quota is exhausted";
  if (err != 0) return std::strerror(err);
  return "disk full or directory removed?";
}

}  // namespace

void install_output_signal_handlers() {
  std::signal(SIGXFSZ, SIG_IGN);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction sa {};
    sa.sa_handler = remove_temps_and_reraise;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESETHAND;
    ::sigaction(sig, &sa, nullptr);
  }
}

// ---- --bits and --compression, by the table's rows ------------------------------
namespace {

// "a", "a or b", "a, b or c"
std::string one_of(const std::vector<std::string>& v) {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) s += (i == 0 ? "" : i + 1 == v.size() ? " or " : ", ") + v[i];
  return s;
}

const io::Format& row_for(const std::string& path, const std::string& flag) {
  if (path.empty()) throw Error(flag + " needs a file name");
  const std::string e = lower_ext(path);
  if (const io::Format* f = io::format_of_extension(e)) return *f;
  std::vector<std::string> known;
  for (const io::Format* f : io::formats()) known.push_back(f->extensions.front());
  throw Error(flag + " '" + path + "': unknown output type '" + e + "'; use " + one_of(known));
}

// The storage type for a file: explicit --bits, or the format's natural one
// (data maps, is_color false, default to float where the format has it).
io::Storage storage_type(const io::Format& f, const std::string& path, const std::string& bits,
                         const std::string& flag, bool is_color) {
  static const char* names[] = {"8", "16", "half", "float"};
  const std::string b = bits == "auto" ? (is_color ? f.color_bits : f.data_bits) : bits;
  const auto it = std::find(std::begin(names), std::end(names), b);
  if (it == std::end(names))
    throw Error("--bits '" + bits + "' is not a bit depth; use auto, 8, 16, half or float");
  if (std::find(f.bits.begin(), f.bits.end(), b) == f.bits.end()) {
    // Half-float TIFF (Adobe's extension) is read by few programs: a row
    // that does not hold a depth refuses it rather than store another.
    std::string also;
    for (const io::Format* o : io::formats())
      if (o != &f && b != "8" && std::find(o->bits.begin(), o->bits.end(), b) != o->bits.end()) {
        also = " (or write " + b + " to " + o->extensions.front() + ")";
        break;
      }
    throw Error(flag + " '" + path + "': --bits " + bits + " is not available for " + lower_ext(path) +
                " files; use " + one_of(f.bits) + also);
  }
  return static_cast<io::Storage>(it - std::begin(names));
}

// NAME[:LEVEL], the spelling of OpenImageIO's "compression" attribute. Each
// format takes its own names; a name another format would take is refused,
// never replaced by a default (OpenImageIO's EXR writer falls back to zip for
// a name it does not know, silently).
io::Compression parse_compression(const io::Format& f, const std::string& path, const std::string& text,
                                  const std::string& flag) {
  io::Compression c;
  if (text == "auto" || text.empty()) return c;
  const std::string e = lower_ext(path);
  const auto colon = text.find(':');
  const std::string name = text.substr(0, colon);
  auto bad = [&](const std::string& why) {
    return Error("--compression '" + text + "' for " + flag + " '" + path + "': " + why + "; " + e +
                 " files take " + compression_names(e));
  };
  const io::CompressionRule* rule = nullptr;
  for (const auto& r : f.compressions)
    if (name == r.name) rule = &r;
  if (!rule) throw bad("'" + name + "' is not a compression of this format");
  c.name = name;
  c.lossy = rule->lossy;
  if (colon != std::string::npos) {
    const std::string lv = text.substr(colon + 1);
    if (rule->min_level > rule->max_level) throw bad("'" + name + "' takes no level");
    const bool digits = !lv.empty() && lv.size() <= 4 &&
                        std::all_of(lv.begin(), lv.end(), [](char ch) { return ch >= '0' && ch <= '9'; });
    const int l = digits ? std::stoi(lv) : -1;
    if (!digits || l < rule->min_level || l > rule->max_level)
      throw bad("the level '" + lv + "' is not a whole number in " + std::to_string(rule->min_level) + ".." +
                std::to_string(rule->max_level));
    c.level = l;
  } else if (name == "jpeg") {
    throw bad("JPEG's compression is its quality: give it as jpeg:1..100 (the default is 98)");
  }
  return c;
}

}  // namespace

std::string compression_names(const std::string& ext) {
  std::string s = "auto";
  const io::Format* f = io::format_of_extension(ext);
  if (!f) return s;
  for (const auto& r : f->compressions) {
    s += ", ";
    s += r.name;
    if (r.min_level <= r.max_level) {
      if (std::string(r.name) != "jpeg") s += std::string(", ") + r.name;
      s += ":" + std::to_string(r.min_level) + ".." + std::to_string(r.max_level);
    }
    if (r.lossy) s += " (lossy)";
  }
  return s;
}

std::string compression_help() {
  std::string by_format, autos;
  for (const io::Format* f : io::formats()) {
    autos += std::string(autos.empty() ? "" : "; ") + f->title + ": " + f->auto_is;
    std::string names = compression_names(f->extensions.front());
    names = names.substr(names.find(", ") + 2);  // less "auto"
    by_format += std::string("; ") + f->title + ": " + names;
  }
  return "compression of the output image, NAME[:LEVEL]: auto is each format's default (" + autos + ")" + by_format +
         ". Lossless forms give the same pixels; maps keep their format's default lossless compression "
         "(docs/formats.md)";
}

void check_encoding(const std::string& path, const WriteOptions& opts, const std::string& flag) {
  const io::Format& f = row_for(path, flag);
  const io::Storage type = storage_type(f, path, opts.bits, flag, opts.is_color);
  const bool integer = type == io::Storage::u8 || type == io::Storage::u16;
  if (!opts.float_reason.empty() && (integer || !f.holds_data)) {
    std::vector<std::string> data;
    for (const io::Format* o : io::formats())
      if (o->holds_data) data.push_back(o->extensions.front() + (o->name == std::string("tiff") ? " (float)" : ""));
    throw Error(flag + " '" + path + "': " + opts.float_reason + "; write it to " + one_of(data));
  }
  const io::Compression c = parse_compression(f, path, opts.compression, flag);
  bool lossless = false;
  for (const auto& r : f.compressions) lossless |= !r.lossy;
  if (c.lossy && lossless && (!opts.is_color || !opts.float_reason.empty())) {
    std::vector<std::string> names;
    for (const auto& r : f.compressions)
      if (!r.lossy) names.push_back(r.name);
    throw Error("--compression '" + opts.compression + "' for " + flag + " '" + path +
                "' is lossy, and this output is data, which brume writes losslessly; use " + one_of(names));
  }
}

void check_writable(const std::string& path, const WriteOptions& opts, const std::string& flag) {
  check_encoding(path, opts, flag);
  check_output_dir(path, flag);
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw Error(flag + " '" + path + "' is a directory");
}

namespace {
// The folders OutputSets of this process created inside CreateOutputFolders
// scopes, each with the count of sets that still use it. When the last one
// is done with a folder and the folder is empty (its set failed before
// renaming anything into it), the folder is removed: a batch frame that
// failed on a full disk left empty s0/ s1/ s2/ (issue #51). Under one lock,
// so that a frame never removes a folder another frame of the process is
// about to write into; rmdir leaves a folder that holds anything.
std::mutex g_folders_mu;
std::map<std::string, int> g_folder_users;

// The folder of an output, created now inside a CreateOutputFolders scope
// (check_output_dir accepted it as creatable); elsewhere it exists already.
// The folders it made, or that an earlier set made and still uses, are
// added to `used` (deepest first), each with one more user.
void ensure_output_folder(const std::string& path, const std::string& flag, std::vector<std::string>& used) {
  if (!t_create_folders) return;
  const fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) return;
  std::lock_guard<std::mutex> lock(g_folders_mu);
  std::error_code ec;
  // The chain up to the first folder that exists.
  std::vector<fs::path> made;
  for (fs::path d = dir; !d.empty() && !fs::exists(d, ec); d = d.parent_path()) {
    made.push_back(d);
    if (d == d.parent_path()) break;
  }
  if (!made.empty()) {
    fs::create_directories(dir, ec);
    if (!fs::is_directory(dir, ec))
      throw Error(flag + " '" + path + "': directory '" + dir.string() + "' cannot be created: " + ec.message());
  }
  // The folders made now, then those above them that earlier sets made.
  fs::path d = dir;
  for (; !d.empty(); d = d.parent_path()) {
    const std::string key = d.string();
    const bool now = std::find(made.begin(), made.end(), d) != made.end();
    auto it = g_folder_users.find(key);
    if (!now && it == g_folder_users.end()) break;
    if (std::find(used.begin(), used.end(), key) == used.end()) {
      ++g_folder_users[key];
      used.push_back(key);
    }
    if (d == d.parent_path()) break;
  }
}

// Inside a CreateOutputFolders scope, the folder of `path` is gone.
bool folder_was_removed(const std::string& path) {
  if (!t_create_folders) return false;
  const fs::path dir = fs::path(path).parent_path();
  std::error_code ec;
  return !dir.empty() && !fs::exists(dir, ec);
}

// One set is done with its folders: each loses a user, and one that no set
// uses any more is removed when empty (rmdir: a folder with a file stays).
void release_output_folders(const std::vector<std::string>& used) {
  if (used.empty()) return;
  std::lock_guard<std::mutex> lock(g_folders_mu);
  for (const std::string& key : used) {  // deepest first
    auto it = g_folder_users.find(key);
    if (it == g_folder_users.end() || --it->second > 0) continue;
    g_folder_users.erase(it);
    std::error_code ec;
    fs::remove(fs::path(key), ec);  // only when empty
  }
}
}  // namespace

OutputSet::~OutputSet() {
  for (auto& p : pending_) {
    std::error_code ec;
    fs::remove(p.tmp, ec);
    unregister_temp(p.slot);
  }
  release_output_folders(folders_);
}

void OutputSet::add_pending(const std::string& tmp, const std::string& final_path, const std::string& flag) {
  pending_.push_back({tmp, final_path, register_temp(tmp), flag});
}

void OutputSet::write(const std::string& path, const Image& img, const WriteOptions& opts,
                      const std::string& flag) {
  check_writable(path, opts, flag);
  const std::string e = lower_ext(path);
  const io::Format& f = row_for(path, flag);
  const io::Storage type = storage_type(f, path, opts.bits, flag, opts.is_color);
  if (!f.channel_counts.empty() &&
      std::find(f.channel_counts.begin(), f.channel_counts.end(), img.channels) == f.channel_counts.end()) {
    std::vector<std::string> counts, data;
    for (int n : f.channel_counts) counts.push_back(std::to_string(n));
    for (const io::Format* o : io::formats())
      if (o->holds_data && o->channel_counts.empty()) data.push_back(o->extensions.front());
    throw Error(flag + " '" + path + "': " + f.title + " holds " + one_of(counts) + " channels; write this " +
                std::to_string(img.channels) + "-channel image as " + one_of(data));
  }
  const bool integer = type == io::Storage::u8 || type == io::Storage::u16;
  Transfer t = opts.transfer;
  if (t == Transfer::automatic) t = (integer && opts.is_color) ? Transfer::srgb : Transfer::linear;

  // The values as stored: the image itself, or an sRGB-encoded copy (8-bit:
  // the codes themselves, by srgb_encode_8). An alpha channel (the last of
  // 2 or 4) is coverage, stored as it is.
  Image encoded;
  std::vector<std::uint8_t> codes;
  const Image* src = &img;
  const int c = img.channels, alpha = c == 2 || c == 4 ? c - 1 : -1;
  if (t == Transfer::srgb && type == io::Storage::u8) {
    codes.resize(img.data.size());
    srgb_encode_8(img.data.data(), codes.data(), codes.size());
    if (alpha >= 0)
      for (std::size_t i = static_cast<std::size_t>(alpha); i < codes.size(); i += static_cast<std::size_t>(c))
        codes[i] = static_cast<std::uint8_t>(io::to_count(img.data[i], 255.0f));
  } else if (t == Transfer::srgb) {
    encoded = img;
    for (std::size_t i = 0; i < encoded.data.size(); ++i)
      if (static_cast<int>(i % static_cast<std::size_t>(c)) != alpha)
        encoded.data[i] = linear_to_srgb(std::max(encoded.data[i], 0.0f));
    src = &encoded;
  }

  io::WriteRequest req;
  req.width = img.width, req.height = img.height, req.channels = img.channels, req.type = type;
  req.codes = codes.empty() ? nullptr : codes.data();
  req.values = src->data.data();
  req.srgb = t == Transfer::srgb;
  req.description = opts.description;
  req.compression = parse_compression(f, path, opts.compression, flag);
  req.threads = std::min(io::io_threads(), 64);
  if (!opts.channel_names.empty()) {
    if (std::string(f.name) != "openexr")
      throw Error(flag + " '" + path + "': named channels (layers) are written to OpenEXR files only; give a .exr "
                  "output");
    if (opts.channel_names.size() != static_cast<std::size_t>(img.channels) ||
        (!opts.channel_bits.empty() && opts.channel_bits.size() != opts.channel_names.size()))
      throw Error("internal: " + std::to_string(opts.channel_names.size()) + " channel names for a " +
                  std::to_string(img.channels) + "-channel image");
    req.channel_names = &opts.channel_names;
    if (!opts.channel_bits.empty()) req.channel_bits = &opts.channel_bits;
  }
  if (!opts.string_attributes.empty()) req.attributes = &opts.string_attributes;

  if (f.refuse)
    if (const std::string why = f.refuse(req); !why.empty()) throw Error(flag + " '" + path + "': " + why);
  ensure_output_folder(path, flag, folders_);
  const std::string tmp = temp_path_for(path);
  add_pending(tmp, path, flag);
  std::string why;
  errno = 0;
  bool ok = f.write(tmp, req, &why);
  if (!ok && folder_was_removed(path)) {
    // Another process's failed frame removed the empty folder between its
    // creation and this write (a batch's shards share folders): once more.
    ensure_output_folder(path, flag, folders_);
    why.clear();
    errno = 0;
    ok = f.write(tmp, req, &why);
  }
  if (!ok) {
    // errno's reason (or the writer's own when errno says nothing), the
    // directory's if it has gone since the check.
    const int err = errno;
    check_output_dir(path, flag);
    throw Error(flag + " '" + path + "': write failed: " +
                (err == 0 && !why.empty() ? why : write_failure(err) + (why.empty() ? "" : " (" + why + ")")));
  }
  io::note_writer(f.name);
}

void OutputSet::write_text(const std::string& path, const std::string& text, const std::string& flag) {
  ensure_output_folder(path, flag, folders_);
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(flag + " '" + path + "': directory '" + dir.string() + "' does not exist; create it first");
  const std::string tmp = temp_path_for(path);
  add_pending(tmp, path, flag);
  for (int attempt = 0;; ++attempt) {
    errno = 0;
    std::ofstream f(tmp, std::ios::binary);
    f << text;
    f.close();
    if (f) return;
    const int err = errno;
    if (attempt == 0 && folder_was_removed(path)) {  // as in write: once more
      ensure_output_folder(path, flag, folders_);
      continue;
    }
    throw Error(flag + " '" + path + "': write failed: " + write_failure(err));
  }
}

void OutputSet::commit() {
  while (!pending_.empty()) {
    const Pending& p = pending_.front();
    std::error_code ec;
    fs::rename(p.tmp, p.final_path, ec);
    if (ec) {
      check_output_dir(p.final_path, p.flag);  // the directory gone since the write: say so
      throw Error("cannot move the finished output into place at '" + p.final_path + "': " + ec.message());
    }
    unregister_temp(p.slot);
    pending_.erase(pending_.begin());
  }
}

void write_image(const std::string& path, const Image& img, const WriteOptions& opts,
                 const std::string& flag) {
  OutputSet set;
  set.write(path, img, opts, flag);
  set.commit();
}

}  // namespace brume
