// The count conversion the former direct JPEG and TIFF modules use, until
// their rows (src/io/formats/jpeg.cpp, tiff.cpp) replace them.
#pragma once

#include "io/formats/format.hpp"

namespace brume::detail {
using CountValues = io::CountValues;
inline unsigned oiio_count(float v, float max) { return io::to_count(v, max); }
}  // namespace brume::detail
