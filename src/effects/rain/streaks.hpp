// brume — the camera pass every falling-particle effect shares (rain's drops, snow's flakes;
// brume/rain.hpp, "rain on a camera's image", states the equations): the scene through the
// analytic media, the particles of a field in the camera's frustum, and their streaks over the
// exposure, composited far to near tile by tile. Internal (not installed).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/rain.hpp"
#include "effects/rain/falling.hpp"

namespace brume {

// A particle's streak in the camera's cv frame (x right, y down, z forward).
struct Streak {
  double c[3];        // position at mid-exposure [m]
  double u[3];        // velocity [m/s]
  double area;        // [px² m²] (π/4)·D²·fx·fy: its image area at (r, z) is area·r/z³
  double sigma_px;    // the splat kernel's σ
  double range;       // [m] at mid-exposure
  float e[3];         // its radiance through the media in front of it, linear RGB
  double t0, t1;      // [s] the part of the exposure it is drawn over (z >= z_clip)
  int v_lo, v_hi;     // rows it can touch
  int u_lo, u_hi;     // and columns
  std::size_t order;  // enumeration index (ties)
};

struct StreakCamera {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
};

// The camera pass's flags after the particles' own (rain's, snow's: the same member names), in
// this order; `seed_flag` names the seed, `one` and `many` the particle ("drop", "drops"),
// `medium` the effect ("rain"), `paths` what the lens widens ("streaks").
template <class P>
void streak_camera_params(ParamTable<P>& d, const char* seed_flag, const std::string& one, const std::string& many,
                          const std::string& medium, const std::string& paths) {
  d.real("exposure-time", &P::exposure_s, "s", Range::left_open(0.0, 10.0),
         ("exposure T: a " + one + "'s streak is its image's path over T").c_str())
      .count(seed_flag, &P::seed, "1", Range::at_least(0.0),
             ("seed of the " + one + " field (same seed, same " + many + ")").c_str())
      .text("wind", &P::wind,
            "wind X,Y,Z in m/s in the vehicle frame (x forward, y left, z up; the camera level, looking along +x)")
      .real("ego-speed", &P::ego_speed_m_s, "m/s", Range::closed(-100.0, 100.0),
            ("the camera's speed along its forward axis: the " + many + " move back past it (not with --poses)").c_str())
      .count("frame", &P::frame, "1", Range::at_least(0.0),
             ("frame K of a sequence: the " + many + " of the field at t = K * --frame-interval, each moved in "
              "closed form by its fall and --wind, the camera at its frame-K pose (moved s * t by --ego-speed s, or "
              "placed by --poses); the exposure is centred on t; 0: the field as hashed")
                 .c_str())
      .since(4, 0)
      .real("frame-interval", &P::frame_interval_s, "s", Range::left_open(0.0, 3600.0),
            "time between frames (KITTI's cameras: 0.1 s, 10 Hz)")
      .since(4, 0.1)
      .text("poses", &P::poses,
            "KITTI odometry poses: one line of 12 numbers per frame, camera 0's 3x4 [R|t] into the world (no "
            "header); the camera at --frame K is placed by line K relative to line 0, its motion over the exposure "
            "from lines K and K + 1 (the last: K - 1 and K); needs --kitti-calib (its P2 places camera 2, the "
            "image's, relative to camera 0)")
      .reads_file()
      .since(4, "")
      .real("f-number", &P::f_number, "1", Range::above(0.0),
            ("f-number n of the lens (with the camera's --focal-length and --sensor-width, as dof takes them): " +
             paths + " widen to the thin lens's circle of confusion; none: a pinhole")
                .c_str(),
            "none")
      .real("focus-distance", &P::focus_distance_m, "m", Range::above(0.0),
            "planar depth of the plane in focus (with --f-number)", "none")
      .real("q-eff", &P::q_eff, "1", Range::closed(1.0, 2.0),
            "the camera's extinction efficiency Q_eff: sigma_cam = Q_eff/2 sigma_lidar (default fitted to the "
            "international visibility code's rain rows, docs/rain.md)")
      .real("z-split", &P::z_split_m, "m", Range::left_open(0.0, 1000.0),
            (many + " are drawn up to this planar depth; beyond it the " + medium + " is an analytic medium").c_str())
      .real("z-near", &P::z_near_m, "m", Range::above(0.0),
            (many + " are drawn from this planar depth (nearer ones are analytic)").c_str())
      .real("epsilon", &P::epsilon, "1", Range::closed(0.0, 1.0),
            ("thinning: a " + one + " whose estimated coverage of a pixel is below epsilon is not drawn (its " +
             "extinction is analytic); 0 draws every " + one)
                .c_str())
      .real("visibility", &P::visibility_m, "m", Range::above(0.0),
            ("haze's meteorological visibility (extinction 3.912/V, Koschmieder) composed with the " + medium +
             " in haze's composite; none: " + medium + " is the only medium")
                .c_str(),
            "none")
      .rgb("airlight", &P::airlight, "linear RGB", Range::at_least(0.0),
           "colour of the medium; auto: haze's estimate (the median sky colour, else a grey at the 99th "
           "percentile of luminance)");
}

// A range the scene knows (finite, > 0; else the sky).
inline bool streak_range_known(float r) { return std::isfinite(r) && r > 0.0f; }

// 1. The scene through the analytic media: per pixel the transmission e^{−front_tau(r, cos θ)}
// (0 where the range is unknown and the media's σ > 0; blended by the sky weight), composed by
// s.composite or as T·C + (1 − T)·A; `transmission` receives it.
Image streak_background(const CameraRainScene& s, const std::function<double(double r, double cos_theta)>& front_tau,
                        double sigma_total, int threads, Image* transmission);

// The streaks of a pass slab by slab (a slab's in their order within it).
using StreakSlabs = std::vector<std::vector<Streak>>;

// 2. The particles of `field` with D >= threshold_mm(z) at planar depths in [z_near, z_split),
// slab by slab of the field's cells (x forward in the vehicle frame: the camera's z), each slab's
// lateral extent the frustum widened by grow_m(z0, z1) [m]; make(at, d_mm, k) fills a streak
// (false: not drawn). Returns them slab by slab, each with its `order` (its index over the slabs).
StreakSlabs frustum_streaks(const RainField& field, const std::function<double(double z)>& threshold_mm,
                                    double z_near, double z_split,
                                    const std::function<double(double z0, double z1)>& grow_m,
                                    const StreakCamera& cam, int threads,
                                    const std::function<bool(const Vec3& at, double d_mm, Streak& k)>& make,
                                    std::size_t& cells, std::size_t& seen);

// The same particles at a frame of a sequence where the field has moved or the camera is not at the
// field's origin (pose.moved): the field's source cells whose particles can land in the frustum at
// t (as the scan's general pass finds them: falling_source_spans, falling_min_speed), each particle
// moved by falling_at with its fall speed fall_m_s(d) (non-decreasing in d; `d_below(v)`: the
// largest diameter falling slower than v, or null where any diameter falls at one speed) and the
// wind, then taken into the camera's axes at its pose; make(at, d_mm, k) as above (`at` in the
// camera's field axes). Slab by slab of the particles' depths, in an order that does not depend on
// the threads.
StreakSlabs moving_frustum_streaks(const RainField& field, const std::function<double(double z)>& threshold_mm,
                                   double z_near, double z_split,
                                   const std::function<double(double z0, double z1)>& grow_m,
                                   const StreakCamera& cam, int threads, const StreakPose& pose, const Vec3& wind,
                                   const std::function<double(double d_mm)>& fall_m_s, double d_max_mm,
                                   const std::function<double(double v)>& d_below,
                                   const std::function<bool(const Vec3& at, double d_mm, Streak& k)>& make,
                                   std::size_t& cells, std::size_t& seen);

// A particle's velocity relative to the camera in the camera's cv frame: its fall f [m/s] and the
// wind (world) less the camera's velocity, in the camera's axes at its pose.
inline void streak_velocity(const StreakPose& pose, const Vec3& wind, double fall_m_s, double u[3]) {
  Vec3 w{wind.x - pose.velocity.x, wind.y - pose.velocity.y, wind.z - fall_m_s - pose.velocity.z};
  if (pose.rotated) w = pose.world_from_camera.rotation.transposed() * w;
  u[0] = -w.y, u[1] = -w.z, u[2] = w.x;  // the cv frame: x = −y, y = −z, z = x
}

// The record's {poses, kitti_calib: {path, sha256}} of a camera pass's --poses and the calibration that
// places camera 2 (brume run checks them); {} without --poses.
nlohmann::json streak_pose_files(const std::string& poses, const std::string& kitti_calib);

// The camera's speed [m/s] for the streaks' margin (--ego-speed's |s| exactly: the square root of
// a double's rounded square is its magnitude).
inline double streak_speed(const StreakPose& pose) {
  const Vec3& v = pose.velocity;
  return std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
}

// The thin lens's blur [px] at planar depth z: the circle of confusion α·|z − z_f|/z (α at
// infinity, 0: a pinhole).
struct StreakLens {
  double alpha = 0, focus_m = 0;
  double blur_px(double z) const { return alpha > 0.0 ? alpha * std::abs(z - focus_m) / z : 0.0; }
};

// A slab's lateral margin [m] between planar depths z0 and z1: the particles' motion over half
// the exposure (`motion_m`) and 3 σ of the widest kernel (a particle of d_max_mm) in metres.
double streak_grow_m(double z0, double z1, double d_max_mm, double motion_m, const StreakLens& lens,
                     const StreakCamera& cam);

// A particle of the field (vehicle frame, `at`; diameter d_mm; cv velocity u) as a streak: its
// position, image area, kernel (its width and the lens's blur: σ = w/4) and range; then
// bound_streak. False when it leaves nothing in the image.
bool place_streak(Streak& k, const Vec3& at, double d_mm, const double u[3], const StreakLens& lens, double exposure_s,
                  double z_clip, const StreakCamera& cam);

// The scene's checks every camera pass makes (`effect` names it: "rain needs an RGB image").
void check_streak_scene(const CameraRainScene& s, const std::string& effect);

// The part of the exposure [−T/2, T/2] a streak (c, u, sigma_px set) spends at z >= z_clip, and
// the rows and columns it can touch; false when none is left or it stays out of the image.
bool bound_streak(Streak& k, double exposure_s, double z_clip, const StreakCamera& cam);

// 3. The streaks taken far to near (ties: their order) and composited into `out`, each pixel
// I ← (1 − α)·I + α·E with α its coverage, hidden where the scene's range is nearer
// (kRainDepthSoftness): how many were drawn, how many α were clamped to 1, and the mean length of
// their paths in the image [px] (summed far to near).
struct StreakSplat {
  std::size_t drawn = 0, alpha_clamped = 0;
  double mean_streak_px = 0.0;
};
StreakSplat splat_streaks(const StreakSlabs& streaks, ConstImageView range, Image& out, const StreakCamera& cam,
                          int threads);

// The streaks binned for a splat: in storage order (`drops`), and tile by tile of tile_w x tile_h
// pixels far to near (ties: their order), each tile's list in_tile[first[t] .. first[t + 1]) of
// indices into `drops` (a streak is listed in every tile its rows and columns, one pixel wider,
// touch); the mean length of their paths in the image [px], summed far to near. The CPU's splat
// and the GPU's (effects/rain/rain_gpu.hpp) take the same lists.
struct StreakBins {
  std::vector<const Streak*> drops;
  int tiles_x = 0, tiles_y = 0;
  std::vector<std::size_t> first;
  std::vector<std::uint32_t> in_tile;
  double mean_streak_px = 0.0;
};
StreakBins bin_streaks(const StreakSlabs& streaks, const StreakCamera& cam, int tile_w, int tile_h, int threads);

// How a streak is sampled: its path's ends (ua, va) at t0 and (ub, vb) at t1 in the image, n
// samples uniform in time (a sample's time t0 + (t1 − t0)·(i + 0.5)/n), each spread bilinearly
// (gauss false: σ < 0.5 px) or across a Gaussian of σ = sigma_px truncated at rad = ⌈3σ⌉ pixels.
struct StreakSampling {
  double ua, va, ub, vb;
  int n;
  bool gauss;
  int rad;
};
inline StreakSampling streak_sampling(const Streak& k, const StreakCamera& cam) {
  StreakSampling s;
  const auto at = [&](double t, double& u, double& v) {
    const double px = k.c[0] + k.u[0] * t, py = k.c[1] + k.u[1] * t, pz = k.c[2] + k.u[2] * t;
    u = cam.fx * px / pz + cam.cx, v = cam.fy * py / pz + cam.cy;
  };
  at(k.t0, s.ua, s.va);
  at(k.t1, s.ub, s.vb);
  const double len = std::hypot(s.ub - s.ua, s.vb - s.va);
  const double h = std::max(0.5, 0.5 * k.sigma_px);
  s.n = std::min(1 << 16, static_cast<int>(std::ceil(len / h)) + 1);
  s.gauss = k.sigma_px >= 0.5;
  s.rad = s.gauss ? static_cast<int>(std::ceil(3.0 * k.sigma_px)) : 0;
  return s;
}

// Step 3 done elsewhere (CameraRainScene::splatter: the GPU's pass, effects/rain/rain_gpu.hpp):
// the same streaks into the same image, as splat_streaks.
class StreakSplatter {
 public:
  virtual ~StreakSplatter() = default;
  virtual StreakSplat splat(const StreakSlabs& streaks, ConstImageView range, Image& out, const StreakCamera& cam,
                            int threads) const = 0;
};
// The scene's splatter where it has one, else splat_streaks.
inline StreakSplat splat_scene_streaks(const CameraRainScene& s, const StreakSlabs& streaks, Image& out,
                                       const StreakCamera& cam, int threads) {
  return s.splatter ? s.splatter->splat(streaks, s.range, out, cam, threads)
                    : splat_streaks(streaks, s.range, out, cam, threads);
}

// An image's box mean over (2h+1)² about a pixel (clamped), per channel, by a summed-area table.
class StreakBoxMean {
 public:
  StreakBoxMean(ConstImageView rgb, int h);
  double mean(int x, int y, int c) const;
  double total(int c) const;

 private:
  double& at(int x, int y, int c) { return s_[(static_cast<std::size_t>(y) * (w_ + 1) + x) * 3 + c]; }
  double get(int x, int y, int c) const { return s_[(static_cast<std::size_t>(y) * (w_ + 1) + x) * 3 + c]; }
  int w_, h_, r_;
  std::vector<double> s_;
};

}  // namespace brume
