// brume — the OpenEXR subsets read and written with the OpenEXR library
// itself (io/exr_direct.hpp says which files and why).
#include "io/exr_direct.hpp"

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVersion.h>

#include <algorithm>
#include <atomic>
#include <ctime>
#include <cstring>
#include <fstream>
#include <memory>
#include <mutex>

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

bool exr_subset_writable(int channels, bool linear, const std::string& compression) {
  return (channels == 1 || channels == 3) && linear && exr_compression(compression) >= 0;
}

bool write_exr_subset(const std::string& path, int width, int height, int channels, bool half, const float* px,
                      const std::string& compression, const std::string& description, int threads, std::string* why) {
  try {
    ensure_pool(threads);
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
