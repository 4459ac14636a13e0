// brume — a stub particle medium (issue #53): what a particle medium (rain,
// snow: issue #56) adds is one implementation of brume/medium.hpp in its own
// folder. This one is a constant extinction σ plus fixed spherical particles:
// within its sampled range r_s the particles stand for the medium (they
// occlude and echo explicitly), beyond it the medium is analytic, σ over
// [r_s, r] (Medium::optical_depth's default), so no optical depth is counted
// twice.
#pragma once

#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "brume/medium.hpp"

namespace brume::test {

struct StubParticle {
  Vec3 at;                          // [m] its centre, in the medium's frame
  double radius_m = 0.1;            // [m] a ray passing nearer than this meets it
  double echo = 0.0;                // its LiDAR return's intensity at the sensor (the scan's scale)
  std::array<float, 3> radiance{};  // its linear RGB radiance (it covers the whole pixel)
};

class StubMedium final : public Medium {
 public:
  StubMedium(double sigma_per_m, double sampled_range_m, std::vector<StubParticle> particles = {})
      : sigma_(sigma_per_m), sampled_(sampled_range_m), particles_(std::move(particles)) {}

  double extinction_per_m() const override { return sigma_; }
  double sampled_range_m() const override { return sampled_; }

  void particles(const MediumRay& ray, double range_m, double, std::vector<Particle>& out) const override {
    for (const StubParticle& p : particles_) {
      const Vec3 d{p.at.x - ray.origin.x, p.at.y - ray.origin.y, p.at.z - ray.origin.z};
      const double t = d.x * ray.dir.x + d.y * ray.dir.y + d.z * ray.dir.z;  // along the ray
      if (!(t > 0.0 && t < range_m && t <= sampled_)) continue;
      const double miss2 = d.x * d.x + d.y * d.y + d.z * d.z - t * t;
      if (miss2 <= p.radius_m * p.radius_m) out.push_back({t, p.echo, 1.0, p.radiance});
    }
  }

  nlohmann::json scan_record(const ScanRun& run) const override {
    return {{"medium", "stub"},
            {"extinction_per_m", sigma_},
            {"sampled_range_m", sampled_},
            {"points", run.points},
            {"echo_points", run.echoes}};
  }

 private:
  double sigma_, sampled_;
  std::vector<StubParticle> particles_;
};

}  // namespace brume::test
