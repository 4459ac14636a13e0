// brume — the haze pipeline: what `brume haze` does, as a library call, in
// the shape every effect follows (brume/pipeline.hpp): analyse the measured
// range, prepare it, dispatch once on Exec, record.
#include <chrono>
#include <utility>

#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/haze.hpp"
#include "brume/record.hpp"

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
        .nest(&HazeJob::output, output_param_table(haze_map_outputs()));
    return d;
  }();
  return t;
}

namespace {

// The effect on the prepared range, with the analysis of the measured one.
HazeRun haze_on_prepared(ConstImageView rgb, HazeAnalysis analysis, const PreparedRange& prep, const HazeParams& p,
                         const Exec& exec) {
  HazeRun run;
  run.analysis = std::move(analysis);
  BackendChoice backend = choose_backend(exec);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json timing;
  if (backend.gpu) {
    GpuHaze gh(*backend.gpu, copy_of(rgb), prep.range);  // the upload's dense staging copy
    run.result = gh.render(p, run.analysis, exec.gpu_filter);
    timing = gpu_timing_record(gh.timing());
  } else {
    run.result = apply_haze(rgb, prep.range, p, run.analysis, exec);
    timing = cpu_timing_record(t0, run.analysis.plan.iterations);
  }
  run.record["haze"] = haze_record(p, run.analysis);
  if (prep.applied)
    run.record["haze"]["derived"]["unknown_range_rule"] =
        "prepared: holes filled, sky at S_max, horizon margin matted (see prepare)";
  run.record["prepare"] = prep.record;
  run.record["execution"] = backend.record;
  run.record["execution"]["timing"] = timing;
  return run;
}

}  // namespace

HazeRun run_haze(ConstImageView rgb, ConstImageView measured_range, const HazeParams& p, const RangeStep& prepare,
                 const Exec& exec, const std::set<std::string>& given) {
  validate_haze(p, given);
  // Image-wide statistics (R_max, the airlight from the sky) come from the
  // measured range; the effect then runs on the prepared one, whose sky lies
  // at S_max > R_max (so it gets the far transmission and sigma_max).
  HazeAnalysis analysis = analyse_haze(rgb, measured_range, p);
  const PreparedRange prep = prepare_step(measured_range, prepare, given, exec.threads);
  return haze_on_prepared(rgb, std::move(analysis), prep, p, exec);
}

HazeRun run_haze_prepared(const Image& rgb, const Image& measured_range, const PreparedRange& prepared,
                          const HazeParams& p, const Exec& exec, const std::set<std::string>& given) {
  validate_haze(p, given);
  HazeAnalysis analysis = analyse_haze(rgb, measured_range, p);
  if (prepared.range.width != measured_range.width || prepared.range.height != measured_range.height)
    throw Error("internal: the prepared range is not the measured range's size");
  return haze_on_prepared(rgb, std::move(analysis), prepared, p, exec);
}

nlohmann::json run_haze_job(const HazeJob& job, const ExecOptions& eo, const RunContext& ctx) {
  // Every parameter is checked before any file is touched, whatever the input.
  haze_job_table().validate(job);
  validate_haze(job.haze, ctx.given);
  check_range_step(job.prepare, ctx.given);
  const Exec exec = eo.exec();
  check_outputs(job.output, haze_map_outputs());

  LoadedInputs in = load_inputs(job.input, true);

  check_working_memory("haze", in.rgb, 140);  // measured peak bytes per pixel (README "Reliability")
  HazeRun run = run_haze(in.rgb, in.depth.range, job.haze, job.prepare, exec, ctx.given);

  const nlohmann::json rec = job_record("haze", ctx, haze_job_table().to_json(job), in.record, run.record, eo.timing);
  write_outputs(job.output, haze_map_outputs(), run.result.rgb,
                {{"transmission", run.result.transmission}, {"scale-map", run.result.scale}}, &in.image_info, rec);
  return rec;
}

}  // namespace brume
