// brume — Radiance HDR (RGBE) files read and written by brume itself
// (internal).
//
// `brume sky fit` reads HDR sky photos and panoramas (../shared/data's Poly
// Haven skies are Radiance files); through OpenImageIO each such run paid
// the ~0.3 s module load (src/io/codec.hpp) of a 0.45 s run. The format is
// a text header and run-length coded RGBE pixels, so brume reads the common
// form itself, as OpenImageIO reads it:
//  - the subset: the magic line "#?RADIANCE" or "#?RGBE", header lines up
//    to an empty line (FORMAT, if given, 32-bit_rle_rgbe; other variables
//    and comments are taken as they come, as OpenImageIO takes GAMMA and
//    PRIMARIES: they change no value), the resolution line "-Y H +X W"
//    (rows top to bottom, the usual orientation), then every scanline
//    either run-length coded (the "2 2 hi lo" form, for 8 <= W < 32768)
//    or, when the file's first scanline is not, the whole image stored
//    flat, four bytes a pixel;
//  - the values: (m_R, m_G, m_B) x 2^(e - 136) for e > 0, else 0 (Walter's
//    rgbe2float, which OpenImageIO's reader uses: not Ward's m + 0.5) --
//    exact in float, so the same bits;
//  - FileInfo as OpenImageIO gives it: format "hdr", 32-bit float, R G B,
//    no description.
// Anything else (XYZE, another orientation, the old run-length form, a
// scanline that is short, long or malformed, bytes after the image) returns
// false, and the caller reads the file through OpenImageIO as before.
// Test: IO.HdrSubsetIsReadAsOpenImageIOReadsIt (tests/test_io.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

#include "brume/image.hpp"

namespace brume::detail {

// Reads `path` into *out (3 channels) when it is a Radiance file of the
// subset above, calling check(width, height, 3) before any allocation (it
// may throw). out == nullptr: the header only. Returns false, with *out
// unchanged, for any other file. w, h: the size read from the header.
bool read_hdr_subset(const std::string& path, Image* out, int& width, int& height,
                     const std::function<void(int, int, int)>& check);

// How many reads of this process took the subset path (for tests).
std::uint64_t hdr_direct_reads();

// The write side: an RGB image whose values are all >= 0 or NaN (a sky
// render's ground is NaN), as
// OpenImageIO's writer writes it -- the header "#?RADIANCE",
// "FORMAT=32-bit_rle_rgbe", an empty line, "-Y H +X W"; each pixel by
// Walter's float2rgbe (frexp of the largest component); each scanline of
// 8 to 32767 px run-length coded component by component as Walter's
// RGBE_WriteBytes_RLE does it (runs of 4 or more, at most 127; literal
// stretches of at most 128), narrower or wider images flat -- the same file
// byte for byte (test: IO.HdrSubsetWritesTheFileOpenImageIOWrites). Other
// values (negative, inf: what the writer makes of them depends on an
// undefined cast) go through OpenImageIO.
bool hdr_subset_writable(const float* px, std::size_t n);
// Writes px (w x h x 3 floats) to `path`; false on a failed write (errno
// says why; the file may be left partial: the caller writes to a temporary).
bool write_hdr_subset(const std::string& path, int width, int height, const float* px);
// How many files this process wrote that way (for tests).
std::uint64_t hdr_direct_writes();

}  // namespace brume::detail
