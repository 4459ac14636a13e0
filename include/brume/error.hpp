// brume — errors for bad input.
//
// User-facing failures (a file that cannot be read, a parameter out of range,
// sizes that disagree) throw brume::Error with a message that names the file or
// parameter, the offending value, what is allowed and how to fix it. Internal
// invariants use assert; they are never triggered by user input.
#pragma once

#include <stdexcept>
#include <string>

namespace brume {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace brume
