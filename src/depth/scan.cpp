// brume — LiDAR scans: the one reader of KITTI velodyne .bin files and the
// one validation of a scan's points, for every command that reads a scan
// (depth's --velodyne, brume lidar fog, the camera effects' --lidar, their
// arrays from Python). Issue #51: `lidar fog` and `haze --lidar` had their
// own reader without the 10 M point limit (50 M points ran at 2.4 GB; under
// a memory limit they ended in std::bad_alloc) and read /dev/zero until the
// kernel killed them; depth convert dropped NaN points where lidar fog
// refused them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/text.hpp"

namespace brume {

namespace {
std::string scan_count_text(std::uint64_t n) {
  std::string s = std::to_string(n), out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (i > 0 && (s.size() - i) % 3 == 0) out += ' ';
    out += s[i];
  }
  return out;
}
}  // namespace

std::vector<float> parse_kitti_bin(const std::string& bytes, const std::string& what) {
  if (bytes.size() % 16 != 0)
    throw Error(what + ": " + std::to_string(bytes.size()) +
                " bytes is not a whole number of points (KITTI .bin: 16 bytes a point, float32 x, y, z, "
                "reflectance); the file is truncated or not a KITTI scan");
  if (bytes.size() / 16 > kMaxScanPoints)
    throw Error(what + " holds " + scan_count_text(bytes.size() / 16) + " points; one KITTI scan has ~120 000 and brume "
                "refuses more than " + scan_count_text(kMaxScanPoints) + " (is this a concatenation of scans, or not a "
                "Velodyne .bin?)");
  static_assert(sizeof(float) == 4, "float32");
  std::vector<float> v(bytes.size() / 4);
  if (!v.empty()) std::memcpy(v.data(), bytes.data(), bytes.size());  // little-endian host (x86-64, AArch64)
  return v;
}

std::string kitti_bin_bytes(const float* points, std::size_t n) {
  return std::string(reinterpret_cast<const char*>(points), n * 16);
}

void check_kitti_bin_output(const std::string& path, const std::string& flag) {
  if (std::filesystem::path(path).extension() != ".bin")
    throw Error(flag + " '" + path + "': a scan is written as a KITTI .bin (float32 x, y, z, intensity); name it *.bin");
  check_output_dir(path, flag);
}

std::vector<float> read_kitti_bin(const std::string& path, const std::string& flag, double bytes_per_point) {
  // The size decides before anything is read or allocated: a regular file
  // (brume/io.hpp) of whole points, at most kMaxScanPoints of them, whose
  // run fits in memory.
  InputFile f(path, flag);
  const std::string name = f.name();
  const std::uint64_t bytes = f.size();
  if (bytes % 16 != 0)
    throw Error(name + " is " + std::to_string(bytes) + " bytes, not a whole number of points (KITTI .bin: 16 bytes "
                "a point, float32 x, y, z, reflectance); the file is truncated or not a KITTI scan");
  const std::uint64_t n = bytes / 16;
  if (n > kMaxScanPoints)
    throw Error(name + " holds " + scan_count_text(n) + " points; one KITTI scan has ~120 000 and brume refuses more "
                "than " + scan_count_text(kMaxScanPoints) + " (is this a concatenation of scans, or not a Velodyne "
                ".bin?)");
  check_memory(static_cast<std::uint64_t>(static_cast<double>(n) * std::max(16.0, bytes_per_point)),
               "reading the " + scan_count_text(n) + " points of " + name);
  std::vector<float> v(static_cast<std::size_t>(n) * 4);
  if (n > 0) f.read_all(reinterpret_cast<char*>(v.data()), bytes);
  return v;
}

void validate_scan(const float* xyzi, std::size_t n, const std::string& what) {
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = xyzi + 4 * i;
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(q[c]))
        throw Error(what + ": point " + std::to_string(i) + " has a non-finite " + "xyzi"[c] + " (" + text::g(q[c]) +
                    "); a scan's coordinates and intensities must be finite numbers: drop such points first");
    if (q[3] < 0.0f)
      throw Error(what + ": point " + std::to_string(i) + " has a negative intensity " + text::g(q[3]) +
                  "; intensities are reflectances >= 0");
    const double x = q[0], y = q[1], z = q[2], r = std::sqrt(x * x + y * y + z * z);
    if (r > kMaxScanRangeM)
      throw Error(what + ": point " + std::to_string(i) + " lies " + text::g(r) + " m from the sensor; brume takes "
                  "points up to " + text::g(kMaxScanRangeM) + " m (no LiDAR return is farther: KITTI's HDL-64E reaches "
                  "120 m, survey scanners 6 km): drop the point, or check the scan's units");
  }
}

}  // namespace brume
