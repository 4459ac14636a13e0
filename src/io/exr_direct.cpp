// brume — the OpenEXR subsets read and written with the OpenEXR library
// itself (io/exr_direct.hpp says which files and why).
#include "io/exr_direct.hpp"

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfGenericOutputFile.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVersion.h>
#include <libdeflate.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <stdexcept>
#include <ctime>
#include <cstring>
#include <fstream>
#include <memory>
#include <mutex>
#include <new>

namespace brume::detail {

namespace {
std::atomic<std::uint64_t> g_direct_reads{0}, g_direct_writes{0};

// OpenEXR compresses and decompresses through its own global pool of
// threads, which only grows here (OpenImageIO, if loaded later, sets it
// too). May throw (OpenEXR's exceptions).
void ensure_pool(int threads) {
  if (threads <= 0) return;
  static std::mutex m;
  std::lock_guard<std::mutex> lock(m);
  if (Imf::globalThreadCount() < threads) Imf::setGlobalThreadCount(threads);
}

// The 8-byte preamble: the magic number and the version field, whose flags
// say tiled, multi-part and deep (non-image) before OpenEXR parses more.
bool preamble_in_subset(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char b[8];
  if (!f.read(b, 8)) return false;
  if (!Imf::isImfMagic(b)) return false;
  int version;
  std::memcpy(&version, b + 4, 4);  // little-endian on every host brume builds for (x86-64, arm64)
  return Imf::getVersion(version) == 2 && !Imf::isMultiPart(version) && !Imf::isNonImage(version) &&
         Imf::supportsFlags(Imf::getFlags(version));
}

// The channel order OpenImageIO gives, for the sets of the subset; empty for
// any other set (left to OpenImageIO).
std::vector<std::string> subset_order(const Imf::ChannelList& list, Imf::PixelType& type) {
  std::vector<std::string> names;
  bool first = true;
  for (auto it = list.begin(); it != list.end(); ++it) {
    const Imf::Channel& c = it.channel();
    if (c.xSampling != 1 || c.ySampling != 1) return {};
    if (c.type != Imf::HALF && c.type != Imf::FLOAT) return {};
    if (!first && c.type != type) return {};
    type = c.type;
    first = false;
    names.emplace_back(it.name());
  }
  if (names.size() == 1) return names;
  std::vector<std::string> sorted = names;
  std::sort(sorted.begin(), sorted.end());  // the ChannelList's own order, by name
  if (sorted == std::vector<std::string>{"B", "G", "R"}) return {"R", "G", "B"};
  if (sorted == std::vector<std::string>{"A", "B", "G", "R"}) return {"R", "G", "B", "A"};
  return {};
}

// ZIP and ZIPS scanline files: OpenEXR 3.1 inflates each block with zlib
// and undoes its predictor one byte at a time, and its frame buffer copy
// converts value by value: of a 1600 x 1120 float RGB zip file's read
// (~110 ms on 2 threads, AMD EPYC Zen 4), zlib was a third and OpenEXR's
// own loops another. Here OpenEXR still parses and checks the header and
// the offset table and hands over each block's packed bytes
// (InputFile::rawPixelData, serially: it reads the file), and brume
// decodes the blocks on `threads` threads by the format's rules: a block as
// long as its raw scanlines is stored as is, a shorter one is a zlib stream
// (inflated by libdeflate, which must give exactly the raw length) of the
// byte deltas + 128 of the even bytes followed by the odd bytes; then each
// scanline's channels (in the header's order, little-endian half or float)
// go to their place in the interleaved image, half to float exactly (Imath,
// as OpenEXR converts). The same floats as OpenEXR's readPixels (test:
// IO.ExrSubsetIsReadAsOpenImageIOReadsIt); a block that does not decode
// returns false (OpenImageIO then reads or reports the file).
struct DecompressorFree {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};
bool read_zip_blocks(Imf::InputFile& in, const std::vector<std::string>& names, bool half, float* dst, int threads) {
  const Imf::Header& h = in.header();
  const Imath::Box2i dw = h.dataWindow();
  const int W = dw.max.x - dw.min.x + 1, H = dw.max.y - dw.min.y + 1;
  const int lines = h.compression() == Imf::ZIPS_COMPRESSION ? 1 : 16;
  const int blocks = (H + lines - 1) / lines;
  const int C = static_cast<int>(names.size());
  std::vector<int> place;  // the image channel of each of the file's, in the file's order
  for (auto it = h.channels().begin(); it != h.channels().end(); ++it)
    place.push_back(static_cast<int>(std::find(names.begin(), names.end(), it.name()) - names.begin()));
  const std::size_t vb = half ? 2 : 4;
  const std::size_t row = static_cast<std::size_t>(W) * static_cast<std::size_t>(C) * vb;
  std::vector<std::vector<unsigned char>> packed(static_cast<std::size_t>(blocks));
  for (int b = 0; b < blocks; ++b) {
    const char* p = nullptr;
    int n = 0;
    in.rawPixelData(dw.min.y + b * lines, p, n);
    if (n < 0 || (n > 0 && !p)) return false;
    packed[static_cast<std::size_t>(b)].assign(reinterpret_cast<const unsigned char*>(p),
                                               reinterpret_cast<const unsigned char*>(p) + n);
  }
  std::atomic<bool> bad{false};
#pragma omp parallel num_threads(std::max(1, threads))
  {
    // (Nothing may throw out of the parallel region: an allocation that
    // fails marks the read bad.)
    std::unique_ptr<libdeflate_decompressor, DecompressorFree> z(libdeflate_alloc_decompressor());
    std::vector<unsigned char> delta, raw;
    try {
      delta.resize(row * lines), raw.resize(row * lines);
    } catch (const std::bad_alloc&) {
      z.reset();
    }
    if (!z) bad = true;
#pragma omp for schedule(dynamic, 1)
    for (int b = 0; b < blocks; ++b) {
      if (bad.load(std::memory_order_relaxed)) continue;
      const int y0 = b * lines, n = std::min(lines, H - y0);
      const std::size_t size = row * static_cast<std::size_t>(n);
      const std::vector<unsigned char>& pk = packed[static_cast<std::size_t>(b)];
      const unsigned char* src = pk.data();
      if (pk.size() != size) {
        std::size_t got = 0;
        if (pk.size() > size ||
            libdeflate_zlib_decompress(z.get(), pk.data(), pk.size(), delta.data(), size, &got) != LIBDEFLATE_SUCCESS ||
            got != size) {
          bad = true;
          continue;
        }
        for (std::size_t i = 1; i < size; ++i) delta[i] = static_cast<unsigned char>(delta[i] + delta[i - 1] - 128);
        const std::size_t half_n = size / 2;  // (even: 2- or 4-byte values)
        for (std::size_t i = 0; i < half_n; ++i) raw[2 * i] = delta[i], raw[2 * i + 1] = delta[half_n + i];
        src = raw.data();
      }
      for (int l = 0; l < n; ++l) {
        const unsigned char* line = src + static_cast<std::size_t>(l) * row;
        float* out = dst + static_cast<std::size_t>(y0 + l) * static_cast<std::size_t>(W) * C;
        for (std::size_t j = 0; j < place.size(); ++j) {
          const unsigned char* v = line + j * static_cast<std::size_t>(W) * vb;
          float* o = out + place[j];
          if (half) {
            for (int x = 0; x < W; ++x) {
              std::uint16_t bits;
              std::memcpy(&bits, v + 2 * static_cast<std::size_t>(x), 2);
              Imath::half hv;
              hv.setBits(bits);
              o[static_cast<std::size_t>(x) * C] = static_cast<float>(hv);
            }
          } else {
            for (int x = 0; x < W; ++x) std::memcpy(o + static_cast<std::size_t>(x) * C, v + 4 * static_cast<std::size_t>(x), 4);
          }
        }
      }
    }
  }
  return !bad;
}
}  // namespace

std::uint64_t exr_direct_reads() { return g_direct_reads.load(); }

bool read_exr_subset(const std::string& path, Image* out, ExrInfo& info,
                     const std::function<void(int, int, int)>& check, int threads) {
  if (!preamble_in_subset(path)) return false;
  // Any OpenEXR complaint (its Iex exceptions derive from std::exception)
  // returns false: OpenImageIO then reads the file, or reports it, as
  // before. check's brume::Error is thrown outside the try blocks.
  ExrInfo got;
  std::unique_ptr<Imf::InputFile> in;
  Imath::Box2i dw;
  try {
    ensure_pool(threads);
    in = std::make_unique<Imf::InputFile>(path.c_str(), threads);
    const Imf::Header& h = in->header();
    dw = h.dataWindow();
    if (dw != h.displayWindow() || !in->isComplete()) return false;
    Imf::PixelType type = Imf::HALF;
    got.channel_names = subset_order(h.channels(), type);
    if (got.channel_names.empty()) return false;
    const long long w = static_cast<long long>(dw.max.x) - dw.min.x + 1;
    const long long hgt = static_cast<long long>(dw.max.y) - dw.min.y + 1;
    if (w <= 0 || hgt <= 0 || w > (1 << 30) || hgt > (1 << 30)) return false;
    got.width = static_cast<int>(w);
    got.height = static_cast<int>(hgt);
    got.channels = static_cast<int>(got.channel_names.size());
    got.bits = type == Imf::HALF ? 16 : 32;
    if (const auto* c = h.findTypedAttribute<Imf::StringAttribute>("comments")) got.description = c->value();
  } catch (const std::exception&) {
    return false;
  }
  check(got.width, got.height, got.channels);
  if (!out) {
    info = std::move(got);
    return true;
  }
  Image img(got.width, got.height, got.channels);
  try {
    const Imf::Header& h = in->header();
    if (!h.hasTileDescription() &&
        (h.compression() == Imf::ZIP_COMPRESSION || h.compression() == Imf::ZIPS_COMPRESSION)) {
      if (!read_zip_blocks(*in, got.channel_names, got.bits == 16, img.data.data(), threads)) return false;
      ++g_direct_reads;
      info = std::move(got);
      *out = std::move(img);
      return true;
    }
    const std::size_t C = static_cast<std::size_t>(got.channels);
    const std::size_t xs = C * sizeof(float), ys = xs * static_cast<std::size_t>(got.width);
    // OpenEXR addresses a slice by (x, y) in data-window coordinates: the
    // base is where pixel (0, 0) would be (Imf::Slice::Make does the same
    // arithmetic).
    char* base = reinterpret_cast<char*>(img.data.data());
    const std::ptrdiff_t shift = static_cast<std::ptrdiff_t>(dw.min.x) * static_cast<std::ptrdiff_t>(xs) +
                                 static_cast<std::ptrdiff_t>(dw.min.y) * static_cast<std::ptrdiff_t>(ys);
    Imf::FrameBuffer fb;
    for (std::size_t c = 0; c < C; ++c)
      fb.insert(got.channel_names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float) - shift, xs, ys));
    in->setFrameBuffer(fb);
    in->readPixels(dw.min.y, dw.max.y);
  } catch (const std::exception&) {
    return false;
  }
  ++g_direct_reads;
  info = std::move(got);
  *out = std::move(img);
  return true;
}

namespace {
// The compressions of the subset by brume's names ("auto": OpenImageIO's
// default for EXR, zip); -1 for any other.
int exr_compression(const std::string& name) {
  static const std::pair<const char*, Imf::Compression> names[] = {
      {"auto", Imf::ZIP_COMPRESSION},   {"none", Imf::NO_COMPRESSION},    {"rle", Imf::RLE_COMPRESSION},
      {"zip", Imf::ZIP_COMPRESSION},    {"zips", Imf::ZIPS_COMPRESSION},  {"piz", Imf::PIZ_COMPRESSION},
      {"pxr24", Imf::PXR24_COMPRESSION}, {"b44", Imf::B44_COMPRESSION},   {"b44a", Imf::B44A_COMPRESSION},
      {"dwaa", Imf::DWAA_COMPRESSION},  {"dwab", Imf::DWAB_COMPRESSION}};
  for (const auto& [n, c] : names)
    if (name == n) return static_cast<int>(c);
  return -1;
}
}  // namespace

namespace {
// ZIP and ZIPS files, whose blocks brume compresses itself (below).
// OpenEXR 3.1 compresses each block with zlib's compress2 on its pool's
// threads: on a 1600 x 1120 float RGB image (the demo's blur output, 2
// threads, AMD EPYC Zen 4) 300 of a 500 ms EXR -> EXR run, nearly all of
// it zlib's deflate. libdeflate (already linked for PNG) deflates the same
// data at the same level 2-2.5x faster (one thread: 600 -> 250-300 ms).
//
// The file is OpenEXR's in every part but the deflate streams: the
// preamble and header bytes come from OpenEXR's own functions
// (writeMagicNumberAndVersionField, Header::writeTo) for the same Header,
// and each block's data is what OpenEXR's ZipCompressor makes of it (the
// scanlines of the block, each channel's values in the header's channel
// order, little-endian; the bytes split into even and odd halves; each
// byte replaced by its difference to the previous one + 128; zlib-wrapped
// deflate at the header's zipCompressionLevel, OpenEXR's default 4), kept
// only when shorter than the raw block, else the raw block, as OpenEXR
// does. Any reader of EXR inflates the same block data; the streams, and
// so the file's length, differ from zlib's by ~0.1 % (test:
// IO.ExrSubsetWritesTheFileOpenImageIOWrites). Blocks are compressed on
// `threads` threads, then written in order.
struct CompressorFree {
  void operator()(libdeflate_compressor* c) const { libdeflate_free_compressor(c); }
};
// Exposes OpenEXR's (protected) preamble writer.
struct Preamble : Imf::GenericOutputFile {
  void write(Imf::OStream& os, const Imf::Header& h) { writeMagicNumberAndVersionField(os, h); }
};

bool write_zip_blocks(const std::string& path, const Imf::Header& h, int W, int H, int C,
                      const std::vector<std::string>& names, bool half, const float* px, int threads) {
  const int lines = h.compression() == Imf::ZIPS_COMPRESSION ? 1 : 16;
  const int blocks = (H + lines - 1) / lines;
  const std::size_t vb = half ? 2 : 4;
  // The source channel of each channel in the header's (sorted) order.
  std::vector<int> order;
  for (auto it = h.channels().begin(); it != h.channels().end(); ++it)
    order.push_back(static_cast<int>(std::find(names.begin(), names.end(), it.name()) - names.begin()));
  const std::size_t row_bytes = static_cast<std::size_t>(W) * static_cast<std::size_t>(C) * vb;
  std::vector<std::vector<unsigned char>> out(static_cast<std::size_t>(blocks));
  const int level = h.zipCompressionLevel();
  std::atomic<bool> failed{false};
#pragma omp parallel num_threads(std::max(1, threads))
  {
    // (Nothing may throw out of the parallel region: an allocation that
    // fails marks the write failed.)
    std::unique_ptr<libdeflate_compressor, CompressorFree> z(libdeflate_alloc_compressor(level));
    std::vector<unsigned char> raw, split, delta;
    try {
      raw.resize(row_bytes * lines), split.resize(raw.size()), delta.resize(raw.size());
    } catch (const std::bad_alloc&) {
      z.reset();
    }
    if (!z) failed = true;
#pragma omp for schedule(dynamic, 1)
    for (int b = 0; b < blocks; ++b) {
      if (failed.load(std::memory_order_relaxed)) continue;
      const int y0 = b * lines, n = std::min(lines, H - y0);
      const std::size_t size = row_bytes * static_cast<std::size_t>(n);
      unsigned char* r = raw.data();
      for (int y = y0; y < y0 + n; ++y) {
        const float* row = px + static_cast<std::size_t>(y) * W * C;
        for (int c : order) {
          if (half) {
            for (int x = 0; x < W; ++x, r += 2) {
              const std::uint16_t bits = Imath::half(row[static_cast<std::size_t>(x) * C + c]).bits();
              std::memcpy(r, &bits, 2);
            }
          } else {
            for (int x = 0; x < W; ++x, r += 4) std::memcpy(r, row + static_cast<std::size_t>(x) * C + c, 4);
          }
        }
      }
      // OpenEXR's Zip::compress: even bytes, then odd bytes (size is even:
      // values are 2 or 4 bytes); then deltas.
      const std::size_t half_n = size / 2;
      for (std::size_t i = 0; i < half_n; ++i) split[i] = raw[2 * i], split[half_n + i] = raw[2 * i + 1];
      delta[0] = split[0];
      for (std::size_t i = 1; i < size; ++i) delta[i] = static_cast<unsigned char>(split[i] - split[i - 1] + 128);
      std::vector<unsigned char>& o = out[static_cast<std::size_t>(b)];
      try {
        o.resize(libdeflate_zlib_compress_bound(z.get(), size));
        const std::size_t got = libdeflate_zlib_compress(z.get(), delta.data(), size, o.data(), o.size());
        if (got > 0 && got < size) {
          o.resize(got);
        } else {
          o.assign(raw.data(), raw.data() + size);
        }
      } catch (const std::bad_alloc&) {
        failed = true;
      }
    }
  }
  if (failed) throw std::runtime_error("out of memory deflating the EXR blocks");
  Imf::StdOSStream head;
  Preamble().write(head, h);
  h.writeTo(head);
  const std::string hb = head.str();
  // The offset table, then each block: its first line, its size, its data.
  std::vector<std::uint64_t> offsets(static_cast<std::size_t>(blocks));
  std::uint64_t at = hb.size() + 8 * static_cast<std::uint64_t>(blocks);
  for (int b = 0; b < blocks; ++b) {
    offsets[static_cast<std::size_t>(b)] = at;
    at += 8 + out[static_cast<std::size_t>(b)].size();
  }
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "wb"), std::fclose);
  if (!f) throw std::runtime_error("cannot open " + path + " for writing: " + std::strerror(errno));
  bool ok = std::fwrite(hb.data(), 1, hb.size(), f.get()) == hb.size() &&
            std::fwrite(offsets.data(), 8, offsets.size(), f.get()) == offsets.size();
  for (int b = 0; ok && b < blocks; ++b) {
    const std::vector<unsigned char>& o = out[static_cast<std::size_t>(b)];
    const std::int32_t y = h.dataWindow().min.y + b * lines, size = static_cast<std::int32_t>(o.size());
    ok = std::fwrite(&y, 4, 1, f.get()) == 1 && std::fwrite(&size, 4, 1, f.get()) == 1 &&
         std::fwrite(o.data(), 1, o.size(), f.get()) == o.size();
  }
  const int err = errno;
  if (std::fclose(f.release()) != 0 || !ok)
    throw std::runtime_error("cannot write " + path + ": " + std::strerror(ok ? errno : err));
  return true;
}
}  // namespace

bool exr_subset_writable(int channels, bool linear, const std::string& compression) {
  return (channels == 1 || channels == 3) && linear && exr_compression(compression) >= 0;
}

bool write_exr_subset(const std::string& path, int width, int height, int channels, bool half, const float* px,
                      const std::string& compression, const std::string& description, int threads, std::string* why) {
  try {
    // Header(w, h) holds OpenImageIO's defaults for the rest: windows from
    // (0, 0), pixelAspectRatio 1, screenWindowCenter (0, 0), width 1,
    // INCREASING_Y.
    Imf::Header h(width, height);
    h.compression() = static_cast<Imf::Compression>(exr_compression(compression));
    const Imf::PixelType type = half ? Imf::HALF : Imf::FLOAT;
    const std::vector<std::string> names =
        channels == 1 ? std::vector<std::string>{"Y"} : std::vector<std::string>{"R", "G", "B"};
    for (const std::string& n : names) h.channels().insert(n, Imf::Channel(type));
    if (!description.empty()) h.insert("comments", Imf::StringAttribute(description));
    // OpenImageIO names the DWA level it compresses with (its default, 45,
    // OpenEXR's too).
    if (h.compression() == Imf::DWAA_COMPRESSION || h.compression() == Imf::DWAB_COMPRESSION)
      h.insert("dwaCompressionLevel", Imf::FloatAttribute(45.0f));
    // OpenImageIO stamps its files with the time of writing (DateTime, in
    // EXR "capDate"), in local time.
    const std::time_t now = std::time(nullptr);
    std::tm local{};
    localtime_r(&now, &local);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y:%m:%d %H:%M:%S", &local);
    h.insert("capDate", Imf::StringAttribute(stamp));
    if (h.compression() == Imf::ZIP_COMPRESSION || h.compression() == Imf::ZIPS_COMPRESSION) {
      write_zip_blocks(path, h, width, height, channels, names, half, px, threads);
      ++g_direct_writes;
      return true;
    }
    ensure_pool(threads);  // OpenEXR's compressors use its pool
    const std::size_t C = static_cast<std::size_t>(channels);
    const std::size_t n = C * static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    // OpenEXR's writer converts no pixel type: half files get halves made
    // by Imath's conversion (round to nearest even, as OpenImageIO's).
    std::vector<Imath::half> halves;
    const char* base = reinterpret_cast<const char*>(px);
    std::size_t value_bytes = sizeof(float);
    if (half) {
      halves.resize(n);
      for (std::size_t i = 0; i < n; ++i) halves[i] = Imath::half(px[i]);
      base = reinterpret_cast<const char*>(halves.data());
      value_bytes = sizeof(Imath::half);
    }
    Imf::OutputFile out(path.c_str(), h, threads);
    const std::size_t xs = C * value_bytes, ys = xs * static_cast<std::size_t>(width);
    Imf::FrameBuffer fb;
    for (std::size_t c = 0; c < C; ++c)  // (Slice takes char*; the writer only reads)
      fb.insert(names[c], Imf::Slice(type, const_cast<char*>(base) + c * value_bytes, xs, ys));
    out.setFrameBuffer(fb);
    out.writePixels(height);
  } catch (const std::exception& e) {
    if (why) *why = e.what();
    return false;
  }
  ++g_direct_writes;
  return true;
}

std::uint64_t exr_direct_writes() { return g_direct_writes.load(); }

}  // namespace brume::detail
