// brume — rain's physics, its drop field and rain on a LiDAR scan as a
// particle medium (brume/rain.hpp states the equations; docs/rain.md).
#include "brume/rain.hpp"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdint>
#include <limits>

#include "brume/error.hpp"
#include "core/text.hpp"

namespace brume {

namespace {
constexpr double kPi = 3.14159265358979323846;
// A cell's index in a table: Teschner et al. 2003's spatial hash (three
// large primes, xor), cheap where the drop field's hash need not be.
std::size_t rain_cell_hash(const RainCell& c) {
  return static_cast<std::size_t>((static_cast<std::uint64_t>(c.ix) * 73856093u) ^
                                  (static_cast<std::uint64_t>(c.iy) * 19349663u) ^
                                  (static_cast<std::uint64_t>(c.iz) * 83492791u));
}
// The drop field's words, so that its draws are none of the speckle's.
constexpr std::uint64_t kRainFieldTag = 0x7261696e6669656cull;  // "rainfiel"
}  // namespace

double atlas_zero_speed_mm() { return std::log(10.3 / 9.65) / 0.6; }

double marshall_palmer_lambda_per_mm(double rate_mm_h) { return 4.1 * std::pow(rate_mm_h, -0.21); }

double marshall_palmer_density(double rate_mm_h, double d_mm) {
  if (rate_mm_h == 0.0) return 0.0;
  return kMarshallPalmerN0 * std::exp(-marshall_palmer_lambda_per_mm(rate_mm_h) * d_mm);
}

double atlas_terminal_velocity_m_per_s(double d_mm) { return 9.65 - 10.3 * std::exp(-0.6 * d_mm); }

double rain_extinction_per_m(double rate_mm_h, double q) {
  if (rate_mm_h == 0.0) return 0.0;
  const double l = marshall_palmer_lambda_per_mm(rate_mm_h);
  // ∫_0^∞ D²·e^{−ΛD} dD = 2/Λ³; mm² per m³ is 1e−6 per m.
  return q * (kPi / 4.0) * 2.0 * kMarshallPalmerN0 / (l * l * l) * 1e-6;
}

double rain_drops_per_m3(double rate_mm_h, double d_min_mm, double d_max_mm) {
  if (rate_mm_h == 0.0) return 0.0;
  const double l = marshall_palmer_lambda_per_mm(rate_mm_h);
  return kMarshallPalmerN0 / l * (std::exp(-l * d_min_mm) - std::exp(-l * d_max_mm));
}

// ---- the drop field ---------------------------------------------------------------------

RainField::RainField(double rate_mm_h, double d_min_mm, double d_max_mm, std::uint64_t seed, std::uint64_t frame)
    : rate_(rate_mm_h), d_min_(d_min_mm), d_max_(d_max_mm), key_(hash_fold(hash_fold(seed, kRainFieldTag), frame)) {
  if (rate_ > 0.0) {
    lambda_ = marshall_palmer_lambda_per_mm(rate_);
    n_ = rain_drops_per_m3(rate_, d_min_, d_max_);
    tail_ = std::exp(-lambda_ * d_max_);
    scale_ = kRainCellM * kRainCellM * kRainCellM * kMarshallPalmerN0 / lambda_;
  }
}

void RainField::cell_drops(const RainCell& cell, double d_floor_mm, std::vector<RainDrop>& out) const {
  for_each_drop(cell, d_floor_mm, [&](const Vec3& at, double s) { out.push_back({at, diameter_mm(s)}); });
}

double RainField::measure_above(double d_mm) const {
  if (n_ <= 0.0) return 0.0;
  const double d = std::max(d_mm, d_min_);
  if (d >= d_max_) return 0.0;
  return d == d_min_ ? kRainCellM * kRainCellM * kRainCellM * n_ : scale_ * (std::exp(-lambda_ * d) - tail_);
}

double RainField::diameter_mm(double s) const {
  // M(D) = s: e^{−ΛD} = s/scale + e^{−Λ·D_max}; rounding only can leave [D_min, D_max].
  const double d = -std::log(s / scale_ + tail_) / lambda_;
  return std::min(std::max(d, d_min_), d_max_);
}

void RainField::cone_cells(const MediumRay& ray, double t0, double t1, double half_width, std::vector<RainCell>& out) {
  out.clear();
  if (!(t1 > t0)) return;
  const double c = kRainCellM;
  const double o[3] = {ray.origin.x, ray.origin.y, ray.origin.z};
  const double d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
  std::int64_t idx[3];
  double tmax[3], tdelta[3];
  int step[3];
  for (int a = 0; a < 3; ++a) {
    const double p = o[a] + t0 * d[a];
    idx[a] = static_cast<std::int64_t>(std::floor(p / c));
    step[a] = d[a] > 0.0 ? 1 : d[a] < 0.0 ? -1 : 0;
    const double inf = std::numeric_limits<double>::infinity();
    tmax[a] = step[a] > 0   ? (static_cast<double>(idx[a] + 1) * c - o[a]) / d[a]
              : step[a] < 0 ? (static_cast<double>(idx[a]) * c - o[a]) / d[a]
                            : inf;
    tdelta[a] = step[a] != 0 ? c / std::abs(d[a]) : inf;
  }
  // Each cell once, in the order the DDA meets it: an open-addressing set of
  // indices into `out` (a sort of the list cost 17 % of a scan's time).
  // Sized for the steps' boxes (about three cells a step) at a load below a half.
  thread_local std::vector<std::uint32_t> table;  // index + 1; 0: empty
  const double steps = (t1 - t0) * (std::abs(d[0]) + std::abs(d[1]) + std::abs(d[2])) / c + 3.0;
  std::size_t size = 64;
  while (static_cast<double>(size) < 8.0 * steps && size < (std::size_t(1) << 24)) size *= 2;
  table.assign(size, 0u);
  const auto slot_of = [&](const RainCell& c) {
    const std::size_t mask = table.size() - 1;
    std::size_t i = rain_cell_hash(c) & mask;
    while (table[i] != 0 && !(out[table[i] - 1] == c)) i = (i + 1) & mask;
    return i;
  };
  const auto insert = [&](const RainCell& c) {
    const std::size_t i = slot_of(c);
    if (table[i] != 0) return;
    out.push_back(c);
    table[i] = static_cast<std::uint32_t>(out.size());
    if (2 * out.size() > table.size()) {  // keep the load below a half
      std::fill(table.begin(), table.end(), 0u);
      table.resize(table.size() * 2, 0u);
      for (std::size_t k = 0; k < out.size(); ++k) table[slot_of(out[k])] = static_cast<std::uint32_t>(k + 1);
    }
  };
  double ta = t0;
  for (;;) {
    const double tb = std::min({tmax[0], tmax[1], tmax[2], t1});
    // The segment [ta, tb] within this cell, widened by the cone's radius at tb.
    const double w = tb * half_width;
    std::int64_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      const double pa = o[a] + std::max(ta, t0) * d[a], pb = o[a] + tb * d[a];
      lo[a] = static_cast<std::int64_t>(std::floor((std::min(pa, pb) - w) / c));
      hi[a] = static_cast<std::int64_t>(std::floor((std::max(pa, pb) + w) / c));
    }
    for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z) insert({x, y, z});
    if (tb >= t1) break;
    const int a = tmax[0] <= tmax[1] ? (tmax[0] <= tmax[2] ? 0 : 2) : (tmax[1] <= tmax[2] ? 1 : 2);
    idx[a] += step[a];
    ta = tmax[a];
    tmax[a] += tdelta[a];
  }
}

// ---- the parameters ----------------------------------------------------------------------

const ParamTable<RainDrops>& rain_drops_param_table() {
  static const ParamTable<RainDrops> t = [] {
    ParamTable<RainDrops> d("rain");
    d.real("rate", &RainDrops::rate_mm_h, "mm/h", Range::closed(0.0, 500.0),
           "rain rate R (Marshall-Palmer drop sizes: N0 = 8000 m^-3 mm^-1, Lambda = 4.1 R^-0.21 mm^-1; one drop "
           "field for the camera and the LiDAR); 0: no rain, the input back as the other media leave it",
           "none")
        .real("drop-min", &RainDrops::drop_min_mm, "mm", Range::at_least(atlas_zero_speed_mm()),
              "smallest drawn drop D_min; Atlas's fall speed is negative below 0.1087 mm")
        .real("drop-max", &RainDrops::drop_max_mm, "mm", Range::left_open(0.0, 10.0),
              "largest drawn drop D_max (larger drops break up); must exceed --drop-min");
    return d;
  }();
  return t;
}

void validate_rain_drops(const RainDrops& d) {
  rain_drops_param_table().validate(d);
  if (!d.rate_mm_h) throw Error("no rain rate given: use --rate R (mm/h, in [0, 500])");
  if (!(d.drop_max_mm > d.drop_min_mm))
    throw Error("--drop-max " + text::g(d.drop_max_mm) + " must exceed --drop-min " + text::g(d.drop_min_mm) +
                " (the drawn drops' diameters lie between them); give a larger --drop-max");
}

const ParamTable<LidarRainParams>& lidar_rain_param_table() {
  static const ParamTable<LidarRainParams> t = [] {
    ParamTable<LidarRainParams> d("rain");
    d.nest(&LidarRainParams::drops, rain_drops_param_table())
        .real("divergence", &LidarRainParams::divergence_mrad, "mrad", Range::left_open(0.0, 50.0),
              "full divergence theta of the LiDAR's beam: a drop meets a beam when its centre lies in the cone")
        .real("drop-reflectance", &LidarRainParams::drop_reflectance, "1", Range::closed(0.0, 1.0),
              "a drop's backscatter rho_d as a Lambertian reflectance of its cross-section, on the scan's intensity "
              "scale (default 2 pi/S, S = 18 sr: liquid water drops' lidar ratio; docs/rain.md)")
        .real("noise-floor", &LidarRainParams::noise_floor, "1/m^2", Range::above(0.0),
              "noise floor F: the weakest mean return power (intensity/range^2) the sensor detects; default below "
              "KITTI 000001's weakest non-zero return (7.7e-6)")
        .real("blind-range", &LidarRainParams::blind_range_m, "m", Range::at_least(0.0),
              "r_min: the sensor reports no return nearer (no drop echo there)")
        .count("seed", &LidarRainParams::seed, "1", Range::at_least(0.0),
               "seed of the drop field and of the detection draws (same seed, same scan)");
    return d;
  }();
  return t;
}

void validate_lidar_rain(const LidarRainParams& p) {
  lidar_rain_param_table().validate(p);
  validate_rain_drops(p.drops);
}

// ---- rain on a LiDAR scan ------------------------------------------------------------------

namespace {

class LidarRain final : public Medium {
 public:
  explicit LidarRain(const LidarRainParams& p)
      : p_(p),
        sigma_(rain_extinction_per_m(*p.drops.rate_mm_h, kLidarRainQ)),
        field_(*p.drops.rate_mm_h, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed),
        theta_(p.divergence_mrad * 1e-3) {
    // D_t(r) = θ·r²·√(F/ρ_d) [m]: the smallest drop whose echo can reach F at r.
    if (field_.drops_per_m3() > 0.0 && p.drop_reflectance > 0.0) {
      k_ = theta_ * std::sqrt(p.noise_floor / p.drop_reflectance);
      reach_ = std::sqrt(p.drops.drop_max_mm * 1e-3 / k_);
    }
  }

  double extinction_per_m() const override { return sigma_; }

  void particles(const MediumRay& ray, double range_m, double, std::vector<Particle>& out) const override {
    visit(ray, range_m, [&](double t, double power, double) { out.push_back({t, power * range_m * range_m, 0.0, {}}); });
  }

  // The strongest drop echo above the floor per beam (the others never win).
  void scan_echoes(const float* points, std::size_t n, std::vector<ScanEcho>& out) const override {
    if (reach_ <= 0.0) return;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = points[4 * i], y = points[4 * i + 1], z = points[4 * i + 2];
      const double r = std::sqrt(x * x + y * y + z * z);
      if (!(r > p_.blind_range_m)) continue;
      const MediumRay b{{0.0, 0.0, 0.0}, {x / r, y / r, z / r}};
      double best = -1.0, best_t = 0.0, best_rep = 0.0;
      visit(b, r, [&](double t, double power, double reported) {
        if (power > best) best = power, best_t = t, best_rep = reported;
      });
      if (best >= 0.0) out.push_back({i, best_t, best * r * r, best_rep});
    }
  }

  nlohmann::json scan_record(const ScanRun& run) const override {
    return lidar_rain_record(p_, {run, drawn_});
  }

  std::size_t drawn() const { return drawn_; }
  LidarRain(const LidarRain&) = delete;

 private:
  // Calls f(t, P_d, ρ_d·e^{−2σt}·a) for every drop in the beam's cone over
  // [r_min, range) whose echo power P_d reaches the floor.
  template <class F>
  void visit(const MediumRay& ray, double range_m, F&& f) const {
    if (reach_ <= 0.0) return;
    const double t1 = std::min(range_m, reach_), hw = theta_ / 2.0;
    RainField::cone_cells(ray, p_.blind_range_m, t1, hw, cells_);
    const double cos_half = 1.0 / std::sqrt(1.0 + hw * hw);
    const double c = kRainCellM;
    const double o[3] = {ray.origin.x, ray.origin.y, ray.origin.z};
    for (const RainCell& cell : cells_) {
      // The cell's nearest range along any direction in a cone: its distance × cos(θ/2).
      const std::int64_t ci[3] = {cell.ix, cell.iy, cell.iz};
      double dist2 = 0.0;
      for (int a = 0; a < 3; ++a) {
        const double lo = static_cast<double>(ci[a]) * c, hi = lo + c;
        const double g = std::max({lo - o[a], 0.0, o[a] - hi});
        dist2 += g * g;
      }
      const double r_near = std::max(p_.blind_range_m, std::sqrt(dist2) * cos_half);
      if (r_near >= t1) continue;
      const double dfl = k_ * r_near * r_near * 1e3;
      Slot& slot = cache_[slot_of(cell)];
      const bool same = slot.cell == cell && slot.dfl == dfl;  // a scan's beams: the same cell, the same floor
      const double m = same ? slot.m : field_.measure_above(dfl);
      if (!(m > 0.0)) continue;
      const auto test = [&](const Vec3& at, double s) {
        const double px = at.x - o[0], py = at.y - o[1], pz = at.z - o[2];
        const double t = px * ray.dir.x + py * ray.dir.y + pz * ray.dir.z;
        if (!(t >= p_.blind_range_m && t < range_m)) return;
        const double perp2 = std::max(0.0, px * px + py * py + pz * pz - t * t);
        if (perp2 > t * hw * t * hw) return;
        const double frac = std::min(1.0, std::pow(field_.diameter_mm(s) * 1e-3 / (theta_ * t), 2));
        const double reported = p_.drop_reflectance * std::exp(-2.0 * sigma_ * t) * frac;
        const double power = reported / (t * t);
        if (power >= p_.noise_floor) f(t, power, reported);
      };
      // Neighbouring beams cross the same cells: a cell's drops are kept in
      // a direct-mapped cache, drawn to some measure m_s; a request of m <= m_s
      // takes the prefix s <= m of them (the same drops, largest first).
      if (slot.cell == cell && slot.m >= m && slot.n <= kSlotDrops) {
        for (std::uint32_t j = 0; j < slot.n && slot.s[j] <= m; ++j) test(slot.at[j], slot.s[j]);
        continue;
      }
      slot.cell = cell, slot.dfl = dfl, slot.m = m, slot.n = 0;
      field_.for_each_drop_within(cell, m, [&](const Vec3& at, double s) {
        ++drawn_;
        if (slot.n < kSlotDrops) slot.at[slot.n] = at, slot.s[slot.n] = s;
        ++slot.n;  // beyond kSlotDrops: not kept (drawn again next time)
        test(at, s);
      });
    }
  }

  // A cache slot: a cell's drops as drawn to the measure m (n > kSlotDrops: not kept).
  // A cell whose measure is 0 is never stored (its slot keeps another's).
  static constexpr std::uint32_t kSlotDrops = 16;
  static constexpr std::size_t kSlots = std::size_t(1) << 14;
  struct Slot {
    RainCell cell{INT64_MIN, INT64_MIN, INT64_MIN};
    double dfl = -1.0, m = -1.0;  // the diameter [mm] and measure it was drawn to
    std::uint32_t n = 0;
    std::array<Vec3, kSlotDrops> at;
    std::array<double, kSlotDrops> s;
  };
  static std::size_t slot_of(const RainCell& c) { return rain_cell_hash(c) & (kSlots - 1); }

  LidarRainParams p_;
  double sigma_;
  RainField field_;
  double theta_, k_ = 0.0, reach_ = 0.0;
  mutable std::vector<RainCell> cells_;
  mutable std::vector<Slot> cache_ = std::vector<Slot>(kSlots);
  mutable std::size_t drawn_ = 0;
};

}  // namespace

std::unique_ptr<Medium> lidar_rain_as_medium(const LidarRainParams& p) {
  validate_lidar_rain(p);
  return std::make_unique<LidarRain>(p);
}

LidarRainStats lidar_rain(const float* in, float* out, std::size_t n, const LidarRainParams& p, std::uint8_t* labels,
                          const std::string& what) {
  validate_lidar_rain(p);
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = in + 4 * i;
    if (!(std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2]) && std::isfinite(q[3])))
      throw Error(what + ": point " + std::to_string(i) + " has a non-finite coordinate or intensity");
    if (q[3] < 0.0f)
      throw Error(what + ": point " + std::to_string(i) + " has a negative intensity " + text::g(q[3]) +
                  "; intensities are reflectances >= 0");
  }
  const LidarRain m(p);
  const ScanDetection detection{p.noise_floor, p.seed};
  LidarRainStats st;
  st.run = scan_through_media({&m}, in, out, n, what, &detection, labels);
  st.drops_drawn = m.drawn();
  return st;
}

nlohmann::json lidar_rain_record(const LidarRainParams& p, const LidarRainStats& st) {
  const double r = p.drops.rate_mm_h.value_or(0.0);
  const std::size_t moved = st.run.echoes, lost = st.run.lost;
  return {{"model",
           "Marshall-Palmer 1948 drop sizes, Atlas et al. 1973 fall speed; per beam the drops in its cone echo "
           "(Kilic et al. 2021, from the paper's equations), the strongest return wins, speckle detection against "
           "the noise floor"},
          {"rate_mm_h", r},
          {"n0_per_m3_mm", kMarshallPalmerN0},
          {"lambda_per_mm", r > 0.0 ? nlohmann::json(marshall_palmer_lambda_per_mm(r)) : nlohmann::json(nullptr)},
          {"extinction_per_m", rain_extinction_per_m(r, kLidarRainQ)},
          {"extinction_q", kLidarRainQ},
          {"extinction_q_from", "a narrow beam loses the drops' forward diffraction lobe: Q = 2 (extinction paradox)"},
          {"drops_per_m3", rain_drops_per_m3(r, p.drops.drop_min_mm, p.drops.drop_max_mm)},
          {"divergence_mrad", p.divergence_mrad},
          {"drop_reflectance", p.drop_reflectance},
          {"drop_reflectance_from",
           "2 pi/S, S the lidar ratio of liquid water drops (about 18 sr; Pinnick et al. 1983); docs/rain.md"},
          {"noise_floor_per_m2", p.noise_floor},
          {"blind_range_m", p.blind_range_m},
          {"drop_min_mm", p.drops.drop_min_mm},
          {"drop_max_mm", p.drops.drop_max_mm},
          {"cell_m", kRainCellM},
          {"seed", p.seed},
          {"frame", 0},
          {"points", st.run.points},
          {"kept", st.run.points - moved - lost},
          {"moved_to_drops", moved},
          {"lost", lost},
          {"drops_drawn", st.drops_drawn}};
}

}  // namespace brume
