// brume — parameter declarations.
//
// Each effect declares its numeric parameters once, in a table of
// (name, unit, default, allowed range, help, member). The command-line flags,
// the range checks with their error messages and the JSON parameter record
// are all generated from that table (libvips / darktable style), so the three
// can never disagree.
#pragma once

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "brume/error.hpp"

namespace brume {

template <class P>
struct ParamDecl {
  const char* name;   // flag name without dashes, also the record's key
  const char* unit;   // "m", "px", "1" (dimensionless), ...
  double P::*field;
  double min;         // allowed range [min, max] (or (min, max] if min_open)
  double max;
  bool min_open;
  const char* help;
};

// "--name V is out of range: allowed [min, max] (unit). help"
template <class P>
void validate(const P& p, const std::vector<ParamDecl<P>>& table) {
  for (const auto& d : table) {
    const double v = p.*(d.field);
    const bool low = d.min_open ? !(v > d.min) : !(v >= d.min);
    if (!std::isfinite(v) || low || v > d.max) {
      std::ostringstream m;
      m << "--" << d.name << " " << v << " is not allowed: it must be a finite number in "
        << (d.min_open ? "(" : "[") << d.min << ", ";
      if (std::isinf(d.max)) m << "inf)"; else m << d.max << "]";
      m << " (" << d.unit << "); " << d.help;
      throw Error(m.str());
    }
  }
}

// Help text with unit and range, for the CLI.
template <class P>
std::string describe(const ParamDecl<P>& d) {
  std::ostringstream m;
  m << d.help << " [" << d.unit << ", " << (d.min_open ? "(" : "[") << d.min << ", ";
  if (std::isinf(d.max)) m << "inf)"; else m << d.max << "]";
  m << "]";
  return m.str();
}

}  // namespace brume
