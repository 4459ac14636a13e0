// brume — the camera's mirror march (render_wet, wet.cpp) over a batch of rays, several rays
// side by side in the lanes of a SIMD vector, and render_wet's work on every pixel around it (the
// planar depth and the ground test of a row, the rays' set-up and Fresnel factor): wet_march.cpp,
// internal.
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
  void resize(std::size_t n);  // w0 .. flags
  void push(double w0_, double dw_, double uinf_, double vinf_, double cu_, double cv_, double major_, double w_lift_,
            std::uint8_t flags_);
};

// Marches every ray of `r` and fills its end, hu and hv, several rays side by side: the same
// steps, tests and bisection as render_wet's march a ray at a time, lane by lane (the same bits).
// False, and nothing done, where the CPU's vectors hold fewer than 8 doubles: there the lanes
// were measured slower than a ray at a time (docs/wet-ground.md).
bool wet_march_rays(const WetMarchMaps& m, WetMarchRays& r);

// The camera and the plane as render_wet's pixels see them: intrinsics [px], the plane's normal
// (world +y) in the camera's cv frame, the camera's height above it [m] (NaN: unknown) and the
// ground tolerance [m]; the film's wetted fraction f and water index n (WetOptics).
struct WetPixelFrame {
  double fx = 1.0, fy = 1.0, cx = 0.0, cy = 0.0;
  double nx = 0.0, ny = 0.0, nz = 0.0;
  double h = 0.0, tol = 0.0;
  double f = 0.0, n = 1.0;
  double step_px = 1.0;  // kWetMarchStepPx
  bool lift = false;  // above_ground: the rays' lift and the depth without the plane's pixels
};
// A pixel's flags (wet_depth_row): its ray goes down (known depth, d·n < 0); it lies on the plane.
enum : std::uint8_t { kWetDown = 1, kWetOnPlane = 2 };

// One row y of `width` pixels: the planar depth z[x] = range/|ray| (float; inf: unknown), with
// lift zo[x] (z but inf on the plane's pixels; else zo may be null), and flags[x]. rx[x] =
// (x − cx)/fx, ry = (y − cy)/fy. The same IEEE operations as the scalar expressions in render_wet
// (docs/wet-ground.md): the same bits on every target.
void wet_depth_row(const WetPixelFrame& f, const double* rx, double ry, const float* range, int width, float* z,
                   float* zo, std::uint8_t* flags);

// The rays of n ground pixels (x, y; planar depth z0) set up as render_wet marches them: r's
// w0 .. flags (r is resized to n), and mirror[i] = f·R_F(−d·n) as float (WetOptics::mirror).
void wet_setup_rays(const WetPixelFrame& f, const std::int32_t* x, const std::int32_t* y, const float* z0,
                    std::size_t n, WetMarchRays& r, float* mirror);

}  // namespace brume::detail
