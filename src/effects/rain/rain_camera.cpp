// brume — rain on a camera's image: the LiDAR's drop field seen through a pinhole camera over an
// exposure, its streaks (Garg & Nayar) depth-tested against the scene, and the rain it does not
// draw as an analytic medium (brume/rain.hpp states the equations; docs/rain.md, "The camera").
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <vector>

#include "brume/error.hpp"
#include "brume/rain.hpp"
#include "core/text.hpp"

namespace brume {

namespace {
constexpr double kCamPi = 3.14159265358979323846;
constexpr double kCamInf = std::numeric_limits<double>::infinity();
constexpr double kRefracted = 0.94, kReflected = 0.06;  // Garg & Nayar's split of a drop's radiance
}  // namespace

double camera_rain_extinction_per_m(double rate_mm_h, double q_eff) {
  return q_eff / 2.0 * rain_extinction_per_m(rate_mm_h, kLidarRainQ);
}

double rain_d2_between(double rate_mm_h, double a_mm, double b_mm) {
  if (rate_mm_h == 0.0 || !(b_mm > a_mm)) return 0.0;
  const double l = marshall_palmer_lambda_per_mm(rate_mm_h);
  // ∫_x^∞ D²e^{−ΛD} dD = e^{−Λx}(x²/Λ + 2x/Λ² + 2/Λ³).
  const auto g = [l](double x) {
    return std::isinf(x) ? 0.0 : std::exp(-l * x) * (x * x / l + 2.0 * x / (l * l) + 2.0 / (l * l * l));
  };
  return kMarshallPalmerN0 * (g(a_mm) - g(b_mm));
}

// ---- the parameters ----------------------------------------------------------------------

const ParamTable<CameraRainParams>& camera_rain_param_table() {
  static const ParamTable<CameraRainParams> t = [] {
    using P = CameraRainParams;
    ParamTable<P> d("rain");
    d.nest(&P::drops, rain_drops_param_table())
        .real("exposure-time", &P::exposure_s, "s", Range::left_open(0.0, 10.0),
              "exposure T: a drop's streak is its image's path over T")
        .count("rain-seed", &P::seed, "1", Range::at_least(0.0), "seed of the drop field (same seed, same drops)")
        .text("wind", &P::wind,
              "wind X,Y,Z in m/s in the vehicle frame (x forward, y left, z up; the camera level, looking along +x)")
        .real("ego-speed", &P::ego_speed_m_s, "m/s", Range::closed(-100.0, 100.0),
              "the camera's speed along its forward axis: the drops move back past it")
        .real("f-number", &P::f_number, "1", Range::above(0.0),
              "f-number n of the lens (with the camera's --focal-length and --sensor-width, as dof takes them): "
              "streaks widen to the thin lens's circle of confusion; none: a pinhole",
              "none")
        .real("focus-distance", &P::focus_distance_m, "m", Range::above(0.0),
              "planar depth of the plane in focus (with --f-number)", "none")
        .real("q-eff", &P::q_eff, "1", Range::closed(1.0, 2.0),
              "the camera's extinction efficiency Q_eff: sigma_cam = Q_eff/2 sigma_lidar (default fitted to the "
              "international visibility code's rain rows, docs/rain.md)")
        .real("z-split", &P::z_split_m, "m", Range::left_open(0.0, 1000.0),
              "drops are drawn up to this planar depth; beyond it the rain is an analytic medium")
        .real("z-near", &P::z_near_m, "m", Range::above(0.0),
              "drops are drawn from this planar depth (nearer ones are analytic)")
        .real("epsilon", &P::epsilon, "1", Range::closed(0.0, 1.0),
              "thinning: a drop whose estimated coverage of a pixel is below epsilon is not drawn (its extinction "
              "is analytic); 0 draws every drop")
        .real("visibility", &P::visibility_m, "m", Range::above(0.0),
              "haze's meteorological visibility (extinction 3.912/V, Koschmieder) composed with the rain in haze's "
              "composite; none: rain is the only medium",
              "none")
        .rgb("airlight", &P::airlight, "linear RGB", Range::at_least(0.0),
             "colour of the medium; auto: haze's estimate (the median sky colour, else a grey at the 99th "
             "percentile of luminance)");
    return d;
  }();
  return t;
}

Vec3 camera_rain_wind(const CameraRainParams& p) {
  std::stringstream ss(p.wind);
  std::string item;
  double v[3] = {0.0, 0.0, 0.0};
  int n = 0;
  while (std::getline(ss, item, ',')) {
    if (n < 3) {
      char* end = nullptr;
      v[n] = std::strtod(item.c_str(), &end);
      if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(v[n]) || std::abs(v[n]) > 100.0)
        throw Error("--wind '" + p.wind + "': '" + item +
                    "' is not a finite number of m/s in [-100, 100]; give X,Y,Z, e.g. 0,3,0 (3 m/s to the left)");
    }
    ++n;
  }
  if (n != 3)
    throw Error("--wind '" + p.wind + "' has " + std::to_string(n) +
                " components; give X,Y,Z in m/s (vehicle frame: x forward, y left, z up), e.g. 0,3,0");
  return {v[0], v[1], v[2]};
}

void validate_camera_rain(const CameraRainParams& p) {
  camera_rain_param_table().validate(p);
  validate_rain_drops(p.drops);
  if (!(p.z_split_m > p.z_near_m))
    throw Error("--z-split " + text::g(p.z_split_m) + " m must exceed --z-near " + text::g(p.z_near_m) +
                " m (drops are drawn between them); give a larger --z-split");
  if (p.f_number.has_value() != p.focus_distance_m.has_value())
    throw Error(std::string("the lens's blur needs both --f-number and --focus-distance; ") +
                (p.f_number ? "give --focus-distance M" : "give --f-number N") + ", or neither (a pinhole)");
  (void)camera_rain_wind(p);
}

// ---- the thinning rule and the analytic optical depth ------------------------------------------

CameraRainOptics::CameraRainOptics(const CameraRainParams& p, const Intrinsics& k, double coc_infinity_px)
    : p_(p),
      fx_(k.fx),
      alpha_(coc_infinity_px),
      zf_(p.focus_distance_m.value_or(0.0)),
      sigma_cam_(camera_rain_extinction_per_m(p.drops.rate_mm_h.value_or(0.0), p.q_eff)) {
  const int n = kRainThinningSteps;
  const double rate = p.drops.rate_mm_h.value_or(0.0);
  dz_ = p.z_split_m / n;
  dt_.assign(n + 1, kCamInf);
  g_.assign(n + 1, 0.0);
  sd_.assign(n + 1, 0.0);
  double run = p.drops.drop_min_mm;  // D_t made non-decreasing in z
  for (int i = 1; i <= n; ++i) {
    const double z = i * dz_;
    if (rate == 0.0 || z < p.z_near_m) continue;
    double dt = kCamInf;
    if (p.epsilon <= 0.0 || estimate(p.drops.drop_min_mm, z) >= p.epsilon) {
      dt = p.drops.drop_min_mm;
    } else if (estimate(p.drops.drop_max_mm, z) >= p.epsilon) {
      double lo = p.drops.drop_min_mm, hi = p.drops.drop_max_mm;  // estimate(lo) < ε <= estimate(hi)
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        (estimate(mid, z) >= p.epsilon ? hi : lo) = mid;
      }
      dt = hi;
    }
    run = std::max(run, dt);
    dt_[i] = run;
  }
  // G at the nodes: σ_d is constant on ((i−1)dz, i·dz] (threshold_mm takes node i there), drawn from z_near.
  for (int i = 1; i <= n; ++i) {
    const double a = std::max((i - 1) * dz_, p.z_near_m), b = i * dz_;
    const double len = std::max(0.0, b - a);
    sd_[i] = std::isinf(dt_[i]) ? 0.0 : kCamPi / 4.0 * 1e-6 * rain_d2_between(rate, dt_[i], p.drops.drop_max_mm);
    g_[i] = g_[i - 1] + sd_[i] * len;
  }
}

double CameraRainOptics::estimate(double d_mm, double z) const {
  const double d = fx_ * d_mm * 1e-3 / z;  // the drop's image diameter [px]
  const double b = alpha_ > 0.0 ? alpha_ * std::abs(z - zf_) / z : 0.0;
  const double w = std::sqrt(d * d + b * b);
  const double len = fx_ * atlas_terminal_velocity_m_per_s(d_mm) * p_.exposure_s / z;
  return kCamPi / 4.0 * d * d / (std::max(1.0, w) * std::max(1.0, len));
}

double CameraRainOptics::threshold_mm(double z) const {
  if (!(z >= p_.z_near_m) || !(z < p_.z_split_m)) return kCamInf;
  const int i = std::min(kRainThinningSteps, std::max(1, static_cast<int>(std::ceil(z / dz_))));
  return dt_[i];
}

double CameraRainOptics::tau(double r, double cos_theta) const {
  const double z = std::min(r * cos_theta, p_.z_split_m);
  double g = 0.0;
  if (z > 0.0) {
    const int i = std::min(kRainThinningSteps, std::max(1, static_cast<int>(std::ceil(z / dz_))));
    const double a = std::max((i - 1) * dz_, p_.z_near_m);
    g = g_[i - 1] + sd_[i] * std::max(0.0, z - a);
  }
  return std::max(0.0, sigma_cam_ * r - g / cos_theta);
}

// ---- the streaks ---------------------------------------------------------------------------------

namespace {

struct RainStreak {
  double c[3];       // cv position at mid-exposure [m]
  double u[3];       // cv velocity [m/s]
  double area;       // [px² m²] (π/4)·D²·fx·fy: its image area at (r, z) is area·r/z³
  double sigma_px;   // the splat kernel's σ
  double range;      // [m] at mid-exposure
  float e[3];        // E′, linear RGB
  double t0, t1;     // [s] the part of the exposure it is drawn over (z >= z_near/2)
  int v_lo, v_hi;    // rows it can touch
  int u_lo, u_hi;    // and columns
  std::size_t order; // enumeration index (ties)
};

// An image's box mean over (2h+1)² about a pixel (clamped), per channel, by a summed-area table.
class RainBoxMean {
 public:
  RainBoxMean(ConstImageView rgb, int h) : w_(rgb.width()), h_(rgb.height()), r_(h), s_((w_ + 1) * (h_ + 1) * 3, 0.0) {
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x)
        for (int c = 0; c < 3; ++c)
          at(x + 1, y + 1, c) = rgb.at(x, y, c) + at(x, y + 1, c) + at(x + 1, y, c) - at(x, y, c);
  }
  double mean(int x, int y, int c) const {
    const int x0 = std::max(0, x - r_), x1 = std::min(w_, x + r_ + 1), y0 = std::max(0, y - r_),
              y1 = std::min(h_, y + r_ + 1);
    const double s = get(x1, y1, c) - get(x0, y1, c) - get(x1, y0, c) + get(x0, y0, c);
    return s / (static_cast<double>(x1 - x0) * (y1 - y0));
  }
  double total(int c) const { return get(w_, h_, c) / (static_cast<double>(w_) * h_); }

 private:
  double& at(int x, int y, int c) { return s_[(static_cast<std::size_t>(y) * (w_ + 1) + x) * 3 + c]; }
  double get(int x, int y, int c) const { return s_[(static_cast<std::size_t>(y) * (w_ + 1) + x) * 3 + c]; }
  int w_, h_, r_;
  std::vector<double> s_;
};

bool cam_known(float r) { return std::isfinite(r) && r > 0.0f; }

}  // namespace

Image render_camera_rain(const CameraRainScene& s, const CameraRainParams& p, const Exec& exec,
                         CameraRainStats* stats, Image* transmission) {
  validate_camera_rain(p);
  const int W = s.rgb.width(), H = s.rgb.height();
  if (s.rgb.channels() != 3) throw Error("rain needs an RGB image, got " + std::to_string(s.rgb.channels()) + " channels");
  if (s.range.channels() != 1 || s.range.width() != W || s.range.height() != H)
    throw Error("the range map " + s.range.size_string() + " does not match the image " + s.rgb.size_string() +
                "; they must be the same size");
  if (!s.sky_weight.empty() && (s.sky_weight.width() != W || s.sky_weight.height() != H))
    throw Error("internal: the sky weight is " + s.sky_weight.size_string() + ", the image " + s.rgb.size_string());
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const double rate = *p.drops.rate_mm_h, T = p.exposure_s;
  const double fx = s.k.fx, fy = s.k.fy, cx = s.k.cx, cy = s.k.cy;
  const CameraRainOptics optics(p, s.k, s.coc_infinity_px);
  CameraRainStats st;
  st.sigma_lidar = rain_extinction_per_m(rate, kLidarRainQ);
  st.sigma_cam = optics.sigma_cam();
  const double sigma_total = st.sigma_cam + s.haze_sigma_per_m;
  const auto ray_cos = [&](double u, double v) {
    const double x = (u - cx) / fx, y = (v - cy) / fy;
    return 1.0 / std::sqrt(x * x + y * y + 1.0);
  };
  const auto front_tau = [&](double r, double cos_theta) {
    return s.analytic ? s.haze_sigma_per_m * r + optics.tau(r, cos_theta) : 0.0;
  };

  // 1. The scene through the analytic media (haze's composite, or the pipeline's).
  Image tau0(W, H, 1);
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = s.range.at(x, y);
      float t = 1.0f;
      if (s.analytic) {
        // Unknown range (the sky) lies beyond the unbounded media: transmission 0 when there are any.
        t = cam_known(r) ? static_cast<float>(std::exp(-front_tau(r, ray_cos(x, y)))) : (sigma_total > 0.0 ? 0.0f : 1.0f);
        if (!s.sky_weight.empty()) {
          const float w = s.sky_weight.at(x, y);
          const float t_sky = sigma_total > 0.0 ? 0.0f : 1.0f;
          t = w <= 0.0f ? t : w >= 1.0f ? t_sky : (1.0f - w) * t + w * t_sky;
        }
      }
      tau0.data[static_cast<std::size_t>(y) * W + x] = t;
    }
  Image out;
  if (s.composite) {
    out = s.composite(tau0);
  } else {
    out = Image(W, H, 3);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        const float t = tau0.data[i];
        for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = t * s.rgb.at(x, y, c) + (1.0f - t) * s.airlight[c];
      }
  }
  if (transmission) *transmission = tau0;

  // 2. The drops of the field in the frustum, z_near <= z < z_split at mid-exposure.
  const RainField field(rate, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  const Vec3 wind = camera_rain_wind(p);
  const double s_ego = p.ego_speed_m_s;
  const double v_max = atlas_terminal_velocity_m_per_s(p.drops.drop_max_mm);
  const double speed_max = std::sqrt(wind.x * wind.x + wind.y * wind.y + wind.z * wind.z) + std::abs(s_ego) + v_max;
  const double margin_m = speed_max * T / 2.0 + 0.01;
  const double xa = (-0.5 - cx) / fx, xb = (W - 0.5 - cx) / fx, ya = (-0.5 - cy) / fy, yb = (H - 0.5 - cy) / fy;
  const double c = kRainCellM;
  const std::int64_t ix0 = static_cast<std::int64_t>(std::floor(p.z_near_m / c));
  const std::int64_t ix1 = static_cast<std::int64_t>(std::floor(p.z_split_m / c));
  const std::size_t slabs = static_cast<std::size_t>(ix1 - ix0 + 1);
  std::vector<std::vector<RainStreak>> found(slabs);
  std::vector<std::size_t> seen(slabs, 0), cells(slabs, 0);
  const RainBoxMean env(s.rgb, std::max(1, H / 4));
  double env_total[3];
  for (int k = 0; k < 3; ++k) env_total[k] = env.total(k);
  const double alpha = s.coc_infinity_px, zf = p.focus_distance_m.value_or(0.0);
  const auto blur_px = [&](double z) { return alpha > 0.0 ? alpha * std::abs(z - zf) / z : 0.0; };
  const double z_clip = 0.5 * p.z_near_m;

#pragma omp parallel for num_threads(nt) schedule(dynamic, 4)
  for (std::int64_t ix = ix0; ix <= ix1; ++ix) {
    const std::size_t si = static_cast<std::size_t>(ix - ix0);
    const double z0 = std::max(static_cast<double>(ix) * c, p.z_near_m), z1 = static_cast<double>(ix + 1) * c;
    if (!(z0 < p.z_split_m)) continue;
    const double m = field.measure_above(optics.threshold_mm(z0));
    if (!(m > 0.0)) continue;
    // The slab's lateral extent: the frustum widened by the drops' motion and their kernel.
    const double kpx = 3.0 * std::sqrt(std::pow(blur_px(z0) / 4.0, 2) + std::pow(blur_px(z1) / 4.0, 2) +
                                       std::pow(fx * p.drops.drop_max_mm * 1e-3 / z0 / 4.0, 2)) +
                       2.0;
    const double grow = margin_m + kpx * z1 / std::min(fx, fy);
    const double xlo = std::min(xa * z0, xa * z1) - grow, xhi = std::max(xb * z0, xb * z1) + grow;
    const double ylo = std::min(ya * z0, ya * z1) - grow, yhi = std::max(yb * z0, yb * z1) + grow;
    // Vehicle frame: y = −x_cv, z = −y_cv.
    const std::int64_t jy0 = static_cast<std::int64_t>(std::floor(-xhi / c)),
                       jy1 = static_cast<std::int64_t>(std::floor(-xlo / c));
    const std::int64_t jz0 = static_cast<std::int64_t>(std::floor(-yhi / c)),
                       jz1 = static_cast<std::int64_t>(std::floor(-ylo / c));
    std::vector<RainStreak>& list = found[si];
    for (std::int64_t jy = jy0; jy <= jy1; ++jy)
      for (std::int64_t jz = jz0; jz <= jz1; ++jz) {
        ++cells[si];
        field.for_each_drop_within(RainCell{ix, jy, jz}, m, [&](const Vec3& at, double sm) {
          ++seen[si];
          const double z = at.x;
          const double d_mm = field.diameter_mm(sm);
          if (d_mm < optics.threshold_mm(z)) return;
          const double v = atlas_terminal_velocity_m_per_s(d_mm);
          RainStreak k;
          k.c[0] = -at.y, k.c[1] = -at.z, k.c[2] = at.x;
          k.u[0] = -wind.y, k.u[1] = v - wind.z, k.u[2] = wind.x - s_ego;
          // The part of the exposure in front of the camera (z >= z_near/2).
          k.t0 = -T / 2.0, k.t1 = T / 2.0;
          if (k.u[2] != 0.0) {
            const double tc = (z_clip - k.c[2]) / k.u[2];  // z(tc) = z_clip
            if (k.u[2] < 0.0) k.t1 = std::min(k.t1, tc);
            else k.t0 = std::max(k.t0, tc);
          }
          if (!(k.t1 > k.t0)) return;
          const double r = std::sqrt(k.c[0] * k.c[0] + k.c[1] * k.c[1] + z * z);
          const double dm = d_mm * 1e-3;
          k.area = kCamPi / 4.0 * dm * dm * fx * fy;
          const double dpx = fx * dm / z, b = blur_px(z);
          k.sigma_px = std::sqrt(dpx * dpx + b * b) / 4.0;
          k.range = r;
          // Its rows over the exposure (a straight path: the ends bound it), widened by the kernel.
          double vmin = kCamInf, vmax = -kCamInf, umin = kCamInf, umax = -kCamInf;
          for (double t : {k.t0, k.t1}) {
            const double zz = k.c[2] + k.u[2] * t;
            const double uu = fx * (k.c[0] + k.u[0] * t) / zz + cx, vv = fy * (k.c[1] + k.u[1] * t) / zz + cy;
            vmin = std::min(vmin, vv), vmax = std::max(vmax, vv), umin = std::min(umin, uu), umax = std::max(umax, uu);
          }
          const double kr = 3.0 * k.sigma_px + 1.0;
          if (umax + kr < -0.5 || umin - kr > W - 0.5 || vmax + kr < -0.5 || vmin - kr > H - 0.5) return;
          k.v_lo = static_cast<int>(std::max(0.0, std::floor(vmin - kr)));
          k.v_hi = static_cast<int>(std::min(H - 1.0, std::ceil(vmax + kr)));
          k.u_lo = static_cast<int>(std::max(0.0, std::floor(umin - kr)));
          k.u_hi = static_cast<int>(std::min(W - 1.0, std::ceil(umax + kr)));
          // E: what the drop refracts (the image about it) and reflects (the image's mean),
          // seen through the analytic media in front of it.
          const double um = fx * k.c[0] / z + cx, vm = fy * k.c[1] / z + cy;
          const int ui = std::min(W - 1, std::max(0, static_cast<int>(std::lround(um))));
          const int vi = std::min(H - 1, std::max(0, static_cast<int>(std::lround(vm))));
          const double tf = std::exp(-front_tau(r, z / r));
          for (int q = 0; q < 3; ++q) {
            const double e = s.drop_radiance ? (*s.drop_radiance)[q]
                                             : kRefracted * env.mean(ui, vi, q) + kReflected * env_total[q];
            k.e[q] = static_cast<float>(tf * e + (1.0 - tf) * s.airlight[q]);
          }
          k.order = list.size();
          list.push_back(k);
        });
      }
  }
  std::vector<RainStreak> drops;
  for (std::size_t i = 0; i < slabs; ++i) {
    st.cells += cells[i];
    st.drops_seen += seen[i];
    for (RainStreak& k : found[i]) {
      k.order = drops.size();
      drops.push_back(k);
    }
  }
  // Far to near (ties: the enumeration's order).
  std::sort(drops.begin(), drops.end(), [](const RainStreak& a, const RainStreak& b) {
    return a.range != b.range ? a.range > b.range : a.order < b.order;
  });
  st.drops_drawn = drops.size();

  // 3. The streaks, composited far to near, tile by tile: a tile's pixels stay in cache while
  // the drops that can touch it (listed in the drops' order) are splatted, each pixel taking the
  // same updates in the same order as a single pass over the drops would give it (the same image
  // on any number of threads). A drop's rows and columns (v_lo..v_hi, u_lo..u_hi) bound every
  // pixel its samples touch; its tiles are taken one pixel wider.
  constexpr int kTileW = 128, kTileH = 32;
  const int tiles_x = (W + kTileW - 1) / kTileW, tiles_y = (H + kTileH - 1) / kTileH;
  std::vector<std::vector<std::uint32_t>> in_tile(static_cast<std::size_t>(tiles_x) * tiles_y);
  for (std::size_t d = 0; d < drops.size(); ++d) {
    const RainStreak& k = drops[d];
    const int ty0 = std::max(0, k.v_lo - 1) / kTileH, ty1 = std::min(H - 1, k.v_hi + 1) / kTileH;
    const int tx0 = std::max(0, k.u_lo - 1) / kTileW, tx1 = std::min(W - 1, k.u_hi + 1) / kTileW;
    for (int ty = ty0; ty <= ty1; ++ty)
      for (int tx = tx0; tx <= tx1; ++tx)
        in_tile[static_cast<std::size_t>(ty) * tiles_x + tx].push_back(static_cast<std::uint32_t>(d));
  }
  std::vector<std::size_t> clamped(static_cast<std::size_t>(nt), 0);
#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    std::vector<double> wx, wy;
#pragma omp for schedule(dynamic, 1)
    for (int tile = 0; tile < tiles_x * tiles_y; ++tile) {
    const int y_lo = tile / tiles_x * kTileH, y_hi = std::min(H, y_lo + kTileH);
    const int x_lo = tile % tiles_x * kTileW, x_hi = std::min(W, x_lo + kTileW);
    for (const std::uint32_t d : in_tile[static_cast<std::size_t>(tile)]) {
      const RainStreak& k = drops[d];
      double pz = 0.0;
      const auto at = [&](double t, double& u, double& v, double& r) {
        const double px = k.c[0] + k.u[0] * t, py = k.c[1] + k.u[1] * t;
        pz = k.c[2] + k.u[2] * t;
        u = fx * px / pz + cx, v = fy * py / pz + cy, r = std::sqrt(px * px + py * py + pz * pz);
      };
      double ua, va, ub, vb, rr;
      at(k.t0, ua, va, rr);
      at(k.t1, ub, vb, rr);
      const double len = std::hypot(ub - ua, vb - va);
      const double h = std::max(0.5, 0.5 * k.sigma_px);
      const int n = std::min(1 << 16, static_cast<int>(std::ceil(len / h)) + 1);
      const bool gauss = k.sigma_px >= 0.5;
      const int rad = gauss ? static_cast<int>(std::ceil(3.0 * k.sigma_px)) : 0;
      for (int i = 0; i < n; ++i) {
        const double t = k.t0 + (k.t1 - k.t0) * (i + 0.5) / n;
        double u, v, r;
        at(t, u, v, r);
        // The coverage over the exposure is the time average of the drop's image area there.
        const double a_sample = k.area * r / (pz * pz * pz) / n;
        const double inv_soft = 1.0 / (kRainDepthSoftness * r);
        const auto put = [&](int x, int y, double w) {
          if (x < x_lo || x >= x_hi || y < y_lo || y >= y_hi || !(w > 0.0)) return;
          const float rs = s.range.at(x, y);
          double vis = 1.0;
          if (cam_known(rs)) vis = std::min(1.0, std::max(0.0, (rs - r) * inv_soft));
          double a = w * a_sample * vis;
          if (!(a > 0.0)) return;
          if (a > 1.0) a = 1.0, ++clamped[static_cast<std::size_t>(tid)];
          float* o = &out.data[(static_cast<std::size_t>(y) * W + x) * 3];
          for (int q = 0; q < 3; ++q) o[q] += static_cast<float>(a) * (k.e[q] - o[q]);
        };
        if (!gauss) {
          const double fu = std::floor(u), fv = std::floor(v);
          const int x0 = static_cast<int>(fu), y0 = static_cast<int>(fv);
          if (x0 + 1 < x_lo || x0 >= x_hi || y0 + 1 < y_lo || y0 >= y_hi) continue;  // no tap in the tile
          const double ax = u - fu, ay = v - fv;
          put(x0, y0, (1 - ax) * (1 - ay));
          put(x0 + 1, y0, ax * (1 - ay));
          put(x0, y0 + 1, (1 - ax) * ay);
          put(x0 + 1, y0 + 1, ax * ay);
        } else {
          const int xc = static_cast<int>(std::lround(u)), yc = static_cast<int>(std::lround(v));
          if (yc + rad < y_lo || yc - rad >= y_hi || xc + rad < x_lo || xc - rad >= x_hi) continue;
          wx.assign(2 * rad + 1, 0.0), wy.assign(2 * rad + 1, 0.0);
          double sx = 0.0, sy = 0.0;
          const double inv = 1.0 / (2.0 * k.sigma_px * k.sigma_px);
          for (int j = -rad; j <= rad; ++j) {
            sx += wx[j + rad] = std::exp(-std::pow(xc + j - u, 2) * inv);
            sy += wy[j + rad] = std::exp(-std::pow(yc + j - v, 2) * inv);
          }
          for (int jy = -rad; jy <= rad; ++jy) {
            const int y = yc + jy;
            if (y < y_lo || y >= y_hi) continue;
            for (int jx = -rad; jx <= rad; ++jx) put(xc + jx, y, wx[jx + rad] * wy[jy + rad] / (sx * sy));
          }
        }
      }
    }
    }
  }
  for (std::size_t i = 0; i < clamped.size(); ++i) st.alpha_clamped += clamped[i];
  double total_len = 0.0;
  for (const RainStreak& k : drops) {
    double e[2][2];
    for (int j = 0; j < 2; ++j) {
      const double t = j ? k.t1 : k.t0, pz = k.c[2] + k.u[2] * t;
      e[j][0] = fx * (k.c[0] + k.u[0] * t) / pz, e[j][1] = fy * (k.c[1] + k.u[1] * t) / pz;
    }
    total_len += std::hypot(e[1][0] - e[0][0], e[1][1] - e[0][1]);
  }
  st.mean_streak_px = drops.empty() ? 0.0 : total_len / static_cast<double>(drops.size());
  if (stats) *stats = st;
  return out;
}

nlohmann::json camera_rain_record(const CameraRainParams& p, const CameraRainStats& st) {
  const double r = p.drops.rate_mm_h.value_or(0.0);
  const Vec3 w = camera_rain_wind(p);
  return {{"model",
           "Marshall-Palmer 1948 drop sizes, Atlas et al. 1973 fall speed; the drop field of `brume lidar rain` "
           "advected over the exposure and drawn as streaks (Garg & Nayar 2007's photometry: coverage by dwell "
           "time), depth-tested against the scene; the rest of the rain analytic"},
          {"rate_mm_h", r},
          {"lambda_per_mm", r > 0.0 ? nlohmann::json(marshall_palmer_lambda_per_mm(r)) : nlohmann::json(nullptr)},
          {"extinction_lidar_per_m", st.sigma_lidar},
          {"extinction_per_m", st.sigma_cam},
          {"q_eff", p.q_eff},
          {"q_eff_from",
           "least-squares fit in ln V of 3.912/sigma_cam to the international visibility code's rain rows (2.5, "
           "12.5, 25, 100 mm/h: 5.9, 2.8, 1.9, 0.77 km, as the free-space-optics literature reproduces the code "
           "ITU-R P.1817 tabulates; not checked against P.1817's text), 1.64; docs/rain.md"},
          {"rain_visibility_m", st.sigma_cam > 0.0 ? nlohmann::json(3.912 / st.sigma_cam) : nlohmann::json(nullptr)},
          {"exposure_s", p.exposure_s},
          {"seed", p.seed},
          {"frame", 0},
          {"cell_m", kRainCellM},
          {"drop_min_mm", p.drops.drop_min_mm},
          {"drop_max_mm", p.drops.drop_max_mm},
          {"drops_per_m3", rain_drops_per_m3(r, p.drops.drop_min_mm, p.drops.drop_max_mm)},
          {"z_near_m", p.z_near_m},
          {"z_split_m", p.z_split_m},
          {"epsilon", p.epsilon},
          {"thinning",
           "a drop is drawn when D >= D_t(z), the smallest diameter whose on-axis coverage estimate (pi/4)(f D/z)^2 "
           "/ (max(1, w) max(1, f v(D) T/z)) reaches epsilon, non-decreasing in z; the drops not drawn are analytic"},
          {"depth_softness", kRainDepthSoftness},
          {"wind_m_s", {w.x, w.y, w.z}},
          {"ego_speed_m_s", p.ego_speed_m_s},
          {"frame_axes", "vehicle frame x forward, y left, z up at the camera; the camera level, looking along +x"},
          {"drop_radiance",
           "0.94 x the image's box mean over a window of half the image height about the drop (refracted) + 0.06 x "
           "the image's mean (reflected)"},
          {"cells", st.cells},
          {"drops_seen", st.drops_seen},
          {"drops_drawn", st.drops_drawn},
          {"alpha_clamped", st.alpha_clamped},
          {"mean_streak_px", st.mean_streak_px}};
}

}  // namespace brume
