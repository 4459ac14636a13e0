// brume — depth sources (see brume/depth_source.hpp).
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <vector>

#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/record.hpp"
#include "brume/stereo.hpp"
#include "core/text.hpp"
#include "core/warnings.hpp"

namespace brume {

const EnumNames<RenderBackground>& render_background_names() {
  static const EnumNames<RenderBackground> n = {{RenderBackground::automatic, "auto"}, {RenderBackground::off, "off"}};
  return n;
}

const char* const kRenderBackgroundRule =
    "stored values >= 1e9 (Cycles: 1e10), exactly 65504 (Eevee: half float's largest) and +-inf are unknown "
    "(sky), compared as stored, before --depth-scale (float range and planar-depth files)";

int DepthSource::sources() const {
  int n = 0;
  for (const std::string* f :
       {&range, &z, &disparity, &depth_buffer, &inverse_depth, &normalized_depth, &velodyne, &stereo_right})
    n += f->empty() ? 0 : 1;
  return n;
}

namespace {
// The intrinsics the pixel flags give (--fx.., --fov-x.., calib.txt), if any.
bool pixel_intrinsics(const DepthSource& s, int width, int height, Intrinsics& k, std::string& from) {
  if (s.k.fx > 0.0 || s.k.fy > 0.0) {
    k = resolve(s.k, width, height);
    from = "--fx";
    return true;
  }
  if (!std::isnan(s.fov_x_deg) || !std::isnan(s.fov_y_deg)) {
    k = intrinsics_from_fov(width, height, s.fov_x_deg, s.fov_y_deg);
    k.cx = s.k.cx, k.cy = s.k.cy;
    k = resolve(k, width, height);
    from = std::isnan(s.fov_x_deg) ? "--fov-y" : "--fov-x";
    return true;
  }
  if (!s.calib.empty()) {
    k = resolve(read_calib_camera(s.calib), width, height);
    from = "--calib";
    return true;
  }
  return false;
}

}  // namespace

Intrinsics depth_intrinsics(const DepthSource& s, int width, int height) {
  Intrinsics k;
  std::string from;
  const bool pixels = pixel_intrinsics(s, width, height, k, from);
  if (!s.lens.given()) {
    if (pixels) return k;
    throw Error("planar depth needs the camera: give --fx (and --fy, --cx, --cy), or --fov-x/--fov-y, or --calib "
                "(a calib.txt, or KITTI depth completion's intrinsics/*.txt), or the camera in millimetres (--focal-length MM --sensor-width MM, as Blender states it)");
  }
  if (!pixels) return lens_intrinsics(s.lens, width, height);
  // Both: the pixels win (as depth of field's lens beside --fov-x always
  // did); the millimetres must describe the same camera.
  if (s.lens.lens_shift[0] != 0.0 || s.lens.lens_shift[1] != 0.0)
    throw Error("--lens-shift places the principal point of the camera in millimetres, but " + from +
                " gives the pixel intrinsics, which win: give the principal point as --cx/--cy, or drop " + from +
                " and let --focal-length and --sensor-width give the camera");
  if (!s.lens.focal_length_mm)
    throw Error("--sensor-width/--sensor-height describe the camera in millimetres with --focal-length, which is "
                "missing (" + from + " gives the pixel intrinsics); add --focal-length MM or drop the sensor flags");
  const Intrinsics kl = lens_intrinsics(s.lens, width, height);
  const double apart = std::abs(kl.fx / k.fx - 1.0);
  if (apart > 0.01) {
    const LensScale l = lens_scale(s.lens, width, height);
    throw Error("the lens gives fx = focal length x " + text::g(l.side_px) + " px / sensor = " +
                text::g(*s.lens.focal_length_mm) + " mm x " + text::g(l.side_px) + " px / " + text::g(l.sensor_mm) + " mm = " +
                text::g(kl.fx) + " px (--sensor-fit " + enum_name(sensor_fit_names(), s.lens.sensor_fit) +
                "), but " + from + " gives fx = " + text::g(k.fx) + " px (" + text::g(100.0 * apart) +
                " % apart; at most 1 % is allowed): correct --focal-length or " + l.sensor_flag + " (or --sensor-fit), "
                "or " + from);
  }
  return k;
}

Camera depth_camera(const DepthSource& s, int width, int height, const CameraPose& pose) {
  if (!s.velodyne.empty()) {
    if (s.kitti_calib.empty()) throw Error("--velodyne needs --kitti-calib FILE (P2, R0_rect, Tr_velo_to_cam)");
    // The lidar is projected into rectified camera 2: P2 = K [I | t], so K is P2's left 3x3.
    const KittiCalib c = read_kitti_calib(s.kitti_calib);
    Intrinsics k;
    k.fx = c.P2[0], k.fy = c.P2[5], k.cx = c.P2[2], k.cy = c.P2[6];
    return make_camera(k, width, height, pose);
  }
  return make_camera(depth_intrinsics(s, width, height), width, height, pose);
}

namespace {

nlohmann::json intrinsics_record(const Intrinsics& k) {
  return {{"fx_px", k.fx}, {"fy_px", k.fy}, {"cx_px", k.cx}, {"cy_px", k.cy}};
}

// Integer files of values in [0, 1] (UNORM): count / (2^bits - 1).
void unorm(Image& im, const FileInfo& info) {
  if (!info.integer) return;
  const double maxval = std::ldexp(1.0, info.bits) - 1.0;
  for (float& v : im.data) v = static_cast<float>(v / maxval);
}

// A range or planar depth is a distance: a negative stored value is either a
// no-data sentinel (GeoPose3K marks the sky with -1) or a signed convention
// (OpenGL eye-space z), and guessing which would be wrong half the time.
void refuse_negative(const Image& stored, const char* flag, const std::string& path, const DepthSource& s) {
  std::size_t negatives = 0, first = 0;
  for (std::size_t i = 0; i < stored.data.size(); ++i)
    if (stored.data[i] < 0.0f && std::isfinite(stored.data[i]))
      if (negatives++ == 0) first = i;
  if (!negatives) return;
  const float v = stored.data[first];
  throw Error(std::string(flag) + " '" + path + "' stores " + std::to_string(negatives) + " negative value(s), the first " +
              text::g(v, 9) + " at pixel (" + std::to_string(first % stored.width) + ", " + std::to_string(first / stored.width) +
              "); distances must be > 0 where known (NaN, inf or 0 mark unknown pixels). If " + text::g(v, 9) +
              " marks the sky or missing data (GeoPose3K uses -1), pass --unknown-value " + text::g(v, 9) +
              (s.unknown_value ? " (the --unknown-value " + text::g(*s.unknown_value, 9) + " given matches other values, not this one)" : "") +
              "; if the map is signed (OpenGL eye-space z is negative in front of the camera), negate it first.");
}

// A disparity map in px (the scale already applied) to range, by --calib's
// or --fx/--baseline's camera: Z = f B / (d + doffs), then along the ray.
Image disparity_range(const Image& v, const DepthSource& s, const std::string& what, double scale,
                      nlohmann::json& rec) {
  double f = s.k.fx, doffs = s.disparity_offset, baseline = s.baseline_m;
  Intrinsics k;
  if (!s.calib.empty()) {
    StereoCalib c = read_stereo_calib(s.calib);
    if (c.width > 0 && (c.width != v.width || c.height != v.height))
      throw Error(what + " is " + v.size_string() + " but --calib '" + s.calib + "' says " +
                  std::to_string(c.width) + "x" + std::to_string(c.height));
    f = c.f_px, doffs = c.doffs_px, baseline = c.baseline_m;
    k.fx = k.fy = c.f_px, k.cx = c.cx, k.cy = c.cy;
    rec["calib"] = {{"path", s.calib}, {"sha256", sha256_file(s.calib)}};  // an input: brume run checks it
  } else {
    if (!(f > 0.0) || !(baseline > 0.0))
      throw Error(what + " without --calib needs --fx (focal length in pixels at the disparity map's size) and "
                  "--baseline (metres)");
    k = s.k;
  }
  k = resolve(k, v.width, v.height);
  Image zz = disparity_to_z(v, f, baseline, doffs);
  rec["formula"] = "Z = f B / (d + doffs), d = disparity_scale * stored";
  rec["f_px"] = f, rec["baseline_m"] = baseline, rec["doffs_px"] = doffs, rec["disparity_scale"] = scale;
  rec["intrinsics"] = intrinsics_record(k);
  return z_to_range(zz, k);
}

// --stereo-right: the pair matched (brume/stereo.hpp), its disparity
// converted as --disparity's.
LoadedDepth stereo_depth(const DepthSource& s, int width, int height) {
  if (s.stereo_left.empty())
    throw Error("--stereo-right '" + s.stereo_right + "' needs the pair's left view: an effect takes it from "
                "--image; depth convert and depth prepare from --stereo-left FILE");
  if (s.unknown_value)
    throw Error("--unknown-value does not apply to --stereo-right: the matched disparity marks unknown pixels "
                "NaN itself; drop --unknown-value");
  if (s.disparity_scale != 1.0 || s.disparity_offset != 0.0)
    throw Error("--disparity-scale and --disparity-offset describe a stored disparity file; --stereo-right's "
                "disparity is computed in pixels (doffs comes from --calib); drop them");
  LoadedDepth out;
  nlohmann::json& rec = out.record;
  nlohmann::json lrec, rrec;
  const StereoView L = read_stereo_view(s.stereo_left, "--stereo-left", &lrec, s.stereo_left_layer);
  const StereoView R = read_stereo_view(s.stereo_right, "--stereo-right", &rrec, s.stereo_right_layer);
  if (width > 0 && (L.width != width || L.height != height))
    throw Error("--stereo-left '" + s.stereo_left + "' is " + std::to_string(L.width) + "x" +
                std::to_string(L.height) + " but the image is " + std::to_string(width) + "x" +
                std::to_string(height) + "; the depth must be the image's");
  if (!s.calib.empty()) {  // before the matching: a calib.txt of another size is refused at once
    const StereoCalib c = read_stereo_calib(s.calib);
    if (c.width > 0 && (c.width != L.width || c.height != L.height))
      throw Error("--stereo-left '" + s.stereo_left + "' is " + std::to_string(L.width) + "x" +
                  std::to_string(L.height) + " but --calib '" + s.calib + "' says " + std::to_string(c.width) + "x" +
                  std::to_string(c.height) + "; the calibration must be the pair's (rescale it with the images)");
  } else if (!(s.k.fx > 0.0) || !(s.baseline_m > 0.0)) {
    throw Error("--stereo-right without --calib needs --fx (focal length in pixels) and --baseline (metres)");
  }
  StereoResult st = compute_stereo(L, R, s.stereo, "--stereo-left '" + s.stereo_left + "'",
                                   "--stereo-right '" + s.stereo_right + "'");
  rec = {{"source", "stereo"}, {"left", lrec}, {"right", rrec}, {"stereo", st.record}};
  out.path = s.stereo_right;
  out.range = disparity_range(st.disparity, s, "--stereo-left '" + s.stereo_left + "'", 1.0, rec);
  rec["formula"] = "Z = f B / (d + doffs), d the matched disparity";
  std::size_t unknown = 0;
  for (float x : out.range.data) unknown += std::isfinite(x) && x > 0.0f ? 0 : 1;
  rec["unknown_pixels"] = unknown;
  return out;
}

}  // namespace

void refuse_fusion(const DepthSource& s, const std::string& what) {
  if (!s.fused()) return;
  throw Error(what + " converts one depth source, but --stereo-right '" + s.stereo_right + "' is given beside " +
              "another: the pair is fused with a sparse source by the completion; run brume depth complete (or an "
              "effect with --complete), or drop one of the two");
}

StereoGeometry stereo_geometry(const DepthSource& s, int width, int height) {
  StereoGeometry g;
  const std::string pair = std::to_string(width) + "x" + std::to_string(height);
  if (!s.calib.empty()) {
    const StereoCalib c = read_stereo_calib(s.calib);
    if (c.width > 0 && (c.width != width || c.height != height))
      throw Error("--calib '" + s.calib + "' says " + std::to_string(c.width) + "x" + std::to_string(c.height) +
                  " but the pair (--image, --stereo-right) is " + pair +
                  "; the calibration must be the pair's (rescale it with the images, or give the pair it belongs to)");
    g.f_px = c.f_px, g.baseline_m = c.baseline_m, g.doffs_px = c.doffs_px;
    g.k.fx = g.k.fy = c.f_px, g.k.cx = c.cx, g.k.cy = c.cy;
    g.record = {{"from", "--calib"}, {"path", s.calib}, {"sha256", sha256_file(s.calib)}};
  } else if (!s.kitti_calib.empty()) {
    const KittiCalib c = read_kitti_calib(s.kitti_calib);
    if (!c.has_p3)
      throw Error("--stereo-right with --kitti-calib '" + s.kitti_calib + "': the file has no P3 (the right colour "
                  "camera's projection), which gives the pair's baseline; use the object benchmark's calib file (it "
                  "has P0-P3), or give --fx (px) and --baseline (m)");
    // P2 = K [I | t2], P3 = K [I | t3] (rectified): P[0,3] = fx tx, so B = (P2[0,3] - P3[0,3]) / fx.
    g.f_px = c.P2[0], g.baseline_m = (c.P2[3] - c.P3[3]) / c.P2[0], g.doffs_px = c.P3[2] - c.P2[2];
    if (!(g.baseline_m > 0.0))
      throw Error("--kitti-calib '" + s.kitti_calib + "': P2 and P3 give a baseline of " + text::g(g.baseline_m, 9) +
                  " m ((P2[0,3] - P3[0,3]) / fx); camera 3 must lie to the right of camera 2 (> 0): the file's P2 and "
                  "P3 are exchanged or damaged");
    g.k.fx = c.P2[0], g.k.fy = c.P2[5], g.k.cx = c.P2[2], g.k.cy = c.P2[6];
    g.record = {{"from", "--kitti-calib: f = P2[0,0], B = (P2[0,3] - P3[0,3]) / f, doffs = P3[0,2] - P2[0,2]"},
                {"path", s.kitti_calib}, {"sha256", sha256_file(s.kitti_calib)}};
  } else if (s.k.fx > 0.0 && s.baseline_m > 0.0) {
    g.f_px = s.k.fx, g.baseline_m = s.baseline_m, g.doffs_px = 0.0;
    g.k = s.k;
    g.record = {{"from", "--fx, --baseline"}};
  } else {
    throw Error("--stereo-right beside a sparse source needs the pair's calibration to turn its disparity into "
                "metres: --calib calib.txt (Middlebury 2014 / ETH3D), --kitti-calib with P2 and P3 (KITTI), or --fx "
                "(px) and --baseline (m)");
  }
  g.k = resolve(g.k, width, height);
  g.record["f_px"] = g.f_px, g.record["baseline_m"] = g.baseline_m, g.record["doffs_px"] = g.doffs_px;
  return g;
}

namespace {
LoadedDepth load_depth_as_read(const DepthSource& s, int width, int height);

// A sparse source beside --stereo-right (brume/fuse.hpp): the scan read as
// alone, the pair matched over the range the scan bounds, its disparity
// fitted to the scan.
LoadedDepth fused_depth(const DepthSource& s, int width, int height) {
  if (s.stereo_left.empty())
    throw Error("--stereo-right '" + s.stereo_right + "' needs the pair's left view: give --image FILE (the left view; "
                "depth prepare also takes --stereo-left FILE)");
  DepthSource scan = s;
  scan.stereo_right.clear(), scan.stereo_left.clear();
  scan.stereo_right_layer.clear(), scan.stereo_left_layer.clear();
  scan.stereo = StereoParams{};
  LoadedDepth out = load_depth_as_read(scan, width, height);
  const int W = out.range.width, H = out.range.height;
  nlohmann::json lrec, rrec;
  const StereoView L = read_stereo_view(s.stereo_left, "--stereo-left", &lrec, s.stereo_left_layer);
  const StereoView R = read_stereo_view(s.stereo_right, "--stereo-right", &rrec, s.stereo_right_layer);
  for (const StereoView* v : {&L, &R})
    if (v->width != W || v->height != H)
      throw Error((v == &L ? "--image '" + s.stereo_left : "--stereo-right '" + s.stereo_right) + "' is " +
                  std::to_string(v->width) + "x" + std::to_string(v->height) + " but the depth '" + out.path +
                  "' is " + out.range.size_string() + "; the pair and the scan must be the same size (resample the "
                  "views with their calibration, or project the scan at the pair's size)");
  const StereoGeometry g = stereo_geometry(s, W, H);
  StereoParams sp = s.stereo;
  nlohmann::json search;
  if (sp.max_disparity) {
    search = {{"rule", "--max-disparity as given"}, {"max_disparity_px", *sp.max_disparity}};
  } else if (const int bound = stereo_search_bound(out.range, g, W, sp.block, &search); bound > 0) {
    sp.max_disparity = bound;
  } else {
    search = {{"rule", "auto (the scan gives no positive disparity)"}};
  }
  StereoResult st = compute_stereo(L, R, sp, "--image '" + s.stereo_left + "'", "--stereo-right '" + s.stereo_right + "'");
  StereoFill fill = fit_stereo_to_scan(out.range, st, g);
  if (fill.record.contains("warning")) {
    const std::string w = "--stereo-right '" + s.stereo_right + "': " + fill.record["warning"].get<std::string>();
    out.record["warnings"].push_back(w);
    print_warning("", w);
  }
  out.record["stereo"] = {{"left", lrec},      {"right", rrec},   {"geometry", g.record},
                          {"search", search}, {"matching", st.record}, {"fit", fill.record}};
  out.fusion = std::make_shared<const StereoFill>(std::move(fill));
  return out;
}
}  // namespace

std::optional<Intrinsics> source_camera(const DepthSource& s, int width, int height) {
  if (width <= 0 || height <= 0) return std::nullopt;
  if (!s.velodyne.empty()) {
    if (s.kitti_calib.empty()) return std::nullopt;
    return depth_camera(s, width, height).k;
  }
  if (s.k.fx > 0.0 || s.k.fy > 0.0 || !std::isnan(s.fov_x_deg) || !std::isnan(s.fov_y_deg) || !s.calib.empty())
    return depth_intrinsics(s, width, height);
  return std::nullopt;
}

LoadedDepth load_depth(const DepthSource& s, int width, int height) {
  LoadedDepth d = load_depth_as_read(s, width, height);
  d.camera = source_camera(s, d.range.width, d.range.height);
  // --calib is an input whichever source reads it (--z, --range, a depth
  // buffer take the camera from it): brume run checks its hash.
  if (!s.calib.empty() && d.record.is_object() && !d.record.contains("calib"))
    d.record["calib"] = {{"path", s.calib}, {"sha256", sha256_file(s.calib)}};
  return d;
}

namespace {
LoadedDepth load_depth_as_read(const DepthSource& s, int width, int height) {
  const int given = s.sources();
  if (s.fused()) return fused_depth(s, width, height);
  if (given != 1)
    throw Error(given == 0 ? "no depth given: use one of --range, --z, --disparity, --depth-buffer, --inverse-depth, --normalized-depth, --velodyne, --stereo-right"
                           : "give exactly one depth source (--range, --z, --disparity, --depth-buffer, --inverse-depth, --normalized-depth, --velodyne or --stereo-right), or one of them and --stereo-right, which the completion fuses");
  if (!s.stereo_right.empty()) return stereo_depth(s, width, height);
  // The matching's parameters mean nothing to the other sources: one set
  // away from its default is refused rather than ignored.
  for (const auto& d : stereo_param_table().params())
    if (stereo_param_table().is_set(s.stereo, d.spec.name, {}))
      throw Error("--" + d.spec.name + " " + d.spec.format(d.get(s.stereo)) + " is a stereo matching parameter, but "
                  "no --stereo-right was given; drop --" + d.spec.name + " or match a pair with --stereo-right FILE");
  if (!s.stereo_left.empty())
    throw Error("--stereo-left '" + s.stereo_left + "' is the left view of a pair, but no --stereo-right was given; "
                "add --stereo-right FILE, or drop --stereo-left");
  if (!s.stereo_right_layer.empty() || !s.stereo_left_layer.empty())
    throw Error(std::string(s.stereo_right_layer.empty() ? "--stereo-left-layer" : "--stereo-right-layer") +
                " names a layer of a stereo view, but no --stereo-right was given; drop it");
  LoadedDepth out;
  nlohmann::json& rec = out.record;
  FileInfo info;

  if (!s.velodyne.empty()) {
    if (s.unknown_value)
      throw Error("--unknown-value " + text::g(*s.unknown_value, 9) + " does not apply to --velodyne '" + s.velodyne +
                  "': a lidar scan stores points, not a grid with a no-data value (pixels no point hits are "
                  "unknown already); drop --unknown-value");
    if (width <= 0 && !s.like.empty()) {
      const ImageHeader h = read_header(s.like);  // its size only: no pixels are decoded
      width = h.width, height = h.height;
    } else if (width <= 0) {
      width = s.width, height = s.height;
    }
    if (s.kitti_calib.empty()) throw Error("--velodyne needs --kitti-calib FILE (P2, R0_rect, Tr_velo_to_cam)");
    LidarImage li = project_velodyne(s.velodyne, read_kitti_calib(s.kitti_calib), width, height);
    out.range = li.range;
    out.path = s.velodyne;
    rec = {{"source", "velodyne"},
           {"path", s.velodyne},
           {"sha256", sha256_file(s.velodyne)},
           {"kitti_calib", {{"path", s.kitti_calib}, {"sha256", sha256_file(s.kitti_calib)}}},
           {"projection", "P2 R0_rect Tr_velo_to_cam, nearest point per pixel, pixel centres at integers"},
           {"points", li.points},
           {"points_in_view", li.points_in_view},
           {"pixels_hit", li.pixels_hit},
           {"coverage", li.coverage}};
    if (!s.like.empty())  // the image whose size it takes: an input too
      rec["like"] = {{"path", s.like}, {"sha256", sha256_file(s.like)}};
    return out;
  }

  const std::string& path = !s.range.empty() ? s.range : !s.z.empty() ? s.z : !s.disparity.empty() ? s.disparity
                          : !s.depth_buffer.empty() ? s.depth_buffer : !s.inverse_depth.empty() ? s.inverse_depth
                          : s.normalized_depth;
  out.path = path;
  const char* flag = !s.range.empty() ? "--range" : !s.z.empty() ? "--z" : !s.disparity.empty() ? "--disparity"
                   : !s.depth_buffer.empty() ? "--depth-buffer" : !s.inverse_depth.empty() ? "--inverse-depth"
                   : "--normalized-depth";
  ScalarRead how;
  how.channel = s.channel;
  how.channel_flag = "--depth-channel";
  how.depth = true;
  how.rule = s.channel_rule;
  Image v = read_scalar(path, how, &info);
  if (width > 0 && (v.width != width || v.height != height))
    throw Error("depth '" + path + "' is " + v.size_string() + " but the image is " + std::to_string(width) + "x" +
                std::to_string(height) + "; they must be the same size (resample the depth, or crop both)");
  const std::string read_channel = info.channels_read.empty() ? std::string() : info.channels_read.front();
  if (!s.range.empty() && info.blender && is_depth_pass_name(read_channel))
    throw Error("--range '" + path + "': its channel " + read_channel + " is Blender's Depth (Z) pass, which is "
                "planar depth -- the distance along the camera's axis (constant along a level ground row; Cycles and "
                "Eevee alike), not along each pixel's ray -- so as a range it would be short by 1/cos of each "
                "ray's angle. Give it as --z '" + path + "' with the camera (--focal-length MM --sensor-width MM, "
                "as Blender's camera states them, or --fov-x DEG)");
  rec = file_record(path, info, v);
  rec["channel"] = read_channel;
  rec["channel_rule"] = info.channel_rule;
  if (s.unknown_value) {
    // Before any scaling or conversion, so V is what the file stores (and what
    // a dataset's documentation names), whatever the --depth-scale.
    const float sentinel = static_cast<float>(*s.unknown_value);
    std::size_t marked = 0;
    for (float& x : v.data)
      if (x == sentinel) x = NAN, ++marked;
    rec["unknown_value"] = *s.unknown_value;
    rec["unknown_value_pixels"] = marked;
  }
  const bool distance = !s.range.empty() || !s.z.empty();
  if (distance && s.render_background == RenderBackground::automatic && !info.integer) {
    // As stored, before any scaling (like --unknown-value); integer files
    // hold counts, whose 65504 is a distance.
    std::size_t marked = 0;
    for (float& x : v.data)
      if (is_render_background(x)) x = NAN, ++marked;
    rec["render_background"] = {{"rule", kRenderBackgroundRule}, {"pixels", marked}};
  } else if (distance) {
    rec["render_background"] = {{"rule", s.render_background == RenderBackground::off
                                              ? "off: every stored value read as a distance"
                                              : "integer file: its counts are distances"},
                                {"pixels", 0}};
  }

  auto metres = [&](const char* what) {
    if (info.integer && !s.depth_scale)
      throw Error(std::string(what) + " '" + path + "' stores " + std::to_string(info.bits) +
                  "-bit integers; say how many metres one count is with --depth-scale (alias --range-scale), "
                  "e.g. 0.001 for millimetres, 0.00390625 (1/256) for KITTI depth PNGs");
    const double sc = s.depth_scale.value_or(1.0);
    if (!(sc > 0.0) || !std::isfinite(sc))
      throw Error("--depth-scale " + std::to_string(sc) + " is not allowed: metres per unit must be finite and > 0");
    for (float& x : v.data) {
      if (info.integer && x == 0.0f) x = NAN;  // 0 = no measurement in integer depth files
      else x = static_cast<float>(x * sc);
    }
    rec["scale_m_per_unit"] = sc;
  };

  if (!s.range.empty()) {
    rec["source"] = "range";
    refuse_negative(v, "--range", path, s);
    metres("--range");
    out.range = std::move(v);
  } else if (!s.z.empty()) {
    rec["source"] = "planar z";
    refuse_negative(v, "--z", path, s);
    metres("--z");
    Intrinsics k = depth_intrinsics(s, v.width, v.height);
    rec["intrinsics"] = intrinsics_record(k);
    out.range = z_to_range(v, k);
  } else if (!s.disparity.empty()) {
    rec["source"] = "disparity";
    if (info.integer)  // Middlebury 2005/2006 PNGs: 0 = unknown, d = scale * I + offset
      for (float& x : v.data) x = x == 0.0f ? NAN : static_cast<float>(s.disparity_scale * x);
    else if (s.disparity_scale != 1.0)
      for (float& x : v.data) x = static_cast<float>(s.disparity_scale * x);
    out.range = disparity_range(v, s, "--disparity '" + path + "'", s.disparity_scale, rec);
  } else if (!s.depth_buffer.empty()) {
    rec["source"] = "depth buffer";
    unorm(v, info);
    const DepthBufferConvention c = parse_depth_buffer_convention(s.convention);
    if (std::isnan(s.near_m) || std::isnan(s.far_m))
      throw Error("--depth-buffer needs --near and --far (metres; --far inf for an infinite far plane)");
    Intrinsics k = depth_intrinsics(s, v.width, v.height);
    rec["convention"] = s.convention, rec["near_m"] = s.near_m;
    rec["far_m"] = std::isinf(s.far_m) ? nlohmann::json("inf") : nlohmann::json(s.far_m);
    rec["intrinsics"] = intrinsics_record(k);
    out.range = z_to_range(depth_buffer_to_z(v, c, s.near_m, s.far_m), k);
    out.window_depth = std::move(v);
  } else if (!s.inverse_depth.empty()) {
    rec["source"] = "inverse depth";
    unorm(v, info);
    if (std::isnan(s.inverse_scale))
      throw Error("--inverse-depth needs --inverse-scale A (and --inverse-shift B): z = 1 / (A v + B); monocular "
                  "estimates are defined only up to these, so brume never guesses them");
    Intrinsics k = depth_intrinsics(s, v.width, v.height);
    rec["formula"] = "z = 1 / (scale v + shift)", rec["scale"] = s.inverse_scale, rec["shift"] = s.inverse_shift;
    rec["intrinsics"] = intrinsics_record(k);
    out.range = z_to_range(inverse_depth_to_z(v, s.inverse_scale, s.inverse_shift), k);
  } else {
    rec["source"] = "normalized depth";
    unorm(v, info);
    if (std::isnan(s.near_m) || std::isnan(s.far_m))
      throw Error("--normalized-depth needs --near and --far (metres): z = near + v (far - near)");
    Intrinsics k = depth_intrinsics(s, v.width, v.height);
    rec["formula"] = "z = near + v (far - near)", rec["near_m"] = s.near_m, rec["far_m"] = s.far_m;
    rec["intrinsics"] = intrinsics_record(k);
    out.range = z_to_range(normalized_depth_to_z(v, s.near_m, s.far_m), k);
  }
  std::size_t unknown = 0;
  float largest = 0.0f;
  for (float x : out.range.data) {
    const bool known = std::isfinite(x) && x > 0.0f;
    unknown += known ? 0 : 1;
    if (known && x > largest) largest = x;
  }
  rec["unknown_pixels"] = unknown;
  if (largest > kPlausibleDistanceMax) {
    // One plausibility rule: no scene brume renders reaches 1000 km; such a
    // value is a background marker or a unit error.
    const std::string w = std::string(flag) + " '" + path + "': the largest distance is " + text::g(largest, 9) +
                          " m, beyond " + text::g(kPlausibleDistanceMax, 9) + " m: a renderer's or dataset's \"no surface\" "
                          "value read as a distance (give it as --unknown-value V" +
                          (distance && s.render_background == RenderBackground::off ? ", or --renderer-background auto" : "") +
                          "), or the wrong unit (--depth-scale)";
    rec["warnings"].push_back(w);
    print_warning("", w);
  }
  return out;
}
}  // namespace

}  // namespace brume
