// brume — the PNG subset read and written with libpng itself (png_direct.hpp).
//
// libpng reports errors by longjmp to the setjmp of the function that called
// it. Each function below calls setjmp once, after every C++ object it owns
// is constructed, and between the setjmp and its returns only libpng calls,
// plain values, the buffers declared before it (resized, filled) and the
// reader's per-value map (which does not throw) run -- and read_image_data
// and the writer's `fast` and segmented image data, which call no libpng
// function after the buffers they declare -- so a longjmp skips no
// destructor; the Guard's destructor frees libpng's
// structures and the FILE on every return.
#include "io/png_direct.hpp"

#include <libdeflate.h>
#include <png.h>
#include <strings.h>
#include <omp.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
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
// allocation ("out of range"). f: positioned after the signature. Returns
// the file's size (0 when it cannot be told).
std::uint64_t check_chunk_lengths(std::FILE* f, const std::string& path) {
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
  return size;
}

// ---- The image data without libpng's row loop (read_image_data below) ----
//
// Debian 12's libpng 1.6.39 is built without its SIMD row filters, and its
// Paeth unfiltering -- the filter of almost every row of Middlebury's 8-bit
// RGB views -- branches on the data: for Art's 463 x 370 view libpng took
// 4.5 ms, of which zlib's inflate 1.9 ms and the unfiltering ~2.5 ms (AMD
// EPYC Zen 5). libdeflate (Debian's libdeflate 1.14, a whole-buffer
// DEFLATE/zlib codec) inflates the same stream in 1.0 ms, and the filters
// below, branch-free, unfilter it in 0.75 ms. The bytes are the same: PNG
// decoding is exact, and every filter is the spec's formula (PNG, ISO/IEC
// 15948, 9.2-9.4; tested against libpng on every filter, channel count and
// depth of the subset).

// The Paeth predictor (PNG 9.4) without branches: a when pa <= pb and
// pa <= pc, else b when pb <= pc, else c.
inline int paeth_predictor(int a, int b, int c) {
  const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
  const int ab = pb < pa ? b : a;
  const int pab = pb < pa ? pb : pa;
  return pc < pab ? c : ab;
}

// Undoes the filter `type` of one row of n bytes in place; prior: the row
// above, unfiltered (zeros for the first row); kBpp: bytes per pixel (1, 2,
// 3, 4, 6 or 8 in the subset, alpha included). Returns false for a filter
// type over 4.
template <int kBpp>
bool unfilter_row(int type, unsigned char* __restrict row, const unsigned char* __restrict prior, std::size_t n) {
  switch (type) {
    case 0:
      return true;
    case 1:  // Sub
      for (std::size_t i = kBpp; i < n; ++i) row[i] = static_cast<unsigned char>(row[i] + row[i - kBpp]);
      return true;
    case 2:  // Up (vectorised)
      for (std::size_t i = 0; i < n; ++i) row[i] = static_cast<unsigned char>(row[i] + prior[i]);
      return true;
    case 3:  // Average
      for (std::size_t i = 0; i < kBpp && i < n; ++i) row[i] = static_cast<unsigned char>(row[i] + (prior[i] >> 1));
      for (std::size_t i = kBpp; i < n; ++i)
        row[i] = static_cast<unsigned char>(row[i] + ((row[i - kBpp] + prior[i]) >> 1));
      return true;
    case 4:  // Paeth
      for (std::size_t i = 0; i < kBpp && i < n; ++i) row[i] = static_cast<unsigned char>(row[i] + prior[i]);
      for (std::size_t i = kBpp; i < n; ++i)
        row[i] = static_cast<unsigned char>(row[i] + paeth_predictor(row[i - kBpp], prior[i], prior[i - kBpp]));
      return true;
    default:
      return false;
  }
}

bool unfilter(int bpp, int type, unsigned char* row, const unsigned char* prior, std::size_t n) {
  switch (bpp) {
    case 1: return unfilter_row<1>(type, row, prior, n);
    case 2: return unfilter_row<2>(type, row, prior, n);
    case 3: return unfilter_row<3>(type, row, prior, n);
    case 4: return unfilter_row<4>(type, row, prior, n);
    case 6: return unfilter_row<6>(type, row, prior, n);
    default: return unfilter_row<8>(type, row, prior, n);
  }
}

std::atomic<std::uint64_t> fast_reads{0};

struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};
struct CompressorDeleter {
  void operator()(libdeflate_compressor* c) const { libdeflate_free_compressor(c); }
};

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}
void put_be32(unsigned char* p, std::uint32_t v) {
  p[0] = static_cast<unsigned char>(v >> 24), p[1] = static_cast<unsigned char>(v >> 16);
  p[2] = static_cast<unsigned char>(v >> 8), p[3] = static_cast<unsigned char>(v);
}

// One chunk (length, type, data, CRC-32 of type and data) to f.
bool write_chunk(std::FILE* f, const char* type, const unsigned char* data, std::size_t len) {
  unsigned char head[8], crc[4];
  put_be32(head, static_cast<std::uint32_t>(len));
  std::memcpy(head + 4, type, 4);
  std::uint32_t c = static_cast<std::uint32_t>(libdeflate_crc32(0, head + 4, 4));
  if (len > 0) c = static_cast<std::uint32_t>(libdeflate_crc32(c, data, len));  // (a null buffer gives 0, not c)
  put_be32(crc, c);
  return std::fwrite(head, 1, 8, f) == 8 && (len == 0 || std::fwrite(data, 1, len, f) == len) &&
         std::fwrite(crc, 1, 4, f) == 4;
}

// libpng's choice of row filter (pngwutil.c, png_write_find_filter, 1.6):
// each filter in `mask` (1 None, 2 Sub, 4 Up, 8 Average, 16 Paeth, libpng's
// PNG_FILTER_* >> 3) is applied to row r (n bytes, bpp bytes a pixel; p the
// row above, zeros above the first) and scored by the sum over its bytes of
// v < 128 ? v : 256 - v (the byte read as signed, its magnitude); the first
// least score wins (strictly less replaces, in the order None, Sub, Up,
// Average, Paeth), and a mask of one filter applies it unscored. libpng
// stops scoring a filter once its partial sum exceeds the best so far; the
// full sum then exceeds it too, so the choice is the same. Writes the
// filter byte and the filtered row to out (n + 1 bytes); tmp holds 4 n.
unsigned filter_cost(unsigned char v) { return v < 128 ? v : 256u - v; }
void choose_filter(const unsigned char* __restrict r, const unsigned char* __restrict p, std::size_t n, int bpp,
                   unsigned mask, unsigned char* __restrict out, unsigned char* __restrict tmp) {
  unsigned char* __restrict c1 = tmp;           // Sub
  unsigned char* __restrict c2 = tmp + n;       // Up
  unsigned char* __restrict c3 = tmp + 2 * n;   // Average
  unsigned char* __restrict c4 = tmp + 3 * n;   // Paeth
  const std::size_t b = std::min<std::size_t>(static_cast<std::size_t>(bpp), n);
  for (std::size_t i = 0; i < b; ++i) {  // no pixel to the left: a = c = 0
    c1[i] = r[i];
    c2[i] = static_cast<unsigned char>(r[i] - p[i]);
    c3[i] = static_cast<unsigned char>(r[i] - (p[i] >> 1));
    c4[i] = static_cast<unsigned char>(r[i] - p[i]);  // Paeth's predictor is b there
  }
#pragma omp simd
  for (std::size_t i = b; i < n; ++i) {
    const int a = r[i - b], up = p[i], c = p[i - b];
    c1[i] = static_cast<unsigned char>(r[i] - a);
    c2[i] = static_cast<unsigned char>(r[i] - up);
    c3[i] = static_cast<unsigned char>(r[i] - ((a + up) >> 1));
    const int q = up - c, s = a - c;  // libpng's p and pc
    const int pa = q < 0 ? -q : q, pb = s < 0 ? -s : s, pc = q + s < 0 ? -(q + s) : q + s;
    const int pred = (pa <= pb && pa <= pc) ? a : (pb <= pc) ? up : c;
    c4[i] = static_cast<unsigned char>(r[i] - pred);
  }
  const unsigned char* rows[5] = {r, c1, c2, c3, c4};
  int best = 0;
  if (std::popcount(mask) == 1) {
    best = std::countr_zero(mask);
  } else {
    std::size_t s0 = 0, s1 = 0, s2 = 0, s3 = 0, s4 = 0;
#pragma omp simd reduction(+ : s0, s1, s2, s3, s4)
    for (std::size_t i = 0; i < n; ++i) {
      s0 += filter_cost(r[i]), s1 += filter_cost(c1[i]), s2 += filter_cost(c2[i]);
      s3 += filter_cost(c3[i]), s4 += filter_cost(c4[i]);
    }
    const std::size_t sums[5] = {s0, s1, s2, s3, s4};
    std::size_t mins = (mask & 1u) ? s0 : SIZE_MAX - 256;  // libpng's start when None is not tried
    for (int f = 1; f < 5; ++f)
      if ((mask >> f & 1u) && sums[f] < mins) mins = sums[f], best = f;
  }
  out[0] = static_cast<unsigned char>(best);
  std::memcpy(out + 1, rows[best], n);
}

// A byte buffer left uninitialised (std::vector would clear it first: a
// pass over the filtered image data, and every page of a deflate bound of
// which only the compressed part is ever written).
struct Bytes {
  explicit Bytes(std::size_t n) : p(new unsigned char[n]), n(n) {}
  unsigned char* data() { return p.get(); }
  std::size_t size() const { return n; }
  std::unique_ptr<unsigned char[]> p;
  std::size_t n;
};

// A zlib stream of image data to f as IDAT chunks of 1 MiB (the last
// shorter), then IEND. False on a failed write (errno says why).
bool write_image_data(std::FILE* f, const unsigned char* z, std::size_t zlen) {
  errno = 0;
  constexpr std::size_t kIdat = std::size_t{1} << 20;
  for (std::size_t at = 0; at < zlen; at += kIdat)
    if (!write_chunk(f, "IDAT", z + at, std::min(kIdat, zlen - at))) return false;
  return write_chunk(f, "IEND", nullptr, 0);
}

// The image data of a non-interlaced PNG of the subset, unfiltered, written
// to `dst` (h rows of 1 filter byte + rowbytes), when nothing about it is
// unusual; false otherwise, and the caller has libpng read it (which then
// reports what is wrong: a CRC, a short or long stream, a bad filter...).
// f: positioned just after the first IDAT chunk's header, where
// png_read_info leaves it (libpng reads a FILE with fread of exactly the
// bytes it needs). Checked as libpng would fail or warn: every IDAT's CRC
// (libdeflate's CRC-32, the PNG one), the zlib stream's Adler-32 and its
// length (exactly h rows, no data left over), each row's filter type, and
// after the IDATs only ancillary chunks up to IEND (their data are not read:
// neither libpng's reader here nor OpenImageIO keeps a chunk after the image
// data). file_size: from check_chunk_lengths, so every length fits the file.
bool read_image_data(std::FILE* f, std::uint64_t file_size, std::size_t rowbytes, int bpp, std::size_t h,
                     unsigned char* dst) {
  const long pos = std::ftell(f);
  if (pos < 16 || file_size == 0 || static_cast<std::uint64_t>(pos) > file_size) return false;
  std::uint64_t at = static_cast<std::uint64_t>(pos) - 8;  // the first IDAT's header
  const std::size_t room = static_cast<std::size_t>(file_size - at);
  auto z = std::make_unique_for_overwrite<unsigned char[]>(room);
  std::size_t zlen = 0;
  unsigned char hdr[8], crc[4];
  if (std::fseek(f, static_cast<long>(at), SEEK_SET) != 0) return false;
  bool idat = true;
  for (;;) {
    if (std::fread(hdr, 1, 8, f) != 8) return false;  // no IEND
    const std::uint32_t len = be32(hdr);
    if (len > 0x7fffffffu || at + 12 + len > file_size) return false;
    const bool is_idat = std::memcmp(hdr + 4, "IDAT", 4) == 0;
    if (idat && is_idat) {
      if (std::fread(z.get() + zlen, 1, len, f) != len || std::fread(crc, 1, 4, f) != 4) return false;
      const auto c = static_cast<std::uint32_t>(libdeflate_crc32(libdeflate_crc32(0, hdr + 4, 4), z.get() + zlen, len));
      if (c != be32(crc)) return false;
      zlen += len;
    } else {
      idat = false;
      if (std::memcmp(hdr + 4, "IEND", 4) == 0) break;
      if (!(hdr[4] & 0x20)) return false;  // a critical chunk (IDAT again, PLTE, unknown) after the image data
      if (std::fseek(f, static_cast<long>(len) + 4, SEEK_CUR) != 0) return false;
    }
    at += 12 + len;
  }
  const std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> d(libdeflate_alloc_decompressor());
  if (!d) return false;
  const std::size_t stride = rowbytes + 1, want = stride * h;
  std::size_t used = 0, got = 0;
  if (libdeflate_zlib_decompress_ex(d.get(), z.get(), zlen, dst, want, &used, &got) != LIBDEFLATE_SUCCESS ||
      used != zlen || got != want)
    return false;
  const std::vector<unsigned char> zeros(rowbytes, 0);
  for (std::size_t y = 0; y < h; ++y) {
    unsigned char* row = dst + y * stride;
    if (!unfilter(bpp, row[0], row + 1, y == 0 ? zeros.data() : row + 1 - stride, rowbytes)) return false;
  }
  return true;
}

}  // namespace

bool read_png_subset(const std::string& path, Image* out, PngInfo& info,
                     const std::function<void(int, int, int)>& check, const std::function<float(float, int)>& map,
                     bool with_alpha) {
  ReadGuard g;
  g.f = std::fopen(path.c_str(), "rb");
  if (!g.f) return false;
  unsigned char sig[8];
  if (std::fread(sig, 1, 8, g.f) != 8 || png_sig_cmp(sig, 0, 8) != 0) return false;
  const std::uint64_t file_size = check_chunk_lengths(g.f, path);  // may throw (before libpng is involved)
  g.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &g, read_error, read_warning);
  if (!g.png) return false;
  g.info = png_create_info_struct(g.png);
  if (!g.info) return false;
  std::vector<unsigned char> rows;
  std::vector<png_bytep> row_ptrs;
  CountValues values;
  Image img;
  PngInfo got;
  if (setjmp(png_jmpbuf(g.png))) return false;
  png_init_io(g.png, g.f);
  png_set_sig_bytes(g.png, 8);
  png_read_info(g.png, g.info);
  png_uint_32 w = 0, h = 0;
  int depth = 0, color = 0;
  png_get_IHDR(g.png, g.info, &w, &h, &depth, &color, nullptr, nullptr, nullptr);
  const bool alpha = color == PNG_COLOR_TYPE_GRAY_ALPHA || color == PNG_COLOR_TYPE_RGB_ALPHA;
  if (g.warned || (depth != 8 && depth != 16) ||
      (color != PNG_COLOR_TYPE_GRAY && color != PNG_COLOR_TYPE_RGB && !(with_alpha && alpha)) ||
      png_get_valid(g.png, g.info, PNG_INFO_tRNS) || w == 0 || h == 0 || w > 0x7fffffff || h > 0x7fffffff)
    return false;
  got.width = static_cast<int>(w);
  got.height = static_cast<int>(h);
  got.channels = color == PNG_COLOR_TYPE_RGB_ALPHA ? 4 : color == PNG_COLOR_TYPE_RGB ? 3 : alpha ? 2 : 1;
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
  values.reset(depth, map);  // a count's value, as OpenImageIO returns it, then map
  const std::size_t row_values = static_cast<std::size_t>(w) * got.channels;
  img = Image(got.width, got.height, got.channels);
  auto convert = [&](const unsigned char* src, float* dst) { values.convert(src, dst, row_values); };
  if (passes == 1) {
    // The image data inflated and unfiltered without libpng's row loop
    // (read_image_data), into the tail of the float image's own buffer --
    // h rows of 1 + rowbytes bytes, at most 3/4 of it (8 bits; 16 bits: at
    // most half) -- and each row then copied out and converted to the front:
    // row y's floats end where raw row y + 1 begins or before (the floats
    // take 4 bytes a value, a raw row 1 + 1 or 2 bytes a value), so no
    // second image-sized buffer. Anything unusual: libpng reads the rows
    // from the first IDAT again, as before.
    const std::size_t stride = rowbytes + 1, raw = stride * h;
    auto* bytes = reinterpret_cast<unsigned char*>(img.data.data());
    unsigned char* tail = bytes + img.data.size() * sizeof(float) - raw;
    const long idat = std::ftell(g.f);
    rows.resize(rowbytes);
    if (read_image_data(g.f, file_size, rowbytes, got.channels * (depth / 8), h, tail)) {
      const bool swap = depth == 16 && std::endian::native == std::endian::little;  // PNG's counts are big-endian
      for (png_uint_32 y = 0; y < h; ++y) {
        const unsigned char* src = tail + y * stride + 1;
        if (swap)
          for (std::size_t i = 0; i < rowbytes; i += 2) rows[i] = src[i + 1], rows[i + 1] = src[i];
        else
          std::memcpy(rows.data(), src, rowbytes);
        convert(rows.data(), img.data.data() + y * row_values);
      }
      *out = std::move(img);
      info = std::move(got);
      fast_reads.fetch_add(1, std::memory_order_relaxed);
      return true;
    }
    if (idat < 0 || std::fseek(g.f, idat, SEEK_SET) != 0) return false;
    // libpng row by row through one row buffer.
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

std::uint64_t png_fast_reads() { return fast_reads.load(std::memory_order_relaxed); }

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
  const std::size_t stride_bytes = row_values * (bits / 8) + 1;  // a filtered row: its filter byte, its counts
  // Row y's counts as PNG stores them (16 bits: big-endian), into dst.
  auto counts_into = [&](std::size_t y, unsigned char* dst) {
    const std::size_t base = y * row_values;
    if (codes) {
      std::memcpy(dst, codes + base, row_values);
    } else if (bits == 8) {
      for (std::size_t i = 0; i < row_values; ++i) dst[i] = static_cast<unsigned char>(oiio_count(values[base + i], 255.0f));
    } else {
      for (std::size_t i = 0; i < row_values; ++i) {
        const unsigned c = oiio_count(values[base + i], 65535.0f);
        dst[2 * i] = static_cast<unsigned char>(c >> 8), dst[2 * i + 1] = static_cast<unsigned char>(c);
      }
    }
  };
  auto fill_row = [&](std::size_t y) {  // into `row`
    counts_into(y, row.data());
    return row.data();
  };
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
  if (deflate.fast) {
    // `fast` (png_direct.hpp): the rows Up-filtered into one buffer (counts
    // big-endian, as PNG stores them), deflated by libdeflate in one call,
    // and written as IDAT chunks of 1 MiB and IEND after the chunks libpng
    // wrote (its writes are plain fwrite calls on f, in order).
    const std::size_t rowbytes = row_values * (bits / 8), stride = rowbytes + 1;
    const std::size_t h = static_cast<std::size_t>(height);
    Bytes raw(stride * h);
    std::vector<unsigned char> prev(rowbytes, 0);
    for (std::size_t y = 0; y < h; ++y) {
      const unsigned char* r = fill_row(y);
      unsigned char* o = raw.data() + y * stride;
      o[0] = 2;  // Up
      for (std::size_t i = 0; i < rowbytes; ++i) o[1 + i] = static_cast<unsigned char>(r[i] - prev[i]);
      prev.swap(row);
    }
    const std::unique_ptr<libdeflate_compressor, CompressorDeleter> c(libdeflate_alloc_compressor(1));
    if (!c) {
      *error = "cannot allocate libdeflate's compressor";
      return false;
    }
    Bytes z(libdeflate_zlib_compress_bound(c.get(), raw.size()));
    const std::size_t zlen = libdeflate_zlib_compress(c.get(), raw.data(), raw.size(), z.data(), z.size());
    if (zlen == 0) {  // (cannot happen within the bound)
      *error = "libdeflate could not compress the image data";
      return false;
    }
    if (!write_image_data(g.f, z.data(), zlen)) {
      error->clear();  // errno says why
      return false;
    }
  } else if (stride_bytes * static_cast<std::size_t>(height) > kDeflateSegment) {
    // zlib's deflate in segments on several threads (png_direct.hpp): the
    // rows' counts, libpng's filter choice per row, each segment of
    // kDeflateSegment filtered bytes deflated by its own stream primed with
    // the 32 KiB before it, ended by a sync flush (the last by the end of
    // the stream), the Adler-32 of all of them after.
    const std::size_t rowbytes = stride_bytes - 1, h = static_cast<std::size_t>(height);
    const int bpp = channels * bits / 8, t = std::max(1, deflate.threads);
    // libpng's filters (png_write_IHDR, png_write_start_row): all five at
    // 8 and 16 bits, Up alone for rle; none that reads the row above for a
    // one-row image, none that reads the pixel to the left for one column.
    unsigned mask = deflate.rle ? 4u : 31u;
    if (height == 1) mask &= ~(4u | 8u | 16u);
    if (width == 1) mask &= ~(2u | 8u | 16u);
    if (mask == 0) mask = 1u;
    // Per thread: a block of consecutive rows, their counts made a row at a
    // time (with the row above the block's first) beside the four filtered
    // candidates, so that no image of counts is held: the extra memory is
    // the filtered image data and its deflated copy.
    Bytes raw(stride_bytes * h);
    std::vector<unsigned char> zero(rowbytes, 0);
    std::vector<unsigned char> tmp(6 * rowbytes * static_cast<std::size_t>(t));
#pragma omp parallel num_threads(t)
    {
      const auto k = static_cast<std::size_t>(omp_get_thread_num()), n = static_cast<std::size_t>(omp_get_num_threads());
      unsigned char* own = tmp.data() + k * 6 * rowbytes;
      unsigned char* buf[2] = {own + 4 * rowbytes, own + 5 * rowbytes};
      auto counts_of = [&](std::size_t y, unsigned char* b) -> const unsigned char* {
        if (codes) return codes + y * rowbytes;
        counts_into(y, b);
        return b;
      };
      const std::size_t block = (h + n - 1) / n, y0 = std::min(h, k * block), y1 = std::min(h, y0 + block);
      const unsigned char* prev = y0 > 0 && y0 < y1 ? counts_of(y0 - 1, buf[1]) : zero.data();
      for (std::size_t y = y0; y < y1; ++y) {
        const unsigned char* cur = counts_of(y, buf[(y - y0) & 1]);  // never the buffer prev is in
        choose_filter(cur, prev, rowbytes, bpp, mask, raw.data() + y * stride_bytes, own);
        prev = cur;
      }
    }
    const std::size_t total = raw.size(), nseg = (total + kDeflateSegment - 1) / kDeflateSegment;
    std::vector<std::size_t> at(nseg + 1, 0), len(nseg, 0);
    for (std::size_t i = 0; i < nseg; ++i)  // room for each segment: zlib's bound, plus the flush's few bytes
      at[i + 1] = at[i] + compressBound(static_cast<uLong>(std::min(kDeflateSegment, total - i * kDeflateSegment))) + 64;
    Bytes z(at[nseg] + 4);
    std::atomic<bool> failed{false};
#pragma omp parallel for num_threads(t) schedule(dynamic, 1)
    for (std::size_t i = 0; i < nseg; ++i) {
      const std::size_t b = i * kDeflateSegment, e = std::min(total, b + kDeflateSegment);
      const bool last = i + 1 == nseg;
      z_stream zs{};
      // The first segment carries the zlib header (window 15, as libpng's
      // for any image this size), the others are raw deflate.
      if (deflateInit2(&zs, deflate.level, Z_DEFLATED, i == 0 ? 15 : -15, 8, deflate.rle ? Z_RLE : Z_DEFAULT_STRATEGY) !=
          Z_OK) {
        failed = true;
        continue;
      }
      const std::size_t dict = std::min<std::size_t>(32768, b);
      bool ok = i == 0 || deflateSetDictionary(&zs, raw.data() + b - dict, static_cast<uInt>(dict)) == Z_OK;
      zs.next_in = raw.data() + b;
      zs.avail_in = static_cast<uInt>(e - b);
      zs.next_out = z.data() + at[i];
      zs.avail_out = static_cast<uInt>(at[i + 1] - at[i]);
      const int rc = ok ? ::deflate(&zs, last ? Z_FINISH : Z_SYNC_FLUSH) : Z_STREAM_ERROR;
      ok = ok && rc == (last ? Z_STREAM_END : Z_OK) && zs.avail_in == 0 && zs.avail_out > 0;
      len[i] = zs.total_out;
      deflateEnd(&zs);
      if (!ok) failed = true;
    }
    if (failed) {
      *error = "zlib could not compress the image data";
      return false;
    }
    std::size_t zlen = 0;
    for (std::size_t i = 0; i < nseg; ++i) {  // the segments side by side (each moves left, or stays)
      std::memmove(z.data() + zlen, z.data() + at[i], len[i]);
      zlen += len[i];
    }
    put_be32(z.data() + zlen, static_cast<std::uint32_t>(libdeflate_adler32(1, raw.data(), total)));
    zlen += 4;
    if (!write_image_data(g.f, z.data(), zlen)) {
      error->clear();  // errno says why
      return false;
    }
  } else {
    for (std::size_t y = 0; y < static_cast<std::size_t>(height); ++y) png_write_row(g.png, fill_row(y));
    png_write_end(g.png, nullptr);
  }
  std::FILE* f = g.f;
  g.f = nullptr;
  if (std::fclose(f) != 0) {
    error->clear();  // errno says why
    return false;
  }
  return true;
}

}  // namespace brume::detail
