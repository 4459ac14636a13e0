// brume — the OpenEXR header guard (internal). The OpenEXR row runs it
// before every open, and every file with OpenEXR's magic goes to that row
// first, so OpenImageIO never opens an unguarded one (image_io.cpp).
#pragma once

#include <string>

namespace brume::io {

// Throws brume::Error naming `path` when an OpenEXR file's header declares an
// attribute larger than what is left of the file. OpenEXR 3.1 (Debian 12)
// allocates each header attribute at its declared size before it reads the
// bytes, so a 1 kB file declaring a 1.7 GB attribute costs 1.7 GB and seconds
// per open (found by fuzz/fuzz_image.cpp; reproducer
// fuzz/corpus/image/openexr_huge_attribute.bin). Any other file, or a header
// the scan cannot follow, is left to the library, which reports it.
void check_exr_attributes(const std::string& path);

}  // namespace brume::io
