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

}  // namespace brume::detail
