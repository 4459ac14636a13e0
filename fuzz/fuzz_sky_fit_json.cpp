// A sky fit's JSON as --turbidity-from reads it (brume aerial, sky render).
#include <cmath>

#include "brume/error.hpp"
#include "brume/sky.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = brume::fuzz::temp_path("-fit.json");
  brume::fuzz::write_file(path, data, size);
  try {
    const double t = brume::turbidity_from_fit_json(path);
    if (!(t >= 1.0 && t <= 20.0)) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
