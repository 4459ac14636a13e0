// brume — rain on a camera's image: the LiDAR's drop field seen through a pinhole camera over an
// exposure, its streaks (Garg & Nayar) depth-tested against the scene, and the rain it does not
// draw as an analytic medium (brume/rain.hpp states the equations; docs/rain.md, "The camera").
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <utility>
#include <vector>

#include "brume/error.hpp"
#include "brume/rain.hpp"
#include "core/text.hpp"
#include "effects/rain/rain_internal.hpp"
#include "effects/rain/streaks.hpp"
#include "media/scan_returns.hpp"

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
    d.nest(&P::drops, rain_drops_param_table());
    streak_camera_params(d, "rain-seed", "drop", "drops", "rain", "streaks");
    // The scan's (--lidar, lidar=): brume lidar rain's --return-mode.
    declare_return_mode(d, &P::return_mode, "the scan of --lidar", "drop");
    d.choice("lidar-frame", &P::lidar_frame, {"camera", "scan"},
             "the frame the scan of --lidar draws its drops in: camera (with --kitti-calib, camera 2's: the drops "
             "the image shows are the ones the scan sees; without it the scan's own, with a warning), scan (the "
             "scan's own frame: brume lidar rain without --kitti-calib)")
        .since(4, "scan");
    return d;
  }();
  return t;
}

Vec3 camera_rain_wind(const CameraRainParams& p) { return parse_wind_m_s(p.wind); }

Vec3 parse_wind_m_s(const std::string& wind) {
  std::stringstream ss(wind);
  std::string item;
  double v[3] = {0.0, 0.0, 0.0};
  int n = 0;
  while (std::getline(ss, item, ',')) {
    if (n < 3) {
      char* end = nullptr;
      v[n] = std::strtod(item.c_str(), &end);
      if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(v[n]) || std::abs(v[n]) > 100.0)
        throw Error("--wind '" + wind + "': '" + item +
                    "' is not a finite number of m/s in [-100, 100]; give X,Y,Z, e.g. 0,3,0 (3 m/s to the left)");
    }
    ++n;
  }
  if (n != 3)
    throw Error("--wind '" + wind + "' has " + std::to_string(n) +
                " components; give X,Y,Z in m/s (vehicle frame: x forward, y left, z up), e.g. 0,3,0");
  return {v[0], v[1], v[2]};
}

void validate_camera_rain(const CameraRainParams& p) {
  camera_rain_param_table().validate(p);
  validate_rain_drops(p.drops);
  validate_streak_camera(p.z_split_m, p.z_near_m, p.f_number, p.focus_distance_m, p.wind, "drops");
}

void validate_streak_camera(double z_split_m, double z_near_m, const std::optional<double>& f_number,
                            const std::optional<double>& focus_distance_m, const std::string& wind,
                            const std::string& particles) {
  if (!(z_split_m > z_near_m))
    throw Error("--z-split " + text::g(z_split_m) + " m must exceed --z-near " + text::g(z_near_m) + " m (" +
                particles + " are drawn between them); give a larger --z-split");
  if (f_number.has_value() != focus_distance_m.has_value())
    throw Error(std::string("the lens's blur needs both --f-number and --focus-distance; ") +
                (f_number ? "give --focus-distance M" : "give --f-number N") + ", or neither (a pinhole)");
  (void)parse_wind_m_s(wind);
}

// ---- the thinning rule and the analytic optical depth ------------------------------------------

namespace {
StreakPopulation rain_population(const CameraRainParams& p) {
  const double rate = p.drops.rate_mm_h.value_or(0.0);
  StreakPopulation pop;
  pop.any = rate != 0.0;
  pop.d_min_mm = p.drops.drop_min_mm, pop.d_max_mm = p.drops.drop_max_mm;
  pop.exposure_s = p.exposure_s, pop.z_near_m = p.z_near_m, pop.z_split_m = p.z_split_m, pop.epsilon = p.epsilon;
  pop.focus_distance_m = p.focus_distance_m.value_or(0.0);
  pop.sigma_cam = camera_rain_extinction_per_m(rate, p.q_eff);
  pop.speed_m_s = atlas_terminal_velocity_m_per_s;
  pop.d2_between = [rate](double a, double b) { return rain_d2_between(rate, a, b); };
  return pop;
}
}  // namespace

CameraRainOptics::CameraRainOptics(const CameraRainParams& p, const Intrinsics& k, double coc_infinity_px)
    : CameraRainOptics(rain_population(p), k, coc_infinity_px) {}

CameraRainOptics::CameraRainOptics(StreakPopulation pop, const Intrinsics& k, double coc_infinity_px)
    : pop_(std::move(pop)), fx_(k.fx), alpha_(coc_infinity_px), zf_(pop_.focus_distance_m) {
  const StreakPopulation& p = pop_;
  const int n = kRainThinningSteps;
  dz_ = p.z_split_m / n;
  dt_.assign(n + 1, kCamInf);
  g_.assign(n + 1, 0.0);
  sd_.assign(n + 1, 0.0);
  double run = p.d_min_mm;  // D_t made non-decreasing in z
  for (int i = 1; i <= n; ++i) {
    const double z = i * dz_;
    if (!p.any || z < p.z_near_m) continue;
    double dt = kCamInf;
    if (p.epsilon <= 0.0 || estimate(p.d_min_mm, z) >= p.epsilon) {
      dt = p.d_min_mm;
    } else if (estimate(p.d_max_mm, z) >= p.epsilon) {
      double lo = p.d_min_mm, hi = p.d_max_mm;  // estimate(lo) < ε <= estimate(hi)
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
    sd_[i] = std::isinf(dt_[i]) ? 0.0 : kCamPi / 4.0 * 1e-6 * p.d2_between(dt_[i], p.d_max_mm);
    g_[i] = g_[i - 1] + sd_[i] * len;
  }
}

double CameraRainOptics::estimate(double d_mm, double z) const {
  const double d = fx_ * d_mm * 1e-3 / z;  // the particle's image diameter [px]
  const double b = alpha_ > 0.0 ? alpha_ * std::abs(z - zf_) / z : 0.0;
  const double w = std::sqrt(d * d + b * b);
  const double len = fx_ * pop_.speed_m_s(d_mm) * pop_.exposure_s / z;
  return kCamPi / 4.0 * d * d / (std::max(1.0, w) * std::max(1.0, len));
}

double CameraRainOptics::threshold_mm(double z) const {
  if (!(z >= pop_.z_near_m) || !(z < pop_.z_split_m)) return kCamInf;
  const int i = std::min(kRainThinningSteps, std::max(1, static_cast<int>(std::ceil(z / dz_))));
  return dt_[i];
}

double CameraRainOptics::tau(double r, double cos_theta) const {
  const double z = std::min(r * cos_theta, pop_.z_split_m);
  double g = 0.0;
  if (z > 0.0) {
    const int i = std::min(kRainThinningSteps, std::max(1, static_cast<int>(std::ceil(z / dz_))));
    const double a = std::max((i - 1) * dz_, pop_.z_near_m);
    g = g_[i - 1] + sd_[i] * std::max(0.0, z - a);
  }
  return std::max(0.0, pop_.sigma_cam * r - g / cos_theta);
}

// ---- the streaks ---------------------------------------------------------------------------------

Image render_camera_rain(const CameraRainScene& s, const CameraRainParams& p, const Exec& exec,
                         CameraRainStats* stats, Image* transmission) {
  return render_camera_rain_drawn(s, p, exec, stats, transmission, nullptr);
}

Image render_camera_rain_drawn(const CameraRainScene& s, const CameraRainParams& p, const Exec& exec,
                               CameraRainStats* stats, Image* transmission, StreakSlabs* drawn) {
  validate_camera_rain(p);
  check_streak_scene(s, "rain");
  const int W = s.rgb.width(), H = s.rgb.height();
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const double rate = *p.drops.rate_mm_h, T = p.exposure_s;
  const double fx = s.k.fx, fy = s.k.fy, cx = s.k.cx, cy = s.k.cy;
  const StreakCamera cam{W, H, fx, fy, cx, cy};
  const CameraRainOptics optics(p, s.k, s.coc_infinity_px);
  CameraRainStats st;
  st.sigma_lidar = rain_extinction_per_m(rate, kLidarRainQ);
  st.sigma_cam = optics.sigma_cam();
  const double sigma_total = st.sigma_cam + s.haze_sigma_per_m;
  const auto front_tau = [&](double r, double cos_theta) {
    return s.analytic ? s.haze_sigma_per_m * r + optics.tau(r, cos_theta) : 0.0;
  };

  // 1. The scene through the analytic media (haze's composite, or the pipeline's).
  Image out = s.background ? s.background(optics, transmission)
                           : streak_background(s, front_tau, sigma_total, nt, transmission);

  // 2. The drops of the field in the frustum, z_near <= z < z_split at mid-exposure.
  // At frame K the field as the scan draws it (LidarRainParams' frame: hashed at frame 0, each drop
  // moved by rain_drop_at), the camera at its pose then.
  const RainField field(rate, p.drops.drop_min_mm, p.drops.drop_max_mm, p.seed);
  const Vec3 wind = camera_rain_wind(p);
  const StreakPose pose = streak_camera_pose(p.frame, p.frame_interval_s, p.ego_speed_m_s, p.poses, s.kitti_calib);
  const double v_max = atlas_terminal_velocity_m_per_s(p.drops.drop_max_mm);
  const double speed_max = std::sqrt(wind.x * wind.x + wind.y * wind.y + wind.z * wind.z) + streak_speed(pose) + v_max;
  const double margin_m = speed_max * T / 2.0 + 0.01;
  const StreakBoxMean env(s.rgb, std::max(1, H / 4));
  double env_total[3];
  for (int k = 0; k < 3; ++k) env_total[k] = env.total(k);
  const StreakLens lens{s.coc_infinity_px, p.focus_distance_m.value_or(0.0)};
  const double z_clip = 0.5 * p.z_near_m;
  const auto grow_m = [&](double z0, double z1) {
    return streak_grow_m(z0, z1, p.drops.drop_max_mm, margin_m, lens, cam);
  };
  const auto make = [&](const Vec3& at, double d_mm, Streak& k) {
    const double z = at.x;
    double u[3];
    streak_velocity(pose, wind, atlas_terminal_velocity_m_per_s(d_mm), u);
    if (!place_streak(k, at, d_mm, u, lens, T, z_clip, cam)) return false;
    const double r = k.range;
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
    return true;
  };
  const auto threshold = [&](double z) { return optics.threshold_mm(z); };
  StreakSlabs drops =
      pose.moved ? moving_frustum_streaks(field, threshold, p.z_near_m, p.z_split_m, grow_m, cam, nt, pose, wind,
                                          atlas_terminal_velocity_m_per_s, p.drops.drop_max_mm,
                                          atlas_diameter_below_mm, make, st.cells, st.drops_seen)
                 : frustum_streaks(field, threshold, p.z_near_m, p.z_split_m, grow_m, cam, nt, make, st.cells,
                                   st.drops_seen);

  // 3. The streaks, composited far to near (ties: the enumeration's order), tile by tile (on the
  // CPU, or by the scene's splatter: the GPU's pass).
  const StreakSplat splat = splat_scene_streaks(s, drops, out, cam, nt);
  st.drops_drawn = splat.drawn, st.alpha_clamped = splat.alpha_clamped, st.mean_streak_px = splat.mean_streak_px;
  if (stats) *stats = st;
  if (drawn) *drawn = std::move(drops);
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
          {"frame", p.frame},
          {"frame_interval_s", p.frame_interval_s},
          {"time_s", static_cast<double>(p.frame) * p.frame_interval_s},
          {"layer_m", kRainLayerM},
          {"layer_base_m", kRainLayerBaseM},
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
