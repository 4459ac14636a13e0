// JPEG through libjpeg-turbo (Debian 12: libjpeg62-turbo 2.1.5).
//  - read: 8-bit samples, 1 component (grey, channel Y) or 3 (YCbCr or RGB,
//    converted to RGB by libjpeg); baseline, extended or progressive, with
//    libjpeg's default decoding (islow DCT, fancy upsampling), as
//    OpenImageIO, which reads JPEG with the same library, decodes it. Values:
//    the count times the float 1/255. The description: the comments (COM
//    markers) joined in file order, each up to a NUL if it holds one; a file
//    without a comment gives its Exif ImageDescription, if any. CMYK, YCCK
//    and 12-bit files go to OpenImageIO. A file libjpeg cannot decode is an
//    error naming the file and libjpeg's reason -- and so is one it decodes
//    only in part: libjpeg warns and goes on for a truncated file ("Premature
//    end of JPEG file") or corrupt entropy-coded data, filling what is missing
//    with grey, which would pass for pixels; its other warnings (extraneous
//    bytes between markers, an unknown JFIF revision or Adobe transform, data
//    after the image) leave the pixels whole and are ignored.
//  - write: 1 or 3 channels, 8 bits; JFIF; quality from --compression
//    jpeg:N (98 by default); chroma 4:4:4 at quality >= 90, else libjpeg's
//    4:2:0 (see kFullChroma); the standard Huffman tables (see write()). The
//    description goes in comments, in as many COM markers as its length
//    needs (at most kComBytes each: a marker's length field is 16 bits), the
//    first one holding the start: OpenImageIO reports that first marker as
//    ImageDescription, brume's reader joins them all. JPEG holds the values
//    as given: sRGB-encoded colour normally, linear values when asked (the
//    file says nothing of it; brume's record does).
// Tests: tests/io/test_jpeg.cpp.
#include <csetjmp>
#include <cstdio>
// jpeglib.h needs FILE and size_t declared first.
#include <jpeglib.h>
#include <jerror.h>  // the warnings' codes

#include <cerrno>
#include <cstring>
#include <vector>

#include "brume/error.hpp"
#include "io/formats/format.hpp"

namespace brume::io {
namespace jpeg_row {

// The most bytes of text one COM marker holds: 65535 less the two bytes of
// the length field itself.
constexpr std::size_t kComBytes = 65533;

// At this quality and above the chroma planes are kept at full resolution
// (4:4:4): 4:2:0 halves their resolution, which no quality setting gets
// back -- a one-pixel colour edge (a red roof against the haze) bleeds into
// its neighbours. Measured on the 1600 x 1120 demo haze at 98 (Intel Xeon
// family 6 model 207, 2026-12-05): 688 kB in 8.7 ms against 4:2:0's 535 kB
// in 6.2 ms, a price a request for >= 90 accepts.
constexpr int kFullChroma = 90;

// libjpeg reports a fatal error through error_exit, which must not return
// (a longjmp back to the caller, with the message and errno kept), and a
// warning through emit_message with level -1.
struct ErrorMgr {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
  int err = 0;
  bool damaged = false;  // a warning that the pixels are not all the file's
};
[[noreturn]] void error_exit(j_common_ptr c) {
  auto* e = reinterpret_cast<ErrorMgr*>(c->err);
  e->err = errno;
  (*c->err->format_message)(c, e->message);
  std::longjmp(e->jump, 1);
}
void emit_message(j_common_ptr c, int level) {
  auto* e = reinterpret_cast<ErrorMgr*>(c->err);
  if (level >= 0 || e->damaged) return;  // trace messages; or the first damage already noted
  switch (c->err->msg_code) {
    case JWRN_EXTRANEOUS_DATA:
    case JWRN_JFIF_MAJOR:
    case JWRN_ADOBE_XFORM:
    case JWRN_TOO_MUCH_DATA:
    case JWRN_BOGUS_ICC:
      return;
    default:
      e->damaged = true;
      (*c->err->format_message)(c, e->message);
  }
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
struct Compress {
  jpeg_compress_struct c{};
  bool made = false;
  ~Compress() {
    if (made) jpeg_destroy_compress(&c);
  }
};

bool sniff(const unsigned char* h, std::size_t n) { return n >= 3 && h[0] == 0xff && h[1] == 0xd8 && h[2] == 0xff; }

// The ImageDescription (tag 270, ASCII) of an Exif APP1 block's first
// directory: "Exif\0\0", then a TIFF structure (byte order, 42, IFD0's
// offset; 12-byte entries of tag, type, count and the value or its
// offset). Empty when absent or when the block does not parse.
std::string exif_description(const unsigned char* p, std::size_t n) {
  if (n < 14 || std::memcmp(p, "Exif\0\0", 6) != 0) return {};
  p += 6, n -= 6;
  const bool le = p[0] == 'I' && p[1] == 'I';
  if (!le && !(p[0] == 'M' && p[1] == 'M')) return {};
  auto u16 = [&](std::size_t at) { return le ? unsigned(p[at]) | unsigned(p[at + 1]) << 8 : unsigned(p[at]) << 8 | p[at + 1]; };
  auto u32 = [&](std::size_t at) { return le ? u16(at) | u16(at + 2) << 16 : u16(at) << 16 | u16(at + 2); };
  const std::size_t ifd = u32(4);
  if (ifd > n || n - ifd < 2) return {};
  const std::size_t count = u16(ifd);
  for (std::size_t k = 0; k < count && ifd + 2 + 12 * (k + 1) <= n; ++k) {
    const std::size_t e = ifd + 2 + 12 * k;
    if (u16(e) != 270 || u16(e + 2) != 2) continue;
    const std::size_t len = u32(e + 4), at = len <= 4 ? e + 8 : u32(e + 8);
    if (at > n || n - at < len) return {};
    return std::string(reinterpret_cast<const char*>(p + at), len).c_str();  // up to its NUL
  }
  return {};
}

// A decoder on the file with its header and markers read; false when the
// file is not one this row takes. Throws for a file libjpeg cannot decode.
struct Opened {
  File file;
  Decompress d;
  ErrorMgr err;
  int channels = 0;
};
[[noreturn]] void fail(const std::string& path, const ErrorMgr& e) {
  throw Error("cannot read '" + path + "': a damaged JPEG (" + e.message + ")");
}
// The setjmp here serves the calls in open() only; read() sets its own
// before it calls libjpeg again.
bool open(const std::string& path, Opened& o) {
  o.file.f = std::fopen(path.c_str(), "rb");
  if (!o.file.f) return false;
  o.d.c.err = jpeg_std_error(&o.err.pub);
  o.err.pub.error_exit = error_exit;
  o.err.pub.emit_message = emit_message;
  if (setjmp(o.err.jump)) fail(path, o.err);
  jpeg_create_decompress(&o.d.c);
  o.d.made = true;
  jpeg_stdio_src(&o.d.c, o.file.f);
  jpeg_save_markers(&o.d.c, JPEG_COM, 0xffff);
  jpeg_save_markers(&o.d.c, JPEG_APP0 + 1, 0xffff);
  jpeg_read_header(&o.d.c, TRUE);
  if (o.err.damaged) fail(path, o.err);
  const jpeg_decompress_struct& c = o.d.c;
  if (c.data_precision != 8) return false;
  if (c.jpeg_color_space == JCS_GRAYSCALE && c.num_components == 1) o.channels = 1;
  if ((c.jpeg_color_space == JCS_YCbCr || c.jpeg_color_space == JCS_RGB) && c.num_components == 3) o.channels = 3;
  return o.channels > 0;
}

bool header(const std::string& path, Header& out) {
  Opened o;
  if (!open(path, o)) return false;
  out = {static_cast<int>(o.d.c.image_width), static_cast<int>(o.d.c.image_height), o.channels};
  return true;
}

bool read(const ReadRequest& r, Decoded& out) {
  Opened o;
  if (!open(r.path, o)) return false;
  jpeg_decompress_struct& c = o.d.c;
  const int w = static_cast<int>(c.image_width), h = static_cast<int>(c.image_height), ch = o.channels;
  r.check(w, h, ch);
  std::string com, exif;
  bool has_com = false;
  for (jpeg_saved_marker_ptr m = c.marker_list; m; m = m->next) {
    if (m->marker == JPEG_COM) {
      com += std::string(reinterpret_cast<const char*>(m->data), m->data_length).c_str();
      has_com = true;
    } else if (exif.empty()) {
      exif = exif_description(m->data, m->data_length);
    }
  }
  // Settled before the setjmp below: nothing after it changes a local.
  const std::string description = has_com ? com : exif;
  // Everything a longjmp would skip is made before the setjmp below.
  Image img(w, h, ch);
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(ch);
  std::vector<unsigned char> row(n);
  CountValues counts;
  counts.reset(8, r.map);
  if (setjmp(o.err.jump)) fail(r.path, o.err);
  c.out_color_space = ch == 1 ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_start_decompress(&c);
  while (c.output_scanline < c.output_height) {
    const std::size_t y = c.output_scanline;
    JSAMPROW p = row.data();
    jpeg_read_scanlines(&c, &p, 1);
    counts.convert(row.data(), img.data.data() + y * n, n);
  }
  jpeg_finish_decompress(&c);
  if (o.err.damaged) fail(r.path, o.err);
  out.img = std::move(img);
  out.info.format = "jpeg";
  out.info.integer = true;
  out.info.bits = 8;
  out.info.channel_names = ch == 1 ? std::vector<std::string>{"Y"} : std::vector<std::string>{"R", "G", "B"};
  out.info.description = description;
  out.mapped = static_cast<bool>(r.map);
  return true;
}

std::string refuse(const WriteRequest& r) {
  if (r.width > JPEG_MAX_DIMENSION || r.height > JPEG_MAX_DIMENSION)
    return "JPEG holds at most " + std::to_string(JPEG_MAX_DIMENSION) + " pixels a side";
  return {};
}

bool write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  File file;
  errno = 0;
  file.f = std::fopen(tmp.c_str(), "wb");
  if (!file.f) return false;  // errno says why
  Compress z;
  ErrorMgr err;
  const std::size_t n = static_cast<std::size_t>(r.width) * static_cast<std::size_t>(r.channels);
  std::vector<unsigned char> row(n);
  z.c.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = error_exit;
  err.pub.emit_message = emit_message;  // nothing printed
  if (setjmp(err.jump)) {
    *why = err.message;
    errno = err.err;
    return false;
  }
  jpeg_create_compress(&z.c);
  z.made = true;
  jpeg_stdio_dest(&z.c, file.f);
  z.c.image_width = static_cast<JDIMENSION>(r.width);
  z.c.image_height = static_cast<JDIMENSION>(r.height);
  z.c.input_components = r.channels;
  z.c.in_color_space = r.channels == 3 ? JCS_RGB : JCS_GRAYSCALE;
  jpeg_set_defaults(&z.c);  // JFIF, YCbCr for colour, 4:2:0
  const int quality = r.compression.level >= 1 ? r.compression.level : 98;
  jpeg_set_quality(&z.c, quality, TRUE);
  if (r.channels == 3 && quality >= kFullChroma) z.c.comp_info[0].h_samp_factor = z.c.comp_info[0].v_samp_factor = 1;
  // libjpeg's standard Huffman tables: tables fitted to the image
  // (optimize_coding) made the demo haze at 98 3 % smaller (669 against
  // 688 kB) for three times the encoding time (26 against 8.7 ms).
  jpeg_start_compress(&z.c, TRUE);
  for (std::size_t at = 0; at < r.description.size(); at += kComBytes) {
    const std::size_t len = std::min(kComBytes, r.description.size() - at);
    jpeg_write_marker(&z.c, JPEG_COM, reinterpret_cast<const JOCTET*>(r.description.data() + at),
                      static_cast<unsigned>(len));
  }
  for (std::size_t y = 0; y < static_cast<std::size_t>(r.height); ++y) {
    store_samples(r, y * n, n, row.data());
    JSAMPROW p = row.data();
    jpeg_write_scanlines(&z.c, &p, 1);
  }
  jpeg_finish_compress(&z.c);
  if (std::fflush(file.f) != 0 || std::ferror(file.f)) return false;  // errno says why
  const int closed = std::fclose(file.f);
  file.f = nullptr;
  return closed == 0;
}
}  // namespace jpeg_row

const Format& jpeg_format() {
  using namespace jpeg_row;
  static const Format f{.name = "jpeg", .title = "JPEG", .extensions = {".jpg", ".jpeg"}, .bits = {"8"},
                        .color_bits = "8", .data_bits = "8", .compressions = {{"jpeg", 1, 100, true}},
                        .channel_counts = {1, 3}, .holds_data = false, .sniff = sniff, .header = header,
                        .read = read, .refuse = refuse, .write = write, .auto_is = "jpeg:98"};
  return f;
}

}  // namespace brume::io
