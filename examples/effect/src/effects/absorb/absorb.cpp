// brume — the example effect's CPU path (brume/absorb.hpp): the per-pixel
// maths of absorb_math.glsl over the image.
#include "brume/absorb.hpp"

#include <cmath>
#include <string>

#include "brume/error.hpp"
#include "shared/prelude_cpp.h"

namespace brume {

const ParamTable<AbsorbParams>& absorb_param_table() {
  static const ParamTable<AbsorbParams> t = [] {
    ParamTable<AbsorbParams> d("absorb");
    // Up to 10 per metre: beyond it a tenth of a metre already absorbs 63 %
    // (a wall, not a medium).
    d.real("absorption", &AbsorbParams::absorption_per_m, "1/m", Range::closed(0.0, 10.0),
           "absorption coefficient kappa_a: the light lost per metre of range (Beer-Lambert, no airlight)");
    return d;
  }();
  return t;
}

AbsorbRun run_absorb(ConstImageView rgb, ConstImageView range, const AbsorbParams& p) {
  absorb_param_table().validate(p);
  if (rgb.channels() != 3)
    throw Error("absorb: the image has " + std::to_string(rgb.channels()) + " channels; give linear RGB (3 channels)");
  if (range.width() != rgb.width() || range.height() != rgb.height() || range.channels() != 1)
    throw Error("absorb: the range is " + range.size_string() + "x" + std::to_string(range.channels()) +
                " but the image is " + rgb.size_string() + "; give one channel of the image's size");
  AbsorbRun r;
  r.rgb = Image(rgb.width(), rgb.height(), 3);
  r.transmission = Image(rgb.width(), rgb.height(), 1);
  const float k = static_cast<float>(p.absorption_per_m);
  for (int y = 0; y < rgb.height(); ++y) {
    const float* c = rgb.row(y);
    const float* d = range.row(y);
    float* o = r.rgb.row(y);
    float* t = r.transmission.row(y);
    for (int x = 0; x < rgb.width(); ++x) {
      const float R = d[x * range.pixel_stride()];
      const bool known = std::isfinite(R) && R > 0.0f;
      r.unknown_pixels += known ? 0 : 1;
      const float T = known ? shared::brume_absorb_transmittance(k, R) : 1.0f;
      t[x] = T;
      for (int ch = 0; ch < 3; ++ch) o[x * 3 + ch] = T * c[x * rgb.pixel_stride() + ch];
    }
  }
  r.record = {{"parameters", absorb_param_table().to_json(p)},
              {"model", "Beer-Lambert absorption, no in-scattering: C exp(-kappa_a R)"},
              {"unknown_range_pixels", r.unknown_pixels},
              {"unknown_range_rule", "kept unchanged (T = 1)"}};
  return r;
}

}  // namespace brume
