// brume — one description of where a range map comes from, shared by every
// command that takes depth (`brume depth convert`, `brume haze`, and the
// effects to come): the same flags, the same explicit conventions, the same
// record of what was done.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/depth.hpp"
#include "brume/fuse.hpp"
#include "brume/image.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/stereo.hpp"

namespace brume {

enum class RenderBackground { automatic, off };
const EnumNames<RenderBackground>& render_background_names();
// The rule in words (--help, the record, the docs).
extern const char* const kRenderBackgroundRule;
// Whether a stored value of a float range or planar-depth file is a renderer's background.
inline bool is_render_background(float v) { return v >= 1e9f || v == 65504.0f || v == -INFINITY; }
// The largest distance [m] taken without a warning: beyond it a value is
// more likely a background or a unit error than a surface (the plausibility
// rule of the depth layer).
constexpr double kPlausibleDistanceMax = 1e6;

struct DepthSource {
  // Exactly one source file:
  std::string range;             // metres along the ray
  std::string z;                 // planar depth in metres (needs intrinsics)
  std::string disparity;         // stereo disparity in px (calib.txt, or --fx and --baseline)
  std::string depth_buffer;      // rasteriser window depth in [0, 1] (--near, --far, --convention)
  std::string inverse_depth;     // monocular inverse depth: z = 1 / (scale v + shift)
  std::string normalized_depth;  // monocular normalised depth: z = near + v (far - near)
  std::string velodyne;          // KITTI scan (.bin) with --kitti-calib
  std::string stereo_right;      // right view of a rectified pair: its disparity is computed (brume/stereo.hpp)
                                 // and converted as --disparity's (calib.txt, or --fx and --baseline);
                                 // beside a sparse source (the one other source given), fused with it by
                                 // the completion (brume/fuse.hpp)
  std::string stereo_left;       // the pair's left view: the effects' --image (the default there);
                                 // depth convert and depth prepare name it here
  std::string stereo_right_layer, stereo_left_layer;  // their layers in files with layers (brume/io.hpp)
  StereoParams stereo;           // the matching's parameters (--max-disparity, --stereo-...)

  std::string channel;           // channel name in a multi-channel file (e.g. Z of an EXR)
  // No channel named: a file with layers' one depth pass by name (names), or
  // as before schema 4 (first): its one channel, or R of equal R, G, B.
  LayerRule channel_rule = LayerRule::names;
  std::optional<double> depth_scale;  // metres per count (integer range / z files; required there)
  // A stored value that means "no measurement" (GeoPose3K range maps mark the
  // sky with -1): pixels whose stored value equals it exactly become unknown
  // (NaN). Compared with the file's values as read (counts of an integer file,
  // the float of a float file; V rounded to float32 like the file's values)
  // before --depth-scale, --disparity-scale or any conversion. Every source
  // read from an image file (range, z, disparity, depth buffer, inverse and
  // normalised depth); refused with --velodyne, whose scan has no stored grid.
  std::optional<double> unknown_value;
  // Renderers' "no surface" values in range and planar-depth files (float
  // files only): stored values >= 1e9 (Cycles writes 1e10), exactly 65504
  // (Eevee: half float's largest) and +-inf are unknown (sky) -- compared as
  // stored, before --depth-scale, as --unknown-value is. off: read as
  // distances (the rule of records before schema 4). Disparity, depth
  // buffers and normalised or inverse depth have conventions of their own.
  RenderBackground render_background = RenderBackground::automatic;
  Intrinsics k;                  // --fx --fy --cx --cy
  double fov_x_deg = NAN, fov_y_deg = NAN;
  // The camera in millimetres (--focal-length, --sensor-width, --sensor-height,
  // --sensor-fit, --lens-shift; brume/depth.hpp): the intrinsics when no pixel
  // ones are given; with them, the pixels win and the lens must agree within
  // 1 % (depth of field's CoC reads its millimetres either way).
  LensCamera lens;
  std::string calib;             // Middlebury 2014 / ETH3D calib.txt
  double baseline_m = NAN;       // stereo baseline without calib.txt
  double disparity_scale = 1.0;  // d = scale * stored + offset
  double disparity_offset = 0.0; // Middlebury 2005 dmin, or doffs
  std::string convention = "opengl";  // opengl | d3d | reversed-z
  double near_m = NAN, far_m = NAN;   // depth buffer / normalised depth planes
  double inverse_scale = NAN, inverse_shift = 0.0;
  std::string kitti_calib;
  int width = 0, height = 0;     // image size for --velodyne when no image is at hand
  std::string like;              // ... or take it from this image

  int sources() const;  // how many of the depth sources above are given (load_depth needs exactly one,
                        // or one and --stereo-right: fused())
  // A sparse source and --stereo-right: the completion fuses them (brume/fuse.hpp).
  bool fused() const { return !stereo_right.empty() && sources() == 2; }
};

struct LoadedDepth {
  Image range;           // metres along the ray, NaN unknown
  nlohmann::json record; // what was read and how it was converted; "warnings": what it cannot vouch for
  std::string path;      // the source file
  Image window_depth;    // --depth-buffer: the window depth d in [0, 1] as read (NaN unknown), for a GPU pass
                         // that linearises it itself; empty for other sources
  // The camera the range map was seen from, where the source gives one
  // (source_camera): the completion's planar continuation uses it.
  std::optional<Intrinsics> camera;
  // A scan projected from a sensor beside the camera (--velodyne): the
  // completion's occlusion rule applies to it (CompleteParams::offset_scan).
  bool offset_scan = false;
  // A sparse source with --stereo-right (DepthSource::fused): the pair's
  // range fitted to the scan, for the completion to fill what the scan
  // misses; `range` is the scan's alone.
  std::shared_ptr<const StereoFill> fusion;
};

// Convert the source to a range map. width/height: the image the depth
// belongs to (for the lidar projection and the default principal point; 0 if
// unknown). Throws brume::Error naming the flag or file.
LoadedDepth load_depth(const DepthSource& src, int width = 0, int height = 0);

// Intrinsics from the source's flags (--fx.., --fov-x.., calib.txt, or the
// camera in millimetres), for a width x height image; throws when none were
// given, or when the millimetres disagree with the pixels by more than 1 %.
Intrinsics depth_intrinsics(const DepthSource& src, int width, int height);

// The camera the depth was seen from, for a width x height image (both > 0):
// KITTI lidar (--velodyne with --kitti-calib) takes camera 2's K from P2
// (fx = P2[0], fy = P2[5], cx = P2[2], cy = P2[6]); every other source its
// depth_intrinsics. The pose comes from `pose` (default: level, looking north,
// height unknown); make_camera validates it.
Camera depth_camera(const DepthSource& src, int width, int height, const CameraPose& pose = {});

// Refuses a fused source (a sparse one and --stereo-right) for `what`, a
// command without a completion (depth convert): the fusion is the
// completion's.
void refuse_fusion(const DepthSource& src, const std::string& what);

// The geometry of the rectified pair of --stereo-right beside a sparse
// source, for a width x height pair (brume/fuse.hpp, step 1): --calib's
// calib.txt, --kitti-calib's P2 and P3 (with --velodyne), or --fx and
// --baseline; throws naming the flags when none is given or the file does
// not fit the pair.
StereoGeometry stereo_geometry(const DepthSource& src, int width, int height);

// The source's camera intrinsics for a width x height map where its flags
// give them (--velodyne with --kitti-calib: P2; --fx.., --fov-x.., --calib),
// else none (a range map alone needs no camera).
std::optional<Intrinsics> source_camera(const DepthSource& src, int width, int height);

}  // namespace brume
