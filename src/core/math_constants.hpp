// brume — the angle constants the sky, camera and depth code share (one
// definition, so that the library also builds as one translation unit: the
// sanitizer builds' unity mode, scripts/test-sanitize.sh).
#pragma once

namespace brume {
inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kDeg = kPi / 180.0;  // radians per degree
}  // namespace brume
