// brume — which return a scan's beam reports when the media offer several (issue #56's
// --return-mode): brume/medium.hpp's scan_through_media with the rule named. Internal.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "brume/medium.hpp"
#include "brume/params.hpp"

namespace brume {

// strongest: the strongest of the target's return and the echoes above the floor (ties: the
//   target) -- scan_through_media's rule;
// last: the farthest return above the floor: the target whenever ScanDetection keeps it (its
//   conditional detection draw, as for strongest), else the farthest echo (ties: the first
//   offered), else the point is lost. Without a detection the target is always kept.
// The media's scan_echoes must offer, per point, the echo the rule would pick among theirs.
enum class ScanReturn { strongest, last };
ScanRun scan_through_media(const std::vector<const Medium*>& media, const float* in, float* out, std::size_t n,
                           const std::string& what, const ScanDetection* detection, std::uint8_t* labels,
                           ScanReturn mode);

// A --return-mode value ("strongest" or "last", validated by its declaration) as the rule.
inline ScanReturn scan_return(const std::string& mode) {
  return mode == "last" ? ScanReturn::last : ScanReturn::strongest;
}

// The --return-mode declaration every scan through particles shares (brume lidar rain and snow,
// and brume rain and snow's --lidar): `beam` says what reports ("a beam", "the scan of --lidar"),
// `particle` names the particle ("drop", "flake").
template <class P>
void declare_return_mode(ParamTable<P>& d, std::string P::*m, const std::string& beam, const std::string& particle) {
  const std::string help = "which return " + beam + " reports: strongest (the target or the strongest " + particle +
                           " echo above the noise floor), last (the farthest return above the floor: the target "
                           "whenever it is detected, else the farthest " +
                           particle + " echo)";
  d.choice("return-mode", m, {"strongest", "last"}, help.c_str()).since(4, "strongest");
}

}  // namespace brume
