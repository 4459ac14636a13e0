// brume — command-line tool: one subcommand per effect.
//
//   brume haze  --image IMG --range RANGE --out OUT [parameters]
//   brume blur  --image IMG (--sigma S | --scale-map MAP) --out OUT
//   brume demo  --out-dir DIR
//
// Every numeric effect parameter comes from its effect's declaration table
// (brume/params.hpp): flag, unit, default, range and help are declared once.
// Errors name the file or flag, the value, what is allowed and the fix; the
// exit status is non-zero and no output file is left behind.
#include <CLI/CLI.hpp>
#include <chrono>
#include <memory>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <unistd.h>

#include "brume/demo_scene.hpp"
#include "brume/depth_source.hpp"
#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/prepare.hpp"
#include "brume/record.hpp"

namespace fs = std::filesystem;
using namespace brume;

namespace {

const char* const kEdgeRateHelp =
    "edge rate rho(x,u) between a pixel and its neighbour: mean (the paper's eq. 12), min or harmonic "
    "(min and harmonic keep a blurred background from leaking into sharp foreground edges)";

std::vector<std::string> g_argv;

// Add every declared parameter of an effect as a --flag bound to its field.
template <class P>
void add_param_flags(CLI::App* app, P& p, const std::vector<ParamDecl<P>>& table,
                     std::map<std::string, CLI::Option*>* opts = nullptr) {
  for (const auto& d : table) {
    CLI::Option* o = app->add_option(std::string("--") + d.name, p.*(d.field), describe(d))
                         ->capture_default_str()
                         ->type_name("NUM");
    if (opts) (*opts)[d.name] = o;
  }
}

std::array<float, 3> parse_rgb(const std::string& s, const std::string& flag) {
  std::array<float, 3> v{};
  std::stringstream ss(s);
  std::string item;
  int n = 0;
  while (std::getline(ss, item, ',')) {
    if (n >= 3) n = 4;
    if (n < 3) {
      try {
        std::size_t used = 0;
        v[n] = std::stof(item, &used);
        if (used != item.size()) throw std::invalid_argument("junk");
      } catch (const std::exception&) {
        throw Error(flag + " '" + s + "': '" + item + "' is not a number; give R,G,B in linear light, e.g. 0.8,0.82,0.85, or auto");
      }
    }
    ++n;
  }
  if (n != 3) throw Error(flag + " '" + s + "' must be three comma-separated numbers R,G,B (linear light) or auto");
  for (float c : v)
    if (!std::isfinite(c) || c < 0.0f)
      throw Error(flag + " '" + s + "': components must be finite and >= 0");
  return v;
}

// The depth flags every command that takes depth shares (brume/depth_source.hpp).
void add_depth_flags(CLI::App* app, DepthSource& d) {
  auto* g = app->add_option_group("depth", "depth source (exactly one) and its conventions");
  g->add_option("--range", d.range, "range map: metres from the camera centre along each pixel's ray; NaN, inf, 0 unknown");
  g->add_option("--z", d.z, "planar depth map in metres (needs --fx.. or --fov-x/--fov-y or --calib)");
  g->add_option("--disparity", d.disparity, "stereo disparity in px: PFM with --calib calib.txt, or a PNG with --fx --baseline");
  g->add_option("--depth-buffer", d.depth_buffer, "rasteriser window depth in [0,1] (--near --far --convention, --fov-y..)");
  g->add_option("--inverse-depth", d.inverse_depth, "monocular inverse depth: z = 1/(--inverse-scale v + --inverse-shift)");
  g->add_option("--normalized-depth", d.normalized_depth, "monocular depth in [0,1]: z = --near + v (--far - --near)");
  g->add_option("--velodyne", d.velodyne, "KITTI Velodyne scan (.bin) projected with --kitti-calib");
  g->add_option("--depth-channel,--range-channel", d.channel, "channel holding the depth in a multi-channel file (e.g. Z)");
  g->add_option("--depth-scale,--range-scale", d.depth_scale,
                "metres per stored unit; required for integer range/z files (0.001 mm, 0.00390625 KITTI)");
  g->add_option("--fx", d.k.fx, "focal length in px (x)");
  g->add_option("--fy", d.k.fy, "focal length in px (y; default --fx)");
  g->add_option("--cx", d.k.cx, "principal point x in px (default (W-1)/2; pixel centres at integers)");
  g->add_option("--cy", d.k.cy, "principal point y in px (default (H-1)/2)");
  g->add_option("--fov-x", d.fov_x_deg, "horizontal field of view in degrees, edge to edge");
  g->add_option("--fov-y", d.fov_y_deg, "vertical field of view in degrees, edge to edge");
  g->add_option("--calib", d.calib, "Middlebury 2014 / ETH3D calib.txt (cam0, doffs, baseline in mm)");
  g->add_option("--baseline", d.baseline_m, "stereo baseline in metres (without --calib)");
  g->add_option("--disparity-scale", d.disparity_scale, "disparity = scale * stored value (+ --disparity-offset)")->capture_default_str();
  g->add_option("--disparity-offset", d.disparity_offset, "doffs / Middlebury 2005 dmin, in px of the disparity map")->capture_default_str();
  g->add_option("--convention", d.convention, "depth-buffer convention: opengl, d3d, reversed-z")->capture_default_str();
  g->add_option("--near", d.near_m, "near plane in metres (depth buffers, normalised depth)");
  g->add_option("--far", d.far_m, "far plane in metres; inf = infinite far plane (depth buffers)");
  g->add_option("--inverse-scale", d.inverse_scale, "A in z = 1/(A v + B)");
  g->add_option("--inverse-shift", d.inverse_shift, "B in z = 1/(A v + B)")->capture_default_str();
  g->add_option("--kitti-calib", d.kitti_calib, "KITTI calibration file for --velodyne");
  g->add_option("--like", d.like, "image whose size the --velodyne scan is projected to (when no --image is given)");
  g->add_option("--width", d.width, "image width for --velodyne (or --like)");
  g->add_option("--height", d.height, "image height for --velodyne (or --like)");
}

// Flags of the range preparation (brume/prepare.hpp), shared by `depth
// prepare` and every effect.
void add_prepare_flags(CLI::App* app, PrepareParams& p) {
  app->add_option("--sky-margin", p.sky_margin_px, "width mu of the matted horizon between scene and sky, px")
      ->capture_default_str();
  app->add_option("--s-max-factor", p.s_max_factor, "sky range S_max = factor * R_max (> 1)")->capture_default_str();
  app->add_option("--min-coverage", p.min_coverage, "refuse maps whose known pixels cover less than this fraction")
      ->capture_default_str();
}

// Write JSON atomically (temp + rename) after the images.
void check_record_path(const std::string& path) {
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error("--record '" + path + "': directory '" + dir.string() + "' does not exist; create it first");
  if (::access(dir.c_str(), W_OK) != 0)
    throw Error("--record '" + path + "': directory '" + dir.string() + "' is not writable");
}

struct Common {
  std::string image, image_transfer = "auto", out, bits = "auto", out_transfer = "auto", record;
  int threads = 0;
  bool reference = false;
  std::string backend = "cpu", gpu_filter = "auto";
  bool timing = false;
};

// The GPU context a run asks for: --backend gpu must get one (or fail with
// the reason), auto takes one when it can and says so, cpu never opens one.
std::unique_ptr<GpuContext> open_gpu(const Common& c, nlohmann::json& exec) {
  const Backend b = parse_backend(c.backend);
  parse_gpu_filter(c.gpu_filter);
  exec["backend_requested"] = c.backend;
  exec["backend"] = "cpu";
  if (b == Backend::cpu) return nullptr;
  if (c.reference) throw Error("--reference is the CPU's double-precision path; it cannot be combined with --backend " + c.backend);
  try {
    auto ctx = std::make_unique<GpuContext>();
    exec["backend"] = "gpu";
    exec["gpu"] = {{"renderer", ctx->info().renderer}, {"version", ctx->info().version}, {"platform", ctx->info().platform}};
    return ctx;
  } catch (const Error& e) {
    if (b == Backend::gpu) throw;
    std::fprintf(stderr, "brume: --backend auto: %s; running on the CPU\n", e.what());
    exec["gpu_unavailable"] = e.what();
    return nullptr;
  }
}

Exec cpu_exec(const Common& c) {
  Exec ex;
  ex.threads = c.threads;
  ex.path = c.reference ? Path::reference : Path::fast;
  return ex;
}

// blur has no premultiply or composite pass: only the stages a command ran are printed.
void print_timing(const char* cmd, const GpuTiming& t, const GpuInfo& info, bool haze_passes) {
  std::fprintf(stderr, "brume %s: GPU %s (%s): upload %.3f ms, ", cmd, info.renderer.c_str(),
               t.gpu_timer ? "timer queries" : "glFinish wall time", t.upload_ms);
  if (haze_passes) std::fprintf(stderr, "premultiply %.3f ms, ", t.premultiply_ms);
  std::fprintf(stderr, "diffusion %.3f ms (%d passes, %.4f ms each), ", t.diffuse_ms, t.iterations,
               t.iterations ? t.diffuse_ms / t.iterations : 0.0);
  if (haze_passes) std::fprintf(stderr, "composite %.3f ms, ", t.composite_ms);
  std::fprintf(stderr, "read back %.3f ms\n", t.readback_ms);
}

void add_common(CLI::App* app, Common& c) {
  app->add_option("--image", c.image, "input colour image (PNG, JPEG, TIFF, EXR, PFM, HDR)")->required();
  app->add_option("--image-transfer", c.image_transfer,
                  "transfer function of the input: auto (integer files sRGB, float files linear), srgb, linear")
      ->capture_default_str();
  app->add_option("--out", c.out, "output image (.png .jpg .tif .exr .pfm .hdr)")->required();
  app->add_option("--bits", c.bits, "output storage: auto (PNG/TIFF: the input's 8 or 16 bits, else 16; JPEG 8; EXR/PFM/HDR float), 8, 16, half, float")
      ->capture_default_str();
  app->add_option("--out-transfer", c.out_transfer,
                  "transfer function of the output: auto (sRGB for 8/16-bit, linear for float), srgb, linear")
      ->capture_default_str();
  app->add_option("--record", c.record, "write a JSON record of every parameter, derived value and input hash");
  app->add_option("--threads", c.threads, "worker threads (0 = all cores); results do not depend on it")
      ->capture_default_str();
  app->add_flag("--reference", c.reference, "use the scalar double-precision reference path (slow; for checking)");
  app->add_option("--backend", c.backend, "cpu, gpu (OpenGL ES 3.2 over headless EGL) or auto (gpu when available)")
      ->capture_default_str();
  app->add_option("--gpu-filter", c.gpu_filter,
                  "GPU interpolation between texels: auto, hardware (texture units), shader (exact float weights)")
      ->capture_default_str();
  app->add_flag("--timing", c.timing, "print the time of each pass (GPU timer queries where available)");
}

int run_haze(const Common& c, HazeParams p, const DepthSource& depth, const std::string& prepare_mode,
             const PrepareParams& pp, const std::string& airlight, const std::string& scheme,
             const std::string& precision, const std::string& edge_rate, const std::string& composite,
             const std::string& transmission_out, const std::string& scale_out, bool kappa_given, bool albedo_given) {
  p.diffusion.scheme = parse_scheme(scheme);
  p.diffusion.precision = parse_precision(precision);
  p.diffusion.edge_rate = parse_edge_rate(edge_rate);
  p.composite = parse_composite(composite);
  if (prepare_mode != "auto" && prepare_mode != "off")
    throw Error("--prepare '" + prepare_mode + "' is not a mode; use auto (fill holes, identify and matte the sky) or off");
  if (airlight == "auto") {
    p.airlight_auto = true;
  } else {
    p.airlight_auto = false;
    p.airlight = parse_rgb(airlight, "--airlight");
  }
  if (p.visibility_m > 0.0 && kappa_given)
    throw Error("--visibility sets the extinction; do not also give --kappa-a/--kappa-s (use --albedo to split it)");
  if (albedo_given && !(p.visibility_m > 0.0))
    throw Error("--albedo only applies with --visibility; with --kappa-a/--kappa-s the split is explicit");
  validate(p, haze_param_table());
  const Transfer in_t = parse_transfer(c.image_transfer, "--image-transfer");
  WriteOptions wo;
  wo.bits = c.bits;
  wo.transfer = parse_transfer(c.out_transfer, "--out-transfer");
  WriteOptions data_opts;
  data_opts.is_color = false;
  data_opts.bits = "auto";
  // Validate every output location before any work.
  check_writable(c.out, wo, "--out");
  if (!transmission_out.empty()) check_writable(transmission_out, data_opts, "--transmission");
  WriteOptions scale_opts = data_opts;
  scale_opts.float_reason = "sigma is in pixels and exceeds 1";
  if (!scale_out.empty()) check_writable(scale_out, scale_opts, "--scale-map");
  if (!c.record.empty()) check_record_path(c.record);

  FileInfo img_info;
  Image rgb = read_color(c.image, in_t, &img_info);
  LoadedDepth depth_in = load_depth(depth, rgb.width, rgb.height);
  // Image-wide statistics (R_max, airlight from the sky) come from the
  // measured range; the effect then runs on the prepared one, whose sky lies
  // at S_max > R_max.
  HazeAnalysis a = analyse_haze(rgb, depth_in.range, p);
  nlohmann::json prep_rec = {{"mode", prepare_mode}, {"applied", false}};
  Image prepared;
  const Image* range = &depth_in.range;
  if (prepare_mode == "auto" && a.unknown_pixels > 0) {
    PrepareResult pr = prepare_range(depth_in.range, pp);
    prepared = std::move(pr.range);
    range = &prepared;
    prep_rec = prepare_record(pp, pr);
    prep_rec["mode"] = "auto";
    prep_rec["applied"] = true;
  }
  const Exec ex = cpu_exec(c);
  nlohmann::json exec_rec = {{"path", c.reference ? "reference" : "fast"}, {"threads", c.threads}};
  std::unique_ptr<GpuContext> gpu = open_gpu(c, exec_rec);
  HazeResult r;
  if (gpu) {
    GpuHaze gh(*gpu, rgb, *range);
    r = gh.render(p, a, parse_gpu_filter(c.gpu_filter));
    if (c.timing) print_timing("haze", gh.timing(), gpu->info(), true);
  } else {
    const auto t0 = std::chrono::steady_clock::now();
    r = apply_haze(rgb, *range, p, a, ex);
    if (c.timing)
      std::fprintf(stderr, "brume haze: CPU (%s path): %.1f ms for premultiply, %d diffusion iterations and composite\n",
                   c.reference ? "reference" : "fast",
                   std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count(),
                   a.plan.iterations);
  }

  nlohmann::json rec = record_header("haze", g_argv);
  rec["inputs"] = {{"image", file_record(c.image, img_info, rgb)}, {"depth", depth_in.record}};
  rec["haze"] = haze_record(p, a);
  rec["prepare"] = prep_rec;
  if (prep_rec["applied"].get<bool>())
    rec["haze"]["derived"]["unknown_range_rule"] = "prepared: holes filled, sky at S_max, horizon margin matted (see prepare)";
  rec["execution"] = exec_rec;

  if (wo.bits == "auto" && img_info.integer && (img_info.bits == 8 || img_info.bits == 16)) {
    std::string e = fs::path(c.out).extension().string();
    if (e == ".png" || e == ".tif" || e == ".tiff") wo.bits = std::to_string(img_info.bits);
  }
  wo.description = rec.dump();
  OutputSet outs;
  outs.write(c.out, r.rgb, wo, "--out");
  if (!transmission_out.empty()) outs.write(transmission_out, r.transmission, data_opts, "--transmission");
  if (!scale_out.empty()) outs.write(scale_out, r.scale, scale_opts, "--scale-map");
  if (!c.record.empty()) outs.write_text(c.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  std::fprintf(stderr, "brume haze: %s  R_max %.4g m  sigma_max %.3g px  %d iterations (%s)\n", c.out.c_str(),
               a.range_max_m, a.sigma_max, a.plan.iterations, to_string(p.diffusion.scheme).c_str());
  return 0;
}

int run_blur(const Common& c, double sigma, const std::string& scale_map, double sigma0,
             const std::string& scheme, const std::string& precision, const std::string& edge_rate, double rho_max) {
  DiffusionParams dp;
  dp.edge_rate = parse_edge_rate(edge_rate);
  dp.rho_max = rho_max;
  dp.scheme = parse_scheme(scheme);
  dp.precision = parse_precision(precision);
  dp.sigma0 = sigma0;
  if (!(sigma0 > 0.0) || !std::isfinite(sigma0))
    throw Error("--sigma0 " + std::to_string(sigma0) + " is not allowed: the inner scale must be finite and > 0 px");
  if (scale_map.empty()) {
    if (!std::isfinite(sigma) || sigma < sigma0) {
      std::ostringstream m;
      m << "--sigma " << sigma << " px is below the inner scale --sigma0 " << sigma0
        << " px (or not finite); diffusion can only add blur. The Gaussian applied is sqrt(sigma^2 - sigma0^2): give --sigma >= --sigma0";
      throw Error(m.str());
    }
  }
  const Transfer in_t = parse_transfer(c.image_transfer, "--image-transfer");
  WriteOptions wo;
  wo.bits = c.bits;
  wo.transfer = parse_transfer(c.out_transfer, "--out-transfer");
  check_writable(c.out, wo, "--out");
  if (!c.record.empty()) check_record_path(c.record);

  FileInfo info, map_info;
  Image rgb = read_color(c.image, in_t, &info);
  Image smap;
  double smax = sigma;
  if (!scale_map.empty()) {
    smap = read_scalar(scale_map, "", &map_info);
    if (smap.width != rgb.width || smap.height != rgb.height)
      throw Error("--scale-map '" + scale_map + "' is " + smap.size_string() + " but --image '" + c.image + "' is " +
                  rgb.size_string() + "; they must be the same size");
    smax = sigma0;
    for (float v : smap.data)
      if (std::isfinite(v)) smax = std::max(smax, static_cast<double>(v));
  } else {
    smap = Image(rgb.width, rgb.height, 1, static_cast<float>(sigma));
  }
  Image f(rgb.width, rgb.height, 4);
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    for (int k = 0; k < 3; ++k) f.data[i * 4 + k] = rgb.data[i * 3 + k];
    f.data[i * 4 + 3] = 1.0f;
  }
  const Exec ex = cpu_exec(c);
  nlohmann::json exec_rec = {{"path", c.reference ? "reference" : "fast"}, {"threads", c.threads}};
  std::unique_ptr<GpuContext> gpu = open_gpu(c, exec_rec);
  DiffusionPlan plan;
  if (gpu) {
    GpuTiming t;
    plan = diffuse_gpu(*gpu, f, smap, smax, dp, parse_gpu_filter(c.gpu_filter), &t);
    if (c.timing) print_timing("blur", t, gpu->info(), false);
  } else {
    const auto t0 = std::chrono::steady_clock::now();
    plan = diffuse(f, smap, smax, dp, ex);
    if (c.timing)
      std::fprintf(stderr, "brume blur: CPU: %.1f ms for %d iterations\n",
                   std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count(), plan.iterations);
  }
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int k = 0; k < 3; ++k) rgb.data[i * 3 + k] = f.data[i * 4 + k];

  nlohmann::json rec = record_header("blur", g_argv);
  rec["inputs"] = {{"image", file_record(c.image, info, rgb)}};
  if (!scale_map.empty()) rec["inputs"]["scale_map"] = file_record(scale_map, map_info, smap);
  else rec["sigma_px"] = sigma;
  rec["diffusion"] = diffusion_record(dp, plan);
  rec["execution"] = exec_rec;
  rec["effective_gaussian_px"] = scale_map.empty() ? std::sqrt(sigma * sigma - sigma0 * sigma0) : -1.0;
  if (wo.bits == "auto" && info.integer && (info.bits == 8 || info.bits == 16)) {
    std::string e = fs::path(c.out).extension().string();
    if (e == ".png" || e == ".tif" || e == ".tiff") wo.bits = std::to_string(info.bits);
  }
  wo.description = rec.dump();
  OutputSet outs;
  outs.write(c.out, rgb, wo, "--out");
  if (!c.record.empty()) outs.write_text(c.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  std::fprintf(stderr, "brume blur: %s  sigma_max %.3g px  %d iterations (%s, %s)\n", c.out.c_str(), smax,
               plan.iterations, to_string(dp.scheme).c_str(), to_string(dp.precision).c_str());
  return 0;
}

int run_depth_convert(const DepthSource& d, const std::string& out, const std::string& kind,
                      const std::string& record) {
  if (kind != "range" && kind != "z") throw Error("--kind '" + kind + "' is not a depth kind; use range or z");
  WriteOptions data;
  data.is_color = false;
  data.float_reason = "depth in metres needs a float file";
  check_writable(out, data, "--out");
  if (!record.empty()) check_record_path(record);
  LoadedDepth ld = load_depth(d);
  Image result = ld.range;
  nlohmann::json rec = record_header("depth convert", g_argv);
  rec["depth"] = ld.record;
  rec["kind"] = kind;
  if (kind == "z") {
    Intrinsics k;
    if (!d.velodyne.empty()) {
      KittiCalib c = read_kitti_calib(d.kitti_calib);  // camera 2's K from P2
      k.fx = c.P2[0], k.fy = c.P2[5], k.cx = c.P2[2], k.cy = c.P2[6];
    } else {
      k = depth_intrinsics(d, result.width, result.height);
    }
    result = range_to_z(result, k);
    rec["z_intrinsics"] = {{"fx_px", k.fx}, {"fy_px", k.fy}, {"cx_px", k.cx}, {"cy_px", k.cy}};
  }
  data.description = rec.dump();
  OutputSet outs;
  outs.write(out, result, data, "--out");
  if (!record.empty()) outs.write_text(record, rec.dump(2) + "\n", "--record");
  outs.commit();
  std::size_t unknown = ld.record.value("unknown_pixels", std::size_t{0});
  if (!d.velodyne.empty()) unknown = result.pixels() - ld.record["pixels_hit"].get<std::size_t>();
  std::fprintf(stderr, "brume depth convert: %s  %s  %dx%d  %.2f %% unknown", out.c_str(), kind.c_str(), result.width,
               result.height, 100.0 * unknown / result.pixels());
  if (!d.velodyne.empty())
    std::fprintf(stderr, "  (lidar: %zu of %zu points in view, coverage %.2f %% of pixels)",
                 ld.record["points_in_view"].get<std::size_t>(), ld.record["points"].get<std::size_t>(),
                 100.0 * ld.record["coverage"].get<double>());
  std::fprintf(stderr, "\n");
  return 0;
}

int run_depth_prepare(const DepthSource& d, const PrepareParams& pp, const std::string& out, const std::string& masks,
                      const std::string& record) {
  WriteOptions data;
  data.is_color = false;
  data.float_reason = "a range in metres needs a float file";
  check_writable(out, data, "--out");
  if (!record.empty()) check_record_path(record);
  if (!masks.empty()) {
    std::error_code ec;
    fs::create_directories(masks, ec);
    if (!fs::is_directory(masks)) throw Error("--masks '" + masks + "' cannot be created: " + ec.message());
  }
  LoadedDepth ld = load_depth(d, 0, 0);
  PrepareResult pr = prepare_range(ld.range, pp);
  nlohmann::json rec = record_header("depth prepare", g_argv);
  rec["depth"] = ld.record;
  rec["prepare"] = prepare_record(pp, pr);
  data.description = rec.dump();
  OutputSet outs;
  outs.write(out, pr.range, data, "--out");
  if (!masks.empty()) {
    WriteOptions m;
    m.is_color = false;
    m.bits = "8";
    outs.write((fs::path(masks) / "sky.png").string(), pr.sky_mask, m, "--masks");
    outs.write((fs::path(masks) / "holes.png").string(), pr.hole_mask, m, "--masks");
    outs.write((fs::path(masks) / "margin.png").string(), pr.margin_mask, m, "--masks");
    WriteOptions c;
    c.bits = "8";
    outs.write((fs::path(masks) / "prepared-preview.png").string(), range_preview(pr.range), c, "--masks");
  }
  if (!record.empty()) outs.write_text(record, rec.dump(2) + "\n", "--record");
  outs.commit();
  std::fprintf(stderr,
               "brume depth prepare: %s  known %.1f %%, %zu holes (%.2f %%), sky %.1f %% at S_max %.4g m (R_max %.4g m), "
               "margin %.2f %% solved to residual %.2g in %d iterations\n",
               out.c_str(), 100 * pr.known_fraction, pr.holes, 100.0 * pr.hole_pixels / pr.range.pixels(),
               100.0 * pr.sky_pixels / pr.range.pixels(), pr.s_max_m, pr.range_max_m,
               100.0 * pr.margin_pixels / pr.range.pixels(), pr.margin_residual, pr.solver_iterations);
  return 0;
}

}  // namespace

int run_demo(const std::string& dir, int width, int height, int threads);
int run_study(const std::string& what, const std::string& out_dir, bool quick, const std::string& backend,
              const std::string& image_path);

int main(int argc, char** argv) {
  for (int i = 0; i < argc; ++i) g_argv.emplace_back(argv[i]);
  CLI::App app{"brume: physically based, depth-aware haze, fog and lens effects for RGB-D images"};
  app.set_version_flag("--version", std::string("brume ") + BRUME_VERSION);
  app.require_subcommand(1);

  // haze
  CLI::App* haze = app.add_subcommand("haze", "haze and fog with scattering blur (Hansard eq. 1-7)");
  Common hc;
  HazeParams hp;
  std::string airlight = "auto", scheme = "invariant-exact", precision = "f32", composite = "premultiplied",
              transmission_out, scale_out, edge_rate = to_string(DiffusionParams{}.edge_rate);
  DepthSource hdepth;
  std::string prepare_mode = "auto";
  PrepareParams hprep;
  add_common(haze, hc);
  add_depth_flags(haze, hdepth);
  haze->add_option("--prepare", prepare_mode,
                   "auto: fill holes, identify and matte the sky (Hansard 4.1) when the range has unknown pixels; "
                   "off: treat unknown range as R_max")
      ->capture_default_str();
  add_prepare_flags(haze, hprep);
  std::map<std::string, CLI::Option*> hopts;
  add_param_flags(haze, hp, haze_param_table(), &hopts);
  haze->add_option("--airlight", airlight, "airlight B as linear R,G,B, or auto (median sky colour; else a bright grey)")
      ->capture_default_str();
  haze->add_option("--scheme", scheme, "diffusion scheme: standard, invariant, invariant-exact")->capture_default_str();
  haze->add_option("--rho-max", hp.diffusion.rho_max,
                   "largest diffusion rate per iteration, (0, 0.25]; 0 = scheme default (0.2 invariant-exact, 0.25 others)")
      ->capture_default_str();
  haze->add_option("--precision", precision, "storage between iterations: f32 or f16")->capture_default_str();
  haze->add_option("--edge-rate", edge_rate, kEdgeRateHelp)->capture_default_str();
  haze->add_option("--composite", composite, "premultiplied (eq. 4) or naive (comparison only)")->capture_default_str();
  haze->add_option("--transmission", transmission_out, "write the blurred transmission (alpha after diffusion)");
  haze->add_option("--scale-map", scale_out, "write the target scale sigma(x) in pixels (float file)");

  // blur
  CLI::App* blur = app.add_subcommand("blur", "the diffusion engine alone: Gaussian or space-variant blur");
  Common bc;
  double sigma = NAN, sigma0 = 1.0;
  std::string scale_map, bscheme = "invariant-exact", bprecision = "f32";
  add_common(blur, bc);
  auto* o_sigma = blur->add_option("--sigma", sigma, "constant target scale in px (the result is a Gaussian of sqrt(sigma^2 - sigma0^2))");
  auto* o_map = blur->add_option("--scale-map", scale_map, "per-pixel target scale in px (1-channel float file)");
  o_sigma->excludes(o_map);
  blur->add_option("--sigma0", sigma0, "inner scale of the input in px")->capture_default_str();
  blur->add_option("--scheme", bscheme, "standard, invariant, invariant-exact")->capture_default_str();
  blur->add_option("--precision", bprecision, "f32 or f16")->capture_default_str();
  std::string bedge = to_string(DiffusionParams{}.edge_rate);
  blur->add_option("--edge-rate", bedge, kEdgeRateHelp)->capture_default_str();
  double brho = 0.0;
  blur->add_option("--rho-max", brho, "largest rate per iteration, (0, 0.25]; 0 = scheme default")->capture_default_str();

  // depth
  CLI::App* depth = app.add_subcommand("depth", "depth maps: convert any depth source to range or planar z");
  depth->require_subcommand(1);
  CLI::App* dconv = depth->add_subcommand("convert", "convert a depth source to a range (or z) map in metres");
  DepthSource cdepth;
  std::string conv_out, conv_kind = "range", conv_record;
  add_depth_flags(dconv, cdepth);
  dconv->add_option("--out", conv_out, "output float file (.exr, .pfm, .tif)")->required();
  dconv->add_option("--kind", conv_kind, "range (metres along the ray) or z (planar depth)")->capture_default_str();
  dconv->add_option("--record", conv_record, "write a JSON record of the conversion");

  CLI::App* dprep = depth->add_subcommand("prepare", "fill holes, identify the sky and matte the horizon (Hansard 4.1)");
  DepthSource pdepth;
  PrepareParams pparams;
  std::string prep_out, prep_masks, prep_record;
  add_depth_flags(dprep, pdepth);
  add_prepare_flags(dprep, pparams);
  dprep->add_option("--out", prep_out, "prepared range, float file (.exr, .pfm, .tif)")->required();
  dprep->add_option("--masks", prep_masks, "directory for sky.png, holes.png, margin.png and prepared-preview.png");
  dprep->add_option("--record", prep_record, "write a JSON record of what was done");

  // demo
  CLI::App* demo = app.add_subcommand("demo", "render the built-in RGB-D scene clean, with haze and with fog");
  std::string demo_dir;
  int demo_w = 960, demo_h = 672, demo_threads = 0;
  demo->add_option("--out-dir", demo_dir, "directory for the images (created if missing)")->required();
  demo->add_option("--width", demo_w, "width in pixels")->capture_default_str();
  demo->add_option("--height", demo_h, "height in pixels")->capture_default_str();
  demo->add_option("--threads", demo_threads, "worker threads (0 = all)")->capture_default_str();

  // study
  CLI::App* study = app.add_subcommand("study", "accuracy and speed studies (Hansard 5.2-5.3)");
  std::string study_what, study_dir, study_backend = "cpu", study_image;
  bool study_quick = false;
  study->add_option("what", study_what, "the study: diffusion")->required();
  study->add_option("--out-dir", study_dir, "directory for accuracy.csv and speed.csv")->required();
  study->add_flag("--quick", study_quick, "small image and a few sigma (a smoke test)");
  study->add_option("--backend", study_backend, "cpu, gpu or all")->capture_default_str();
  study->add_option("--image", study_image, "real image in [0,1] for the accuracy part (default Middlebury Art)");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  try {
    if (*haze) {
      bool kappa_given = hopts["kappa-a"]->count() > 0 || hopts["kappa-s"]->count() > 0;
      bool albedo_given = hopts["albedo"]->count() > 0;
      return run_haze(hc, hp, hdepth, prepare_mode, hprep, airlight, scheme, precision, edge_rate, composite, transmission_out, scale_out,
                      kappa_given, albedo_given);
    }
    if (*blur) {
      if (o_sigma->count() == 0 && o_map->count() == 0)
        throw Error("blur needs a target scale: give --sigma S (px) or --scale-map FILE");
      return run_blur(bc, sigma, scale_map, sigma0, bscheme, bprecision, bedge, brho);
    }
    if (*demo) return run_demo(demo_dir, demo_w, demo_h, demo_threads);
    if (*study) return run_study(study_what, study_dir, study_quick, study_backend, study_image);
    if (*dprep) return run_depth_prepare(pdepth, pparams, prep_out, prep_masks, prep_record);
    if (*dconv) return run_depth_convert(cdepth, conv_out, conv_kind, conv_record);
  } catch (const brume::Error& e) {
    std::string cmd = app.get_subcommands().front()->get_name();
    if (*dconv) cmd = "depth convert";
    if (*dprep) cmd = "depth prepare";
    std::fprintf(stderr, "brume %s: error: %s\n", cmd.c_str(), e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "brume: internal error: %s\n", e.what());
    return 3;
  }
  return 0;
}
