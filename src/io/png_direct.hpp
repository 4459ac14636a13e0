// brume — 8- and 16-bit grey and RGB PNG read and written with libpng itself
// (internal).
//
// Every image format brume does not read itself (PNG here, JPEG, OpenEXR,
// Radiance HDR and PFM elsewhere) goes through OpenImageIO, loaded on first use
// (src/io/codec.hpp), and that load is ~0.4 s of symbol lookups across
// Debian's OpenImageIO and its 260 libraries -- more than a whole haze run on
// a Middlebury frame, paid by every `brume haze in.png ... --out out.png`
// and once by every batch. The PNGs of the datasets brume's users turn
// foggy (Middlebury, KITTI, Cityscapes: 8-bit RGB images, 8/16-bit grey
// disparity and depth) and the PNGs brume writes are a small subset of PNG,
// so brume reads and writes that subset with libpng directly, exactly as
// OpenImageIO would:
//  - read: 8 or 16 bits, grey or RGB, no transparency chunk (tRNS), any
//    interlacing (the image data of a non-interlaced file inflated by
//    libdeflate and unfiltered by brume, ~2x libpng's speed: png_direct.cpp);
//    values as OpenImageIO returns them (the count times the
//    float 1/255 or 1/65535), FileInfo as it gives it (format "png", channels
//    Y or R G B, the "Description" text as the description). Anything else --
//    palette, alpha, 1/2/4 bits, tRNS, a libpng error or warning of any kind
//    (a corrupt or truncated file) -- returns false, and the caller reads the
//    file through OpenImageIO as before, which then gives its own result or
//    its own error message;
//  - write: 1 or 3 channels, 8 or 16 bits, the chunks OpenImageIO's writer
//    puts there for brume's attributes (gAMA 1.0 for linear, sRGB + gAMA +
//    cHRM for sRGB, oFFs 0 0, tEXt oiio:ColorSpace and Description), its
//    deflate level (png:compressionLevel, default 6), strategy and row
//    filters (libpng's adaptive choice, or for `rle` compression="rle" with
//    png:filter = Up: PngDeflate below), and its
//    float-to-count rounding (round half away from zero of v x 255 or
//    v x 65535, clamped; NaN to 0) -- the same file, byte for byte (tested
//    against OpenImageIO's writer), for image data up to kDeflateSegment
//    bytes; longer data are the same filtered rows deflated in segments on
//    several threads (PngDeflate below).
// Tests: IO.PngSubset* (tests/test_io.cpp).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <vector>
#include <functional>
#include <string>

#include "brume/image.hpp"

namespace brume::detail {

struct PngInfo {
  int width = 0, height = 0, channels = 0, bits = 0;
  std::string description;
};

// Reads `path` into *out (channels 1 or 3, values as OpenImageIO gives
// them, or map(value, bits) when map is given) when it is a PNG of the subset
// above, calling check(width, height, channels) after the header and before
// any allocation (it may throw). out == nullptr: the header only (info, the
// check; no pixel decoded). map is called once per distinct count (every
// count of an 8-bit file, the counts met in a 16-bit one), so its result is
// map's own, bit for bit, with no pass over the image after the decode; it
// must not throw. Returns false, having changed nothing, for any other file
// or on any libpng error or warning; throws brume::Error (naming the file)
// for a PNG with a chunk that runs past the end of the file, before libpng
// or OpenImageIO would allocate its declared length (png_direct.cpp), and
// whatever check throws.
// with_alpha: grey + alpha and RGBA files too (channels 2 and 4, alpha
// last), every channel's count times 1/255 or 1/65535 as the others -- the
// values OpenImageIO gives when asked to keep alpha unassociated, which is
// how PNG stores it (read_unassociated, brume/io.hpp). Without it such files
// return false, as before.
bool read_png_subset(const std::string& path, Image* out, PngInfo& info,
                     const std::function<void(int, int, int)>& check,
                     const std::function<float(float, int)>& map = {}, bool with_alpha = false);

// How many reads of this process took the image data without libpng's row
// loop (read_image_data in png_direct.cpp: libdeflate's inflate and
// brume's own unfiltering), for tests: a well-formed non-interlaced file
// of the subset does; anything unusual, an interlaced file or a PNG outside
// the subset does not.
std::uint64_t png_fast_reads();

// OpenImageIO's conversion of a float to a count 0..max (255 or 65535) in
// its vector loop: round half away from zero of v x max, clamped, NaN to 0
// (measured against convert_pixel_values on every count's rounding
// boundary; its scalar loop, for the last < 16 values of a call, differs in
// one 8-bit value, 0.0019607842 = 0.5/255 rounded, which it makes 1).
inline unsigned oiio_count(float v, float max) {
  if (v != v) return 0;
  const float r = std::round(v * max);
  return static_cast<unsigned>(r < 0.0f ? 0.0f : r > max ? max : r);
}

// The values of 8- or 16-bit counts as OpenImageIO returns them -- the
// count times the float 1/255 or 1/65535 -- then `map` (the caller's
// per-value function, evaluated once per distinct count, so the result is
// map's bit for bit): the one conversion of the PNG, JPEG and TIFF subset
// readers. Default-constructed before a reader's setjmp, reset once the
// header gives the bit depth.
class CountValues {
 public:
  void reset(int bits, const std::function<float(float, int)>& map) {
    bits_ = bits;
    map_ = map;
    k_ = bits == 8 ? 1.0f / 255.0f : 1.0f / 65535.0f;
    table_.clear();
    known_.clear();
    if (bits == 8) {
      table_.resize(256);
      for (unsigned c = 0; c < 256; ++c) table_[c] = map_ ? map_(static_cast<float>(c) * k_, 8) : static_cast<float>(c) * k_;
    } else if (map_) {
      table_.assign(65536, 0.0f);  // [count]: its value, as met
      known_.assign(65536, 0);
    }
  }
  // n counts at src (a byte each, or two in native byte order) to every
  // step-th float of dst.
  void convert(const unsigned char* src, float* dst, std::size_t n, std::size_t step = 1) {
    if (bits_ == 8) {
      for (std::size_t i = 0; i < n; ++i) dst[i * step] = table_[src[i]];
      return;
    }
    for (std::size_t i = 0; i < n; ++i) {
      std::uint16_t c;
      std::memcpy(&c, src + 2 * i, 2);
      if (!map_) {
        dst[i * step] = static_cast<float>(c) * k_;
      } else {
        if (!known_[c]) table_[c] = map_(static_cast<float>(c) * k_, 16), known_[c] = 1;
        dst[i * step] = table_[c];
      }
    }
  }

 private:
  int bits_ = 8;
  float k_ = 1.0f / 255.0f;
  std::function<float(float, int)> map_;
  std::vector<float> table_;
  std::vector<unsigned char> known_;
};

// Whether write_png_subset writes this output (else OpenImageIO does).
bool png_subset_writable(int channels, int bits);

// How the rows are filtered and deflated.
//  - level 0..9, rle false: libpng's adaptive filter choice per row (all
//    five filters tried, the least sum of absolute differences kept) and
//    zlib's default strategy at that level: `--compression zip:N`, `none`
//    (level 0) and `auto` (6), OpenImageIO's defaults;
//  - rle true: every row filtered with Up (the difference to the row above)
//    and deflated with zlib's run-length strategy (matches of distance 1
//    only; the level does not change its output): `--compression rle`,
//    brume batch's PNG default. Measured on 8-bit RGB frames (Middlebury
//    thirds before and after haze, a KITTI frame), AMD EPYC Zen 5, against
//    zip:1: 1.9-2.4x faster to write and 1.3-2.1x faster to read back,
//    files from 27 % smaller (a hazy frame: long runs) to 5 % larger. Up
//    alone, not the adaptive choice: trying five filters per row was half
//    of zip:1's time, and Paeth, the smallest with rle, reads back about as
//    slowly as zip:1 (Paeth rows unfilter slowest in libpng 1.6.39);
//  - fast true: every row filtered with Up and the whole image deflated by
//    libdeflate at its level 1 in one call (libpng writes the chunks before
//    the image data, the same as for the other settings; brume the IDAT
//    chunks, 1 MiB each, and IEND): `--compression fast`, brume batch's PNG
//    default since 2026-12-02 (fourth session). No OpenImageIO setting
//    writes these bytes: the file is brume's own, a valid PNG that every
//    decoder reads. On the hazy Middlebury frames of bench_batch, against
//    rle: ~1.8x faster to deflate (2.7 -> 1.5 ms for Art), files from 9 %
//    smaller to 2 % larger; read back as fast (Up rows). The filtered rows
//    and their deflated copy are held whole while writing: up to twice the
//    file's raw bytes (6 bytes a pixel for 16-bit RGB), beside the float
//    image's 12.
//  Segments (level 0..9 and rle, since 2026-12-03, ninth session): zlib is
//  one thread's work, ~250-300 ms of a 1600 x 1120 8-bit RGB image at level
//  6 -- half a whole haze run. Image data longer than kDeflateSegment
//  bytes (filtered, with the filter bytes) are filtered by brume, with
//  libpng's choice of filter per row (the same filtered bytes, tested), and
//  deflated in segments of kDeflateSegment bytes on `threads` threads, each
//  segment a zlib stream of its own primed with the 32 KiB before it (a
//  preset dictionary, as pigz does: matches still reach back across the
//  seam) and ended by a sync flush (an empty stored block, 5 bytes), the
//  last one by the stream's end and the Adler-32 of all. The result is one
//  zlib stream, as PNG requires, that any decoder reads; its bytes differ
//  from libpng's single stream from the first seam on (the file is a few
//  bytes per segment larger: +0.06 % on the 1600 x 1120 demo haze), and do
//  not depend on the thread count (the segments are fixed by the byte
//  count). Held while writing: the filtered image data and their deflated
//  copy (the counts are made a row at a time per thread), as for `fast`.
//  Shorter image data go through libpng's row loop as before: the same
//  file as OpenImageIO's, byte for byte.
inline constexpr std::size_t kDeflateSegment = std::size_t{256} << 10;
struct PngDeflate {
  int level = 6;
  bool rle = false;
  bool fast = false;
  int threads = 1;  // for the segments' deflate (and the filtering before it)
};
// libpng's PNG_FILTER_UP (png.h is not included here): the value of
// OpenImageIO's png:filter attribute for the same rows.
inline constexpr int kPngFilterUp = 0x20;

// Writes `channels`-channel pixels (u8 codes when `codes` is not null, else
// floats converted as OpenImageIO converts them) to `path` at `bits` bits.
// colorspace: "sRGB" or "linear"; description: empty for none. Returns
// false when the file cannot be written, errno as the failing call left it
// and *error libpng's message (empty when the failure was opening or
// closing the file, which errno explains).
bool write_png_subset(const std::string& path, int width, int height, int channels, int bits,
                      const std::uint8_t* codes, const float* values, const std::string& colorspace,
                      const std::string& description, PngDeflate deflate, std::string* error);

}  // namespace brume::detail
