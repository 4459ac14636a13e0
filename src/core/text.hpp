// Small text helpers shared by the parsers of manifests, sampling specs,
// parameter values and spectral tables (internal).
#pragma once

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "brume/error.hpp"

namespace brume::text {

// v in printf's %.<digits>g, for messages and records ("0.05", "1.2e+03").
inline std::string g(double v, int digits = 6) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

// `s` without leading and trailing white space (the C locale's isspace:
// space, \t, \n, \v, \f, \r).
inline std::string trim(std::string_view s) {
  std::size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return std::string(s.substr(a, b - a));
}

// ASCII lower case (bytes above 0x7F unchanged).
inline std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// strtod over the whole text ("1e-3", "inf", "nan"), nothing left over and
// nothing trimmed; false for empty text. Callers that refuse non-finite
// values or overflow check v and errno themselves.
inline bool parse_number(const std::string& t, double& v) {
  if (t.empty()) return false;
  char* end = nullptr;
  v = std::strtod(t.c_str(), &end);
  return end == t.c_str() + t.size();
}

// Throws "<what> <v> is not allowed: it must be a finite number > 0" unless v
// is finite and > 0 (v in %g, as std::ostream writes a double).
inline void require_positive(double v, const std::string& what) {
  if (!(v > 0.0) || !std::isfinite(v)) throw Error(what + " " + g(v) + " is not allowed: it must be a finite number > 0");
}

}  // namespace brume::text
