// brume — the height-layered LiDAR fog: brume's fog profiles along each
// beam (brume/lidar_fog.hpp has the equations, docs/lidar.md "Height-layered
// fog" the pose, the elevation bins and their error bound).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <limits>
#include <vector>

#include "brume/error.hpp"
#include "brume/height_profile.hpp"
#include "brume/lidar_fog.hpp"
#include "core/text.hpp"
#include "effects/lidar/lidar_fog_tables.hpp"

namespace brume::lidar_detail {

namespace {

using Clock = std::chrono::steady_clock;

// Along one beam from the scan's origin climbing at s = sin θ: the density
// δ(r) = d.at(r·s) (d relative to the origin's height), the optical depth
// F(r) from brume's fog integral, and the soft integrand without the
// backscatter ratio, g(r) = ξ(r)·δ(r)·e^{−2F(r)}/r². Node and middle values
// are computed in batches (prepare), one conversion of the density each.
struct BeamIntegrand {
  double r1 = 0.0, r2 = 0.0, s = 0.0, h = 0.0;
  const HeightDensity* d = nullptr;
  std::vector<double> node_g, mid_g;  // g at r_j = j·h and at (j + ½)·h
  std::vector<float> node_f;          // F at r_j

  double value(double r, float f) const {
    if (r <= r1) return 0.0;
    const double t = std::exp(-2.0 * static_cast<double>(f));
    return t == 0.0 ? 0.0 : overlap(r, r1, r2) * d->at(r * s) * t / (r * r);  // no ∞·0 where the fog is opaque
  }
  double g(double r) const {
    const float rf = static_cast<float>(r), sf = static_cast<float>(s);
    float f = 0.0f;
    height_optical_depths(*d, &rf, &sf, &f, 1);
    return value(r, f);
  }
  double node(std::size_t j, double) const { return node_g[j]; }
  double mid(std::size_t j, double) const { return mid_g[j]; }

  // The nodes below `to` and the middles of the cells below to − 1.
  void prepare(std::size_t to) {
    const std::size_t n0 = node_g.size(), m0 = mid_g.size();
    const std::size_t nn = to - n0, nm = to - 1 - m0;
    std::vector<float> r(nn + nm), y(nn + nm, static_cast<float>(s)), f(nn + nm);
    for (std::size_t k = 0; k < nn; ++k) r[k] = static_cast<float>(static_cast<double>(n0 + k) * h);
    for (std::size_t k = 0; k < nm; ++k) r[nn + k] = static_cast<float>((static_cast<double>(m0 + k) + 0.5) * h);
    height_optical_depths(*d, r.data(), y.data(), f.data(), nn + nm);
    for (std::size_t k = 0; k < nn; ++k) {
      node_f.push_back(f[k]);
      node_g.push_back(value(static_cast<double>(n0 + k) * h, f[k]));
    }
    for (std::size_t k = 0; k < nm; ++k) mid_g.push_back(value((static_cast<double>(m0 + k) + 0.5) * h, f[nn + k]));
  }
};

// One beam's soft-return table: the uncut curve at the nodes, its prefix
// maximum, and the cut peaks at the nodes the points ask for.
class BeamSoft {
 public:
  // The table to r_end (the farthest point) or, with `stop`, to where no
  // later node can exceed the curve's maximum so far.
  BeamSoft(const LidarFogParams& p, const LidarFogMedium& m, const HeightDensity& d, double s, double r_end, bool stop)
      : c_(m.pulse_m), r1_(p.r1_m) {
    h_ = c_.h;
    f_.r1 = p.r1_m, f_.r2 = p.r2_m, f_.s = s, f_.h = h_, f_.d = &d;
    const double ratio = p.lidar_ratio_sr ? 1.0 / *p.lidar_ratio_sr : 0.046 / std::log(20.0);  // β_b/δ
    k_ = m.c_a * p.p0_w * ratio * 2.0 / kSpeedOfLight;
    const std::size_t n = kLidarStepsPerPulse;
    lidar_table_nodes(r_end, h_, p.tau_h_ns, "the farthest point of the beams this table serves");
    const std::size_t want = static_cast<std::size_t>(std::floor(r_end / h_)) + 3;
    // For every R' ≥ R (ξ ≤ 1, sin² ≤ 1, 1/r² ≤ 1/(R−L)², F rising):
    //   P(R') ≤ k·δ_max·(L/2)·e^{−2F(R−L)}/(R−L)²   (∫ sin² over the window = L/2,
    //          δ_max the largest density on the beam), and
    //   P(R') ≤ k·½·e^{−2F(R−L)}/(R−L)²             (∫ δ·e^{−2F} dr = ½ Δe^{−2F}: dF/dr = δ).
    const double bound_k = std::min(k_ * height_density_max(d, 0.0, s * r_end) * 0.5 * m.pulse_m, 0.5 * k_);
    constexpr std::size_t kChunk = 512;
    while (c_.size() < want) {
      const std::size_t from = c_.size(), to = std::min(want, from + kChunk);
      f_.prepare(to);
      c_.extend(f_, to);
      for (std::size_t j = from; j < to; ++j) {
        const double v = c_.cut(k_, j, j);
        uncut_.push_back(v);
        const bool rise = max_.empty() || v > max_.back();
        max_.push_back(rise ? v : max_.back());
        at_.push_back(rise ? static_cast<std::uint32_t>(j) : at_.back());
      }
      const std::size_t last = to - 1;
      if (stop && last >= n) {
        const double rl = static_cast<double>(last - n) * h_;
        if (rl >= r1_ && bound_k * std::exp(-2.0 * static_cast<double>(f_.node_f[last - n])) / (rl * rl) <= max_.back()) {
          stopped_ = true;
          break;
        }
      }
    }
    memo_.assign(uncut_.size(), -1.0);
    memo_at_.assign(uncut_.size(), 0);
  }

  std::size_t nodes() const { return uncut_.size(); }
  double step() const { return h_; }
  const std::vector<double>& uncut() const { return uncut_; }
  double max_w() const { return max_.back(); }
  double max_range() const { return at_.back() * h_; }

  // The soft peak's power [W] and range [m] for a cut at R0 (as SoftModel::peak).
  void peak(double r0, double& power, double& range) {
    const double u = r0 / h_;
    const std::size_t k = static_cast<std::size_t>(u);
    if (k + 1 >= nodes()) {  // beyond a stopped table: its maximum
      power = max_.back();
      range = at_.back() * h_;
      return;
    }
    double pa = 0.0, pb, pc, ra, rb, rc;
    if (k >= 1) cut_peak(k - 1, pa, ra);
    cut_peak(k, pb, rb);
    cut_peak(k + 1, pc, rc);
    interpolate_peak(k >= 1, pa, pb, pc, rb, rc, u - static_cast<double>(k), power, range);
  }

 private:
  // The curve cut at node m: the larger of the uncut curve's prefix maximum
  // and the cut tail's maximum on (r_m, r_m + L). The tail is searched only
  // where the uncut curve, which bounds it, rises above the prefix maximum
  // within (r_m, r_m + L) or beyond the table's end.
  void cut_peak(std::size_t m, double& power, double& range) {
    if (memo_[m] < 0.0) {
      const std::size_t n = kLidarStepsPerPulse, last = nodes() - 1;
      double best = max_[m];
      std::size_t at = at_[m];
      bool tail = static_cast<double>(m) * h_ > r1_;
      if (tail && m + n - 1 <= last) tail = max_[m + n - 1] > max_[m];
      else if (tail && stopped_) tail = max_[last] > max_[m];
      if (tail) c_.tail_max(k_, m, best, at);
      memo_[m] = best;
      memo_at_[m] = static_cast<std::uint32_t>(at);
    }
    power = memo_[m];
    range = memo_at_[m] * h_;
  }

  Cumulative c_;
  BeamIntegrand f_;
  double r1_ = 0.0, h_ = 0.0, k_ = 0.0;
  bool stopped_ = false;
  std::vector<double> uncut_, max_, memo_;
  std::vector<std::uint32_t> at_, memo_at_;
};

}  // namespace

LayeredMedium layered_medium(const LidarFogParams& p) {
  LayeredMedium md;
  md.world_from_scan = lidar_world_from_scan(p);
  HeightMedium f = p.fog;
  f.profile = *p.profile;
  if (f.profile == HeightProfile::table) md.table = read_density_table(f.table_file);
  md.density = height_density(f, md.table, md.world_from_scan.translation.y);
  // One evaluation outside the threads: a table of too many rows is refused here.
  const float r = 1.0f, y = 0.0f;
  float out = 0.0f;
  height_optical_depths(md.density, &r, &y, &out, 1);
  return md;
}

SoftCurve layered_soft_curve(const LidarFogParams& p, const LidarFogMedium& m, double range_end_m) {
  if (!(range_end_m <= kLidarLayeredRangeMax))
    throw Error("--soft-curve: the scan's farthest point is " + text::g(range_end_m) + " m away; a height-layered "
                "fog's curve is tabulated up to " + text::g(kLidarLayeredRangeMax) + " m: drop the farther points");
  const LayeredMedium md = layered_medium(p);
  const double end = std::max(range_end_m, p.r2_m + m.pulse_m);
  const BeamSoft b(p, m, md.density, 0.0, end, false);
  SoftCurve c;
  c.step_m = b.step();
  const std::size_t n = std::min(b.nodes(), static_cast<std::size_t>(std::ceil(end / c.step_m)) + 1);
  c.power_w.assign(b.uncut().begin(), b.uncut().begin() + static_cast<std::ptrdiff_t>(n));
  const std::size_t at = static_cast<std::size_t>(std::max_element(c.power_w.begin(), c.power_w.end()) - c.power_w.begin());
  c.peak_w = c.power_w[at];
  c.peak_range_m = static_cast<double>(at) * c.step_m;
  return c;
}

LidarFogStats layered_fog(const float* in, float* out, std::size_t n, const LidarFogParams& p,
                          const LidarFogMedium& m, const std::string& what) {
  const auto t0 = Clock::now();
  LidarFogStats st;
  st.points = n;
  const LayeredMedium md = layered_medium(p);
  const Mat3& rot = md.world_from_scan.rotation;
  st.origin_height_m = md.world_from_scan.translation.y;
  st.origin_density_per_m = md.density.at(0.0);
  const long long count = static_cast<long long>(n);
  constexpr std::size_t kBatch = 4096;

  // Each beam: its range, its world-up component s and the optical depth F
  // to its point (brume's fog integral, the point's own s: no bin), in
  // batches of kBatch points (fixed, so that a point's F never depends on the
  // threads); with them the least s of the points that can turn into fog
  // (R0 > R1, intensity > 0), the first point too far to tabulate and the
  // count within R1 (reductions whose result does not depend on the order).
  // Batches handed out one at a time (a thread that lost its core to another
  // process holds the other up by one batch, not by half the scan); one
  // thread below kLidarLayeredParallelPoints (lidar_fog_tables.hpp).
  std::vector<double> range(n), climb(n);
  std::vector<float> rf(n), sf(n), depth(n);
  std::vector<char> active(n);  // can turn into fog: R0 > R1 and intensity > 0
  const long long batches = (count + kBatch - 1) / kBatch;
  double s_min = INFINITY;
  std::size_t near = 0;
  long long far = count;  // the first point that can turn into fog beyond kLidarLayeredRangeMax
#pragma omp parallel for schedule(dynamic, 1) reduction(min : s_min, far) reduction(+ : near) \
    if (n >= kLidarLayeredParallelPoints)
  for (long long b = 0; b < batches; ++b) {
    const std::size_t a = static_cast<std::size_t>(b) * kBatch, an = std::min<std::size_t>(kBatch, n - a);
    for (std::size_t i = a; i < a + an; ++i) {
      const float* q = in + 4 * i;
      const double x = q[0], y = q[1], z = q[2];
      const Vec3 w = rot * Vec3{x, y, z};
      const double norm = std::sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
      range[i] = std::sqrt(x * x + y * y + z * z);
      climb[i] = norm > 0.0 ? w.y / norm : 0.0;
      active[i] = range[i] > p.r1_m && q[3] > 0.0f;
      rf[i] = static_cast<float>(range[i]);
      sf[i] = static_cast<float>(climb[i]);
      if (active[i]) {
        s_min = std::min(s_min, climb[i]);
        if (range[i] > kLidarLayeredRangeMax) far = std::min(far, static_cast<long long>(i));
      } else {
        near += range[i] <= p.r1_m;
      }
    }
    height_optical_depths(md.density, rf.data() + a, sf.data() + a, depth.data() + a, an);
  }

  // The tables reach each bin's farthest point (1-cm nodes): a point
  // farther than any LiDAR's return is refused rather than tabulated.
  if (far < count) {
    const std::size_t i = static_cast<std::size_t>(far);
    throw Error(what + ": point " + std::to_string(i) + " is " + text::g(range[i]) +
                " m away; a height-layered fog tabulates the soft return along each beam to its farthest point, up "
                "to " +
                text::g(kLidarLayeredRangeMax) +
                " m (no LiDAR return is farther): drop the point or check the scan's units");
  }
  st.zero_range = near;

  // Bins of width Δ in s over the points that can turn into fog; the others
  // are attenuated beside the tables (below).
  const double delta = p.elevation_step_deg * kPi / 180.0;
  const std::size_t bins = std::isfinite(s_min) ? static_cast<std::size_t>(std::floor(2.0 / delta)) + 2 : 0;
  std::vector<std::size_t> start(bins + 1, 0);
  auto bin_of = [&](std::size_t i) {
    return std::min(bins - 1, static_cast<std::size_t>((climb[i] - s_min) / delta));
  };
  for (std::size_t i = 0; i < n; ++i)
    if (active[i]) ++start[bin_of(i) + 1];
  for (std::size_t b = 0; b < bins; ++b) start[b + 1] += start[b];
  std::vector<std::size_t> order(bins ? start[bins] : 0), fill(start.begin(), start.end());
  std::vector<double> s_lo(bins, INFINITY), s_hi(bins, -INFINITY), r_end(bins, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    if (!active[i]) continue;
    const std::size_t b = bin_of(i);
    order[fill[b]++] = i;
    s_lo[b] = std::min(s_lo[b], climb[i]);
    s_hi[b] = std::max(s_hi[b], climb[i]);
    r_end[b] = std::max(r_end[b], range[i]);
  }
  std::vector<std::size_t> used;
  for (std::size_t b = 0; b < bins; ++b)
    if (start[b + 1] > start[b]) {
      used.push_back(b);
      st.bin_offset_max = std::max(st.bin_offset_max, 0.5 * (s_hi[b] - s_lo[b]));
    }
  // The longest tables first, so that the threads end together.
  std::sort(used.begin(), used.end(), [&](std::size_t a, std::size_t b) { return r_end[a] > r_end[b]; });

  // Each table's size before the threads start (an Error cannot leave an
  // OpenMP region): the longest first.
  if (!used.empty())
    lidar_table_nodes(r_end[used.front()], m.pulse_m / kLidarStepsPerPulse, p.tau_h_ns, "the scan's farthest point");

  // One table a bin, at the middle of its beams' s; its points on the same thread.
  const PointRule rule(p, m);
  std::size_t soft = 0, nodes = 0;
  double table_ms = 0.0;
  long long overflow = count;
  const long long used_n = static_cast<long long>(used.size());
  std::vector<double> max_w(used.size()), max_r(used.size());
  // The work items: the tables, longest first, then the points that cannot
  // turn into fog, attenuated in batches (small items last, so that the
  // threads end together); one at a time.
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : soft, nodes, table_ms) reduction(min : overflow) \
    if (used_n > 1 || n >= kLidarLayeredParallelPoints)
  for (long long u = 0; u < used_n + batches; ++u) {
    if (u >= used_n) {
      const std::size_t a = static_cast<std::size_t>(u - used_n) * kBatch, an = std::min<std::size_t>(kBatch, n - a);
      for (std::size_t i = a; i < a + an; ++i) {
        if (active[i]) continue;
        const float* q = in + 4 * i;
        float* o = out + 4 * i;
        o[0] = q[0], o[1] = q[1], o[2] = q[2],
        o[3] = static_cast<float>(q[3] * std::exp(-2.0 * static_cast<double>(depth[i])));
      }
      continue;
    }
    const std::size_t b = used[static_cast<std::size_t>(u)];
    const auto a = Clock::now();
    BeamSoft beam(p, m, md.density, 0.5 * (s_lo[b] + s_hi[b]), r_end[b], true);
    table_ms += std::chrono::duration<double, std::milli>(Clock::now() - a).count();
    nodes += beam.nodes();
    max_w[static_cast<std::size_t>(u)] = beam.max_w();
    max_r[static_cast<std::size_t>(u)] = beam.max_range();
    for (std::size_t k = start[b]; k < start[b + 1]; ++k) {
      const std::size_t i = order[k];
      double pw, pr;
      beam.peak(range[i], pw, pr);
      bool over = false;
      if (rule.place(in + 4 * i, out + 4 * i, i, range[i], std::exp(-2.0 * static_cast<double>(depth[i])), pw, pr,
                     over))
        ++soft;
      if (over) overflow = std::min(overflow, static_cast<long long>(i));
    }
  }
  if (overflow < count) throw_overflow(in, overflow, what);
  for (std::size_t u = 0; u < used.size(); ++u)  // the largest maximum of the beams' tables
    if (max_w[u] > st.peak_w) st.peak_w = max_w[u], st.peak_range_m = max_r[u];
  st.soft = soft;
  st.tables = used.size();
  st.table_nodes = nodes;
  st.table_ms = table_ms;
  st.points_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  return st;
}

}  // namespace brume::lidar_detail
