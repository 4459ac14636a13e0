// brume — reading image and range-map files: the table of formats
// (io/formats/format.hpp) picks a row by the file's first bytes; what no row
// takes goes to OpenImageIO, in the module loaded on first use
// (io/codec.hpp). Values: integer files give the count times 1/(2^bits - 1)
// (or, for read_scalar, the counts), float files their values; read_color
// then applies the transfer (brume/io.hpp).
#include <omp.h>

#include <openssl/evp.h>

#include <algorithm>
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
#include "io/formats/exr.hpp"
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
void check_readable(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw FileNotFound("cannot read '" + path + "': no such file");
  if (fs::is_directory(path, ec))
    throw Error("cannot read '" + path + "': it is a directory, not an image file");
}

// The file opened for reading (its header parsed), or an error naming it;
// an OpenEXR file passes the attribute guard first (io/formats/exr.hpp).
std::unique_ptr<codec::Input> open_image(const std::string& path) {
  check_readable(path);
  io::check_exr_attributes(path);
  std::string e;
  auto in = codec::api("reading '" + path + "'").open_input(path, false, &e);
  if (!in) throw Error("cannot read '" + path + "': " + (e.empty() ? "unknown or unsupported image format" : e));
  return in;
}

// The row for a file, nullptr when none takes it (OpenImageIO's turn).
const io::Format* row_of(const std::string& path) {
  return io::format_of_file(path);
}

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

}  // namespace

ImageHeader read_header(const std::string& path) {
  check_readable(path);
  if (const io::Format* f = row_of(path)) {
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

// What read_raw returns: the values as OpenImageIO reads them, the integer
// counts (read_scalar), or, for read_color, the values already decoded from
// sRGB where a row can do that during its decode (per count, srgb_to_linear
// of the value: bit for bit what decoding them after gives).
enum class RawValues { values, counts, srgb_linear };

struct Raw {
  Image img;
  FileInfo info;
  bool linear = false;  // already decoded from sRGB (RawValues::srgb_linear by a row)
};

// Every channel of the first subimage as float.
Raw read_raw(const std::string& path, RawValues want) {
  check_readable(path);
  // Before any allocation, from a header: the size limits, then memory for
  // the decoded file (all channels) and the caller's converted copy (<= 3).
  const auto check_size = [&](int w, int h, int c) {
    check_declared_size(path, w, h, c);
    const std::uint64_t px = static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h);
    check_memory(px * 4 * static_cast<std::uint64_t>(c + 3), "reading '" + path + "'");
  };
  if (const io::Format* f = row_of(path)) {
    io::ReadRequest req;
    req.path = path;
    req.check = check_size;
    if (want == RawValues::counts)
      req.map = [](float v, int bits) { return static_cast<float>(std::nearbyint(v * (std::ldexp(1.0, bits) - 1.0))); };
    if (want == RawValues::srgb_linear) req.map = [](float v, int) { return srgb_to_linear(v); };
    req.threads = std::min(io::io_threads(), 64);
    io::Decoded d;
    if (f->read(req, d)) {
      io::note_reader(f->name);
      Raw r;
      r.img = std::move(d.img);
      r.info = std::move(d.info);
      r.info.path = path;
      r.linear = d.mapped && want == RawValues::srgb_linear;
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
  io::note_reader("oiio");
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
  if (want == RawValues::counts && r.info.integer) {
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
  if (const io::Format* f = row_of(path)) {
    io::ReadRequest req;
    req.path = path;
    req.check = check_size;
    req.with_alpha = true;
    req.threads = std::min(io::io_threads(), 64);
    io::Decoded d;
    if (f->read(req, d)) {
      io::note_reader(f->name);
      r.img = std::move(d.img);
      r.info = std::move(d.info);
      r.info.path = path;
      r.alpha = d.alpha;
      r.unassociated = d.unassociated;
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
  io::note_reader("oiio");
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
      io::SrgbDecodeTable decode(r.info.bits <= 8 ? 8 : 16);
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
    io::SrgbDecodeTable decode(r.info.bits <= 8 ? 8 : 16);
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
