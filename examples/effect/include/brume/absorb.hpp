// brume — `brume absorb`, the example effect (examples/effect/README.md): the
// smallest command that has what every effect has (a parameter table, a CPU
// path over a GLSL topic, a job from files to files, a record that `brume run`
// repeats, a batch row, tests of its own). Not part of brume's library: the
// ctest example_effect_builds_from_its_files copies it into a scratch copy of
// the tree to prove docs/architecture.md's "Adding an effect".
//
// The model: a purely absorbing medium (Beer-Lambert, Hansard eq. 1 with
// kappa_s = 0): C'(x) = C(x) exp(-kappa_a R(x)), R the range along the pixel's
// ray [m], kappa_a [1/m]. No in-scattering, so no airlight and no blur.
#pragma once

#include <cstddef>

#include <nlohmann/json.hpp>

#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

struct AbsorbParams {
  double absorption_per_m = 0.01;  // kappa_a [1/m]: 1 % of the light lost per metre
};
const ParamTable<AbsorbParams>& absorb_param_table();

struct AbsorbRun {
  Image rgb;            // linear RGB, C exp(-kappa_a R)
  Image transmission;   // T = exp(-kappa_a R), 1 channel; 1 where the range is unknown
  std::size_t unknown_pixels = 0;
  nlohmann::json record;  // the "absorb" block of the run's record
};
// `rgb`: linear RGB (3 channels); `range`: metres along each pixel's ray, the
// same size. A pixel of unknown range (NaN, +-inf, <= 0) keeps its colour
// (T = 1) and is counted in the record: the job's range step (--prepare)
// fills such pixels first unless it is off.
AbsorbRun run_absorb(ConstImageView rgb, ConstImageView range, const AbsorbParams& p);

}  // namespace brume
