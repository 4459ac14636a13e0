// Peers of the diffusion engine (the study's competitors): the direct
// space-variant gather against a true Gaussian, the mip-map blur's level
// variances against their closed forms and its impulse response against the
// target scale, and how each treats a sharp foreground pixel.
#include <cmath>

#include "brume/peers.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

// Per-axis second moment of channel 0 about (cx, cy).
double impulse_variance(const Image& f, int cx, int cy) {
  double m = 0, v = 0;
  for (int y = 0; y < f.height; ++y)
    for (int x = 0; x < f.width; ++x) {
      const double a = f.at(x, y, 0);
      m += a;
      v += a * 0.5 * ((x - cx) * (x - cx) + (y - cy) * (y - cy));
    }
  return v / m;
}

}  // namespace

TEST(PeerGather, ConstantScaleIsATrueGaussian) {
  // With a window of 4 s the truncated mass is 2 * 6.3e-5 per axis; after
  // renormalisation the error against the radius-5s double reference is a
  // fraction of that times the image's contrast (<= 1): RMS bound 1e-4.
  BRUME_REQUIRE_DATA(kArt);
  Image f = to_rgba(read_color(data_path(kArt)));
  for (double sigma : {2.0, 6.0}) {
    Image g = f;
    peers::gather_blur(g, Image(f.width, f.height, 1, static_cast<float>(sigma)), 1.0, 4.0);
    const Diff d = compare(g, gaussian_reference(f, std::sqrt(sigma * sigma - 1.0)), 0, 3);
    EXPECT_LE(d.rms, 1e-4) << "sigma " << sigma << ": " << d;
  }
}

TEST(PeerGather, InnerScaleIsTheIdentity) {
  Image f(9, 7, 4);
  for (std::size_t i = 0; i < f.data.size(); ++i) f.data[i] = static_cast<float>(i % 13) / 13.0f;
  Image g = f;
  peers::gather_blur(g, Image(9, 7, 1, 1.0f), 1.0);
  EXPECT_EQ(g.data, f.data);
}

TEST(PeerMipmap, LevelVariancesMatchClosedForms) {
  // Level 1: Gaussian 1 + box 1/4 = 1.25, plus bilinear reconstruction from
  // texels 2 px apart at phases 1/4 and 3/4: 4 * 3/16 = 0.75 -> 2.0.
  // Level 2: 1.25 + 4 * 1.25 = 6.25, plus 16 * mean t(1-t) over phases
  // 5/8, 7/8, 1/8, 3/8 (= 11/64) = 2.75 -> 9.0. (Worked by hand.)
  EXPECT_DOUBLE_EQ(peers::mipmap_level_variance(0), 0.0);
  EXPECT_NEAR(peers::mipmap_level_variance(1), 2.0, 1e-12);
  EXPECT_NEAR(peers::mipmap_level_variance(2), 9.0, 1e-12);
}

TEST(PeerMipmap, ImpulseReachesTheTargetVariance) {
  // The blend weight is chosen from each level's second moment, so an
  // impulse must spread to the target variance sigma^2 - sigma0^2. What can
  // move it: the sampled (not continuous) Gaussian of each level and the
  // bilinear phase of the impulse against the 2^k grid, whose effect on the
  // second moment about the impulse averages out over the tent's support.
  // Measured within 0.3 % at sigma 2-25; bound 1 % at each of 8 positions.
  const int n = 256;
  for (double sigma : {2.0, 4.5, 9.0, 17.0}) {
    const double target = sigma * sigma - 1.0;
    double mean = 0;
    int count = 0;
    for (int off = 0; off < 8; ++off) {
      Image f(n, n, 4, 0.0f);
      const int c = n / 2 + off;
      f.at(c, c, 0) = 1.0f;
      peers::mipmap_blur(f, Image(n, n, 1, static_cast<float>(sigma)), 1.0);
      const double v = impulse_variance(f, c, c);
      EXPECT_NEAR(v, target, 0.01 * target) << "sigma " << sigma << " offset " << off;
      mean += v, ++count;
    }
    EXPECT_NEAR(mean / count, target, 0.005 * target) << "sigma " << sigma;
  }
}

TEST(PeerMipmap, SharpPixelsReadLevelZeroButBlurredPixelsReadTheirNeighbours) {
  // A sharp near square on a far background at sigma 12: the square keeps its
  // colour exactly (sigma = sigma0 indexes level 0 with weight 0), and the
  // background next to it picks up the square's colour from coarse levels
  // (the leakage Elek et al. mask out).
  const int n = 128;
  Image f(n, n, 4, 0.0f), map(n, n, 1, 12.0f);
  for (int y = 48; y < 80; ++y)
    for (int x = 48; x < 80; ++x) f.at(x, y, 1) = 1.0f, map.at(x, y) = 1.0f;
  Image g = f;
  peers::mipmap_blur(g, map, 1.0);
  for (int y = 48; y < 80; ++y)
    for (int x = 48; x < 80; ++x) ASSERT_EQ(g.at(x, y, 1), 1.0f);
  EXPECT_GT(g.at(45, 64, 1), 0.1f);
}
