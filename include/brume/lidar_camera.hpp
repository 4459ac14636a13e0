// brume — a camera frame and its LiDAR scan fogged by one medium (issue #41,
// docs/lidar.md "A camera frame and its scan from one medium").
//
// Every camera effect that models a medium (haze, haze+dof, fog, aerial)
// nests one shared block, "lidar", in its job table:
//   --lidar IN.bin --lidar-out OUT.bin [--lidar-wavelength NM]
//   [--lidar-tau-h, --lidar-p0, ... --lidar-seed: the scan's medium's own
//    settings (brume lidar fog's flags less --visibility/--alpha), prefixed]
// and add_camera_lidar(c) wraps the command's run, its command-line run,
// its check and its summary once, for all of them: the scan is fogged
// through the medium interface (brume/medium.hpp) by the camera's medium
// (camera_lidar_medium, from the command's extinction hooks), the medium
// writes its record block under "lidar", the input goes under
// "inputs.lidar", and the foggy scan is written with the image, maps and
// record, all or none (RunContext::files). `brume run` repeats both outputs.
#pragma once

#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/command.hpp"

namespace brume {

constexpr double kLidarWavelengthNm = 905.0;  // the common automotive LiDAR (Velodyne HDL-64E: 905 nm)

struct CameraLidar {
  std::string points;                        // --lidar: the frame's scan, KITTI .bin
  std::string out;                           // --lidar-out: the foggy scan, KITTI .bin
  double wavelength_nm = kLidarWavelengthNm; // --lidar-wavelength [nm]: a spectral medium's (aerial) extinction there
  nlohmann::json medium;                     // --lidar-tau-h ... --lidar-seed: the scan's medium's own settings
                                             // as its table's JSON (unset names: their defaults; α is the camera's)
};
// Block "lidar"; the scan medium's flags (brume lidar fog's) with the prefix
// "lidar-", without --visibility and --alpha.
const ParamTable<CameraLidar>& camera_lidar_param_table();

// The LiDAR's extinction from the camera's job: THE one place where the
// camera's medium becomes the scan's α (the layered model enters here).
struct CameraLidarMedium {
  double alpha_per_m = 0.0;
  std::string rule;  // how α follows from the camera's parameters, for the record
};
// Throws brume::Error naming the flags: a job without physical units
// (haze in normalised kappas), a medium that is no medium (classic fog), a
// medium that varies with height (not yet: issue #41 item 3), a spectral
// medium's wavelength outside its model.
CameraLidarMedium camera_lidar_medium(const CommandDef& c, const nlohmann::json& job, double wavelength_nm);

// Adds the step (CommandDef::finish) that wraps c's run, cli_run, check and
// report (c's table nests camera_lidar_param_table(); its extinction hooks
// are read when the step runs, so the call may come before or after them),
// and its array form where it has one: the keyword
// array lidar= (an (N, 4) scan, read in place) and the block's settings as
// keywords (lidar_seed, lidar_wavelength, ...: not its files); the foggy
// points come back as the Result's "lidar" (None without a scan), the
// record's "lidar" block and job block as the command line's, from the same
// functions (the scan's parameters, brume/medium.hpp's scan_through_media), so they
// equal --lidar-out bit for bit.
// A medium that varies with height (fog's profiles) also takes kitti_calib=
// (the depth block's --kitti-calib: the scan's pose), recorded with its hash.
void add_camera_lidar(CommandDef& c);

}  // namespace brume
