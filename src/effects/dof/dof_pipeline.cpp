// brume — the depth-of-field pipeline: what `brume dof` does, as a library
// call, in the shape every effect follows (brume/pipeline.hpp): prepare the
// range, turn it into planar depth, form the scale map from the CoC, dispatch
// once on Exec (the GPU runs the engine's own passes on that map), record.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "brume/command.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/gpu_context.hpp"
#include "brume/record.hpp"
#include "effects/dof/dof_job.hpp"
#include "effects/dof/dof_preview.hpp"

namespace brume {

const ParamTable<DofParams>& dof_sampling_table();

namespace {

nlohmann::json dof_record(const DofParams& p, const DofAnalysis& a, const Intrinsics& k, const std::string& k_source) {
  nlohmann::json j;
  // The block's parameters and the camera's lens the CoC used (the depth block's).
  j["parameters"] = dof_sampling_table().to_json(p);
  j["units"] = dof_sampling_table().units();
  j["diffusion"] = diffusion_record(dof_diffusion_params(p), a.plan);
  j["diffusion"]["dof_scheme"] = to_string(p.scheme);
  j["derived"] = {
      {"coc_infinity_px", a.alpha_px},
      {"sigma_max_px", a.sigma_max},
      {"coc_limit_px", p.coc_limit_px},
      {"capped_pixels", a.capped_pixels},
      {"unknown_depth_pixels", a.unknown_pixels},
      {"unknown_depth_rule", "unknown depth is infinitely far: c = alpha"},
      {"near_field_pixels", a.near_pixels},
      {"foreground_rule", p.foreground == Foreground::soft
                              ? "near-field sigma in octave bands [2^j, 2^(j+1)) px, each blurred by a Gaussian of 2^j px, max with "
                                "sigma (§3.4)"
                              : "none (the CoC map as is)"},
      {"z_min_m", a.z_min_m},
      {"z_max_m", a.z_max_m},
      {"sigma_law", "sigma = min(sqrt(sigma0^2 + (c/4)^2), coc_limit), c = alpha |Z - Zf| / Z"},
      {"intrinsics", {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}, {"source", k_source}}},
  };
  return j;
}

bool cpu_only(const DofParams& p) { return p.scheme == DofScheme::bertalmio || p.scheme == DofScheme::leaky; }

// The GPU runs the engine's passes (rates from sigma, diffusion): the schemes
// whose edge weights they form. --backend gpu with another is an error
// (checked before any work); --backend auto runs those on the CPU.
void check_gpu_scheme(const DofParams& p, Backend b) {
  if (b != Backend::gpu) return;
  if (cpu_only(p))
    throw Error("--scheme " + to_string(p.scheme) +
                " runs on the CPU only (a comparison with the paper; the GPU passes form symmetric edge weights): "
                "use --backend cpu, or --scheme invariant-exact or standard on the GPU");
}

}  // namespace

bool depth_flags_give_intrinsics(const DepthSource& s) {
  return s.k.fx > 0.0 || s.k.fy > 0.0 || !std::isnan(s.fov_x_deg) || !std::isnan(s.fov_y_deg) || !s.calib.empty() ||
         (!s.velodyne.empty() && !s.kitti_calib.empty());
}

const std::vector<MapOutput>& dof_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"scale-map", "write the target scale sigma(x) in pixels (float file)", "sigma is in pixels and exceeds 1"},
  };
  return m;
}

const ParamTable<DofJob>& dof_job_table() {
  static const ParamTable<DofJob> t = [] {
    ParamTable<DofJob> d("dof");
    d.nest(&DofJob::input, input_param_table(true))
        .nest(&DofJob::prepare, range_step_param_table())
        .nest(&DofJob::dof, dof_param_table())
        .nest(&DofJob::scene, scene_scale_param_table())
        .nest(&DofJob::output, output_param_table(dof_map_outputs()));
    return d;
  }();
  return t;
}

Intrinsics dof_intrinsics(const DepthSource& src, int width, int height) {
  // The depth flags' pixels, or the camera in millimetres; both: checked to
  // agree within 1 % (depth_intrinsics).
  if (depth_flags_give_intrinsics(src) || src.lens.focal_length_mm) return depth_camera(src, width, height).k;
  throw Error("depth of field needs planar depth, so the camera's intrinsics: give --fx (or --fov-x, --calib), or "
              "the lens (--focal-length and --sensor-width)");
}

std::string dof_intrinsics_source(const DepthSource& src, int width, int height) {
  if (depth_flags_give_intrinsics(src)) return "depth flags";
  const bool vertical = src.lens.sensor_fit == SensorFit::vertical ||
                        (src.lens.sensor_fit == SensorFit::automatic && height > width);
  return vertical ? "lens (focal length x height / sensor " +
                        std::string(src.lens.sensor_fit == SensorFit::vertical ? "height" : "width") + ")"
                  : "lens (focal length x width / sensor width)";
}

void check_dof_camera(const DepthSource& src) {
  // The intrinsics' agreement with the lens is checked on the image's size; here only that one of them is given.
  if (!depth_flags_give_intrinsics(src) && !src.lens.focal_length_mm) (void)dof_intrinsics(src, 640, 480);
}

DofRun run_dof(DenseImageRef rgb, DenseImageRef measured_range, const Intrinsics& k, const DofParams& p,
               const RangeStep& prepare, const Exec& exec, const std::set<std::string>& given) {
  validate_dof(p, given);
  check_gpu_scheme(p, exec.gpu ? Backend::gpu : exec.backend);
  if (rgb.channels != 3) throw Error("depth of field needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  if (rgb.width != measured_range.width || rgb.height != measured_range.height)
    throw Error("range map " + measured_range.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the range map, or crop both)");
  // A sparse map is completed first (guided by rgb), when the step says so.
  const CompletedRange done = complete_step(measured_range.view(), rgb.view(), prepare, given, exec.threads);
  PreparedRange prep = prepare_step(done.view(measured_range.view()), prepare, given, exec.threads);
  prep.record["complete"] = done.record;
  return run_dof_prepared(rgb, prep, k, p, exec, given);
}

DofRun run_dof_prepared(DenseImageRef rgb, const PreparedRange& prep, const Intrinsics& k, const DofParams& p,
                        const Exec& exec, const std::set<std::string>& given) {
  validate_dof(p, given);
  check_gpu_scheme(p, exec.gpu ? Backend::gpu : exec.backend);
  Exec ex = exec;
  if (cpu_only(p) && ex.backend == Backend::automatic) ex.backend = Backend::cpu;
  if (rgb.channels != 3) throw Error("depth of field needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  if (rgb.width != prep.range.width || rgb.height != prep.range.height)
    throw Error("range map " + prep.range.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the range map, or crop both)");
  DofRun run;
  const Image z = planar_depth(prep.range, k);
  BackendChoice backend = choose_backend(ex);
  if (ex.backend != exec.backend)
    backend.record["note"] = "--scheme " + to_string(p.scheme) + " runs on the CPU only; --backend auto chose the CPU";
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json timing;
  if (backend.gpu) {
    // The engine's GPU passes on the scale map from the CoC (formed on the
    // host: one pass over W x H, nothing to gain from a GPU pass).
    run.result.scale = dof_scale_map(z, p, run.analysis, exec);
    Image f(rgb.width, rgb.height, 4);
    for (std::size_t i = 0; i < rgb.pixels(); ++i) {
      for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = rgb.data[i * 3 + c];
      f.data[i * 4 + 3] = 1.0f;
    }
    GpuTiming t;
    diffuse_gpu(*backend.gpu, f, run.result.scale, run.analysis.sigma_max, dof_diffusion_params(p), exec.gpu_filter,
                &t);
    run.result.rgb = Image(rgb.width, rgb.height, 3);
    for (std::size_t i = 0; i < rgb.pixels(); ++i)
      for (int c = 0; c < 3; ++c) run.result.rgb.data[i * 3 + c] = f.data[i * 4 + c];
    timing = gpu_timing_record(t);
  } else {
    run.result = apply_dof(rgb, z, p, run.analysis, exec);
    timing = cpu_timing_record(t0, run.analysis.plan.iterations);
  }
  run.record["dof"] = dof_record(p, run.analysis, k, "given by the caller");
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  return run;
}


// The preview (effects/dof/dof_preview.hpp): the engine's passes on the scale
// map from the CoC, formed on the host as the GPU path of run_dof_prepared
// does, and named by its contents.
namespace {
Image dof_preview_scale(const DofParams& p, const Intrinsics& k, const PreviewInputs& in, DofAnalysis& a) {
  check_gpu_scheme(p, Backend::gpu);
  return dof_scale_map(planar_depth(in.prepared.range, k), p, a);
}
}  // namespace

nlohmann::json dof_preview_steps(PreviewFrame& frame, const DofParams& p, const Intrinsics& k, const PreviewInputs& in,
                                 const std::string& input, const std::string& prefix, const std::string& last) {
  DofAnalysis a;
  Image scale = dof_preview_scale(p, k, in, a);
  const DiffusionParams dp = dof_diffusion_params(p);
  const std::string name = frame.add_map("dof.scale", std::move(scale));
  const std::string f0 = prefix + "0", f1 = prefix + "1";
  const char* f = dp.precision == Precision::f16 ? "RGBA16F" : "RGBA32F";
  nlohmann::json& plan = frame.plan;
  plan["targets"][f0] = f;
  plan["targets"][f1] = f;
  plan["steps"].push_back({{"copy", {{"from", input}, {"to", f0}}}});
  preview_diffusion_steps(plan, dp, a.plan, name, f0, f1, last);
  return {{"sigma_max_px", a.sigma_max}, {"coc_infinity_px", a.alpha_px}, {"iterations", a.plan.iterations}};
}

// Where brume view's page starts (brume/preview.hpp): focused at the image
// centre's depth, with a circle of confusion at infinity of 1 % of the image
// width where no lens is given (--focus-distance is required, and the CoC or
// the lens), and the assumed camera where neither the depth flags nor the
// lens give one.
std::vector<PreviewStart> dof_preview_start(const DofParams& p, bool camera_given, const PreviewScene& s) {
  std::vector<PreviewStart> v;
  const bool lens = p.f_number || p.lens.focal_length_mm || p.lens.sensor_width_mm;
  if (!camera_given && !p.lens.focal_length_mm) v.push_back(preview_assumed_camera(s));
  if (!p.focus_distance_m && s.centre_range_m > 0.0) {
    const double f = preview_round(s.centre_range_m);
    v.push_back({"focus-distance", f,
                 "focused at the image centre's depth, " + preview_text(f) +
                     " m (--focus-distance is required); click the picture to focus elsewhere"});
  }
  if (!p.coc_infinity_px && !lens) {
    const double c = preview_round(std::max(2.0, 0.01 * s.width));
    v.push_back({"coc-infinity", c,
                 "a circle of confusion of " + preview_text(c) +
                     " px at infinity (1 % of the image width; the CoC or the lens is required)"});
  }
  return v;
}

// The parameter of depth of field that --scene-scale scales (brume/pipeline.hpp).
const std::vector<std::string>& dof_scene_lengths() {
  static const std::vector<std::string> n = {"focus-distance"};
  return n;
}

PreviewFrame dof_preview(const nlohmann::json& job, const PreviewInputs& in) {
  DofJob j;
  dof_job_table().from_json(j, job, "job");
  PreviewFrame frame;
  frame.plan["targets"] = nlohmann::json::object();
  frame.plan["steps"] = nlohmann::json::array();
  const Intrinsics k = dof_intrinsics(j.input.depth, preview_full_width(in), preview_full_height(in));
  frame.plan["derived"] = dof_preview_steps(frame, dof_with_lens(j.dof, j.input.depth.lens),
                                            preview_intrinsics(k, in.scale), in, "image", "f", "blurred");
  frame.plan["result"] = "blurred";
  return frame;
}

nlohmann::json run_dof_job(const DofJob& job, const ExecOptions& eo, const RunContext& ctx) {
  const EffectJob<DofJob> e{
      "dof",
      dof_job_table(),
      dof_map_outputs(),
      90,
      [&](const DofJob& j, const ExecOptions& x) {
        validate_dof(dof_with_lens(j.dof, j.input.depth.lens), ctx.given);
        check_gpu_scheme(j.dof, x.backend);
      },
      [&](const DofJob& j, LoadedInputs& in, const Exec& exec) {
        DofParams p = j.dof;
        const nlohmann::json scaled = apply_scene_scale(dof_param_table(), p, dof_scene_lengths(), j.scene,
                                                        in.depth.range);
        const Intrinsics k = dof_intrinsics(j.input.depth, in.rgb.width, in.rgb.height);
        DofRun run = run_dof(in.rgb, in.depth.range, k, dof_with_lens(p, j.input.depth.lens),
                             with_camera(j.prepare, in.depth), exec, ctx.given);
        if (!scaled.is_null()) run.record["scene_scale"] = scaled;
        run.record["dof"]["derived"]["intrinsics"]["source"] =
            dof_intrinsics_source(j.input.depth, in.rgb.width, in.rgb.height);
        return EffectOutput{std::move(run.result.rgb), {{"scale-map", std::move(run.result.scale)}},
                            std::move(run.record)};
      }};
  return run_effect_job(e, job, eo, ctx);
}

// The parameters `brume sample` draws for depth of field: the block's and
// the camera's lens (the depth block's declaration, nested: one declaration).
const ParamTable<DofParams>& dof_sampling_table() {
  static const ParamTable<DofParams> t = [] {
    ParamTable<DofParams> d("dof");
    d.extend(dof_param_table()).nest(&DofParams::lens, lens_param_table("depth"));
    return d;
  }();
  return t;
}

CommandDef dof_command() {
  CommandDef c = make_command<DofJob>({
      .name = "dof",
      .cli = "dof",
      .summary = "depth of field by leak-free diffusion (thin-lens CoC, Bertalmio eq. 1-2, 16)",
      .table = &dof_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const DofJob& j, const std::set<std::string>& g) {
        validate_dof(dof_with_lens(j.dof, j.input.depth.lens), g);
        check_range_step(j.prepare, g);
      },
      .run = &run_dof_job,
      .report = [](const DofJob& j, const nlohmann::json& rec) {
        const auto& d = rec["dof"]["derived"];
        std::fprintf(stderr, "brume dof: %s  CoC at infinity %.3g px  sigma_max %.3g px (%zu capped)  %d iterations (%s, %s)\n",
                     j.output.out.c_str(), d["coc_infinity_px"].get<double>(), d["sigma_max_px"].get<double>(),
                     d["capped_pixels"].get<std::size_t>(), rec["dof"]["diffusion"]["iterations"].get<int>(),
                     rec["dof"]["diffusion"]["dof_scheme"].get<std::string>().c_str(),
                     rec["execution"]["backend"].get<std::string>().c_str());
      },
  });
  // A 50 mm lens on a 36 mm (full-frame) sensor, the "normal" lens whose
  // field of view is close to most datasets' cameras (fix --focal-length and
  // --sensor-width to your camera), at the full stops f/1.4-f/8 (where depth
  // of field is visible at all), focused log-uniformly from 1 m (close-up) to
  // 50 m (street scenes; beyond, the scene is all in focus). --coc-infinity
  // replaces the lens.
  c.sampling = make_sampling<DofParams>(dof_sampling_table(),
                                        {{"focus-distance", "loguniform(1, 50)", {}},
                                         {"f-number", "choice(1.4, 2, 2.8, 4, 5.6, 8)", {"coc-infinity"}},
                                         {"focal-length", "50", {"coc-infinity"}},
                                         {"sensor-width", "36", {"coc-infinity"}}},
                                        &validate_dof);
  c.gpu_passes = {"diffusion.rates", "diffusion.iterate"};
  c.preview = &dof_preview;
  c.preview_start = [](const nlohmann::json& job, const std::set<std::string>&, const PreviewScene& s) {
    DofJob j;
    dof_job_table().from_json(j, job, "job");
    return dof_preview_start(dof_with_lens(j.dof, j.input.depth.lens), s.camera_given, s);
  };
  // --scene-scale scales the lengths to the frame when a job runs; the page's values are metres.
  c.preview_fixed.push_back("scene");
  static const auto call = array_call_table(dof_param_table(),
                                            kArrayPrepare | kArrayIntrinsics | kArrayScene | kArrayExec);
  c.arrays = make_array_form<DofParams>(
      "dof", "",
      "Depth of field by leak-free diffusion (thin-lens circle of confusion). `range` is metres along the ray; "
      "planar depth comes from the intrinsics or the lens. As `brume dof`.",
      rgb_range_args(ArrayArg::As::dense), call, {"rgb", "scale", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<DofParams>& k, const Exec& e, const std::set<std::string>& g) {
        DofParams p = k.p;
        const nlohmann::json scaled = apply_scene_scale(dof_param_table(), p, dof_scene_lengths(), k.scene,
                                                        in[1].dense.view());
        const Intrinsics ki = dof_intrinsics(k.depth, in[0].dense.width, in[0].dense.height);
        p.lens = k.depth.lens;
        // run_dof reads a given context as backend gpu (its CPU-only schemes
        // would be refused), so with auto it makes its own.
        Exec ex = e;
        if (ex.backend != Backend::gpu) ex.gpu = nullptr;
        DofRun r = run_dof(in[0].dense, in[1].dense, ki, p, k.prepare, ex, g);
        if (!scaled.is_null()) r.record["scene_scale"] = scaled;
        return ArrayResult{{{"rgb", std::move(r.result.rgb)}, {"scale", std::move(r.result.scale)}},
                           std::move(r.record),
                           {},
                           {}};
      },
      [](const ArrayCall<DofParams>& k, const std::set<std::string>& g) {
        validate_dof(dof_with_lens(k.p, k.depth.lens), g);
        check_range_step(k.prepare, g);
        check_gpu_scheme(k.p, k.exec.backend);
        check_dof_camera(k.depth);
      });
  return c;
}

}  // namespace brume
