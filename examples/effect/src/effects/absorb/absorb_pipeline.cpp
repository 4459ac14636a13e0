// brume — `brume absorb`, the example effect's pipeline: the shared steps
// (brume/pipeline.hpp: load the inputs, complete and prepare the range, write
// the outputs and the record) around run_absorb, and its definition for the
// list of commands.
#include <cstdio>

#include "brume/command.hpp"
#include "brume/record.hpp"
#include "effects/absorb/absorb_job.hpp"

namespace brume {

const std::vector<MapOutput>& absorb_map_outputs() {
  static const std::vector<MapOutput> m = {
      {"transmission", "write the transmission exp(-kappa_a R), 1 channel", ""},
  };
  return m;
}

const ParamTable<AbsorbJob>& absorb_job_table() {
  static const ParamTable<AbsorbJob> t = [] {
    ParamTable<AbsorbJob> d("absorb");
    d.nest(&AbsorbJob::input, input_param_table(true))
        .nest(&AbsorbJob::prepare, range_step_param_table())
        .nest(&AbsorbJob::absorb, absorb_param_table())
        .nest(&AbsorbJob::output, output_param_table(absorb_map_outputs()));
    return d;
  }();
  return t;
}

nlohmann::json run_absorb_job(const AbsorbJob& job, const ExecOptions& eo, const RunContext& ctx) {
  const EffectJob<AbsorbJob> e{
      "absorb",
      absorb_job_table(),
      absorb_map_outputs(),
      40,  // bytes a pixel beyond the decoded image: the range, its preparation, the result and the map
      [](const AbsorbJob&, const ExecOptions&) {},
      [&](const AbsorbJob& j, LoadedInputs& in, const Exec& exec) {
        // A sparse range (a LiDAR scan) is completed, guided by the image,
        // and its unknown pixels (the sky) are prepared, as for every effect.
        const RangeStep step = with_camera(j.prepare, in.depth);
        const CompletedRange done = complete_step(in.depth.range, in.rgb, step, ctx.given, exec.threads);
        PreparedRange prep = prepare_step(done.view(in.depth.range), step, ctx.given, exec.threads);
        prep.record["complete"] = done.record;
        AbsorbRun run = run_absorb(in.rgb, prep.range, j.absorb);
        nlohmann::json rec = {{"absorb", run.record}, {"prepare", prep.record}};
        return EffectOutput{std::move(run.rgb), {{"transmission", std::move(run.transmission)}}, std::move(rec)};
      }};
  return run_effect_job(e, job, eo, ctx);
}

CommandDef absorb_command() {
  CommandDef c = make_command<AbsorbJob>({
      .name = "absorb",
      .cli = "absorb",
      .summary = "the example effect: a purely absorbing medium, C exp(-kappa_a R) (examples/effect/)",
      .table = &absorb_job_table(),
      .writes_record = true,
      .batchable = true,
      .run = &run_absorb_job,
      .report = [](const AbsorbJob& j, const nlohmann::json& rec) {
        std::fprintf(stderr, "brume absorb: %s  kappa_a %g 1/m  %zu pixels of unknown range kept\n",
                     j.output.out.c_str(), j.absorb.absorption_per_m,
                     rec["absorb"]["unknown_range_pixels"].get<std::size_t>());
      },
  });
  return c;
}

}  // namespace brume
