// brume — snow's physics (the flakes' sizes, volume fraction and number) and
// snow on a LiDAR scan by the footprint model as a particle medium
// (brume/snow.hpp states the equations; docs/snow.md).
#include "brume/snow.hpp"

#include "effects/snow/snow_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "brume/error.hpp"
#include "core/math_constants.hpp"  // kPi: one definition (unity builds)
#include "core/text.hpp"
#include "media/scan_points_check.hpp"
#include "media/scan_returns.hpp"

namespace brume {

namespace {
constexpr const char* kGunnMarshall = "gunn-marshall";
constexpr const char* kSekhonSrivastava = "sekhon-srivastava";
// The flakes' draws, so that they are none of the speckle's nor rain's.
constexpr std::uint64_t kSnowTag = 0x736e6f77666c616bull;  // "snowflak"

// P(3, z) = 1 − e^{−z}(1 + z + z²/2), the regularised lower incomplete gamma
// of order 3 (∫_0^y D²e^{−ΛD} dD = 2/Λ³·P(3, Λy)); its series below 1, where
// the closed form cancels.
double gamma_p3(double z) {
  if (!(z > 0.0)) return 0.0;
  if (std::isinf(z)) return 1.0;
  if (z < 1.0) {  // e^{−z}·Σ_{k>=0} z^{3+k}/(3+k)!
    double term = z * z * z / 6.0, sum = 0.0;
    for (int k = 0; k < 40 && term > 1e-18 * sum; ++k) sum += term, term *= z / (4.0 + k);
    return std::exp(-z) * sum;
  }
  return 1.0 - std::exp(-z) * (1.0 + z + z * z / 2.0);
}

std::uint32_t float_bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  return u;
}
}  // namespace

// ---- the flakes ---------------------------------------------------------------------------

const ParamTable<SnowFlakes>& snow_flakes_param_table() {
  static const ParamTable<SnowFlakes> t = [] {
    ParamTable<SnowFlakes> d("snow");
    d.real("rate", &SnowFlakes::rate_mm_h, "mm/h", Range::closed(0.0, 10.0),
           "water-equivalent snowfall rate S (the melted flakes' flux); 0: no snow, the input back as the other "
           "media leave it",
           "none")
        .choice("distribution", &SnowFlakes::distribution, {kGunnMarshall, kSekhonSrivastava},
                "the melted sizes' exponential slope: gunn-marshall (Lambda = 2.55 S^-0.48 mm^-1, Gunn & Marshall "
                "1958) or sekhon-srivastava (Lambda = 2.29 S^-0.45 mm^-1, Sekhon & Srivastava 1970); the intercept "
                "follows from the flux")
        .real("flake-density", &SnowFlakes::flake_density_g_cm3, "g/cm^3", Range::closed(0.005, 0.917),
              "the flakes' bulk density rho_s: a flake is (1/rho_s)^(1/3) times its melted drop (aggregates "
              "0.01-0.2, ice 0.917)")
        .real("fall-speed", &SnowFlakes::fall_speed_m_s, "m/s", Range::closed(0.1, 10.0),
              "the flakes' fall speed v_t, one for all sizes (aggregates about 0.5-2; Locatelli & Hobbs 1974); it "
              "sets how many flakes carry the rate");
    return d;
  }();
  return t;
}

void validate_snow_flakes(const SnowFlakes& f) {
  snow_flakes_param_table().validate(f);
  if (!f.rate_mm_h)
    throw Error("no snowfall rate given: use --rate S (water-equivalent mm/h, in [0, 10])");
}

double snow_melted_lambda_per_mm(const std::string& distribution, double rate_mm_h) {
  if (distribution == kGunnMarshall) return 2.55 * std::pow(rate_mm_h, -0.48);
  if (distribution == kSekhonSrivastava) return 2.29 * std::pow(rate_mm_h, -0.45);
  throw Error("--distribution " + distribution + " is not known; use gunn-marshall or sekhon-srivastava");
}

SnowSizes snow_sizes(const SnowFlakes& f) {
  SnowSizes s;
  s.scale = std::cbrt(kWaterDensityGcm3 / f.flake_density_g_cm3);
  const double rate = f.rate_mm_h.value_or(0.0);
  if (!(rate > 0.0)) return s;
  s.lambda_melted_per_mm = snow_melted_lambda_per_mm(f.distribution, rate);
  s.lambda_flake_per_mm = s.lambda_melted_per_mm / s.scale;
  s.volume_fraction = kWaterDensityGcm3 * rate / (3.6e6 * f.flake_density_g_cm3 * f.fall_speed_m_s);
  const double l = s.lambda_flake_per_mm;
  s.n0_flake = 1e9 * s.volume_fraction * (l * l) * (l * l) / kPi;  // mm⁻⁴ → m⁻³ mm⁻¹
  s.n0_melted = s.scale * s.n0_flake;
  s.flakes_per_m3 = s.n0_flake / l;
  return s;
}

double SnowSizes::flake_density(double d_f_mm) const {
  return n0_flake > 0.0 ? n0_flake * std::exp(-lambda_flake_per_mm * d_f_mm) : 0.0;
}
double SnowSizes::melted_density(double d_m_mm) const {
  return n0_melted > 0.0 ? n0_melted * std::exp(-lambda_melted_per_mm * d_m_mm) : 0.0;
}
double SnowSizes::extinction_per_m(double q) const {
  if (!(n0_flake > 0.0)) return 0.0;
  const double l = lambda_flake_per_mm;
  return q * (kPi / 4.0) * 2.0 * n0_flake / (l * l * l) * 1e-6;  // mm² per m³ is 1e−6 per m
}

const ParamTable<LidarSnowParams>& lidar_snow_param_table() {
  static const ParamTable<LidarSnowParams> t = [] {
    ParamTable<LidarSnowParams> d("snow");
    d.nest(&LidarSnowParams::flakes, snow_flakes_param_table())
        .real("divergence", &LidarSnowParams::divergence_mrad, "mrad", Range::left_open(0.0, 50.0),
              "full divergence theta of the LiDAR's beam: its footprint at range r is theta r wide, and a flake "
              "whose centre lies in the cone occludes (D_f/(theta r))^2 of it")
        .real("flake-reflectance", &LidarSnowParams::flake_reflectance, "1", Range::closed(0.0, 1.0),
              "a flake's reflectance rho_f on the scan's intensity scale (fresh snow's albedo near 905 nm; "
              "docs/snow.md)")
        .real("noise-floor", &LidarSnowParams::noise_floor, "1/m^2", Range::above(0.0),
              "noise floor F: the weakest mean return power (intensity/range^2) the sensor detects; flakes whose "
              "echo cannot reach it occlude in expectation")
        .real("blind-range", &LidarSnowParams::blind_range_m, "m", Range::at_least(0.0),
              "r_min: the sensor reports no return nearer; no flake is drawn there")
        .count("seed", &LidarSnowParams::seed, "1", Range::at_least(0.0),
               "seed of the flakes and of the detection draws (same seed, same scan)");
    declare_return_mode(d, &LidarSnowParams::return_mode, "a beam", "flake");
    d.count("frame", &LidarSnowParams::frame, "1", Range::at_least(0.0),
            "frame K of a sequence: each beam's flakes drawn afresh from (seed, K, the beam), as the flakes in a "
            "footprint a few cm wide are others 0.1 s later; 0: the draws of a single scan")
        .since(4, 0);
    return d;
  }();
  return t;
}

void validate_lidar_snow(const LidarSnowParams& p) {
  lidar_snow_param_table().validate(p);
  validate_snow_flakes(p.flakes);
}

// ---- the footprint model ----------------------------------------------------------------

namespace {

// A beam's outcome: the strongest flake echo (power < 0: none) and the target's share.
struct BeamOutcome {
  double power = -1.0, range = 0.0, reported = 0.0;
  double left = 1.0, area = 0.0;  // the target's share is left·e^{−area}: Π(1 − a) of the drawn flakes, A(r)
  std::size_t drawn = 0;
};

// The tables of one snowfall and sensor: along the axis from r_min on nodes
// x_j = r_min + j·h, the drawn flakes' intensity λ (linear between nodes) and
// its integral L, and the undrawn flakes' expected occlusion per metre α
// (linear between nodes) and its integral A; beyond the last node α is
// σ(Q = 1) (every flake undrawn, none as wide as the footprint).
class SnowFootprint {
 public:
  // Tabulated out to the farthest point, r_max (the values at the nodes do not depend on it).
  SnowFootprint(const LidarSnowParams& p, double r_max)
      : p_(p), sizes_(snow_sizes(p.flakes)), last_(scan_return(p.return_mode) == ScanReturn::last) {
    theta_ = p.divergence_mrad * 1e-3;
    lam_ = sizes_.lambda_flake_per_mm;
    r_min_ = p.blind_range_m;
    if (!(sizes_.n0_flake > 0.0)) return;
    active_ = true;
    sigma1_ = sizes_.extinction_per_m(1.0);
    key_ = hash_fold(hash_fold(p.seed, kSnowTag), p.frame);
    // D_t(x) = θ·x²·√(F/ρ_f) [m]; none detectable where ρ_f = 0 or beyond
    // √(ρ_f/F) (a flake filling the footprint stays below F).
    double x_draw = r_min_;
    if (p.flake_reflectance > 0.0) {
      ct_mm_ = 1e3 * theta_ * std::sqrt(p.noise_floor / p.flake_reflectance);
      // Beyond Λ_f·D_t = 40 a beam expects fewer than e^{−40}·n·(cone) drawn flakes: none is drawn.
      x_draw = std::min(std::sqrt(40.0 / (lam_ * ct_mm_)), std::sqrt(p.flake_reflectance / p.noise_floor));
    }
    draws_ = x_draw > r_min_;
    // α is σ(Q = 1) to e^{−60} once the footprint is 60/Λ_f wide.
    const double x_end =
        std::min(std::max(x_draw, 60.0 / (lam_ * 1e3 * theta_)), std::max(r_max, r_min_)) + h_;
    constexpr double kMaxNodes = 1 << 22;
    if ((x_end - r_min_) / h_ > kMaxNodes)
      throw Error("a point lies " + text::g(r_max) + " m from the sensor, and with --noise-floor " +
                  text::g(p.noise_floor) + " flakes are detectable out to " + text::g(x_draw) +
                  " m; the footprint model tabulates its beams on " + text::g(h_ * 100) + " cm steps out to " +
                  text::g(r_min_ + kMaxNodes * h_) + " m: leave out points that far, or give a larger --noise-floor");
    const std::size_t nodes = static_cast<std::size_t>(std::ceil((x_end - r_min_) / h_)) + 1;
    lambda_.resize(nodes), cum_.resize(nodes), alpha_.resize(nodes), area_.resize(nodes);
    const double k_cone = kPi / 4.0 * theta_ * theta_ * sizes_.flakes_per_m3;  // λ = k_cone·x²·e^{−Λ_f D_t}
    for (std::size_t j = 0; j < nodes; ++j) {
      const double x = node(j);
      const bool drawn_here = draws_ && x < x_draw;
      const double dt = drawn_here ? ct_mm_ * x * x : std::numeric_limits<double>::infinity();
      lambda_[j] = drawn_here ? k_cone * x * x * std::exp(-lam_ * dt) : 0.0;
      alpha_[j] = undrawn_per_m(x, dt);
      cum_[j] = j == 0 ? 0.0 : cum_[j - 1] + h_ * 0.5 * (lambda_[j - 1] + lambda_[j]);
      area_[j] = j == 0 ? 0.0 : area_[j - 1] + h_ * 0.5 * (alpha_[j - 1] + alpha_[j]);
    }
    // L's inverse starts from a bucket of L (the step holding its lower end): about one step a bucket.
    if (cum_.back() > 0.0) {
      bucket_.resize(nodes);
      inv_dl_ = static_cast<double>(nodes) / cum_.back();
      std::size_t j = 0;
      for (std::size_t b = 0; b < nodes; ++b) {
        const double lo = static_cast<double>(b) / inv_dl_;
        while (j + 1 < nodes && cum_[j + 1] <= lo) ++j;
        bucket_[b] = static_cast<std::uint32_t>(j);
      }
    }
  }

  bool active() const { return active_; }
  double sigma1() const { return sigma1_; }

  // The beam to (x, y, z) at range r (> r_min): its drawn flakes near to
  // far, the strongest detectable echo and the target's share; `detail`
  // (tests): every share.
  BeamOutcome beam(const float* q, double r, SnowBeam* detail = nullptr) const {
    BeamOutcome o;
    if (!active_ || !(r > r_min_)) return o;
    double T = 1.0;  // Π(1 − a) of the drawn flakes met so far
    if (draws_) {
      const double l_r = measure(r);
      const std::uint64_t hb = hash_fold(hash_fold(key_, static_cast<std::uint64_t>(float_bits(q[0])) |
                                                              static_cast<std::uint64_t>(float_bits(q[1])) << 32),
                                         float_bits(q[2]));
      // The drawn flakes as points of L over [0, L(r)): a Poisson number of mean L(r), by inversion
      // of one uniform (where L(r) <= 30; beyond, as sums of unit exponentials), each at u·L(r),
      // sorted (near to far: L increases), with its own hash for its diameter.
      thread_local std::vector<std::pair<double, std::uint64_t>> pts;
      pts.clear();
      if (l_r <= 30.0) {
        const double u0 = hash_unit(hash_fold(hb, 0));  // (hash_fold mixes: its top bits are uniform)
        double pk = std::exp(-l_r), c = pk;
        for (std::uint64_t k = 1; u0 >= c; ++k) {
          const std::uint64_t hk = hash_fold(hb, k);
          pts.push_back({hash_unit(hk) * l_r, hk});
          pk *= l_r / static_cast<double>(k);
          if (!(pk > 1e-17 * c)) break;  // the rest of the distribution is below rounding
          c += pk;
        }
        std::sort(pts.begin(), pts.end());
      } else {
        double s = 0.0;
        for (std::uint64_t k = 1;; ++k) {
          const std::uint64_t hk = hash_fold(hb, k);
          s += -std::log1p(-hash_unit(hk));
          if (!(s < l_r)) break;
          pts.push_back({s, hk});
        }
      }
      double a_prev = 0.0;  // A at the previous flake (detail)
      for (const auto& [s, hk] : pts) {
        const double x = range_at(s);
        if (!(x < r)) break;
        ++o.drawn;
        const double d = ct_mm_ * x * x - std::log1p(-hash_unit(hash_mix(hk))) / lam_;  // D_t + Exp(Λ_f) [mm]
        const double w = d / (1e3 * theta_ * x);
        const double a = std::min(w * w, 1.0);
        const double bound = p_.flake_reflectance * a * T / (x * x);  // its echo with no undrawn flake nearer
        // strongest: a flake whose echo can beat the best so far; last: any that can reach F (the
        // flakes come near to far, so the last detectable one met is the farthest).
        if (detail || (bound >= p_.noise_floor && (last_ || bound > o.power))) {
          const double ax = area_at(x), share = a * T * std::exp(-ax), power = p_.flake_reflectance * share / (x * x);
          if (power >= p_.noise_floor && (last_ || power > o.power))
            o.power = power, o.range = x, o.reported = p_.flake_reflectance * share;
          if (detail) {
            detail->undrawn_share += T * (std::exp(-a_prev) - std::exp(-ax));
            detail->flakes.push_back({x, d, a, share, power});
            a_prev = ax;
          }
        }
        T *= 1.0 - a;
      }
      if (detail) detail->undrawn_share += T * (std::exp(-a_prev) - std::exp(-area_at(r)));
    } else if (detail) {
      detail->undrawn_share = 1.0 - std::exp(-area_at(r));
    }
    o.area = area_at(r);
    o.left = T;
    if (detail) detail->target_share = T * std::exp(-o.area);
    return o;
  }

 private:
  double node(std::size_t j) const { return r_min_ + static_cast<double>(j) * h_; }

  // The undrawn flakes' expected occlusion per metre at x (drawn from D_t [mm] up):
  // (π/4)·1e−6·∫_0^{D_t} min(D², c²)·N_f dD, c = θx [mm].
  double undrawn_per_m(double x, double dt) const {
    const double c = 1e3 * theta_ * x, n0 = sizes_.n0_flake, l = lam_;
    double v = 2.0 / (l * l * l) * gamma_p3(l * std::min(dt, c));
    if (dt > c) v += c * c * (std::exp(-l * c) - std::exp(-l * dt)) / l;
    return kPi / 4.0 * 1e-6 * n0 * v;
  }

  // L(x): the drawn flakes' expected count over [r_min, x] (λ linear in each step).
  double measure(double x) const {
    const double u = (x - r_min_) / h_;
    if (!(u > 0.0)) return 0.0;
    if (u >= static_cast<double>(cum_.size() - 1)) return cum_.back();
    const std::size_t j = static_cast<std::size_t>(u);
    const double t = x - node(j), g = (lambda_[j + 1] - lambda_[j]) / h_;
    return cum_[j] + lambda_[j] * t + 0.5 * g * t * t;
  }
  // L's inverse for 0 <= s < L(∞): the step j with L_j <= s < L_{j+1}, then λ's
  // linear integral there solved for the offset.
  double range_at(double s) const {
    std::size_t j = bucket_[std::min(bucket_.size() - 1, static_cast<std::size_t>(s * inv_dl_))];
    while (j + 1 < cum_.size() && cum_[j + 1] <= s) ++j;
    if (j + 1 >= cum_.size()) return node(cum_.size() - 1);
    const double ds = s - cum_[j], l0 = lambda_[j], g = (lambda_[j + 1] - lambda_[j]) / h_;
    const double den = l0 + std::sqrt(std::max(0.0, l0 * l0 + 2.0 * g * ds));
    const double t = den > 0.0 ? std::min(2.0 * ds / den, h_) : 0.0;
    return node(j) + t;
  }
  // A(x): the undrawn flakes' expected occlusion over [r_min, x].
  double area_at(double x) const {
    const double u = (x - r_min_) / h_;
    if (!(u > 0.0)) return 0.0;
    const std::size_t last = area_.size() - 1;
    if (u >= static_cast<double>(last)) return area_.back() + sigma1_ * (x - node(last));
    const std::size_t j = static_cast<std::size_t>(u);
    const double t = x - node(j), g = (alpha_[j + 1] - alpha_[j]) / h_;
    return area_[j] + alpha_[j] * t + 0.5 * g * t * t;
  }

  LidarSnowParams p_;
  SnowSizes sizes_;
  bool last_, active_ = false, draws_ = false;
  double theta_ = 0, lam_ = 0, r_min_ = 0, sigma1_ = 0, ct_mm_ = 0, h_ = 0.01, inv_dl_ = 0;
  std::uint64_t key_ = 0;
  std::vector<double> lambda_, cum_, alpha_, area_;
  std::vector<std::uint32_t> bucket_;
};

// The farthest point's range [m] (0 for none).
double farthest(const float* points, std::size_t n) {
  double r2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = points[4 * i], y = points[4 * i + 1], z = points[4 * i + 2];
    r2 = std::max(r2, x * x + y * y + z * z);
  }
  return std::sqrt(r2);
}

class LidarSnow final : public Medium {
 public:
  explicit LidarSnow(const LidarSnowParams& p) : p_(p), sigma1_(snow_sizes(p.flakes).extinction_per_m(1.0)) {}

  // The expected one-way occlusion as a two-way optical depth: e^{−2τ} = e^{−σ(Q=1)·(t − r_min)}.
  double extinction_per_m() const override { return sigma1_ / 2.0; }
  double optical_depth(const MediumRay&, double range_m) const override {
    return sigma1_ / 2.0 * std::max(0.0, range_m - p_.blind_range_m);
  }

  // Each beam drawn once: its target's share as τ = −½·ln(share), its
  // strongest echo kept for scan_echoes on the same points.
  void scan_optical_depths(const float* points, std::size_t n, double* tau) const override {
    run(points, n);
    for (std::size_t i = 0; i < n; ++i) tau[i] = tau_[i];
  }
  void scan_echoes(const float* points, std::size_t n, std::vector<ScanEcho>& out) const override {
    if (points != for_ || n != tau_.size()) run(points, n);
    out.insert(out.end(), echoes_.begin(), echoes_.end());
  }
  nlohmann::json scan_record(const ScanRun& run) const override { return lidar_snow_record(p_, {run, drawn_}); }
  std::size_t drawn() const { return drawn_; }

 private:
  void run(const float* points, std::size_t n) const {
    for_ = points;
    tau_.assign(n, 0.0);
    echoes_.clear();
    const SnowFootprint fp(p_, farthest(points, n));
    if (!fp.active()) return;
    for (std::size_t i = 0; i < n; ++i) {
      const float* q = points + 4 * i;
      const double x = q[0], y = q[1], z = q[2];
      const double r = std::sqrt(x * x + y * y + z * z);
      const BeamOutcome o = fp.beam(q, r);
      drawn_ += o.drawn;
      // τ = −½·ln(share) = ½·(A(r) − ln Π(1 − a)): +inf at share 0.
      if (o.area > 0.0 || o.left < 1.0) tau_[i] = 0.5 * (o.area - (o.left < 1.0 ? std::log(o.left) : 0.0));
      if (o.power >= 0.0) echoes_.push_back({i, o.range, o.power * r * r, o.reported});
    }
  }

  LidarSnowParams p_;
  double sigma1_;
  mutable const float* for_ = nullptr;
  mutable std::vector<double> tau_;
  mutable std::vector<ScanEcho> echoes_;
  mutable std::size_t drawn_ = 0;
};

}  // namespace

std::vector<SnowBeam> lidar_snow_beams(const LidarSnowParams& p, const float* points, std::size_t n) {
  validate_lidar_snow(p);
  const SnowFootprint fp(p, farthest(points, n));
  std::vector<SnowBeam> beams(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = points + 4 * i;
    const double x = q[0], y = q[1], z = q[2];
    fp.beam(q, std::sqrt(x * x + y * y + z * z), &beams[i]);
  }
  return beams;
}

std::unique_ptr<Medium> lidar_snow_as_medium(const LidarSnowParams& p) {
  validate_lidar_snow(p);
  return std::make_unique<LidarSnow>(p);
}

LidarSnowStats lidar_snow(const float* in, float* out, std::size_t n, const LidarSnowParams& p, std::uint8_t* labels,
                          const std::string& what) {
  validate_lidar_snow(p);
  check_scan_points(in, n, what);
  const LidarSnow m(p);
  const ScanDetection detection{p.noise_floor, p.seed};
  LidarSnowStats st;
  st.run = scan_through_media({&m}, in, out, n, what, &detection, labels, scan_return(p.return_mode));
  st.flakes_drawn = m.drawn();
  return st;
}

nlohmann::json lidar_snow_record(const LidarSnowParams& p, const LidarSnowStats& st) {
  const SnowSizes s = snow_sizes(p.flakes);
  const double rate = p.flakes.rate_mm_h.value_or(0.0);
  const auto or_null = [rate](double v) { return rate > 0.0 ? nlohmann::json(v) : nlohmann::json(nullptr); };
  const std::size_t moved = st.run.echoes, lost = st.run.lost;
  return {{"model",
           "exponential melted sizes (" + p.flakes.distribution +
               "), flakes (rho_w/rho_s)^(1/3) larger, N0 from the water flux; per beam the footprint model: flakes "
               "in the cone occlude min((D_f/(theta r))^2, 1) of what nearer ones leave, the strongest echo wins, "
               "speckle detection against the noise floor"},
          {"rate_mm_h", rate},
          {"distribution", p.flakes.distribution},
          {"lambda_melted_per_mm", or_null(s.lambda_melted_per_mm)},
          {"flake_density_g_cm3", p.flakes.flake_density_g_cm3},
          {"flake_scale", s.scale},
          {"lambda_flake_per_mm", or_null(s.lambda_flake_per_mm)},
          {"fall_speed_m_s", p.flakes.fall_speed_m_s},
          {"volume_fraction", s.volume_fraction},
          {"n0_flake_per_m3_mm", s.n0_flake},
          {"n0_melted_per_m3_mm", s.n0_melted},
          {"flakes_per_m3", s.flakes_per_m3},
          {"extinction_per_m", s.extinction_per_m(kLidarSnowQ)},
          {"extinction_q", kLidarSnowQ},
          {"extinction_applied", "none: the flakes' shares are the occlusion over the whole beam"},
          {"divergence_mrad", p.divergence_mrad},
          {"flake_reflectance", p.flake_reflectance},
          {"flake_reflectance_from", "fresh snow's spectral albedo near 905 nm (about 0.9; Warren 1982)"},
          {"noise_floor_per_m2", p.noise_floor},
          {"blind_range_m", p.blind_range_m},
          {"seed", p.seed},
          {"frame", p.frame},
          {"return_mode", p.return_mode},
          {"points", st.run.points},
          {"kept", st.run.points - moved - lost},
          {"moved_to_flakes", moved},
          {"lost", lost},
          {"flakes_drawn", st.flakes_drawn}};
}

}  // namespace brume
