// brume — OpenEXR files read and written with the OpenEXR library itself
// (internal).
//
// OpenImageIO is loaded on first use (src/io/codec.hpp), and that load is
// ~0.3 s of symbol lookups across Debian's OpenImageIO and its 260
// libraries. Range and depth maps are commonly OpenEXR (brume's own demo
// writes its range map as one; renderers write Z as EXR), so a `brume haze
// --range range.exr` paid that load on every run: on the 1600 x 1120 demo,
// 288 of an 867 ms run (2026-12-03, AMD EPYC Zen 4). OpenEXR itself (libOpenEXR
// 3.1 and its 10 libraries, linked by libbrume) costs a fraction of a
// millisecond to load, so brume reads the common EXR files through it,
// exactly as OpenImageIO would (OpenImageIO reads EXR with the same library):
//  - the subset: a single-part scanline or tiled image (no deep data)
//    whose data window is its display window, every channel of one pixel
//    type, half or float, not subsampled, and either one channel (any
//    name) or the channels R, G, B or R, G, B, A -- the orders OpenImageIO
//    gives those sets (it puts R, G, B, A first; other sets it orders by
//    rules of its own, so they stay with it);
//  - the values: each channel converted to float by OpenEXR (half to
//    float is exact), as OpenImageIO's read_image converts them;
//  - FileInfo as OpenImageIO gives it: format "openexr", 16 bits (half) or
//    32 (float), the channel names, the "comments" attribute as the
//    description (OpenImageIO's ImageDescription).
// Anything else, or any exception from OpenEXR (a corrupt or truncated
// file), returns false and the caller reads the file through OpenImageIO
// as before, which gives its own result or its own error message.
// Test: IO.ExrSubsetIsReadAsOpenImageIOReadsIt (tests/test_io.cpp). Writing:
// below.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "brume/image.hpp"

namespace brume::detail {

struct ExrInfo {
  int width = 0, height = 0, channels = 0, bits = 0;
  std::vector<std::string> channel_names;
  std::string description;
};

// Reads `path` into *out (its channels interleaved, as floats) when it is
// an OpenEXR file of the subset above, calling check(width, height,
// channels) after the header and before any allocation (it may throw; its
// exception propagates). out == nullptr: the header only. threads: the
// threads OpenEXR may use to decompress (its own pool; 0: the calling
// thread). Returns false, with *out unchanged, for any other file or on
// any error.
bool read_exr_subset(const std::string& path, Image* out, ExrInfo& info,
                     const std::function<void(int, int, int)>& check, int threads);

// How many reads of this process took the subset path (for tests).
std::uint64_t exr_direct_reads();

// The write side: the files brume writes as EXR -- 1 channel (Y) or 3 (R G
// B), half or float, linear values, compression "auto" (OpenImageIO's
// default, zip) or a named one without a level (none, rle, zip, zips, piz,
// pxr24, b44, b44a, dwaa, dwab) -- written by OpenEXR as OpenImageIO's
// writer writes them: the same header attributes (channels, compression,
// the windows, lineOrder, pixelAspectRatio, screenWindowCenter and Width,
// the description as "comments", the time of writing as "capDate",
// "YYYY:MM:DD HH:MM:SS" in local time), the same values (float to half by
// OpenEXR's conversion, which OpenImageIO uses), hence the same file byte
// for byte bar capDate's value -- except that zip and zips blocks are
// deflated by brume with libdeflate on `threads` threads (OpenEXR's own
// block layout and predictor, its level; 2-2.5x faster than OpenEXR's
// zlib), so their streams differ while every block inflates to OpenEXR's
// bytes (test: IO.ExrSubsetWritesTheFileOpenImageIOWrites). Anything else
// (levels, other channel counts, sRGB-encoded values) goes through
// OpenImageIO.
bool exr_subset_writable(int channels, bool linear, const std::string& compression);
// Writes px (w x h x channels floats) to `path`; false and *why on failure
// (the file may be left partial: the caller writes to a temporary).
bool write_exr_subset(const std::string& path, int width, int height, int channels, bool half, const float* px,
                      const std::string& compression, const std::string& description, int threads, std::string* why);
// How many files this process wrote that way (for tests).
std::uint64_t exr_direct_writes();

}  // namespace brume::detail
