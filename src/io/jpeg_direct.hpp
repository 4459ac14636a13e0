// brume — 8-bit grey and colour JPEG read with libjpeg itself (internal).
//
// A JPEG photo (`brume haze --image photo.jpg`) went through OpenImageIO,
// whose first use in a process loads its module (~0.4 s of symbol lookups,
// src/io/codec.hpp): on the 1600 x 1120 demo a JPEG input's read took
// 390-445 ms against a PNG's 50-60 (2026-12-03, AMD EPYC Zen 4).
// OpenImageIO reads JPEG with libjpeg (Debian's libjpeg-turbo), so brume
// reads the common files with the same library and the same settings
// (libjpeg's defaults: islow DCT, fancy upsampling), exactly as it would:
//  - the subset: 8-bit samples, one component (grey, channel Y) or three
//    (YCbCr or RGB, to RGB by libjpeg), baseline, extended or progressive;
//    values as OpenImageIO returns them (the count times the float 1/255),
//    FileInfo as it gives it (format "jpeg", 8 bits, integer, the last
//    comment (COM) as the description);
//  - anything else -- CMYK or YCCK (OpenImageIO converts those itself), a
//    libjpeg error or warning of any kind (a corrupt or truncated file),
//    an Exif block whose first directory names an ImageDescription (which
//    OpenImageIO would report as the description; brume does not parse
//    Exif further) -- returns false, and the caller reads the file through
//    OpenImageIO as before, which then gives its own result or error.
// Test: IO.JpegSubsetIsReadAsOpenImageIOReadsIt (tests/test_io.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

#include "brume/image.hpp"

namespace brume::detail {

struct JpegInfo {
  int width = 0, height = 0, channels = 0;
  std::string description;
};

// Reads `path` into *out (channels 1 or 3, values as OpenImageIO gives
// them, or map(value, 8) when map is given: called once per count, 256
// times) when it is a JPEG of the subset above, calling check(width,
// height, channels) after the header and before any allocation (it may
// throw; its exception propagates). out == nullptr: the header only.
// Returns false, having changed nothing, for any other file or on any
// libjpeg error or warning.
bool read_jpeg_subset(const std::string& path, Image* out, JpegInfo& info,
                      const std::function<void(int, int, int)>& check,
                      const std::function<float(float, int)>& map = {});

// How many reads of this process took the subset path (for tests).
std::uint64_t jpeg_direct_reads();

// The write side: brume's JPEG outputs -- 1 channel (grey) or 3 (RGB), 8
// bits, any quality, a description of at most 60 000 bytes -- written with
// libjpeg as OpenImageIO 2.4's writer writes them: libjpeg's defaults
// (JFIF 1.01, density 1:1, 4:2:0 for colour, the standard Huffman tables,
// baseline) at the quality (98 when none is given), then its markers: the
// description as a comment (with its NUL), an Exif block (a little-endian
// TIFF structure: the description's bytes, then IFD0 with
// ImageDescription and, for sRGB-encoded counts, a pointer to an Exif
// directory holding ExifVersion 0230, ComponentsConfiguration,
// FlashpixVersion 0100 and ColorSpace 1; an empty IFD0 when there is
// neither) and, with a description, a Photoshop 3.0 IPTC block with it as
// the caption (2:120), and the same counts (oiio_count: OpenImageIO's
// rounding) -- hence the same file byte for byte
// (test: IO.JpegSubsetWritesTheFileOpenImageIOWrites). A longer
// description goes to OpenImageIO (its markers would overflow).
bool jpeg_subset_writable(int channels, std::size_t description_bytes);
// codes: 8-bit counts as they are (the sRGB encoder's), else values. false
// and *why on failure (the file may be left partial: the caller writes to
// a temporary).
bool write_jpeg_subset(const std::string& path, int width, int height, int channels, const std::uint8_t* codes,
                       const float* values, bool srgb, const std::string& description, int quality, std::string* why);
// How many files this process wrote that way (for tests).
std::uint64_t jpeg_direct_writes();

}  // namespace brume::detail
