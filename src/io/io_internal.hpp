// brume — what the parts of image I/O share (internal): the declared-size
// check every read makes before it allocates, an extension in lower case,
// and the parsed --bits and --compression of an output.
#pragma once

#include <cstdint>
#include <string>

#include "brume/io.hpp"
#include "io/formats/format.hpp"

namespace brume {

// A header's size against --max-pixels and a sane channel count; throws
// brume::Error naming the file (limits.cpp).
void check_declared_size(const std::string& path, std::int64_t w, std::int64_t h, std::int64_t channels);

// ".PNG" -> ".png" of a path's extension.
std::string lower_ext(const std::string& path);

}  // namespace brume
