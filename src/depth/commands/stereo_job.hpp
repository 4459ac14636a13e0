// brume — `brume depth stereo` as a job from files to files with declared
// parameters and a re-runnable record (brume/pipeline.hpp): a rectified pair
// to a disparity map in pixels (brume/stereo.hpp), in the convention
// --disparity reads. Private to the library (not installed): a program runs
// it through the list of commands (find_command("depth stereo")->run).
#pragma once

#include <cmath>
#include <string>

#include "brume/pipeline.hpp"
#include "brume/stereo.hpp"

namespace brume {

struct DepthStereoJob {
  std::string left, right;   // the rectified pair's views
  std::string left_layer, right_layer;  // their layers in files with layers (brume/io.hpp)
  std::string calib;         // Middlebury 2014 / ETH3D calib.txt, or:
  double fx_px = 0.0;        // [px] focal length (0: unset) ...
  double baseline_m = NAN;   // [m] ... and baseline (NaN: unset)
  StereoParams stereo;
  std::string out;           // disparity [px], float file (PFM, EXR, TIFF)
  std::string confidence;    // 0..1 per pixel (optional)
  std::string record;
};
const ParamTable<DepthStereoJob>& depth_stereo_job_table();
nlohmann::json run_depth_stereo_job(const DepthStereoJob& job, const RunContext& ctx = {});

}  // namespace brume
