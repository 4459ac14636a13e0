// brume — where the sky of a range map lies (brume/haze.hpp, "The sky"):
// auto (identified sky at infinity in physical units, or --sky-distance), or
// Hansard's S_max whatever the units (the rule of records before schema 3).
// Its own header so that the parameter blocks that hold it (haze, fog, and
// the LiDAR's, through the fog's parameter header) include no effect's whole header.
#pragma once

#include "brume/params.hpp"

namespace brume {

enum class SkyRule { automatic, s_max };
const EnumNames<SkyRule>& sky_rule_names();

}  // namespace brume
