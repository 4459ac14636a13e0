// brume — the preparation's sky, checked against the image (internal to the depth family).
//
// Hansard 4.1's rule (brume/prepare.hpp) takes an unknown region of a dense
// range map as sky by its shape alone: it touches the image's top row, or it
// is large. A ground-truth disparity with holes (ETH3D's terrace: shadows
// under the tables, glass, thin chair legs, all one region reaching the top)
// has its holes taken as sky, and an effect whose sky lies beyond the medium
// paints them with the airlight. The image tells: sky is smooth.
#pragma once

#include <cstddef>

#include "brume/complete.hpp"
#include "brume/image.hpp"
#include "brume/prepare.hpp"

namespace brume {

// The rule prepare_range applies to an unknown region (8-connected) of
// `area` pixels of a frame of `pixels`.
inline bool prepare_takes_as_sky(bool touches_top, double area, double pixels, const PrepareParams& p) {
  return (touches_top && area >= p.sky_min_fraction * pixels) || area >= p.sky_large_fraction * pixels;
}

struct PreparedSkyCheck {
  std::size_t pixels = 0;  // the frame's
  std::size_t sky = 0;     // taken as sky by the rule
  std::size_t unlike = 0;  // of those, not smooth in the image
};

// The pixels prepare_range would take as sky, and among them those the image
// does not show as smooth by the completion's roughness test (brume/complete.hpp's
// sky rule: a 5x5 standard deviation of sRGB luma at most c.sky_roughness).
// rgb: linear RGB of the range's size.
PreparedSkyCheck check_prepared_sky(ConstImageView range, ConstImageView rgb, const PrepareParams& p,
                                    const CompleteParams& c);

}  // namespace brume
