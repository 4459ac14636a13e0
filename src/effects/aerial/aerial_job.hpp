// brume — `brume aerial` as a job from files to files -- its table, map outputs and run: the
// command's half of the family, whose public header (brume/aerial.hpp) declares the parameters and
// the functions. Private to the library (not installed): a program runs a job through the list of
// commands (brume/command.hpp: find_command("aerial")->run).
#pragma once

#include "brume/aerial.hpp"
#include "brume/lidar_camera.hpp"
#include "brume/pipeline.hpp"

namespace brume {

struct AerialJob {
  InputFiles input;
  RangeStep prepare;
  AerialParams aerial;
  OutputFiles output;  // maps: attenuation, scale-map
  CameraLidar lidar;   // --lidar IN.bin --lidar-out OUT.bin (brume/lidar_camera.hpp): the medium at 905 nm
  std::string target_altitude;  // --target-altitude: metres above sea level per pixel (--path slant)
  std::string turbidity_from;  // --turbidity-from: T from a `brume sky fit` JSON (brume/sky.hpp); must be reliable
  // --turbidity auto --sky-image FILE: T fitted on a photo of the sky as `brume
  // sky fit` does (fit_sky_image_file), refused when unreliable. The sky's own
  // flags carry the prefix --sky- so they do not collide with the photo's
  // (--sky-projection, --sky-yaw, --sky-sun-zenith, --sky-date, --sky-samples, ...).
  std::string sky_image;                           // --sky-image
  std::string sky_image_layer;                     // --sky-image-layer: its layer in a file with layers
  TransferFunction sky_image_transfer = Transfer::automatic;  // --sky-image-transfer
  std::string sky_mask;                            // --sky-mask
  SkyViewParams sky_view;                          // --sky-projection ...
  SunParams sky_sun;                               // --sky-sun ...
  SkyFitOptions sky_fit;                           // --sky-samples ...
};
const std::vector<MapOutput>& aerial_map_outputs();
const ParamTable<AerialJob>& aerial_job_table();
// The turbidity of a job whose T comes from elsewhere, resolved into
// job.aerial.atmosphere.turbidity as `brume aerial` does before it reads the
// photo: --turbidity-from (a `brume sky fit` JSON) or --turbidity auto
// --sky-image (the same fit as `brume sky fit` on that file, seeded, so the
// same T every run). Refuses an unreliable fit, both sources at once, a
// disagreeing --turbidity and --sky-* flags without --sky-image (`given`:
// the parameter names set). fit_record is the record's "turbidity_fit" and
// image_record its inputs' "sky_image" (both null unless --sky-image).
struct AerialTurbidity {
  nlohmann::json fit_record;
  nlohmann::json image_record;
  nlohmann::json from_record;  // --turbidity-from's {path, sha256}: an input (brume run checks it)
};
AerialTurbidity resolve_aerial_turbidity(AerialJob& job, const std::set<std::string>& given);
// --path slant's geometry for a job: --target-altitude read into `store`
// (checked against the image's size), else the camera of the depth source's
// intrinsics and the pose. Level: no geometry (empty).
AerialGeometry aerial_geometry(const AerialJob& job, const DepthSource& depth, int width, int height, Image& store);
nlohmann::json run_aerial_job(const AerialJob& job, const ExecOptions& exec, const RunContext& ctx = {});

}  // namespace brume
