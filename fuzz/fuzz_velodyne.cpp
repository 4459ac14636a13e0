// KITTI Velodyne scan (.bin: float32 x, y, z, reflectance per point) through
// the calibration of KITTI object 000000 (training), into a small image.
#include <cmath>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string bin = brume::fuzz::temp_path("-velodyne.bin");
  static const brume::KittiCalib calib = [] {
    brume::KittiCalib c{};
    const double P2[12] = {707.0493, 0, 604.0814, 45.75831, 0, 707.0493, 180.5066, -0.3454157, 0, 0, 1, 0.004981016};
    const double R0[9] = {0.9999128, 0.01009263, -0.008511932, -0.01012729, 0.9999406, -0.004037671,
                          0.008470675, 0.004123522, 0.9999556};
    const double Tr[12] = {0.006927964, -0.9999722, -0.002757829, -0.02457729, -0.001162982, 0.002749836,
                           -0.9999955, -0.06127237, 0.9999753, 0.006931141, -0.001143899, -0.3321029};
    for (int i = 0; i < 12; ++i) c.P2[i] = P2[i], c.Tr[i] = Tr[i];
    for (int i = 0; i < 9; ++i) c.R0[i] = R0[i];
    return c;
  }();
  brume::fuzz::write_file(bin, data, size);
  try {
    // A quarter-size image (KITTI's is 1242 x 375): points land in and out of view.
    const brume::LidarImage li = brume::project_velodyne(bin, calib, 311, 94);
    if (li.points != size / 16 || li.points_in_view > li.points) std::abort();
    // Every point was checked (issue #51: NaN points were dropped where lidar
    // fog refuses them): the map holds finite ranges > 0 or NaN.
    for (float r : li.range.data)
      if (!std::isnan(r) && !(std::isfinite(r) && r > 0.0f)) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
