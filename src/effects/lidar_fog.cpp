// brume — the homogeneous LiDAR fog (brume/lidar_fog.hpp has the equations).
#include "brume/lidar_fog.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "brume/error.hpp"

namespace brume {

namespace {

constexpr double kPi = 3.14159265358979323846;

std::string num(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

// The overlap ξ(r) and the soft integrand's g(r) = ξ(r)·e^{−2αr}/r².
struct Integrand {
  double r1, r2, alpha;
  double xi(double r) const { return r <= r1 ? 0.0 : r >= r2 ? 1.0 : (r - r1) / (r2 - r1); }
  double g(double r) const { return r <= r1 ? 0.0 : xi(r) * std::exp(-2.0 * alpha * r) / (r * r); }
};

// The cumulative integrals G_f(r_j), f ∈ {1, cos θ, sin θ}, θ = 2πr/L, at
// r_j = j·h (h = L/n), by composite Simpson on each cell [r_j, r_j+1], a
// cell holding R1 or R2 split there (ξ's kinks: Simpson is exact to
// O(h^5·g'''') on each smooth piece).
struct Cumulative {
  double h = 0.0;
  int n = kLidarStepsPerPulse;
  std::vector<double> g0, gc, gs;  // size = nodes
  std::vector<double> cos_node, sin_node;  // cos θ, sin θ at node j mod n
};

Cumulative cumulative(const Integrand& f, double pulse_m, std::size_t nodes) {
  Cumulative c;
  c.h = pulse_m / c.n;
  c.g0.assign(nodes, 0.0);
  c.gc.assign(nodes, 0.0);
  c.gs.assign(nodes, 0.0);
  c.cos_node.resize(c.n);
  c.sin_node.resize(c.n);
  std::vector<double> cos_mid(c.n), sin_mid(c.n);
  for (int j = 0; j < c.n; ++j) {
    c.cos_node[j] = std::cos(2.0 * kPi * j / c.n);
    c.sin_node[j] = std::sin(2.0 * kPi * j / c.n);
    cos_mid[j] = std::cos(2.0 * kPi * (j + 0.5) / c.n);
    sin_mid[j] = std::sin(2.0 * kPi * (j + 0.5) / c.n);
  }
  const double w = 2.0 * kPi / pulse_m;
  // Simpson on [a, b] of g·{1, cos, sin}.
  auto simpson = [&](double a, double b, double& s0, double& sc, double& ss) {
    const double m = 0.5 * (a + b), ga = f.g(a), gm = f.g(m), gb = f.g(b), k = (b - a) / 6.0;
    s0 += k * (ga + 4 * gm + gb);
    sc += k * (ga * std::cos(w * a) + 4 * gm * std::cos(w * m) + gb * std::cos(w * b));
    ss += k * (ga * std::sin(w * a) + 4 * gm * std::sin(w * m) + gb * std::sin(w * b));
  };
  double prev_g = f.g(0.0);
  for (std::size_t j = 0; j + 1 < nodes; ++j) {
    const double a = j * c.h, b = (j + 1) * c.h;
    double s0 = 0.0, sc = 0.0, ss = 0.0;
    const double gb = f.g(b);
    if (b <= f.r1) {
      // g = 0 on the whole cell.
    } else if ((a < f.r1 && f.r1 < b) || (a < f.r2 && f.r2 < b)) {
      double cuts[4] = {a, 0, 0, 0};
      int k = 1;
      if (a < f.r1 && f.r1 < b) cuts[k++] = f.r1;
      if (a < f.r2 && f.r2 < b) cuts[k++] = f.r2;
      cuts[k++] = b;
      for (int q = 0; q + 1 < k; ++q) simpson(cuts[q], cuts[q + 1], s0, sc, ss);
    } else {
      // A smooth cell: the node values come from the periodic tables.
      const double m = 0.5 * (a + b), gm = f.g(m), kk = c.h / 6.0;
      const std::size_t ja = j % c.n, jb = (j + 1) % c.n;
      s0 = kk * (prev_g + 4 * gm + gb);
      sc = kk * (prev_g * c.cos_node[ja] + 4 * gm * cos_mid[ja] + gb * c.cos_node[jb]);
      ss = kk * (prev_g * c.sin_node[ja] + 4 * gm * sin_mid[ja] + gb * c.sin_node[jb]);
    }
    c.g0[j + 1] = c.g0[j] + s0;
    c.gc[j + 1] = c.gc[j] + sc;
    c.gs[j + 1] = c.gs[j] + ss;
    prev_g = gb;
  }
  return c;
}

// The soft model of one run: the uncut curve at the nodes, its peak, and the
// peak of the curve cut at each node below the uncut peak.
class SoftModel {
 public:
  SoftModel(const LidarFogParams& p, const LidarFogMedium& m, double range_end_m) : m_(m) {
    const Integrand f{p.r1_m, p.r2_m, m.alpha};
    const double h = m.pulse_m / kLidarStepsPerPulse;
    // The uncut maximum lies in [0, R2 + L]; one more pulse of nodes for the cut tails.
    const double end = std::max(range_end_m, p.r2_m + m.pulse_m) + 2 * h;
    nodes_ = static_cast<std::size_t>(std::ceil(end / h)) + 1;
    c_ = cumulative(f, m.pulse_m, nodes_);
    k_ = m.c_a * p.p0_w * m.beta_b * 2.0 / kSpeedOfLight;
    uncut_.resize(nodes_);
    for (std::size_t j = 0; j < nodes_; ++j) uncut_[j] = cut(j, j);
    // The uncut peak, searched where it lies.
    const std::size_t search = std::min(nodes_, static_cast<std::size_t>(std::ceil((p.r2_m + m.pulse_m) / h)) + 2);
    peak_node_ = 0;
    for (std::size_t j = 1; j < search; ++j)
      if (uncut_[j] > uncut_[peak_node_]) peak_node_ = j;
    // Cut peaks at the nodes up to the uncut peak: prefix maximum and the cut tail.
    near_peak_.resize(peak_node_ + 2);
    near_range_.resize(peak_node_ + 2);
    std::size_t pre = 0;
    const std::size_t n = kLidarStepsPerPulse;
    for (std::size_t k = 0; k < near_peak_.size(); ++k) {
      if (k >= peak_node_) {
        near_peak_[k] = uncut_[peak_node_];
        near_range_[k] = peak_node_ * h;
        continue;
      }
      if (uncut_[k] > uncut_[pre]) pre = k;
      double best = uncut_[pre];
      std::size_t at = pre;
      if (k * h > p.r1_m)
        for (std::size_t j = k + 1; j < k + n && j < nodes_; ++j) {
          const double v = cut(j, k);
          if (v > best) best = v, at = j;
        }
      near_peak_[k] = best;
      near_range_[k] = at * h;
    }
    h_ = h;
  }

  double step() const { return h_; }
  std::size_t nodes() const { return nodes_; }
  const std::vector<double>& uncut() const { return uncut_; }
  double peak_w() const { return uncut_[peak_node_]; }
  double peak_range() const { return peak_node_ * h_; }

  // The soft peak's power [W] and range [m] for a cut at R0.
  void peak(double r0, double& power, double& range) const {
    const double u = r0 / h_;
    if (u >= static_cast<double>(peak_node_)) {
      power = uncut_[peak_node_];
      range = peak_node_ * h_;
      return;
    }
    const std::size_t k = static_cast<std::size_t>(u);
    const double t = u - k;
    // The power through nodes k-1, k, k+1 (quadratic: near R1 the peak grows
    // like (R0 - R1)^2, which linear interpolation missed by 0.2 % at
    // R0 = R1 + 5 cm); the range linearly between k and k+1.
    if (k >= 1) {
      const double a = near_peak_[k - 1], b = near_peak_[k], c = near_peak_[k + 1];
      power = b + 0.5 * t * (c - a) + 0.5 * t * t * (a - 2 * b + c);
    } else {
      power = near_peak_[k] + t * (near_peak_[k + 1] - near_peak_[k]);
    }
    range = near_range_[k] + t * (near_range_[k + 1] - near_range_[k]);
  }

 private:
  // P_soft(R_j; R0 = r_k) for k ≥ ... : the window [r_{j−n}, r_min(j,k)].
  double cut(std::size_t j, std::size_t k) const {
    const std::size_t n = kLidarStepsPerPulse;
    const std::size_t top = std::min(j, k);
    const bool low = j >= n;
    const std::size_t lo = low ? j - n : 0;
    if (low && lo >= top) return 0.0;
    const double d0 = c_.g0[top] - (low ? c_.g0[lo] : 0.0);
    const double dc = c_.gc[top] - (low ? c_.gc[lo] : 0.0);
    const double ds = c_.gs[top] - (low ? c_.gs[lo] : 0.0);
    const std::size_t q = j % n;
    const double v = k_ * 0.5 * (d0 - c_.cos_node[q] * dc - c_.sin_node[q] * ds);
    return v > 0.0 ? v : 0.0;  // rounding of a window with no fog in it
  }

  LidarFogMedium m_;
  Cumulative c_;
  double k_ = 0.0, h_ = 0.0;
  std::size_t nodes_ = 0, peak_node_ = 0;
  std::vector<double> uncut_, near_peak_, near_range_;
};

// Counter-based noise: the i-th point's draws depend on (seed, i) only, so
// the result does not depend on threads or on which points became fog.
std::uint64_t splitmix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}
double unit(std::uint64_t x) { return ((x >> 11) + 0.5) * (1.0 / 9007199254740992.0); }  // (0, 1)
double gaussian(std::uint64_t seed, std::uint64_t index, std::uint64_t draw) {
  const std::uint64_t base = splitmix(splitmix(seed) ^ (index * 0xd1b54a32d192ed03ull) ^ (draw * 0x8cb92ba72f3d8dd7ull));
  const double u1 = unit(base), u2 = unit(splitmix(base));
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
}

double range_m(const float* q) {
  const double x = q[0], y = q[1], z = q[2];
  return std::sqrt(x * x + y * y + z * z);
}

}  // namespace

const ParamTable<LidarFogParams>& lidar_fog_param_table() {
  static const ParamTable<LidarFogParams> t = [] {
    ParamTable<LidarFogParams> d("lidar");
    d.real("visibility", &LidarFogParams::visibility_m, "m", Range::above(0.0),
           "meteorological visibility V; alpha = 3.912/V (Koschmieder, as the camera effects); give it or --alpha",
           "none")
        .infinite()
        .real("alpha", &LidarFogParams::alpha_per_m, "1/m", Range::at_least(0.0),
              "extinction coefficient alpha of the fog; give it or --visibility", "none")
        .real("tau-h", &LidarFogParams::tau_h_ns, "ns", Range::left_open(0.0, 1000.0), "half-power pulse width tau_H")
        .real("p0", &LidarFogParams::p0_w, "W", Range::above(0.0), "peak power P0 of the pulse")
        .real("a-r", &LidarFogParams::a_r_m2, "m^2", Range::above(0.0), "receiver aperture A_r")
        .real("l-r", &LidarFogParams::l_r, "1", Range::left_open(0.0, 1.0), "receiver efficiency l_r")
        .real("gamma", &LidarFogParams::gamma, "1", Range::left_open(0.0, 1.0),
              "hard target reflectivity Gamma (beta0 = Gamma/pi)")
        .real("r1", &LidarFogParams::r1_m, "m", Range::above(0.0),
              "range where the transmitter-receiver overlap begins (xi = 0 below)")
        .real("r2", &LidarFogParams::r2_m, "m", Range::above(0.0),
              "range of full overlap (xi = 1 above; linear from --r1); must exceed --r1")
        .real("beta-b", &LidarFogParams::beta_b, "1/(m sr)", Range::at_least(0.0),
              "backscatter coefficient of the fog; auto: 0.046/MOR with MOR = ln(20)/alpha (the paper's)")
        .real("intensity-scale", &LidarFogParams::intensity_scale, "1", Range::above(0.0),
              "multiplies the input's intensities into the model's [0, 255] (255: KITTI's reflectance in [0, 1]; "
              "1: a scan already in [0, 255]); a scan mostly above 255 after it is refused")
        .choice("noise", &LidarFogParams::noise, {"on", "off"}, "range noise on the points turned into fog")
        .real("range-noise", &LidarFogParams::range_noise_m, "m", Range::at_least(0.0),
              "standard deviation of that noise (Gaussian, redrawn below --r1)")
        .count("seed", &LidarFogParams::seed, "1", Range::at_least(0.0), "seed of the noise (same seed, same scan)");
    return d;
  }();
  return t;
}

void validate_lidar_fog(const LidarFogParams& p) {
  lidar_fog_param_table().validate(p);
  if (p.visibility_m.has_value() == p.alpha_per_m.has_value())
    throw Error(p.visibility_m ? "--visibility and --alpha both given; give one of them (alpha = 3.912/V)"
                               : "no fog given: use --visibility V (metres) or --alpha A (1/m)");
  if (!(p.r2_m > p.r1_m))
    throw Error("--r2 " + num(p.r2_m) + " must exceed --r1 " + num(p.r1_m) +
                " (the overlap rises from 0 at R1 to 1 at R2); give --r2 greater than --r1");
}

LidarFogMedium lidar_fog_medium(const LidarFogParams& p) {
  validate_lidar_fog(p);
  LidarFogMedium m;
  m.alpha = p.alpha_per_m ? *p.alpha_per_m : (std::isinf(*p.visibility_m) ? 0.0 : 3.912 / *p.visibility_m);
  m.mor_m = m.alpha > 0 ? std::log(20.0) / m.alpha : INFINITY;
  m.beta_b = p.beta_b ? *p.beta_b : 0.046 * m.alpha / std::log(20.0);  // 0.046/MOR
  m.beta0 = p.gamma / kPi;
  m.c_a = kSpeedOfLight * p.l_r * p.a_r_m2 / 2.0;
  m.pulse_m = kSpeedOfLight * p.tau_h_ns * 1e-9;
  return m;
}

SoftCurve lidar_soft_curve(const LidarFogParams& p, double range_end_m) {
  const LidarFogMedium m = lidar_fog_medium(p);
  const SoftModel s(p, m, range_end_m);
  SoftCurve c;
  c.step_m = s.step();
  const std::size_t n = std::min(s.nodes(), static_cast<std::size_t>(
                                                std::ceil(std::max(range_end_m, p.r2_m + m.pulse_m) / s.step())) + 1);
  c.power_w.assign(s.uncut().begin(), s.uncut().begin() + n);
  c.peak_w = s.peak_w();
  c.peak_range_m = s.peak_range();
  return c;
}

std::string soft_curve_csv(const SoftCurve& c) {
  std::string s = "range_m,power_w\n";
  char b[80];
  for (std::size_t j = 0; j < c.power_w.size(); ++j) {
    std::snprintf(b, sizeof b, "%.9g,%.9g\n", j * c.step_m, c.power_w[j]);
    s += b;
  }
  return s;
}

nlohmann::json LidarFogStats::record() const {
  return {{"points", points},
          {"soft_points", soft},
          {"soft_fraction", points ? static_cast<double>(soft) / points : 0.0},
          {"points_within_r1", zero_range},
          {"soft_peak_w", peak_w},
          {"soft_peak_range_m", peak_range_m},
          {"table_ms", table_ms},
          {"points_ms", points_ms}};
}

LidarFogStats lidar_fog(const float* in, float* out, std::size_t n, const LidarFogParams& p, const std::string& what) {
  const LidarFogMedium m = lidar_fog_medium(p);
  // Every point checked before anything is written.
  std::size_t above = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = in + 4 * i;
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(q[c]))
        throw Error(what + ": point " + std::to_string(i) + " has a non-finite " + "xyzi"[c] + " (" + num(q[c]) +
                    "); a scan's coordinates and intensities must be finite numbers: drop such points first");
    if (q[3] < 0.0f)
      throw Error(what + ": point " + std::to_string(i) + " has a negative intensity " + num(q[3]) +
                  "; intensities are reflectances >= 0");
    if (static_cast<double>(q[3]) * p.intensity_scale > 255.0) ++above;
  }
  if (n > 0 && 2 * above > n)
    throw Error("--intensity-scale " + num(p.intensity_scale) + ": " + num(100.0 * above / n) +
                " % of the intensities of " + what + " times it exceed 255, the model's scale [0, 255]; KITTI's reflectance is in [0, 1] "
                "(scale 255); for a scan already in [0, 255] give --intensity-scale 1");
  LidarFogStats st;
  st.points = n;
  if (!(m.alpha > 0.0)) {  // no fog: the scan as it is, bit for bit
    if (out != in) std::memcpy(out, in, n * 4 * sizeof(float));
    return st;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const SoftModel s(p, m, 0.0);
  const auto t1 = std::chrono::steady_clock::now();
  st.peak_w = s.peak_w();
  st.peak_range_m = s.peak_range();
  const double hard_k = m.c_a * p.p0_w * m.beta0;  // P_hard,clear(R0) = hard_k·ξ(R0)/R0²
  const Integrand f{p.r1_m, p.r2_m, m.alpha};
  const bool noise = p.noise == "on" && p.range_noise_m > 0.0;
  // Each point on its own (the noise is counter-based), so the loop runs on
  // every core with the same result -- for scans of a million points and
  // more: a KITTI scan (120 k) takes ~2.3 ms on one thread, and on the
  // loaded 2-vCPU host (load ~9) two threads took 19 ms (the team waits for
  // a busy core); bench/bench_lidar_fog.cpp.
  std::size_t soft = 0, near = 0;
  long long overflow = static_cast<long long>(n);  // the first point whose fog intensity overflows float32
  const long long count = static_cast<long long>(n);
#pragma omp parallel for schedule(static) reduction(+ : soft, near) reduction(min : overflow) if (n >= (1u << 20))
  for (long long ii = 0; ii < count; ++ii) {
    const std::size_t i = static_cast<std::size_t>(ii);
    const float* q = in + 4 * i;
    float* o = out + 4 * i;
    const double x = q[0], y = q[1], z = q[2], inten = q[3];
    const double r0 = std::sqrt(x * x + y * y + z * z);
    const double att = std::exp(-2.0 * m.alpha * r0);
    const float hard = static_cast<float>(inten * att);
    if (r0 <= p.r1_m || !(inten > 0.0)) {
      near += r0 <= p.r1_m;
      o[0] = q[0], o[1] = q[1], o[2] = q[2], o[3] = hard;
      continue;
    }
    double peak_w, peak_r;
    s.peak(r0, peak_w, peak_r);
    const double ratio = peak_w * r0 * r0 / (hard_k * f.xi(r0));
    // i_soft > i_hard ⟺ ratio > e^{−2αR0} (both are i times a factor, i > 0).
    if (!(ratio > att)) {
      o[0] = q[0], o[1] = q[1], o[2] = q[2], o[3] = hard;
      continue;
    }
    double r = peak_r;
    if (noise) {
      std::uint64_t draw = 0;
      do r = peak_r + p.range_noise_m * gaussian(p.seed, i, draw++);
      while (r < p.r1_m && draw < 64);
      if (r < p.r1_m) r = peak_r;  // 64 draws below R1: σ ≫ the soft peak's range
    }
    const double k = r / r0;
    o[0] = static_cast<float>(x * k), o[1] = static_cast<float>(y * k), o[2] = static_cast<float>(z * k);
    o[3] = static_cast<float>(inten * ratio);
    if (!std::isfinite(o[3])) overflow = std::min(overflow, ii);
    ++soft;
  }
  if (overflow < count) {
    const float* q = in + 4 * overflow;
    throw Error(what + ": point " + std::to_string(overflow) + " (intensity " + num(q[3]) + ", range " +
                num(range_m(q)) + " m) gives a fog return whose intensity overflows float32; its intensity or range "
                "is not a LiDAR's: drop the point or check the scan");
  }
  const auto t2 = std::chrono::steady_clock::now();
  st.soft = soft;
  st.zero_range = near;
  st.table_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  st.points_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  return st;
}

// ---- KITTI .bin ----
std::vector<float> parse_kitti_bin(const std::string& bytes, const std::string& what) {
  if (bytes.size() % 16 != 0)
    throw Error(what + ": " + std::to_string(bytes.size()) +
                " bytes is not a whole number of points (KITTI .bin: 16 bytes a point, float32 x, y, z, "
                "reflectance); the file is truncated or not a KITTI scan");
  static_assert(sizeof(float) == 4, "float32");
  std::vector<float> v(bytes.size() / 4);
  if (!v.empty()) std::memcpy(v.data(), bytes.data(), bytes.size());  // little-endian host (x86-64, AArch64)
  return v;
}

std::vector<float> read_kitti_bin(const std::string& path, const std::string& flag) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(flag + " '" + path + "': cannot be read (no such file or no permission)");
  std::ostringstream s;
  s << f.rdbuf();
  if (f.bad()) throw Error(flag + " '" + path + "': read failed");
  return parse_kitti_bin(s.str(), flag + " '" + path + "'");
}

std::string kitti_bin_bytes(const float* points, std::size_t n) {
  return std::string(reinterpret_cast<const char*>(points), n * 16);
}

}  // namespace brume
