// brume — OpenEXR beyond the row (internal): the header guard, and the
// layout and named-channel reads of multilayer and multi-part files
// (renderers' files: Blender's "ViewLayer.Combined.R", Nuke's layers, a part
// per layer). The OpenEXR row runs the guard before every open, and every
// file with OpenEXR's magic goes to that row first, so OpenImageIO never
// opens an unguarded one (image_io.cpp).
#pragma once

#include <string>
#include <vector>

#include "io/formats/format.hpp"

namespace brume::io {

// Throws brume::Error naming `path` when an OpenEXR file's header declares an
// attribute larger than what is left of the file. OpenEXR 3.1 (Debian 12)
// allocates each header attribute at its declared size before it reads the
// bytes, so a 1 kB file declaring a 1.7 GB attribute costs 1.7 GB and seconds
// per open (found by fuzz/fuzz_image.cpp; reproducer
// fuzz/corpus/image/openexr_huge_attribute.bin). Any other file, or a header
// the scan cannot follow, is left to the library, which reports it.
void check_exr_attributes(const std::string& path);

// One part of an OpenEXR file: its name (the "name" attribute; empty in a
// single-part file without one), its channels in the file's order (sorted
// by name), its windows, and whether it is deep (many samples per pixel).
struct ExrPart {
  std::string name;
  std::vector<std::string> channels;
  std::vector<int> bits;  // per channel: 16 (half) or 32 (float, uint)
  PixelWindow data, display;
  bool deep = false;
};
struct ExrLayout {
  std::vector<ExrPart> parts;
  bool multipart = false;
  bool blender = false;  // the first part carries Blender's "BlenderMultiChannel" attribute
};

// The layout of an OpenEXR file (headers only, through OpenEXR's multi-part
// API, which reads single-part files too): false for a file that is not
// OpenEXR; brume::Error naming the file for a damaged one.
bool exr_layout(const std::string& path, ExrLayout& out);

// The channels `names` of part `part` (any flat part: scanline or tiled,
// half, float or uint, which OpenEXR converts to float) as float in that
// order, on the part's display window: pixels outside the data window are
// `pad` (OpenEXR's files hold nothing there). The data window must lie
// inside the display window (exr_window_problem). request.check is called
// with the display window's size before any allocation.
void exr_read_channels(const ReadRequest& request, int part, const std::vector<std::string>& names, float pad,
                       Decoded& out);

// Why brume cannot place a part's data window on its display window (it
// reaches outside: overscan), or empty.
std::string exr_window_problem(const ExrPart& p);

}  // namespace brume::io
