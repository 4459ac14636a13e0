// brume — the OpenEXR subset read with the OpenEXR library itself
// (io/exr_direct.hpp says which files and why).
#include "io/exr_direct.hpp"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVersion.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <fstream>
#include <memory>
#include <mutex>

namespace brume::detail {

namespace {
std::atomic<std::uint64_t> g_direct_reads{0};

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
    if (threads > 0) {
      // OpenEXR decompresses through its own global pool, which only grows
      // here (OpenImageIO, if loaded later, sets it too).
      static std::mutex m;
      std::lock_guard<std::mutex> lock(m);
      if (Imf::globalThreadCount() < threads) Imf::setGlobalThreadCount(threads);
    }
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

}  // namespace brume::detail
