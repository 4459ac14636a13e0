// brume — the insert pipeline: what `brume insert` does, as a library call,
// in the shape every effect follows (brume/pipeline.hpp): the photo through
// load_inputs, the object and its range declared in the job, the aerial
// analysis on the photo's measured range, the depth test, prepare, apply,
// record, write.
#include <cstdio>
#include <chrono>
#include <optional>

#include "brume/command.hpp"
#include "brume/error.hpp"
#include "brume/insert.hpp"
#include "brume/record.hpp"
#include "effects/aerial/insert/insert_job.hpp"
#include "core/warnings.hpp"

namespace brume {

namespace {

nlohmann::json insert_gamma_json(const std::array<double, 3>& g) { return {g[0], g[1], g[2]}; }

nlohmann::json insert_record(const AerialParams& p, const InsertAnalysis& a) {
  const AerialAnalysis& aa = a.aerial;
  nlohmann::json j;
  j["parameters"] = insert_aerial_param_table().to_json(p);
  j["units"] = insert_aerial_param_table().units();
  j["diffusion"] = diffusion_record(p.diffusion, aa.plan);
  nlohmann::json g = nlohmann::json::object();
  for (double s : {100.0, 1000.0, 10000.0})
    g[std::to_string(static_cast<int>(s)) + "_m"] = insert_gamma_json(attenuation_direct(p.atmosphere, aa.sensitivity, s));
  j["derived"] = {
      {"depth_test", "the object is visible where alpha > 0, its range is known and <= the scene's measured range "
                     "(ties: the object; unknown scene range = sky = the object)"},
      {"composite", "out = Gamma alpha E + alpha (1 - Gamma) Iinf + (1 - alpha) photo where visible (alpha: the "
                    "blurred coverage with --lambda); the photo elsewhere, bit for bit"},
      {"object_pixels", a.object_pixels},
      {"visible_pixels", a.visible_pixels},
      {"hidden_pixels", a.hidden_pixels},
      {"coverage_without_range_pixels", a.coverage_without_range_pixels},
      {"coverage_without_range_rule", "alpha > 0 where the object's range is unknown: absent (the photo is kept)"},
      {"object_range_min_m", a.object_range_min_m},
      {"object_range_max_m", a.object_range_max_m},
      {"scene_range_max_m", aa.range_max_m},
      {"scene_range_min_m", aa.range_min_m},
      {"unknown_scene_range_pixels", aa.unknown_pixels},
      {"sensitivity", {{"source", aa.sensitivity.source},
                       {"sha256", aa.sensitivity.sha256},
                       {"space", aa.sensitivity.space == SensitivitySpace::xyz
                                     ? "xyz (M diag(Gamma) M^-1 on linear sRGB)"
                                     : "camera_rgb"}}},
      {"gamma_at", g},
      {"gamma_table", {{"samples", aa.gamma.log_gamma.size()}, {"step_m", aa.gamma.step_m},
                       {"interpolation", "linear in ln Gamma; beyond the table along its last slope"}}},
      {"airlight_linear_rgb", aa.airlight},
      {"airlight_source", aa.airlight_source},
      {"beta_550_per_m", aa.beta_550_per_m},
      {"kappa_s_normalised", aa.kappa_s},
      {"sigma_max_px", aa.sigma_max},
  };
  return j;
}

}  // namespace

const std::vector<MapOutput>& insert_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"coverage", "write the (blurred) coverage the photo was composited under, 1 channel; 0 where the object is "
                   "absent or hidden", ""},
      {"scale-map", "write the target scale sigma(x) in pixels (float file)", "sigma is in pixels and exceeds 1"},
  };
  return m;
}

const ParamTable<InsertJob>& insert_job_table() {
  static const ParamTable<InsertJob> t = [] {
    ParamTable<InsertJob> d("insert");
    d.nest(&InsertJob::input, input_param_table(true))
        .nest(&InsertJob::object, insert_object_param_table())
        .nest(&InsertJob::prepare, range_step_param_table())
        .nest(&InsertJob::aerial, insert_aerial_param_table())
        .nest(&InsertJob::output, output_param_table(insert_map_outputs()));
    return d;
  }();
  return t;
}

InsertRun insert_object(const Image& photo, const Image& scene_range, const Image& object_rgba,
                        const Image& object_range, const AerialParams& asked, const RangeStep& prepare,
                        const Exec& exec, const std::set<std::string>& given) {
  validate_insert(asked, given);
  if (exec.backend == Backend::gpu)
    throw Error("insert runs on the CPU only (no GPU passes yet); use --backend cpu (or auto)");
  InsertRun run;
  // Statistics (R_max, Iinf, the sky) and the depth test on the MEASURED
  // range; the prepared range only shapes sigma where the object is not visible.
  // A sparse map is completed first (guided by the photo), when the step says so.
  const CompletedRange done = complete_step(scene_range, photo, prepare, given, exec.threads);
  const Image& scene = done.applied ? done.range : scene_range;
  // --turbidity contrast: the T the photo shows, fitted on the photo and its
  // scene range as `brume aerial --remove` fits it (the object is rendered
  // into that air); everything after runs at the fitted T.
  AerialParams p = asked;
  std::optional<TurbidityContrastFit> contrast;
  if (p.turbidity_rule == "contrast") {
    contrast = fit_turbidity_contrast(photo, scene, p, nullptr, exec.threads);
    p.atmosphere.turbidity = contrast->turbidity;
    p.turbidity_rule.clear();
  }
  run.analysis = analyse_insert(photo, scene, object_rgba, object_range, p, exec.threads);
  PreparedRange prep = prepare_step(scene, prepare, given, exec.threads);
  prep.record["complete"] = done.record;
  Exec cpu = exec;
  cpu.backend = Backend::cpu;  // auto: the CPU (the only backend insert has)
  BackendChoice backend = choose_backend(cpu);
  const auto t0 = std::chrono::steady_clock::now();
  run.result = apply_insert(photo, prep.range, object_rgba, object_range, p, run.analysis, cpu);
  run.record["insert"] = insert_record(p, run.analysis);
  if (contrast) {
    run.record["turbidity_fit"] = contrast->record;
    if (!contrast->warning.empty()) {
      run.record["insert"]["warnings"].push_back(contrast->warning);
      print_warning("insert", contrast->warning);
    }
  }
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  run.record["execution"]["backend_requested"] = enum_name(backend_names(), exec.backend);
  run.record["execution"]["timing"] = cpu_timing_record(t0, run.analysis.aerial.plan.iterations);
  return run;
}

nlohmann::json run_insert_job(const InsertJob& job, const ExecOptions& eo, const RunContext& ctx) {
  const EffectJob<InsertJob> e{
      "insert", insert_job_table(), insert_map_outputs(),
      190,  // aerial's measured peak (insert runs aerial; its own is not measured)
      [&](const InsertJob& j, const ExecOptions&) {
        validate_insert(j.aerial, ctx.given);
        if (j.object.object.empty()) throw Error("no object given: use --object FILE (RGBA, same size as --image)");
        if (j.object.object_range.empty())
          throw Error("no object range given: use --object-range FILE (metres along the ray, unknown where the "
                      "object is absent)");
      },
      [&](const InsertJob& j, LoadedInputs& in, const Exec& exec) {
        FileInfo oinfo;
        const Image obj = read_object_rgba(j.object.object, &oinfo, j.object.object_layer);
        if (obj.width != in.rgb.width || obj.height != in.rgb.height)
          throw Error("--object '" + j.object.object + "' is " + obj.size_string() + " but --image '" +
                      j.input.image + "' is " + in.rgb.size_string() +
                      "; render the object at the photo's size with the photo's camera");
        DepthSource os;
        os.range = j.object.object_range;
        os.channel = j.object.object_range_channel;
        os.depth_scale = j.object.object_depth_scale;
        os.unknown_value = j.object.object_unknown_value;
        os.render_background = j.input.depth.render_background;  // the scene's rule (records before schema 4: off)
        LoadedDepth orange = load_depth(os, in.rgb.width, in.rgb.height);
        if (orange.range.width != in.rgb.width || orange.range.height != in.rgb.height)
          throw Error("--object-range '" + j.object.object_range + "' is " + orange.range.size_string() +
                      " but --image '" + j.input.image + "' is " + in.rgb.size_string() +
                      "; they must be the same size (render the object's range with the photo's camera)");
        InsertRun run = insert_object(in.rgb, in.depth.range, obj, orange.range, j.aerial,
                                      with_camera(j.prepare, in.depth), exec, ctx.given);
        in.record["object"] = file_record(j.object.object, oinfo, obj);
        in.record["object"]["convention"] = oinfo.integer
                                                ? "sRGB-encoded colour, straight alpha: decoded to linear, then premultiplied"
                                                : "linear, premultiplied (as stored)";
        in.record["object_range"] = orange.record;
        return EffectOutput{std::move(run.result.rgb),
                            {{"coverage", std::move(run.result.coverage)}, {"scale-map", std::move(run.result.scale)}},
                            std::move(run.record)};
      }};
  return run_effect_job(e, job, eo, ctx);
}

CommandDef insert_command() {
  CommandDef c = make_command<InsertJob>({
      .name = "insert",
      .cli = "insert",
      .summary = "insert a virtual object (RGBA + range) into a photo with aerial perspective at its own range",
      .table = &insert_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .run = &run_insert_job,
      .report = [](const InsertJob& j, const nlohmann::json& rec) {
        const auto& d = rec["insert"]["derived"];
        const auto& g = d["gamma_at"]["1000_m"];
        std::fprintf(stderr,
                     "brume insert: %s  object %zu px: %zu visible, %zu hidden  range %.4g..%.4g m  Gamma(1 km) "
                     "%.4f %.4f %.4f  sigma_max %.3g px\n",
                     j.output.out.c_str(), d["object_pixels"].get<std::size_t>(), d["visible_pixels"].get<std::size_t>(),
                     d["hidden_pixels"].get<std::size_t>(), d["object_range_min_m"].get<double>(),
                     d["object_range_max_m"].get<double>(), g[0].get<double>(), g[1].get<double>(), g[2].get<double>(),
                     d["sigma_max_px"].get<double>());
      },
  });
  return c;
}

}  // namespace brume
