// brume — CPU schedules of the diffusion schemes (internal).
//
// The algorithm is stated in include/brume/diffusion.hpp and the per-pixel
// formulas in src/effects/haze/haze_math.glsl and diffusion_stencil.hpp; this
// header declares the two CPU schedules of it: a plain double-precision
// reference and the fast float path.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <vector>

#include "brume/diffusion.hpp"

namespace brume::cpu {

// Half-sample mirror of an index into [0, n): ... 2 1 0 | 0 1 2 ... n-1 | n-1 ...
inline int mirror(int i, int n) {
  if (i >= 0 && i < n) return i;
  const int period = 2 * n;
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - 1 - i;
}

// The largest of n floats that are not NaN, or 0 when none is above 0, with
// sixteen running maxima so that the loop vectorises (one loop-carried max
// per value took 1.2 ms for a 1600 x 1120 map); for such values the order
// of the comparisons cannot change the result.
inline float largest_nonnegative(const float* v, std::size_t n) {
  float m16[16] = {};
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16)
    for (int j = 0; j < 16; ++j) m16[j] = m16[j] < v[i + j] ? v[i + j] : m16[j];
  float m = 0.0f;
  for (float x : m16) m = m < x ? x : m;
  for (; i < n; ++i) m = m < v[i] ? v[i] : m;
  return m;
}

// Buffers of the fast path (the rate map, the per-pixel constants of the
// invariant schemes, edge weights, the fused schedule's rings, copies and
// delay rows; the ping-pong partner of F for the standard scheme and for
// invariant schedules that cannot run in place, diffusion_fusion.hpp),
// uninitialised and reused across iterations and calls. A fresh 28 MB
// buffer per call costs ~7000 first-touch page faults, which on the hosts
// measured (VMs) cost as much as several iterations; a reused one costs none.
// Every value is written before it is read, so reuse cannot change a result.
// Frees a Workspace buffer allocated at `align` bytes.
struct WorkspaceFree {
  std::size_t align = 64;
  void operator()(void* p) const { ::operator delete[](p, std::align_val_t{align}); }
};
class Workspace {
 public:
  enum Slot { partner, rates, growth, vratio, edge_x, edge_y, ring, kSlots };  // ring: the fusion scratch
  // At least n floats, uninitialised; valid until the next get of that slot.
  float* get(Slot s, std::size_t n);
  // The binary16 buffers of the f16 constant-scale path: 0 F, 1 its
  // partner (where the schedule needs one), 2 the fused schedule's scratch.
  std::uint16_t* get_half(int which, std::size_t n);
  std::size_t bytes() const;

 private:
  // Cache-line aligned: a 64-byte vector load of an aligned row offset then
  // touches one line, not two (malloc's large blocks start 16 bytes past a
  // page, which split every 512-bit load of a row across two lines). A
  // buffer of 2 MB or more starts on a 2 MB boundary (and mostly spans
  // whole 2 MB pages: workspace_alloc), so that it can be transparent huge
  // pages from its first byte: a malloc'd block's first and last partial
  // 2 MB took 4 kB faults, ~500 a buffer. With `brume blur`'s output no
  // longer copied (blur_pipeline.cpp), a whole 1600 x 1120 run's page
  // faults went from 6330 to 3820 (space-variant) and 5370 to 3370
  // (constant).
  static constexpr std::size_t kAlign = 64;
  using AlignedFree = WorkspaceFree;
  std::unique_ptr<float[], AlignedFree> p_[kSlots];
  std::size_t n_[kSlots] = {}, b_[kSlots] = {};  // values asked for, bytes allocated
  std::unique_ptr<std::uint16_t[], AlignedFree> h_[3];
  std::size_t hn_[3] = {}, hb_[3] = {};
};

// One diffusion call's hold on a workspace: the process keeps at most one
// (the last returned), so a run of calls reuses it while concurrent calls
// each get their own and at most one set of buffers outlives its call
// (brume::release_diffusion_buffers frees it).
class WorkspaceLease {
 public:
  WorkspaceLease();
  ~WorkspaceLease();
  WorkspaceLease(const WorkspaceLease&) = delete;
  WorkspaceLease& operator=(const WorkspaceLease&) = delete;
  Workspace& operator*() { return *ws_; }

 private:
  std::unique_ptr<Workspace> ws_;
};

// Frees the workspace kept between calls (brume::release_diffusion_buffers).
void release_workspace();
// Bytes of the workspace kept between calls (0 when none is kept).
std::size_t kept_workspace_bytes();

// The CPU schedules take validated inputs (the checks are in diffusion.cpp).
//
// Rate path: F with any channel count for the reference, four channels for
// the fast path (the front end feeds it groups of four) or, for the
// invariant schemes, three (RGB rows of three values a pixel: the same bits
// as those channels of a four-channel run); one rate per pixel
// (double in the reference, the float map in the fast path) and the
// iteration count N. The standard scheme is the conductance path below with
// edge weights formed from the two ends' rates (eq. 12 or its min/harmonic
// variants); the invariant schemes take offsets from sigma_k = s0 e^{k rho}.
void diffuse_reference(Image& f, const std::vector<double>& rho, int iterations, const DiffusionParams& p);
// rho: one float per pixel of f (W x H).
void diffuse_fast(Image& f, const float* rho, int iterations, const DiffusionParams& p, int threads, Workspace& ws);
// The same for one rate everywhere (a constant target scale), invariant
// schemes (the standard one takes the per-pixel path): what diffuse_fast
// does for a map of that rate, bit for bit, without the map. f has four
// channels, or three in f32 (RGB rows of three values a pixel: the same
// bits as those channels of a four-channel run).
void diffuse_fast_uniform(Image& f, float rho, int iterations, const DiffusionParams& p, int threads, Workspace& ws);
// The float rate of one target scale, as rates_from_scale forms it.
float rate_from_scale(float sigma, const DiffusionParams& p, int iterations);

// The float rate map of a target-scale map, per pixel: brume_standard_rate
// or brume_invariant_rate with N as a float (the sigma front end of the fast
// path; threaded), in the workspace's rate slot.
const float* rates_from_scale(const Image& sigma, const DiffusionParams& p, int iterations, int threads,
                              Workspace& ws);

// Conductance path: wx[y W + x] is the weight of the edge between (x, y) and
// (x+1, y), wy[y W + x] that of the edge between (x, y) and (x, y+1); the
// last column of wx and the last row of wy must be 0 (the half-sample mirror
// boundary carries no flux). Same channel rules as the rate path.
void diffuse_conductance_reference(Image& f, const std::vector<double>& wx, const std::vector<double>& wy,
                                   int iterations, bool f16);
void diffuse_conductance_fast(Image& f, const float* wx, const float* wy, int iterations, bool f16, int threads,
                              Workspace& ws);

// Vector level of the fast path: 0 = no AVX2 (the set-up at 128 bits, the
// f16 constant-scale path in float storage, round_to_half after every
// iteration), 1 = AVX2 (Highway's AVX2 target: with FMA and F16C), 2 =
// AVX-512 (Highway's AVX3); the default is the best the CPU has, as Highway
// sees it (simd::force_target narrows that). set_diffusion_simd_limit caps
// it (-1: no cap); a cap of 0 also runs the reference rows (plain C++, no
// Highway) instead of a SIMD target's, a cap of 1 the best target below
// AVX-512 (row_kernels). Every level and target evaluates the same
// elementwise operations in the same order, so all give the same bits.
int diffusion_simd_level();
void set_diffusion_simd_limit(int level);

// Temporal blocking of the constant-scale iterations (diffusion_fusion.hpp):
// which consecutive iterations may share one pass over the image.
struct FusionLimits {
  int halo_rows;           // a group's total halo r_1 + ... + r_m at most this; 0: no fusion
  long long ring_bytes;    // its rings at most this many bytes per thread
  int band_halos;          // a thread's band at least this many halos tall
};
// The limits in force: the defaults, or those set_diffusion_fusion set
// (nullptr: the defaults again), so that tests and benchmarks can compare
// schedules on one host. Results do not depend on them.
FusionLimits diffusion_fusion_limits();
void set_diffusion_fusion(const FusionLimits* limits);

// Round n floats to the nearest IEEE binary16 value (ties to even), in place.
void round_to_half(float* v, std::size_t n);

}  // namespace brume::cpu
