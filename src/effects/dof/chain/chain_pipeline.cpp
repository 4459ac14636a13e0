// brume — haze then depth of field in one run (brume/chain.hpp): the range
// prepared once, the haze stage, its linear RGB handed to the DOF stage in
// memory, one record holding both parameter blocks.
#include <cstdio>
#include <chrono>
#include <utility>

#include "brume/command.hpp"
#include "brume/chain.hpp"
#include "brume/error.hpp"
#include "brume/record.hpp"
#include "effects/dof/chain/chain_job.hpp"
#include "effects/dof/dof_preview.hpp"
#include "effects/haze/haze_preview.hpp"

namespace brume {

namespace {

bool has_dof_prefix(const std::string& n) { return n.rfind(kDofPrefix, 0) == 0; }

// The chain's names split into each stage's own: the DOF's without the prefix.
std::set<std::string> haze_given(const std::set<std::string>& given) {
  std::set<std::string> g;
  for (const auto& n : given)
    if (!has_dof_prefix(n)) g.insert(n);
  return g;
}
std::set<std::string> dof_given(const std::set<std::string>& given) {
  std::set<std::string> g;
  const std::string prefix = kDofPrefix;
  for (const auto& n : given)
    if (has_dof_prefix(n)) g.insert(n.substr(prefix.size()));
  return g;
}

// The DOF stage's checks name its flags as `brume dof` spells them
// (--focus-distance); in the chain the user typed --dof-focus-distance.
// Every "--NAME" of a DOF parameter in the message gets the prefix.
[[noreturn]] void rethrow_prefixed(const Error& e) {
  throw Error(prefix_flag_mentions(e.what(), kDofPrefix,
                                   [](const std::string& n) { return dof_param_table().declares(n); }));
}

template <class F>
auto dof_stage(F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error& e) {
    rethrow_prefixed(e);
  }
}

bool cpu_only(DofScheme s) { return s == DofScheme::bertalmio || s == DofScheme::leaky; }

// Both stages' lengths scaled to the frame (--scene-scale): one factor, the
// DOF's names with the chain's prefix in the record's block.
nlohmann::json chain_scene_scale(HazeParams& haze, DofParams& dof, const SceneScale& s, ConstImageView measured) {
  nlohmann::json block = apply_scene_scale(haze_param_table(), haze, haze_scene_lengths(), s, measured);
  if (block.is_null()) return block;
  const nlohmann::json d = apply_scene_scale(dof_param_table(), dof, dof_scene_lengths(), s, measured);
  for (const auto& [n, v] : d["scaled"].items()) block["scaled"][std::string(kDofPrefix) + n] = v;
  return block;
}

// The chain on arrays (brume.haze_dof): haze's keywords and the DOF's with
// their prefix (dof_focus_distance), as the record's "haze" and "dof" blocks.
struct HazeDofParams {
  HazeParams haze;
  DofParams dof;
};
const ParamTable<HazeDofParams>& haze_dof_param_table() {
  static const ParamTable<HazeDofParams> t = [] {
    ParamTable<HazeDofParams> d("haze");
    d.nest(&HazeDofParams::haze, haze_param_table()).nest(&HazeDofParams::dof, dof_param_table(), kDofPrefix);
    return d;
  }();
  return t;
}

}  // namespace

HazeDofRun run_haze_dof(ConstImageView rgb, ConstImageView measured_range, const Intrinsics& k, const HazeParams& haze,
                        const DofParams& dof, const RangeStep& prepare, const Exec& exec,
                        const std::set<std::string>& given) {
  const std::set<std::string> gh = haze_given(given), gd = dof_given(given);
  // Both stages' parameters are checked before either runs.
  validate_haze(haze, gh);
  dof_stage([&] { validate_dof(dof, gd); });
  if (exec.backend == Backend::gpu && cpu_only(dof.scheme))
    throw Error("--dof-scheme " + to_string(dof.scheme) +
                " runs on the CPU only (a comparison with the paper): use --backend cpu or auto, or --dof-scheme "
                "invariant-exact or standard on the GPU");

  // One context for both stages (a second EGL context would cost its start-up again).
  BackendChoice backend = choose_backend(exec);
  Exec ex = exec;
  ex.gpu = backend.gpu;
  if (!backend.gpu) ex.backend = Backend::cpu;  // auto that chose the CPU: the stages must not try again
  Exec ex_dof = ex;
  nlohmann::json dof_note;
  if (cpu_only(dof.scheme) && backend.gpu) {
    ex_dof.gpu = nullptr;
    ex_dof.backend = Backend::cpu;
    dof_note = "--dof-scheme " + to_string(dof.scheme) + " runs on the CPU only; --backend auto ran that stage on the CPU";
  }

  HazeDofRun run;
  // A sparse map is completed first (guided by rgb), when the step says so.
  const CompletedRange done = complete_step(measured_range, rgb, prepare, gh, exec.threads);
  const ConstImageView measured = done.view(measured_range);
  PreparedRange prep = prepare_step(measured, prepare, gh, exec.threads, haze_sky_beyond(haze));
  prep.record["complete"] = done.record;
  run.haze = run_haze_prepared(rgb, measured, prep, haze, ex, gh);
  run.dof = dof_stage([&] { return run_dof_prepared(run.haze.result.rgb, prep, k, dof, ex_dof, gd); });

  run.record["haze"] = run.haze.record["haze"];
  run.record["dof"] = run.dof.record["dof"];
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  if (!dof_note.is_null()) run.record["execution"]["dof_backend"] = {{"backend", "cpu"}, {"note", dof_note}};
  if (backend.gpu)
    run.record["execution"]["handoff"] =
        "the hazy image is read back (haze's readback_ms) and uploaded as the DOF diffusion's input (dof's upload_ms)";
  run.record["execution"]["timing"] = {{"haze", run.haze.record["execution"]["timing"]},
                                       {"dof", run.dof.record["execution"]["timing"]}};
  return run;
}

const std::vector<MapOutput>& haze_dof_map_outputs() {
  static const std::vector<MapOutput> m = [] {
    std::vector<MapOutput> v = haze_map_outputs();
    v.push_back({"dof-scale-map", "write the depth-of-field stage's target scale sigma(x) in pixels (float file)",
                 "sigma is in pixels and exceeds 1"});
    return v;
  }();
  return m;
}

const ParamTable<HazeDofJob>& haze_dof_job_table() {
  static const ParamTable<HazeDofJob> t = [] {
    ParamTable<HazeDofJob> d("haze");
    d.nest(&HazeDofJob::input, input_param_table(true))
        .nest(&HazeDofJob::prepare, range_step_param_table())
        .nest(&HazeDofJob::haze, haze_param_table())
        .nest(&HazeDofJob::dof, dof_param_table(), kDofPrefix)
        .nest(&HazeDofJob::scene, scene_scale_param_table())
        .nest(&HazeDofJob::output, output_param_table(haze_dof_map_outputs()))
        .nest(&HazeDofJob::lidar, camera_lidar_param_table());
    return d;
  }();
  return t;
}

bool dof_stage_requested(const std::set<std::string>& given) {
  for (const auto& n : given)
    if (has_dof_prefix(n)) return true;
  return false;
}

HazeJob haze_part(const HazeDofJob& job, const std::set<std::string>& given) {
  const auto& t = haze_dof_job_table();
  for (const auto& d : t.params())
    if (has_dof_prefix(d.spec.name) && t.is_set(job, d.spec.name, given))
      throw Error("--" + d.spec.name + " is a setting of the depth-of-field stage; plain haze would ignore it: run the "
                  "chain (run_haze_dof_job), or drop it");
  HazeJob h;
  h.input = job.input;
  h.prepare = job.prepare;
  h.haze = job.haze;
  h.scene = job.scene;
  h.output = job.output;
  h.output.maps.erase("dof-scale-map");
  h.lidar = job.lidar;
  return h;
}

nlohmann::json run_haze_dof_job(const HazeDofJob& job, const ExecOptions& eo, const RunContext& ctx) {
  // Every parameter of both stages is checked before any file is touched.
  haze_dof_job_table().validate(job);
  const std::set<std::string> gh = haze_given(ctx.given), gd = dof_given(ctx.given);
  validate_haze(job.haze, gh);
  const DofParams dof = dof_with_lens(job.dof, job.input.depth.lens);
  dof_stage([&] { validate_dof(dof, gd); });
  check_range_step(job.prepare, gh);
  if (eo.backend == Backend::gpu && cpu_only(job.dof.scheme))
    throw Error("--dof-scheme " + to_string(job.dof.scheme) +
                " runs on the CPU only (a comparison with the paper): use --backend cpu or auto, or --dof-scheme "
                "invariant-exact or standard on the GPU");
  const Exec exec = eo.exec();
  check_outputs(job.output, haze_dof_map_outputs());

  LoadedInputs in = load_inputs(job.input, true);
  check_working_memory("haze+dof", in.rgb, 140);  // haze's measured peak (the larger stage); the chain's own is not measured
  if (!job.haze.airlight) check_airlight_sky(in, "haze");
  HazeParams haze = job.haze;
  DofParams scaled_dof = dof;
  const nlohmann::json scaled = chain_scene_scale(haze, scaled_dof, job.scene, in.depth.range);
  const Intrinsics k = dof_stage([&] { return dof_intrinsics(job.input.depth, in.rgb.width, in.rgb.height); });
  HazeDofRun run = run_haze_dof(in.rgb, in.depth.range, k, haze, scaled_dof, with_camera(job.prepare, in.depth), exec,
                                ctx.given);
  if (!scaled.is_null()) run.record["scene_scale"] = scaled;
  run.record["dof"]["derived"]["intrinsics"]["source"] =
      dof_intrinsics_source(job.input.depth, in.rgb.width, in.rgb.height);

  EffectOutput out{std::move(run.dof.result.rgb),
                   {{"transmission", std::move(run.haze.result.transmission)},
                    {"scale-map", std::move(run.haze.result.scale)},
                    {"dof-scale-map", std::move(run.dof.result.scale)}},
                   nlohmann::json::object(),
                   "transmission",
                   run.haze.analysis.airlight};
  // The alpha the haze stage composes (the lens then blurs the colour, not it).
  const OutputLayers layers = compose_output_layers(job.output, &in, out);
  if (!layers.record.is_null()) run.record["output_layers"] = layers.record;
  const nlohmann::json rec =
      job_record("haze+dof", ctx, haze_dof_job_table().to_json(job), in.record, run.record, eo.timing);
  write_outputs(job.output, haze_dof_map_outputs(), out.main, out.maps, &in.image_info, rec, ctx.files, &layers);
  return rec;
}

namespace {

// The preview (brume/preview.hpp): haze's plan, then the depth-of-field
// steps on its result, as run_haze_dof hands the hazy image to the DOF stage.
PreviewFrame haze_dof_preview(const nlohmann::json& job, const PreviewInputs& in) {
  HazeDofJob j;
  haze_dof_job_table().from_json(j, job, "job");
  PreviewFrame frame = haze_preview_frame(j.haze, in);
  const nlohmann::json dof = dof_stage([&] {
    const Intrinsics k = dof_intrinsics(j.input.depth, preview_full_width(in), preview_full_height(in));
    return dof_preview_steps(frame, dof_with_lens(j.dof, j.input.depth.lens), preview_intrinsics(k, in.scale), in,
                             "out", "dof", "dof.blurred");
  });
  nlohmann::json& plan = frame.plan;
  plan["result"] = "dof.blurred";
  plan["derived"]["dof"] = dof;
  plan["derived"]["iterations"] = plan["derived"]["iterations"].get<int>() + dof["iterations"].get<int>();
  return frame;
}

}  // namespace

CommandDef haze_dof_command() {
  CommandDef c = make_command<HazeDofJob>({
      .name = "haze+dof",
      .cli = "haze",
      .summary = "haze and fog with scattering blur (Hansard eq. 1-7); any --dof-... flag adds depth of field after it",
      .table = &haze_dof_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .batchable = true,
      .check = [](const HazeDofJob& j, const std::set<std::string>& g) {
        const std::set<std::string> gh = haze_given(g);
        validate_haze(j.haze, gh);
        check_range_step(j.prepare, gh);
        try {
          validate_dof(dof_with_lens(j.dof, j.input.depth.lens), dof_given(g));
        } catch (const Error& e) {
          throw Error(std::string("depth-of-field stage (dof.*): ") + e.what());
        }
      },
      .run = &run_haze_dof_job,
      .report = [](const HazeDofJob& j, const nlohmann::json& rec) {
        print_haze_summary(j.output.out, rec);
        if (!rec.contains("dof")) return;  // `brume haze` without a --dof-... flag ran plain haze
        const auto& f = rec["dof"]["derived"];
        std::fprintf(stderr, "  then dof: CoC at infinity %.3g px  sigma_max %.3g px (%zu capped)  %d iterations (%s)\n",
                     f["coc_infinity_px"].get<double>(), f["sigma_max_px"].get<double>(),
                     f["capped_pixels"].get<std::size_t>(), rec["dof"]["diffusion"]["iterations"].get<int>(),
                     rec["dof"]["diffusion"]["dof_scheme"].get<std::string>().c_str());
      },
  });
  c.stage_prefix = kDofPrefix;
  // `brume haze`: a DOF flag given enables the DOF stage; without one the
  // run, its record and `brume run` are plain haze's.
  c.cli_run = [](const nlohmann::json& job, const ExecOptions& e, const RunContext& ctx) {
    HazeDofJob j;
    haze_dof_job_table().from_json(j, job, "job");
    return dof_stage_requested(ctx.given) ? run_haze_dof_job(j, e, ctx) : run_haze_job(haze_part(j, ctx.given), e, ctx);
  };
  c.gpu_passes = {"haze.premultiply", "diffusion.rates", "diffusion.iterate", "haze.composite"};
  c.preview = &haze_dof_preview;
  // Haze's start, then the DOF stage's under its prefix (the camera once).
  c.preview_start = [](const nlohmann::json& job, const std::set<std::string>& given, const PreviewScene& s) {
    HazeDofJob j;
    haze_dof_job_table().from_json(j, job, "job");
    std::vector<PreviewStart> v = haze_preview_start(j.haze, haze_given(given), s);
    for (PreviewStart p : dof_preview_start(dof_with_lens(j.dof, j.input.depth.lens), s.camera_given, s)) {
      if (p.name != "fov-x") {
        p.why = prefix_flag_mentions(p.why, kDofPrefix,
                                     [](const std::string& n) { return dof_param_table().declares(n); });
        p.name = kDofPrefix + p.name;
      }
      v.push_back(std::move(p));
    }
    return v;
  };
  // --scene-scale scales the lengths to the frame when a job runs; the page's values are metres.
  c.preview_fixed.push_back("scene");
  // brume.haze_dof(rgb, range, ...): the chain in memory, the range prepared
  // once, the arrays read in place; its record is the chain's, which `brume
  // run` repeats (brume.transforms.HazeThenDof runs it).
  static const auto call = array_call_table(haze_dof_param_table(),
                                            kArrayPrepare | kArrayIntrinsics | kArrayScene | kArrayExec);
  c.arrays = make_array_form<HazeDofParams>(
      "haze_dof", "",
      "Haze and fog with scattering blur, then depth of field through the hazy image (the chain `brume haze "
      "--dof-...`): the range prepared once, the DOF stage's keywords prefixed dof_ (dof_focus_distance). As "
      "`brume haze` with --dof-... flags.",
      rgb_range_args(ArrayArg::As::view), call, {"rgb", "transmission", "scale", "dof_scale", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<HazeDofParams>& k, const Exec& e, const std::set<std::string>& g) {
        const ConstImageView& rgb = in[0].view;
        HazeParams haze = k.p.haze;
        DofParams dof = dof_with_lens(k.p.dof, k.depth.lens);
        const nlohmann::json scaled = chain_scene_scale(haze, dof, k.scene, in[1].view);
        const Intrinsics ki = dof_stage([&] { return dof_intrinsics(k.depth, rgb.width(), rgb.height()); });
        HazeDofRun r = run_haze_dof(rgb, in[1].view, ki, haze, dof, k.prepare, e, g);
        if (!scaled.is_null()) r.record["scene_scale"] = scaled;
        return ArrayResult{{{"rgb", std::move(r.dof.result.rgb)},
                            {"transmission", std::move(r.haze.result.transmission)},
                            {"scale", std::move(r.haze.result.scale)},
                            {"dof_scale", std::move(r.dof.result.scale)}},
                           std::move(r.record),
                           {},
                           {}};
      },
      [](const ArrayCall<HazeDofParams>& k, const std::set<std::string>& g) {
        validate_haze(k.p.haze, haze_given(g));
        check_range_step(k.prepare, haze_given(g));
        dof_stage([&] {
          validate_dof(dof_with_lens(k.p.dof, k.depth.lens), dof_given(g));
          check_dof_camera(k.depth);
        });
        if (k.exec.backend == Backend::gpu && cpu_only(k.p.dof.scheme))
          throw Error("--dof-scheme " + to_string(k.p.dof.scheme) + " runs on the CPU only: use backend cpu or auto");
      });
  // The chain's medium is its haze stage's.
  c.extinction_per_m = [](const nlohmann::json& job, double) -> std::optional<double> {
    HazeDofJob j;
    haze_dof_job_table().from_json(j, job, "job");
    return haze_extinction_per_m(j.haze);
  };
  add_camera_lidar(c);
  return c;
}

}  // namespace brume
