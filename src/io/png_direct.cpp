// brume — the PNG subset read and written with libpng itself (png_direct.hpp).
//
// libpng reports errors by longjmp to the setjmp of the function that called
// it. Each function below calls setjmp once, after every C++ object it owns
// is constructed, and between the setjmp and its returns only libpng calls,
// plain values, the buffers declared before it (resized, filled) and the
// reader's per-value map (which does not throw) run, so a longjmp skips no
// destructor; the Guard's destructor frees libpng's structures and the FILE
// on every return.
#include "io/png_direct.hpp"

#include <png.h>
#include <strings.h>
#include <zlib.h>

#include <bit>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "brume/error.hpp"

namespace brume::detail {

namespace {

struct ReadGuard {
  std::FILE* f = nullptr;
  png_structp png = nullptr;
  png_infop info = nullptr;
  bool warned = false;
  ~ReadGuard() {
    if (png) png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    if (f) std::fclose(f);
  }
};

// Errors end the read (back to its setjmp); warnings are remembered, and a
// read that had any is handed to OpenImageIO (png_direct.hpp).
void read_error(png_structp png, png_const_charp) { longjmp(png_jmpbuf(png), 1); }
void read_warning(png_structp png, png_const_charp) {
  static_cast<ReadGuard*>(png_get_error_ptr(png))->warned = true;
}

struct WriteGuard {
  std::FILE* f = nullptr;
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::string message;
  ~WriteGuard() {
    if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
    if (f) std::fclose(f);
  }
};

void write_error(png_structp png, png_const_charp msg) {
  static_cast<WriteGuard*>(png_get_error_ptr(png))->message = msg ? msg : "libpng error";
  longjmp(png_jmpbuf(png), 1);
}
void write_warning(png_structp, png_const_charp) {}

// Every chunk of a PNG must fit in the file. libpng allocates a chunk's
// declared length before it reads the data, so a 347-byte file whose tEXt
// chunk declared 2 GB made brume's reader -- and OpenImageIO's, which would
// read it next -- allocate 2 GB before failing at the end of the file
// (found by fuzz_image; OpenImageIO alone peaked at 2.0 GB of RSS on it).
// The chunk headers are walked first (8 bytes each, up to IEND): a chunk
// that runs past the end of the file makes the file truncated or corrupt,
// and it is refused here, by name, without either reader allocating it.
// A length over 2^31 - 1 is left to libpng, which refuses it before any
// allocation ("out of range"). f: positioned after the signature.
void check_chunk_lengths(std::FILE* f, const std::string& path) {
  const long end = std::fseek(f, 0, SEEK_END) == 0 ? std::ftell(f) : -1;
  const auto size = static_cast<std::uint64_t>(end < 0 ? 0 : end);  // unknown: no check
  std::uint64_t at = 8;
  unsigned char h[8];
  while (at + 8 <= size) {
    if (std::fseek(f, static_cast<long>(at), SEEK_SET) != 0 || std::fread(h, 1, 8, f) != 8) break;
    const std::uint64_t len = (std::uint64_t{h[0]} << 24) | (std::uint64_t{h[1]} << 16) | (std::uint64_t{h[2]} << 8) | h[3];
    if (len > 0x7fffffffu) break;
    if (at + 12 + len > size) {
      std::string type;
      for (int i = 4; i < 8; ++i) type += (h[i] >= 0x20 && h[i] < 0x7f) ? static_cast<char>(h[i]) : '?';
      throw Error("cannot read '" + path + "': its " + type + " chunk at byte " + std::to_string(at) + " declares " +
                  std::to_string(len) + " bytes of data, but the file ends " + std::to_string(size - at - 8) +
                  " bytes after the chunk's header: the file is truncated or corrupt");
    }
    at += 12 + len;
    if (std::memcmp(h + 4, "IEND", 4) == 0) break;
  }
  std::fseek(f, 8, SEEK_SET);
}

}  // namespace

bool read_png_subset(const std::string& path, Image* out, PngInfo& info,
                     const std::function<void(int, int, int)>& check, const std::function<float(float, int)>& map) {
  ReadGuard g;
  g.f = std::fopen(path.c_str(), "rb");
  if (!g.f) return false;
  unsigned char sig[8];
  if (std::fread(sig, 1, 8, g.f) != 8 || png_sig_cmp(sig, 0, 8) != 0) return false;
  check_chunk_lengths(g.f, path);  // may throw (before libpng is involved)
  g.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &g, read_error, read_warning);
  if (!g.png) return false;
  g.info = png_create_info_struct(g.png);
  if (!g.info) return false;
  std::vector<unsigned char> rows;
  std::vector<png_bytep> row_ptrs;
  std::vector<float> table;           // [count]: its value (8 bits: every count; 16 bits with a map: as met)
  std::vector<unsigned char> known;   // 16 bits with a map: table[count] computed
  Image img;
  PngInfo got;
  if (setjmp(png_jmpbuf(g.png))) return false;
  png_init_io(g.png, g.f);
  png_set_sig_bytes(g.png, 8);
  png_read_info(g.png, g.info);
  png_uint_32 w = 0, h = 0;
  int depth = 0, color = 0;
  png_get_IHDR(g.png, g.info, &w, &h, &depth, &color, nullptr, nullptr, nullptr);
  if (g.warned || (depth != 8 && depth != 16) || (color != PNG_COLOR_TYPE_GRAY && color != PNG_COLOR_TYPE_RGB) ||
      png_get_valid(g.png, g.info, PNG_INFO_tRNS) || w == 0 || h == 0 || w > 0x7fffffff || h > 0x7fffffff)
    return false;
  got.width = static_cast<int>(w);
  got.height = static_cast<int>(h);
  got.channels = color == PNG_COLOR_TYPE_RGB ? 3 : 1;
  got.bits = depth;
  // The text before the image data, as OpenImageIO reads it (it reads the
  // chunks after the image data without keeping them); the last
  // "Description" wins, as its attribute would.
  png_textp text = nullptr;
  const int ntext = png_get_text(g.png, g.info, &text, nullptr);
  for (int i = 0; i < ntext; ++i)
    if (text[i].key && ::strcasecmp(text[i].key, "Description") == 0) got.description = text[i].text ? text[i].text : "";
  check(got.width, got.height, got.channels);  // may throw (no libpng call is in progress)
  if (!out) {
    info = std::move(got);
    return true;
  }
  if (depth == 16 && std::endian::native == std::endian::little) png_set_swap(g.png);
  const int passes = png_set_interlace_handling(g.png);
  png_read_update_info(g.png, g.info);
  const std::size_t rowbytes = png_get_rowbytes(g.png, g.info);
  if (rowbytes != static_cast<std::size_t>(w) * got.channels * (depth / 8)) return false;
  // A count's value: the count times the float 1/255 or 1/65535, as
  // OpenImageIO returns it, then `map` (the caller's per-value function,
  // evaluated once per distinct count, so the result is map's bit for bit).
  const float k = depth == 8 ? 1.0f / 255.0f : 1.0f / 65535.0f;
  if (depth == 8) {
    table.resize(256);
    for (unsigned c = 0; c < 256; ++c) table[c] = map ? map(static_cast<float>(c) * k, 8) : static_cast<float>(c) * k;
  } else if (map) {
    table.resize(65536);
    known.assign(65536, 0);
  }
  const std::size_t row_values = static_cast<std::size_t>(w) * got.channels;
  img = Image(got.width, got.height, got.channels);
  auto convert = [&](const unsigned char* src, float* dst) {
    if (depth == 8) {
      for (std::size_t i = 0; i < row_values; ++i) dst[i] = table[src[i]];
      return;
    }
    for (std::size_t i = 0; i < row_values; ++i) {
      std::uint16_t c;
      std::memcpy(&c, src + 2 * i, 2);
      if (!map) {
        dst[i] = static_cast<float>(c) * k;
      } else {
        if (!known[c]) table[c] = map(static_cast<float>(c) * k, 16), known[c] = 1;
        dst[i] = table[c];
      }
    }
  };
  if (passes == 1) {
    // Row by row through one row buffer: no second image-sized buffer.
    rows.resize(rowbytes);
    for (png_uint_32 y = 0; y < h; ++y) {
      png_read_row(g.png, rows.data(), nullptr);
      convert(rows.data(), img.data.data() + y * row_values);
    }
  } else {
    // Adam7: the passes fill the whole image before any row is complete.
    rows.resize(rowbytes * h);
    row_ptrs.resize(h);
    for (png_uint_32 y = 0; y < h; ++y) row_ptrs[y] = rows.data() + y * rowbytes;
    png_read_image(g.png, row_ptrs.data());
    for (png_uint_32 y = 0; y < h; ++y) convert(row_ptrs[y], img.data.data() + y * row_values);
  }
  png_read_end(g.png, nullptr);
  if (g.warned) return false;
  *out = std::move(img);
  info = std::move(got);
  return true;
}

static_assert(kPngFilterUp == PNG_FILTER_UP);

bool png_subset_writable(int channels, int bits) { return (channels == 1 || channels == 3) && (bits == 8 || bits == 16); }

bool write_png_subset(const std::string& path, int width, int height, int channels, int bits,
                      const std::uint8_t* codes, const float* values, const std::string& colorspace,
                      const std::string& description, PngDeflate deflate, std::string* error) {
  WriteGuard g;
  errno = 0;
  g.f = std::fopen(path.c_str(), "wb");
  if (!g.f) {
    error->clear();  // errno says why
    return false;
  }
  g.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &g, write_error, write_warning);
  if (g.png) g.info = png_create_info_struct(g.png);
  if (!g.png || !g.info) {
    *error = "cannot create libpng's write structures";
    return false;
  }
  const std::size_t row_values = static_cast<std::size_t>(width) * channels;
  std::vector<unsigned char> row(row_values * (bits / 8));
  std::string cs = colorspace, desc = description;  // (libpng keeps char* to them until png_write_info)
  png_text text[2];
  std::memset(text, 0, sizeof text);
  char key_cs[] = "oiio:ColorSpace", key_desc[] = "Description";
  text[0].compression = PNG_TEXT_COMPRESSION_NONE;
  text[0].key = key_cs;
  text[0].text = cs.data();
  text[1].compression = PNG_TEXT_COMPRESSION_NONE;
  text[1].key = key_desc;
  text[1].text = desc.data();
  if (setjmp(png_jmpbuf(g.png))) {
    if (g.message.empty()) g.message = "libpng error";
    *error = g.message;
    return false;
  }
  png_init_io(g.png, g.f);
  png_set_compression_level(g.png, deflate.level);
  png_set_compression_strategy(g.png, deflate.rle ? Z_RLE : Z_DEFAULT_STRATEGY);
  if (deflate.rle) png_set_filter(g.png, PNG_FILTER_TYPE_BASE, PNG_FILTER_UP);
  png_set_IHDR(g.png, g.info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height), bits,
               channels == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  if (colorspace == "sRGB")
    png_set_sRGB_gAMA_and_cHRM(g.png, g.info, PNG_sRGB_INTENT_ABSOLUTE);
  else
    png_set_gAMA(g.png, g.info, 1.0);
  png_set_oFFs(g.png, g.info, 0, 0, PNG_OFFSET_PIXEL);
  png_set_text(g.png, g.info, text, description.empty() ? 1 : 2);
  png_write_info(g.png, g.info);
  if (bits == 16 && std::endian::native == std::endian::little) png_set_swap(g.png);
  for (int y = 0; y < height; ++y) {
    const std::size_t base = static_cast<std::size_t>(y) * row_values;
    if (codes) {
      std::memcpy(row.data(), codes + base, row_values);
    } else if (bits == 8) {
      for (std::size_t i = 0; i < row_values; ++i) row[i] = static_cast<unsigned char>(oiio_count(values[base + i], 255.0f));
    } else {
      for (std::size_t i = 0; i < row_values; ++i) {
        const auto c = static_cast<std::uint16_t>(oiio_count(values[base + i], 65535.0f));
        std::memcpy(row.data() + 2 * i, &c, 2);
      }
    }
    png_write_row(g.png, row.data());
  }
  png_write_end(g.png, nullptr);
  std::FILE* f = g.f;
  g.f = nullptr;
  if (std::fclose(f) != 0) {
    error->clear();  // errno says why
    return false;
  }
  return true;
}

}  // namespace brume::detail
