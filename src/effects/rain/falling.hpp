// brume — a field of falling particles at a frame of a sequence (rain's drops, snow's flakes; issues
// #56, #58): the closed-form motion of a particle, the cells whose particles can land in a column's
// heights at time t (the search the scan's general pass and the camera's frames share), and the
// camera's pose at frame K. Internal (not installed); implemented in rain.cpp.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "brume/camera.hpp"

namespace brume {

// A particle's hashed centre c [m] at time t [s] in the field's world frame, moved by its fall
// speed f [m/s] (downwards) and the wind w, wrapped within c's layer (kRainLayerM from
// kRainLayerBaseM): rain_drop_at with v(D) given.
Vec3 falling_at(const Vec3& c, double fall_m_s, double t_s, const Vec3& wind);

// The source cells (heights iz, as [iz0, iz1] spans, each cell once) whose particles, falling at
// f − w_z in [f_lo, f_hi] [m/s] (fall speed less the wind's vertical part) over t_s > 0, can land
// at heights [z_lo, z_hi] (a column's, in the world frame) within their layers; appended to `spans`.
void falling_source_spans(double z_lo, double z_hi, double f_lo, double f_hi, double t_s,
                          std::vector<std::pair<std::int64_t, std::int64_t>>& spans);
// The smallest f >= f_lo (fall speed less w_z) with which a particle of cell height iz lands in
// [z_lo, z_hi] (within its layer) at t_s > 0: false when none does at f <= f_hi.
bool falling_min_speed(std::int64_t iz, double z_lo, double z_hi, double f_lo, double f_hi, double t_s, double& f);
// The diameter [mm] whose Atlas fall speed is v [m/s] (slightly less, so that a drop of that
// speed passes), 0 outside (0, 9.65).
double atlas_diameter_below_mm(double v_m_s);

// A camera's place in the drop field's world (its frame at frame 0: the vehicle's axes, x forward,
// y left, z up, origin at the camera) at frame K, and its motion over the exposure.
struct StreakPose {
  RigidTransform world_from_camera;  // the camera's field axes at frame K into the world
  Vec3 velocity;                     // [m/s] the camera's, in the world
  double t_s = 0.0;                  // K·Δt
  bool moved = false;                // not the identity (a frame K > 0, or a rotation)
  bool rotated = false;              // world_from_camera's rotation is not the identity
  bool from_poses = false;           // placed by --poses
};
// From --frame, --frame-interval, --ego-speed (along +x) or --poses (camera 0's KITTI poses; line
// K relative to line 0, camera 2 placed by `kitti_calib`'s P2; the velocity over the exposure from
// lines K and K + 1, else K − 1 and K). Reads the files; errors name the flags.
StreakPose streak_camera_pose(std::uint64_t frame, double frame_interval_s, double ego_speed_m_s,
                              const std::string& poses, const std::string& kitti_calib);
// A sequence's cross rules, the scan's and the camera's: --poses needs a calibration (`calib_why`
// says why and how to give one), not with --ego-speed; K·Δt at most 1e6 s.
void check_sequence_flags(std::uint64_t frame, double frame_interval_s, double ego_speed_m_s, const std::string& poses,
                          const std::string& kitti_calib, const std::string& calib_why);
// The camera's cross rules (--poses with a calibration, not with --ego-speed, the time bounded);
// `calib_how` says how to give a calibration (the CLI's --kitti-calib, or not in Python).
void check_streak_frames(std::uint64_t frame, double frame_interval_s, double ego_speed_m_s,
                         const std::string& poses, const std::string& kitti_calib, const std::string& calib_how);

}  // namespace brume
