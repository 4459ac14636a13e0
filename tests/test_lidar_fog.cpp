// The LiDAR fog (brume/lidar_fog.hpp, issue #41): the homogeneous model
// against closed forms and an independent double-precision integral of the
// soft-target equation written here (Gauss-Legendre in the pulse's time t,
// where the library uses Simpson's rule in range on a table), its bad inputs,
// and `brume lidar fog` with `brume run` of its record.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/lidar_fog.hpp"
#include "test_util.hpp"

namespace fs = std::filesystem;
using namespace brume;
using namespace brume::test;

namespace lidar_fog_tests {

const char* kKitti = "kitti_object_000001/velodyne/000001.bin";

LidarFogParams with_alpha(double a, bool noise = false) {
  LidarFogParams p;
  p.alpha_per_m = a;
  p.noise = noise ? "on" : "off";
  return p;
}

// A synthetic scan: n points on random directions at ranges in [lo, hi] m,
// reflectance in [0, 1].
std::vector<float> scan(std::size_t n, double lo, double hi, unsigned seed = 1) {
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<float> v(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double az = 2 * M_PI * u(g), el = (u(g) - 0.7) * 0.5, r = lo + (hi - lo) * u(g);
    v[4 * i] = static_cast<float>(r * std::cos(el) * std::cos(az));
    v[4 * i + 1] = static_cast<float>(r * std::cos(el) * std::sin(az));
    v[4 * i + 2] = static_cast<float>(r * std::sin(el));
    v[4 * i + 3] = static_cast<float>(u(g));
  }
  return v;
}

// A synthetic scan with KITTI's ranges: n points on random directions as
// scan()'s, their ranges drawn from the range histogram of KITTI object
// 000001's scan (../shared/data/kitti_object_000001/velodyne/000001.bin,
// 120 268 points, 1.5-79.9 m, median 9.9 m; the counts below, uniform within
// each bin; the 40 points under 3 m left out): most points at 5-30 m (80 %;
// 43 % at 5-10 m, mostly the road around the car), 8.5 % at 3-5 m, and a tail
// of 10 % at 30-50 m and 1.4 % out to 80 m. Hard returns left by fog of
// alpha 0.06 / 0.2 / 0.3 per m (`brume lidar fog --noise off`, 2026-12-05):
// KITTI's scan 97 / 71 / 57 %, this histogram (20 000 points drawn with
// numpy) 93 / 64 / 51 %; ranges uniform over 2-80 m instead, the former
// fallback (half the points beyond 41 m, which no street scene gives),
// 43 / 15 / 10 %, under the test's bound of half at 0.06 already.
std::vector<float> kitti_like_scan(std::size_t n, unsigned seed = 1) {
  static const double edges[] = {3, 5, 10, 15, 20, 30, 40, 50, 60, 70, 80};
  static const double counts[] = {10275, 51785, 21499, 10465, 12158, 9718, 2655, 934, 531, 208};
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::discrete_distribution<int> bin(std::begin(counts), std::end(counts));
  std::vector<float> v(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const int b = bin(g);
    const double az = 2 * M_PI * u(g), el = (u(g) - 0.7) * 0.5, r = edges[b] + (edges[b + 1] - edges[b]) * u(g);
    v[4 * i] = static_cast<float>(r * std::cos(el) * std::cos(az));
    v[4 * i + 1] = static_cast<float>(r * std::cos(el) * std::sin(az));
    v[4 * i + 2] = static_cast<float>(r * std::sin(el));
    v[4 * i + 3] = static_cast<float>(u(g));
  }
  return v;
}

// KITTI's scan, or without the data a synthetic one with its ranges.
std::vector<float> kitti_or_synthetic() {
  if (have_data(kKitti)) return read_kitti_bin(data_path(kKitti), "test");
  return kitti_like_scan(20000);
}

double range_of(const float* q) {
  const double x = q[0], y = q[1], z = q[2];
  return std::sqrt(x * x + y * y + z * z);
}

// ---- the independent reference: the soft-target equation as the paper writes it ----
// P_soft(R; R0) = C_A·P0·β_b·∫_0^{2τ_H} sin²(πt/(2τ_H))·ξ(r)e^{−2αr}/r²·U(R0 − r) dt,
// r = R − ct/2, by 8-point Gauss-Legendre on `panels` panels of each piece
// between the breakpoints (ξ's kinks at R1, R2 and the cut at R0).
struct Reference {
  double alpha, beta_b, c_a, p0, tau, r1, r2;
  explicit Reference(const LidarFogParams& p) {
    const double c = 299792458.0;
    alpha = *p.alpha_per_m;
    beta_b = p.beta_b ? *p.beta_b : 0.046 * alpha / std::log(20.0);
    c_a = c * p.l_r * p.a_r_m2 / 2;
    p0 = p0_of(p);
    tau = p.tau_h_ns * 1e-9;
    r1 = p.r1_m;
    r2 = p.r2_m;
  }
  static double p0_of(const LidarFogParams& p) { return p.p0_w; }
  double integrand(double t, double R, double R0) const {
    const double c = 299792458.0, r = R - c * t / 2;
    if (r <= r1 || r > R0) return 0.0;
    const double xi = r >= r2 ? 1.0 : (r - r1) / (r2 - r1);
    const double s = std::sin(M_PI * t / (2 * tau));
    return s * s * xi * std::exp(-2 * alpha * r) / (r * r);
  }
  double power(double R, double R0 = INFINITY, int panels = 40) const {
    static const double x[8] = {-0.9602898564975363, -0.7966664774136267, -0.5255324099163290, -0.1834346424956498,
                                0.1834346424956498,  0.5255324099163290,  0.7966664774136267,  0.9602898564975363};
    static const double w[8] = {0.1012285362903763, 0.2223810344533745, 0.3137066458778873, 0.3626837833783620,
                                0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};
    const double c = 299792458.0;
    std::vector<double> cuts = {0.0, 2 * tau};
    for (double rr : {r1, r2, R0}) {
      const double t = 2 * (R - rr) / c;
      if (t > 0 && t < 2 * tau) cuts.push_back(t);
    }
    std::sort(cuts.begin(), cuts.end());
    double sum = 0.0;
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k)
      for (int q = 0; q < panels; ++q) {
        const double a = cuts[k] + (cuts[k + 1] - cuts[k]) * q / panels;
        const double b = cuts[k] + (cuts[k + 1] - cuts[k]) * (q + 1) / panels;
        for (int i = 0; i < 8; ++i)
          sum += 0.5 * (b - a) * w[i] * integrand(0.5 * (a + b) + 0.5 * (b - a) * x[i], R, R0);
      }
    return c_a * p0 * beta_b * sum;
  }
  // The cut curve's maximum by a dense scan (step / 8) and a golden refinement.
  void peak(double R0, double step, double& best_p, double& best_r) const {
    best_p = 0.0;
    best_r = 0.0;
    const double c = 299792458.0, end = std::min(R0, 1e9) + c * tau;
    for (double R = r1; R <= std::min(end, r2 + c * tau + 1.0); R += step / 8) {
      const double v = power(R, R0, 8);
      if (v > best_p) best_p = v, best_r = R;
    }
    double a = best_r - step / 8, b = best_r + step / 8;
    for (int i = 0; i < 60; ++i) {
      const double m1 = b - (b - a) * 0.618033988749895, m2 = a + (b - a) * 0.618033988749895;
      if (power(m1, R0) < power(m2, R0)) a = m1; else b = m2;
    }
    best_r = 0.5 * (a + b);
    best_p = power(best_r, R0);
  }
};

}  // namespace lidar_fog_tests
using namespace lidar_fog_tests;

// α = 0 (and an infinite visibility) is no fog: the scan comes back bit for bit.
TEST(LidarFog, NoFogReturnsTheInputBitForBit) {
  const std::vector<float> in = kitti_or_synthetic();
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size(), -1.0f);
  lidar_fog(in.data(), out.data(), n, with_alpha(0.0, true));
  EXPECT_EQ(std::memcmp(in.data(), out.data(), in.size() * sizeof(float)), 0);
  LidarFogParams v;
  v.visibility_m = INFINITY;
  std::fill(out.begin(), out.end(), -1.0f);
  const LidarFogStats st = lidar_fog(in.data(), out.data(), n, v);
  EXPECT_EQ(std::memcmp(in.data(), out.data(), in.size() * sizeof(float)), 0);
  EXPECT_EQ(st.soft, 0u);
}

// Points that stay hard keep their coordinates bit for bit and have
// intensity i·e^{−2αR} (float of the double product: one rounding, so the
// tolerance is one float ulp); the count never changes and nothing is rounded
// to the [0, 255] scale (KITTI's reflectances stay in [0, 1]).
TEST(LidarFog, HardReturnsAreAttenuatedByTwiceTheOpticalDepth) {
  const std::vector<float> in = kitti_or_synthetic();
  const std::size_t n = in.size() / 4;
  for (double alpha : {0.01, 0.06, 0.2}) {
    SCOPED_TRACE(alpha);
    std::vector<float> out(in.size());
    const LidarFogStats st = lidar_fog(in.data(), out.data(), n, with_alpha(alpha));
    std::size_t hard = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const float* q = &in[4 * i];
      const float* o = &out[4 * i];
      if (std::memcmp(q, o, 3 * sizeof(float)) != 0) continue;  // moved: a fog return
      ++hard;
      const double want = q[3] * std::exp(-2 * alpha * range_of(q));
      ASSERT_NEAR(o[3], want, std::nextafter(static_cast<float>(want), 1e9f) - static_cast<float>(want)) << i;
    }
    EXPECT_EQ(hard + st.soft, n);
    EXPECT_GT(hard, n / 2);
  }
}

// The tabulated soft curve against the reference integral: every node within
// 1e-6 of the peak power (Simpson on 1-cm cells and Gauss-Legendre agree to
// ~1e-9 relative on the smooth parts; 1e-6 leaves room for the kink cells),
// the peak's range within one table step (the table's peak is its node
// maximum) and its power within 1e-4 (a node within h/2 of a parabola's top
// of width ~L: (h/L)² ~ 1e-5).
TEST(LidarFog, SoftCurveMatchesTheIntegralOfTheSoftTargetEquation) {
  for (double alpha : {0.03, 0.1, 0.3}) {
    SCOPED_TRACE(alpha);
    const LidarFogParams p = with_alpha(alpha);
    const SoftCurve c = lidar_soft_curve(p, 30.0);
    const Reference ref(p);
    ASSERT_GT(c.power_w.size(), 3000u);
    EXPECT_NEAR(c.step_m, 299792458.0 * 20e-9 / kLidarStepsPerPulse, 1e-15);
    double worst = 0.0;
    for (std::size_t j = 0; j < c.power_w.size(); j += 7)
      worst = std::max(worst, std::abs(c.power_w[j] - ref.power(j * c.step_m)));
    EXPECT_LT(worst, 1e-6 * c.peak_w);
    double pp, pr;
    ref.peak(INFINITY, c.step_m, pp, pr);
    EXPECT_NEAR(c.peak_range_m, pr, c.step_m);
    EXPECT_NEAR(c.peak_w, pp, 1e-4 * pp);
    // The paper's magnitudes: a fraction of a milliwatt a few metres out.
    EXPECT_GT(c.peak_range_m, p.r2_m);
    EXPECT_LT(c.peak_range_m, p.r2_m + 299792458.0 * 20e-9);
  }
}

// A surface closer than the uncut peak cuts the fog behind it: with a
// backscatter strong enough that every point turns into fog, each point's
// soft intensity and range are the cut curve's peak (the prefix/suffix
// tables, interpolated in R0) against the reference's dense search, within
// 2e-4 in power (quadratic interpolation between 1-cm nodes of a peak that
// grows like (R0 - R1)^2 near R1; linear interpolation missed by 2e-3 at
// R0 = 0.95 m) and 1.5 steps in range (node maximum, linear in R0).
TEST(LidarFog, CutCurvePeaksMatchTheReferenceAtEveryRange) {
  LidarFogParams p = with_alpha(0.05);
  p.beta_b = 1e4;  // unphysical: strong enough that every point, the nearest too, turns into fog
  const LidarFogMedium m = lidar_fog_medium(p);
  const Reference ref(p);
  const double h = m.pulse_m / kLidarStepsPerPulse;
  std::vector<float> in;
  for (double r0 : {0.95, 0.97, 1.05, 1.3, 2.0, 2.777, 3.5, 4.2, 6.0, 25.0}) in.insert(in.end(), {0.0f, static_cast<float>(r0), 0.0f, 0.5f});
  std::vector<float> out(in.size());
  const LidarFogStats st = lidar_fog(in.data(), out.data(), in.size() / 4, p);
  ASSERT_EQ(st.soft, in.size() / 4);
  for (std::size_t i = 0; i < in.size() / 4; ++i) {
    const double r0 = in[4 * i + 1];
    SCOPED_TRACE(r0);
    double pp, pr;
    ref.peak(r0, h, pp, pr);
    const double xi = r0 >= p.r2_m ? 1.0 : (r0 - p.r1_m) / (p.r2_m - p.r1_m);
    const double hard_clear = m.c_a * p.p0_w * m.beta0 * xi / (r0 * r0);
    EXPECT_NEAR(out[4 * i + 3], 0.5 * pp / hard_clear, 2e-4 * 0.5 * pp / hard_clear);
    EXPECT_NEAR(out[4 * i + 1], pr, 1.5 * h);
    EXPECT_EQ(out[4 * i], 0.0f);  // along the beam
    EXPECT_EQ(out[4 * i + 2], 0.0f);
  }
}

// Denser fog turns more of the scan into fog returns.
TEST(LidarFog, FogFractionGrowsWithAlpha) {
  const std::vector<float> in = kitti_or_synthetic();
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  std::size_t last = 0;
  for (double alpha : {0.005, 0.02, 0.04, 0.06, 0.08, 0.12, 0.2, 0.3}) {
    const LidarFogStats st = lidar_fog(in.data(), out.data(), n, with_alpha(alpha));
    EXPECT_GE(st.soft, last) << alpha;
    last = st.soft;
  }
  EXPECT_GT(last, n / 10);
}

// i_soft is proportional to i: a point of zero reflectance stays where it
// is, with intensity 0, whatever the fog; the noise is seeded.
TEST(LidarFog, ZeroReflectanceNeverBecomesFogAndTheNoiseIsSeeded) {
  std::vector<float> in = scan(5000, 1.0, 120.0);
  for (std::size_t i = 0; i < in.size() / 4; i += 2) in[4 * i + 3] = 0.0f;
  std::vector<float> out(in.size()), again(in.size()), other(in.size());
  LidarFogParams p = with_alpha(0.3, true);
  const LidarFogStats st = lidar_fog(in.data(), out.data(), in.size() / 4, p);
  EXPECT_GT(st.soft, in.size() / 16);
  for (std::size_t i = 0; i < in.size() / 4; i += 2) {
    EXPECT_EQ(std::memcmp(&in[4 * i], &out[4 * i], 3 * sizeof(float)), 0) << i;
    EXPECT_EQ(out[4 * i + 3], 0.0f);
  }
  lidar_fog(in.data(), again.data(), in.size() / 4, p);
  EXPECT_EQ(std::memcmp(out.data(), again.data(), out.size() * sizeof(float)), 0);
  p.seed = 7;
  lidar_fog(in.data(), other.data(), in.size() / 4, p);
  EXPECT_NE(std::memcmp(out.data(), other.data(), out.size() * sizeof(float)), 0);
  // Noise off: every fog return sits at the soft peak's range (float rounding).
  p.noise = "off";
  const LidarFogStats s2 = lidar_fog(in.data(), out.data(), in.size() / 4, p);
  for (std::size_t i = 0; i < in.size() / 4; ++i)
    if (std::memcmp(&in[4 * i], &out[4 * i], 3 * sizeof(float)) != 0 && range_of(&in[4 * i]) > s2.peak_range_m) {
      EXPECT_NEAR(range_of(&out[4 * i]), s2.peak_range_m, 1e-5);
    }
}

// The camera's medium and the LiDAR's are one number: haze's extinction for
// --visibility V (the list of commands' extinction_per_m) is the LiDAR fog's
// α for the same V, to the bit, and the record says so.
TEST(LidarFog, CameraAndLidarShareTheExtinction) {
  const CommandDef* haze = find_command("haze");
  const CommandDef* lidar = find_command("lidar fog");
  ASSERT_TRUE(haze && lidar && haze->extinction_per_m && lidar->extinction_per_m);
  EXPECT_EQ(lidar->extinction_per_m(lidar->defaults, 0.0), std::nullopt);
  for (double v : {20.0, 50.0, 333.0, 1000.0}) {
    const std::optional<double> cam = haze->extinction_per_m(haze->build({{"visibility", v}}), 0.0);
    const std::optional<double> lid = lidar->extinction_per_m(lidar->build({{"visibility", v}}), 0.0);
    ASSERT_TRUE(cam && lid);
    EXPECT_EQ(*cam, *lid) << v;
    LidarFogParams p;
    p.visibility_m = v;
    EXPECT_EQ(lidar_fog_medium(p).alpha, *cam);
  }
}

// Bad inputs: a clear Error naming the problem.
TEST(LidarFog, BadInputsAreRefused) {
  EXPECT_NE(error_of([] { parse_kitti_bin(std::string(33, '\0'), "--points 'x.bin'"); }).find("16 bytes"),
            std::string::npos);
  EXPECT_EQ(parse_kitti_bin(std::string(32, '\0'), "x").size(), 8u);
  // An empty scan is zero points (the fuzz reproducer empty_scan_memcpy_null.bin:
  // it once passed a null pointer to memcpy).
  EXPECT_TRUE(parse_kitti_bin(std::string(), "x").empty());
  std::vector<float> in = scan(10, 2, 20), out(in.size());
  in[4 * 3 + 1] = NAN;
  EXPECT_NE(error_of([&] { lidar_fog(in.data(), out.data(), 10, with_alpha(0.1)); }).find("point 3"), std::string::npos);
  in[4 * 3 + 1] = 1.0f;
  in[4 * 4 + 3] = -0.5f;
  EXPECT_NE(error_of([&] { lidar_fog(in.data(), out.data(), 10, with_alpha(0.1)); }).find("negative"), std::string::npos);
  in[4 * 4 + 3] = 0.5f;
  LidarFogParams p;
  EXPECT_NE(error_of([&] { lidar_fog_param_table().set_text(p, "alpha", "-0.1"); }).find("--alpha"), std::string::npos);
  EXPECT_NE(error_of([&] { validate_lidar_fog(p); }).find("--visibility"), std::string::npos);  // neither given
  p.alpha_per_m = 0.1;
  p.visibility_m = 50;
  EXPECT_NE(error_of([&] { validate_lidar_fog(p); }).find("both"), std::string::npos);
  p.visibility_m.reset();
  p.r2_m = 0.9;
  EXPECT_NE(error_of([&] { validate_lidar_fog(p); }).find("--r2"), std::string::npos);
  // A scan on [0, 255] read with KITTI's scale 255: refused, the fix named.
  for (std::size_t i = 0; i < 10; ++i) in[4 * i + 3] = 40.0f + 20.0f * i;
  const std::string e = error_of([&] { lidar_fog(in.data(), out.data(), 10, with_alpha(0.1)); });
  EXPECT_NE(e.find("--intensity-scale 1"), std::string::npos) << e;
  LidarFogParams one = with_alpha(0.1);
  one.intensity_scale = 1.0;
  EXPECT_NO_THROW(lidar_fog(in.data(), out.data(), 10, one));
  // A fog return beyond float32 is an Error, not inf.
  in[4 * 6 + 3] = 1e37f;
  one.beta_b = 1e6;
  EXPECT_NE(error_of([&] { lidar_fog(in.data(), out.data(), 10, one); }).find("point 6"), std::string::npos);
}

// `brume lidar fog` end to end: the .bin and the soft curve written, the
// record names α and every flag, `brume run` repeats it bit for bit; a bad
// input writes nothing.
class LidarFogCli : public ScratchDirTest {};

TEST_F(LidarFogCli, RunsAndBrumeRunRepeatsIt) {
  const std::vector<float> pts = scan(3000, 1.5, 90.0, 5);
  {
    std::ofstream f(p("in.bin"), std::ios::binary);
    const std::string b = kitti_bin_bytes(pts.data(), pts.size() / 4);
    f.write(b.data(), static_cast<std::streamsize>(b.size()));
  }
  fs::create_directories(p("first"));
  const CliRun r = run("lidar fog --points " + p("in.bin") + " --visibility 40 --seed 3 --out " + p("first/o.bin") +
                       " --record " + p("first/o.json") + " --soft-curve " + p("first/s.csv"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::vector<float> out = read_kitti_bin(p("first/o.bin"), "out");
  ASSERT_EQ(out.size(), pts.size());
  const nlohmann::json rec = read_json(p("first/o.json"));
  EXPECT_EQ(rec["command"], "lidar fog");
  EXPECT_NEAR(rec["lidar"]["alpha_per_m"].get<double>(), 3.912 / 40, 1e-15);
  EXPECT_EQ(rec["job"]["lidar"]["seed"], 3);
  EXPECT_EQ(rec["job"]["lidar"]["tau-h"], 20.0);
  EXPECT_GT(rec["lidar"]["soft_points"].get<int>(), 0);
  // The CSV is the uncut table: its rows against the reference integral.
  std::ifstream csv(p("first/s.csv"));
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "range_m,power_w");
  LidarFogParams prm = with_alpha(3.912 / 40);
  const Reference ref(prm);
  double peak = 0.0, worst = 0.0, last_r = 0.0;
  std::size_t rows = 0;
  for (; std::getline(csv, line); ++rows) {
    double r, w;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf", &r, &w), 2) << line;
    peak = std::max(peak, w);
    if (rows % 50 == 0) worst = std::max(worst, std::abs(w - ref.power(r)));
    last_r = r;
  }
  EXPECT_LT(worst, 1e-6 * peak);
  EXPECT_GE(last_r, 89.0);  // to the farthest point
  // brume run: the same bytes.
  const CliRun again = run("run " + p("first/o.json") + " --out-dir " + p("again"));
  ASSERT_EQ(again.status, 0) << again.output;
  for (const char* f : {"o.bin", "s.csv"}) {
    const std::string a = file_bytes(p(std::string("first/") + f)), b = file_bytes(p(std::string("again/") + f));
    EXPECT_TRUE(!a.empty() && a == b) << f;
  }
}

TEST_F(LidarFogCli, BadInputsWriteNothing) {
  {
    std::ofstream f(p("odd.bin"), std::ios::binary);
    f << std::string(40, '\0');
  }
  std::vector<float> pts = scan(50, 2, 40);
  pts[4 * 7] = NAN;
  {
    std::ofstream f(p("nan.bin"), std::ios::binary);
    f << kitti_bin_bytes(pts.data(), 50);
  }
  pts[4 * 7] = 1.0f;
  for (std::size_t i = 0; i < 50; ++i) pts[4 * i + 3] = 100.0f;
  {
    std::ofstream f(p("u8.bin"), std::ios::binary);
    f << kitti_bin_bytes(pts.data(), 50);
  }
  const std::string tail = " --out " + p("o.bin") + " --record " + p("o.json") + " --soft-curve " + p("s.csv");
  struct Case {
    std::string args, says;
  };
  for (const Case& c : {Case{"--points " + p("odd.bin") + " --alpha 0.1", "16 bytes"},
                        Case{"--points " + p("nan.bin") + " --alpha 0.1", "non-finite"},
                        Case{"--points " + p("u8.bin") + " --alpha 0.1", "--intensity-scale 1"},
                        Case{"--points " + p("u8.bin") + " --alpha -1", "--alpha"},
                        Case{"--points " + p("u8.bin") + " --alpha 0.1 --intensity-scale 1 --r1 2 --r2 1", "--r2"},
                        Case{"--points " + p("u8.bin"), "--visibility"}}) {
    SCOPED_TRACE(c.args);
    const CliRun r = run("lidar fog " + c.args + tail);
    EXPECT_NE(r.status, 0);
    EXPECT_NE(r.output.find(c.says), std::string::npos) << r.output;
    for (const char* f : {"o.bin", "o.json", "s.csv"}) EXPECT_FALSE(fs::exists(p(f))) << f;
  }
}
