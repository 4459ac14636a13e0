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

// Two kinds a caller may want to tell apart (the Python module maps them to
// FileNotFoundError and RuntimeError; every other Error is a ValueError):
// an input file that does not exist, and no GPU context to run on. Both are
// still brume::Error, so `catch (const Error&)` sees them as before.
class FileNotFound : public Error {
 public:
  using Error::Error;
};
class GpuUnavailable : public Error {
 public:
  using Error::Error;
};

}  // namespace brume
