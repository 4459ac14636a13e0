// Rain on KITTI 000001's scan (issue #56's target): the fractions of points lost and moved to a
// drop, per 10 m range bin, against an independent Monte Carlo of the model written here from
// docs/rain.md's equations (not brume's drop field, cells, cone enumeration nor thinning), fed
// the record's θ, ρ_d, floor, D_min, D_max, r_min, σ and Λ; 10 seeds (2 under a sanitizer); within
// 4 standard errors per bin and a χ² over the bins. Skips with a message without the data.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <random>
#include <vector>

#include "brume/depth.hpp"
#include "brume/rain.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace rain_kitti_tests {

constexpr double kPi = 3.14159265358979323846;

// The model of one beam (docs/rain.md, "The LiDAR"), as a Poisson process of the drops whose echo
// reaches the floor F: a drop of diameter D [mm] at axial range t in the beam's cone (cross-section
// π(θt/2)²) between r_min and the target echoes P_d = ρ_d·e^{−2σt}·min((D/(θt))², 1)/t²; its
// intensity in (t, D) is π(θt/2)²·N0·e^{−ΛD} per m per mm. Drops below F are never detected, so
// only D >= D*(t) matters, D*(t) = θ·t²·√(F·e^{2σt}/ρ_d) (the unsaturated branch; none where a
// drop filling the beam stays below F). The cumulative intensity along the axis, M(t), is
// tabulated with the midpoint rule on 2 mm steps.
struct BeamModel {
  double theta = 0, rho_d = 0, floor = 0, d_min = 0, d_max = 0, r_min = 0, sigma = 0, lambda = 0, n0 = 0;
  double t_end = 0.0, dt = 0.0;
  std::vector<double> cum;  // M at r_min + k·dt

  double d_star_mm(double t) const {  // the smallest detectable diameter at t, or +inf
    const double full = rho_d * std::exp(-2.0 * sigma * t) / (t * t);  // a drop filling the beam
    if (full < floor) return INFINITY;
    const double d = 1e3 * theta * t * std::sqrt(floor / full);  // (D/(θt))² = F/full
    return std::max(d, d_min);
  }
  double density(double t) const {  // detectable drops per metre of the axis
    const double a = d_star_mm(t);
    if (!(a < d_max)) return 0.0;
    const double w = theta * t / 2.0;
    return kPi * w * w * n0 / lambda * (std::exp(-lambda * a) - std::exp(-lambda * d_max));
  }
  void tabulate() {
    // Beyond √(D_max·1e−3/(θ·√(F/ρ_d))) not even D_max reaches F (e^{−2σt} <= 1 only lowers it).
    t_end = std::sqrt(d_max * 1e-3 / (theta * std::sqrt(floor / rho_d))) + 0.01;
    const int n = std::max(1, static_cast<int>(std::ceil((t_end - r_min) / 0.002)));
    dt = (t_end - r_min) / n;
    cum.assign(static_cast<std::size_t>(n) + 1, 0.0);
    for (int k = 0; k < n; ++k) cum[k + 1] = cum[k] + density(r_min + (k + 0.5) * dt) * dt;
  }
  double measure(double r) const {  // M(min(r, t_end)), linear within a step
    if (!(r > r_min)) return 0.0;
    const double x = (std::min(r, t_end) - r_min) / dt;
    const std::size_t k = std::min(static_cast<std::size_t>(x), cum.size() - 2);
    return cum[k] + (x - static_cast<double>(k)) * (cum[k + 1] - cum[k]);
  }
  double range_at(double m) const {  // the inverse of measure
    const std::size_t k =
        std::min(static_cast<std::size_t>(std::upper_bound(cum.begin(), cum.end(), m) - cum.begin()), cum.size() - 1);
    const std::size_t j = k == 0 ? 0 : k - 1;
    const double w = cum[j + 1] - cum[j];
    return r_min + (static_cast<double>(j) + (w > 0.0 ? (m - cum[j]) / w : 0.0)) * dt;
  }
};

// Per bin, the expected counts (the sum of the beams' probabilities) and their variance.
struct Bins {
  std::vector<double> n, moved, lost, var_moved, var_lost;  // the Monte Carlo's
  std::vector<double> obs_moved, obs_lost;                  // brume's, over the seeds
  explicit Bins(std::size_t k)
      : n(k), moved(k), lost(k), var_moved(k), var_lost(k), obs_moved(k), obs_lost(k) {}
};

// Adjacent bins merged from the far end until each expects at least `min` counts (the normal
// approximation of a bin's count, and χ²'s rule of thumb).
std::vector<std::pair<std::size_t, std::size_t>> groups(const std::vector<double>& expected, double min) {
  std::vector<std::pair<std::size_t, std::size_t>> g;
  std::size_t end = expected.size();
  double acc = 0.0;
  for (std::size_t i = expected.size(); i-- > 0;) {
    acc += expected[i];
    if (acc >= min || i == 0) {
      if (acc < min && !g.empty()) g.back().first = 0;  // the nearest remainder joins its neighbour
      else g.push_back({i, end});
      end = i, acc = 0.0;
    }
  }
  return g;
}

TEST(LidarRainKitti, BinFractionsAgreeWithAMonteCarloOfTheModel) {
  const std::string rel = "kitti_object_000001/velodyne/000001.bin";
  if (!have_data(rel)) GTEST_SKIP() << data_absent(rel);
  const std::vector<float> all = read_kitti_bin(data_path(rel), "the scan");
  // Every 40th point (3 007 of 120 268; the cost of brume's rain is per beam): points 40 apart in
  // the scan are ~60 mrad apart in azimuth, or on other lasers, so their 2 mrad cones share no
  // drop and the beams are independent, as the standard errors below take them.
  constexpr std::size_t kStride = 40;
  std::vector<float> pts;
  for (std::size_t i = 0; i < all.size() / 4; i += kStride)
    pts.insert(pts.end(), all.begin() + 4 * i, all.begin() + 4 * i + 4);
  const std::size_t n = pts.size() / 4;
  // 10 seeds; 2 in a sanitizer build (the same code paths for ASan to check, at a fifth of the cost:
  // the standard errors below follow the count, the statistics are the uninstrumented run's).
  constexpr int kSeeds = kSanitizerBuild ? 2 : 10;
  constexpr std::size_t kBins = 8;  // 10 m bins; the last holds everything beyond 70 m
  const auto bin_of = [&](std::size_t i) {
    const double r = std::sqrt(double(pts[4 * i]) * pts[4 * i] + double(pts[4 * i + 1]) * pts[4 * i + 1] +
                               double(pts[4 * i + 2]) * pts[4 * i + 2]);
    return std::min(kBins - 1, static_cast<std::size_t>(r / 10.0));
  };

  LidarRainParams p;
  p.drops.rate_mm_h = 25.0;
  Bins b(kBins);
  nlohmann::json rec;
  std::vector<std::uint8_t> labels(n);
  std::vector<float> out(pts.size());
  for (int s = 0; s < kSeeds; ++s) {
    p.seed = static_cast<std::uint64_t>(s) + 1;
    const LidarRainStats st = lidar_rain(pts.data(), out.data(), n, p, labels.data());
    if (s == 0) rec = lidar_rain_record(p, st);
    for (std::size_t i = 0; i < n; ++i) {
      b.obs_moved[bin_of(i)] += labels[i] == 1 ? 1.0 : 0.0;
      b.obs_lost[bin_of(i)] += labels[i] == 2 ? 1.0 : 0.0;
    }
  }

  // The Monte Carlo, from the record's values.
  BeamModel m;
  m.theta = rec["divergence_mrad"].get<double>() * 1e-3;
  m.rho_d = rec["drop_reflectance"].get<double>();
  m.floor = rec["noise_floor_per_m2"].get<double>();
  m.d_min = rec["drop_min_mm"].get<double>();
  m.d_max = rec["drop_max_mm"].get<double>();
  m.r_min = rec["blind_range_m"].get<double>();
  m.sigma = rec["extinction_per_m"].get<double>();
  m.lambda = rec["lambda_per_mm"].get<double>();
  m.n0 = rec["n0_per_m3_mm"].get<double>();
  m.tabulate();
  std::mt19937_64 rng(20261206);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  constexpr int kDraws = 400;  // per beam: the Monte Carlo's variance is 1/40 of the 10 seeds'
  double echoes_checked = 0.0, echoes_below_floor = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = pts[4 * i], y = pts[4 * i + 1], z = pts[4 * i + 2], in = pts[4 * i + 3];
    const double r = std::sqrt(x * x + y * y + z * z);
    const double tr = std::exp(-2.0 * m.sigma * r);        // two-way transmittance
    const double target = in * tr / (r * r);               // P_t
    const double clear = std::max(in / (r * r), m.floor);  // x = max(i/r², F)
    const double keep = std::exp(-(m.floor / clear) * (1.0 / tr - 1.0));  // speckle: kept again when it wins
    const double mu = m.measure(r);
    std::poisson_distribution<int> count(mu > 0.0 ? mu : 1e-300);
    int beaten = 0, none = 0;
    for (int k = 0; k < kDraws; ++k) {
      const int drops = mu > 0.0 ? count(rng) : 0;
      double best = 0.0;
      for (int d = 0; d < drops; ++d) {
        const double t = m.range_at(unit(rng) * mu);
        const double a = m.d_star_mm(t);
        const double dd = a - std::log1p(-unit(rng) * (1.0 - std::exp(-m.lambda * (m.d_max - a)))) / m.lambda;
        const double frac = std::min(1.0, std::pow(dd * 1e-3 / (m.theta * t), 2));
        const double pd = m.rho_d * std::exp(-2.0 * m.sigma * t) * frac / (t * t);
        echoes_checked += 1.0;
        echoes_below_floor += pd < m.floor * (1.0 - 1e-9) ? 1.0 : 0.0;
        best = std::max(best, pd);
      }
      if (drops == 0) ++none;
      else if (best > target) ++beaten;
    }
    // Per beam: moved when a drop beats the target, or the target wins but its speckle is lost
    // and a detectable drop is there; lost when neither (the speckle in expectation).
    const double p_beaten = double(beaten) / kDraws, p_none = double(none) / kDraws;
    const double p_moved = p_beaten + (1.0 - keep) * (1.0 - p_beaten - p_none);
    const double p_lost = (1.0 - keep) * p_none;
    const std::size_t j = bin_of(i);
    b.n[j] += kSeeds;
    b.moved[j] += kSeeds * p_moved;
    b.lost[j] += kSeeds * p_lost;
    // brume's count: a sum of independent Bernoulli draws (10 seeds, independent beams); the
    // Monte Carlo's estimate adds its own variance (kDraws draws of the drops per beam).
    b.var_moved[j] += kSeeds * p_moved * (1.0 - p_moved) * (1.0 + double(kSeeds) / kDraws);
    b.var_lost[j] += kSeeds * p_lost * (1.0 - p_lost) * (1.0 + double(kSeeds) / kDraws);
  }
  EXPECT_GT(echoes_checked, 1000.0);
  EXPECT_EQ(echoes_below_floor, 0.0);  // the sampled region is exactly the detectable one

  // Per group of bins: |brume − Monte Carlo| within 4 standard errors; and χ² over the groups
  // below its 0.999 quantile (Wilson–Hilferty), for each fraction.
  double total_moved = 0.0;
  for (int f = 0; f < 2; ++f) {
    const std::vector<double>& e = f == 0 ? b.moved : b.lost;
    const std::vector<double>& v = f == 0 ? b.var_moved : b.var_lost;
    const std::vector<double>& o = f == 0 ? b.obs_moved : b.obs_lost;
    double chi2 = 0.0;
    const auto g = groups(e, 5.0);
    for (const auto& [lo, hi] : g) {
      double ee = 0.0, vv = 0.0, oo = 0.0, nn = 0.0;
      for (std::size_t j = lo; j < hi; ++j) ee += e[j], vv += v[j], oo += o[j], nn += b.n[j];
      SCOPED_TRACE((f == 0 ? "moved, " : "lost, ") + std::to_string(10 * lo) + "-" +
                   (hi == kBins ? std::string("inf") : std::to_string(10 * hi)) + " m: brume " +
                   std::to_string(oo / nn) + ", Monte Carlo " + std::to_string(ee / nn) + " of " +
                   std::to_string(nn) + " beams");
      EXPECT_LE(std::abs(oo - ee), 4.0 * std::sqrt(vv));
      std::printf("%s %zu-%zu m: brume %.5f MC %.5f of %.0f, z %.2f\n", f == 0 ? "moved" : "lost", 10 * lo, 10 * hi,
                  oo / nn, ee / nn, nn, (oo - ee) / std::sqrt(vv));
      chi2 += (oo - ee) * (oo - ee) / vv;
      if (f == 0) total_moved += oo;
    }
    const double k = static_cast<double>(g.size()), zq = 3.090;  // z of 0.999
    const double q999 = k * std::pow(1.0 - 2.0 / (9.0 * k) + zq * std::sqrt(2.0 / (9.0 * k)), 3);
    EXPECT_LT(chi2, q999) << (f == 0 ? "moved" : "lost") << ": chi2 " << chi2 << " over " << k << " groups";
    std::printf("chi2 %.2f over %.0f groups (0.999: %.2f)\n", chi2, k, q999);
    EXPECT_GE(g.size(), f == 0 ? 4u : 1u);  // the test has bins to compare
  }
  EXPECT_GT(total_moved, 100.0 * kSeeds);
}

}  // namespace rain_kitti_tests
