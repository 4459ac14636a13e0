// KITTI Velodyne scan (.bin: float32 x, y, z, reflectance per point) through
// the LiDAR fog (brume lidar fog's parser and model): any bytes either give
// a brume::Error or a scan of the same count with finite values, in
// homogeneous fog and in height-layered fog.
// (The file is read as the CLI reads --points.)
#include <cmath>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/lidar_fog.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    static const std::string bin = brume::fuzz::temp_path("-lidar.bin");
    brume::fuzz::write_file(bin, data, size);
    const std::vector<float> in = brume::read_kitti_bin(bin, "--points");
    const std::size_t n = in.size() / 4;
    std::vector<float> out(in.size());
    brume::LidarFogParams p;
    p.alpha_per_m = 0.1;
    p.intensity_scale = 1.0;  // any scale of intensities the bytes hold
    const brume::LidarFogStats st = brume::lidar_fog(in.data(), out.data(), n, p, "fuzz");
    if (st.points != n || st.soft > n) std::abort();
    for (float v : out)
      if (!std::isfinite(v)) std::abort();
    // The same scan in height-layered fog (an exponential ground fog, the
    // scan's z up at 1.7 m): the elevation bins and their tables.
    brume::LidarFogParams l;
    l.profile = brume::HeightProfile::exponential;
    l.fog.density_per_m = 0.1;
    l.fog.falloff_per_m = 0.3;
    l.pose.sensor_height_m = 1.7;
    l.intensity_scale = 1.0;
    const brume::LidarFogStats sl = brume::lidar_fog(in.data(), out.data(), n, l, "fuzz");
    if (sl.points != n || sl.soft > n) std::abort();
    for (float v : out)
      if (!std::isfinite(v)) std::abort();
  } catch (const brume::Error&) {
  }
  return 0;
}
