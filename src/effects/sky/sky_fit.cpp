// brume — turbidity from a photographed sky (Morales 2014 ch. 2, eq. 2.1, with
// a fitted scale instead of one reference pixel; the method is stated in
// include/brume/sky.hpp). Levenberg-Marquardt is Eigen's (unsupported module
// NonLinearOptimization, MINPACK's lmdif with a forward-difference Jacobian).
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <unordered_set>

#include <unsupported/Eigen/NonLinearOptimization>
#include <unsupported/Eigen/NumericalDiff>

#include "brume/error.hpp"
#include "core/math_constants.hpp"
#include "brume/sky.hpp"
#include "shared/prelude_cpp.h"

namespace brume {

namespace {

constexpr double kTLo = kSkyTurbidityMin, kTHi = kSkyTurbidityMax;

// A sample ready for the fit: log of the measured luminance and its angles.
struct Point {
  double log_l, theta, gamma;
};

// log of F_Y(theta, gamma)/F_Y(0, theta_s) at T, for every point.
void log_model(double t, double ts, const std::vector<Point>& pts, const std::vector<int>& idx, std::vector<double>& out) {
  const PerezCoefficients k = perez_coefficients(SkyChannel::Y, t);
  const double norm = std::log(perez(k, 0.0, ts));
  out.resize(idx.size());
  for (std::size_t i = 0; i < idx.size(); ++i) {
    const Point& p = pts[idx[i]];
    out[i] = std::log(perez(k, p.theta, p.gamma)) - norm;
  }
}

// Residuals with the closed-form scale: r_i = a_i - mean(a), a_i = log L_i - log m_i(T).
double log_scale_and_residuals(double t, double ts, const std::vector<Point>& pts, const std::vector<int>& idx,
                               std::vector<double>& r) {
  log_model(t, ts, pts, idx, r);
  double mean = 0.0;
  for (std::size_t i = 0; i < idx.size(); ++i) {
    r[i] = pts[idx[i]].log_l - r[i];
    mean += r[i];
  }
  mean /= static_cast<double>(idx.size());
  for (double& v : r) v -= mean;
  return mean;
}

double ssr(double t, double ts, const std::vector<Point>& pts, const std::vector<int>& idx, std::vector<double>& r) {
  log_scale_and_residuals(t, ts, pts, idx, r);
  double s = 0.0;
  for (double v : r) s += v * v;
  return s;
}

// Bounded 1-D search: the best of a 48-point grid over [1.7, 20], then a
// golden-section refinement inside the neighbouring grid cells.
double grid_golden(double ts, const std::vector<Point>& pts, const std::vector<int>& idx, std::vector<double>& r) {
  constexpr int kGrid = 48;
  const double step = (kTHi - kTLo) / (kGrid - 1);
  int best = 0;
  double bs = INFINITY;
  for (int i = 0; i < kGrid; ++i) {
    const double s = ssr(kTLo + i * step, ts, pts, idx, r);
    if (s < bs) bs = s, best = i;
  }
  double a = kTLo + std::max(best - 1, 0) * step, b = kTLo + std::min(best + 1, kGrid - 1) * step;
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  double c = b - g * (b - a), d = a + g * (b - a);
  double fc = ssr(c, ts, pts, idx, r), fd = ssr(d, ts, pts, idx, r);
  for (int it = 0; it < 40 && b - a > 1e-7; ++it) {
    if (fc < fd) b = d, d = c, fd = fc, c = b - g * (b - a), fc = ssr(c, ts, pts, idx, r);
    else a = c, c = d, fc = fd, d = a + g * (b - a), fd = ssr(d, ts, pts, idx, r);
  }
  return 0.5 * (a + b);
}

// Bounded by reparametrisation: T = 1.7 + 18.3 / (1 + e^{-p}).
double t_of_p(double p) { return kTLo + (kTHi - kTLo) / (1.0 + std::exp(-p)); }
double p_of_t(double t) {
  const double f = std::clamp((t - kTLo) / (kTHi - kTLo), 1e-9, 1.0 - 1e-9);
  return std::log(f / (1.0 - f));
}

struct LogResiduals {
  using Scalar = double;
  enum { InputsAtCompileTime = Eigen::Dynamic, ValuesAtCompileTime = Eigen::Dynamic };
  using InputType = Eigen::VectorXd;
  using ValueType = Eigen::VectorXd;
  using JacobianType = Eigen::MatrixXd;
  const std::vector<Point>* pts = nullptr;
  const std::vector<int>* idx = nullptr;
  double ts = 0.0;
  int inputs() const { return 1; }
  int values() const { return static_cast<int>(idx->size()); }
  int operator()(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
    std::vector<double> r;
    log_scale_and_residuals(t_of_p(x[0]), ts, *pts, *idx, r);
    for (std::size_t i = 0; i < r.size(); ++i) f[static_cast<Eigen::Index>(i)] = r[i];
    return 0;
  }
};

double levenberg_marquardt(double t0, double ts, const std::vector<Point>& pts, const std::vector<int>& idx) {
  LogResiduals fn;
  fn.pts = &pts, fn.idx = &idx, fn.ts = ts;
  Eigen::NumericalDiff<LogResiduals> nd(fn);
  Eigen::LevenbergMarquardt<Eigen::NumericalDiff<LogResiduals>> lm(nd);
  lm.parameters.xtol = 1e-12;
  lm.parameters.ftol = 1e-14;
  lm.parameters.maxfev = 400;
  Eigen::VectorXd x(1);
  x[0] = p_of_t(t0);
  lm.minimize(x);
  return t_of_p(x[0]);
}

struct RepeatResult {
  double t = NAN, log_k = NAN, inlier_fraction = 0, residual = NAN;
  std::vector<SkySample> samples;
};

double median_of(std::vector<double> v) {
  const std::size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  return v[m];
}

// One sampling: RANSAC (4-sample hypotheses by the bounded grid search, the
// scale by the median over all samples, inliers |r| < threshold), then
// Levenberg-Marquardt on the consensus set, inliers recomputed once.
RepeatResult fit_once(std::vector<SkySample> s, double ts, const SkyFitOptions& o, std::mt19937_64& rng) {
  std::vector<Point> pts(s.size());
  for (std::size_t i = 0; i < s.size(); ++i) pts[i] = {std::log(s[i].measured), s[i].direction.zenith_deg * kDeg, s[i].model};
  std::vector<int> all(s.size());
  std::iota(all.begin(), all.end(), 0);
  std::vector<double> r, lm_all;
  auto inliers_at = [&](double t, std::vector<int>& in) {
    log_model(t, ts, pts, all, lm_all);
    std::vector<double> a(all.size());
    for (std::size_t i = 0; i < all.size(); ++i) a[i] = pts[i].log_l - lm_all[i];
    const double lk = median_of(a);
    in.clear();
    for (std::size_t i = 0; i < all.size(); ++i)
      if (std::fabs(a[i] - lk) < o.inlier_threshold) in.push_back(static_cast<int>(i));
  };
  const int n = static_cast<int>(s.size());
  const int m = std::min(4, n);
  std::vector<int> best_in, in, pick(m);
  for (int it = 0; it < o.ransac_iterations; ++it) {
    // m distinct indices (Floyd's algorithm would need a set; m is 4).
    for (int j = 0; j < m; ++j) {
      int c;
      do c = static_cast<int>(std::uniform_int_distribution<int>(0, n - 1)(rng));
      while (std::find(pick.begin(), pick.begin() + j, c) != pick.begin() + j);
      pick[j] = c;
    }
    const double th = grid_golden(ts, pts, pick, r);
    inliers_at(th, in);
    if (in.size() > best_in.size()) best_in = in;
    if (best_in.size() == all.size()) break;  // every sample agrees: nothing to reject
  }
  RepeatResult res;
  if (best_in.size() < 2) best_in = all;
  double t = levenberg_marquardt(grid_golden(ts, pts, best_in, r), ts, pts, best_in);
  inliers_at(t, in);
  if (in.size() >= 2 && in != best_in) {
    best_in = in;
    t = levenberg_marquardt(grid_golden(ts, pts, best_in, r), ts, pts, best_in);
  }
  res.t = t;
  res.log_k = log_scale_and_residuals(t, ts, pts, best_in, r);
  double ss = 0.0;
  for (double v : r) ss += v * v;
  res.residual = std::sqrt(ss / static_cast<double>(r.size()));
  res.inlier_fraction = static_cast<double>(best_in.size()) / static_cast<double>(n);
  std::vector<char> is_in(n, 0);
  for (int i : best_in) is_in[i] = 1;
  log_model(t, ts, pts, all, lm_all);
  for (int i = 0; i < n; ++i) {
    s[i].model = std::exp(res.log_k + lm_all[i]);
    s[i].inlier = is_in[i] != 0;
  }
  res.samples = std::move(s);
  return res;
}

void check_options(const SkyFitOptions& o) {
  if (o.samples < 10 || o.samples > 100000)
    throw Error("--samples " + std::to_string(o.samples) + " is not allowed; use 10..100000 (default 100)");
  if (o.repeats < 1 || o.repeats > 100) throw Error("--repeats " + std::to_string(o.repeats) + " is not allowed; use 1..100");
  if (o.ransac_iterations < 1 || o.ransac_iterations > 10000)
    throw Error("--ransac-iterations " + std::to_string(o.ransac_iterations) + " is not allowed; use 1..10000");
  if (!(o.inlier_threshold > 0.0 && o.inlier_threshold <= 2.0))
    throw Error("--inlier-threshold " + std::to_string(o.inlier_threshold) + " is not allowed; use (0, 2]");
}

// Combine the repeats: the median turbidity, its repeat's samples, the spread.
SkyFitResult aggregate(std::vector<RepeatResult> reps, std::size_t candidates) {
  SkyFitResult f;
  f.candidates = candidates;
  std::vector<double> ts;
  for (const auto& r : reps) ts.push_back(r.t);
  f.repeat_turbidities = ts;
  std::vector<std::size_t> order(reps.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return reps[a].t < reps[b].t; });
  const RepeatResult& med = reps[order[order.size() / 2]];
  f.turbidity = med.t;
  f.scale = std::exp(med.log_k);
  f.inlier_fraction = med.inlier_fraction;
  f.residual = med.residual;
  f.samples = med.samples;
  double mean = 0.0;
  for (double t : ts) mean += t;
  mean /= static_cast<double>(ts.size());
  double var = 0.0;
  for (double t : ts) var += (t - mean) * (t - mean);
  f.turbidity_spread = ts.size() > 1 ? std::sqrt(var / static_cast<double>(ts.size() - 1)) : 0.0;
  // Reliability: each reason is a way the number could be confidently wrong.
  if (f.samples.size() < 30) f.reasons.push_back("fewer than 30 usable sky samples");
  if (f.inlier_fraction < 0.5)
    f.reasons.push_back("fewer than half the samples agree with a clear Preetham sky (clouds, overcast, or a wrong sun)");
  if (f.turbidity < kTLo + 0.05 || f.turbidity > kTHi - 0.05)
    f.reasons.push_back("the fit ran into the model's bound [1.7, 20]: the sky is outside what the model describes");
  if (f.turbidity_spread > std::max(0.25, 0.05 * f.turbidity))
    f.reasons.push_back("the turbidity changes between samplings by more than max(0.25, 5 %)");
  f.reliable = f.reasons.empty();
  return f;
}

// The sample's gamma travels in SkySample::model until the fit fills it (an
// internal convention of this file: fit_once reads it as gamma).
SkySample with_gamma(SkySample s, const SkyDirection& sun) {
  s.model = angle_between(s.direction.zenith_deg * kDeg, s.direction.azimuth_deg * kDeg, sun.zenith_deg * kDeg,
                          sun.azimuth_deg * kDeg);
  return s;
}

bool usable_direction(const SkyDirection& d, const SkyDirection& sun, const SkyFitOptions& o) {
  if (!(d.zenith_deg <= o.max_zenith_deg && d.zenith_deg < 90.0)) return false;
  const double g = angle_between(d.zenith_deg * kDeg, d.azimuth_deg * kDeg, sun.zenith_deg * kDeg, sun.azimuth_deg * kDeg);
  return g >= o.sun_exclusion_deg * kDeg;
}

void check_sun(const SkyDirection& sun) {
  if (!(sun.zenith_deg >= 0.0 && sun.zenith_deg < 90.0))
    throw Error("the sun's zenith angle " + std::to_string(sun.zenith_deg) +
                " deg is not above the horizon; the Preetham model has no twilight: fit a daytime sky");
}

}  // namespace

SkyFitResult fit_turbidity(const std::vector<SkySample>& candidates, const SkyDirection& sun, const SkyFitOptions& o) {
  check_options(o);
  check_sun(sun);
  std::vector<SkySample> usable;
  for (const SkySample& s : candidates)
    if (std::isfinite(s.measured) && s.measured > 0.0 && usable_direction(s.direction, sun, o))
      usable.push_back(with_gamma(s, sun));
  if (usable.size() < 10)
    throw Error("only " + std::to_string(usable.size()) +
                " usable sky samples (above the horizon, within --max-zenith, outside --sun-exclusion of the sun, "
                "positive luminance); at least 10 are needed");
  const double ts = sun.zenith_deg * kDeg;
  std::vector<RepeatResult> reps;
  for (int rep = 0; rep < o.repeats; ++rep) {
    std::mt19937_64 rng(o.seed * 0x9E3779B97F4A7C15ull + static_cast<std::uint64_t>(rep));
    std::vector<SkySample> drawn;
    if (usable.size() <= static_cast<std::size_t>(o.samples)) {
      drawn = usable;
    } else {
      std::vector<std::size_t> ix(usable.size());
      std::iota(ix.begin(), ix.end(), 0);
      for (int i = 0; i < o.samples; ++i) {
        const std::size_t j = i + std::uniform_int_distribution<std::size_t>(0, ix.size() - 1 - i)(rng);
        std::swap(ix[i], ix[j]);
        drawn.push_back(usable[ix[i]]);
      }
    }
    reps.push_back(fit_once(std::move(drawn), ts, o, rng));
  }
  return aggregate(std::move(reps), usable.size());
}

SkyFitResult fit_sky_image(DenseImageRef rgb, bool integer_image, const SkyGeometry& g, const SkyDirection& sun,
                           const Image* mask, const SkyFitOptions& o) {
  check_options(o);
  check_sun(sun);
  if (rgb.width != g.width || rgb.height != g.height)
    throw Error("internal: sky geometry " + std::to_string(g.width) + "x" + std::to_string(g.height) +
                " does not match the image " + rgb.size_string());
  if (mask && (mask->width != rgb.width || mask->height != rgb.height))
    throw Error("--mask " + mask->size_string() + " does not match the image " + rgb.size_string() +
                "; give a mask of the image's size");
  const double ts = sun.zenith_deg * kDeg;
  const std::size_t total = rgb.pixels();
  auto sample_at = [&](std::size_t i, SkySample& s) {
    const int x = static_cast<int>(i % rgb.width), y = static_cast<int>(i / rgb.width);
    if (mask && !(mask->at(x, y) > 0.5f)) return false;
    const float r = rgb.at(x, y, 0), gg = rgb.at(x, y, 1), b = rgb.at(x, y, 2);
    if (integer_image && std::max({r, gg, b}) >= 0.955f) return false;  // saturated: not a measurement
    const double l = shared::brume_srgb_to_y(r, gg, b);
    if (!(std::isfinite(l) && l > 0.0)) return false;
    const std::optional<SkyDirection> d = direction_of_pixel(g, x, y);
    if (!d || !usable_direction(*d, sun, o)) return false;
    s.direction = *d, s.u = x, s.v = y, s.measured = l;
    s = with_gamma(s, sun);
    return true;
  };
  // Pixels are drawn at random and tested (a full scan costs more than the
  // fit: 10-20 ms on 0.5 Mpx); when 50 N draws do not give N usable pixels,
  // the image is scanned once and sampled from the list.
  std::vector<SkySample> scanned;
  bool did_scan = false;
  std::size_t tried = 0, accepted = 0;
  std::vector<RepeatResult> reps;
  for (int rep = 0; rep < o.repeats; ++rep) {
    std::mt19937_64 rng(o.seed * 0x9E3779B97F4A7C15ull + static_cast<std::uint64_t>(rep));
    std::vector<SkySample> drawn;
    if (!did_scan) {
      std::unordered_set<std::size_t> seen;
      const std::size_t cap = std::min<std::size_t>(50 * static_cast<std::size_t>(o.samples), total);
      while (drawn.size() < static_cast<std::size_t>(o.samples) && seen.size() < cap) {
        const std::size_t i = std::uniform_int_distribution<std::size_t>(0, total - 1)(rng);
        if (!seen.insert(i).second) continue;
        SkySample s;
        ++tried;
        if (sample_at(i, s)) drawn.push_back(s), ++accepted;
      }
      if (drawn.size() < static_cast<std::size_t>(o.samples)) {
        for (std::size_t i = 0; i < total; ++i) {
          SkySample s;
          if (sample_at(i, s)) scanned.push_back(s);
        }
        did_scan = true;
      }
    }
    if (did_scan) {
      if (scanned.size() < 10)
        throw Error("the image has " + std::to_string(scanned.size()) +
                    " usable sky pixels (above the horizon, within --max-zenith, outside --sun-exclusion, inside "
                    "--mask, not saturated, positive); at least 10 are needed: check --projection, "
                    "--azimuth-offset, the sun and the mask");
      drawn.clear();
      std::vector<std::size_t> ix(scanned.size());
      std::iota(ix.begin(), ix.end(), 0);
      const std::size_t nd = std::min<std::size_t>(scanned.size(), static_cast<std::size_t>(o.samples));
      for (std::size_t i = 0; i < nd; ++i) {
        const std::size_t j = i + std::uniform_int_distribution<std::size_t>(0, ix.size() - 1 - i)(rng);
        std::swap(ix[i], ix[j]);
        drawn.push_back(scanned[ix[i]]);
      }
    }
    reps.push_back(fit_once(std::move(drawn), ts, o, rng));
  }
  const std::size_t candidates =
      did_scan ? scanned.size()
               : static_cast<std::size_t>(static_cast<double>(accepted) / static_cast<double>(tried) * total);
  return aggregate(std::move(reps), candidates);
}

nlohmann::json sky_fit_json(const SkyFitResult& r, const SunFound& sun) {
  nlohmann::json j;
  j["turbidity"] = r.turbidity;
  j["turbidity_spread"] = r.turbidity_spread;
  nlohmann::json s = {{"zenith_deg", sun.direction.zenith_deg},
                      {"azimuth_deg", sun.direction.azimuth_deg},
                      {"source", sun.source}};
  if (!sun.record.is_null())
    for (auto it = sun.record.begin(); it != sun.record.end(); ++it) s[it.key()] = it.value();
  j["sun"] = s;
  j["inlier_fraction"] = r.inlier_fraction;
  j["residual"] = r.residual;
  j["reliable"] = r.reliable;
  j["unreliable_because"] = r.reasons;
  j["scale"] = r.scale;
  j["repeat_turbidities"] = r.repeat_turbidities;
  j["usable_sky_pixels"] = r.candidates;
  j["residual_definition"] = "RMS of log(measured) - log(scale * model) over the inliers";
  nlohmann::json arr = nlohmann::json::array();
  for (const SkySample& q : r.samples)
    arr.push_back({{"zenith_deg", q.direction.zenith_deg},
                   {"azimuth_deg", q.direction.azimuth_deg},
                   {"pixel", {q.u, q.v}},
                   {"measured", q.measured},
                   {"model", q.model},
                   {"inlier", q.inlier}});
  j["samples"] = arr;
  return j;
}

}  // namespace brume
