// brume — errors for bad input.
//
// User-facing failures (a file that cannot be read, a parameter out of range,
// sizes that disagree) throw brume::Error with a message that names the file or
// parameter, the offending value, what is allowed and how to fix it. Internal
// invariants use assert; they are never triggered by user input.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

namespace brume {

// `text` as printable UTF-8: every byte that breaks the UTF-8 encoding and
// every ASCII control character but newline and tab shown as \xHH (the form
// check_utf8 uses), so that a message quoting a damaged file (a corrupt
// OpenEXR attribute name, a libtiff tag) reaches a terminal, a JSON record or
// a Python str whole.
std::string printable_text(std::string_view text);

// Its message is printable UTF-8 whatever it quotes (printable_text).
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(printable_text(what)) {}
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
