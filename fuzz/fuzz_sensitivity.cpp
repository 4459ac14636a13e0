// Camera spectral sensitivities (brume aerial --sensitivity): the CSV of
// wavelength_nm,r,g,b rows, and the same bytes as a camspec database
// (FILE#CAMERA) looked up under a name taken from the input's first line.
#include <cmath>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "fuzz_util.hpp"

namespace {
void check(const brume::SpectralSensitivity& s) {
  for (const auto& q : s.q)
    for (double v : q)
      if (!std::isfinite(v) || v < 0.0) std::abort();  // a response: finite, >= 0
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = brume::fuzz::temp_path("-sensitivity.csv");
  brume::fuzz::write_file(path, data, size);
  try {
    check(brume::load_sensitivity(path));
  } catch (const brume::Error&) {
  }
  // The camera's name: the text after the first "---" line, as the database lays it out.
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::string camera = "Canon 5D";
  const auto dash = text.find("---");
  if (dash != std::string::npos) {
    const auto nl = text.find('\n', dash);
    if (nl != std::string::npos) camera = text.substr(nl + 1, text.find('\n', nl + 1) - nl - 1);
  }
  try {
    check(brume::load_sensitivity(path + "#" + camera));
  } catch (const brume::Error&) {
  }
  return 0;
}
