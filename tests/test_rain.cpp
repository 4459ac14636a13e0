// Rain (brume/rain.hpp, issue #56): the extinction against an independent
// numerical integral of the Marshall–Palmer distribution, Atlas's fall
// speed, the drop field's counts against Poisson (χ²), its thinning and its
// cone enumeration against a brute-force search written here, the LiDAR
// rule against a per-beam computation written here, the detection rule's
// loss fraction against its closed form, and `brume lidar rain` with
// `brume run` of its record.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <set>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/rain.hpp"
#include "effects/rain/rain_internal.hpp"
#include "streak_scene.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace rain_tests {

const char* kKitti = "kitti_object_000001/velodyne/000001.bin";
constexpr double kPi = 3.14159265358979323846;

double lambda_of(double r) { return 4.1 * std::pow(r, -0.21); }  // Marshall & Palmer 1948, written again

// σ by composite Simpson in D over [0, 60/Λ] (e^{−60} of the integrand's
// mass lies beyond), 200 000 intervals: the quadrature's error is ~h⁴ of the
// integrand's fourth derivative, below 1e−12 relative.
double extinction_by_quadrature(double rate, double q) {
  const double l = lambda_of(rate), top = 60.0 / l;
  const int m = 200000;
  const double h = top / m;
  const auto f = [&](double d) { return d * d * 8000.0 * std::exp(-l * d); };
  double s = f(0.0) + f(top);
  for (int k = 1; k < m; ++k) s += (k % 2 ? 4.0 : 2.0) * f(k * h);
  return q * (kPi / 4.0) * s * h / 3.0 * 1e-6;  // mm² per m³ → 1/m
}

TEST(RainPhysics, ExtinctionIsTheIntegralOfTheDistribution) {
  for (double r : {1.0, 5.0, 25.0, 100.0}) {
    SCOPED_TRACE(r);
    const double sigma = rain_extinction_per_m(r);
    const double l = lambda_of(r);
    // 1e−6 relative: the target; the quadrature is good to 1e−12.
    EXPECT_NEAR(sigma, extinction_by_quadrature(r, 2.0), 1e-6 * sigma);
    EXPECT_NEAR(sigma, kPi * 8000.0 / (l * l * l) * 1e-6, 1e-12 * sigma);
    // The power law it is usually quoted as (3.65e−4 rounds 3.6473e−4).
    EXPECT_NEAR(sigma, 3.65e-4 * std::pow(r, 0.63), 1e-3 * sigma);
    EXPECT_NEAR(rain_extinction_per_m(r, 1.0), sigma / 2.0, 1e-15 * sigma);
  }
  EXPECT_EQ(rain_extinction_per_m(0.0), 0.0);
  EXPECT_EQ(rain_drops_per_m3(0.0, 0.11, 8.0), 0.0);
}

TEST(RainPhysics, TerminalVelocityIsAtlas1973) {
  for (double d : {0.2, 0.5, 1.0, 2.0, 4.0, 6.0})
    EXPECT_NEAR(atlas_terminal_velocity_m_per_s(d), 9.65 - 10.3 * std::exp(-0.6 * d), 1e-12);
  // Gunn & Kinzer 1949 measured 6.49 m/s at 2 mm and 9.09 m/s at 5 mm: Atlas's fit within 2 %.
  EXPECT_NEAR(atlas_terminal_velocity_m_per_s(2.0), 6.49, 0.02 * 6.49);
  EXPECT_NEAR(atlas_terminal_velocity_m_per_s(5.0), 9.09, 0.02 * 9.09);
  const double d0 = atlas_zero_speed_mm();
  EXPECT_NEAR(d0, 0.1087, 1e-4);
  EXPECT_NEAR(atlas_terminal_velocity_m_per_s(d0), 0.0, 1e-12);
  EXPECT_LT(atlas_terminal_velocity_m_per_s(0.1), 0.0);
  LidarRainParams p;
  p.drops.rate_mm_h = 5.0;
  p.drops.drop_min_mm = 0.1;
  EXPECT_NE(error_of([&] { validate_lidar_rain(p); }).find("--drop-min"), std::string::npos);
}

// Wilson–Hilferty's χ² quantile (k dof, z the normal quantile): within 0.5 %
// of the exact quantile for k >= 10 at these tails.
double chi2_quantile(double k, double z) {
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3);
}
constexpr double kZ999 = 3.2905;  // two-sided significance 0.001

// Drawn counts per volume are Poisson with the integral's mean, on the
// unthinned sampler: the histogram of counts per cell over 100 seeds
// against Poisson's probabilities (χ², bins of expected count >= 5), and the
// counts per 1 m³ over the 100 seeds against Poisson's variance (dispersion
// χ² with 100 dof); both at significance 0.001 (a correct sampler fails one
// in a thousand runs; seeds fixed, so the run is deterministic).
TEST(RainField, CountsPerVolumeArePoissonWithTheIntegralsMean) {
  for (double rate : {5.0, 100.0}) {
    SCOPED_TRACE(rate);
    const double n = rain_drops_per_m3(rate, 0.11, 8.0);
    const double l = lambda_of(rate);
    EXPECT_NEAR(n, 8000.0 / l * (std::exp(-0.11 * l) - std::exp(-8.0 * l)), 1e-12 * n);
    const double mu_cell = n * kRainCellM * kRainCellM * kRainCellM;
    std::vector<double> hist(200, 0.0);
    double dispersion = 0.0, d_sum = 0.0, d_count = 0.0;
    std::vector<RainDrop> drops;
    for (std::uint64_t seed = 0; seed < 100; ++seed) {
      const RainField field(rate, 0.11, 8.0, seed);
      std::size_t total = 0;
      for (int x = -4; x < 4; ++x)
        for (int y = -4; y < 4; ++y)
          for (int z = -4; z < 4; ++z) {  // 512 cells: 1 m³
            drops.clear();
            field.cell_drops({x, y, z}, 0.0, drops);
            hist[std::min<std::size_t>(drops.size(), hist.size() - 1)] += 1.0;
            total += drops.size();
            for (const RainDrop& d : drops) {
              EXPECT_TRUE(d.at.x >= x * kRainCellM && d.at.x < (x + 1) * kRainCellM);
              EXPECT_TRUE(d.at.z >= z * kRainCellM && d.at.z < (z + 1) * kRainCellM);
              EXPECT_TRUE(d.d_mm >= 0.11 && d.d_mm <= 8.0);
              d_sum += d.d_mm, d_count += 1.0;
            }
          }
      dispersion += (total - n) * (total - n) / n;
    }
    EXPECT_GT(dispersion, chi2_quantile(100, -kZ999));
    EXPECT_LT(dispersion, chi2_quantile(100, kZ999));
    // Histogram χ²: counts k merged upwards until a bin expects >= 5; the
    // last bin is the whole upper tail.
    const double cells = 100.0 * 512.0;
    std::vector<double> ob, ex;
    double o = 0.0, e = 0.0, pk = std::exp(-mu_cell), cum = 0.0;
    for (std::size_t k = 0; k + 1 < hist.size(); ++k) {
      o += hist[k], e += cells * pk, cum += pk;
      pk *= mu_cell / (k + 1.0);
      if (e >= 5.0 && cells * (1.0 - cum) >= 5.0) ob.push_back(o), ex.push_back(e), o = e = 0.0;
    }
    double so = 0.0, se = 0.0;
    for (std::size_t j = 0; j < ob.size(); ++j) so += ob[j], se += ex[j];
    ob.push_back(cells - so), ex.push_back(cells - se);
    double chi2 = 0.0;
    for (std::size_t j = 0; j < ob.size(); ++j) chi2 += (ob[j] - ex[j]) * (ob[j] - ex[j]) / ex[j];
    const int bins = static_cast<int>(ob.size());
    ASSERT_GE(bins, 8);
    EXPECT_LT(chi2, chi2_quantile(bins - 1, kZ999)) << bins << " bins, mean " << mu_cell;
    // Diameters: the truncated exponential's mean, D_min + 1/Λ − (D_max − D_min)·e^{−ΛΔ}/(1 − e^{−ΛΔ}),
    // within 4 standard errors (its standard deviation is below 1/Λ).
    const double span = 8.0 - 0.11, cut = std::exp(-l * span);
    const double mean = 0.11 + 1.0 / l - span * cut / (1.0 - cut);
    EXPECT_NEAR(d_sum / d_count, mean, 4.0 / l / std::sqrt(d_count));
  }
}

TEST(RainField, ThinningDrawsAPrefixOfTheSameDrops) {
  const RainField field(25.0, 0.11, 8.0, 9);
  std::vector<RainDrop> all, big;
  for (int x = 0; x < 30; ++x) {
    all.clear(), big.clear();
    field.cell_drops({x, -3, 7}, 0.0, all);
    field.cell_drops({x, -3, 7}, 0.6, big);
    for (std::size_t k = 1; k < all.size(); ++k) EXPECT_LE(all[k].d_mm, all[k - 1].d_mm);  // largest first
    std::size_t above = 0;
    while (above < all.size() && all[above].d_mm >= 0.6) ++above;
    ASSERT_EQ(big.size(), above);
    for (std::size_t k = 0; k < big.size(); ++k) {
      EXPECT_EQ(big[k].d_mm, all[k].d_mm);
      EXPECT_EQ(big[k].at.x, all[k].at.x);
      EXPECT_EQ(big[k].at.y, all[k].at.y);
    }
  }
  // Another seed, another field; another frame, another field.
  std::vector<RainDrop> a, b;
  RainField(25.0, 0.11, 8.0, 10).cell_drops({1, 2, 3}, 0.0, a);
  RainField(25.0, 0.11, 8.0, 9, 1).cell_drops({1, 2, 3}, 0.0, b);
  all.clear();
  field.cell_drops({1, 2, 3}, 0.0, all);
  EXPECT_FALSE(a.size() == all.size() && !a.empty() && a[0].d_mm == all[0].d_mm);
  EXPECT_FALSE(b.size() == all.size() && !b.empty() && b[0].d_mm == all[0].d_mm);
}

// The cells every drop in a cone lies in, found without the DDA: every
// sample of the axis every quarter cell with its 3×3×3 neighbourhood (the
// cone's radius stays below a cell here).
std::set<std::array<std::int64_t, 3>> brute_cells(const MediumRay& ray, double t0, double t1) {
  std::set<std::array<std::int64_t, 3>> s;
  for (double t = t0; t <= t1 + kRainCellM; t += kRainCellM / 4) {
    const std::int64_t cx = static_cast<std::int64_t>(std::floor((ray.origin.x + t * ray.dir.x) / kRainCellM));
    const std::int64_t cy = static_cast<std::int64_t>(std::floor((ray.origin.y + t * ray.dir.y) / kRainCellM));
    const std::int64_t cz = static_cast<std::int64_t>(std::floor((ray.origin.z + t * ray.dir.z) / kRainCellM));
    for (int a = -1; a <= 1; ++a)
      for (int b = -1; b <= 1; ++b)
        for (int c = -1; c <= 1; ++c) s.insert({cx + a, cy + b, cz + c});
  }
  return s;
}

std::vector<MediumRay> random_beams(std::size_t n, unsigned seed) {
  std::mt19937 g(seed);
  std::normal_distribution<double> u(0.0, 1.0);
  std::vector<MediumRay> v;
  for (std::size_t i = 0; i < n; ++i) {
    Vec3 d{u(g), u(g), 0.3 * u(g)};
    const double k = 1.0 / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    v.push_back({{0.0, 0.0, 0.0}, {d.x * k, d.y * k, d.z * k}});
  }
  return v;
}

TEST(RainField, ConeCellsHoldEveryDropOfTheCone) {
  const RainField field(100.0, 0.11, 8.0, 4);
  const double hw = 0.01;  // a wide beam (20 mrad) to make the widening matter
  std::vector<RainCell> cells;
  std::vector<RainDrop> drops;
  std::size_t in_cone = 0;
  for (const MediumRay& b : random_beams(60, 3)) {
    RainField::cone_cells(b, 1.0, 8.0, hw, cells);
    std::set<std::array<std::int64_t, 3>> dda;
    for (const RainCell& c : cells) dda.insert({c.ix, c.iy, c.iz});
    EXPECT_EQ(dda.size(), cells.size());  // each once
    for (const auto& c : brute_cells(b, 1.0, 8.0)) {
      drops.clear();
      field.cell_drops({c[0], c[1], c[2]}, 0.0, drops);
      for (const RainDrop& d : drops) {
        const double t = d.at.x * b.dir.x + d.at.y * b.dir.y + d.at.z * b.dir.z;
        const double perp2 = d.at.x * d.at.x + d.at.y * d.at.y + d.at.z * d.at.z - t * t;
        if (t < 1.0 || t >= 8.0 || perp2 > t * hw * t * hw) continue;
        ++in_cone;
        EXPECT_TRUE(dda.count(c)) << "a drop at range " << t << " in a cell the DDA missed";
      }
    }
  }
  EXPECT_GT(in_cone, 100u);  // the test saw drops
}

// A synthetic scan: n points on random directions at ranges in [lo, hi] m.
std::vector<float> scan(std::size_t n, double lo, double hi, double reflectance, unsigned seed) {
  std::vector<float> v;
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  for (const MediumRay& b : random_beams(n, seed)) {
    const double r = u(g);
    v.insert(v.end(), {static_cast<float>(b.dir.x * r), static_cast<float>(b.dir.y * r),
                       static_cast<float>(b.dir.z * r), static_cast<float>(reflectance)});
  }
  return v;
}

LidarRainParams rain(double rate) {
  LidarRainParams p;
  p.drops.rate_mm_h = rate;
  return p;
}

TEST(LidarRain, RateZeroGivesTheScanBackByteForByte) {
  std::vector<float> in = scan(2000, 0.5, 80.0, 0.3, 2);
  for (std::size_t i = 0; i < 2000; i += 7) in[4 * i + 3] = 0.0f;  // reflectance 0 kept too
  std::vector<float> out(in.size());
  std::vector<std::uint8_t> labels(2000, 9);
  const LidarRainStats st = lidar_rain(in.data(), out.data(), 2000, rain(0.0), labels.data());
  EXPECT_EQ(st.run.lost, 0u);
  EXPECT_EQ(st.run.echoes, 0u);
  EXPECT_EQ(st.drops_drawn, 0u);
  EXPECT_EQ(std::memcmp(in.data(), out.data(), in.size() * 4), 0);
  for (std::uint8_t l : labels) EXPECT_EQ(l, 0);
}

// Per beam, written here: the strongest drop echo over every drop of the
// unthinned field near the axis (brute_cells), by the header's formula.
struct Strongest {
  double power = -1.0, range = 0.0, reported = 0.0;
};
// The farthest one above the floor instead with `farthest`.
Strongest strongest_drop(const RainField& field, const MediumRay& b, double r, const LidarRainParams& p,
                         bool farthest = false) {
  const double theta = p.divergence_mrad * 1e-3, sigma = rain_extinction_per_m(*p.drops.rate_mm_h);
  Strongest s;
  std::vector<RainDrop> drops;
  for (const auto& c : brute_cells(b, p.blind_range_m, std::min(r, 40.0))) {
    drops.clear();
    field.cell_drops({c[0], c[1], c[2]}, 0.0, drops);
    for (const RainDrop& d : drops) {
      const double t = d.at.x * b.dir.x + d.at.y * b.dir.y + d.at.z * b.dir.z;
      const double perp2 = d.at.x * d.at.x + d.at.y * d.at.y + d.at.z * d.at.z - t * t;
      if (t < p.blind_range_m || t >= r || perp2 > (t * theta / 2) * (t * theta / 2)) continue;
      const double a = std::min(1.0, (d.d_mm * 1e-3 / (theta * t)) * (d.d_mm * 1e-3 / (theta * t)));
      const double rep = p.drop_reflectance * std::exp(-2.0 * sigma * t) * a;
      if (rep / (t * t) >= p.noise_floor && (farthest ? t > s.range : rep / (t * t) > s.power)) s = {rep / (t * t), t, rep};
    }
  }
  return s;
}

// The moved points against the per-beam computation: a point whose
// strongest drop beats its target (clear power max(i/r², F), through the
// rain) moves to that drop with its apparent reflectance; one whose drop
// does not beat it is kept or, lost to the speckle draw, takes the drop;
// one with no drop above the floor is kept or lost. Ranges and intensities
// within float32's 1e−6.
TEST(LidarRain, EchoesAreTheStrongestDropOfTheBeamsCone) {
  LidarRainParams p = rain(100.0);
  p.divergence_mrad = 20.0;  // a wide beam: many drops meet it
  p.seed = 5;
  const std::size_t n = 300;
  std::vector<float> in = scan(n, 2.0, 30.0, 0.0, 8);
  for (std::size_t i = 0; i < n; ++i) in[4 * i + 3] = static_cast<float>((i % 10) * 0.1);
  std::vector<float> out(in.size());
  std::vector<std::uint8_t> labels(n);
  const LidarRainStats st = lidar_rain(in.data(), out.data(), n, p, labels.data());
  const RainField field(100.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  const double sigma = rain_extinction_per_m(100.0);
  std::size_t k = 0, moved = 0, beaten = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = in.data() + 4 * i;
    const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
    const MediumRay b{{0, 0, 0}, {q[0] / r, q[1] / r, q[2] / r}};
    const Strongest s = strongest_drop(field, b, r, p);
    const double trans = std::exp(-2.0 * sigma * r);
    const double target = std::max(q[3] / (r * r), p.noise_floor) * trans;
    SCOPED_TRACE(i);
    if (s.power > target) {
      ++beaten;
      ASSERT_EQ(labels[i], 1);
    } else if (s.power < 0.0) {
      ASSERT_NE(labels[i], 1);
    } else {
      ASSERT_NE(labels[i], 2);
    }
    if (labels[i] == 2) continue;
    const float* o = out.data() + 4 * k++;
    if (labels[i] == 1) {
      ++moved;
      const double ro = std::sqrt(double(o[0]) * o[0] + double(o[1]) * o[1] + double(o[2]) * o[2]);
      EXPECT_NEAR(ro, s.range, 2e-6 * s.range);
      EXPECT_NEAR(o[3], s.reported, 1e-6 * s.reported);
    } else {  // kept points carry i·e^{−2σr}, in place
      EXPECT_EQ(o[0], q[0]);
      EXPECT_NEAR(o[3], q[3] * trans, 1e-6 * q[3]);
    }
  }
  EXPECT_EQ(k, n - st.run.lost);
  EXPECT_EQ(moved, st.run.echoes);
  EXPECT_GT(beaten, 10u);  // the test saw drops win
  EXPECT_GT(st.drops_drawn, 0u);
}

// The echoes of two searches, field by field, exactly.
void same_echoes(const std::vector<float>& pts, const LidarRainParams& p, LidarRainSearch a_search,
                 LidarRainSearch b_search, const char* what) {
  SCOPED_TRACE(what);
  const std::size_t n = pts.size() / 4;
  const std::unique_ptr<Medium> ma = lidar_rain_as_medium_searching(p, a_search),
                                mb = lidar_rain_as_medium_searching(p, b_search);
  std::vector<ScanEcho> a, b;
  ma->scan_echoes(pts.data(), n, a);
  mb->scan_echoes(pts.data(), n, b);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_GT(a.size(), n / 50);
  for (std::size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a[k].point, b[k].point) << k;
    EXPECT_EQ(a[k].range_m, b[k].range_m) << a[k].point;
    EXPECT_EQ(a[k].intensity, b[k].intensity) << a[k].point;
    EXPECT_EQ(a[k].reported, b[k].reported) << a[k].point;
  }
}

// The echoes of the cell-major pass and of the beam-by-beam search.
void same_echoes_cell_and_beam(const std::vector<float>& pts, const LidarRainParams& p, const char* what) {
  same_echoes(pts, p, LidarRainSearch::by_cell, LidarRainSearch::by_beam, what);
}

// The scan's echoes drawn cell by cell (each cell once, its drops against the
// beams binned by direction) are the beam-by-beam search's (each beam's cone
// cells enumerated), bit for bit: the same drops win with the same range,
// power and reflectance, on random beams (wide and narrow cones, a blind zone
// of 0, ranges past r_reach), on beams along the axes and near the zenith
// (the binning's edges); and on a sample of KITTI 000001's scan.
TEST(LidarRain, CellMajorPassRepeatsTheBeamByBeamSearchBitForBit) {
  struct Case {
    const char* what;
    std::vector<float> pts;
    LidarRainParams p;
  };
  std::vector<Case> cases;
  const auto with = [](double rate, double div, double blind, std::uint64_t seed) {
    LidarRainParams p = rain(rate);
    p.divergence_mrad = div, p.blind_range_m = blind, p.seed = seed;
    return p;
  };
  // Small scans: the cell-major pass sweeps whole bricks (0.5 m) about each sparse beam.
  cases.push_back({"random, defaults, 25 mm/h", scan(400, 0.5, 40.0, 0.1, 21), with(25.0, 2.0, 1.0, 0)});
  cases.push_back({"random, 100 mm/h, seed 9", scan(400, 1.5, 15.0, 0.0, 22), with(100.0, 2.0, 1.0, 9)});
  cases.push_back({"random, 20 mrad, no blind zone", scan(150, 0.2, 15.0, 0.2, 23), with(100.0, 20.0, 0.0, 3)});
  cases.push_back({"random, 50 mrad, 5 mm/h", scan(100, 0.2, 8.0, 0.0, 24), with(5.0, 50.0, 0.3, 4)});
  {
    std::vector<float> v;  // along the axes, the quadrants' diagonals and near the zenith and nadir
    const double dirs[][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}, {1, 1, 0},
                              {-1, 1, 0}, {-1, -1, 0}, {1, -1, 0}, {1e-4, 0, 1}, {0, -2e-3, -1}, {1, 1, 1}};
    for (int k = 0; k < 12; ++k)
      for (const auto& d : dirs) {
        const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), r = 2.0 + 0.9 * k;
        v.insert(v.end(), {static_cast<float>(d[0] / n * r), static_cast<float>(d[1] / n * r),
                           static_cast<float>(d[2] / n * r), 0.0f});
      }
    cases.push_back({"axes and poles, 20 mrad", v, with(100.0, 20.0, 0.5, 5)});
  }
  for (const Case& c : cases) same_echoes_cell_and_beam(c.pts, c.p, c.what);
}

TEST(LidarRain, CellMajorPassRepeatsTheBeamByBeamSearchOnKitti) {
  const std::string k = "kitti_object_000001/velodyne/000001.bin";
  if (!have_data(k)) GTEST_SKIP() << data_absent(k);
  const std::vector<float> all = read_kitti_bin(data_path(k), "--points");
  std::vector<float> v;  // every 60th point: the beam-by-beam search costs ~20 µs a beam
  for (std::size_t i = 0; i < all.size() / 4; i += 60) v.insert(v.end(), all.begin() + 4 * i, all.begin() + 4 * i + 4);
  LidarRainParams p = rain(25.0);
  p.seed = 1;
  same_echoes_cell_and_beam(v, p, "KITTI 000001, every 60th point, 25 mm/h");
}

// The detection rule: with no drop echo (ρ_d = 0), points at the floor
// (reflectance 0) are lost with the probability 1 − e^{−(1/T − 1)}, T the
// two-way transmittance, within 4 binomial standard errors; at a vanishing
// rate almost none is (the rule is continuous at R = 0).
TEST(LidarRain, LossFollowsTheDetectionRuleAndVanishesWithTheRate) {
  const std::size_t n = 20000;
  const std::vector<float> in = scan(n, 40.0, 40.0, 0.0, 11);
  std::vector<float> out(in.size());
  for (double rate : {100.0, 5.0, 1e-3}) {
    SCOPED_TRACE(rate);
    LidarRainParams p = rain(rate);
    p.drop_reflectance = 0.0;
    const LidarRainStats st = lidar_rain(in.data(), out.data(), n, p);
    const double r = std::sqrt(double(in[0]) * in[0] + double(in[1]) * in[1] + double(in[2]) * in[2]);
    const double trans = std::exp(-2.0 * rain_extinction_per_m(rate) * r);
    const double q = 1.0 - std::exp(-(1.0 / trans - 1.0));
    const double se = std::sqrt(q * (1.0 - q) / n);
    EXPECT_NEAR(static_cast<double>(st.run.lost) / n, q, 4.0 * se + 1.0 / n);
    if (rate < 1.0) {
      EXPECT_LT(st.run.lost, 20u);  // q = 3.8e−4 at 40 m
    }
  }
  // Bright points are hardly lost: 1 − e^{−(F r²/i)(1/T − 1)} = 1.4e−4 at
  // 10 m for i = 0.5; the count within 4 Poisson standard errors (+1).
  const std::vector<float> bright = scan(n, 10.0, 10.0, 0.5, 12);
  LidarRainParams p = rain(100.0);
  p.drop_reflectance = 0.0;
  const LidarRainStats st = lidar_rain(bright.data(), out.data(), n, p);
  const double r = std::sqrt(double(bright[0]) * bright[0] + double(bright[1]) * bright[1] + double(bright[2]) * bright[2]);
  const double trans = std::exp(-2.0 * rain_extinction_per_m(100.0) * r);
  const double mean = n * (1.0 - std::exp(-(p.noise_floor * r * r / 0.5) * (1.0 / trans - 1.0)));
  EXPECT_NEAR(static_cast<double>(st.run.lost), mean, 4.0 * std::sqrt(mean) + 1.0);
}

// The medium composed by hand through the media layer (what a camera
// effect's scan will do) gives lidar_rain's points and labels, bit for bit;
// its record block counts them.
TEST(LidarRain, AsAMediumItComposesAsLidarRainRuns) {
  LidarRainParams p = rain(25.0);
  p.seed = 2;
  const std::size_t n = 3000;
  const std::vector<float> in = scan(n, 1.5, 60.0, 0.05, 4);
  std::vector<float> a(in.size()), b(in.size());
  std::vector<std::uint8_t> la(n), lb(n);
  const LidarRainStats st = lidar_rain(in.data(), a.data(), n, p, la.data());
  const std::unique_ptr<Medium> m = lidar_rain_as_medium(p);
  EXPECT_EQ(m->extinction_per_m(), rain_extinction_per_m(25.0));
  EXPECT_EQ(m->sampled_range_m(), 0.0);  // echoes only: σ over the whole beam
  const ScanDetection det{p.noise_floor, p.seed};
  const ScanRun run = scan_through_media({m.get()}, in.data(), b.data(), n, "scan", &det, lb.data());
  EXPECT_EQ(run.lost, st.run.lost);
  EXPECT_EQ(run.echoes, st.run.echoes);
  EXPECT_GT(run.echoes, 0u);
  EXPECT_EQ(la, lb);
  EXPECT_EQ(std::memcmp(a.data(), b.data(), 16 * (n - run.lost)), 0);
  const nlohmann::json block = m->scan_record(run);
  EXPECT_EQ(block["moved_to_drops"], run.echoes);
  EXPECT_EQ(block["lost"], run.lost);
  EXPECT_EQ(block["kept"], n - run.echoes - run.lost);
  // A ray's particles (the interface's per-ray form) hold the drop a moved point went to.
  std::size_t checked = 0, k = 0;
  for (std::size_t i = 0; i < n && checked < 20; ++i) {
    if (la[i] == 2) continue;
    const float* o = a.data() + 4 * k++;
    if (la[i] != 1) continue;
    const float* q = in.data() + 4 * i;
    const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
    std::vector<Particle> met;
    m->particles({{0, 0, 0}, {q[0] / r, q[1] / r, q[2] / r}}, r, q[3], met);
    const double ro = std::sqrt(double(o[0]) * o[0] + double(o[1]) * o[1] + double(o[2]) * o[2]);
    bool found = false;
    for (const Particle& pt : met) found = found || std::abs(pt.range_m - ro) < 1e-5 * ro;
    EXPECT_TRUE(found) << "point " << i;
    ++checked;
  }
  EXPECT_EQ(checked, 20u);
  // Without a detection the composition is the one before it: no point lost.
  const ScanRun plain = scan_through_media({m.get()}, in.data(), b.data(), n);
  EXPECT_EQ(plain.lost, 0u);
}

TEST(LidarRain, BadInputsAreRefused) {
  LidarRainParams p;
  EXPECT_NE(error_of([&] { validate_lidar_rain(p); }).find("--rate"), std::string::npos);
  EXPECT_NE(error_of([&] { lidar_rain_param_table().set_text(p, "rate", "-1"); }).find("--rate"), std::string::npos);
  EXPECT_NE(error_of([&] { lidar_rain_param_table().set_text(p, "divergence", "0"); }).find("--divergence"),
            std::string::npos);
  p.drops.rate_mm_h = 5.0;
  p.drops.drop_max_mm = 0.1;
  p.drops.drop_min_mm = 0.2;
  EXPECT_NE(error_of([&] { validate_lidar_rain(p); }).find("--drop-max"), std::string::npos);
  std::vector<float> in = scan(10, 2.0, 20.0, 0.3, 1), out(40);
  in[4 * 3 + 3] = -0.5f;
  EXPECT_NE(error_of([&] { lidar_rain(in.data(), out.data(), 10, rain(5.0)); }).find("point 3"), std::string::npos);
}

// `brume lidar rain` end to end: the output and labels, the record, `brume
// run` bit for bit, rate 0 byte for byte; a bad input writes nothing.
class LidarRainCli : public ScratchDirTest {
 protected:
  void write_scan(const std::string& path, const std::vector<float>& pts) {
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(pts.data()), static_cast<std::streamsize>(pts.size() * 4));
  }
};

TEST_F(LidarRainCli, RunsAndBrumeRunRepeatsIt) {
  std::vector<float> pts = scan(3000, 1.5, 60.0, 0.2, 5);
  for (std::size_t i = 0; i < 3000; i += 3) pts[4 * i + 3] = 0.0f;
  write_scan(p("in.bin"), pts);
  fs::create_directories(p("first"));
  const CliRun r = run("lidar rain --points " + p("in.bin") + " --rate 100 --seed 3 --out " +
                       p("first/o.bin") + " --labels " + p("first/l.u8") + " --record " + p("first/o.json"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("moved to drops"), std::string::npos) << r.output;
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["command"], "lidar rain");
  EXPECT_EQ(rec["job"]["rain"]["seed"], 3);
  EXPECT_NEAR(rec["rain"]["extinction_per_m"].get<double>(), rain_extinction_per_m(100.0), 1e-18);
  const std::string labels = file_bytes(p("first/l.u8"));
  ASSERT_EQ(labels.size(), 3000u);
  std::size_t count[3] = {0, 0, 0};
  for (char c : labels) {
    ASSERT_LT(static_cast<unsigned char>(c), 3);
    ++count[static_cast<unsigned char>(c)];
  }
  EXPECT_EQ(count[0], rec["rain"]["kept"].get<std::size_t>());
  EXPECT_EQ(count[1], rec["rain"]["moved_to_drops"].get<std::size_t>());
  EXPECT_EQ(count[2], rec["rain"]["lost"].get<std::size_t>());
  EXPECT_GT(count[1], 0u);
  EXPECT_GT(count[2], 0u);
  EXPECT_EQ(file_bytes(p("first/o.bin")).size(), 16 * (count[0] + count[1]));
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  for (const char* f : {"o.bin", "l.u8"}) {
    const std::string a = file_bytes(p(std::string("first/") + f)), b = file_bytes(p(std::string("again/") + f));
    EXPECT_TRUE(!a.empty() && a == b) << f;
  }
  // Rate 0: the scan back, byte for byte.
  const CliRun zero = run("lidar rain --points " + p("in.bin") + " --rate 0 --out " + p("zero.bin"));
  ASSERT_EQ(zero.status, 0) << zero.output;
  EXPECT_EQ(file_bytes(p("zero.bin")), file_bytes(p("in.bin")));
}

TEST_F(LidarRainCli, BadInputsWriteNothing) {
  std::vector<float> pts = scan(50, 2, 40, 0.3, 1);
  write_scan(p("ok.bin"), pts);
  pts[4 * 7 + 3] = -1.0f;
  write_scan(p("neg.bin"), pts);
  {
    std::ofstream f(p("odd.bin"), std::ios::binary);
    f << std::string(40, '\0');
  }
  const std::string tail = " --out " + p("o.bin") + " --labels " + p("l.u8") + " --record " + p("o.json");
  struct Case {
    std::string args, says;
  };
  for (const Case& c : {Case{"--points " + p("ok.bin"), "--rate"}, Case{"--points " + p("ok.bin") + " --rate -2", "--rate"},
                        Case{"--points " + p("ok.bin") + " --rate 600", "--rate"},
                        Case{"--points " + p("ok.bin") + " --rate 5 --drop-min 3 --drop-max 2", "--drop-max"},
                        Case{"--points " + p("odd.bin") + " --rate 5", "16 bytes"},
                        Case{"--points " + p("neg.bin") + " --rate 5", "point 7"}}) {
    SCOPED_TRACE(c.args);
    const CliRun r = run("lidar rain " + c.args + tail);
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find(c.says), std::string::npos) << r.output;
    for (const char* f : {"o.bin", "l.u8", "o.json"}) EXPECT_FALSE(fs::exists(p(f))) << f;
  }
  const CliRun r = run("lidar rain --points " + p("ok.bin") + " --rate 5 --out " + p("o.ply"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(".bin"), std::string::npos) << r.output;
}


// ---- --return-mode last, the field's motion and frames, the camera's frame (issue #56) ----------

// --return-mode last: a point is kept wherever the detection rule keeps its target (the same draw
// as the strongest mode's, so the lost points are the same ones), else it moves to the farthest
// drop echo above the floor (found here over the unthinned field, strongest_drop's), else it is lost. The three
// searches (beam by beam, cell by cell, the general pass) give the same echoes.
TEST(LidarRain, LastReturnKeepsTheDetectedTargetElseTheFarthestDrop) {
  LidarRainParams p = rain(100.0);
  p.divergence_mrad = 20.0;
  p.seed = 5;
  const std::size_t n = 200;
  std::vector<float> in = scan(n, 2.0, 30.0, 0.0, 8);
  for (std::size_t i = 0; i < n; ++i) in[4 * i + 3] = static_cast<float>((i % 10) * 0.02);
  std::vector<float> out(in.size()), out_s(in.size());
  std::vector<std::uint8_t> labels(n), labels_s(n);
  LidarRainParams ps = p;
  p.return_mode = "last";
  const LidarRainStats st = lidar_rain(in.data(), out.data(), n, p, labels.data());
  lidar_rain(in.data(), out_s.data(), n, ps, labels_s.data());
  const RainField field(100.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  std::size_t k = 0, moved = 0, beaten = 0;
  for (std::size_t i = 0; i < n; ++i) {
    SCOPED_TRACE(i);
    const float* q = in.data() + 4 * i;
    const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
    const MediumRay b{{0, 0, 0}, {q[0] / r, q[1] / r, q[2] / r}};
    const Strongest far = strongest_drop(field, b, r, p, true), strong = strongest_drop(field, b, r, p);
    EXPECT_EQ(labels[i] == 2, labels_s[i] == 2);       // the same detection draws
    if (labels[i] == 1) EXPECT_EQ(labels_s[i], 1);     // a target lost in last mode is lost (or beaten) in strongest
    if (labels[i] == 2) EXPECT_LT(far.power, 0.0);     // lost only without a drop above the floor
    if (labels_s[i] == 1 && labels[i] == 0) ++beaten;  // a drop outshone a target the last return keeps
    if (labels[i] == 2) continue;
    const float* o = out.data() + 4 * k++;
    if (labels[i] == 1) {
      ++moved;
      ASSERT_GE(far.power, 0.0);
      const double ro = std::sqrt(double(o[0]) * o[0] + double(o[1]) * o[1] + double(o[2]) * o[2]);
      EXPECT_NEAR(ro, far.range, 2e-6 * far.range);
      EXPECT_NEAR(o[3], far.reported, 1e-6 * far.reported);
      if (strong.range != far.range) EXPECT_LT(far.power, strong.power);
    } else {
      EXPECT_EQ(o[0], q[0]);
    }
  }
  EXPECT_EQ(moved, st.run.echoes);
  EXPECT_GT(moved, 3u);
  EXPECT_GT(beaten, 10u);
  // The searches agree on the farthest echoes.
  same_echoes(in, p, LidarRainSearch::by_cell, LidarRainSearch::by_beam, "last: cell and beam");
  same_echoes(in, p, LidarRainSearch::general, LidarRainSearch::by_beam, "last: general and beam");
}

// The general pass (the one every moving or calibrated field takes), run on a scan in its own frame
// at frame 0, finds the cell-major pass's echoes bit for bit (random beams, the axes, KITTI).
TEST(LidarRain, GeneralPassRepeatsTheCellPassAtFrameZero) {
  LidarRainParams p = rain(25.0);
  same_echoes(scan(400, 0.5, 40.0, 0.1, 21), p, LidarRainSearch::general, LidarRainSearch::by_cell, "defaults");
  p = rain(100.0);
  p.divergence_mrad = 20.0, p.blind_range_m = 0.0, p.seed = 3;
  same_echoes(scan(150, 0.2, 15.0, 0.2, 23), p, LidarRainSearch::general, LidarRainSearch::by_cell, "20 mrad");
  const std::string k = kKitti;
  if (!have_data(k)) GTEST_SKIP() << data_absent(k);
  const std::vector<float> all = read_kitti_bin(data_path(k), "--points");
  std::vector<float> v;
  for (std::size_t i = 0; i < all.size() / 4; i += 60) v.insert(v.end(), all.begin() + 4 * i, all.begin() + 4 * i + 4);
  p = rain(25.0);
  p.seed = 1;
  same_echoes(v, p, LidarRainSearch::general, LidarRainSearch::by_cell, "KITTI, every 60th point");
}

std::string text_of(double x) {
  char b[64];
  std::snprintf(b, sizeof b, "%.17g", x);
  return b;
}

// A 4x4 rigid transform, written here (row-major, x' = M x).
struct M4 {
  double m[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
  M4 operator*(const M4& b) const {
    M4 r;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        r.m[i][j] = 0;
        for (int k = 0; k < 4; ++k) r.m[i][j] += m[i][k] * b.m[k][j];
      }
    return r;
  }
  Vec3 apply(const Vec3& p) const {
    return {m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3], m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3],
            m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3]};
  }
  M4 inverse() const {  // rigid: [Rᵀ | −Rᵀt]
    M4 r;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) r.m[i][j] = m[j][i];
    for (int i = 0; i < 3; ++i) r.m[i][3] = -(r.m[i][0] * m[0][3] + r.m[i][1] * m[1][3] + r.m[i][2] * m[2][3]);
    return r;
  }
};
M4 from_3x4(const std::vector<double>& v) {
  M4 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) r.m[i][j] = v[4 * i + j];
  return r;
}
M4 yaw(double a, Vec3 t) {  // about camera 0's y axis (down), then t
  M4 r;
  r.m[0][0] = std::cos(a), r.m[0][2] = std::sin(a), r.m[2][0] = -std::sin(a), r.m[2][2] = std::cos(a);
  r.m[0][3] = t.x, r.m[1][3] = t.y, r.m[2][3] = t.z;
  return r;
}
std::string row_3x4(const M4& a) {
  std::string s;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) s += text_of(a.m[i][j]) + (i == 2 && j == 3 ? "" : " ");
  return s;
}

// A KITTI calibration written here: camera 0 looks along the Velodyne's x (x_cam = −y_velo,
// y_cam = −z_velo, z_cam = x_velo) from 0.27 m ahead and 0.08 m below it, slightly turned; R0_rect
// a small rotation; P2 with camera 2's 6 cm baseline.
const std::vector<double> kTr = {0.0, -1.0, 0.0, -0.01, 0.0, 0.0, -1.0, -0.08, 1.0, 0.0, 0.0, -0.27};
std::vector<double> small_rotation() {  // about z by 0.0099 rad, then about y by −0.0074: KITTI's R0_rect's size
  const double a = 0.0099, b = -0.0074;
  const double z[3][3] = {{std::cos(a), -std::sin(a), 0}, {std::sin(a), std::cos(a), 0}, {0, 0, 1}};
  const double y[3][3] = {{std::cos(b), 0, std::sin(b)}, {0, 1, 0}, {-std::sin(b), 0, std::cos(b)}};
  std::vector<double> r(9, 0.0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) r[3 * i + j] += y[i][k] * z[k][j];
  return r;
}
const std::vector<double> kR0 = small_rotation();
const double kFx = 721.5, kCx = 609.6, kCy = 172.9;
const std::vector<double> kP2 = {kFx, 0, kCx, 44.86, 0, kFx, kCy, 0.2164, 0, 0, 1, 0.002746};
std::string kitti_calib_text() {
  const auto line = [](const char* key, const std::vector<double>& v) {
    std::string s = key;
    for (double x : v) s += " " + text_of(x);
    return s + "\n";
  };
  return line("P0:", {kFx, 0, kCx, 0, 0, kFx, kCy, 0, 0, 0, 1, 0}) + line("P1:", {kFx, 0, kCx, -386, 0, kFx, kCy, 0, 0, 0, 1, 0}) +
         line("P2:", kP2) + line("P3:", {kFx, 0, kCx, -339.5, 0, kFx, kCy, 2.2, 0, 0, 1, 0.0027}) + line("R0_rect:", kR0) +
         line("Tr_velo_to_cam:", kTr) + line("Tr_imu_to_velo:", {1, 0, 0, -0.8, 0, 1, 0, 0.3, 0, 0, 1, -0.8});
}
// The drop field's frame from the Velodyne's, written here: camera 2's cv frame (R0·Tr, then
// P2's offset K⁻¹·P2[:, 3]) with the vehicle's axes (x = z_cv, y = −x_cv, z = −y_cv).
M4 field_from_velo() {
  M4 r0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r0.m[i][j] = kR0[3 * i + j];
  const double bz = kP2[11], by = (kP2[7] - kCy * bz) / kFx, bx = (kP2[3] - kCx * bz) / kFx;
  M4 off, axes;
  off.m[0][3] = bx, off.m[1][3] = by, off.m[2][3] = bz;
  axes.m[0][0] = 0, axes.m[0][2] = 1, axes.m[1][0] = -1, axes.m[1][1] = 0, axes.m[2][1] = -1, axes.m[2][2] = 0;
  return axes * off * r0 * from_3x4(kTr);
}
double atlas(double d) { return 9.65 - 10.3 * std::exp(-0.6 * d); }  // written again

class LidarRainFrames : public ScratchDirTest {};

// Consecutive frames show the same drops moved: drops of the field (large ones, 2.5-7 m from the
// sensor) are found at frame K on beams aimed where the closed form puts them -- their hashed
// centre c moved by (w_x, w_y, w_z − v(D))·K·Δt, seen from the sensor's pose at K -- and at
// frame K + 1 displaced by (w − v(D)·z)·Δt. The poses are a KITTI poses file (camera 0 turning
// and driving) with the calibration above; then --ego-speed without a calibration. The echo's range
// equals the drop's distance within 1e−6 m (float32 beam directions at 8 m: ~1e−6 rad of aim).
TEST_F(LidarRainFrames, ConsecutiveFramesShowTheSameDropsMovedInClosedForm) {
  {
    std::ofstream(p("calib.txt")) << kitti_calib_text();
    std::ofstream f(p("poses.txt"));
    for (int k = 0; k < 8; ++k) f << row_3x4(yaw(0.01 + 0.03 * k, {0.02 * k * k, -0.01 * k, 1.1 * k})) << "\n";
  }
  struct Case {
    const char* what;
    bool calib;
    double ego;
  };
  for (const Case& c : {Case{"poses and calibration", true, 0.0}, Case{"ego speed, the scan's frame", false, 12.0}}) {
    SCOPED_TRACE(c.what);
    LidarRainParams p = rain(50.0);
    p.seed = 11, p.wind = "1.5,-2,0.25", p.frame_interval_s = 0.1, p.ego_speed_m_s = c.ego;
    if (c.calib) p.kitti_calib = this->p("calib.txt"), p.poses = this->p("poses.txt");
    const Vec3 w{1.5, -2.0, 0.25};
    const RainField field(50.0, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
    // The sensor's pose at frame k in the field's world, written here.
    std::vector<std::vector<double>> poses;
    {
      std::ifstream f(this->p("poses.txt"));
      for (std::string line; std::getline(f, line);) {
        std::istringstream ls(line);
        std::vector<double> v(12);
        for (double& x : v) ls >> x;
        poses.push_back(v);
      }
    }
    const auto world_from_sensor = [&](int k) {
      if (!c.calib) {
        M4 t;
        t.m[0][3] = c.ego * 0.1 * k;
        return t;
      }
      M4 r0;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r0.m[i][j] = kR0[3 * i + j];
      const M4 cam0_from_velo = r0 * from_3x4(kTr);
      return field_from_velo() * cam0_from_velo.inverse() * from_3x4(poses[0]).inverse() * from_3x4(poses[k]) *
             cam0_from_velo;
    };
    // Large drops of the field in front of the sensor at frame 0.
    std::vector<RainDrop> drops, chosen;
    for (int ix = 16; ix < 48 && chosen.size() < 12; ++ix)
      for (int iy = -16; iy < 16; ++iy)
        for (int iz = -8; iz < 8; ++iz) {
          drops.clear();
          field.cell_drops({ix, iy, iz}, 3.0, drops);
          for (const RainDrop& d : drops) chosen.push_back(d);
        }
    ASSERT_GE(chosen.size(), 8u);
    // Those 2.5-7 m from the sensor at frame 3 (the sensor has moved 3-4 m).
    std::vector<char> use(chosen.size(), 0);
    for (int K : {3, 4}) {
      p.frame = static_cast<std::uint64_t>(K);
      const M4 S = world_from_sensor(K), Sinv = S.inverse();
      std::vector<float> pts;
      std::vector<double> expect;
      for (std::size_t j = 0; j < chosen.size(); ++j) {
        const RainDrop& d = chosen[j];
        const double t = 0.1 * K;
        const Vec3 at{d.at.x + w.x * t, d.at.y + w.y * t, d.at.z + (w.z - atlas(d.d_mm)) * t};  // no layer crossed
        const Vec3 q = Sinv.apply(at);  // in the sensor's frame
        const double r = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
        if (K == 3) use[j] = r > 2.5 && r < 7.0;
        if (!use[j]) continue;
        // The target 5 cm behind the drop, the last return: no other drop of the cone is farther.
        pts.insert(pts.end(), {static_cast<float>(q.x / r * (r + 0.05)), static_cast<float>(q.y / r * (r + 0.05)),
                               static_cast<float>(q.z / r * (r + 0.05)), 0.0f});
        expect.push_back(r);
      }
      ASSERT_GE(expect.size(), 5u);
      p.return_mode = "last";
      const std::unique_ptr<Medium> m = lidar_rain_as_medium(p);
      std::vector<ScanEcho> e;
      m->scan_echoes(pts.data(), expect.size(), e);
      std::vector<double> got(expect.size(), -1.0);
      for (const ScanEcho& x : e) got[x.point] = x.range_m;
      for (std::size_t i = 0; i < expect.size(); ++i) EXPECT_NEAR(got[i], expect[i], 1e-5) << "frame " << K << ", drop " << i;
    }
  }
}

// Frame 0 and no motion give today's scan bit for bit (the flags' since()): --frame 0 with a wind,
// an ego speed or the poses of frame 0 (and its calibration) is the scan without them; a frame > 0
// is a different scan with the same statistics (the field stays Poisson: the fraction of points
// moved to drops at frame 1000 with wind, 100 s, every drop having wrapped in its layer, agrees
// with frame 0's over 3 seeds within 4 standard errors of the difference); bad poses are refused
// naming the flag and line.
TEST_F(LidarRainFrames, FrameZeroRepeatsTheScanAndFramesKeepTheStatistics) {
  std::ofstream(p("calib.txt")) << kitti_calib_text();
  {
    std::ofstream f(p("poses.txt"));
    f << row_3x4(yaw(0.3, {1, 2, 3})) << "\n" << row_3x4(yaw(0.35, {1, 2, 4})) << "\n";
  }
  // A sector ahead (azimuth ±15°, elevation −10° to +2°, 2-6 m, reflectance 0) of 6 mrad beams at
  // 100 mm/h, which meet drops often: the moving field's pass draws each column of its layer the
  // cones cross, so a near sector keeps it cheap.
  std::vector<float> in;
  {
    std::mt19937 g(31);
    std::uniform_real_distribution<double> az(-0.26, 0.26), el(-0.17, 0.035), rr(2.0, 6.0);
    for (int i = 0; i < 2000; ++i) {
      const double a = az(g), e = el(g), r = rr(g);
      in.insert(in.end(), {static_cast<float>(r * std::cos(e) * std::cos(a)), static_cast<float>(r * std::cos(e) * std::sin(a)),
                           static_cast<float>(r * std::sin(e)), 0.0f});
    }
  }
  const auto run_scan = [&](const LidarRainParams& q) {
    std::vector<float> out(in.size());
    std::vector<std::uint8_t> labels(in.size() / 4);
    const LidarRainStats st = lidar_rain(in.data(), out.data(), in.size() / 4, q, labels.data());
    out.resize(4 * (st.run.points - st.run.lost));
    return std::make_pair(out, st);
  };
  LidarRainParams p0 = rain(100.0);
  p0.seed = 2, p0.divergence_mrad = 6.0;
  const auto ref = run_scan(p0);
  LidarRainParams q = p0;
  q.wind = "3,1,0", q.ego_speed_m_s = 20.0;
  EXPECT_EQ(run_scan(q).first, ref.first);
  LidarRainParams c = p0;
  c.kitti_calib = p("calib.txt");
  const auto cal = run_scan(c);
  EXPECT_NE(cal.first, ref.first);  // the camera's frame: other drops
  c.poses = p("poses.txt");
  EXPECT_EQ(run_scan(c).first, cal.first);  // frame 0 of a sequence
  c.frame = 1;
  EXPECT_NE(run_scan(c).first, cal.first);
  // Frame 1000 (100 s: every drop has crossed its layer) against frame 0, 3 seeds.
  double m0 = 0, m1 = 0;
  const double n = static_cast<double>(in.size() / 4) * 3;
  for (std::uint64_t seed = 0; seed < 3; ++seed) {
    LidarRainParams a = p0, b = p0;
    a.seed = b.seed = seed;
    b.frame = 1000, b.wind = "2,-1,0.5";
    m0 += static_cast<double>(run_scan(a).second.run.echoes);
    m1 += static_cast<double>(run_scan(b).second.run.echoes);
  }
  const double f0 = m0 / n, f1 = m1 / n, se = std::sqrt(2.0 * f0 * (1 - f0) / n);
  EXPECT_GT(f0, 0.3);
  EXPECT_NEAR(f1, f0, 4.0 * se) << "moved fractions " << f0 << " at frame 0, " << f1 << " at frame 1000";
  // Refusals.
  {
    std::ofstream(p("bad.txt")) << "1 0 0 0 0 1 0 0 0 0 1\n";
    std::ofstream(p("skew.txt")) << "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n";
  }
  LidarRainParams b = p0;
  b.poses = p("poses.txt");
  EXPECT_NE(error_of([&] { validate_lidar_rain(b); }).find("--kitti-calib"), std::string::npos);
  b.kitti_calib = p("calib.txt");
  b.ego_speed_m_s = 3;
  EXPECT_NE(error_of([&] { validate_lidar_rain(b); }).find("--ego-speed"), std::string::npos);
  b.ego_speed_m_s = 0, b.frame = 2;
  EXPECT_NE(error_of([&] { lidar_rain_as_medium(b); }).find("needs line 3"), std::string::npos);
  b.poses = p("bad.txt"), b.frame = 0;
  EXPECT_NE(error_of([&] { lidar_rain_as_medium(b); }).find("line 1 has 11 numbers"), std::string::npos);
  b.poses = p("skew.txt"), b.frame = 1;
  EXPECT_NE(error_of([&] { lidar_rain_as_medium(b); }).find("not a rotation"), std::string::npos);
  b = p0;
  b.wind = "1,2";
  EXPECT_NE(error_of([&] { validate_lidar_rain(b); }).find("--wind"), std::string::npos);
  b = p0;
  b.return_mode = "first";
  EXPECT_NE(error_of([&] { validate_lidar_rain(b); }).find("return-mode"), std::string::npos);
}

// One frame for the camera's and the scan's drops: with the calibration, every drop the scan echoes
// (beams from the Velodyne into the camera's view, targets 5.5 m away, only drops of 4-8 mm) that
// projects into the image projects through KITTI's P2·R0_rect·Tr_velo_to_cam onto a pixel the camera pass brightened (its
// drops white on black, 0.1 ms: no streak; within a pixel of it). Without the calibration the
// scan's drops are other drops: most of their projections land on black.
TEST_F(LidarRainFrames, ADropTheScanEchoesIsWhereTheCameraDrawsIt) {
  std::ofstream(p("calib.txt")) << kitti_calib_text();
  const int W = 240, Hh = 120;
  Flat f = flat(W, Hh, kFx, 0.0f, 1000.0);
  f.k.cx = kCx - 500.0, f.k.cy = kCy - 110.0;  // a crop of KITTI's frame about its centre (the same P2 shifted)
  CameraRainParams cp;
  cp.drops.rate_mm_h = 100.0, cp.drops.drop_min_mm = 4.0;
  cp.seed = 4, cp.exposure_s = 1e-4, cp.z_split_m = 6.0, cp.epsilon = 0.0;
  const Image img = render_camera_rain(scene_of(f, false, {1.0f, 1.0f, 1.0f}), cp, two_threads());
  // The beams: through pixels of the crop at 8 m in camera 2's frame, from the Velodyne.
  const M4 v2f = field_from_velo(), f2v = v2f.inverse();
  std::vector<float> pts;
  for (int v = 0; v < Hh; v += 1)
    for (int u = 0; u < W; u += 1) {
      const double x = (u - f.k.cx) / kFx, y = (v - f.k.cy) / kFx;  // cv at depth 1
      const Vec3 cv{x * 8, y * 8, 8};
      const Vec3 q = f2v.apply({cv.z, -cv.x, -cv.y});
      const double r = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
      pts.insert(pts.end(), {static_cast<float>(q.x / r * 5.5), static_cast<float>(q.y / r * 5.5),
                             static_cast<float>(q.z / r * 5.5), 0.0f});
    }
  const auto hits = [&](bool calib) {
    LidarRainParams lp;
    lp.drops = cp.drops, lp.seed = cp.seed;
    if (calib) lp.kitti_calib = p("calib.txt");
    std::vector<ScanEcho> e;
    lidar_rain_as_medium(lp)->scan_echoes(pts.data(), pts.size() / 4, e);
    std::size_t lit = 0, inside = 0;
    for (const ScanEcho& x : e) {
      const float* q = pts.data() + 4 * x.point;
      const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
      const Vec3 pv{q[0] / r * x.range_m, q[1] / r * x.range_m, q[2] / r * x.range_m};
      // KITTI's projection, written here: P2·R0_rect·Tr_velo_to_cam.
      M4 r0;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r0.m[i][j] = kR0[3 * i + j];
      const Vec3 c0 = (r0 * from_3x4(kTr)).apply(pv);
      const double X = kP2[0] * c0.x + kP2[2] * c0.z + kP2[3], Y = kP2[5] * c0.y + kP2[6] * c0.z + kP2[7],
                   Z = c0.z + kP2[11];
      const double u = X / Z - 500.0, v = Y / Z - 110.0;  // in the crop
      if (!(u >= 1.0 && u <= W - 2.0 && v >= 1.0 && v <= Hh - 2.0)) continue;  // a cone's edge beyond the crop
      ++inside;
      float best = 0.0f;
      for (int dv = -1; dv <= 1; ++dv)
        for (int du = -1; du <= 1; ++du) {
          const int uu = static_cast<int>(std::lround(u)) + du, vv = static_cast<int>(std::lround(v)) + dv;
          if (uu >= 0 && uu < W && vv >= 0 && vv < Hh) best = std::max(best, img.at(uu, vv, 0));
        }
      lit += best > 0.02f;
    }
    return std::make_pair(inside, lit);
  };
  const auto [n_cal, lit_cal] = hits(true);
  const auto [n_own, lit_own] = hits(false);
  EXPECT_GE(n_cal, 20u);  // the beams met drops that project into the crop
  EXPECT_EQ(lit_cal, n_cal) << "echoed drops the camera did not draw where they project";
  EXPECT_LT(lit_own, n_own / 2) << "the scan's own frame: other drops";
}

}  // namespace rain_tests
