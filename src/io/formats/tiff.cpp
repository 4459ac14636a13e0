// TIFF through libtiff (Debian 12: 4.5, deflating with libdeflate).
//  - read: the first directory of a classic or BigTIFF file, either byte
//    order; 1 sample (BlackIsZero, channel Y) or 3 (RGB, R G B) and, for
//    read_unassociated, a last extra sample that is an alpha (grey+alpha,
//    RGBA); 8- or 16-bit unsigned integers or 32-bit IEEE floats; no
//    Orientation or top-left; contiguous or separate planes; strips or tiles;
//    any compression libtiff has a codec for. libtiff decodes and undoes the
//    predictors (TIFFReadEncodedStrip/Tile). Values: the count times the
//    float 1/255 or 1/65535, floats as stored -- as OpenImageIO, which reads
//    TIFF with the same library, gives them; the ImageDescription is the
//    description. A palette, CMYK, YCbCr, signed, 1..12-bit, half or double
//    file, or one with another orientation, goes to OpenImageIO; a file
//    libtiff cannot decode (truncated, corrupt) is an error naming the file
//    and libtiff's reason.
//  - write: 1 or 3 channels, and 2 or 4 with the last an unassociated alpha
//    (ExtraSamples 2); 8 or 16 bits or 32-bit float; strips of about
//    kStripBytes, each handed whole to libtiff, which predicts and deflates
//    it (libdeflate, in one call for a whole strip); the description as the
//    ImageDescription. Counts are round(v x (2^bits - 1)), clamped, NaN 0
//    (io::to_count). Compression:
//      auto          Deflate at level 1 (see kAutoLevel) with the
//                    horizontal predictor for counts, the floating-point one
//                    for floats
//      zip           the same at level 6 (zip:N at level N)
//      lzw           LZW with the same predictors
//      packbits      PackBits
//      none          the samples as they are
// Messages go to handlers of this file only (TIFFOpenExt's options), so that
// reads on several threads keep theirs apart and libtiff prints nothing;
// warnings (an unknown private tag, say) do not change the pixels and are
// dropped. Tests: tests/io/test_tiff.cpp.
#include <tiffio.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <vector>

#include "brume/error.hpp"
#include "io/formats/format.hpp"

namespace brume::io {
namespace tiff_row {

// The rows a written strip holds: about this many bytes of samples. Large
// enough that libtiff hands libdeflate few, whole strips; small enough that
// the strip and libtiff's predicted copy of it stay in cache-sized buffers.
constexpr std::size_t kStripBytes = 512 * 1024;

// The Deflate level of "auto". libtiff deflates on one thread; measured on
// the 1600 x 1120 demo haze (Intel Xeon family 6 model 207, 2026-12-05,
// 512 KiB strips): 16-bit RGB at level 6 270 ms / 4.55 MB, at 4 125 ms /
// 4.68 MB, at 1 70 ms / 4.74 MB; float RGB at 6 760 ms / 10.44 MB, at 1
// 350 ms / 10.69 MB. Predicted image data gains 2-4 % from the higher
// levels for 2-4 times the time; "zip" keeps OpenImageIO's 6.
constexpr int kAutoLevel = 1;

// libtiff's first error for one file, and errno as it was then (a failed
// write's ENOSPC or EFBIG, before libtiff's clean-up calls change it).
struct Messages {
  std::string error;
  int err = 0;
};
int on_error(TIFF*, void* user, const char*, const char* fmt, va_list ap) {
  auto* m = static_cast<Messages*>(user);
  const int saved = errno;
  if (m->error.empty()) {
    char b[512];
    std::vsnprintf(b, sizeof b, fmt, ap);
    m->error = b;
    m->err = saved;
  }
  errno = saved;
  return 1;  // handled: libtiff's process-wide handler (which prints) is not called
}
int on_warning(TIFF*, void*, const char*, const char*, va_list) { return 1; }

// A file opened with this file's handlers. Declared after its Messages,
// which TIFFClose may still report to.
struct Handle {
  TIFF* t = nullptr;
  ~Handle() {
    if (t) TIFFClose(t);
  }
};
TIFF* open(const std::string& path, const char* mode, Messages& m) {
  TIFFOpenOptions* o = TIFFOpenOptionsAlloc();
  if (!o) return nullptr;
  TIFFOpenOptionsSetErrorHandlerExtR(o, on_error, &m);
  TIFFOpenOptionsSetWarningHandlerExtR(o, on_warning, &m);
  TIFF* t = TIFFOpenExt(path.c_str(), mode, o);
  TIFFOpenOptionsFree(o);
  return t;
}

[[noreturn]] void fail(const std::string& path, const Messages& m, const char* otherwise) {
  std::string why = m.error.empty() ? otherwise : m.error;
  if (why.rfind(path + ": ", 0) == 0) why.erase(0, path.size() + 2);  // libtiff's "NAME: ..." names it again
  throw Error("cannot read '" + path + "': " + why);
}

bool sniff(const unsigned char* h, std::size_t n) {
  // "II" then 42 or 43 (BigTIFF) little-endian, or "MM" and the same big-endian.
  return n >= 4 && ((h[0] == 'I' && h[1] == 'I' && (h[2] == 42 || h[2] == 43) && h[3] == 0) ||
                    (h[0] == 'M' && h[1] == 'M' && h[2] == 0 && (h[3] == 42 || h[3] == 43)));
}

// The first directory's layout, when this row takes the file.
struct Layout {
  std::uint32_t width = 0, height = 0;
  int channels = 0, bits = 0;
  bool floating = false, separate = false, unassociated = false;
};
bool layout(TIFF* t, bool with_alpha, Layout& l) {
  std::uint16_t spp = 1, bps = 1, fmt = SAMPLEFORMAT_UINT, photo = 0, planar = PLANARCONFIG_CONTIG;
  std::uint16_t comp = COMPRESSION_NONE, orientation = ORIENTATION_TOPLEFT, nextra = 0;
  std::uint16_t* extra = nullptr;
  if (!TIFFGetField(t, TIFFTAG_IMAGEWIDTH, &l.width) || !TIFFGetField(t, TIFFTAG_IMAGELENGTH, &l.height) ||
      !TIFFGetField(t, TIFFTAG_PHOTOMETRIC, &photo))
    return false;
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLESPERPIXEL, &spp);
  TIFFGetFieldDefaulted(t, TIFFTAG_BITSPERSAMPLE, &bps);
  TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLEFORMAT, &fmt);
  TIFFGetFieldDefaulted(t, TIFFTAG_PLANARCONFIG, &planar);
  TIFFGetFieldDefaulted(t, TIFFTAG_COMPRESSION, &comp);
  TIFFGetFieldDefaulted(t, TIFFTAG_ORIENTATION, &orientation);
  TIFFGetFieldDefaulted(t, TIFFTAG_EXTRASAMPLES, &nextra, &extra);
  // Colour samples: 1 for BlackIsZero, 3 for RGB; then at most one extra,
  // an alpha, taken only when the caller keeps alpha.
  const int colour = photo == PHOTOMETRIC_MINISBLACK ? 1 : photo == PHOTOMETRIC_RGB ? 3 : 0;
  if (colour == 0 || spp != colour + nextra || nextra > 1) return false;
  if (nextra == 1 && (!with_alpha || (extra[0] != EXTRASAMPLE_ASSOCALPHA && extra[0] != EXTRASAMPLE_UNASSALPHA)))
    return false;
  const bool integer = fmt == SAMPLEFORMAT_UINT && (bps == 8 || bps == 16);
  l.floating = fmt == SAMPLEFORMAT_IEEEFP && bps == 32;
  if ((!integer && !l.floating) || orientation != ORIENTATION_TOPLEFT || !TIFFIsCODECConfigured(comp) ||
      (planar != PLANARCONFIG_CONTIG && planar != PLANARCONFIG_SEPARATE) || l.width == 0 || l.height == 0 ||
      l.width > 0x7fffffff || l.height > 0x7fffffff)
    return false;
  l.channels = spp;
  l.bits = bps;
  l.separate = planar == PLANARCONFIG_SEPARATE && spp > 1;
  l.unassociated = nextra == 1 && extra[0] == EXTRASAMPLE_UNASSALPHA;
  return true;
}

TIFF* open_for_read(const std::string& path, Messages& m) {
  // "m": read the file, not a memory map of it (a file shortened while it
  // is read is then an error, not SIGBUS).
  TIFF* t = open(path, "rm", m);
  if (!t) fail(path, m, "libtiff cannot open it");
  m.error.clear();  // the directory was read: errors libtiff recovered from are not the pixels'
  return t;
}

bool header(const std::string& path, Header& out) {
  Messages m;
  Handle h;
  h.t = open_for_read(path, m);
  Layout l;
  if (!layout(h.t, true, l)) return false;
  out = {static_cast<int>(l.width), static_cast<int>(l.height), l.channels};
  return true;
}

bool read(const ReadRequest& r, Decoded& out) {
  Messages m;
  Handle h;
  h.t = open_for_read(r.path, m);
  TIFF* t = h.t;
  Layout l;
  if (!layout(t, r.with_alpha, l)) return false;
  const int w = static_cast<int>(l.width), hgt = static_cast<int>(l.height), c = l.channels;
  r.check(w, hgt, c);
  // Samples of one plane's pixel, and what one strip or tile holds.
  const std::size_t W = l.width, C = static_cast<std::size_t>(c), bytes = static_cast<std::size_t>(l.bits / 8);
  const std::size_t per_px = l.separate ? 1 : C;
  const int planes = l.separate ? c : 1;
  std::uint32_t tw = l.width, th = 1;
  const bool tiled = TIFFIsTiled(t);
  if (tiled) {
    if (!TIFFGetField(t, TIFFTAG_TILEWIDTH, &tw) || !TIFFGetField(t, TIFFTAG_TILELENGTH, &th) || tw == 0 || th == 0)
      fail(r.path, m, "no tile size");
    // A tile may overhang the image, but not absurdly: the buffer below is
    // at most the image's size or 4 Mpx, whichever is larger.
    const std::uint64_t tile_px = static_cast<std::uint64_t>(tw) * th;
    if (tile_px > std::max<std::uint64_t>(static_cast<std::uint64_t>(W) * l.height, 1u << 22))
      throw Error("cannot read '" + r.path + "': it declares " + std::to_string(tw) + " x " + std::to_string(th) +
                  " tiles for a " + std::to_string(w) + " x " + std::to_string(hgt) + " image (a corrupt header?)");
  } else {
    TIFFGetFieldDefaulted(t, TIFFTAG_ROWSPERSTRIP, &th);
    th = std::clamp<std::uint32_t>(th, 1, l.height);
  }
  const std::size_t row_bytes = static_cast<std::size_t>(tw) * per_px * bytes;
  const tmsize_t block = static_cast<tmsize_t>(row_bytes * th);
  if ((tiled ? TIFFTileSize64(t) : TIFFStripSize64(t)) != static_cast<std::uint64_t>(block))
    return false;  // a layout the sizes above do not describe (subsampling): OpenImageIO's
  std::vector<unsigned char> buf(static_cast<std::size_t>(block));
  Image img(w, hgt, c);
  CountValues counts;
  if (!l.floating) counts.reset(l.bits, r.map);
  // n samples of buf to every step-th float of dst.
  auto convert = [&](const unsigned char* src, float* dst, std::size_t n, std::size_t step) {
    if (!l.floating) return counts.convert(src, dst, n, step);
    for (std::size_t i = 0; i < n; ++i) std::memcpy(dst + i * step, src + 4 * i, 4);
  };
  for (int p = 0; p < planes; ++p)
    for (std::uint32_t y0 = 0; y0 < l.height; y0 += th)
      for (std::uint32_t x0 = 0; x0 < l.width; x0 += tw) {
        const auto plane = static_cast<std::uint16_t>(p);
        const std::uint32_t rows = std::min(th, l.height - y0), cols = std::min(tw, l.width - x0);
        // A strip's last may be short; a tile is always whole.
        const tmsize_t want = tiled ? block : static_cast<tmsize_t>(row_bytes * rows);
        const tmsize_t got = tiled ? TIFFReadEncodedTile(t, TIFFComputeTile(t, x0, y0, 0, plane), buf.data(), block)
                                   : TIFFReadEncodedStrip(t, TIFFComputeStrip(t, y0, plane), buf.data(), want);
        if (got != want || !m.error.empty()) fail(r.path, m, "a strip or tile is short");
        for (std::uint32_t y = 0; y < rows; ++y) {
          float* dst = img.data.data() + ((static_cast<std::size_t>(y0) + y) * W + x0) * C + static_cast<std::size_t>(p);
          convert(buf.data() + y * row_bytes, dst, cols * per_px, l.separate ? C : 1);
        }
      }
  out.img = std::move(img);
  out.info.format = "tiff";
  out.info.integer = !l.floating;
  out.info.bits = l.bits;
  static const std::vector<std::string> names[5] = {{}, {"Y"}, {"Y", "A"}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
  out.info.channel_names = names[c];
  if (char* d = nullptr; TIFFGetField(t, TIFFTAG_IMAGEDESCRIPTION, &d) && d) out.info.description = d;
  out.mapped = !l.floating && r.map;
  out.alpha = c == 2 || c == 4 ? c - 1 : -1;
  out.unassociated = l.unassociated;
  return true;
}

int bits_of(Storage s) { return s == Storage::u8 ? 8 : s == Storage::u16 ? 16 : 32; }

bool write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  const int bits = bits_of(r.type);
  const bool floating = r.type == Storage::f32;
  const std::size_t n = static_cast<std::size_t>(r.width) * static_cast<std::size_t>(r.channels);
  const std::size_t row_bytes = n * static_cast<std::size_t>(bits / 8), H = static_cast<std::size_t>(r.height);
  // Classic TIFF addresses 4 GiB; larger images go to BigTIFF (OpenImageIO's threshold).
  const bool big = row_bytes * H > 4000ull * 1024 * 1024;
  Messages m;
  Handle h;
  auto failed = [&](const char* otherwise) {
    *why = m.error.empty() ? otherwise : m.error;
    const int err = m.err;
    TIFFClose(h.t);
    h.t = nullptr;
    errno = err;  // the failed write's reason, not the clean-up's
    return false;
  };
  errno = 0;
  h.t = open(tmp, big ? "w8" : "w", m);
  if (!h.t) {
    *why = m.error;
    errno = m.err;
    return false;
  }
  TIFF* t = h.t;
  const Compression& k = r.compression;
  std::uint16_t comp = COMPRESSION_ADOBE_DEFLATE;
  if (k.name == "lzw") comp = COMPRESSION_LZW;
  if (k.name == "packbits") comp = COMPRESSION_PACKBITS;
  if (k.name == "none") comp = COMPRESSION_NONE;
  const std::size_t rows = std::clamp<std::size_t>(kStripBytes / std::max<std::size_t>(row_bytes, 1), 1, H);
  bool ok = TIFFSetField(t, TIFFTAG_IMAGEWIDTH, static_cast<std::uint32_t>(r.width)) &&
            TIFFSetField(t, TIFFTAG_IMAGELENGTH, static_cast<std::uint32_t>(r.height)) &&
            TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, static_cast<std::uint16_t>(r.channels)) &&
            TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, static_cast<std::uint16_t>(bits)) &&
            TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, floating ? SAMPLEFORMAT_IEEEFP : SAMPLEFORMAT_UINT) &&
            TIFFSetField(t, TIFFTAG_PHOTOMETRIC, r.channels >= 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK) &&
            TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG) &&
            TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, static_cast<std::uint32_t>(rows)) &&
            TIFFSetField(t, TIFFTAG_COMPRESSION, comp);
  if (ok && (r.channels == 2 || r.channels == 4)) {
    const std::uint16_t alpha = EXTRASAMPLE_UNASSALPHA;
    ok = TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, &alpha);
  }
  if (ok && (comp == COMPRESSION_ADOBE_DEFLATE || comp == COMPRESSION_LZW))
    ok = TIFFSetField(t, TIFFTAG_PREDICTOR, floating ? PREDICTOR_FLOATINGPOINT : PREDICTOR_HORIZONTAL);
  if (ok && comp == COMPRESSION_ADOBE_DEFLATE)
    ok = TIFFSetField(t, TIFFTAG_ZIPQUALITY, k.name != "zip" ? kAutoLevel : k.level >= 1 ? k.level : 6);
  if (ok && !r.description.empty()) ok = TIFFSetField(t, TIFFTAG_IMAGEDESCRIPTION, r.description.c_str());
  if (!ok) return failed("libtiff refused a tag");
  // Each strip filled with the stored samples (host order: libtiff writes
  // a "w" file in it) and handed to libtiff whole.
  std::vector<unsigned char> strip(rows * row_bytes);
  for (std::size_t y0 = 0, s = 0; y0 < H; y0 += rows, ++s) {
    const std::size_t count = std::min(rows, H - y0) * n, at = y0 * n;
    store_samples(r, at, count, strip.data());
    if (TIFFWriteEncodedStrip(t, static_cast<std::uint32_t>(s), strip.data(),
                              static_cast<tmsize_t>(count * static_cast<std::size_t>(bits / 8))) < 0)
      return failed("libtiff could not write a strip");
  }
  // The directory, then the file closed (TIFFClose cannot report a failure).
  if (!TIFFWriteDirectory(t) || !m.error.empty()) return failed("libtiff could not write the directory");
  TIFFClose(h.t);
  h.t = nullptr;
  if (!m.error.empty()) {
    *why = m.error;
    errno = m.err;
    return false;
  }
  return true;
}
}  // namespace tiff_row

const Format& tiff_format() {
  using namespace tiff_row;
  static const Format f{.name = "tiff", .title = "TIFF", .extensions = {".tif", ".tiff"}, .bits = {"8", "16", "float"},
                        .color_bits = "16", .data_bits = "float",
                        .compressions = {{"none", 1, 0, false}, {"lzw", 1, 0, false}, {"zip", 1, 9, false},
                                         {"packbits", 1, 0, false}},
                        .channel_counts = {1, 2, 3, 4}, .holds_data = true, .sniff = sniff, .header = header,
                        .read = read, .write = write, .auto_is = "zip:1"};
  return f;
}

}  // namespace brume::io
