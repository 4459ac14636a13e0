// brume — a height density in the per-ray code's form (src/media/height_profile.glsl),
// for the media's own integrals and an effect's passes that embed the profile
// (layered fog's BrumeFog). Internal.
#pragma once

#include "brume/height_profile.hpp"
#include "shared/prelude_cpp.h"

namespace brume {

// The density once per frame or scan; a table of more rows than the code
// holds is refused (brume::Error).
shared::BrumeProfile shared_profile(const HeightDensity& d);

}  // namespace brume
