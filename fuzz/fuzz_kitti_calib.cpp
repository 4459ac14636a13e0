// KITTI object calibration (brume depth convert --kitti-calib), then a
// projection of a fixed four-point scan through what was read.
#include <cstring>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = brume::fuzz::temp_path("-kitti-calib.txt");
  static const std::string bin = [] {
    const float pts[4][4] = {{5, 0, 0, 1}, {10, 1, -1, 1}, {20, -2, 0.5f, 1}, {-3, 0, 0, 1}};
    std::uint8_t b[sizeof pts];
    std::memcpy(b, pts, sizeof pts);
    return brume::fuzz::write_file(brume::fuzz::temp_path("-kitti-scan.bin"), b, sizeof b);
  }();
  brume::fuzz::write_file(path, data, size);
  try {
    const brume::KittiCalib c = brume::read_kitti_calib(path);
    const brume::LidarImage li = brume::project_velodyne(bin, c, 32, 24);
    if (li.points_in_view > li.points) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
