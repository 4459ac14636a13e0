// brume — the steps every effect's pipeline shares (see brume/pipeline.hpp).
#include "pipeline/scan_job.hpp"
#include "brume/pipeline.hpp"
#include "brume/command.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <malloc.h>
#include <mutex>
#include <set>
#include <unistd.h>

#include "brume/error.hpp"
#include "brume/gpu_context.hpp"
#include "brume/medium.hpp"
#include "brume/record.hpp"
#include "core/text.hpp"
#include "core/timing.hpp"
#include "depth/sky_check.hpp"
#include "core/warnings.hpp"

namespace fs = std::filesystem;

namespace brume {

// glibc returns large buffers (128 kB up to its dynamic 32 MB threshold) to
// the kernel when they are freed, and the next allocation faults fresh
// pages in, cleared by the kernel. Measured with the heap kept (README
// "Speed" and "Datasets"): 30 Middlebury haze frames on one thread 2.6 ->
// 2.0 s (AMD EPYC, 2026-12-01); a single 1600 x 1120 demo haze run, whose
// blur and preparation free and allocate image-sized buffers, ~384 -> ~348
// ms whole (Zen 4, 2026-12-03, medians of 12 alternated runs; the effect
// ~135 -> ~117 ms), peak RSS +2.5 MB.
void keep_freed_heap() {
  static const bool once = [] {
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
    return true;
  }();
  (void)once;
}

// ---- name tables ------------------------------------------------------------------
const EnumNames<PrepareMode>& prepare_mode_names() {
  static const EnumNames<PrepareMode> n = {{PrepareMode::automatic, "auto"}, {PrepareMode::off, "off"}};
  return n;
}

const EnumNames<CompleteMode>& complete_mode_names() {
  static const EnumNames<CompleteMode> n = {
      {CompleteMode::automatic, "auto"}, {CompleteMode::off, "off"}, {CompleteMode::on, "on"}};
  return n;
}

const EnumNames<OutAlpha>& out_alpha_names() {
  static const EnumNames<OutAlpha> n = {{OutAlpha::automatic, "auto"}, {OutAlpha::off, "off"}};
  return n;
}

const EnumNames<LayerRule>& layer_rule_names() {
  static const EnumNames<LayerRule> n = {{LayerRule::names, "names"}, {LayerRule::first, "first"}};
  return n;
}

const EnumNames<NonFinite>& nonfinite_names() {
  static const EnumNames<NonFinite> n = {{NonFinite::error, "error"}, {NonFinite::zero, "zero"}};
  return n;
}

// ---- shared blocks -----------------------------------------------------------------
namespace {
// The --compression help, from the table of formats (built once: the specs
// hold C strings).
const char* compression_help_text() {
  static const std::string help = compression_help();
  return help.c_str();
}
}  // namespace

namespace {

ParamTable<Intrinsics> intrinsics_table() {
  ParamTable<Intrinsics> k("depth");
  k.real_or_unset("fx", &Intrinsics::fx, "px", Range::above(0.0), "focal length in pixels (x)", 0.0)
      .real_or_unset("fy", &Intrinsics::fy, "px", Range::above(0.0), "focal length in pixels (y); auto: --fx", 0.0)
      .real_or_unset("cx", &Intrinsics::cx, "px", Range::any(),
                     "principal point x; auto: (W-1)/2 (pixel centres at integers)", NAN)
      .real_or_unset("cy", &Intrinsics::cy, "px", Range::any(), "principal point y; auto: (H-1)/2", NAN);
  return k;
}

}  // namespace

const ParamTable<LensCamera>& lens_param_table(const std::string& block) {
  static std::map<std::string, ParamTable<LensCamera>> cache;
  static std::mutex mu;
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache.find(block);
  if (it != cache.end()) return it->second;
  ParamTable<LensCamera> d(block);
  // Depth of field's lens was its own until schema 4 (--focal-length and
  // --sensor-width of `brume dof`, --dof-focal-length and --dof-sensor-width
  // of the haze+dof chain): the depth block's lens keeps those spellings and
  // reads those records.
  const bool depth = block == "depth";
  d.real("focal-length", &LensCamera::focal_length_mm, "mm", Range::above(0.0),
         "focal length F of the camera in millimetres, as 3D software states it (with --sensor-width): fx = fy = F s "
         "/ sensor, s the side the sensor fit spans (docs/renderers.md)", "none");
  if (depth) d.formerly("dof.focal-length").formerly("dof.dof-focal-length").alias("dof-focal-length");
  d.real("sensor-width", &LensCamera::sensor_width_mm, "mm", Range::above(0.0),
         "sensor width; with --sensor-fit auto it spans the image's larger side, with horizontal the image width "
         "(Blender's Camera > Sensor > Size)", "none");
  if (depth) d.formerly("dof.sensor-width").formerly("dof.dof-sensor-width").alias("dof-sensor-width");
  d.real("sensor-height", &LensCamera::sensor_height_mm, "mm", Range::above(0.0),
            "sensor height, used with --sensor-fit vertical (it spans the image height)", "none")
      .choice("sensor-fit", &LensCamera::sensor_fit, sensor_fit_names(),
              "which image side the sensor spans, as Blender's Sensor Fit: auto (the sensor width spans the larger "
              "side), horizontal (the width spans the image width), vertical (the height spans the image height)")
      .since(4, "horizontal")
      .pair("lens-shift", &LensCamera::lens_shift, "1", Range::closed(-10.0, 10.0),
            "Blender's lens shift X,Y in units of the side the sensor fit spans (auto: the larger side): cx = (W-1)/2 "
            "- X s, cy = (H-1)/2 + Y s");
  return cache.emplace(block, std::move(d)).first->second;
}

const ParamTable<DepthSource>& depth_param_table() {
  static const ParamTable<DepthSource> t = [] {
    ParamTable<DepthSource> d("depth");
    d.text("range", &DepthSource::range, "range map: metres from the camera centre along each pixel's ray; NaN, inf, 0 unknown")
        .reads_file()
        .text("z", &DepthSource::z, "planar depth map in metres (needs --fx.. or --fov-x/--fov-y or --calib)")
        .reads_file()
        .text("disparity", &DepthSource::disparity, "stereo disparity in px: PFM with --calib calib.txt, or a PNG with --fx --baseline")
        .reads_file()
        .text("depth-buffer", &DepthSource::depth_buffer, "rasteriser window depth in [0,1] (--near --far --convention, --fov-y..)")
        .reads_file()
        .text("inverse-depth", &DepthSource::inverse_depth, "monocular inverse depth: z = 1/(--inverse-scale v + --inverse-shift)")
        .reads_file()
        .text("normalized-depth", &DepthSource::normalized_depth, "monocular depth in [0,1]: z = --near + v (--far - --near)")
        .reads_file()
        .text("velodyne", &DepthSource::velodyne, "KITTI Velodyne scan (.bin) projected with --kitti-calib")
        .reads_file()
        .text("stereo-right", &DepthSource::stereo_right,
              "right view of a rectified pair: disparity matched (SGBM, docs/depth.md) and converted as --disparity's "
              "(--calib, or --fx --baseline); the left view is --image")
        .reads_file()
        .text("stereo-left", &DepthSource::stereo_left,
              "left view for --stereo-right where no --image is given (depth convert, depth prepare); default --image")
        .reads_file()
        .text("stereo-right-layer", &DepthSource::stereo_right_layer,
              "the layer of --stereo-right in a file with layers (NAME.R, NAME.G, NAME.B of a multilayer OpenEXR)")
        .text("stereo-left-layer", &DepthSource::stereo_left_layer,
              "the layer of --stereo-left in a file with layers (with --image: --image-layer)")
        .nest(&DepthSource::stereo, stereo_param_table())
        .text("depth-channel", &DepthSource::channel, "channel holding the depth in a multi-channel file (e.g. Z)")
        .alias("range-channel")
        .choice("depth-channel-rule", &DepthSource::channel_rule, layer_rule_names(),
                "how a depth file with layers is read when no --depth-channel is given: names (its one channel named "
                "like a depth pass -- Z, depth, *.depth, *.Depth.Z --, never a Mist pass) or first (its one channel, "
                "or R of equal R, G, B: the rule of records before schema 4)")
        .since(4, "first")
        .real("depth-scale", &DepthSource::depth_scale, "m", Range::above(0.0),
              "metres per stored unit; required for integer range/z files (0.001 mm, 0.00390625 KITTI)", "none")
        .alias("range-scale")
        .real("unknown-value", &DepthSource::unknown_value, "file units", Range::any(),
              "stored value marking unknown pixels (sky, no data; GeoPose3K: -1), exact match before any scaling", "none")
        .choice("renderer-background", &DepthSource::render_background, render_background_names(),
                "renderers' 'no surface' values in float --range and --z files: auto (stored values >= 1e9 -- Cycles "
                "writes 1e10 --, exactly 65504 -- Eevee, half float's largest -- and +-inf are unknown, i.e. sky; "
                "compared as stored, before --depth-scale) or off (read as distances)")
        .since(4, "off")
        .nest(&DepthSource::k, intrinsics_table())
        .real_or_unset("fov-x", &DepthSource::fov_x_deg, "deg", Range::left_open(0.0, 180.0),
                       "horizontal field of view, edge to edge", NAN)
        .real_or_unset("fov-y", &DepthSource::fov_y_deg, "deg", Range::left_open(0.0, 180.0),
                       "vertical field of view, edge to edge", NAN)
        .nest(&DepthSource::lens, lens_param_table("depth"))
        .text("calib", &DepthSource::calib,
              "Middlebury 2014 / ETH3D calib.txt (cam0, doffs, baseline in mm), or KITTI depth completion's "
              "intrinsics/*.txt (the 3x3 K as 9 numbers: the camera without a baseline, for --z and --range)")
        .reads_file("", 0, 4)
        .real_or_unset("baseline", &DepthSource::baseline_m, "m", Range::above(0.0),
                       "stereo baseline (without --calib)", NAN)
        .real("disparity-scale", &DepthSource::disparity_scale, "1", Range::any(),
              "disparity = scale * stored value + --disparity-offset")
        .real("disparity-offset", &DepthSource::disparity_offset, "px", Range::any(),
              "doffs / Middlebury 2005 dmin, in px of the disparity map")
        .choice("convention", &DepthSource::convention, {"opengl", "d3d", "reversed-z"}, "depth-buffer convention")
        .real_or_unset("near", &DepthSource::near_m, "m", Range::any(), "near plane (depth buffers, normalised depth)", NAN)
        .real_or_unset("far", &DepthSource::far_m, "m", Range::any(),
                       "far plane; inf = infinite far plane (depth buffers)", NAN)
        .infinite()
        .real_or_unset("inverse-scale", &DepthSource::inverse_scale, "1/m", Range::any(), "A in z = 1/(A v + B)", NAN)
        .real("inverse-shift", &DepthSource::inverse_shift, "1/m", Range::any(), "B in z = 1/(A v + B)")
        .text("kitti-calib", &DepthSource::kitti_calib,
              "KITTI calibration file (calib/N.txt, or an odometry sequence's calib.txt): --velodyne's projection, "
              "--stereo-right's baseline, and rain's and snow's --poses and scan frame")
        .reads_file("", 0, 4)
        .text("like", &DepthSource::like, "image whose size a --velodyne scan is projected to (when no --image is given)")
        .reads_file("", 0, 5)
        .integer("width", &DepthSource::width, "px", Range::closed(0, 65535), "image width for --velodyne; 0: from --like")
        .integer("height", &DepthSource::height, "px", Range::closed(0, 65535), "image height for --velodyne; 0: from --like");
    return d;
  }();
  return t;
}

Exec ExecOptions::exec() const {
  Exec e;
  e.threads = threads;
  e.path = reference ? Path::reference : Path::fast;
  e.backend = backend;
  e.gpu_filter = gpu_filter;
  e.gpu = gpu;
  if (reference && backend != Backend::cpu)
    throw Error("--reference is the CPU's double-precision path; it cannot be combined with --backend " +
                enum_name(backend_names(), backend));
  return e;
}

const ParamTable<ExecOptions>& exec_param_table() {
  static const ParamTable<ExecOptions> t = [] {
    ParamTable<ExecOptions> d("execution");
    d.integer("threads", &ExecOptions::threads, "1", Range::closed(0, 4096),
              "worker threads (0 = all cores); results do not depend on it")
        .boolean("reference", &ExecOptions::reference, "use the scalar double-precision reference path (slow; for checking)")
        .choice("backend", &ExecOptions::backend, backend_names(),
                "cpu, gpu (any OpenGL ES 3.2 context, software ones included) or auto (a hardware GPU when there "
                "is one, else the CPU)")
        .choice("gpu-filter", &ExecOptions::gpu_filter, gpu_filter_names(),
                "GPU interpolation between texels: auto, hardware (texture units), shader (exact float weights)")
        .boolean("timing", &ExecOptions::timing, "print the time of each pass (GPU timer queries where available)");
    return d;
  }();
  return t;
}

const ParamTable<InputFiles>& input_param_table(bool with_depth) {
  static const auto make = [](bool depth) {
    ParamTable<InputFiles> d("input");
    d.text("image", &InputFiles::image, "input colour image (PNG, JPEG, TIFF, EXR, PFM, HDR)")
        .reads_file()
        .text("image-layer", &InputFiles::image_layer,
              "the layer of a file with layers read as the colour image: NAME.R, NAME.G, NAME.B (and NAME.A) of a "
              "multilayer OpenEXR, e.g. ViewLayer.Combined (Blender), or a multi-part file's part; empty: the plain "
              "R, G, B, or the file's only colour layer (a file with several is refused, listing them)")
        .choice("image-layer-rule", &InputFiles::image_layer_rule, layer_rule_names(),
                "how --image is read when it has layers and no --image-layer is given: names (its only colour layer, "
                "else refused with the list) or first (its first three channels in the file's order, the rule of "
                "records before schema 4)")
        .since(4, "first");
    transfer_param(d, "image-transfer", &InputFiles::image_transfer,
                   "the input")
        .choice("nonfinite", &InputFiles::nonfinite, nonfinite_names(),
                "NaN or inf in the colour image: error (default; names the count and the first pixel) or zero "
                "(replaced by 0, the count recorded)");
    if (depth) d.nest(&InputFiles::depth, depth_param_table());
    return d;
  };
  static const ParamTable<InputFiles> with = make(true), without = make(false);
  return with_depth ? with : without;
}

const ParamTable<RangeStep>& range_step_param_table() {
  static const ParamTable<RangeStep> t = [] {
    ParamTable<RangeStep> d("prepare");
    d.choice("prepare", &RangeStep::mode, prepare_mode_names(),
             "auto: fill holes, identify and matte the sky (Hansard 4.1) when the range has unknown pixels; "
             "off: the effect sees unknown range as it is (haze: R_max; fog: sky, integrated along the ray)")
        .nest(&RangeStep::params, prepare_param_table())
        .choice("complete", &RangeStep::complete, complete_mode_names(),
                "depth completion guided by the image (brume depth complete): auto (complete a map whose known "
                "pixels cover less than --min-coverage, e.g. a lidar scan, instead of refusing it; only when "
                "--prepare auto), on (always), off (never)")
        .nest(&RangeStep::completion, complete_param_table());
    return d;
  }();
  return t;
}

const ParamTable<SceneScale>& scene_scale_param_table() {
  static const ParamTable<SceneScale> t = [] {
    ParamTable<SceneScale> d("scene");
    d.real("scene-scale", &SceneScale::reference_m, "m", Range::above(0.0),
           "the median range R_ref the effect's lengths are given for: the run scales them by this frame's median "
           "range over R_ref (15 suits the sampled defaults; docs/transforms.md); off: the lengths are metres",
           "off");
    return d;
  }();
  return t;
}

double median_known_range(ConstImageView range) {
  std::vector<float> known;
  known.reserve(static_cast<std::size_t>(range.width()) * static_cast<std::size_t>(range.height()));
  for (int y = 0; y < range.height(); ++y)
    for (int x = 0; x < range.width(); ++x) {
      const float r = range.at(x, y);
      if (std::isfinite(r) && r > 0.0f) known.push_back(r);
    }
  if (known.empty()) return NAN;
  const std::size_t mid = known.size() / 2;
  std::nth_element(known.begin(), known.begin() + static_cast<std::ptrdiff_t>(mid), known.end());
  double m = known[mid];
  if (known.size() % 2 == 0) {  // the mean of the two middle values
    const float below = *std::max_element(known.begin(), known.begin() + static_cast<std::ptrdiff_t>(mid));
    m = 0.5 * (static_cast<double>(below) + m);
  }
  return m;
}

const ParamTable<OutputFiles>& output_param_table(const std::vector<MapOutput>& maps, bool main_required) {
  // One table per distinct declaration list (effects keep theirs static).
  static std::map<std::string, ParamTable<OutputFiles>> cache;
  std::string key = main_required ? "1" : "0";
  for (const auto& m : maps) key += std::string("|") + m.name;
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  ParamTable<OutputFiles> d("output");
  d.text("out", &OutputFiles::out, "output image (.png .jpg .tif .exr .pfm .hdr)")
      .writes_file()
      .choice("bits", &OutputFiles::bits, {"auto", "8", "16", "half", "float"},
              "output storage: auto (PNG/TIFF: the input's 8 or 16 bits, else 16; JPEG 8; EXR/PFM/HDR float)")
      .choice("out-transfer", &OutputFiles::transfer, transfer_names(),
              "transfer function of the output: auto (sRGB for 8/16-bit, linear for float), srgb, linear")
      .text("compression", &OutputFiles::compression, compression_help_text())
      .choice("out-alpha", &OutputFiles::alpha, out_alpha_names(),
              "an OpenEXR output's alpha: auto (the input's alpha, when it has one, as the medium composes it: "
              "A' = T A + (1 - T), premultiplied over) or off (R, G, B only)")
      .since(4, "off")
      .boolean("keep-layers", &OutputFiles::keep_layers,
               "OpenEXR output for a compositor: every other channel of the input as stored, the medium as its own "
               "RGBA layer (<view>.Medium: (1 - T) B, 1 - T) and the maps as layers (<view>.Transmission, "
               "<view>.BlurScale, ...) beside the colour layer")
      .text("record", &OutputFiles::record, "write a JSON record of every parameter, derived value and input hash")
      .writes_file();
  for (const MapOutput& m : maps) {
    ParamSpec s;
    s.name = m.name;
    s.kind = ParamKind::text;
    s.output_file = true;
    s.help = m.help;
    const std::string name = m.name;
    d.custom(
        s,
        [name](const OutputFiles& o) {
          auto f = o.maps.find(name);
          return nlohmann::json(f == o.maps.end() ? std::string() : f->second);
        },
        [name](OutputFiles& o, const nlohmann::json& v) {
          const std::string path = v.get<std::string>();
          if (path.empty()) o.maps.erase(name); else o.maps[name] = path;
        });
  }
  return cache.emplace(key, std::move(d)).first->second;
}

bool is_output_file(const ParamSpec& s) { return s.output_file; }

bool is_input_file(const ParamSpec& s) {
  if ((s.block != "input" && s.block != "depth") || s.kind != ParamKind::text) return false;
  // How a file is read, not a file: --image-layer, --image-transfer (whose
  // table:FILE the record hashes with the image: file_record).
  const auto ends_with = [&n = s.name](const std::string& suffix) {
    return n.size() > suffix.size() && n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  return s.name != "depth-channel" && !ends_with("-layer") && !ends_with("-transfer");
}

std::vector<ArrayArg> rgb_range_args(ArrayArg::As as) {
  return {{"rgb", 3, false, as}, {"range", 1, false, as}};
}

const std::vector<std::string>& camera_intrinsics_params() {
  static const std::vector<std::string> n = {"fx", "fy", "cx", "cy", "fov-x", "fov-y"};
  return n;
}

const std::set<std::string>& depth_file_params() {
  static const std::set<std::string> skip = [] {
    // The intrinsics as numbers, the calibration file, and the camera in
    // millimetres (focal length, sensor, fit, lens shift).
    std::set<std::string> keep(camera_intrinsics_params().begin(), camera_intrinsics_params().end());
    keep.insert("calib");
    for (const auto& d : lens_param_table("depth").params()) keep.insert(d.spec.name);
    std::set<std::string> s;
    for (const auto& d : depth_param_table().params())
      if (!keep.count(d.spec.name)) s.insert(d.spec.name);
    return s;
  }();
  return skip;
}


// ---- steps ---------------------------------------------------------------------------
RunPhases& run_phases() {
  thread_local RunPhases p;
  return p;
}

std::size_t check_nonfinite_colour(ConstImageView rgb, NonFinite mode, const std::string& what,
                                   const std::string& fix) {
  std::size_t bad = 0;
  int fx = 0, fy = 0, fc = 0;
  float fv = 0.0f;
  const int nc = rgb.channels();
  for (int y = 0; y < rgb.height(); ++y) {
    const float* r = rgb.row(y);
    for (int x = 0; x < rgb.width(); ++x)
      for (int c = 0; c < nc; ++c) {
        const float v = r[x * rgb.pixel_stride() + c];
        if (std::isfinite(v)) continue;
        if (bad++ == 0) fx = x, fy = y, fc = c, fv = v;
      }
  }
  if (bad > 0 && mode == NonFinite::error)
    throw Error(what + " has " + std::to_string(bad) + " non-finite value" + (bad == 1 ? "" : "s") +
                " (NaN or inf); the first is " + (std::isnan(fv) ? "NaN" : fv > 0 ? "+inf" : "-inf") + " at x " +
                std::to_string(fx) + ", y " + std::to_string(fy) + " (row 0 at the top), channel " +
                std::to_string(fc) + "; a blur would smear it over its neighbourhood. " + fix +
                " to replace them by 0");
  return bad;
}

void replace_nonfinite(Image& rgb) {
  for (float& f : rgb.data)
    if (!std::isfinite(f)) f = 0.0f;
}

LoadedInputs load_inputs(const InputFiles& in, bool with_depth) {
  if (in.image.empty()) throw Error("no colour image given: use --image FILE");
  const auto t0 = std::chrono::steady_clock::now();
  struct Phase {
    std::chrono::steady_clock::time_point t0;
    ~Phase() {
      run_phases().read_ms += ms_since(t0);
      run_phases().read_end = std::chrono::steady_clock::now();
    }
  } phase{t0};
  LoadedInputs L;
  ColorRead how;
  how.transfer = in.image_transfer;
  how.layer = in.image_layer;
  how.rule = in.image_layer_rule;
  L.rgb = read_color(in.image, how, &L.image_info, &L.alpha);
  L.record["image"] = file_record(in.image, L.image_info, L.rgb);
  const std::size_t bad = check_nonfinite_colour(L.rgb, in.nonfinite, "--image '" + in.image + "'",
                                                 "Fix the file, or pass --nonfinite zero");
  if (bad > 0) {
    replace_nonfinite(L.rgb);
    L.record["image"]["nonfinite_replaced"] = bad;
  }
  if (with_depth) {
    DepthSource ds = in.depth;
    if (!ds.stereo_right.empty()) {  // the pair's left view is the image itself
      if (!ds.stereo_left.empty() && ds.stereo_left != in.image)
        throw Error("--stereo-left '" + ds.stereo_left + "' differs from --image '" + in.image +
                    "': the matched depth belongs to the left view, so an effect takes the image as the left view; "
                    "drop --stereo-left");
      ds.stereo_left = in.image;
      if (!ds.stereo_left_layer.empty() && ds.stereo_left_layer != in.image_layer)
        throw Error("--stereo-left-layer '" + ds.stereo_left_layer + "' differs from --image-layer '" + in.image_layer +
                    "': the left view is the image itself; drop --stereo-left-layer");
      ds.stereo_left_layer = in.image_layer;
    }
    L.depth = load_depth(ds, L.rgb.width, L.rgb.height);
    L.depth.offset_scan = !ds.velodyne.empty();
    if (L.depth.range.width != L.rgb.width || L.depth.range.height != L.rgb.height)
      throw Error("depth '" + L.depth.path + "' is " + L.depth.range.size_string() + " but --image '" + in.image +
                  "' is " + L.rgb.size_string() + "; they must be the same size (resample the depth map, or crop both)");
    L.record["depth"] = L.depth.record;
  }
  return L;
}

void check_airlight_sky(const LoadedInputs& in, const std::string& effect) {
  if (in.alpha.empty() || in.depth.range.empty() || in.alpha.pixels() != in.depth.range.pixels()) return;
  std::size_t unknown = 0, clear = 0;
  for (std::size_t i = 0; i < in.alpha.pixels(); ++i)
    if (!known_range(in.depth.range.data[i])) {
      ++unknown;
      clear += in.alpha.data[i] < 0.5f ? 1 : 0;
    }
  if (unknown * 200 < in.alpha.pixels() || clear * 2 < unknown) return;
  throw Error(effect + ": --image '" + in.image_info.path + "' is transparent where it has no depth (alpha < 1/2 on " +
              std::to_string(clear) + " of its " + std::to_string(unknown) + " sky pixels: a render with a transparent "
              "film), so its sky's colour, 0 there, cannot give the airlight; give the medium's colour with --airlight "
              "R,G,B (linear; Blender: the World's colour)");
}

void check_working_memory(const std::string& effect, const Image& frame, double bytes_per_pixel) {
  const double bytes = bytes_per_pixel * static_cast<double>(frame.pixels());
  check_memory(static_cast<std::uint64_t>(bytes), effect + " on a " + frame.size_string() + " frame");
}

std::size_t unknown_range_pixels(const Image& range) {
  std::size_t n = 0;
  for (float r : range.data) n += known_range(r) ? 0 : 1;
  return n;
}

void check_range_step(const RangeStep& step, const std::set<std::string>& given) {
  prepare_param_table().validate(step.params);
  complete_param_table().validate(step.completion);
  const bool never = step.complete == CompleteMode::off ||
                     (step.complete == CompleteMode::automatic && step.mode == PrepareMode::off);
  if (never)
    for (const auto& d : complete_param_table().params())
      if (complete_param_table().is_set(step.completion, d.spec.name, given))
        throw Error("--" + d.spec.name + " is a completion parameter, but " +
                    (step.complete == CompleteMode::off ? std::string("--complete off skips the completion")
                                                        : std::string("--complete auto completes only when the "
                                                                      "preparation runs, and --prepare is off")) +
                    "; drop --" + d.spec.name + " or use --complete on");
  if (step.mode == PrepareMode::off)
    for (const auto& d : prepare_param_table().params())
      if (prepare_param_table().is_set(step.params, d.spec.name, given))
        throw Error("--" + d.spec.name + " is a preparation parameter, but --prepare off skips the preparation; "
                    "drop --" + d.spec.name + " or use --prepare auto");
}

PreparedRange prepare_step(const Image& measured, const RangeStep& step, const std::set<std::string>& given,
                           int threads, bool sky_weight) {
  check_range_step(step, given);
  PreparedRange out;
  out.record = {{"mode", enum_name(prepare_mode_names(), step.mode)}, {"applied", false}};
  if (step.mode == PrepareMode::automatic && unknown_range_pixels(measured) > 0) {
    PrepareResult pr = prepare_range(measured, step.params, threads, sky_weight);
    out.record = prepare_record(step.params, pr);
    out.range = std::move(pr.range);
    out.sky_mask = std::move(pr.sky_mask);
    out.sky_weight = std::move(pr.sky_weight);
    out.applied = true;
    out.record["mode"] = "auto";
    out.record["applied"] = true;
  } else {
    out.range = measured;
  }
  return out;
}

PreparedRange prepare_step(ConstImageView measured, const RangeStep& step, const std::set<std::string>& given,
                           int threads, bool sky_weight) {
  check_range_step(step, given);
  std::size_t unknown = 0;
  for (int y = 0; y < measured.height(); ++y)
    for (int x = 0; x < measured.width(); ++x) {
      const float r = measured.at(x, y);
      unknown += (std::isfinite(r) && r != 0.0f) ? 0 : 1;
    }
  if (step.mode == PrepareMode::automatic && unknown > 0) return prepare_step(copy_of(measured), step, given, threads, sky_weight);
  PreparedRange out;
  out.record = {{"mode", enum_name(prepare_mode_names(), step.mode)}, {"applied", false}};
  out.range = copy_of(measured);
  return out;
}

namespace {
// The preparation takes unknown regions as sky by their shape (Hansard 4.1).
// Where a share of the frame of at least kSkyUnderSurfaceWarn among them lies
// below a measured surface of its column (seen under a table, a canopy, a
// bridge: rare for sky), they are likely holes in the depth that an effect
// with its sky beyond the medium paints with the airlight: the completion's
// record says so. Measured (2026-12-07), the share of the frame taken as sky
// and the share below a surface: ETH3D terrace's ground truth 36.7 % and
// 26.7 %, playground_1l 44.9 % and 42.4 %; GeoPose3K's Matterhorn 35.5 % and
// 0, the demo scene 20.1 % and 0 (at 160 x 112 px too).
constexpr double kSkyUnderSurfaceWarn = 0.05;

void warn_sky_under_surfaces(nlohmann::json& record, ConstImageView measured, const RangeStep& step) {
  const PreparedSkyCheck c = check_prepared_sky(measured, step.params);
  if (c.pixels == 0) return;
  const double n = static_cast<double>(c.pixels), under = static_cast<double>(c.under) / n;
  record["prepared_sky_under_surface_fraction"] = under;  // (the share taken as sky: prepare.sky_fraction)
  if (under < kSkyUnderSurfaceWarn) return;
  char pct[160];
  std::snprintf(pct, sizeof pct, "%.1f %% of the frame, and %.1f %% of the frame among them lies", 100.0 * c.sky / n,
                100.0 * under);
  record["warnings"].push_back(
      "the range's unknown regions that the preparation takes as sky (those touching the image's top edge, or "
      "covering at least --sky-large-fraction " + text::g(step.params.sky_large_fraction) + " of it) cover " +
      pct + " below a measured surface of its column: sky seen only under something (a table, a canopy, a "
      "bridge) is rare, so these are likely holes in the depth (shadows, glass, a matcher's gaps) that the effect "
      "treats as sky; give --complete on to complete the range guided by the image (it keeps as sky only bright, "
      "smooth regions reaching the top), or raise --sky-min-fraction and --sky-large-fraction");
}
}  // namespace

bool completes(const RangeStep& step, double known_fraction) {
  return step.complete == CompleteMode::on ||
         (step.complete == CompleteMode::automatic && step.mode == PrepareMode::automatic &&
          known_fraction < step.params.min_coverage);
}

CompletedRange complete_step(ConstImageView measured, ConstImageView rgb, const RangeStep& step,
                             const std::set<std::string>& given, int threads) {
  check_range_step(step, given);
  check_stereo_fattening_given(step.stereo != nullptr, given);
  CompletedRange out;
  out.record = {{"mode", enum_name(complete_mode_names(), step.complete)}, {"applied", false}};
  if (step.stereo && step.complete == CompleteMode::off)
    throw Error("--stereo-right beside a sparse depth source is fused with it by the completion, which --complete off "
                "skips; use --complete auto (or on), or drop one of the two sources");
  if (step.complete == CompleteMode::off || measured.empty()) return out;
  std::size_t known = 0;
  for (int y = 0; y < measured.height(); ++y)
    for (int x = 0; x < measured.width(); ++x) known += known_range(measured.at(x, y)) ? 1 : 0;
  const double fraction = static_cast<double>(known) / static_cast<double>(measured.pixels());
  // A stereo view to fuse: completed whatever the coverage (the fusion is the completion's).
  if (!step.stereo && !completes(step, fraction)) {
    // Checked where its remedy, --complete on, can run: an image beside the map.
    if (step.complete == CompleteMode::automatic && step.mode == PrepareMode::automatic && !rgb.empty() &&
        known < measured.pixels())
      warn_sky_under_surfaces(out.record, measured, step);
    return out;
  }
  if (rgb.empty()) {
    // auto without an image (brume depth prepare without --image): as
    // before completion existed, the preparation refuses the sparse map.
    if (step.complete == CompleteMode::automatic && !step.stereo) return out;
    throw Error("--complete " + enum_name(complete_mode_names(), step.complete) + ": completing the range needs the "
                "colour image that guides it, and none was given (brume depth prepare: give --image FILE)");
  }
  // Dense as they are (a copy only of a strided view, e.g. a numpy slice).
  Image range_copy, guide_copy;
  if (!measured.contiguous()) range_copy = copy_of(measured);
  if (!rgb.contiguous()) guide_copy = copy_of(rgb);
  const DenseImageRef range = range_copy.empty() ? DenseImageRef(measured) : DenseImageRef(range_copy);
  const DenseImageRef guide = guide_copy.empty() ? DenseImageRef(rgb) : DenseImageRef(guide_copy);
  CompleteResult cr = complete_range(range, guide, step.completion, threads, step.camera ? &*step.camera : nullptr);
  nlohmann::json fusion;
  if (step.stereo) fusion = fuse_stereo(cr, range, *step.stereo, step.completion.radius_px,
                                        step.completion.stereo_fattening_px);
  out.record.update(complete_record(step.completion, cr));
  if (step.stereo) out.record["stereo_fusion"] = fusion, out.record["stereo_fusion"]["fit"] = step.stereo->record;
  out.record["applied"] = true;
  out.record["measured_known_fraction"] = fraction;
  out.range = std::move(cr.range);
  out.confidence = std::move(cr.confidence);
  out.applied = true;
  return out;
}

BackendChoice::BackendChoice() = default;
BackendChoice::~BackendChoice() = default;
BackendChoice::BackendChoice(BackendChoice&&) noexcept = default;
BackendChoice& BackendChoice::operator=(BackendChoice&&) noexcept = default;

namespace {
// A note about the backend, printed once per process: a batch's frames would
// otherwise repeat it for every frame.
void note_once(const std::string& text) {
  static std::mutex mu;
  static std::set<std::string> said;
  std::lock_guard<std::mutex> lock(mu);
  if (said.insert(text).second) std::fprintf(stderr, "%s\n", text.c_str());
}
}  // namespace

BackendChoice choose_backend(const Exec& exec) {
  BackendChoice c;
  c.record = {{"backend_requested", enum_name(backend_names(), exec.backend)},
              {"backend", "cpu"},
              {"path", exec.path == Path::reference ? "reference" : "fast"},
              {"threads", exec.threads}};
  if (exec.backend == Backend::cpu) return c;
  if (exec.path == Path::reference)
    throw Error("--reference is the CPU's double-precision path; it cannot be combined with --backend " +
                enum_name(backend_names(), exec.backend));
  GpuContext* g = exec.gpu;
  if (!g) {
    try {
      c.owned = std::make_unique<GpuContext>();
      g = c.owned.get();
    } catch (const Error& e) {
      if (exec.backend == Backend::gpu) throw;
      note_once(std::string("brume: --backend auto: ") + e.what() + "; running on the CPU");
      c.record["gpu_unavailable"] = e.what();
      return c;
    }
  }
  if (exec.backend == Backend::automatic && g->info().software) {
    // Measured here: llvmpipe ran haze 1.7-6x (blur up to 30x) slower than the CPU backend.
    note_once("brume: --backend auto: the GPU '" + g->info().renderer +
              "' is a software rasteriser, slower than the CPU backend; running on the CPU (--backend gpu forces it)");
    c.record["gpu_skipped"] = "software renderer: " + g->info().renderer;
    c.owned.reset();
    return c;
  }
  c.gpu = g;
  c.record["backend"] = "gpu";
  c.record["gpu_filter"] = enum_name(gpu_filter_names(), exec.gpu_filter);
  c.record["gpu"] = {{"renderer", g->info().renderer}, {"version", g->info().version},
                     {"platform", g->info().platform}, {"software", g->info().software}};
  return c;
}

void check_record_path(const std::string& path) { check_output_dir(path, "--record"); }

namespace {

WriteOptions map_options(const MapOutput& m) {
  WriteOptions w;
  w.is_color = false;
  w.bits = "auto";
  w.float_reason = m.float_reason ? m.float_reason : "";
  return w;
}

const MapOutput& declared(const std::vector<MapOutput>& decl, const std::string& name) {
  for (const auto& m : decl)
    if (name == m.name) return m;
  throw Error("internal: output map '" + name + "' is not declared");
}

WriteOptions main_options(const OutputFiles& o) {
  WriteOptions w;
  w.bits = o.bits;
  w.transfer = o.transfer;
  w.compression = o.compression;
  return w;
}

}  // namespace

void check_outputs(const OutputFiles& o, const std::vector<MapOutput>& decl) {
  if (o.out.empty()) throw Error("no output given: use --out FILE");
  check_writable(o.out, main_options(o), "--out");
  if (o.keep_layers) {
    std::string e = fs::path(o.out).extension().string();
    for (char& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (e != ".exr")
      throw Error("--keep-layers writes the input's layers beside the result, which only an OpenEXR file holds, but "
                  "--out '" + o.out + "' is not one: give a .exr output, or drop --keep-layers");
    if (o.transfer == Transfer::srgb)
      throw Error("--keep-layers keeps the input's channels as stored (depth, normals, ...), which --out-transfer "
                  "srgb would encode as colour: drop --out-transfer srgb");
  }
  for (const auto& [name, path] : o.maps) check_writable(path, map_options(declared(decl, name)), "--" + name);
  if (!o.record.empty()) check_record_path(o.record);
}

void write_outputs(const OutputFiles& o, const std::vector<MapOutput>& decl, const Image& main,
                   const std::map<std::string, Image>& maps, const FileInfo* input_info, const nlohmann::json& record,
                   const std::vector<CompanionFile>& companions, const OutputLayers* layers) {
  WriteOptions wo = main_options(o);
  if (wo.bits == "auto" && input_info && input_info->integer && (input_info->bits == 8 || input_info->bits == 16)) {
    std::string e = fs::path(o.out).extension().string();
    for (char& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (e == ".png" || e == ".tif" || e == ".tiff") wo.bits = std::to_string(input_info->bits);
  }
  wo.description = record.dump();
  const auto t0 = std::chrono::steady_clock::now();
  if (run_phases().write_begin == std::chrono::steady_clock::time_point{}) run_phases().write_begin = t0;
  OutputSet outs;
  if (layers && !layers->image.empty()) {
    wo.channel_names = layers->names;
    wo.channel_bits = layers->bits;
    wo.string_attributes = layers->attributes;
    outs.write(o.out, layers->image, wo, "--out");
  } else {
    outs.write(o.out, main, wo, "--out");
  }
  for (const auto& [name, path] : o.maps) {
    auto it = maps.find(name);
    if (it == maps.end()) throw Error("internal: the pipeline made no '" + name + "' map");
    outs.write(path, it->second, map_options(declared(decl, name)), "--" + name);
  }
  for (const CompanionFile& f : companions) outs.write_text(f.path, f.bytes, f.flag);
  if (!o.record.empty()) outs.write_text(o.record, record.dump(2) + "\n", "--record");
  const auto t1 = std::chrono::steady_clock::now();
  run_phases().write_ms += std::chrono::duration<double, std::milli>(t1 - t0).count();
  outs.commit();
  run_phases().rename_ms += ms_since(t1);
}

nlohmann::json gpu_timing_record(const GpuTiming& t) {
  nlohmann::json j = {{"clock", t.gpu_timer ? "timer queries" : "glFinish wall time"}, {"upload_ms", t.upload_ms}};
  if (t.premultiply_ms > 0.0) j["premultiply_ms"] = t.premultiply_ms;
  j["diffusion_ms"] = t.diffuse_ms;
  j["passes"] = t.iterations;
  if (t.composite_ms > 0.0) j["composite_ms"] = t.composite_ms;
  j["read_back_ms"] = t.readback_ms;
  return j;
}

nlohmann::json cpu_timing_record(std::chrono::steady_clock::time_point t0, int iterations) {
  return {{"clock", "wall"},
          {"total_ms", std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count()},
          {"iterations", iterations}};
}

nlohmann::json job_record(const std::string& command, const RunContext& ctx, nlohmann::json job, nlohmann::json inputs,
                          const nlohmann::json& run_record, bool print_timing) {
  nlohmann::json rec = run_record_header(command, ctx.argv);
  rec["job"] = std::move(job);
  rec["inputs"] = std::move(inputs);
  rec.update(run_record);
  if (ctx.extra.is_object()) {
    // A block's inputs join the run's (a camera effect's LiDAR scan), the rest are top-level blocks.
    for (const auto& [k, v] : ctx.extra.items())
      if (k == "inputs" && v.is_object() && rec["inputs"].is_object()) rec["inputs"].update(v);
      else rec[k] = v;
  }
  // The depth's warnings (the completion's record, within the preparation's).
  if (const nlohmann::json::json_pointer at("/prepare/complete/warnings"); rec.contains(at))
    for (const auto& w : rec[at])
      if (w.is_string()) print_warning(command, w.get<std::string>());
  if (print_timing && rec.contains("execution"))
    std::fprintf(stderr, "brume %s: %s: %s\n", command.c_str(), rec["execution"].value("backend", "cpu").c_str(),
                 rec["execution"].value("timing", nlohmann::json::object()).dump().c_str());
  return rec;
}

nlohmann::json run_record_header(const std::string& command, const std::vector<std::string>& argv) {
  nlohmann::json j = record_header(command, argv);
  j["schema_version"] = kRecordSchemaVersion;
  return j;
}

ArrayResult scan_array_result(const ConstImageView& points, const std::string& what,
                              const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*)>& run) {
  std::vector<float> dense;
  const float* src = scan_points(points, what, dense);
  const std::size_t n = static_cast<std::size_t>(points.height());
  std::vector<float> out(4 * n);
  ArrayResult r;
  std::vector<std::uint8_t>& labels = r.bytes["labels"];
  labels.resize(n);
  const std::size_t kept = n - run(src, out.data(), n, labels.data());
  Image pts(4, static_cast<int>(kept), 1);
  std::copy(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(4 * kept), pts.data.begin());
  r.images["points"] = std::move(pts);
  return r;
}

nlohmann::json run_scan_file_job(
    const std::string& command, const RunContext& ctx, const nlohmann::json& job, const ScanFiles& files,
    const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*, const std::string&,
                                    nlohmann::json& blocks)>& run) {
  if (files.points.empty()) throw Error("no scan given: use --points FILE.bin (KITTI velodyne)");
  if (files.out.empty()) throw Error("no output given: use --out FILE.bin");
  check_kitti_bin_output(files.out, "--out");
  if (!files.labels.empty()) check_output_dir(files.labels, "--labels");
  if (!files.record.empty()) check_record_path(files.record);

  const std::vector<float> in = read_kitti_bin(files.points, "--points");
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  std::string labels(n, '\0');
  nlohmann::json blocks = nlohmann::json::object();
  const std::size_t lost = run(in.data(), out.data(), n, reinterpret_cast<std::uint8_t*>(labels.data()),
                               "--points '" + files.points + "'", blocks);
  const nlohmann::json inputs = {
      {"points", {{"path", files.points}, {"sha256", sha256_file(files.points)}, {"points", n}}}};
  const nlohmann::json rec = job_record(command, ctx, job, inputs, blocks, false);
  OutputSet outs;
  outs.write_text(files.out, kitti_bin_bytes(out.data(), n - lost), "--out");
  if (!files.labels.empty()) outs.write_text(files.labels, labels, "--labels");
  if (!files.record.empty()) outs.write_text(files.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  return rec;
}

}  // namespace brume
