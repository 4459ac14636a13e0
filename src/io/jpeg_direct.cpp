// brume — the JPEG subset read with libjpeg itself (io/jpeg_direct.hpp says
// which files and why).
#include "io/jpeg_direct.hpp"

#include <csetjmp>
#include <cstdio>
// jpeglib.h needs FILE and size_t declared first.
#include <jpeglib.h>

#include <atomic>
#include <cstring>
#include <memory>
#include <vector>

namespace brume::detail {

namespace {
std::atomic<std::uint64_t> g_reads{0};

// libjpeg reports errors through error_exit (which must not return: a
// longjmp back to read_jpeg_subset) and warnings through emit_message
// with level -1; any warning (a corrupt-data one, e.g. a premature end of
// data, after which libjpeg would fill the rest with grey) declines the file.
struct ErrorMgr {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  bool warned = false;
};
[[noreturn]] void error_exit(j_common_ptr c) { std::longjmp(reinterpret_cast<ErrorMgr*>(c->err)->jump, 1); }
void emit_message(j_common_ptr c, int level) {
  if (level < 0) reinterpret_cast<ErrorMgr*>(c->err)->warned = true;
}

// The ImageDescription (tag 270) of an Exif APP1 block's first directory
// (IFD0; the TIFF structure after "Exif\0\0": byte order, 42, the IFD's
// offset, then 12-byte entries: tag, type, count, value or its offset), as
// a C string. Returns 0: no such tag, 1: found (*text), -1: the block does
// not parse or the tag is not ASCII (the file goes to OpenImageIO).
int exif_description(const unsigned char* p, unsigned n, std::string* text) {
  if (n < 6 || std::memcmp(p, "Exif\0\0", 6) != 0) return 0;
  p += 6, n -= 6;
  if (n < 8) return -1;
  const bool le = p[0] == 'I' && p[1] == 'I';
  if (!le && !(p[0] == 'M' && p[1] == 'M')) return -1;
  auto u16 = [&](unsigned at) { return le ? unsigned(p[at]) | unsigned(p[at + 1]) << 8 : unsigned(p[at]) << 8 | p[at + 1]; };
  auto u32 = [&](unsigned at) { return le ? u16(at) | u16(at + 2) << 16 : u16(at) << 16 | u16(at + 2); };
  const unsigned ifd = u32(4);
  if (ifd > n || n - ifd < 2) return -1;
  const unsigned count = u16(ifd);
  if ((n - ifd - 2) / 12 < count) return -1;
  for (unsigned k = 0; k < count; ++k) {
    const unsigned e = ifd + 2 + 12 * k;
    if (u16(e) != 270) continue;
    const unsigned type = u16(e + 2), len = u32(e + 4);
    if (type != 2) return -1;
    const unsigned at = len <= 4 ? e + 8 : u32(e + 8);
    if (at > n || n - at < len) return -1;
    *text = std::string(reinterpret_cast<const char*>(p + at), len).c_str();
    return 1;
  }
  return 0;
}

struct File {
  std::FILE* f = nullptr;
  ~File() {
    if (f) std::fclose(f);
  }
};
struct Decompress {
  jpeg_decompress_struct c{};
  bool made = false;
  ~Decompress() {
    if (made) jpeg_destroy_decompress(&c);
  }
};
}  // namespace

std::uint64_t jpeg_direct_reads() { return g_reads.load(); }

bool read_jpeg_subset(const std::string& path, Image* out, JpegInfo& info,
                      const std::function<void(int, int, int)>& check,
                      const std::function<float(float, int)>& map) {
  File file;
  file.f = std::fopen(path.c_str(), "rb");
  if (!file.f) return false;
  unsigned char soi[2];
  if (std::fread(soi, 1, 2, file.f) != 2 || soi[0] != 0xFF || soi[1] != 0xD8) return false;
  std::rewind(file.f);
  // Every object with a destructor is made before setjmp, so that a
  // longjmp from libjpeg skips none; check() may throw (an ordinary
  // exception, which unwinds them all).
  Decompress d;
  ErrorMgr err;
  JpegInfo got;
  std::vector<unsigned char> row;
  Image img;
  float table[256];
  d.c.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = error_exit;
  err.pub.emit_message = emit_message;
  if (setjmp(err.jump)) return false;
  jpeg_create_decompress(&d.c);
  d.made = true;
  jpeg_stdio_src(&d.c, file.f);
  jpeg_save_markers(&d.c, JPEG_COM, 0xFFFF);
  jpeg_save_markers(&d.c, JPEG_APP0 + 1, 0xFFFF);
  if (jpeg_read_header(&d.c, TRUE) != JPEG_HEADER_OK || err.warned) return false;
  const bool grey = d.c.jpeg_color_space == JCS_GRAYSCALE && d.c.num_components == 1;
  const bool colour =
      (d.c.jpeg_color_space == JCS_YCbCr || d.c.jpeg_color_space == JCS_RGB) && d.c.num_components == 3;
  if ((!grey && !colour) || d.c.data_precision != 8 || d.c.image_width == 0 || d.c.image_height == 0 ||
      d.c.image_width > 0x7fffffff || d.c.image_height > 0x7fffffff)
    return false;
  // The description: the comment (COM) or Exif's ImageDescription, each up
  // to its first NUL as OpenImageIO keeps them (writing, it puts the same
  // text in both); a file where both are present and differ goes to
  // OpenImageIO, whose choice between them brume does not copy.
  bool has_com = false, has_exif = false;
  std::string com, exif;
  for (jpeg_saved_marker_ptr m = d.c.marker_list; m; m = m->next) {
    if (m->marker == JPEG_COM) {
      com = std::string(reinterpret_cast<const char*>(m->data), m->data_length).c_str();
      has_com = true;
    }
    if (m->marker == JPEG_APP0 + 1) {
      const int e = exif_description(m->data, m->data_length, &exif);
      if (e < 0) return false;
      has_exif = has_exif || e > 0;
    }
  }
  if (has_com && has_exif && com != exif) return false;
  got.description = has_com ? com : exif;
  got.width = static_cast<int>(d.c.image_width);
  got.height = static_cast<int>(d.c.image_height);
  got.channels = grey ? 1 : 3;
  check(got.width, got.height, got.channels);
  if (out) {
    d.c.out_color_space = grey ? JCS_GRAYSCALE : JCS_RGB;
    jpeg_start_decompress(&d.c);
    if (static_cast<int>(d.c.output_width) != got.width || static_cast<int>(d.c.output_height) != got.height ||
        d.c.output_components != got.channels)
      return false;
    const std::size_t rv = static_cast<std::size_t>(got.width) * static_cast<std::size_t>(got.channels);
    row.resize(rv);
    img = Image(got.width, got.height, got.channels);
    const float k = 1.0f / 255.0f;
    for (unsigned c = 0; c < 256; ++c) table[c] = map ? map(static_cast<float>(c) * k, 8) : static_cast<float>(c) * k;
    while (d.c.output_scanline < d.c.output_height) {
      const int y = static_cast<int>(d.c.output_scanline);
      JSAMPROW r = row.data();
      if (jpeg_read_scanlines(&d.c, &r, 1) != 1) return false;
      float* dst = img.data.data() + static_cast<std::size_t>(y) * rv;
      for (std::size_t i = 0; i < rv; ++i) dst[i] = table[row[i]];
    }
    jpeg_finish_decompress(&d.c);
    if (err.warned) return false;  // corrupt data libjpeg read past
    *out = std::move(img);
  }
  info = std::move(got);
  ++g_reads;
  return true;
}

}  // namespace brume::detail
