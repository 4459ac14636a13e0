// KITTI object calibration (brume depth convert --kitti-calib), then a
// projection of a fixed four-point scan through what was read. What the
// reader accepts is usable (issue #51: a singular R0_rect, an all-zero
// Tr_velo_to_cam, fx = 0 and a repeated P2: were accepted): R0_rect and
// Tr_velo_to_cam's 3x3 part rotations, P2's focal lengths > 0.
#include <cmath>
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
    for (int which = 0; which < 2; ++which) {
      const double* m = which == 0 ? c.R0 : c.Tr;
      const int stride = which == 0 ? 3 : 4;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          double g = 0.0;
          for (int k = 0; k < 3; ++k) g += m[k * stride + i] * m[k * stride + j];
          if (!(std::abs(g - (i == j ? 1.0 : 0.0)) <= 1.001e-3)) std::abort();
        }
    }
    if (!(c.P2[0] > 0.0 && c.P2[5] > 0.0)) std::abort();
    const brume::LidarImage li = brume::project_velodyne(bin, c, 32, 24);
    if (li.points_in_view > li.points) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
