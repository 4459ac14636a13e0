// brume — the steps `brume rain` and `brume snow` share around their camera pass
// (effects/rain/streaks.hpp): the lens, the range's completion and preparation, haze's
// analysis and composite, the record's common fields, the mask, the scan's files. Internal.
#pragma once

#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/command.hpp"
#include "brume/depth_source.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/pipeline.hpp"
#include "brume/rain.hpp"
#include "brume/range_step.hpp"

namespace brume {

// The thin lens's circle of confusion at infinity [px] (dof's), 0 for a pinhole.
double streak_coc_px(std::optional<double> f_number, std::optional<double> focus_distance_m, const DepthSource& depth,
                     int width, int height);
// --f-number needs the camera in millimetres; `particles` names what it blurs ("the streaks").
// How a camera pass's --poses gets its calibration (check_streak_frames' `calib_how`): the command
// line's depth block, or none in the array forms.
constexpr const char* kStreakCalibHowCli =
    "give --kitti-calib FILE (its P2), or --ego-speed instead of --poses";
constexpr const char* kStreakCalibHowPython =
    "give kitti_calib=FILE (KITTI's calib/N.txt: its P2), or ego_speed instead of poses";
void check_streak_lens(std::optional<double> f_number, const DepthSource& depth, const std::string& particles);

// The camera's particles on an image and its measured range: completed and prepared as haze
// does it, haze's airlight (and with `visibility_m` its medium and composite), then `render` on
// the scene (it fills the record's block `block`); the record's blocks.
struct StreakRun {
  Image rgb, transmission;
  nlohmann::json record;
};
StreakRun run_camera_streaks(ConstImageView rgb, ConstImageView measured_range, const DepthSource& depth,
                             const RangeStep& step, const Exec& exec, const std::set<std::string>& given, double coc,
                             std::optional<double> visibility_m, std::optional<Rgb> airlight, const std::string& block,
                             const std::function<Image(const CameraRainScene& scene, Image* transmission,
                                                       nlohmann::json& block)>& render);

// brume.rain's and brume.snow's array forms: the scan of lidar= (in[2], when present) first,
// through `scan` (it fills the record's block `lidar_block` and returns the points lost: "lidar"
// and "lidar_labels"; else None for both), then the image through `image` ("rgb",
// "transmission" and its record's blocks).
ArrayResult streak_array_result(
    const std::vector<ArrayIn>& in, const std::string& what, const std::string& lidar_block,
    const std::function<std::size_t(const float* in, float* out, std::size_t n, std::uint8_t* labels,
                                    nlohmann::json& block)>& scan,
    const std::function<StreakRun()>& image);
// brume.rain's and brume.snow's keywords: the command's own, the range's preparation, the
// intrinsics and the execution (array_call_table's), and the depth block's kitti_calib= (the
// command line's --kitti-calib, in the same block of the job): the KITTI calibration that places
// the camera of poses= and rain's lidar= scan in the camera's frame.
template <class P>
ParamTable<ArrayCall<P>> streak_array_call_table(const ParamTable<P>& own) {
  ParamTable<ArrayCall<P>> t = array_call_table(own, kArrayPrepare | kArrayIntrinsics | kArrayExec);
  std::set<std::string> others;
  for (const auto& d : depth_param_table().params())
    if (d.spec.name != "kitti-calib") others.insert(d.spec.name);
  t.nest_except(&ArrayCall<P>::depth, depth_param_table(), others);
  return t;
}
// kitti_calib= changes nothing unless the call uses it (`uses`: poses=, or rain's lidar= in the
// camera's frame): refused then, naming the function.
void check_streak_array_calib(const std::string& kitti_calib, bool uses, const std::string& fn);

// A call that went through a scan says so in its job, as the camera effects' lidar= does: an
// empty lidar block (the scan has no settings of its own: the particles').
void streak_array_lidar_job(CommandDef& c);

// --mask: `out` where the grey image is white, `rgb` where black, mixed between; its file record.
void apply_streak_mask(Image& out, const Image& rgb, const std::string& mask, nlohmann::json& record);

}  // namespace brume
