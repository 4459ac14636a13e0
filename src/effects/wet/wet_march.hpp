// brume — the camera's mirror march (render_wet, wet.cpp) over a batch of rays, several rays
// side by side in the lanes of a SIMD vector (wet_march.cpp; internal).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace brume::detail {

// The min-depth pyramids' block sizes [px] (the march asks the coarse one first).
constexpr int kWetCoarseBlock = 32, kWetFineBlock = 8;

// The maps the march reads (built by render_wet): the planar depth and the minima of the 32- and
// 8-px blocks' rectangles, each followed (above_ground) by its copy without the plane's pixels at
// the offsets *_off (0: no such copy).
struct WetMarchMaps {
  int width = 0, height = 0;
  const float* maps = nullptr;      // one array: the march's lanes read any of the maps in one gather
  std::size_t z_at = 0, z_off = 0;  // planar depth, width x height (inf: the sky)
  std::size_t rect_at[2] = {0, 0}, rect_off[2] = {0, 0};  // coarse, fine: 9 rectangle minima a block
  int bw[2] = {0, 0}, bh[2] = {0, 0};
  const float* blocks[2] = {nullptr, nullptr};  // the blocks' own minima (bw x bh), for a rectangle the table lacks
  std::size_t blocks_off[2] = {0, 0};
  float front_k = 1.0f, thick_k = 1.0f;  // 1 + margin; 1 + margin + thickness (float, as the tests)
  int max_steps = 0;
};

// The rays of a batch, one per ground pixel, as render_wet sets them up: w = 1/Z along the
// reflected ray, u = uinf + w·cu, v = vinf + w·cv, dw the step; the lift at w_lift.
struct WetMarchRays {
  enum : std::uint8_t { dz_positive = 1, can_lift = 2, lifted = 4 };
  enum End : std::uint8_t { leaves = 0, hit = 1, infinity = 2 };
  std::vector<double> w0, dw, uinf, vinf, cu, cv, major, w_lift;
  std::vector<std::uint8_t> flags;
  // the march's result: how it ended; at a hit, the crossing's point (hu, hv)
  std::vector<std::uint8_t> end;
  std::vector<double> hu, hv;
  std::size_t size() const { return w0.size(); }
  void clear();
  void push(double w0_, double dw_, double uinf_, double vinf_, double cu_, double cv_, double major_, double w_lift_,
            std::uint8_t flags_);
};

// Marches every ray of `r` and fills its end, hu and hv, several rays side by side: the same
// steps, tests and bisection as render_wet's march a ray at a time, lane by lane (the same bits).
// False, and nothing done, where the CPU's vectors hold fewer than 8 doubles: there the lanes
// were measured slower than a ray at a time (docs/wet-ground.md).
bool wet_march_rays(const WetMarchMaps& m, WetMarchRays& r);

}  // namespace brume::detail
