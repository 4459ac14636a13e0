// brume — depth sources (see brume/depth_source.hpp).
#include <cmath>
#include <cstdio>
#include <optional>
#include <vector>

#include "brume/depth_source.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/record.hpp"
#include "brume/stereo.hpp"

namespace brume {

int DepthSource::sources() const {
  int n = 0;
  for (const std::string* f :
       {&range, &z, &disparity, &depth_buffer, &inverse_depth, &normalized_depth, &velodyne, &stereo_right})
    n += f->empty() ? 0 : 1;
  return n;
}

Intrinsics depth_intrinsics(const DepthSource& s, int width, int height) {
  if (s.k.fx > 0.0 || s.k.fy > 0.0) return resolve(s.k, width, height);
  if (!std::isnan(s.fov_x_deg) || !std::isnan(s.fov_y_deg)) {
    Intrinsics k = intrinsics_from_fov(width, height, s.fov_x_deg, s.fov_y_deg);
    k.cx = s.k.cx, k.cy = s.k.cy;
    return resolve(k, width, height);
  }
  if (!s.calib.empty()) {
    return resolve(read_calib_camera(s.calib), width, height);
  }
  throw Error("planar depth needs the camera: give --fx (and --fy, --cx, --cy), or --fov-x/--fov-y, or --calib (a "
              "calib.txt, or KITTI depth completion's intrinsics/*.txt)");
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

std::string fmt(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
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
              fmt(v) + " at pixel (" + std::to_string(first % stored.width) + ", " + std::to_string(first / stored.width) +
              "); distances must be > 0 where known (NaN, inf or 0 mark unknown pixels). If " + fmt(v) +
              " marks the sky or missing data (GeoPose3K uses -1), pass --unknown-value " + fmt(v) +
              (s.unknown_value ? " (the --unknown-value " + fmt(*s.unknown_value) + " given matches other values, not this one)" : "") +
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
  const StereoView L = read_stereo_view(s.stereo_left, "--stereo-left", &lrec);
  const StereoView R = read_stereo_view(s.stereo_right, "--stereo-right", &rrec);
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

namespace {
LoadedDepth load_depth_as_read(const DepthSource& s, int width, int height);
}

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
  if (given != 1)
    throw Error(given == 0 ? "no depth given: use one of --range, --z, --disparity, --depth-buffer, --inverse-depth, --normalized-depth, --velodyne, --stereo-right"
                           : "give exactly one depth source (--range, --z, --disparity, --depth-buffer, --inverse-depth, --normalized-depth, --velodyne or --stereo-right)");
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
  LoadedDepth out;
  nlohmann::json& rec = out.record;
  FileInfo info;

  if (!s.velodyne.empty()) {
    if (s.unknown_value)
      throw Error("--unknown-value " + fmt(*s.unknown_value) + " does not apply to --velodyne '" + s.velodyne +
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
  Image v = read_scalar(path, s.channel, &info);
  if (width > 0 && (v.width != width || v.height != height))
    throw Error("depth '" + path + "' is " + v.size_string() + " but the image is " + std::to_string(width) + "x" +
                std::to_string(height) + "; they must be the same size (resample the depth, or crop both)");
  rec = file_record(path, info, v);
  if (!s.channel.empty()) rec["channel"] = s.channel;
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
  for (float x : out.range.data) unknown += std::isfinite(x) && x > 0.0f ? 0 : 1;
  rec["unknown_pixels"] = unknown;
  return out;
}
}  // namespace

}  // namespace brume
