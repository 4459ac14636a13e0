// brume — the LiDAR fog's soft-return tables, shared by the homogeneous model
// (lidar_fog.cpp) and the height-layered one (lidar_fog_layered.cpp); the
// equations are in brume/lidar_fog.hpp. Internal to the lidar part.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/height_profile.hpp"
#include "brume/lidar_fog.hpp"
#include "core/math_constants.hpp"

namespace brume::lidar_detail {

// kPi: brume's one definition (core/math_constants.hpp): lidar_fog.cpp's
// `using namespace lidar_detail` would make a second one ambiguous wherever a
// unity build puts another effect after it.

// Below these many points a scan's per-point loops run on one thread: a
// parallel region ends when every thread has arrived, and on a loaded host
// (here the builds of other sessions, each session its own scheduler group)
// the second thread can wait a time slice or more for a core. Measured with
// `brume_bench_lidar_fog 11 sizes` (synthetic scans, AMD EPYC family 26, 2
// vCPU, load average 6.3, 2026-12-06), the points' loops forced onto both
// threads against one: the homogeneous fog's 2^16 points took 3.1 ms on one
// thread and 15.8 ms on two, 2^18 points 15.5 and 26.3 ms, 2^20 89 and 103
// ms. The homogeneous loop costs ~35 ns a point on one thread of a quieter
// host (1.2 M points: 44 ms on one thread, 24 ms on two, Intel Xeon at load
// ~2, 2026-12-05), so from 2^20 points a wait of ~10 ms for a core costs at
// most a quarter of what two threads gain; the layered fog's beams (range,
// s and the optical depth: ~4 times a homogeneous point, measured in the
// same run) reach that work at 2^18 points.
constexpr std::size_t kLidarParallelPoints = std::size_t{1} << 20;
constexpr std::size_t kLidarLayeredParallelPoints = std::size_t{1} << 18;

// The nodes of a soft-return table from 0 to end_m at steps of h_m = L/600
// (L = c·τ_H), counted in double before any conversion and bounded (issue
// #51: neither --tau-h nor a far point may ask for a table without end; a
// point at 1e6 m once grew --soft-curve without bound, one at 1e8 m ended in
// std::bad_alloc, one at 1e20 m overflowed the count and wrote "0,0").
// kMaxLidarTableNodes = 2^22 = 4 194 304 nodes, ~60 bytes each while a table
// is built (~250 MB): 2 km (kLidarLayeredRangeMax) at 0.5-mm steps, i.e. a
// 1-ns pulse. The default 20-ns pulse tabulates 1-cm steps: KITTI's farthest
// point (~80 m) is 8 000 nodes, 2 km 200 000. `to` says what sets end_m.
constexpr double kMaxLidarTableNodes = 4194304.0;
inline std::size_t lidar_table_nodes(double end_m, double h_m, double tau_h_ns, const std::string& to) {
  const double nodes = std::ceil(end_m / h_m) + 3.0;
  if (!(nodes <= kMaxLidarTableNodes)) {
    char b[320];
    std::snprintf(b, sizeof b,
                  "the soft-return table to %.6g m (%s) at steps of c tau_H / %d = %.3g m (--tau-h %.6g ns) needs "
                  "%.4g nodes; brume refuses more than %.0f (~250 MB while a table is built): raise --tau-h "
                  "(LiDAR pulses are 2-20 ns wide; the default is 20)",
                  end_m, to.c_str(), kLidarStepsPerPulse, h_m, tau_h_ns, nodes, kMaxLidarTableNodes);
    throw Error(b);
  }
  return static_cast<std::size_t>(nodes);
}

// The transmitter-receiver overlap ξ(r): 0 below R1, 1 above R2, linear between.
inline double overlap(double r, double r1, double r2) { return r <= r1 ? 0.0 : r >= r2 ? 1.0 : (r - r1) / (r2 - r1); }

// The cumulative integrals G_f(r_j), f ∈ {1, cos θ, sin θ}, θ = 2πr/L, at
// r_j = j·h (h = L/n), by composite Simpson on each cell [r_j, r_j+1], a
// cell holding R1 or R2 split there (ξ's kinks: Simpson is exact to
// O(h^5·g'''') on each smooth piece). Built node by node (extend), so that a
// layered table can stop where its curve can no longer rise. The integrand
// F gives g(r) anywhere (F::g), and on the smooth cells its values at the
// cell's end node and middle (F::node(j, r), F::mid(j, r)), which a layered
// integrand evaluates in batches.
// cos θ and sin θ, θ = 2πr/L, at the nodes j·h and the cells' middles
// (j + ½)·h of one pulse length (periodic in j mod n): one set for every table.
struct PulseTrig {
  std::vector<double> cos_node, sin_node, cos_mid, sin_mid;
  static const PulseTrig& get() {
    static const PulseTrig t = [] {
      PulseTrig r;
      const std::size_t n = kLidarStepsPerPulse;
      r.cos_node.resize(n), r.sin_node.resize(n), r.cos_mid.resize(n), r.sin_mid.resize(n);
      for (std::size_t j = 0; j < n; ++j) {
        const double dn = static_cast<double>(n);
        r.cos_node[j] = std::cos(2.0 * kPi * static_cast<double>(j) / dn);
        r.sin_node[j] = std::sin(2.0 * kPi * static_cast<double>(j) / dn);
        r.cos_mid[j] = std::cos(2.0 * kPi * (static_cast<double>(j) + 0.5) / dn);
        r.sin_mid[j] = std::sin(2.0 * kPi * (static_cast<double>(j) + 0.5) / dn);
      }
      return r;
    }();
    return t;
  }
};

struct Cumulative {
  double h = 0.0, w = 0.0;
  std::size_t n = kLidarStepsPerPulse;
  std::vector<double> g0, gc, gs;  // one entry a node built so far
  const std::vector<double>& cos_node = PulseTrig::get().cos_node;
  const std::vector<double>& sin_node = PulseTrig::get().sin_node;
  const std::vector<double>& cos_mid = PulseTrig::get().cos_mid;
  const std::vector<double>& sin_mid = PulseTrig::get().sin_mid;
  double prev_g = 0.0;

  explicit Cumulative(double pulse_m) : h(pulse_m / kLidarStepsPerPulse), w(2.0 * kPi / pulse_m) {}
  std::size_t size() const { return g0.size(); }

  // Grows the tables to `nodes` nodes.
  template <class F>
  void extend(const F& f, std::size_t nodes) {
    if (g0.empty()) {
      g0.push_back(0.0), gc.push_back(0.0), gs.push_back(0.0);
      prev_g = f.g(0.0);
    }
    // Simpson on [a, b] of g·{1, cos, sin}.
    auto simpson = [&](double a, double b, double& s0, double& sc, double& ss) {
      const double m = 0.5 * (a + b), ga = f.g(a), gm = f.g(m), gb = f.g(b), k = (b - a) / 6.0;
      s0 += k * (ga + 4 * gm + gb);
      sc += k * (ga * std::cos(w * a) + 4 * gm * std::cos(w * m) + gb * std::cos(w * b));
      ss += k * (ga * std::sin(w * a) + 4 * gm * std::sin(w * m) + gb * std::sin(w * b));
    };
    g0.reserve(nodes), gc.reserve(nodes), gs.reserve(nodes);
    for (std::size_t j = g0.size() - 1; j + 1 < nodes; ++j) {
      const double a = static_cast<double>(j) * h, b = static_cast<double>(j + 1) * h;
      double s0 = 0.0, sc = 0.0, ss = 0.0;
      const double gb = f.node(j + 1, b);
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
        const double gm = f.mid(j, 0.5 * (a + b)), kk = h / 6.0;
        const std::size_t ja = j % n, jb = (j + 1) % n;
        s0 = kk * (prev_g + 4 * gm + gb);
        sc = kk * (prev_g * cos_node[ja] + 4 * gm * cos_mid[ja] + gb * cos_node[jb]);
        ss = kk * (prev_g * sin_node[ja] + 4 * gm * sin_mid[ja] + gb * sin_node[jb]);
      }
      g0.push_back(g0[j] + s0);
      gc.push_back(gc[j] + sc);
      gs.push_back(gs[j] + ss);
      prev_g = gb;
    }
  }

  // P_soft(R_j; R0 = r_kk) = k·½·(ΔG0 − cos θ_j ΔGc − sin θ_j ΔGs) over the
  // window [r_{j−n}, r_min(j, kk)] (k: the constant before the integral).
  // Reads the tables at nodes ≤ min(j, kk) only.
  double cut(double k, std::size_t j, std::size_t kk) const {
    const std::size_t top = std::min(j, kk);
    const bool low = j >= n;
    const std::size_t lo = low ? j - n : 0;
    if (low && lo >= top) return 0.0;
    const double d0 = g0[top] - (low ? g0[lo] : 0.0);
    const double dc = gc[top] - (low ? gc[lo] : 0.0);
    const double ds = gs[top] - (low ? gs[lo] : 0.0);
    const std::size_t q = j % n;
    const double v = k * 0.5 * (d0 - cos_node[q] * dc - sin_node[q] * ds);
    return v > 0.0 ? v : 0.0;  // rounding of a window with no fog in it
  }

  // The cut tail's maximum: max(best, cut(k, j, m)) over j in (m, m + n),
  // its node in `at` (the first of equal values) -- cut's arithmetic, in
  // runs where the window's start j − n (node 0 below n) and j mod n are
  // affine in j.
  void tail_max(double k, std::size_t m, double& best, std::size_t& at) const {
    const double a0 = g0[m], ac = gc[m], as = gs[m];
    const std::size_t end = m + n;
    std::size_t j = m + 1;
    while (j < end) {
      const std::size_t q0 = j % n;
      std::size_t stop = std::min(end, j + (n - q0));
      if (j < n) stop = std::min(stop, n);
      const double* c = cos_node.data() + q0 - j;
      const double* s = sin_node.data() + q0 - j;
      if (j < n) {  // the window starts at node 0, where G = 0
        for (; j < stop; ++j) {
          const double v = k * 0.5 * (a0 - c[j] * ac - s[j] * as);
          if (v > best) best = v, at = j;
        }
      } else {
        const double* l0 = g0.data() - n;
        const double* lc = gc.data() - n;
        const double* ls = gs.data() - n;
        for (; j < stop; ++j) {
          const double v = k * 0.5 * ((a0 - l0[j]) - c[j] * (ac - lc[j]) - s[j] * (as - ls[j]));
          if (v > best) best = v, at = j;
        }
      }
    }
  }
};

// The cut peak at R0 = (k + t)·h from the cut peaks at nodes k − 1, k, k + 1
// (pa, pb, pc; pa only when has_a, k ≥ 1) and the ranges rb, rc at k, k + 1:
// the power quadratically through the three nodes (near R1 the peak grows
// like (R0 − R1)², which linear interpolation missed by 0.2 % at
// R0 = R1 + 5 cm), the range linearly between k and k + 1.
inline void interpolate_peak(bool has_a, double pa, double pb, double pc, double rb, double rc, double t,
                             double& power, double& range) {
  if (has_a) power = pb + 0.5 * t * (pc - pa) + 0.5 * t * t * (pa - 2 * pb + pc);
  else power = pb + t * (pc - pb);
  range = rb + t * (rc - rb);
}

// Counter-based noise: the i-th point's draws depend on (seed, i) only, so
// the result does not depend on threads or on which points became fog.
inline std::uint64_t splitmix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}
inline double unit(std::uint64_t x) { return (static_cast<double>(x >> 11) + 0.5) * (1.0 / 9007199254740992.0); }
inline double gaussian(std::uint64_t seed, std::uint64_t index, std::uint64_t draw) {
  const std::uint64_t base = splitmix(splitmix(seed) ^ (index * 0xd1b54a32d192ed03ull) ^ (draw * 0x8cb92ba72f3d8dd7ull));
  const double u1 = unit(base), u2 = unit(splitmix(base));
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
}

// The per-point rule (brume/lidar_fog.hpp) once the soft peak is known.
struct PointRule {
  double r1 = 0.0, r2 = 0.0;
  double hard_k = 0.0;  // P_hard,clear(R0) = hard_k·ξ(R0)/R0²
  bool noise = false;
  double noise_m = 0.0;
  std::uint64_t seed = 0;

  explicit PointRule(const LidarFogParams& p, const LidarFogMedium& m)
      : r1(p.r1_m), r2(p.r2_m), hard_k(m.c_a * p.p0_w * m.beta0), noise(p.noise == "on" && p.range_noise_m > 0.0),
        noise_m(p.range_noise_m), seed(p.seed) {}

  // Point i (q → o) at range r0 > R1 with intensity > 0, attenuation att =
  // e^{−2F(R0)} and soft peak (peak_w, peak_r): the hard return, or the point
  // moved to the soft peak. Returns true for a fog return; sets `overflow`
  // when its intensity overflows float32.
  bool place(const float* q, float* o, std::size_t i, double r0, double att, double peak_w, double peak_r,
             bool& overflow) const {
    const double inten = q[3];
    const double ratio = peak_w * r0 * r0 / (hard_k * overlap(r0, r1, r2));
    // i_soft > i_hard ⟺ ratio > e^{−2F(R0)} (both are i times a factor, i > 0).
    if (!(ratio > att)) {
      o[0] = q[0], o[1] = q[1], o[2] = q[2], o[3] = static_cast<float>(inten * att);
      return false;
    }
    double r = peak_r;
    if (noise) {
      std::uint64_t draw = 0;
      do r = peak_r + noise_m * gaussian(seed, i, draw++);
      while (r < r1 && draw < 64);
      if (r < r1) r = peak_r;  // 64 draws below R1: σ ≫ the soft peak's range
    }
    const double k = r / r0;
    o[0] = static_cast<float>(q[0] * k), o[1] = static_cast<float>(q[1] * k), o[2] = static_cast<float>(q[2] * k);
    o[3] = static_cast<float>(inten * ratio);
    overflow = !std::isfinite(o[3]);
    return true;
  }
};

// A height-layered p's density relative to the scan's origin, and that
// origin's place (reads --kitti-calib and a --table file once).
struct LayeredMedium {
  RigidTransform world_from_scan;
  DensityTable table;
  HeightDensity density;
};
LayeredMedium layered_medium(const LidarFogParams& p);

// The height-layered run (lidar_fog_layered.cpp); p has a profile other
// than constant and has been validated, the points checked.
LidarFogStats layered_fog(const float* in, float* out, std::size_t n, const LidarFogParams& p,
                          const LidarFogMedium& m, const std::string& what);
// The level beam's uncut curve of a layered p to range_end_m.
SoftCurve layered_soft_curve(const LidarFogParams& p, const LidarFogMedium& m, double range_end_m);
// The error of a point whose fog return overflows float32.
[[noreturn]] void throw_overflow(const float* in, long long index, const std::string& what);

}  // namespace brume::lidar_detail
