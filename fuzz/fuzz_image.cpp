// The image readers on mutated files: read_header, read_color,
// read_scalar and read_unassociated (brume insert's object layer: PNG with
// alpha too). The first byte picks the file's extension (OpenImageIO chooses
// its reader by it, then by content), the rest is the file. OpenImageIO and
// its codecs are Debian's, uninstrumented: this finds crashes and bad
// handling in brume's use of them (sizes, channels, bit depths, limits), not
// coverage inside them. A file goes first to the row of the table of formats
// its first bytes name (src/io/formats/: libspng, libjpeg, libtiff,
// OpenEXR, brume's PFM and HDR readers), then, when the row does not take
// it, to OpenImageIO. Mutations rarely keep a chunk's CRC right, so nearly every mutated PNG
// would stop at the first CRC check, before its image data is inflated and
// unfiltered: for a .png whose first byte is 6 (mod 12), the harness
// writes every chunk's CRC anew (the chunks it can walk), so that mutated
// lengths, zlib streams and filter bytes reach the decoders.
#include <zlib.h>

#include <cstdint>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "fuzz_util.hpp"

namespace {
const char* const kExt[] = {".png", ".jpg", ".tif", ".exr", ".pfm", ".hdr"};
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Small enough that a mutated header declaring a large image is refused
  // by brume's limit rather than decoded (a decode of 500 Mpx per input would
  // stall the fuzzer); the limit's own check is what is exercised.
  brume::set_max_pixels(4'000'000);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static std::string paths[6];
  const int k = data[0] % 6;
  if (paths[k].empty()) paths[k] = brume::fuzz::temp_path(std::string("-image") + kExt[k]);
  std::vector<std::uint8_t> png;
  if (k == 0 && (data[0] / 6) % 2 == 1) {
    png.assign(data + 1, data + size);
    for (std::size_t at = 8; at + 12 <= png.size();) {
      const std::size_t len = (std::size_t{png[at]} << 24) | (std::size_t{png[at + 1]} << 16) |
                              (std::size_t{png[at + 2]} << 8) | png[at + 3];
      if (len > png.size() - at - 12) break;
      const auto c = static_cast<std::uint32_t>(crc32(0, png.data() + at + 4, static_cast<uInt>(len + 4)));
      for (int i = 0; i < 4; ++i) png[at + 8 + len + i] = static_cast<std::uint8_t>(c >> (24 - 8 * i));
      at += 12 + len;
    }
  }
  const std::string& path = png.empty() ? brume::fuzz::write_file(paths[k], data + 1, size - 1)
                                        : brume::fuzz::write_file(paths[k], png.data(), png.size());
  try {
    const brume::ImageHeader h = brume::read_header(path);
    if (h.width <= 0 || h.height <= 0 || h.channels <= 0) std::abort();
  } catch (const brume::Error&) {
  }
  try {
    const brume::Image c = brume::read_color(path);
    if (c.channels != 3 || c.data.size() != std::size_t(c.width) * c.height * 3) std::abort();
  } catch (const brume::Error&) {
  }
  try {
    const brume::Image s = brume::read_scalar(path);
    if (s.channels != 1 || s.data.size() != std::size_t(s.width) * s.height) std::abort();
  } catch (const brume::Error&) {
  }
  try {
    const brume::ChannelImage u = brume::read_unassociated(path, "--object");
    const brume::Image& i = u.img;
    if (i.channels <= 0 || i.data.size() != std::size_t(i.width) * i.height * i.channels || u.alpha >= i.channels ||
        u.info.channel_names.size() != std::size_t(i.channels))
      std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
