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

#include "io/png_direct.hpp"  // oiio_count

namespace brume::detail {

namespace {
std::atomic<std::uint64_t> g_jpeg_reads{0}, g_jpeg_writes{0};

// libjpeg reports errors through error_exit (which must not return: a
// longjmp back to read_jpeg_subset) and warnings through emit_message
// with level -1; any warning (a corrupt-data one, e.g. a premature end of
// data, after which libjpeg would fill the rest with grey) declines the file.
struct JpegErrorMgr {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  bool warned = false;
};
[[noreturn]] void error_exit(j_common_ptr c) { std::longjmp(reinterpret_cast<JpegErrorMgr*>(c->err)->jump, 1); }
void emit_message(j_common_ptr c, int level) {
  if (level < 0) reinterpret_cast<JpegErrorMgr*>(c->err)->warned = true;
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

struct JpegFile {
  std::FILE* f = nullptr;
  ~JpegFile() {
    if (f) std::fclose(f);
  }
};
struct JpegDecompress {
  jpeg_decompress_struct c{};
  bool made = false;
  ~JpegDecompress() {
    if (made) jpeg_destroy_decompress(&c);
  }
};
}  // namespace

std::uint64_t jpeg_direct_reads() { return g_jpeg_reads.load(); }

bool read_jpeg_subset(const std::string& path, Image* out, JpegInfo& info,
                      const std::function<void(int, int, int)>& check,
                      const std::function<float(float, int)>& map) {
  JpegFile file;
  file.f = std::fopen(path.c_str(), "rb");
  if (!file.f) return false;
  unsigned char soi[2];
  if (std::fread(soi, 1, 2, file.f) != 2 || soi[0] != 0xFF || soi[1] != 0xD8) return false;
  std::rewind(file.f);
  // Every object with a destructor is made before setjmp, so that a
  // longjmp from libjpeg skips none; check() may throw (an ordinary
  // exception, which unwinds them all).
  JpegDecompress d;
  JpegErrorMgr err;
  JpegInfo got;
  std::vector<unsigned char> row;
  Image img;
  CountValues values;
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
    values.reset(8, map);
    while (d.c.output_scanline < d.c.output_height) {
      const int y = static_cast<int>(d.c.output_scanline);
      JSAMPROW r = row.data();
      if (jpeg_read_scanlines(&d.c, &r, 1) != 1) return false;
      float* dst = img.data.data() + static_cast<std::size_t>(y) * rv;
      values.convert(row.data(), dst, rv);
    }
    jpeg_finish_decompress(&d.c);
    if (err.warned) return false;  // corrupt data libjpeg read past
    *out = std::move(img);
  }
  info = std::move(got);
  ++g_jpeg_reads;
  return true;
}

// ---- writing -------------------------------------------------------------

namespace {
struct JpegCompress {
  jpeg_compress_struct c{};
  bool made = false;
  ~JpegCompress() {
    if (made) jpeg_destroy_compress(&c);
  }
};
void exif_put16(std::string& b, unsigned v) { b += static_cast<char>(v & 0xff), b += static_cast<char>(v >> 8 & 0xff); }
void exif_put32(std::string& b, std::uint32_t v) { exif_put16(b, v & 0xffff), exif_put16(b, v >> 16); }
// One 12-byte little-endian TIFF directory exif_entry.
void exif_entry(std::string& b, unsigned tag, unsigned type, std::uint32_t count, std::uint32_t value) {
  exif_put16(b, tag), exif_put16(b, type), exif_put32(b, count), exif_put32(b, value);
}

// OpenImageIO 2.4's Exif block for brume's attributes (its encode_exif: the
// TIFF header, the values that do not fit an exif_entry, IFD0, then the Exif
// directory; no padding).
std::string exif_block(const std::string& description, bool srgb) {
  std::string b("Exif\0\0II*\0", 10);
  const bool has_desc = !description.empty();
  const std::uint32_t n = static_cast<std::uint32_t>(description.size()) + 1;  // with the NUL
  const bool outside = has_desc && n > 4;
  const std::uint32_t ifd0 = 8 + (outside ? n : 0);
  exif_put32(b, ifd0);
  if (outside) b.append(description.c_str(), n);
  const unsigned entries = (has_desc ? 1 : 0) + (srgb ? 1 : 0);
  exif_put16(b, entries);
  if (has_desc) {
    std::uint32_t v = 8;
    if (!outside) {
      v = 0;
      std::memcpy(&v, description.c_str(), n);  // inline, zero-padded (little-endian host order is the file's)
    }
    exif_entry(b, 0x010e, 2, n, v);
  }
  const std::uint32_t exif_ifd = ifd0 + 2 + 12 * entries + 4;
  if (srgb) exif_entry(b, 0x8769, 4, 1, exif_ifd);
  exif_put32(b, 0);
  if (srgb) {
    exif_put16(b, 4);
    exif_entry(b, 0x9000, 7, 4, 0x30333230u);  // ExifVersion "0230"
    exif_entry(b, 0x9101, 7, 4, 0x00030201u);  // ComponentsConfiguration Y Cb Cr -
    exif_entry(b, 0xa000, 7, 4, 0x30303130u);  // FlashpixVersion "0100"
    exif_entry(b, 0xa001, 3, 1, 1);            // ColorSpace sRGB
    exif_put32(b, 0);
  }
  return b;
}

// Its IPTC block: a Photoshop 3.0 image resource 0x0404 holding the
// caption record 2:120 (lengths big-endian, as two bytes whatever the size).
std::string iptc_block(const std::string& description) {
  std::string b("Photoshop 3.0\0" "8BIM\x04\x04\0\0", 22);
  const std::uint32_t size = 5 + static_cast<std::uint32_t>(description.size());
  for (int s = 24; s >= 0; s -= 8) b += static_cast<char>(size >> s & 0xff);
  b += "\x1c\x02\x78";
  b += static_cast<char>(description.size() >> 8 & 0xff);
  b += static_cast<char>(description.size() & 0xff);
  b += description;
  return b;
}
}  // namespace

bool jpeg_subset_writable(int channels, std::size_t description_bytes) {
  return (channels == 1 || channels == 3) && description_bytes <= 60000;
}

std::uint64_t jpeg_direct_writes() { return g_jpeg_writes.load(); }

bool write_jpeg_subset(const std::string& path, int width, int height, int channels, const std::uint8_t* codes,
                       const float* values, bool srgb, const std::string& description, int quality, std::string* why) {
  why->clear();
  if (!jpeg_subset_writable(channels, description.size()) || width <= 0 || height <= 0 || width > 65500 ||
      height > 65500) {
    *why = "not a JPEG brume writes itself";
    return false;
  }
  JpegFile file;
  file.f = std::fopen(path.c_str(), "wb");
  if (!file.f) return false;  // errno says why
  JpegCompress z;
  JpegErrorMgr err;
  const std::string exif = exif_block(description, srgb), iptc = description.empty() ? "" : iptc_block(description);
  const std::size_t row_values = static_cast<std::size_t>(width) * static_cast<std::size_t>(channels);
  std::vector<unsigned char> row(row_values);
  z.c.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = error_exit;
  err.pub.emit_message = emit_message;
  if (setjmp(err.jump)) {
    char text[JMSG_LENGTH_MAX];
    (*z.c.err->format_message)(reinterpret_cast<j_common_ptr>(&z.c), text);
    *why = text;
    return false;
  }
  jpeg_create_compress(&z.c);
  z.made = true;
  jpeg_stdio_dest(&z.c, file.f);
  z.c.image_width = static_cast<JDIMENSION>(width);
  z.c.image_height = static_cast<JDIMENSION>(height);
  z.c.input_components = channels;
  z.c.in_color_space = channels == 3 ? JCS_RGB : JCS_GRAYSCALE;
  jpeg_set_defaults(&z.c);
  jpeg_set_quality(&z.c, quality, TRUE);
  jpeg_start_compress(&z.c, TRUE);
  if (!description.empty())
    jpeg_write_marker(&z.c, JPEG_COM, reinterpret_cast<const JOCTET*>(description.c_str()),
                      static_cast<unsigned>(description.size() + 1));
  jpeg_write_marker(&z.c, JPEG_APP0 + 1, reinterpret_cast<const JOCTET*>(exif.data()), static_cast<unsigned>(exif.size()));
  if (!iptc.empty())
    jpeg_write_marker(&z.c, JPEG_APP0 + 13, reinterpret_cast<const JOCTET*>(iptc.data()),
                      static_cast<unsigned>(iptc.size()));
  for (std::size_t y = 0; y < static_cast<std::size_t>(height); ++y) {
    if (codes) {
      std::memcpy(row.data(), codes + y * row_values, row_values);
    } else {
      const float* v = values + y * row_values;
      for (std::size_t i = 0; i < row_values; ++i) row[i] = static_cast<unsigned char>(oiio_count(v[i], 255.0f));
    }
    JSAMPROW r = row.data();
    jpeg_write_scanlines(&z.c, &r, 1);
  }
  jpeg_finish_compress(&z.c);
  if (std::fflush(file.f) != 0 || std::ferror(file.f)) return false;  // errno says why
  const int closed = std::fclose(file.f);
  file.f = nullptr;
  if (closed != 0) return false;
  ++g_jpeg_writes;
  return true;
}

}  // namespace brume::detail
