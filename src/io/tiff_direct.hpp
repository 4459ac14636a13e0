// brume — the common TIFF files read with libtiff itself (internal).
//
// A TIFF input (a 16-bit photo, a float depth or scale map) went through
// OpenImageIO, whose first use in a process loads its module (~0.4 s of
// symbol lookups, src/io/codec.hpp). OpenImageIO reads TIFF with libtiff,
// so brume reads the common files with the same library, exactly as it
// would:
//  - the subset: the first directory of a classic or BigTIFF file, either
//    byte order; one sample a pixel (PhotometricInterpretation
//    BlackIsZero, channel Y) or three (RGB, channels R G B), no extra
//    samples; 8- or 16-bit unsigned integers or 32-bit IEEE floats; strips
//    or tiles, contiguous or separate planes; no compression, LZW,
//    Deflate, PackBits, ZSTD or LZMA, with or without a predictor (libtiff
//    undoes them); values as OpenImageIO returns them (the count times the
//    float 1/255 or 1/65535; floats as stored), pixels in stored order
//    (OpenImageIO does not apply the Orientation tag either), FileInfo as
//    it gives it (format "tiff", the ImageDescription as the description);
//  - anything else -- a palette, CMYK, YCbCr, alpha or other extra
//    samples, signed, 1/2/4/12-bit or half/double samples, JPEG or other
//    compression, a libtiff error while opening, or an error or warning
//    while decoding the pixels (a corrupt or truncated strip) -- returns
//    false, and the caller reads the file through OpenImageIO as before,
//    which then gives its own result or error.
// Test: IO.TiffSubsetIsReadAsOpenImageIOReadsIt (tests/test_io.cpp).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "brume/image.hpp"

namespace brume::detail {

struct TiffInfo {
  int width = 0, height = 0, channels = 0;
  int bits = 0;            // 8, 16 (unsigned integers) or 32 (float)
  bool floating = false;
  std::string description;
};

// Reads `path` into *out (channels 1 or 3; values as OpenImageIO gives
// them or, for integer files when map is given, map(value, bits): called
// once per distinct count) when it is a TIFF of the subset above, calling
// check(width, height, channels) after the header and before any
// allocation (it may throw; its exception propagates). out == nullptr: the
// header only. Returns false, having changed nothing, for any other file.
bool read_tiff_subset(const std::string& path, Image* out, TiffInfo& info,
                      const std::function<void(int, int, int)>& check,
                      const std::function<float(float, int)>& map = {});

// How many reads of this process took the subset path (for tests).
std::uint64_t tiff_direct_reads();

// The write side: the TIFF files brume writes -- 1 channel (Y) or 3 (R G
// B), 8- or 16-bit counts or 32-bit floats, compression "auto" (zip),
// none, lzw, zip (any level) or packbits -- written with libtiff as
// OpenImageIO 2.4's writer writes them: the same calls in the same order
// (its tags: width, length, 32 rows a strip, samples, Orientation 1, bits,
// sample format, compression, its predictor -- horizontal for counts,
// floating point for floats, with LZW and Deflate --, Deflate's level,
// PhotometricInterpretation, contiguous planes, the description, the time
// of writing as DateTime "YYYY:MM:DD HH:MM:SS" in local time, an Exif
// directory holding ColorSpace = 1 for sRGB-encoded counts; its early
// directory checkpoint, its directory write at close) and the same counts
// (oiio_count: OpenImageIO's rounding). Every file but a Deflate one taller
// than a strip is OpenImageIO's byte for byte bar DateTime's value. As
// OpenImageIO does for counts, the whole 32-row strips of a Deflate file
// are predicted and deflated outside libtiff and written raw -- here for
// floats too (libtiff's floating-point predictor, re-done row by row), on
// `threads` threads, by libdeflate at the file's level rather than zlib:
// those strips' streams differ from OpenImageIO's while each inflates to
// the same bytes, and the directories hold the same tags and values bar
// the strip offsets and sizes. Rows after the last whole strip, and every
// row of the other compressions, go through libtiff's scanline writer
// (test: IO.TiffSubsetWritesTheFileOpenImageIOWrites).
// codes: 8-bit counts as they are (the sRGB encoder's), else values.
bool tiff_subset_writable(int channels, int bits);
// `level` -1: none given (Deflate's default 6). false and *why on failure
// (the file may be left partial: the caller writes to a temporary).
bool write_tiff_subset(const std::string& path, int width, int height, int channels, int bits,
                       const std::uint8_t* codes, const float* values, bool srgb, const std::string& description,
                       const std::string& compression, int level, int threads, std::string* why);
// How many files this process wrote that way (for tests).
std::uint64_t tiff_direct_writes();

}  // namespace brume::detail
