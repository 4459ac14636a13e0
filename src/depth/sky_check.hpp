// brume — the preparation's sky, checked against the scene (internal to the depth family).
//
// Hansard 4.1's rule (brume/prepare.hpp) takes an unknown region of a dense
// range map as sky by its shape alone: it touches the image's top row, or it
// is large. A ground-truth disparity with holes (ETH3D's terrace: shadows
// under the tables, glass, thin chair legs, all one region reaching the top)
// has its holes taken as sky, and an effect whose sky lies beyond the medium
// paints them with the airlight. The range itself tells: the sky lies above
// the scene, so a pixel taken as sky with a measured surface above it in its
// column is seen under something (a table, a canopy, a bridge) -- rare for
// sky, common for holes.
#pragma once

#include <cstddef>

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
  std::size_t under = 0;   // of those, below a known pixel of their column
};

// The pixels prepare_range would take as sky, and among them those with a
// known (measured) pixel above them in their column.
PreparedSkyCheck check_prepared_sky(ConstImageView range, const PrepareParams& p);

}  // namespace brume
