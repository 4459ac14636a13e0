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
#include "brume/pipeline.hpp"
#include "io/codec.hpp"
#include "io/formats/format.hpp"
#include "io/io_internal.hpp"
#include "io/srgb.hpp"

namespace brume {
namespace fs = std::filesystem;

Transfer parse_transfer(const std::string& s, const std::string& flag) { return parse_enum(transfer_names(), s, flag); }
std::string to_string(Transfer t) { return enum_name(transfer_names(), t); }

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
io::Decoded decode(const std::string& path, const std::string& name, Want want, int extra) {
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
    req.with_alpha = want == Want::with_alpha;
    req.threads = std::min(io::io_threads(), 64);
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

Image read_color(const std::string& path, Transfer transfer, FileInfo* info) {
  // An integer file's automatic transfer is sRGB, which a row decodes during
  // its read.
  check_readable(path);
  io::Decoded d = decode(path, "'" + path + "'", transfer == Transfer::linear ? Want::values : Want::srgb_linear, 3);
  Transfer t = transfer;
  if (t == Transfer::automatic) t = d.info.integer ? Transfer::srgb : Transfer::linear;
  d.info.transfer = t;
  if (info) *info = d.info;
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
  if (s.channels == 3) return std::move(s);
  Image out(s.width, s.height, 3);  // grey: the one channel three times; alpha dropped
  const int c = s.channels;
  for (std::size_t i = 0; i < s.pixels(); ++i)
    for (int k = 0; k < 3; ++k) out.data[i * 3 + k] = s.data[i * c + (c >= 3 ? k : 0)];
  return out;
}

Image read_scalar(const std::string& path, const std::string& channel, FileInfo* info) {
  check_readable(path);
  io::Decoded d = decode(path, "'" + path + "'", Want::counts, 3);
  const Image& s = d.img;
  int pick = 0;
  if (!channel.empty()) {
    const auto& names = d.info.channel_names;
    const auto it = std::find(names.begin(), names.end(), channel);
    if (it == names.end())
      throw Error("'" + path + "' has no channel named '" + channel + "'; its channels are: " + channel_list(names));
    pick = static_cast<int>(it - names.begin());
  } else if (s.channels > 1) {
    // A grey picture stored as RGB is one channel in disguise; anything else is ambiguous.
    const int nc = std::min(s.channels, 3);
    for (std::size_t i = 0; i < s.pixels(); ++i)
      for (int k = 1; k < nc; ++k) {
        const float a = s.data[i * s.channels], b = s.data[i * s.channels + k];
        if (!(a == b || (std::isnan(a) && std::isnan(b))))
          throw Error("'" + path + "' has " + std::to_string(s.channels) + " channels (" +
                      channel_list(d.info.channel_names) +
                      ") that differ; say which one holds the values with --range-channel NAME");
      }
  }
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
