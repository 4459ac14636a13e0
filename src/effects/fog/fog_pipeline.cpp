// brume — the layered-fog pipeline: what `brume fog` does, as a library call,
// in the shape every effect follows (brume/pipeline.hpp): analyse the
// measured range (R_max, the sky's colour), prepare it, dispatch once on
// Exec, record.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/gpu_fog.hpp"
#include "brume/record.hpp"
#include "effects/fog/fog_job.hpp"

namespace brume {

namespace {

nlohmann::json fog_record(const FogParams& p, const FogAnalysis& a) {
  nlohmann::json j;
  j["parameters"] = fog_param_table().to_json(p);
  j["units"] = fog_param_table().units();
  if (p.lambda > 0.0) j["diffusion"] = diffusion_record(p.diffusion, a.plan);
  j["derived"] = {
      {"range_max_m", a.range_max_m},
      {"range_min_m", a.range_min_m},
      {"unknown_range_pixels", a.unknown_pixels},
      {"sky_distance_m", a.sky_distance_m},
      {"sky_distance_source", a.sky_distance_source},
      {"sky_rule",
       a.sky_at_infinity
           ? "sky pixels integrate to infinity along their ray: finite where the density vanishes along it, else "
             "infinite (transmission 0, the fog colour); they blur as at sky_distance_m; across the horizon margin "
             "the scene's and the sky's transmissions blend by the preparation's sky weight"
       : a.sky_blend
           ? "sky pixels integrate to infinity along their ray where the density vanishes along it, else over "
             "sky_distance_m (given); they blur as at sky_distance_m; across the horizon margin the scene's and the "
             "sky's transmissions blend by the preparation's sky weight"
           : "--sky-rule s-max: sky pixels (the margin included) integrate to infinity along their ray where the "
             "density vanishes along it, else over sky_distance_m; they blur as at sky_distance_m"},
      {"optical_depth_rule", "F = l (D(y_f) - D(y_c)) / (y_f - y_c), the mean density over the height interval"},
      {"sigma_max_px", a.sigma_max},
      {"airlight_linear_rgb", a.airlight},
      {"airlight_source", a.airlight_source},
  };
  if (a.camera_used) {
    j["derived"]["camera"] = camera_record(a.camera);
    j["derived"]["density_at_camera_per_m"] = a.density.at(0.0);
  }
  if (!a.table.path.empty())
    j["derived"]["table"] = {{"path", a.table.path}, {"sha256", a.table.sha256}, {"rows", a.table.height_m.size()},
                             {"rule", "piecewise linear, integrated exactly, end values held"}};
  return j;
}

// The range the effect runs on: the prepared one with the identified sky
// unknown again, so that it integrates along its ray (the margin keeps its
// harmonic range, blended by the sky weight; --sky-rule s-max: the margin
// too is sky); or, unprepared, the measured one, where every unknown pixel is sky.
Image effect_range(const PreparedRange& prep, bool blend) {
  Image r = prep.range;
  if (prep.applied)
    for (std::size_t i = 0; i < r.pixels(); ++i)
      if (blend ? prep.sky_weight.data[i] >= 1.0f : prep.sky_mask.data[i] != 0.0f) r.data[i] = 0.0f;
  return r;
}

}  // namespace

const std::vector<MapOutput>& fog_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"optical-depth", "write the optical depth F along each pixel's ray (float file)",
       "the optical depth is unbounded (and +inf behind classic linear fog's end)"},
      {"transmission", "write the transmission f = exp(-F) (after the blur when --lambda > 0), 1 channel", ""},
  };
  return m;
}

const ParamTable<FogJob>& fog_job_table() {
  static const ParamTable<FogJob> t = [] {
    ParamTable<FogJob> d("fog");
    d.nest(&FogJob::input, input_param_table(true))
        .nest(&FogJob::prepare, range_step_param_table())
        .nest(&FogJob::fog, fog_param_table())
        .nest(&FogJob::scene, scene_scale_param_table())
        .nest(&FogJob::output, output_param_table(fog_map_outputs()))
        .nest(&FogJob::lidar, camera_lidar_param_table());
    return d;
  }();
  return t;
}

// The parameters of fog that --scene-scale scales (brume/pipeline.hpp): the
// density along the rays and the classic linear fog's ranges, those the job
// uses (a default it does not use stays the default, which the checks read
// as not given). Not the heights (the falloff, the band, the ramp): the
// camera's height above the ground is metres whatever the frame, so the
// fog's layer keeps its place around it.
static std::vector<std::string> fog_scene_lengths(const FogParams& p) {
  if (p.classic == ClassicFog::linear) return {"fog-start", "fog-end", "sky-distance"};
  if (p.classic == ClassicFog::none && p.profile == HeightProfile::table) return {"sky-distance"};
  return {"density", "sky-distance"};
}

// Where brume view's page starts (brume/preview.hpp). A height profile needs
// the camera's intrinsics and its height: where the command line gave none,
// the page assumes a 60 degree field of view and 1.6 m (eye height) and says
// so. The default density (0.02 /m) is kept where it gives an optical depth
// between 0.05 and 5 at the scene's median range along a level ray from the
// camera; else (a room, a mountain range) the page starts at the density
// that leaves a transmission of 1/2 there.
static std::vector<PreviewStart> fog_preview_start(const nlohmann::json& job, const std::set<std::string>&,
                                                   const PreviewScene& s) {
  FogJob j;
  fog_job_table().from_json(j, job, "job");
  const FogParams& p = j.fog;
  std::vector<PreviewStart> v;
  const bool heights = p.classic == ClassicFog::none && p.profile != HeightProfile::constant;
  double height = p.camera.height_m;
  if (heights) {
    if (!s.camera_given) v.push_back(preview_assumed_camera(s));
    if (std::isnan(height) && p.camera.view_matrix_file.empty()) {
      height = 1.6;
      v.push_back({"camera-height", height,
                   "the camera is assumed 1.6 m above the ground (eye height; the command line gave none): the "
                   "fog's layer lies on the ground; set it under camera"});
    }
  }
  if (p.classic != ClassicFog::none || p.profile == HeightProfile::table || !(s.median_range_m > 0.0)) return v;
  const double level = p.profile == HeightProfile::exponential && std::isfinite(height)
                           ? std::exp(-p.falloff_per_m * (height - p.base_height_m))
                           : 1.0;
  const double tau = p.density_per_m * level * s.median_range_m;
  if (tau >= 0.05 && tau <= 5.0) return v;
  const double d = preview_round(std::log(2.0) / (level * s.median_range_m));
  v.push_back({"density", d,
               "density " + preview_text(d) + " /m: transmission 1/2 at the scene's median range (" +
                   preview_text(s.median_range_m) + " m) at the camera's height; the default 0.02 /m gives " +
                   (tau < 0.05 ? "almost no fog" : "a wall of fog") + " here"});
  return v;
}

// The preview's frame (brume/preview.hpp): the passes and uniforms of
// GpuFog::render (src/effects/fog/fog_gpu.cpp) on the effect's range, shader filtering.
PreviewFrame fog_preview(const nlohmann::json& job, const PreviewInputs& in) {
  FogJob j;
  fog_job_table().from_json(j, job, "job");
  const FogParams& p = j.fog;
  const int w = in.rgb.width, h = in.rgb.height;
  const bool heights = p.classic == ClassicFog::none && p.profile != HeightProfile::constant;
  Camera camera = heights ? depth_camera(j.input.depth, preview_full_width(in), preview_full_height(in), p.camera)
                          : make_camera(Intrinsics{1.0, 1.0, NAN, NAN}, w, h);
  if (heights) {  // the files' camera for the inputs at 1/scale
    camera.k = preview_intrinsics(camera.k, in.scale);
    camera.width = w;
    camera.height = h;
  }
  const bool blend = p.sky_rule == SkyRule::automatic && in.prepared.applied;
  const Image range = effect_range(in.prepared, blend);
  const FogAnalysis a = analyse_fog(in.rgb, in.measured, range, camera, p, j.prepare.params.s_max_factor);
  const FogDensity& d = a.density;
  constexpr std::size_t kMaxKnots = 32;  // BRUME_PROFILE_MAX_KNOTS in GLSL
  if (d.knot_u.size() > kMaxKnots)
    throw Error("--table has " + std::to_string(d.knot_u.size()) + " rows; the GPU pass holds at most 32");
  std::vector<float> ku(kMaxKnots, 0.0f), kd(kMaxKnots, 0.0f);
  for (std::size_t i = 0; i < d.knot_u.size(); ++i) {
    ku[i] = static_cast<float>(d.knot_u[i]);
    kd[i] = static_cast<float>(d.knot_density[i]);
  }
  const bool blur = p.lambda > 0.0;
  const bool sky_blend = a.sky_blend && !in.prepared.sky_weight.empty();
  const Mat3 R = camera.world_from_camera().rotation;
  const auto f = [](double v) { return static_cast<float>(v); };
  PreviewFrame frame;
  nlohmann::json& plan = frame.plan;
  // The effect's range, its sky unknown again (-1, as the GPU uploads it): with
  // --sky-rule auto, prepared, the sky beyond the margin; else the sky mask.
  const std::string range_name = frame.add_map("fog.range", preview_unknown_negative(range));
  const char* fmt = p.diffusion.precision == Precision::f16 ? "RGBA16F" : "RGBA32F";
  plan["targets"] = {{"f0", fmt}, {"f1", fmt}, {"aux", "RGBA32F"}, {"out", "RGBA32F"}};
  plan["steps"] = nlohmann::json::array();
  plan["steps"].push_back(
      {{"pass", "fog.apply"},
       {"in", {"image", range_name, "sky"}},
       {"out", {"f0", "aux"}},
       {"uniforms",
        {{"uRayRow", preview_f3(f(R.m[1][0]), f(R.m[1][1]), f(R.m[1][2]))},
         {"uK", preview_f4(f(camera.k.cx), f(camera.k.cy), f(1.0 / camera.k.fx), f(1.0 / camera.k.fy))},
         {"uKind", preview_i(d.kind())},
         {"uExp", preview_f3(f(d.d0), f(d.falloff), f(d.exponent_c))},
         {"uBand", preview_f2(f(d.band_offset), f(d.band_half_width))},
         {"uClassic", preview_f2(f(d.fog_start), f(d.fog_end))},
         {"uKnots", preview_i(static_cast<int>(d.knot_u.size()))},
         {"uKnotU", {"1fv", ku}},
         {"uKnotD", {"1fv", kd}},
         {"uSkyDistance", preview_f(a.sky_at_infinity ? -1.0f : f(a.sky_distance_m))},
         {"uSkyBlurDistance", preview_f(f(a.sky_distance_m))},
         {"uSkyBlend", preview_i(sky_blend ? 1 : 0)},
         {"uAirlight", preview_f3(a.airlight.data())},
         {"uBlur", preview_i(blur ? 1 : 0)},
         {"uScale", preview_f4(f(p.diffusion.sigma0), f(p.lambda), f(p.albedo), f(1.0 / a.range_max_m))},
         {"uSigmaMax", preview_f(f(a.sigma_max))},
         {"uDepthBuffer", preview_i(0)},
         {"uDepthLinear", preview_f3(0.0f, 0.0f, 0.0f)}}}});
  plan["result"] = "f0";
  if (blur) {
    preview_diffusion_steps(plan, p.diffusion, a.plan, "aux", "f0", "f1", "blurred");
    plan["steps"].push_back({{"pass", "haze.composite"},
                             {"in", {"blurred", "aux"}},
                             {"out", nlohmann::json::array({"out"})},
                             {"uniforms", {{"uAirlight", preview_f3(a.airlight.data())}, {"uNaive", preview_i(0)}}}});
    plan["result"] = "out";
  }
  plan["derived"] = fog_record(p, a)["derived"];
  plan["derived"]["iterations"] = blur ? a.plan.iterations : 0;
  return frame;
}

// What a fog job needs besides its values, checked before any pixel: a
// height profile needs the camera's intrinsics (the rays' directions) and its
// height above the ground. The size is nominal: neither check depends on it.
static void check_fog_camera(const FogParams& p, const DepthSource& depth, const std::set<std::string>& given) {
  validate_fog(p, given);
  if (p.classic != ClassicFog::none || p.profile == HeightProfile::constant) return;
  depth_camera(depth, 640, 480, p.camera)
      .require_height("--profile " + enum_name(height_profile_names(), p.profile) + " (the fog depends on height)");
}

FogRun run_fog(DenseImageRef rgb, DenseImageRef measured_range, const DepthSource& depth, const FogParams& p,
               const RangeStep& prepare, const Exec& exec, const std::set<std::string>& given,
               const Image* window_depth) {
  validate_fog(p, given);
  check_range_step(prepare, given);
  // The pose matters only for the height profiles; classic and constant fog
  // need no intrinsics (a range map alone is enough).
  const bool heights = p.classic == ClassicFog::none && p.profile != HeightProfile::constant;
  const Camera camera = heights ? depth_camera(depth, rgb.width, rgb.height, p.camera)
                                : make_camera(Intrinsics{1.0, 1.0, NAN, NAN}, rgb.width, rgb.height);
  FogRun run;
  // A sparse map is completed first (guided by rgb), when the step says so.
  const CompletedRange done = complete_step(measured_range.view(), rgb.view(), prepare, given, exec.threads);
  const DenseImageRef measured = done.applied ? DenseImageRef(done.range) : measured_range;
  PreparedRange prep = prepare_step(measured.view(), prepare, given, exec.threads, p.sky_rule == SkyRule::automatic);
  prep.record["complete"] = done.record;
  const bool blend = p.sky_rule == SkyRule::automatic && prep.applied;
  const Image range = effect_range(prep, blend);
  const Image no_weight;
  const Image& weight = blend ? prep.sky_weight : no_weight;
  run.analysis = analyse_fog(rgb, measured, range, camera, p, prepare.params.s_max_factor);
  BackendChoice backend = choose_backend(exec);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json timing;
  // A depth buffer goes to the GPU as it is (the pass linearises it) when
  // nothing was prepared; a prepared range (holes filled: --prepare auto
  // found some) is the CPU's and goes as range. Unprepared, both carry the
  // same unknown pixels (the clear value, NaN), so the sky is the same.
  const bool gpu_depth = backend.gpu && window_depth && !window_depth->data.empty() && !prep.applied &&
                        !done.applied;
  if (backend.gpu) {
    std::unique_ptr<GpuFog> gf =
        gpu_depth ? std::make_unique<GpuFog>(*backend.gpu, rgb, *window_depth,
                                             parse_depth_buffer_convention(depth.convention), depth.near_m, depth.far_m)
                  : std::make_unique<GpuFog>(*backend.gpu, rgb, range, &weight);
    run.result = gf->render(p, run.analysis, exec.gpu_filter);
    timing = gpu_timing_record(gf->timing());
    // GpuTiming's first-pass slot is haze's premultiply; here it times the
    // fog pass (ray, optical depth, composite, or F0, sigma and the rates).
    if (timing.contains("premultiply_ms")) {
      timing["fog_pass_ms"] = timing["premultiply_ms"];
      timing.erase("premultiply_ms");
    }
  } else {
    run.result = apply_fog(rgb, range, p, run.analysis, exec, weight);
    timing = cpu_timing_record(t0, run.analysis.plan.iterations);
  }
  run.record["fog"] = fog_record(p, run.analysis);
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  if (backend.gpu)
    run.record["execution"]["gpu_depth_input"] =
        gpu_depth ? "window depth, linearised in the fog pass (src/depth/depth_math.glsl)" : "range from the CPU";
  return run;
}

nlohmann::json run_fog_job(const FogJob& job, const ExecOptions& eo, const RunContext& ctx) {
  const EffectJob<FogJob> e{
      "fog",
      fog_job_table(),
      fog_map_outputs(),
      150,
      [&](const FogJob& j, const ExecOptions&) { validate_fog(j.fog, ctx.given); },
      [&](const FogJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.fog.airlight) check_airlight_sky(in, "fog");
        FogParams p = j.fog;
        const nlohmann::json scaled = apply_scene_scale(fog_param_table(), p, fog_scene_lengths(p), j.scene,
                                                        in.depth.range);
        FogRun run = run_fog(in.rgb, in.depth.range, j.input.depth, p, with_camera(j.prepare, in.depth), exec,
                             ctx.given, &in.depth.window_depth);
        if (!scaled.is_null()) run.record["scene_scale"] = scaled;
        return EffectOutput{std::move(run.result.rgb),
                            {{"optical-depth", std::move(run.result.optical_depth)},
                             {"transmission", std::move(run.result.transmission)}},
                            std::move(run.record),
                            "transmission",
                            run.analysis.airlight};
      }};
  return run_effect_job(e, job, eo, ctx);
}

CommandDef fog_command() {
  CommandDef c = make_command<FogJob>({
      .name = "fog",
      .cli = "fog",
      .summary = "layered fog: height densities integrated along each pixel's ray (Zhou, Chen, Smith), optional "
                 "scattering blur",
      .table = &fog_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const FogJob& j, const std::set<std::string>& g) {
        validate_fog(j.fog, g);
        check_range_step(j.prepare, g);
      },
      .run = &run_fog_job,
      .report = [](const FogJob& j, const nlohmann::json& rec) {
        const auto& d = rec["fog"]["derived"];
        const bool inf = d["sky_distance_source"].get<std::string>().rfind("infinity", 0) == 0;
        std::fprintf(stderr, "brume fog: %s  R_max %.4g m  sky %s%.4g m  sigma_max %.3g px (%s)\n",
                     j.output.out.c_str(), d["range_max_m"].get<double>(), inf ? "at infinity, its blur at " : "at ",
                     d["sky_distance_m"].get<double>(), d["sigma_max_px"].get<double>(),
                     rec["execution"]["backend"].get<std::string>().c_str());
      },
  });
  // Ground density D0 0.002-0.08 /m, i.e. a Koschmieder visibility 3.912/D0
  // of 2 km (mist) down to 50 m (thick fog), log-uniform as for haze;
  // falloff B 0.005-0.2 /m, a scale height 1/B of 200 m (a deep hazy
  // boundary layer) down to 5 m (valley fog lying on the ground); albedo as
  // haze; blur gain 0.5-8 px: unlike haze's, fog's albedo only shapes the
  // blur, so a draw of lambda 0 (Zhou's fog without blur) with an albedo would
  // be refused (validate_fog) -- every combination of the ranges' ends must
  // run (the transforms check them when made) -- and 0.5 px of gain is a
  // blur below a pixel. lambda 0, given, drops the albedo. --classic drops
  // them all; a profile other than the exponential drops the falloff, and the
  // table profile (whose file gives the densities) the density too: a
  // constant, band or ramp profile draws its density as the exponential does.
  c.sampling = make_sampling<FogParams>(fog_param_table(),
                                        {{"density", "loguniform(0.002, 0.08)", {"classic", "profile=table"}},
                                         {"falloff", "loguniform(0.005, 0.2)", {"classic", "profile!=exponential"}},
                                         {"lambda", "uniform(0.5, 8)", {"classic"}},
                                         {"albedo", "uniform(0.8, 1)", {"classic", "lambda=0"}}},
                                        &validate_fog);
  c.gpu_passes = {"fog.apply", "diffusion.rates", "diffusion.iterate", "haze.composite"};
  c.preview = &fog_preview;
  c.preview_start = &fog_preview_start;
  // --scene-scale scales the lengths to the frame when a job runs; the page's values are metres.
  c.preview_fixed.push_back("scene");
  // The height profile's density (a table profile reads its file); classic
  // OpenGL fog is a look, not a medium.
  c.extinction_per_m = [](const nlohmann::json& job, double height_m) -> std::optional<double> {
    FogJob j;
    fog_job_table().from_json(j, job, "job");
    if (j.fog.classic != ClassicFog::none) return std::nullopt;
    const DensityTable table =
        j.fog.profile == HeightProfile::table ? read_density_table(j.fog.table_file) : DensityTable{};
    return fog_density(j.fog, table, 0.0).at(height_m);
  };
  c.height_medium = [](const nlohmann::json& job) -> std::shared_ptr<const HeightMedium> {
    FogJob j;
    fog_job_table().from_json(j, job, "job");
    if (j.fog.classic != ClassicFog::none || j.fog.profile == HeightProfile::constant) return nullptr;
    return std::make_shared<const HeightMedium>(j.fog);  // the profile and the pose, not the fog's look
  };
  static const auto call = array_call_table(fog_param_table(),
                                            kArrayPrepare | kArrayIntrinsics | kArrayScene | kArrayExec);
  c.arrays = make_array_form<FogParams>(
      "fog", "",
      "Layered fog from the range and the camera (Zhou, Chen, Smith), with scattering blur for lambda_ > 0. "
      "The intrinsics (fx.. or fov_x/fov_y) and the pose are keywords. As `brume fog`.",
      rgb_range_args(ArrayArg::As::dense), call, {"rgb", "optical_depth", "transmission", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<FogParams>& k, const Exec& e, const std::set<std::string>& g) {
        FogParams p = k.p;
        const nlohmann::json scaled = apply_scene_scale(fog_param_table(), p, fog_scene_lengths(p), k.scene,
                                                        in[1].dense.view());
        FogRun r = run_fog(in[0].dense, in[1].dense, k.depth, p, k.prepare, e, g);
        if (!scaled.is_null()) r.record["scene_scale"] = scaled;
        return ArrayResult{{{"rgb", std::move(r.result.rgb)},
                            {"optical_depth", std::move(r.result.optical_depth)},
                            {"transmission", std::move(r.result.transmission)}},
                           std::move(r.record),
                           {},
                           {}};
      },
      [](const ArrayCall<FogParams>& k, const std::set<std::string>& g) {
        check_fog_camera(k.p, k.depth, g);
        check_range_step(k.prepare, g);
      });
  add_camera_lidar(c);
  return c;
}

}  // namespace brume
