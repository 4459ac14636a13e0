// brume — snow on a camera's image: the flakes of a field through rain's camera pass (their
// paths over the exposure, depth-tested, blurred by the lens), lit by the scene's sky and ground,
// and the snow not drawn as an analytic medium (brume/snow.hpp states the equations; docs/snow.md).
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "brume/error.hpp"
#include "brume/snow.hpp"
#include "core/text.hpp"
#include "effects/rain/streaks.hpp"
#include "effects/snow/snow_internal.hpp"
#include "media/scan_returns.hpp"

namespace brume {

namespace {
constexpr double kFlakeTail = 40.0;                        // Λ_f·D_max: e^{−40} of the flakes beyond
constexpr std::uint64_t kSnowFieldTag = 0x736e6f776669656cull;  // "snowfiel"

// ∫_a^b D²·N0·e^{−ΛD} dD [mm² m⁻³]: ∫_x^∞ D²e^{−ΛD} dD = e^{−Λx}(x²/Λ + 2x/Λ² + 2/Λ³).
double flake_d2_between(const SnowSizes& s, double a, double b) {
  const double l = s.lambda_flake_per_mm;
  if (!(s.n0_flake > 0.0) || !(b > a)) return 0.0;
  const auto g = [l](double x) { return std::exp(-l * x) * (x * x / l + 2.0 * x / (l * l) + 2.0 / (l * l * l)); };
  return s.n0_flake * (g(a) - g(b));
}

StreakPopulation snow_population(const CameraSnowParams& p) {
  const SnowSizes s = snow_sizes(p.flakes);
  StreakPopulation pop;
  pop.any = s.n0_flake > 0.0;
  pop.d_min_mm = 0.0;
  pop.d_max_mm = pop.any ? kFlakeTail / s.lambda_flake_per_mm : 0.0;
  pop.exposure_s = p.exposure_s, pop.z_near_m = p.z_near_m, pop.z_split_m = p.z_split_m, pop.epsilon = p.epsilon;
  pop.focus_distance_m = p.focus_distance_m.value_or(0.0);
  pop.sigma_cam = s.extinction_per_m(p.q_eff);
  const double v = p.flakes.fall_speed_m_s;
  pop.speed_m_s = [v](double) { return v; };
  pop.d2_between = [s](double a, double b) { return flake_d2_between(s, a, b); };
  return pop;
}
}  // namespace

const ParamTable<CameraSnowParams>& camera_snow_param_table() {
  static const ParamTable<CameraSnowParams> t = [] {
    using P = CameraSnowParams;
    ParamTable<P> d("snow");
    d.nest(&P::flakes, snow_flakes_param_table());
    streak_camera_params(d, "snow-seed", "flake", "flakes", "snow", "flakes");
    d.real("albedo", &P::albedo, "1", Range::closed(0.0, 1.0),
           "a flake's Lambertian albedo a: its radiance a (L_sky + L_ground)/2 under the sky and ground light "
           "estimated from the image");
    // The scan's (--lidar, lidar=): brume lidar snow's --return-mode.
    declare_return_mode(d, &P::return_mode, "the scan of --lidar", "flake");
    return d;
  }();
  return t;
}

void validate_camera_snow(const CameraSnowParams& p) {
  camera_snow_param_table().validate(p);
  validate_snow_flakes(p.flakes);
  validate_streak_camera(p.z_split_m, p.z_near_m, p.f_number, p.focus_distance_m, p.wind, "flakes");
}

LidarSnowParams camera_snow_lidar_params(const CameraSnowParams& p) {
  LidarSnowParams lp;
  lp.flakes = p.flakes;
  lp.seed = p.seed;
  lp.return_mode = p.return_mode;
  lp.frame = p.frame;  // the scan's flakes drawn afresh at frame K (brume lidar snow's --frame)
  return lp;
}

Image render_camera_snow(const CameraRainScene& s, const CameraSnowParams& p, const Exec& exec,
                         CameraSnowStats* stats, Image* transmission) {
  return render_camera_snow_drawn(s, p, exec, stats, transmission, nullptr);
}

Image render_camera_snow_drawn(const CameraRainScene& s, const CameraSnowParams& p, const Exec& exec,
                               CameraSnowStats* stats, Image* transmission, StreakSlabs* drawn) {
  validate_camera_snow(p);
  check_streak_scene(s, "snow");
  const int W = s.rgb.width(), H = s.rgb.height();
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const double T = p.exposure_s;
  const double fx = s.k.fx, fy = s.k.fy, cx = s.k.cx, cy = s.k.cy;
  const StreakCamera cam{W, H, fx, fy, cx, cy};
  const SnowSizes sizes = snow_sizes(p.flakes);
  const StreakPopulation pop = snow_population(p);
  const CameraRainOptics optics(pop, s.k, s.coc_infinity_px);
  CameraSnowStats st;
  st.sigma_cam = optics.sigma_cam();
  const double sigma_total = st.sigma_cam + s.haze_sigma_per_m;
  const auto front_tau = [&](double r, double cos_theta) {
    return s.analytic ? s.haze_sigma_per_m * r + optics.tau(r, cos_theta) : 0.0;
  };

  // The light on the flakes: the sky's mean radiance (its pixels, else the top tenth of rows) and
  // the ground's (the bottom quarter of rows).
  {
    double sky[3] = {0, 0, 0}, n_sky = 0.0, ground[3] = {0, 0, 0}, n_ground = 0.0, top[3] = {0, 0, 0}, n_top = 0.0;
    const int top_rows = std::max(1, H / 10), ground_from = H - std::max(1, H / 4);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const bool is_sky = !s.sky_weight.empty() ? s.sky_weight.at(x, y) >= 0.5f : !streak_range_known(s.range.at(x, y));
        for (int c = 0; c < 3; ++c) {
          const double v = s.rgb.at(x, y, c);
          if (is_sky) sky[c] += v;
          if (y < top_rows) top[c] += v;
          if (y >= ground_from) ground[c] += v;
        }
        n_sky += is_sky, n_top += y < top_rows, n_ground += y >= ground_from;
      }
    st.sky_from = n_sky > 0.0 ? "the sky's pixels (unknown range, or sky weight >= 1/2)" : "the top tenth of rows";
    for (int c = 0; c < 3; ++c) {
      st.sky[c] = n_sky > 0.0 ? sky[c] / n_sky : top[c] / n_top;
      st.ground[c] = ground[c] / n_ground;
    }
  }

  // 1. The scene through the analytic media (haze's composite, or the pipeline's).
  Image out = s.background ? s.background(optics, transmission)
                           : streak_background(s, front_tau, sigma_total, nt, transmission);

  // 2. The flakes of the field in the frustum, z_near <= z < z_split at mid-exposure.
  if (pop.any) {
    const RainField field(sizes.n0_flake, sizes.lambda_flake_per_mm, pop.d_min_mm, pop.d_max_mm, p.seed, 0,
                          kSnowFieldTag);
    // At frame K the field moved (falling_at: every flake at v_t, wrapped in its layer), the camera at its pose.
    const Vec3 wind = parse_wind_m_s(p.wind);
    const StreakPose pose = streak_camera_pose(p.frame, p.frame_interval_s, p.ego_speed_m_s, p.poses, s.kitti_calib);
    const double v = p.flakes.fall_speed_m_s;
    const double speed_max = std::sqrt(wind.x * wind.x + wind.y * wind.y + wind.z * wind.z) + streak_speed(pose) + v;
    const double margin_m = speed_max * T / 2.0 + 0.01;
    const StreakLens lens{s.coc_infinity_px, pop.focus_distance_m};
    const double z_clip = 0.5 * p.z_near_m;
    const auto grow_m = [&](double z0, double z1) { return streak_grow_m(z0, z1, pop.d_max_mm, margin_m, lens, cam); };
    double e[3];
    for (int q = 0; q < 3; ++q) e[q] = s.drop_radiance ? (*s.drop_radiance)[q] : p.albedo * (st.sky[q] + st.ground[q]) / 2.0;
    double u[3];
    streak_velocity(pose, wind, v, u);
    const auto make = [&](const Vec3& at, double d_mm, Streak& k) {
      if (!place_streak(k, at, d_mm, u, lens, T, z_clip, cam)) return false;
      const double z = at.x, r = k.range;
      const double tf = std::exp(-front_tau(r, z / r));
      for (int q = 0; q < 3; ++q) k.e[q] = static_cast<float>(tf * e[q] + (1.0 - tf) * s.airlight[q]);
      return true;
    };
    const auto threshold = [&](double z) { return optics.threshold_mm(z); };
    StreakSlabs flakes =
        pose.moved ? moving_frustum_streaks(field, threshold, p.z_near_m, p.z_split_m, grow_m, cam, nt, pose, wind,
                                            [v](double) { return v; }, pop.d_max_mm, nullptr, make, st.cells,
                                            st.flakes_seen)
                   : frustum_streaks(field, threshold, p.z_near_m, p.z_split_m, grow_m, cam, nt, make, st.cells,
                                     st.flakes_seen);
    // 3. Composited far to near, tile by tile.
    const StreakSplat splat = splat_scene_streaks(s, flakes, out, cam, nt);
    st.flakes_drawn = splat.drawn, st.alpha_clamped = splat.alpha_clamped, st.mean_streak_px = splat.mean_streak_px;
    if (drawn) *drawn = std::move(flakes);
  }
  if (stats) *stats = st;
  return out;
}

nlohmann::json camera_snow_record(const CameraSnowParams& p, const CameraSnowStats& st) {
  const SnowSizes s = snow_sizes(p.flakes);
  const double rate = p.flakes.rate_mm_h.value_or(0.0);
  const Vec3 w = parse_wind_m_s(p.wind);
  const auto or_null = [rate](double v) { return rate > 0.0 ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"model",
           "exponential melted sizes (" + p.flakes.distribution +
               "), flakes (rho_w/rho_s)^(1/3) larger, N0 from the water flux; a field of flakes (rain's cells and "
               "hash, its own draws) advected over the exposure, each an opaque Lambertian disc lit by the image's "
               "sky and ground, depth-tested against the scene; the rest of the snow analytic"},
          {"rate_mm_h", rate},
          {"distribution", p.flakes.distribution},
          {"lambda_melted_per_mm", or_null(s.lambda_melted_per_mm)},
          {"flake_density_g_cm3", p.flakes.flake_density_g_cm3},
          {"lambda_flake_per_mm", or_null(s.lambda_flake_per_mm)},
          {"fall_speed_m_s", p.flakes.fall_speed_m_s},
          {"volume_fraction", s.volume_fraction},
          {"n0_flake_per_m3_mm", s.n0_flake},
          {"flakes_per_m3", s.flakes_per_m3},
          {"flake_max_mm", or_null(kFlakeTail / s.lambda_flake_per_mm)},
          {"extinction_lidar_per_m", s.extinction_per_m(kLidarSnowQ)},
          {"extinction_per_m", st.sigma_cam},
          {"q_eff", p.q_eff},
          {"snow_visibility_m", st.sigma_cam > 0.0 ? nlohmann::json(3.912 / st.sigma_cam) : nlohmann::json(nullptr)},
          {"exposure_s", p.exposure_s},
          {"seed", p.seed},
          {"frame", p.frame},
          {"frame_interval_s", p.frame_interval_s},
          {"time_s", static_cast<double>(p.frame) * p.frame_interval_s},
          {"layer_m", kRainLayerM},
          {"layer_base_m", kRainLayerBaseM},
          {"cell_m", kRainCellM},
          {"z_near_m", p.z_near_m},
          {"z_split_m", p.z_split_m},
          {"epsilon", p.epsilon},
          {"thinning",
           "a flake is drawn when D_f >= D_t(z), the smallest diameter whose on-axis coverage estimate (pi/4)(f D/z)^2 "
           "/ (max(1, w) max(1, f v_t T/z)) reaches epsilon, non-decreasing in z; the flakes not drawn are analytic"},
          {"depth_softness", kRainDepthSoftness},
          {"wind_m_s", {w.x, w.y, w.z}},
          {"ego_speed_m_s", p.ego_speed_m_s},
          {"frame_axes", "vehicle frame x forward, y left, z up at the camera; the camera level, looking along +x"},
          {"albedo", p.albedo},
          {"flake_radiance", "albedo x (L_sky + L_ground)/2: a Lambertian sphere under a sky above and a ground below"},
          {"sky_linear_rgb", st.sky},
          {"sky_from", st.sky_from},
          {"ground_linear_rgb", st.ground},
          {"ground_from", "the bottom quarter of rows"},
          {"cells", st.cells},
          {"flakes_seen", st.flakes_seen},
          {"flakes_drawn", st.flakes_drawn},
          {"alpha_clamped", st.alpha_clamped},
          {"mean_streak_px", st.mean_streak_px}};
}

}  // namespace brume
