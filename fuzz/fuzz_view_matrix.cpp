// A camera's view matrix file (--view-matrix): four rows of four numbers.
#include <cmath>

#include "brume/camera.hpp"
#include "brume/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = brume::fuzz::temp_path("-view.txt");
  brume::fuzz::write_file(path, data, size);
  try {
    const brume::Mat4 m = brume::read_view_matrix(path);
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c)
        if (!std::isfinite(m.m[r][c])) std::abort();  // validated: a finite rigid transform
  } catch (const brume::Error&) {
  }
  return 0;
}
