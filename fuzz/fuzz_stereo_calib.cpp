// Middlebury 2014 / ETH3D calib.txt (brume depth convert --calib).
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = brume::fuzz::temp_path("-calib.txt");
  brume::fuzz::write_file(path, data, size);
  try {
    const brume::StereoCalib c = brume::read_stereo_calib(path);
    // What the reader accepted must be usable: a positive focal length and baseline.
    if (!(c.f_px > 0.0) || !(c.baseline_m > 0.0)) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
