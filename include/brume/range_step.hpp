// brume — the range step every effect on an RGB-D frame takes before its
// own work (brume/pipeline.hpp: the shared steps): the completion of a sparse
// range map (brume/complete.hpp) and its preparation (Hansard §4.1,
// brume/prepare.hpp), as one declared parameter block. Its own header so
// that an effect's public header, whose in-memory run takes a RangeStep or a
// PreparedRange, includes neither the depth sources nor the file steps.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <set>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/complete.hpp"
#include "brume/image.hpp"
#include "brume/params.hpp"
#include "brume/prepare.hpp"

namespace brume {

struct StereoFill;  // brume/fuse.hpp

// Range preparation before an effect (Hansard §4.1), after the completion
// of a sparse map (brume/complete.hpp).
enum class PrepareMode { automatic, off };
const EnumNames<PrepareMode>& prepare_mode_names();
// auto: complete a map whose known pixels cover less than --min-coverage
// (which the preparation would refuse), when the preparation runs; on: always
// complete; off: never (a sparse map is refused as before).
enum class CompleteMode { automatic, off, on };
const EnumNames<CompleteMode>& complete_mode_names();
struct RangeStep {
  PrepareMode mode = PrepareMode::automatic;  // auto: prepare when the range has unknown pixels
  PrepareParams params;
  CompleteMode complete = CompleteMode::automatic;
  CompleteParams completion;
  // Not a parameter: the camera of the range map where its source gives one
  // (LoadedDepth::camera), for the completion's planar continuation.
  std::optional<Intrinsics> camera;
  // Not a parameter either: a stereo view fitted to the scan
  // (LoadedDepth::fusion), which the completion fuses (brume/fuse.hpp).
  std::shared_ptr<const StereoFill> stereo;
};
const ParamTable<RangeStep>& range_step_param_table();

// Unknown pixels (NaN, +-inf, 0) of a range map.
std::size_t unknown_range_pixels(const Image& range);

struct PreparedRange {
  Image range;            // the range the effect runs on (a copy of the measured one when not prepared)
  Image sky_mask;         // when applied: 1 where the preparation identified sky (margin included), else 0
  Image sky_weight;       // when applied and asked for: PrepareResult::sky_weight (1 beyond the margin, harmonic across it)
  bool applied = false;
  nlohmann::json record;  // {"mode", "applied", and the preparation's record when applied}
};
// Validates every preparation parameter whatever the input, refuses
// parameters that `--prepare off` would ignore (`given` names the ones set
// explicitly), and prepares when the mode is auto and the range has unknown
// pixels, on `threads` OpenMP threads (Exec::threads: 0 = all); sky_weight:
// the effect blends its sky across the margin (PreparedRange::sky_weight).
void check_range_step(const RangeStep& step, const std::set<std::string>& given = {});
PreparedRange prepare_step(const Image& measured, const RangeStep& step, const std::set<std::string>& given = {},
                           int threads = 0, bool sky_weight = false);
// The same on pixels owned elsewhere (a numpy array): read in place; the
// effect's range is the preparation's result or, when not prepared, a copy.
PreparedRange prepare_step(ConstImageView measured, const RangeStep& step, const std::set<std::string>& given = {},
                           int threads = 0, bool sky_weight = false);

// The completion step, before an effect's analysis and preparation: the
// measured range completed, guided by the colour image `rgb`, when the step
// says so (RangeStep::complete; `rgb` must then be the range's size). Its
// record ({"mode", "applied", and complete_record's keys when applied})
// goes under the preparation's record as "complete". Records written before
// completion existed have no "complete" block: their jobs read as auto, which
// completes only maps that were refused then, so they replay as before.
struct CompletedRange {
  Image range;            // the completed range when applied, else empty
  Image confidence;       // its confidence when applied
  bool applied = false;
  nlohmann::json record;
  // The range the effect's analysis and preparation take: the completed one, or the measured one.
  ConstImageView view(ConstImageView measured) const { return applied ? ConstImageView(range) : measured; }
};
CompletedRange complete_step(ConstImageView measured, ConstImageView rgb, const RangeStep& step,
                             const std::set<std::string>& given = {}, int threads = 0);
// Whether complete_step completes a measured range whose known fraction is `known_fraction`.
bool completes(const RangeStep& step, double known_fraction);

}  // namespace brume
