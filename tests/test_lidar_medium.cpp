// The LiDAR fog as one implementation of the medium interface
// (brume/medium.hpp): alone, the interface's scan is lidar_fog's bit for bit;
// composed with another medium, extinctions add.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "brume/lidar_fog.hpp"
#include "brume/medium.hpp"
#include "media_stub/stub_medium.hpp"

using namespace brume;
using namespace brume::test;

namespace lidar_medium_tests {

// A fan of beams: elevations −20°..+2°, azimuths all round, ranges 2..80 m,
// intensities 0..1 (a zero among them).
std::vector<float> fan() {
  std::vector<float> v;
  int k = 0;
  for (int e = 0; e < 12; ++e)
    for (int a = 0; a < 90; ++a, ++k) {
      const double el = (-20.0 + 2.0 * e) * M_PI / 180.0, az = a * 4.0 * M_PI / 180.0;
      const double r = 2.0 + 78.0 * ((k * 37) % 101) / 100.0;
      v.insert(v.end(), {static_cast<float>(r * std::cos(el) * std::cos(az)),
                         static_cast<float>(r * std::cos(el) * std::sin(az)), static_cast<float>(r * std::sin(el)),
                         static_cast<float>((k % 11) / 10.0)});
    }
  return v;
}

std::vector<LidarFogParams> fogs() {
  LidarFogParams homogeneous;
  homogeneous.alpha_per_m = 0.06;
  homogeneous.seed = 7;
  LidarFogParams layered;
  layered.profile = HeightProfile::exponential;
  layered.fog.density_per_m = 0.08;
  layered.fog.falloff_per_m = 0.2;
  layered.pose.sensor_height_m = 1.7;
  return {homogeneous, layered};
}

TEST(LidarMedium, AloneTheInterfaceIsLidarFogBitForBit) {
  const std::vector<float> in = fan();
  const std::size_t n = in.size() / 4;
  for (const LidarFogParams& p : fogs()) {
    std::vector<float> direct(in.size()), through(in.size());
    const LidarFogStats st = lidar_fog(in.data(), direct.data(), n, p);
    const std::unique_ptr<Medium> m = lidar_fog_as_medium(p);
    const ScanRun run = scan_through_media({m.get()}, in.data(), through.data(), n);
    EXPECT_EQ(std::memcmp(direct.data(), through.data(), in.size() * sizeof(float)), 0);
    EXPECT_EQ(run.echoes, st.soft);
    EXPECT_GT(st.soft, 0u);
    EXPECT_EQ(m->scan_record(run)["soft_points"], st.soft);
    EXPECT_EQ(m->scan_record(run)["parameters"], lidar_fog_param_table().to_json(p));
  }
}

TEST(LidarMedium, ComposedExtinctionsAddAndItsReturnsStay) {
  const std::vector<float> in = fan();
  const std::size_t n = in.size() / 4;
  constexpr double kRel = 1e-6;  // float32 outputs; the composition's products round differently
  for (const LidarFogParams& p : fogs()) {
    std::vector<float> alone(in.size()), none(in.size()), wet(in.size());
    lidar_fog(in.data(), alone.data(), n, p);
    const std::unique_ptr<Medium> m = lidar_fog_as_medium(p);
    // With a medium of nothing: the same scan, to float rounding.
    const StubMedium empty(0.0, 0.0);
    scan_through_media({m.get(), &empty}, in.data(), none.data(), n);
    for (std::size_t i = 0; i < in.size(); ++i)
      EXPECT_NEAR(none[i], alone[i], std::abs(alone[i]) * kRel + 1e-30) << "value " << i;
    // With a second, analytic medium σ2: a target the fog kept is attenuated
    // by both, e^{−2σ2 R0} more, unless its soft return now wins.
    const double sigma2 = 0.01;
    const StubMedium haze(sigma2, 0.0);
    scan_through_media({&haze, m.get()}, in.data(), wet.data(), n);
    for (std::size_t i = 0; i < n; ++i) {
      const float* q = in.data() + 4 * i;
      if (std::memcmp(q, alone.data() + 4 * i, 3 * sizeof(float)) != 0) continue;  // a soft return
      const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
      const double want = alone[4 * i + 3] * std::exp(-2.0 * sigma2 * r);
      EXPECT_NEAR(wet[4 * i + 3], want, want * kRel + 1e-30) << "point " << i;
    }
  }
}

}  // namespace lidar_medium_tests
