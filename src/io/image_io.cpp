// brume — image and range-map files: PFM directly; the common PNG, OpenEXR
// and Radiance HDR files through png_direct, exr_direct (the OpenEXR
// library) and hdr_direct; everything else through OpenImageIO, in the
// module loaded on first use (src/io/codec.hpp; see brume/io.hpp).
#include <omp.h>

#include <openssl/evp.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"
#include "io/codec.hpp"
#include "io/exr_direct.hpp"
#include "io/hdr_direct.hpp"
#include "io/jpeg_direct.hpp"
#include "io/tiff_direct.hpp"
#include "io/png_direct.hpp"

namespace brume {
namespace fs = std::filesystem;

Transfer parse_transfer(const std::string& s, const std::string& flag) { return parse_enum(transfer_names(), s, flag); }
std::string to_string(Transfer t) { return enum_name(transfer_names(), t); }

namespace {
thread_local bool t_create_folders = false;  // inside a CreateOutputFolders scope
thread_local int t_io_threads = 0;           // an IoThreads scope's count (0: none)
}  // namespace

IoThreads::IoThreads(int n) : outer_(t_io_threads) { t_io_threads = n > 0 ? n : 0; }
IoThreads::~IoThreads() { t_io_threads = outer_; }

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

float srgb_to_linear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

float linear_to_srgb(float v) {
  return v <= 0.0031308f ? v * 12.92f : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

// ---- the sRGB curve over whole images, without a pow per value ---------------
// A std::pow per value was half of writing an 8-bit PNG (a 463x370
// Middlebury frame from Python: 26.6 ms, 13.5 with the encoder below; reading
// went from 16.7 to 15.3 ms). Both tables give exactly the bits of the
// per-value functions above: they are keyed by, and built from, the same
// float operations.
namespace {

// An integer file's values are at most 2^bits distinct floats, so the curve
// is evaluated once per distinct value and looked up after. Keyed by the
// exact float (slot: the nearest count), so any value -- a 12-bit count
// remapped by read_raw, a collision -- that is not the slot's key is
// computed and becomes it: the result is srgb_to_linear(v) bit for bit.
class SrgbDecodeTable {
 public:
  explicit SrgbDecodeTable(int bits)
      : scale_(static_cast<float>((1u << bits) - 1u)),
        key_(std::size_t(1) << bits, std::numeric_limits<float>::quiet_NaN()),
        val_(std::size_t(1) << bits, 0.0f) {}
  float operator()(float v) {
    const float s = v * scale_;
    if (!(s >= 0.0f && s <= scale_)) return srgb_to_linear(v);
    const auto k = static_cast<std::size_t>(s + 0.5f);
    if (key_[k] == v) return val_[k];  // a NaN key (empty slot) equals nothing
    const float r = srgb_to_linear(v);
    key_[k] = v;
    val_[k] = r;
    return r;
  }

 private:
  float scale_;
  std::vector<float> key_, val_;
};

// 8-bit sRGB encoding: the code OpenImageIO stores for the float
// linear_to_srgb(max(v, 0)) is a non-decreasing step function of v with 255
// steps. Their thresholds -- the least float giving each code, found by
// bisection over the floats' ordered bit patterns with OpenImageIO's own
// float -> uint8 conversion -- turn encoding into a few comparisons: a
// bucket on v's top 16 bits gives the code at the bucket's start, and one
// comparison with the next step's threshold the rest, with no branch on the
// value (a loop over the steps, whose exit depends on the value, took 5 % of
// a batch of 8-bit PNG frames). The conversion is OpenImageIO's vector loop
// (calls of whole multiples of 16 values), the one a scanline goes through;
// its scalar tail, which converted the last (width x channels mod 4) values
// of each row before, can round an exact tie (v x 255 = k + 1/2)
// the other way (seen: 0.00015176348 encodes to code 1 there, 0 in the
// vector loop), so such a value could differ by one code between columns;
// now every value is rounded as the vector loop does. Tested against
// OpenImageIO writing the per-value floats for every 97th float in
// [0, 1.01] and each step's neighbours (tests/test_io.cpp).
class SrgbEncoder8 {
 public:
  static const SrgbEncoder8& get() {
    static const SrgbEncoder8 e;
    return e;
  }
  std::uint8_t operator()(float v) const {
    if (std::isnan(v)) return nan_code_;
    if (!(v > 0.0f)) return zero_code_;  // negative and -0: max(v, 0) is 0
    std::uint32_t b;
    std::memcpy(&b, &v, 4);
    const std::size_t i = b >> 16;
    if (i >= bucket_.size()) return 255;  // v >= 2 (and +inf): past the last step
    const Bucket& k = bucket_[i];
    unsigned c = k.code + (v >= k.next ? 1u : 0u);  // no branch on the data: a step is a coin toss
    if (k.more) [[unlikely]]
      while (c < 255 && v >= threshold_[c + 1]) ++c;
    return static_cast<std::uint8_t>(c);
  }

 private:
  // The per-value path's codes of v (any count): OpenImageIO's vector
  // conversion of the encoded floats (detail::oiio_count, so that writing
  // an 8-bit file needs no OpenImageIO; IO.SrgbTablesGiveThePerValueBits
  // checks it against OpenImageIO's own).
  static std::vector<std::uint8_t> slow(const std::vector<float>& v) {
    std::vector<std::uint8_t> c(v.size());
    for (std::size_t i = 0; i < v.size(); ++i)
      c[i] = static_cast<std::uint8_t>(detail::oiio_count(linear_to_srgb(std::max(v[i], 0.0f)), 255.0f));
    return c;
  }
  static float from_bits(std::uint32_t b) {
    float f;
    std::memcpy(&f, &b, 4);
    return f;
  }
  SrgbEncoder8() {
    const std::vector<std::uint8_t> ends = slow({std::numeric_limits<float>::quiet_NaN(), 0.0f});
    nan_code_ = ends[0];
    zero_code_ = ends[1];
    const std::uint32_t top = 0x40000000u;  // 2.0f, whose code is 255
    // All 255 bisections in step: lo[k] < threshold <= hi[k] (slow(lo) < k <= slow(hi)).
    std::vector<std::uint32_t> lo(256, 0), hi(256, top);
    for (int step = 0; step < 32; ++step) {
      std::vector<float> mid(256);
      for (unsigned k = 0; k < 256; ++k) mid[k] = from_bits(lo[k] + (hi[k] - lo[k]) / 2);
      const std::vector<std::uint8_t> c = slow(mid);
      for (unsigned k = zero_code_ + 1u; k < 256; ++k) {
        if (hi[k] - lo[k] <= 1) continue;
        const std::uint32_t m = lo[k] + (hi[k] - lo[k]) / 2;
        (c[k] >= k ? hi[k] : lo[k]) = m;
      }
    }
    threshold_.assign(256, 0.0f);
    for (unsigned k = zero_code_ + 1u; k < 256; ++k) threshold_[k] = from_bits(hi[k]);
    std::vector<float> starts((top >> 16) + 1);
    for (std::size_t i = 0; i < starts.size(); ++i) starts[i] = from_bits(static_cast<std::uint32_t>(i << 16));
    const std::vector<std::uint8_t> start = slow(starts);
    bucket_.resize(starts.size());
    for (std::size_t i = 0; i < starts.size(); ++i) {
      Bucket& k = bucket_[i];
      k.code = start[i];
      k.next = k.code < 255 ? threshold_[k.code + 1] : std::numeric_limits<float>::infinity();
      // A bucket spans 2^-7 of its floats' magnitude and the codes' steps
      // are at least 0.89 % of theirs apart (1/(255 x 0.44), the curve's
      // largest v d(srgb)/dv), so no bucket holds two steps; `more` keeps
      // the result exact were one to.
      const float last = from_bits(static_cast<std::uint32_t>((i << 16) | 0xffffu));
      k.more = k.code < 254 && i + 1 < starts.size() && last >= threshold_[k.code + 2];
    }
  }
  // The code at a bucket's first float, and the threshold of the next step.
  struct Bucket {
    float next;
    std::uint8_t code;
    bool more;  // the bucket holds a second step (none does; see above)
  };
  std::uint8_t nan_code_ = 0, zero_code_ = 0;
  std::vector<float> threshold_;  // [k]: the least float whose code is >= k
  std::vector<Bucket> bucket_;    // [b >> 16]
};

}  // namespace

void srgb_encode_8(const float* v, std::uint8_t* out, std::size_t n) {
  const SrgbEncoder8& e = SrgbEncoder8::get();
  for (std::size_t i = 0; i < n; ++i) out[i] = e(v[i]);
}

namespace {
std::atomic<std::uint64_t> g_max_pixels{default_max_pixels};

std::string mpx(std::uint64_t px) {
  char b[64];
  std::snprintf(b, sizeof b, "%.1f Mpx", static_cast<double>(px) / 1e6);
  return b;
}
std::string mib(std::uint64_t bytes) {
  char b[64];
  std::snprintf(b, sizeof b, "%.0f MiB", static_cast<double>(bytes) / (1024.0 * 1024.0));
  return b;
}

// A number from a one-line kernel file ("max" = no limit).
bool read_u64_file(const std::string& path, std::uint64_t& v) {
  std::ifstream f(path);
  std::string s;
  if (!(f >> s) || s == "max") return false;
  try {
    v = std::stoull(s);
  } catch (...) {
    return false;
  }
  return true;
}

// A "Key:   N kB" line of /proc/meminfo or /proc/self/status, in bytes.
bool read_kb_field(const std::string& path, const std::string& key, std::uint64_t& v) {
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line))
    if (line.compare(0, key.size(), key) == 0 && line.size() > key.size() && line[key.size()] == ':') {
      try {
        v = std::stoull(line.substr(key.size() + 1)) * 1024;
      } catch (...) {
        return false;
      }
      return true;
    }
  return false;
}

void check_declared_size(const std::string& path, std::int64_t w, std::int64_t h, std::int64_t channels) {
  const std::uint64_t px = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
  if (px > max_pixels())
    throw Error("'" + path + "' declares " + std::to_string(w) + " x " + std::to_string(h) + " pixels (" + mpx(px) +
                "), over the limit of " + mpx(max_pixels()) +
                "; a corrupt or hostile header is the usual cause. If the file is genuine, raise the limit with "
                "--max-pixels " + std::to_string(px));
  if (channels > 1024)
    throw Error("'" + path + "' declares " + std::to_string(channels) +
                " channels; brume reads at most 1024 (a corrupt header?)");
}
// The file opened for reading (its header parsed), or an error naming it.
// OpenEXR 3.1 (Debian 12) allocates each header attribute at the size the
// file declares before it reads the bytes, so a 1 kB file declaring a 1.7 GB
// attribute costs 1.7 GB and seconds per open (found by fuzz/fuzz_image.cpp;
// reproducer fuzz/corpus/image/openexr_huge_attribute.bin). Refused here
// first: an attribute (name, type, int32 size, bytes; every header of a
// multi-part file) cannot be larger than what is left of the file. Headers
// this scan cannot follow are left to OpenEXR, which reports them.
void check_exr_attributes(const std::string& path) {
  // Only the first MB is read (it holds any real header's attributes but a
  // large preview); the scan stops at its end and leaves the rest to OpenEXR.
  std::error_code ec;
  const std::uintmax_t total = fs::file_size(path, ec);
  if (ec) return;
  std::vector<char> b(static_cast<std::size_t>(std::min<std::uintmax_t>(total, 1u << 20)));
  std::ifstream f(path, std::ios::binary);
  if (!f.read(b.data(), static_cast<std::streamsize>(b.size()))) return;
  const std::size_t n = b.size();
  if (n < 8 || static_cast<unsigned char>(b[0]) != 0x76 || b[1] != 0x2f || b[2] != 0x31 || b[3] != 0x01) return;
  const bool multipart = (static_cast<unsigned char>(b[5]) & 0x10) != 0;  // version bit 12
  std::size_t i = 8;
  auto cstring = [&](std::string& out) {
    const std::size_t start = i;
    while (i < n && b[i] != '\0' && i - start < 256) ++i;
    if (i >= n || b[i] != '\0') return false;
    out.assign(&b[start], i - start);
    ++i;
    return true;
  };
  for (;;) {  // headers
    std::string name, type;
    if (!cstring(name)) return;
    if (name.empty()) {  // end of this header; a multi-part file ends its list with an empty header
      if (!multipart || i >= n || b[i] == '\0') return;
      continue;
    }
    if (!cstring(type) || i + 4 > n) return;
    std::int32_t size = 0;
    std::memcpy(&size, &b[i], 4);  // little-endian, as x86-64
    i += 4;
    if (size < 0 || static_cast<std::uintmax_t>(size) > total - i)
      throw Error("cannot read '" + path + "': a corrupt OpenEXR header (attribute '" + name + "' declares " +
                  std::to_string(size) + " bytes, but " + std::to_string(total - i) + " remain in the file)");
    i += static_cast<std::size_t>(size);
  }
}

void check_readable(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw FileNotFound("cannot read '" + path + "': no such file");
  if (fs::is_directory(path, ec))
    throw Error("cannot read '" + path + "': it is a directory, not an image file");
}

std::unique_ptr<codec::Input> open_image(const std::string& path) {
  check_readable(path);
  check_exr_attributes(path);
  std::string e;
  auto in = codec::api("reading '" + path + "'").open_input(path, false, &e);
  if (!in) throw Error("cannot read '" + path + "': " + (e.empty() ? "unknown or unsupported image format" : e));
  return in;
}
}  // namespace

std::uint64_t max_pixels() { return g_max_pixels.load(std::memory_order_relaxed); }
void set_max_pixels(std::uint64_t n) {
  if (n < 1) throw Error("--max-pixels must be at least 1");
  g_max_pixels.store(n, std::memory_order_relaxed);
}

std::uint64_t memory_available() {
  std::uint64_t avail = UINT64_MAX, v = 0;
  if (read_kb_field("/proc/meminfo", "MemAvailable", v)) avail = v;
  // cgroup v2: the process's group from /proc/self/cgroup ("0::/path").
  {
    std::ifstream f("/proc/self/cgroup");
    std::string line;
    while (std::getline(f, line)) {
      if (line.rfind("0::", 0) == 0) {
        const std::string dir = "/sys/fs/cgroup" + line.substr(3);
        std::uint64_t limit = 0, used = 0;
        if (read_u64_file(dir + "/memory.max", limit)) {
          read_u64_file(dir + "/memory.current", used);
          avail = std::min(avail, limit > used ? limit - used : 0);
        }
      }
    }
  }
  // cgroup v1 (an unlimited group reports a huge number, harmless here).
  {
    std::uint64_t limit = 0, used = 0;
    if (read_u64_file("/sys/fs/cgroup/memory/memory.limit_in_bytes", limit)) {
      read_u64_file("/sys/fs/cgroup/memory/memory.usage_in_bytes", used);
      avail = std::min(avail, limit > used ? limit - used : 0);
    }
  }
  struct rlimit rl {};
  if (::getrlimit(RLIMIT_AS, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY) {
    std::uint64_t vm = 0;
    read_kb_field("/proc/self/status", "VmSize", vm);
    const std::uint64_t lim = rl.rlim_cur;
    avail = std::min(avail, lim > vm ? lim - vm : 0);
  }
  return avail;
}

void check_memory(std::uint64_t bytes, const std::string& what) {
  const std::uint64_t avail = memory_available();
  if (bytes > avail)
    throw Error(what + " needs about " + mib(bytes) + " of memory but this process may use only " + mib(avail) +
                " more (the least of MemAvailable, the cgroup limit and ulimit -v); free memory, raise the limit "
                "or work on a smaller image");
}

ImageHeader read_header(const std::string& path) {
  // The PNG, JPEG, TIFF, OpenEXR and Radiance subsets' headers without
  // OpenImageIO (io/png_direct.hpp, io/jpeg_direct.hpp, io/tiff_direct.hpp,
  // io/exr_direct.hpp, io/hdr_direct.hpp).
  check_readable(path);
  detail::PngInfo pi;
  if (detail::read_png_subset(path, nullptr, pi, [&](int w, int h, int c) { check_declared_size(path, w, h, c); }))
    return {pi.width, pi.height, pi.channels, "png"};
  detail::JpegInfo ji;
  if (detail::read_jpeg_subset(path, nullptr, ji, [&](int w, int h, int c) { check_declared_size(path, w, h, c); }))
    return {ji.width, ji.height, ji.channels, "jpeg"};
  detail::TiffInfo ti;
  if (detail::read_tiff_subset(path, nullptr, ti, [&](int w, int h, int c) { check_declared_size(path, w, h, c); }))
    return {ti.width, ti.height, ti.channels, "tiff"};
  detail::ExrInfo ei;
  if (detail::read_exr_subset(path, nullptr, ei, [&](int w, int h, int c) { check_declared_size(path, w, h, c); }, 0))
    return {ei.width, ei.height, ei.channels, "openexr"};
  int hw = 0, hh = 0;
  if (detail::read_hdr_subset(path, nullptr, hw, hh, [&](int w, int h, int c) { check_declared_size(path, w, h, c); }))
    return {hw, hh, 3, "hdr"};
  auto in = open_image(path);
  const codec::InputSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.channels <= 0) throw Error("cannot read '" + path + "': empty image");
  check_declared_size(path, spec.width, spec.height, spec.channels);
  return {spec.width, spec.height, spec.channels, spec.format};
}

namespace {

struct Raw {
  Image img;
  FileInfo info;
  bool linear = false;  // already decoded from sRGB (RawValues::srgb_linear and a PNG of the subset)
};

// What read_raw returns: the values as OpenImageIO reads them, the integer
// counts (read_scalar), or, for read_color, the values already decoded from
// sRGB where that can be done during the decode (the PNG subset: per count,
// srgb_to_linear of the value, bit for bit what decoding them after gives).
enum class RawValues { values, counts, srgb_linear };

// PFM read without OpenImageIO. Its PNM reader, on open, copies the whole
// file into a zero-filled buffer of its own before the pixels are asked for:
// for a 1600x1120 RGB PFM (21.5 MB) that is two passes over the data and
// ~10 500 pages first touched. Reading the file here instead took brume
// blur's read from ~300 to ~45 ms on the AMD EPYC VM, the huge-page hint
// included (docs/performance.md). A PFM is a three-token text header and raw floats, so
// brume reads the common form itself, straight into the image (rows flipped:
// PFM stores the picture's bottom row first; bytes swapped for a big-endian
// file, positive scale; values times |scale|, in float, as OpenImageIO
// does). Only a strict subset is taken this way: magic "PF" (RGB) or "Pf"
// (grey), then width, height (decimal digits) and scale (a plain decimal
// number), separated by spaces, tabs or line ends, no comments, then exactly
// one whitespace byte and at least width x height x channels floats. Any
// other file -- a comment, an odd number, a short file, not a PFM at all --
// goes to OpenImageIO, whose reading and messages stand. The FileInfo is the
// one OpenImageIO gives a PFM (format "pnm", 32-bit float, channels R, G, B
// or Y). Tested against OpenImageIO on grey and RGB, little- and big-endian
// files, unusual spacing and ETH3D's PFMs, bit for bit, and on the files it
// must leave to OpenImageIO (tests/test_io.cpp).
struct PfmHeader {
  int width = 0, height = 0, channels = 0;
  double scale = 0.0;
  std::size_t offset = 0;  // where the pixels start
};

bool pfm_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

std::optional<PfmHeader> parse_pfm_header(std::ifstream& f) {
  char head[256];
  f.read(head, sizeof head);
  const std::size_t got = static_cast<std::size_t>(f.gcount());
  if (got < 3 || head[0] != 'P' || (head[1] != 'F' && head[1] != 'f') || !pfm_space(head[2])) return std::nullopt;
  PfmHeader h;
  h.channels = head[1] == 'F' ? 3 : 1;
  std::size_t i = 2;
  std::string tok[3];
  for (std::string& t : tok) {
    while (i < got && pfm_space(head[i])) ++i;
    while (i < got && !pfm_space(head[i])) t += head[i++];
    if (t.empty() || i >= got) return std::nullopt;
  }
  h.offset = i + 1;  // the single whitespace byte that ends the header
  for (int k = 0; k < 2; ++k) {
    const std::string& t = tok[k];
    if (t.size() > 9 || t.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
    const long v = std::strtol(t.c_str(), nullptr, 10);
    if (v < 1) return std::nullopt;
    (k == 0 ? h.width : h.height) = static_cast<int>(v);
  }
  // [-]digits[.digits][(e|E)[+|-]digits]: no inf, nan, hex or leading '+'.
  const std::string& t = tok[2];
  std::size_t j = t[0] == '-' ? 1 : 0;
  const std::size_t int_start = j;
  while (j < t.size() && std::isdigit(static_cast<unsigned char>(t[j]))) ++j;
  if (j == int_start) return std::nullopt;
  if (j < t.size() && t[j] == '.') {
    ++j;
    while (j < t.size() && std::isdigit(static_cast<unsigned char>(t[j]))) ++j;
  }
  if (j < t.size() && (t[j] == 'e' || t[j] == 'E')) {
    ++j;
    if (j < t.size() && (t[j] == '+' || t[j] == '-')) ++j;
    const std::size_t e0 = j;
    while (j < t.size() && std::isdigit(static_cast<unsigned char>(t[j]))) ++j;
    if (j == e0) return std::nullopt;
  }
  if (j != t.size()) return std::nullopt;
  h.scale = std::strtod(t.c_str(), nullptr);
  if (h.scale == 0.0 || !std::isfinite(h.scale)) return std::nullopt;
  return h;
}

bool read_pfm_pixels(std::ifstream& f, const PfmHeader& ph, Image& img) {
  const std::size_t row = static_cast<std::size_t>(ph.width) * static_cast<std::size_t>(ph.channels);
  f.clear();
  f.seekg(static_cast<std::streamoff>(ph.offset));
  for (long y = ph.height - 1; y >= 0; --y) {
    f.read(reinterpret_cast<char*>(img.data.data() + static_cast<std::size_t>(y) * row),
           static_cast<std::streamsize>(row * 4));
    if (!f) return false;
  }
  static_assert(sizeof(float) == 4);
  const std::uint32_t probe = 1;
  const bool host_little = *reinterpret_cast<const unsigned char*>(&probe) == 1;
  if ((ph.scale < 0.0) != host_little)
    for (float& v : img.data) {
      std::uint32_t b;
      std::memcpy(&b, &v, 4);
      b = __builtin_bswap32(b);
      std::memcpy(&v, &b, 4);
    }
  const float k = static_cast<float>(std::fabs(ph.scale));
  if (k != 1.0f)
    for (float& v : img.data) v *= k;
  return true;
}

// Threads the codecs may use (brume/io.hpp, IoThreads): the scope's count
// (--threads), else OpenMP's (the cores, or OMP_NUM_THREADS). OpenEXR's pool
// for a subset file: a 1600 x 1120 zip-compressed float range map took
// 45-60 ms on the calling thread, 24-38 ms with two (OpenImageIO: 29-40 ms;
// AMD EPYC Zen 4, 2 vCPU, 2026-12-03).
int io_threads() { return t_io_threads > 0 ? t_io_threads : omp_get_max_threads(); }
int exr_threads() { return std::min(io_threads(), 64); }

// Read every channel of the first subimage as float. Integer files are read
// as their raw counts (not normalised) when `counts` is set.
// FileInfo of a file OpenImageIO opened (transfer: linear, none applied).
FileInfo file_info_of(const std::string& path, const codec::InputSpec& spec) {
  FileInfo f;
  f.path = path;
  f.format = spec.format;
  f.integer = !spec.floating;
  f.bits = spec.bits_per_sample > 0 ? spec.bits_per_sample : spec.container_bits;
  f.channel_names = spec.channel_names;
  f.description = spec.description;
  return f;
}

Raw read_raw(const std::string& path, RawValues want) {
  const bool counts = want == RawValues::counts;
  check_readable(path);
  // Before any allocation, from a header: the size limits, then memory for
  // the decoded file (all channels) and the caller's converted copy (<= 3).
  const auto check_size = [&](int w, int h, int c) {
    check_declared_size(path, w, h, c);
    const std::uint64_t px = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
    check_memory(px * 4 * static_cast<std::uint64_t>(c + 3), "reading '" + path + "'");
  };
  {
    std::ifstream f(path, std::ios::binary);
    if (const std::optional<PfmHeader> ph = f ? parse_pfm_header(f) : std::nullopt) {
      std::error_code ec;
      const std::uintmax_t size = fs::file_size(path, ec);
      const std::uint64_t px = static_cast<std::uint64_t>(ph->width) * static_cast<std::uint64_t>(ph->height);
      if (!ec && size >= ph->offset && (size - ph->offset) / 4 / static_cast<std::uint64_t>(ph->channels) >= px) {
        check_size(ph->width, ph->height, ph->channels);
        Raw r;
        r.info.path = path;
        r.info.format = "pnm";  // OpenImageIO's name for the format
        r.info.integer = false;
        r.info.bits = 32;
        r.info.channel_names = ph->channels == 3 ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
        r.img = Image(ph->width, ph->height, ph->channels);
        if (read_pfm_pixels(f, *ph, r.img)) return r;
      }
    }
  }
  {
    // 8/16-bit grey and RGB PNG: libpng itself (io/png_direct.hpp); the
    // values and FileInfo are OpenImageIO's, and anything outside the subset
    // (or any libpng complaint) goes on to OpenImageIO below.
    Raw r;
    detail::PngInfo pi;
    std::function<float(float, int)> map;
    if (counts)  // as below
      map = [](float v, int bits) { return static_cast<float>(std::nearbyint(v * (std::ldexp(1.0, bits) - 1.0))); };
    if (want == RawValues::srgb_linear) map = [](float v, int) { return srgb_to_linear(v); };
    if (detail::read_png_subset(path, &r.img, pi, check_size, map)) {
      r.info.path = path;
      r.info.format = "png";
      r.info.integer = true;
      r.info.bits = pi.bits;
      r.info.channel_names =
          pi.channels == 3 ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
      r.info.description = pi.description;
      r.linear = want == RawValues::srgb_linear;
      return r;
    }
    // 8-bit grey and colour JPEG: libjpeg itself (io/jpeg_direct.hpp), the
    // same way.
    detail::JpegInfo ji;
    if (detail::read_jpeg_subset(path, &r.img, ji, check_size, map)) {
      r.info.path = path;
      r.info.format = "jpeg";
      r.info.integer = true;
      r.info.bits = 8;
      r.info.channel_names =
          ji.channels == 3 ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
      r.info.description = ji.description;
      r.linear = want == RawValues::srgb_linear;
      return r;
    }
    // The common TIFF files: libtiff itself (io/tiff_direct.hpp); integer
    // ones the same way, floats as stored (no map: they are linear values,
    // and counts are asked of integer files only).
    detail::TiffInfo ti;
    if (detail::read_tiff_subset(path, &r.img, ti, check_size, map)) {
      r.info.path = path;
      r.info.format = "tiff";
      r.info.integer = !ti.floating;
      r.info.bits = ti.bits;
      r.info.channel_names =
          ti.channels == 3 ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
      r.info.description = ti.description;
      r.linear = !ti.floating && want == RawValues::srgb_linear;
      return r;
    }
  }
  {
    // Single-part half/float OpenEXR with one channel or R G B (A): the
    // OpenEXR library itself (io/exr_direct.hpp); anything else goes on to
    // OpenImageIO below.
    Raw r;
    detail::ExrInfo ei;
    if (detail::read_exr_subset(path, &r.img, ei, check_size, exr_threads())) {
      r.info.path = path;
      r.info.format = "openexr";
      r.info.integer = false;
      r.info.bits = ei.bits;
      r.info.channel_names = std::move(ei.channel_names);
      r.info.description = std::move(ei.description);
      return r;
    }
  }
  {
    // Radiance HDR in its common form: brume itself (io/hdr_direct.hpp).
    Raw r;
    int w = 0, h = 0;
    if (detail::read_hdr_subset(path, &r.img, w, h, check_size)) {
      r.info.path = path;
      r.info.format = "hdr";
      r.info.integer = false;
      r.info.bits = 32;
      r.info.channel_names = {"R", "G", "B"};
      return r;
    }
  }
  auto in = open_image(path);
  const codec::InputSpec& spec = in->spec();
  Raw r;
  r.info = file_info_of(path, spec);
  if (spec.width <= 0 || spec.height <= 0 || spec.channels <= 0)
    throw Error("cannot read '" + path + "': empty image");
  check_size(spec.width, spec.height, spec.channels);  // refused before any allocation: the header decides
  r.img = Image(spec.width, spec.height, spec.channels);
  if (!in->read_float(r.img.data.data())) {
    std::string e = in->error();
    throw Error("cannot read '" + path + "': " + (e.empty() ? "read failed (truncated or corrupt file?)" : e));
  }
  in->close();
  const int container = spec.container_bits;
  const int stored = std::min(r.info.bits, container);
  if (r.info.integer && stored < container && container <= 16) {
    // Fewer bits than the container (a 12-bit TIFF in 16 bits): OpenImageIO
    // widens a count k by bit replication ((k << 4) | (k >> 8)), so the float
    // it returns is not k/4095 (2048 reads as 0.500114, not 0.500122). The top
    // `stored` bits of the widened count are k — also for readers that scale
    // by 65535/4095 instead — and k/(2^stored − 1) is the true value.
    const double wide = std::ldexp(1.0, container) - 1.0, narrow = std::ldexp(1.0, stored) - 1.0;
    const int shift = container - stored;
    for (float& v : r.img.data) {
      const auto k = static_cast<std::uint32_t>(std::nearbyint(v * wide)) >> shift;
      v = static_cast<float>(k / narrow);
    }
  }
  if (counts && r.info.integer) {
    // Counts of the stored bit depth: a 12-bit depth map's 4095 is 4095.
    const double maxval = std::ldexp(1.0, stored) - 1.0;
    for (float& v : r.img.data) v = static_cast<float>(std::nearbyint(v * maxval));
  }
  return r;
}

}  // namespace

ChannelImage read_unassociated(const std::string& path, const std::string& what) {
  const std::string name = what + " '" + path + "'";
  std::error_code ec;
  if (!fs::exists(path, ec)) throw FileNotFound("cannot read " + name + ": no such file");
  const auto check_size = [&](int w, int h, int c) {  // the decoded file and the caller's RGBA copy
    check_declared_size(path, w, h, c);
    const std::uint64_t px = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
    check_memory(px * 4 * static_cast<std::uint64_t>(c + 4), "reading " + name);
  };
  ChannelImage r;
  r.info.path = path;
  {
    detail::PngInfo pi;
    if (detail::read_png_subset(path, &r.img, pi, check_size, {}, true)) {
      static const std::vector<std::string> names[5] = {
          {}, {"Y"}, {"Y", "A"}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
      r.info.format = "png";
      r.info.integer = true;
      r.info.bits = pi.bits;
      r.info.channel_names = names[pi.channels];
      r.info.description = pi.description;
      r.alpha = pi.channels == 2 || pi.channels == 4 ? pi.channels - 1 : -1;
      r.unassociated = true;  // as OpenImageIO marks every PNG when asked to keep alpha so
      return r;
    }
  }
  {
    detail::ExrInfo ei;
    if (detail::read_exr_subset(path, nullptr, ei, [](int, int, int) {}, 0) && ei.channels >= 3 &&
        detail::read_exr_subset(path, &r.img, ei, check_size, exr_threads())) {
      r.info.format = "openexr";
      r.info.bits = ei.bits;
      r.info.channel_names = std::move(ei.channel_names);
      r.info.description = std::move(ei.description);
      r.alpha = ei.channels == 4 ? 3 : -1;
      return r;
    }
  }
  std::string open_error;
  auto in = codec::api("reading " + name).open_input(path, true, &open_error);
  if (!in)
    throw Error("cannot read " + name + ": " + (open_error.empty() ? "unknown or unsupported image format" : open_error));
  const codec::InputSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.channels <= 0) throw Error("cannot read " + name + ": empty image");
  check_size(spec.width, spec.height, spec.channels);
  r.img = Image(spec.width, spec.height, spec.channels);
  if (!in->read_float(r.img.data.data())) {
    const std::string e = in->error();
    throw Error("cannot read " + name + ": " + (e.empty() ? "read failed" : e));
  }
  r.info = file_info_of(path, spec);
  r.alpha = spec.alpha_channel;
  r.unassociated = spec.unassociated_alpha;
  in->close();
  return r;
}

Image read_color(const std::string& path, Transfer transfer, FileInfo* info) {
  // An integer file's automatic transfer is sRGB; the PNG subset (always
  // integer) is decoded from it during its read.
  Raw r = read_raw(path, transfer == Transfer::linear ? RawValues::values : RawValues::srgb_linear);
  Transfer t = transfer;
  if (t == Transfer::automatic) t = r.info.integer ? Transfer::srgb : Transfer::linear;
  r.info.transfer = t;
  if (info) *info = r.info;
  if (r.linear) {
    if (r.img.channels == 3) return std::move(r.img);
    Image out(r.img.width, r.img.height, 3);  // grey: the one channel three times
    for (std::size_t i = 0; i < r.img.pixels(); ++i)
      out.data[i * 3] = out.data[i * 3 + 1] = out.data[i * 3 + 2] = r.img.data[i];
    return out;
  }
  // Three channels: converted in place and returned, no second image (a
  // fresh 960x672 RGB float buffer costs ~15 ms of page faults on a VM).
  if (r.img.channels == 3) {
    if (t == Transfer::srgb && r.info.integer && r.info.bits <= 16) {
      SrgbDecodeTable decode(r.info.bits <= 8 ? 8 : 16);
      for (float& v : r.img.data) v = decode(v);
    } else if (t == Transfer::srgb) {
      for (float& v : r.img.data) v = srgb_to_linear(v);
    }
    return std::move(r.img);
  }
  const Image& s = r.img;
  Image out(s.width, s.height, 3);
  const int c = s.channels;
  if (t == Transfer::srgb && r.info.integer && r.info.bits <= 16) {
    SrgbDecodeTable decode(r.info.bits <= 8 ? 8 : 16);
    for (std::size_t i = 0; i < s.pixels(); ++i)
      for (int k = 0; k < 3; ++k) out.data[i * 3 + k] = decode(s.data[i * c + (c >= 3 ? k : 0)]);
  } else {
    for (std::size_t i = 0; i < s.pixels(); ++i) {
      for (int k = 0; k < 3; ++k) {
        float v = s.data[i * c + (c >= 3 ? k : 0)];
        if (t == Transfer::srgb) v = srgb_to_linear(v);
        out.data[i * 3 + k] = v;
      }
    }
  }
  return out;
}

Image read_scalar(const std::string& path, const std::string& channel, FileInfo* info) {
  Raw r = read_raw(path, RawValues::counts);
  const Image& s = r.img;
  int pick = 0;
  if (!channel.empty()) {
    auto& names = r.info.channel_names;
    auto it = std::find(names.begin(), names.end(), channel);
    if (it == names.end()) {
      std::string all;
      for (auto& n : names) all += (all.empty() ? "" : ", ") + n;
      throw Error("'" + path + "' has no channel named '" + channel + "'; its channels are: " + all);
    }
    pick = static_cast<int>(it - names.begin());
  } else if (s.channels > 1) {
    // A grey picture stored as RGB is one channel in disguise; anything else is ambiguous.
    const int nc = std::min(s.channels, 3);
    for (std::size_t i = 0; i < s.pixels(); ++i)
      for (int k = 1; k < nc; ++k) {
        float a = s.data[i * s.channels], b = s.data[i * s.channels + k];
        if (!(a == b || (std::isnan(a) && std::isnan(b)))) {
          std::string all;
          for (auto& n : r.info.channel_names) all += (all.empty() ? "" : ", ") + n;
          throw Error("'" + path + "' has " + std::to_string(s.channels) + " channels (" + all +
                      ") that differ; say which one holds the values with --range-channel NAME");
        }
      }
  }
  r.info.transfer = Transfer::linear;
  if (info) *info = r.info;
  if (s.channels == 1) return std::move(r.img);  // the file's one channel, no copy
  Image out(s.width, s.height, 1);
  for (std::size_t i = 0; i < s.pixels(); ++i) out.data[i] = s.data[i * s.channels + pick];
  return out;
}

namespace {

std::string lower_ext(const std::string& path) {
  std::string e = fs::path(path).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

// The storage type for a file: explicit --bits, or the format's natural one.
// Data maps (is_color false) default to float where the format has it.
codec::Type storage_type(const std::string& path, const std::string& bits, const std::string& flag, bool is_color) {
  const std::string e = lower_ext(path);
  const bool is_png = e == ".png", is_jpg = e == ".jpg" || e == ".jpeg", is_tif = e == ".tif" || e == ".tiff";
  const bool is_exr = e == ".exr", is_pfm = e == ".pfm", is_hdr = e == ".hdr";
  std::string b = bits;
  if (b == "auto") b = is_jpg ? "8" : is_png ? "16" : (is_tif && is_color) ? "16" : "float";
  auto bad = [&](const std::string& allowed) {
    return Error(flag + " '" + path + "': --bits " + bits + " is not available for " + e +
                 " files; use " + allowed);
  };
  if (is_jpg && b != "8") throw bad("8");
  if (is_png && b != "8" && b != "16") throw bad("8 or 16");
  if (is_exr && b != "half" && b != "float") throw bad("half or float");
  if ((is_pfm || is_hdr) && b != "float") throw bad("float");
  // Half-float TIFF (Adobe's extension) is read by few programs: OpenImageIO
  // writes float instead, silently, unless told otherwise. brume refuses
  // rather than store other than what was asked (.exr holds half).
  if (is_tif && b == "half") throw bad("8, 16 or float (or write half to .exr)");
  if (b == "8") return codec::Type::u8;
  if (b == "16") return codec::Type::u16;
  if (b == "half") return codec::Type::f16;
  if (b == "float") return codec::Type::f32;
  throw Error("--bits '" + bits + "' is not a bit depth; use auto, 8, 16, half or float");
}

// PFM (Middlebury / Debevec): "Pf" (grey) or "PF" (RGB), "W H", a negative
// scale for little-endian floats, then rows from the bottom of the picture up.
// OpenImageIO 2.4 reads PFM but has no PFM writer.
void write_pfm(const std::string& tmp, const Image& img) {
  std::ofstream f(tmp, std::ios::binary);
  f << (img.channels == 1 ? "Pf" : "PF") << "\n" << img.width << " " << img.height << "\n-1.0\n";
  static_assert(sizeof(float) == 4);
  const uint32_t probe = 1;
  const bool little = *reinterpret_cast<const unsigned char*>(&probe) == 1;
  std::vector<float> row(static_cast<std::size_t>(img.width) * img.channels);
  for (int y = img.height - 1; y >= 0; --y) {
    std::copy(img.row(y), img.row(y) + row.size(), row.begin());
    if (!little)
      for (float& v : row) {
        unsigned char* b = reinterpret_cast<unsigned char*>(&v);
        std::swap(b[0], b[3]), std::swap(b[1], b[2]);
      }
    f.write(reinterpret_cast<const char*>(row.data()), static_cast<std::streamsize>(row.size() * 4));
  }
  f.close();
  if (!f) throw Error("write failed");
}

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

// ---- compression --------------------------------------------------------------
// NAME[:LEVEL], the spelling of OpenImageIO's "compression" attribute. Each
// format takes its own names; a name another format would take is refused,
// never replaced by a default (OpenImageIO's EXR writer falls back to zip for
// a name it does not know, silently). The encoder's time is most of a
// dataset frame's write: a 463x370 8-bit Middlebury frame took 13.5 ms to
// write at PNG's default level 6, 8.2 ms at level 1 (~6 % larger) and 7.9
// ms stored (docs/datasets.md).
namespace {

struct CompressionRule {
  const char* name;
  int min_level, max_level;  // min > max: no level
  bool lossy;
};

const std::vector<CompressionRule>& compression_rules(const std::string& e) {
  static const std::vector<CompressionRule> png = {
      {"none", 1, 0, false}, {"zip", 0, 9, false}, {"rle", 1, 0, false}, {"fast", 1, 0, false}};
  static const std::vector<CompressionRule> tif = {
      {"none", 1, 0, false}, {"lzw", 1, 0, false}, {"zip", 1, 9, false}, {"packbits", 1, 0, false}};
  static const std::vector<CompressionRule> exr = {
      {"none", 1, 0, false}, {"rle", 1, 0, false},   {"zip", 1, 9, false},   {"zips", 1, 9, false},
      {"piz", 1, 0, false},  {"pxr24", 1, 0, true},  {"b44", 1, 0, true},    {"b44a", 1, 0, true},
      {"dwaa", 1, 1000, true}, {"dwab", 1, 1000, true}};
  static const std::vector<CompressionRule> jpg = {{"jpeg", 1, 100, true}};
  static const std::vector<CompressionRule> pfm = {{"none", 1, 0, false}};
  static const std::vector<CompressionRule> hdr = {{"rle", 1, 0, false}};
  static const std::vector<CompressionRule> none;
  if (e == ".png") return png;
  if (e == ".tif" || e == ".tiff") return tif;
  if (e == ".exr") return exr;
  if (e == ".jpg" || e == ".jpeg") return jpg;
  if (e == ".pfm") return pfm;
  if (e == ".hdr") return hdr;
  return none;
}

struct Compression {
  std::string name;  // "auto" or a rule's name
  int level = -1;    // -1: none given
  bool lossy = false;
};

Compression parse_compression(const std::string& path, const std::string& text, const std::string& flag) {
  Compression c;
  if (text == "auto" || text.empty()) {
    c.name = "auto";
    return c;
  }
  const std::string e = lower_ext(path);
  const auto colon = text.find(':');
  const std::string name = text.substr(0, colon);
  auto bad = [&](const std::string& why) {
    return Error("--compression '" + text + "' for " + flag + " '" + path + "': " + why + "; " + e +
                 " files take " + compression_names(e));
  };
  const CompressionRule* rule = nullptr;
  for (const auto& r : compression_rules(e))
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
    throw bad("JPEG's compression is its quality: give it as jpeg:1..100 (OpenImageIO's default is 98)");
  }
  return c;
}

// The attributes that carry `c` to OpenImageIO's writer for extension `e`.
codec::Attribute int_attribute(const std::string& name, int v) { return {name, true, v, {}}; }
codec::Attribute text_attribute(const std::string& name, const std::string& v) { return {name, false, 0, v}; }

// PNG's deflate settings for a compression setting (io/png_direct.hpp):
// "none" is deflate's stored blocks (level 0: PNG always deflates), "zip"
// without a level and "auto" are 6, OpenImageIO's default; "rle" the Up
// filter and the run-length strategy at that level, which the strategy
// ignores; "fast" the Up filter and libdeflate's level 1 (brume's own name:
// OpenImageIO has no such setting, and a PNG it writes -- 2 or 4 channels
// -- takes "rle" for it, the nearest it has).
detail::PngDeflate png_deflate(const Compression& c) {
  detail::PngDeflate d;
  d.level = c.name == "none" ? 0 : (c.name == "zip" && c.level >= 0) ? c.level : 6;
  d.rle = c.name == "rle";
  d.fast = c.name == "fast";
  return d;
}

void apply_compression(codec::OutputSpec& spec, const std::string& e, const Compression& c) {
  if (c.name == "auto") return;
  if (e == ".png") {
    const detail::PngDeflate d = png_deflate(c);
    spec.attributes.push_back(int_attribute("png:compressionLevel", d.level));
    if (d.rle || d.fast) {  // rle: the same file as write_png_subset's (tested)
      spec.attributes.push_back(text_attribute("compression", "rle"));
      spec.attributes.push_back(int_attribute("png:filter", detail::kPngFilterUp));
    }
    return;
  }
  if (e == ".hdr") return;  // Radiance HDR's run-length encoding is the writer's only form
  spec.attributes.push_back(text_attribute("compression", c.level >= 0 ? c.name + ":" + std::to_string(c.level) : c.name));
  if ((e == ".tif" || e == ".tiff") && c.name == "zip" && c.level >= 0)
    spec.attributes.push_back(int_attribute("tiff:zipquality", c.level));
}

}  // namespace

std::string compression_names(const std::string& ext) {
  std::string s = "auto";
  for (const auto& r : compression_rules(ext)) {
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

void check_encoding(const std::string& path, const WriteOptions& opts, const std::string& flag) {
  if (path.empty()) throw Error(flag + " needs a file name");
  const std::string e = lower_ext(path);
  static const char* known[] = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".pfm", ".hdr"};
  if (std::find(std::begin(known), std::end(known), e) == std::end(known))
    throw Error(flag + " '" + path + "': unknown output type '" + e +
                "'; use .png, .jpg, .tif, .exr, .pfm or .hdr");
  const codec::Type type = storage_type(path, opts.bits, flag, opts.is_color);
  if (!opts.float_reason.empty() && (type == codec::Type::u8 || type == codec::Type::u16 || e == ".hdr"))
    throw Error(flag + " '" + path + "': " + opts.float_reason + "; write it to .exr, .pfm or .tif (float)");
  const Compression c = parse_compression(path, opts.compression, flag);
  if (c.lossy && (!opts.is_color || !opts.float_reason.empty()) && e != ".jpg" && e != ".jpeg")
    throw Error("--compression '" + opts.compression + "' for " + flag + " '" + path +
                "' is lossy, and this output is data, which brume writes losslessly; use zip, zips, piz, rle or none");
}

void check_writable(const std::string& path, const WriteOptions& opts, const std::string& flag) {
  check_encoding(path, opts, flag);
  check_output_dir(path, flag);
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw Error(flag + " '" + path + "' is a directory");
}

namespace {
// The folder of an output, created now inside a CreateOutputFolders scope
// (check_output_dir accepted it as creatable); elsewhere it exists already.
void ensure_output_folder(const std::string& path, const std::string& flag) {
  if (!t_create_folders) return;
  const fs::path dir = fs::path(path).parent_path();
  std::error_code ec;
  if (dir.empty() || fs::is_directory(dir, ec)) return;
  fs::create_directories(dir, ec);
  if (!fs::is_directory(dir, ec))
    throw Error(flag + " '" + path + "': directory '" + dir.string() + "' cannot be created: " + ec.message());
}
}  // namespace

OutputSet::~OutputSet() {
  for (auto& p : pending_) {
    std::error_code ec;
    fs::remove(p.tmp, ec);
    unregister_temp(p.slot);
  }
}

void OutputSet::add_pending(const std::string& tmp, const std::string& final_path, const std::string& flag) {
  pending_.push_back({tmp, final_path, register_temp(tmp), flag});
}

void OutputSet::write(const std::string& path, const Image& img, const WriteOptions& opts,
                      const std::string& flag) {
  check_writable(path, opts, flag);
  const std::string e = lower_ext(path);
  const codec::Type type = storage_type(path, opts.bits, flag, opts.is_color);
  if ((e == ".hdr") && img.channels != 3)
    throw Error(flag + " '" + path + "': Radiance HDR holds RGB only; write this " +
                std::to_string(img.channels) + "-channel map as .exr, .pfm or .tif");
  if (e == ".pfm" && img.channels != 1 && img.channels != 3)
    throw Error(flag + " '" + path + "': PFM holds 1 or 3 channels");
  const bool integer = type == codec::Type::u8 || type == codec::Type::u16;
  Transfer t = opts.transfer;
  if (t == Transfer::automatic) t = (integer && opts.is_color) ? Transfer::srgb : Transfer::linear;

  // The values as stored: the image itself, or an sRGB-encoded copy (8-bit:
  // the codes themselves, by srgb_encode_8, bit for bit the codes
  // OpenImageIO would make of the encoded floats).
  Image encoded;
  std::vector<std::uint8_t> codes;
  const Image* src = &img;
  if (t == Transfer::srgb && type == codec::Type::u8 && e != ".pfm") {
    codes.resize(img.data.size());
    srgb_encode_8(img.data.data(), codes.data(), codes.size());
  } else if (t == Transfer::srgb) {
    encoded = img;
    for (float& v : encoded.data) v = linear_to_srgb(std::max(v, 0.0f));
    src = &encoded;
  }

  ensure_output_folder(path, flag);
  const std::string tmp = temp_path_for(path);
  // A subset writer's failure: errno's reason (or the writer's own when
  // errno says nothing), the directory's if it has gone since the check.
  auto write_failed = [&](const std::string& why) {
    const int err = errno;
    check_output_dir(path, flag);
    return Error(flag + " '" + path + "': write failed: " +
                 (err == 0 && !why.empty() ? why : write_failure(err) + (why.empty() ? "" : " (" + why + ")")));
  };
  if (e == ".pfm") {
    add_pending(tmp, path, flag);
    try {
      errno = 0;
      write_pfm(tmp, *src);
    } catch (const Error&) {
      const int err = errno;
      check_output_dir(path, flag);  // the directory gone since the check: say so
      throw Error(flag + " '" + path + "': write failed: " + write_failure(err));
    }
    return;
  }
  if (e == ".png" && detail::png_subset_writable(img.channels, type == codec::Type::u8    ? 8
                                                              : type == codec::Type::u16 ? 16
                                                                                         : 0)) {
    // libpng itself, the file OpenImageIO would write (io/png_direct.hpp),
    // at its deflate settings: png:compressionLevel below, 6 when not given.
    detail::PngDeflate deflate = png_deflate(parse_compression(path, opts.compression, flag));
    deflate.threads = std::min(io_threads(), 64);
    add_pending(tmp, path, flag);
    std::string why;
    errno = 0;
    if (!detail::write_png_subset(tmp, img.width, img.height, img.channels, type == codec::Type::u8 ? 8 : 16,
                                  codes.empty() ? nullptr : codes.data(), src->data.data(),
                                  t == Transfer::srgb ? "sRGB" : "linear", opts.description, deflate, &why)) {
      const int err = errno;
      check_output_dir(path, flag);  // the directory gone since the check: say so
      throw Error(flag + " '" + path + "': write failed: " + write_failure(err) + (why.empty() ? "" : " (" + why + ")"));
    }
    return;
  }
  const Compression comp = parse_compression(path, opts.compression, flag);
  if (e == ".exr" && comp.level < 0 &&
      detail::exr_subset_writable(img.channels, t == Transfer::linear, comp.name)) {
    // OpenEXR itself, the file OpenImageIO would write bar its time stamp
    // (io/exr_direct.hpp): no module load.
    add_pending(tmp, path, flag);
    std::string why;
    errno = 0;
    if (!detail::write_exr_subset(tmp, img.width, img.height, img.channels, type == codec::Type::f16,
                                  src->data.data(), comp.name, opts.description, exr_threads(), &why)) {
      throw write_failed(why);
    }
    return;
  }
  if ((e == ".jpg" || e == ".jpeg") && type == codec::Type::u8 &&
      detail::jpeg_subset_writable(img.channels, opts.description.size())) {
    // libjpeg itself, the file OpenImageIO would write (io/jpeg_direct.hpp),
    // at its quality: 98 when none is given.
    add_pending(tmp, path, flag);
    std::string why;
    errno = 0;
    if (!detail::write_jpeg_subset(tmp, img.width, img.height, img.channels, codes.empty() ? nullptr : codes.data(),
                                   src->data.data(), t == Transfer::srgb, opts.description,
                                   comp.level >= 0 ? comp.level : 98, &why)) {
      throw write_failed(why);
    }
    return;
  }
  const int tiff_bits = type == codec::Type::u8 ? 8 : type == codec::Type::u16 ? 16 : type == codec::Type::f32 ? 32 : 0;
  if ((e == ".tif" || e == ".tiff") && detail::tiff_subset_writable(img.channels, tiff_bits)) {
    // libtiff itself, the file OpenImageIO would write bar its time stamp
    // (io/tiff_direct.hpp): no module load, Deflate strips on all threads.
    add_pending(tmp, path, flag);
    std::string why;
    errno = 0;
    if (!detail::write_tiff_subset(tmp, img.width, img.height, img.channels, tiff_bits,
                                   codes.empty() ? nullptr : codes.data(), src->data.data(), t == Transfer::srgb,
                                   opts.description, comp.name, comp.level, std::min(io_threads(), 64), &why)) {
      throw write_failed(why);
    }
    return;
  }
  if (e == ".hdr" && t == Transfer::linear && detail::hdr_subset_writable(src->data.data(), src->data.size())) {
    // brume itself, the file OpenImageIO would write (io/hdr_direct.hpp).
    add_pending(tmp, path, flag);
    errno = 0;
    if (!detail::write_hdr_subset(tmp, img.width, img.height, src->data.data())) {
      const int err = errno;
      check_output_dir(path, flag);  // the directory gone since the check: say so
      throw Error(flag + " '" + path + "': write failed: " + write_failure(err));
    }
    return;
  }
  std::string create_error;
  auto out = codec::api("writing '" + path + "'").create_output(path, &create_error);
  if (!out) throw Error(flag + " '" + path + "': cannot create a writer: " + create_error);
  codec::OutputSpec spec;
  spec.width = img.width, spec.height = img.height, spec.channels = img.channels, spec.type = type;
  if (img.channels == 1) spec.channel_names = {"Y"};
  spec.attributes.push_back(text_attribute("oiio:ColorSpace", t == Transfer::srgb ? "sRGB" : "linear"));
  if (!opts.description.empty()) spec.attributes.push_back(text_attribute("ImageDescription", opts.description));
  apply_compression(spec, e, comp);
  add_pending(tmp, path, flag);
  errno = 0;
  if (!out->open(tmp, spec)) {
    // The directory may have gone since check_writable (loading the codec
    // module above takes ~0.3 s): say so, as check_writable would.
    const std::string why = out->error();
    check_output_dir(path, flag);
    throw Error(flag + " '" + path + "': cannot open for writing: " + why);
  }
  const bool ok = codes.empty() ? out->write_float(src->data.data()) : out->write_u8(codes.data());
  if (!ok) {
    const int err = errno;
    throw Error(flag + " '" + path + "': write failed: " + write_failure(err) + " (" + out->error() + ")");
  }
  if (!out->close()) {
    const int err = errno;
    throw Error(flag + " '" + path + "': close failed: " + write_failure(err) + " (" + out->error() + ")");
  }
  // Some writers report a short write only through the file's size: verify it exists whole.
  std::error_code ec;
  if (!fs::exists(tmp, ec) || fs::file_size(tmp, ec) == 0 || ec)
    throw Error(flag + " '" + path + "': write failed: " + write_failure(errno));
}

void OutputSet::write_text(const std::string& path, const std::string& text, const std::string& flag) {
  ensure_output_folder(path, flag);
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(flag + " '" + path + "': directory '" + dir.string() + "' does not exist; create it first");
  const std::string tmp = temp_path_for(path);
  add_pending(tmp, path, flag);
  errno = 0;
  std::ofstream f(tmp, std::ios::binary);
  f << text;
  f.close();
  if (!f) throw Error(flag + " '" + path + "': write failed: " + write_failure(errno));
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

std::string sha256_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot read '" + path + "' to hash it");
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr);
  std::vector<char> chunk(1 << 16);
  while (in) {
    in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    if (in.gcount() > 0) EVP_DigestUpdate(ctx, chunk.data(), static_cast<std::size_t>(in.gcount()));
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
