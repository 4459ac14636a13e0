// PNG through libspng (Debian 12: 0.7.3, deflating with zlib).
//  - read: 8- or 16-bit grey or RGB (and, for read_unassociated, grey+alpha
//    and RGBA), any interlacing, no tRNS; libspng decodes, unfilters and
//    de-interlaces, checks every CRC, and refuses a chunk longer than the
//    file before allocating it (spng_set_chunk_limits). Values: the count
//    times the float 1/255 or 1/65535, as OpenImageIO gives them; the
//    "Description" text (tEXt, zTXt or iTXt) is the description. A palette,
//    1/2/4-bit or tRNS file goes to OpenImageIO, which reads those (and
//    associates an alpha the way brume's readers do not); a damaged PNG is an
//    error naming the file and libspng's reason.
//  - write: 1 to 4 channels (grey, grey+alpha, RGB, RGBA; alpha stored as
//    given, straight as PNG defines it), 8 or 16 bits; sRGB values with an sRGB chunk
//    (and gAMA 1/2.2, for decoders that know only gAMA), linear ones with
//    gAMA 1.0; the description as a tEXt "Description" chunk (iTXt when it
//    is not Latin-1's ASCII part), the chunk OpenImageIO reads as
//    ImageDescription. Counts are round(v x (2^bits - 1)), clamped, NaN 0
//    (io::to_count). Compression (see kAuto for the default's measurements):
//      auto          the Sub filter on every row, zlib's run-length strategy
//      zip           deflate level 6 (zip:N level N), libspng's per-row
//                    choice of the five filters: the smallest files
//      none          level 0 (stored blocks: PNG always deflates)
//      rle, fast     the Up filter, zlib's run-length strategy: on hazy
//                    dataset frames (brume batch's default, `fast`) 4-30 %
//                    smaller than Sub and ~10 % faster (the six Middlebury
//                    views after haze: 42-140 KB in 2.5-4.9 ms against
//                    60-155 KB in 3.2-5.4 ms)
// Rows are decoded and encoded one at a time (libspng's progressive calls),
// so no second copy of the image is held. Tests: tests/io/test_png.cpp.
#include <spng.h>
#include <zlib.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include "brume/error.hpp"
#include "io/formats/format.hpp"

namespace brume::io {
namespace png_row {
namespace fs = std::filesystem;

// "auto": zlib's single thread is most of a PNG run's write, and on the
// photographs and renders brume writes, Sub-filtered rows deflated with the
// run-length strategy cost a fraction of level 6's time for files 0-14 %
// larger. Measured with libspng 0.7.3 (Intel Xeon family 6 model 207,
// 2026-12-05), 1600x1120 RGB:
//                         Sub + RLE          level 6, per-row choice
//   demo haze,  8-bit     40 ms / 976 KB     249 ms / 865 KB
//   demo haze, 16-bit    106 ms / 4.34 MB    622 ms / 3.94 MB
//   KITTI frame, 8-bit    15 ms / 709 KB     103 ms / 725 KB
// (Sub alone at level 6: 176 ms / 853 KB on the first.) `zip` is there for
// the smallest file.
constexpr int kAutoFilters = SPNG_FILTER_CHOICE_SUB;
constexpr int kAutoStrategy = Z_RLE;

struct File {
  std::FILE* f = nullptr;
  ~File() {
    if (f) std::fclose(f);
  }
};
struct Ctx {
  spng_ctx* c = nullptr;
  ~Ctx() { spng_ctx_free(c); }
};

bool sniff(const unsigned char* h, std::size_t n) {
  static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  return n >= 8 && std::memcmp(h, sig, 8) == 0;
}

[[noreturn]] void fail(const std::string& path, int err) {
  throw Error("cannot read '" + path + "': a damaged PNG (" + spng_strerror(err) + ")");
}

// A decoder on `path` with the header read; channels 0 when the file is
// not one this row takes.
struct Opened {
  File file;
  Ctx ctx;
  spng_ihdr ihdr{};
  int channels = 0;
};
bool open(const std::string& path, bool with_alpha, Opened& o) {
  o.file.f = std::fopen(path.c_str(), "rb");
  if (!o.file.f) return false;
  o.ctx.c = spng_ctx_new(0);
  if (!o.ctx.c) throw Error("cannot read '" + path + "': out of memory");
  std::error_code ec;
  const auto size = static_cast<std::size_t>(fs::file_size(path, ec));
  // No chunk is longer than the file: a larger declared length is refused
  // before anything is allocated for it. The chunks kept (text, ...) hold
  // at most the file's bytes, plus libspng's bookkeeping.
  spng_set_chunk_limits(o.ctx.c, ec ? 0 : size, ec ? 0 : 2 * size + (std::size_t{1} << 20));
  spng_set_png_file(o.ctx.c, o.file.f);
  if (const int e = spng_get_ihdr(o.ctx.c, &o.ihdr)) fail(path, e);
  const int bits = o.ihdr.bit_depth;
  if (bits != 8 && bits != 16) return false;
  struct spng_trns trns {};
  const int t = spng_get_trns(o.ctx.c, &trns);  // reads the chunks up to the image data
  if (t == 0) return false;
  if (t != SPNG_ECHUNKAVAIL) fail(path, t);
  switch (o.ihdr.color_type) {
    case SPNG_COLOR_TYPE_GRAYSCALE: o.channels = 1; break;
    case SPNG_COLOR_TYPE_TRUECOLOR: o.channels = 3; break;
    case SPNG_COLOR_TYPE_GRAYSCALE_ALPHA: o.channels = with_alpha ? 2 : 0; break;
    case SPNG_COLOR_TYPE_TRUECOLOR_ALPHA: o.channels = with_alpha ? 4 : 0; break;
    default: o.channels = 0;
  }
  return o.channels > 0;
}

bool header(const std::string& path, Header& out) {
  Opened o;
  if (!open(path, true, o)) return false;
  out = {static_cast<int>(o.ihdr.width), static_cast<int>(o.ihdr.height), o.channels};
  return true;
}

std::string description(spng_ctx* c) {
  std::uint32_t n = 0;
  if (spng_get_text(c, nullptr, &n) != 0 || n == 0) return {};
  std::vector<spng_text> t(n);
  if (spng_get_text(c, t.data(), &n) != 0) return {};
  for (const spng_text& x : t)
    if (std::strcmp(x.keyword, "Description") == 0 && x.text) return std::string(x.text, x.length);
  return {};
}

bool read(const ReadRequest& r, Decoded& out) {
  Opened o;
  if (!open(r.path, r.with_alpha, o)) return false;
  const int w = static_cast<int>(o.ihdr.width), h = static_cast<int>(o.ihdr.height), c = o.channels;
  const int bits = o.ihdr.bit_depth;
  r.check(w, h, c);
  Image img(w, h, c);
  CountValues counts;
  counts.reset(bits, r.map);
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(c);
  const std::size_t row_bytes = n * static_cast<std::size_t>(bits / 8);
  // SPNG_FMT_PNG: the file's own layout, 16-bit samples in host order.
  if (o.ihdr.interlace_method == SPNG_INTERLACE_NONE) {
    if (const int e = spng_decode_image(o.ctx.c, nullptr, 0, SPNG_FMT_PNG, SPNG_DECODE_PROGRESSIVE)) fail(r.path, e);
    std::vector<unsigned char> row(row_bytes);
    for (int y = 0; y < h; ++y) {
      const int e = spng_decode_row(o.ctx.c, row.data(), row.size());
      if (e != 0 && !(e == SPNG_EOI && y == h - 1)) fail(r.path, e);
      counts.convert(row.data(), img.data.data() + static_cast<std::size_t>(y) * n, n);
    }
  } else {
    std::vector<unsigned char> all(row_bytes * static_cast<std::size_t>(h));
    if (const int e = spng_decode_image(o.ctx.c, all.data(), all.size(), SPNG_FMT_PNG, 0)) fail(r.path, e);
    counts.convert(all.data(), img.data.data(), n * static_cast<std::size_t>(h));
  }
  // The chunks after the image data: the image data's CRC and any text.
  // A file that ends there (no IEND) reads as OpenImageIO reads it.
  if (const int e = spng_decode_chunks(o.ctx.c); e != 0 && e != SPNG_IO_EOF) fail(r.path, e);
  out.img = std::move(img);
  out.info.format = "png";
  out.info.integer = true;
  out.info.bits = bits;
  static const std::vector<std::string> names[5] = {{}, {"Y"}, {"Y", "A"}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
  out.info.channel_names = names[c];
  out.info.description = description(o.ctx.c);
  out.mapped = static_cast<bool>(r.map);
  out.alpha = c == 2 || c == 4 ? c - 1 : -1;
  out.unassociated = r.with_alpha;  // PNG's alpha is straight by definition
  return true;
}

bool ascii(const std::string& s) {
  for (unsigned char ch : s)
    if (ch >= 0x80 || ch == 0) return false;
  return true;
}

bool write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  File file;
  file.f = std::fopen(tmp.c_str(), "wb");
  if (!file.f) return false;
  Ctx ctx;
  ctx.c = spng_ctx_new(SPNG_CTX_ENCODER);
  if (!ctx.c) return false;
  spng_ctx* c = ctx.c;
  const int bits = r.type == Storage::u8 ? 8 : 16;
  spng_ihdr ihdr{};
  ihdr.width = static_cast<std::uint32_t>(r.width);
  ihdr.height = static_cast<std::uint32_t>(r.height);
  ihdr.bit_depth = static_cast<std::uint8_t>(bits);
  static const std::uint8_t types[5] = {0, SPNG_COLOR_TYPE_GRAYSCALE, SPNG_COLOR_TYPE_GRAYSCALE_ALPHA,
                                        SPNG_COLOR_TYPE_TRUECOLOR, SPNG_COLOR_TYPE_TRUECOLOR_ALPHA};
  ihdr.color_type = types[r.channels];
  int e = spng_set_png_file(c, file.f);
  if (!e) e = spng_set_ihdr(c, &ihdr);
  if (!e && r.srgb) e = spng_set_srgb(c, 0);  // perceptual intent
  if (!e) e = spng_set_gama(c, r.srgb ? 1.0 / 2.2 : 1.0);
  std::string keyword = "Description", lang, translated;
  spng_text text{};
  if (!e && !r.description.empty()) {
    std::memcpy(text.keyword, keyword.c_str(), keyword.size() + 1);
    text.type = ascii(r.description) ? SPNG_TEXT : SPNG_ITXT;
    text.length = r.description.size();
    text.text = const_cast<char*>(r.description.c_str());
    text.language_tag = lang.data();
    text.translated_keyword = translated.data();
    e = spng_set_text(c, &text, 1);
  }
  const Compression& k = r.compression;
  int level = 6, filters = kAutoFilters, strategy = kAutoStrategy;  // auto
  if (k.name == "zip") level = k.level >= 0 ? k.level : 6, filters = SPNG_FILTER_CHOICE_ALL, strategy = Z_FILTERED;
  if (k.name == "none") level = 0, filters = SPNG_FILTER_CHOICE_NONE, strategy = Z_DEFAULT_STRATEGY;
  if (k.name == "rle" || k.name == "fast") filters = SPNG_FILTER_CHOICE_UP;
  if (!e) e = spng_set_option(c, SPNG_IMG_COMPRESSION_LEVEL, level);
  if (!e) e = spng_set_option(c, SPNG_IMG_COMPRESSION_STRATEGY, strategy);
  if (!e) e = spng_set_option(c, SPNG_FILTER_CHOICE, filters);
  if (!e) e = spng_encode_image(c, nullptr, 0, SPNG_FMT_PNG, SPNG_ENCODE_PROGRESSIVE | SPNG_ENCODE_FINALIZE);
  const std::size_t n = static_cast<std::size_t>(r.width) * static_cast<std::size_t>(r.channels);
  std::vector<unsigned char> row(n * static_cast<std::size_t>(bits / 8));
  for (int y = 0; y < r.height && !e; ++y) {
    store_samples(r, static_cast<std::size_t>(y) * n, n, row.data());  // 16-bit: host order (SPNG_FMT_PNG)
    e = spng_encode_row(c, row.data(), row.size());
    if (e == SPNG_EOI && y == r.height - 1) e = 0;
  }
  if (e) {
    if (e != SPNG_IO_ERROR) errno = 0;  // errno is the reason only for an I/O failure
    *why = spng_strerror(e);
    return false;
  }
  spng_ctx_free(ctx.c);  // the encoder's last bytes are in the FILE's buffer
  ctx.c = nullptr;
  const int closed = std::fclose(file.f);
  file.f = nullptr;
  return closed == 0;
}
}  // namespace png_row

const Format& png_format() {
  using namespace png_row;
  static const Format f{.name = "png", .title = "PNG", .extensions = {".png"}, .bits = {"8", "16"}, .color_bits = "16",
                        .data_bits = "16",
                        .compressions = {{"none", 1, 0, false}, {"zip", 0, 9, false}, {"rle", 1, 0, false},
                                         {"fast", 1, 0, false}},
                        .channel_counts = {1, 2, 3, 4}, .holds_data = false, .sniff = sniff, .header = header,
                        .read = read, .write = write, .auto_is = "Sub-filtered run-length deflate"};
  return f;
}

}  // namespace brume::io
