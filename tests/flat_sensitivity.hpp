// A flat camera sensitivity (q = 1 in every channel at every wavelength): the
// spectral integrals' test case with an independent closed form.
#pragma once

#include "brume/aerial.hpp"

namespace brume::test {

inline SpectralSensitivity flat_sensitivity() {
  SpectralSensitivity s;
  s.source = "flat";
  s.space = SensitivitySpace::camera_rgb;
  s.q.assign(kSensitivitySamples, {1.0, 1.0, 1.0});
  return s;
}

}  // namespace brume::test
