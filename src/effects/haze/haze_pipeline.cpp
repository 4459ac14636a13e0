// brume — the haze pipeline: what `brume haze` does, as a library call, in
// the shape every effect follows (brume/pipeline.hpp): analyse the measured
// range, prepare it, dispatch once on Exec, record.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <utility>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/gpu_haze.hpp"
#include "brume/haze.hpp"
#include "brume/record.hpp"
#include "effects/haze/haze_job.hpp"
#include "effects/haze/haze_preview.hpp"

namespace brume {

const std::vector<MapOutput>& haze_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"transmission", "write the blurred transmission (alpha after diffusion), 1 channel", ""},
      {"scale-map", "write the target scale sigma(x) in pixels (float file)", "sigma is in pixels and exceeds 1"},
  };
  return m;
}

const ParamTable<HazeJob>& haze_job_table() {
  static const ParamTable<HazeJob> t = [] {
    ParamTable<HazeJob> d("haze");
    d.nest(&HazeJob::input, input_param_table(true))
        .nest(&HazeJob::prepare, range_step_param_table())
        .nest(&HazeJob::haze, haze_param_table())
        .nest(&HazeJob::scene, scene_scale_param_table())
        .nest(&HazeJob::output, output_param_table(haze_map_outputs()))
        .nest(&HazeJob::lidar, camera_lidar_param_table());
    return d;
  }();
  return t;
}

// The "haze" block of a record: parameters, units, the diffusion plan and
// what the analysis derived.
nlohmann::json haze_record(const HazeParams& p, const HazeAnalysis& a) {
  nlohmann::json j;
  j["parameters"] = haze_param_table().to_json(p);
  j["parameters"]["haze"]["kappa_source"] =
      p.visibility_m ? "visibility and albedo (values in derived)" : "kappa-a and kappa-s";
  j["units"] = haze_param_table().units();
  j["diffusion"] = diffusion_record(p.diffusion, a.plan);
  j["derived"] = {
      {"range_max_m", a.range_max_m},
      {"range_min_m", a.range_min_m},
      {"unknown_range_pixels", a.unknown_pixels},
      {"unknown_range_rule", "unknown (NaN, inf, 0) treated as R = R_max"},
      {"sky_rule", a.sky_rule},
      {"sky_transmission", a.sky_beyond ? nlohmann::json(a.sky_transmission) : nlohmann::json()},
      {"kappa_a_normalised", a.kappa_a},
      {"kappa_s_normalised", a.kappa_s},
      {"extinction_per_m", a.extinction_per_m},
      {"kappa_a_per_m", a.kappa_a / a.range_max_m},
      {"kappa_s_per_m", a.kappa_s / a.range_max_m},
      {"sigma_max_px", a.sigma_max},
      {"airlight_linear_rgb", a.airlight},
      {"airlight_source", a.airlight_source},
  };
  return j;
}

// Where brume view's page starts (brume/preview.hpp): the table's defaults
// are normalised (kappa-s 0.25 at R_max), which shows almost no haze where
// the scene's median range is far below its farthest (the demo scene: 8 m
// against 1.2 km). The page starts at the visibility that leaves a
// transmission of 0.8 at the median range, V = 3.912 R_med / ln 1.25 (the
// demo: 150 m; the farther half of the scene then fades from 0.8 to 0).
std::vector<PreviewStart> haze_preview_start(const HazeParams& p, const std::set<std::string>& given,
                                             const PreviewScene& s) {
  std::vector<PreviewStart> v;
  if (p.visibility_m || given.count("kappa-a") || given.count("kappa-s") || !(s.median_range_m > 0.0)) return v;
  const double vis = preview_round(3.912 * s.median_range_m / std::log(1.25));
  v.push_back({"visibility", vis,
               "visibility " + preview_text(vis) + " m: transmission 0.8 at the scene's median range (" +
                   preview_text(s.median_range_m) + " m); the default, normalised kappa-s 0.25 at R_max (" +
                   preview_text(s.range_max_m) + " m), shows little here"});
  return v;
}

// The lengths --scene-scale scales (brume/pipeline.hpp): the medium's
// visibility and the distances that place the scene's end and its sky.
const std::vector<std::string>& haze_scene_lengths() {
  static const std::vector<std::string> n = {"visibility", "range-max", "sky-distance"};
  return n;
}

namespace {

// The effect on the prepared range, with the analysis of the measured one.
HazeRun haze_on_prepared(ConstImageView rgb, HazeAnalysis analysis, const PreparedRange& prep, const HazeParams& p,
                         const Exec& exec) {
  HazeRun run;
  run.analysis = std::move(analysis);
  if (run.analysis.sky_beyond && prep.applied && prep.sky_weight.empty())
    throw Error("internal: the sky lies beyond the medium, but the preparation solved no sky weight "
                "(prepare_step(..., sky_weight = haze_sky_beyond(p)))");
  BackendChoice backend = choose_backend(exec);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json timing;
  if (backend.gpu) {
    GpuHaze gh(*backend.gpu, copy_of(rgb), prep.range,  // the upload's dense staging copy
               run.analysis.sky_beyond ? &prep.sky_weight : nullptr);
    run.result = gh.render(p, run.analysis, exec.gpu_filter);
    timing = gpu_timing_record(gh.timing());
  } else {
    run.result = apply_haze(rgb, prep.range, p, run.analysis, exec, prep.sky_weight);
    timing = cpu_timing_record(t0, run.analysis.plan.iterations);
  }
  run.record["haze"] = haze_record(p, run.analysis);
  if (prep.applied)
    run.record["haze"]["derived"]["unknown_range_rule"] =
        run.analysis.sky_beyond
            ? "prepared: holes filled, the sky's range at S_max (its blur), its transmission as sky_rule says, "
              "horizon margin matted (see prepare)"
            : "prepared: holes filled, sky at S_max, horizon margin matted (see prepare)";
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  return run;
}

std::vector<PreviewStart> haze_preview_start_job(const nlohmann::json& job, const std::set<std::string>& given,
                                                 const PreviewScene& s) {
  HazeJob j;
  haze_job_table().from_json(j, job, "job");
  return haze_preview_start(j.haze, given, s);
}

PreviewFrame haze_preview(const nlohmann::json& job, const PreviewInputs& in) {
  HazeJob j;
  haze_job_table().from_json(j, job, "job");
  return haze_preview_frame(j.haze, in);
}

}  // namespace

// The preview's frame (effects/haze/haze_preview.hpp): the passes and uniforms
// of GpuHaze::render (src/effects/haze/haze_gpu.cpp) with the shader's interpolation.
PreviewFrame haze_preview_frame(const HazeParams& p, const PreviewInputs& in) {
  const HazeAnalysis a = analyse_haze(in.rgb, in.measured, p);
  const bool naive = p.composite == Composite::naive;
  const bool blend = a.sky_beyond && !in.prepared.sky_weight.empty();
  PreviewFrame frame;
  nlohmann::json& plan = frame.plan;
  const char* f = p.diffusion.precision == Precision::f16 ? "RGBA16F" : "RGBA32F";
  plan["targets"] = {{"f0", f}, {"f1", f}, {"aux", "RG32F"}, {"out", "RGBA32F"}};
  plan["steps"] = nlohmann::json::array();
  plan["steps"].push_back({{"pass", "haze.premultiply"},
                           {"in", {"image", "range", "sky", "range"}},
                           {"out", {"f0", "aux"}},
                           {"uniforms",
                            {{"uInvRangeMax", preview_f(static_cast<float>(1.0 / a.range_max_m))},
                             {"uKappa", preview_f(static_cast<float>(a.kappa_a + a.kappa_s))},
                             {"uSigma0", preview_f(static_cast<float>(p.diffusion.sigma0))},
                             {"uSigmaMax", preview_f(static_cast<float>(a.sigma_max))},
                             {"uNaive", preview_i(naive ? 1 : 0)},
                             {"uSkyBlend", preview_i(blend ? 1 : 0)},
                             {"uSkyTau", preview_f(a.sky_transmission)},
                             // haze alone: the falling particles' terms (rain's, snow's) unused, and
                             // their table's sampler given the range (never read)
                             {"uParticles", preview_i(0)},
                             {"uRay", preview_f4(1.0f, 1.0f, 0.0f, 0.0f)},
                             {"uParticleDepth", preview_f4(0.0f, 0.0f, 1.0f, 0.0f)},
                             {"uParticleStepCount", preview_i(1)}}}});
  preview_diffusion_steps(plan, p.diffusion, a.plan, "aux", "f0", "f1", "blurred");
  plan["steps"].push_back({{"pass", "haze.composite"},
                           {"in", {"blurred", "aux"}},
                           {"out", nlohmann::json::array({"out"})},
                           {"uniforms", {{"uAirlight", preview_f3(a.airlight.data())}, {"uNaive", preview_i(naive ? 1 : 0)}}}});
  plan["result"] = "out";
  plan["derived"] = haze_record(p, a)["derived"];
  plan["derived"]["iterations"] = a.plan.iterations;
  return frame;
}

HazeRun run_haze(ConstImageView rgb, ConstImageView measured_range, const HazeParams& p, const RangeStep& prepare,
                 const Exec& exec, const std::set<std::string>& given) {
  validate_haze(p, given);
  // Image-wide statistics (R_max, the airlight from the sky) come from the
  // measured range; the effect then runs on the prepared one, whose sky lies
  // at S_max > R_max (so it gets the far transmission and sigma_max).
  // A sparse map is completed first (guided by rgb), when the step says so.
  const CompletedRange done = complete_step(measured_range, rgb, prepare, given, exec.threads);
  const ConstImageView measured = done.view(measured_range);
  HazeAnalysis analysis = analyse_haze(rgb, measured, p);
  PreparedRange prep = prepare_step(measured, prepare, given, exec.threads, analysis.sky_beyond);
  prep.record["complete"] = done.record;
  return haze_on_prepared(rgb, std::move(analysis), prep, p, exec);
}

HazeRun run_haze_prepared(ConstImageView rgb, ConstImageView measured_range, const PreparedRange& prepared,
                          const HazeParams& p, const Exec& exec, const std::set<std::string>& given) {
  validate_haze(p, given);
  HazeAnalysis analysis = analyse_haze(rgb, measured_range, p);
  if (prepared.range.width != measured_range.width() || prepared.range.height != measured_range.height())
    throw Error("internal: the prepared range is not the measured range's size");
  return haze_on_prepared(rgb, std::move(analysis), prepared, p, exec);
}

nlohmann::json run_haze_job(const HazeJob& job, const ExecOptions& eo, const RunContext& ctx) {
  const EffectJob<HazeJob> e{
      "haze",
      haze_job_table(),
      haze_map_outputs(),
      140,
      [&](const HazeJob& j, const ExecOptions&) { validate_haze(j.haze, ctx.given); },
      [&](const HazeJob& j, LoadedInputs& in, const Exec& exec) {
        if (!j.haze.airlight) check_airlight_sky(in, "haze");
        HazeParams p = j.haze;
        const nlohmann::json scaled = apply_scene_scale(haze_param_table(), p, haze_scene_lengths(), j.scene,
                                                        in.depth.range);
        HazeRun run = run_haze(in.rgb, in.depth.range, p, with_camera(j.prepare, in.depth), exec, ctx.given);
        if (!scaled.is_null()) run.record["scene_scale"] = scaled;
        return EffectOutput{std::move(run.result.rgb),
                            {{"transmission", std::move(run.result.transmission)},
                             {"scale-map", std::move(run.result.scale)}},
                            std::move(run.record),
                            "transmission",
                            run.analysis.airlight};
      }};
  return run_effect_job(e, job, eo, ctx);
}

void print_haze_summary(const std::string& out, const nlohmann::json& rec) {
  const auto& d = rec["haze"]["derived"];
  std::fprintf(stderr, "brume haze: %s  R_max %.4g m  sigma_max %.3g px  %d iterations (%s, %s)\n", out.c_str(),
               d["range_max_m"].get<double>(), d["sigma_max_px"].get<double>(),
               rec["haze"]["diffusion"]["iterations"].get<int>(),
               rec["haze"]["diffusion"]["scheme"].get<std::string>().c_str(),
               rec["execution"]["backend"].get<std::string>().c_str());
}

CommandDef haze_command() {
  CommandDef c = make_command<HazeJob>({
      .name = "haze",
      .cli = "",  // `brume haze` is haze+dof's subcommand: plain haze without a --dof-... flag
      .summary = "haze and fog with scattering blur (Hansard eq. 1-7)",
      .table = &haze_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const HazeJob& j, const std::set<std::string>& g) {
        validate_haze(j.haze, g);
        check_range_step(j.prepare, g);
        if (j.prepare.mode == PrepareMode::off && haze_param_table().is_set(j.haze, "sky-distance", g))
          throw Error("--sky-distance places the sky the preparation identifies, but --prepare off identifies none "
                      "(unknown range is taken as R_max); drop --sky-distance or use --prepare auto");
      },
      .run = &run_haze_job,
      .report = [](const HazeJob& j, const nlohmann::json& rec) { print_haze_summary(j.output.out, rec); },
  });
  // Visibility from dense fog (50 m, the fog threshold is 1 km) to light haze
  // (5 km), log-uniform because perceived haze follows optical depth ~ 1/V
  // over orders of magnitude; albedo 0.8-1 (water droplets and most aerosols
  // scatter far more than they absorb; soot-laden smog reaches 0.8); lambda
  // 0-8 px of blur gain (0: Koschmieder's clean haze; 8 keeps the scattering
  // blur at sigma ~ 8 px at kappa_s' = 1, the soft look of real fog without
  // erasing detail at Middlebury/KITTI sizes). kappa-a and kappa-s take over
  // visibility's role (validate_haze refuses both).
  c.sampling = make_sampling<HazeParams>(haze_param_table(),
                                         {{"visibility", "loguniform(50, 5000)", {"kappa-a", "kappa-s"}},
                                          {"albedo", "uniform(0.8, 1)", {"kappa-a", "kappa-s"}},
                                          {"lambda", "uniform(0, 8)", {}}},
                                         &validate_haze);
  c.gpu_passes = {"haze.premultiply", "diffusion.rates", "diffusion.iterate", "haze.composite"};
  c.preview = &haze_preview;
  c.preview_start = &haze_preview_start_job;
  // --scene-scale scales the lengths to the frame when a job runs; the page's values are metres.
  c.preview_fixed.push_back("scene");
  // A homogeneous medium: Koschmieder's 3.912 / V with a visibility, else the
  // normalised kappas over a given R_max; without either it has no unit.
  c.extinction_per_m = [](const nlohmann::json& job, double) -> std::optional<double> {
    HazeJob j;
    haze_job_table().from_json(j, job, "job");
    return haze_extinction_per_m(j.haze);
  };
  // brume.haze(rgb, range, ...): the arrays read in place (views).
  static const auto call = array_call_table(haze_param_table(), kArrayPrepare | kArrayScene | kArrayExec);
  c.arrays = make_array_form<HazeParams>(
      "haze", "",
      "Haze and fog with scattering blur (Hansard): Beer-Lambert transmission from the range, premultiplied "
      "compositing with the airlight, depth-dependent blur by inhomogeneous diffusion. As `brume haze`.",
      rgb_range_args(ArrayArg::As::view), call, {"rgb", "transmission", "scale", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<HazeParams>& k, const Exec& e, const std::set<std::string>& g) {
        HazeParams p = k.p;
        const nlohmann::json scaled = apply_scene_scale(haze_param_table(), p, haze_scene_lengths(), k.scene,
                                                        in[1].view);
        HazeRun r = run_haze(in[0].view, in[1].view, p, k.prepare, e, g);
        if (!scaled.is_null()) r.record["scene_scale"] = scaled;
        return ArrayResult{{{"rgb", std::move(r.result.rgb)},
                            {"transmission", std::move(r.result.transmission)},
                            {"scale", std::move(r.result.scale)}},
                           std::move(r.record),
                           {},
                           {}};
      },
      [](const ArrayCall<HazeParams>& k, const std::set<std::string>& g) {
        validate_haze(k.p, g);
        check_range_step(k.prepare, g);
      });
  add_camera_lidar(c);  // after c.arrays: lidar= joins the array form
  return c;
}

}  // namespace brume
