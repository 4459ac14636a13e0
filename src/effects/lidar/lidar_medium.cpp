// brume — the LiDAR fog as one implementation of the medium interface
// (brume/medium.hpp; brume/lidar_fog.hpp has the model).
#include <cmath>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>

#include "brume/lidar_fog.hpp"
#include "brume/medium.hpp"
#include "effects/lidar/lidar_fog_tables.hpp"

namespace brume {

namespace {

class LidarFog final : public Medium {
 public:
  explicit LidarFog(const LidarFogParams& p) : p_(p), m_(lidar_fog_medium(p)) {}

  double extinction_per_m() const override { return m_.alpha; }

  double optical_depth(const MediumRay& ray, double range_m) const override {
    if (!std::isnan(m_.alpha)) return m_.alpha * range_m;
    // A height profile: F along the beam, climbing at its world-up component
    // (the layered model's own integral, lidar_fog_layered.cpp).
    if (!layered_) layered_ = lidar_detail::layered_medium(p_);
    const Vec3 o = layered_->world_from_scan.rotation * ray.origin;
    const Vec3 w = layered_->world_from_scan.rotation * ray.dir;
    const double norm = std::sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
    lidar_detail::LayeredMedium md = *layered_;
    // A ray that does not start at the scan's origin starts at another height.
    if (o.y != 0.0) md.density = height_density(layered_profile(), md.table, md.world_from_scan.translation.y + o.y);
    const float r = static_cast<float>(range_m), s = static_cast<float>(norm > 0.0 ? w.y / norm : 0.0);
    float f = 0.0f;
    height_optical_depths(md.density, &r, &s, &f, 1);
    return f;
  }

  // The beams to the scan's points as the layered model integrates them
  // (lidar_fog_layered.cpp: each point's own climb, in float), so that a
  // target's attenuation in a composition is the one lidar_fog applies.
  void scan_optical_depths(const float* points, std::size_t n, double* tau) const override {
    if (!std::isnan(m_.alpha)) return Medium::scan_optical_depths(points, n, tau);
    if (!layered_) layered_ = lidar_detail::layered_medium(p_);
    const Mat3& rot = layered_->world_from_scan.rotation;
    std::vector<float> rf(n), sf(n), f(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double x = points[4 * i], y = points[4 * i + 1], z = points[4 * i + 2];
      const Vec3 w = rot * Vec3{x, y, z};
      const double norm = std::sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
      rf[i] = static_cast<float>(std::sqrt(x * x + y * y + z * z));
      sf[i] = static_cast<float>(norm > 0.0 ? w.y / norm : 0.0);
    }
    height_optical_depths(layered_->density, rf.data(), sf.data(), f.data(), n);
    for (std::size_t i = 0; i < n; ++i) tau[i] = f[i];
  }

  void scan_echoes(const float* points, std::size_t n, std::vector<ScanEcho>& out) const override {
    std::vector<float> fogged(4 * n);
    last_ = lidar_fog(points, fogged.data(), n, p_);
    for (std::size_t i = 0; i < n; ++i) {
      const float* o = fogged.data() + 4 * i;
      if (std::memcmp(points + 4 * i, o, 3 * sizeof(float)) == 0) continue;  // kept: no soft return offered
      out.push_back({i, std::sqrt(double(o[0]) * o[0] + double(o[1]) * o[1] + double(o[2]) * o[2]), o[3]});
    }
  }

  bool scan_alone(const float* in, float* out, std::size_t n, const std::string& what) const override {
    last_ = lidar_fog(in, out, n, p_, what);
    return true;
  }

  nlohmann::json scan_record(const ScanRun&) const override {
    nlohmann::json block = lidar_fog_record(p_, last_);
    block["parameters"] = lidar_fog_param_table().to_json(p_);
    return block;
  }

 private:
  HeightMedium layered_profile() const {
    HeightMedium f = p_.fog;
    f.profile = *p_.profile;
    return f;
  }

  LidarFogParams p_;
  LidarFogMedium m_;
  mutable std::optional<lidar_detail::LayeredMedium> layered_;
  mutable LidarFogStats last_;
};

}  // namespace

std::unique_ptr<Medium> lidar_fog_as_medium(const LidarFogParams& p) { return std::make_unique<LidarFog>(p); }

}  // namespace brume
