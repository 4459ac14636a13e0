// brume — fast CPU schedule of the diffusion schemes: which row kernel runs
// on which rows, in which iteration, on which thread, and the buffers they
// use. The kernels (one row of eq. 11, written once with Highway for every
// SIMD target, beside the reference rows) are diffusion_fast_kernels.cpp; the temporal blocking diffusion_fusion.hpp.
//
// Same algorithm as diffusion_reference.cpp, scheduled for speed. Input is
// the per-pixel rate map (the sigma front end computes it, brume_standard_rate
// or brume_invariant_rate: rates_from_scale) on four interleaved channels, or
// three (RGB rows of the invariant schemes, f32); the front end feeds other
// channel counts as groups of four. The standard scheme forms its edge
// weights once and runs the conductance stencil, which is also the public
// per-edge (depth-of-field) path; its iterations share passes too
// (diffuse_conductance_fast).
//  - rows in parallel (OpenMP, static schedule); every output pixel depends
//    only on the previous iteration, so results do not depend on the thread
//    count;
//  - a constant rate (a constant target scale: the accuracy experiment,
//    `brume blur --sigma`) needs no per-pixel map: every iteration has one
//    offset and one weight (uniform_steps), a row is the vectorised interior
//    plus the mirrored border columns (diffuse_fast_uniform), with the same
//    bits as the map of that rate. Its iterations with small offsets share
//    passes over the image (temporal blocking, diffusion_fusion.hpp): 17
//    iterations at sigma 25 take 6 passes, with the same bits; in f16 with
//    F16C the iterations run on binary16 storage (diffusion_fast_f16.cpp);
//  - a space-variant scale takes, per pixel, the growth e^rho of the running
//    product sigma_k and the exact scheme's variance ratio, formed once
//    (set-up, diffusion_setup_rows.hpp, compiled with the rows for every
//    SIMD target); its iterations are
//    blocked too, each with a radius bounded over the whole map;
//  - every buffer (rate map, growth, edge weights, rings, partner image)
//    comes from a Workspace reused across iterations and calls, the process
//    keeping at most one between calls (WorkspaceLease).
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <vector>

#include "core/huge_pages.hpp"
#include "core/schedule.hpp"
#include "diffusion/diffusion_fusion.hpp"
#include "diffusion/diffusion_rows.hpp"

namespace brume::cpu {

namespace {

int thread_count(int requested) { return requested > 0 ? requested : omp_get_max_threads(); }

// Defaults of the fusion limits (what they bound: diffusion_fusion.hpp),
// measured in docs/performance.md.
constexpr FusionLimits kFusionDefaults{32, 1536 * 1024, 4};
std::mutex g_fusion_mutex;
FusionLimits g_fusion = kFusionDefaults;
}  // namespace

FusionLimits diffusion_fusion_limits() {
  std::lock_guard<std::mutex> lock(g_fusion_mutex);
  return g_fusion;
}
void set_diffusion_fusion(const FusionLimits* limits) {
  std::lock_guard<std::mutex> lock(g_fusion_mutex);
  g_fusion = limits ? *limits : kFusionDefaults;
}

// A buffer of at least `bytes`, uninitialised, with the huge-page hint
// (Workspace's comment): 2 MB aligned when it is 2 MB or more, and rounded
// up to whole 2 MB pages when that adds at most 1/16 (the 1600 x 1120
// partner: 27.3 -> 28 MiB; a quarter-size map, 6.8 MiB, is not rounded to
// 8, and its last partial page takes 4 kB faults), so that the extra heap
// stays within issue #16's 2x the image. Returns the bytes allocated; the
// deleter knows the alignment.
template <class T, class Deleter>
std::size_t workspace_alloc(std::unique_ptr<T[], Deleter>& p, std::size_t bytes, std::size_t small_align) {
  p.reset();  // before the new allocation: never hold both
  const bool huge = bytes >= detail::kHugePageBytes;
  const std::size_t align = huge ? detail::kHugePageBytes : small_align;
  const std::size_t whole = (bytes + detail::kHugePageBytes - 1) & ~(detail::kHugePageBytes - 1);
  if (huge && whole - bytes <= bytes / 16) bytes = whole;
  p = std::unique_ptr<T[], Deleter>(static_cast<T*>(::operator new[](bytes, std::align_val_t{align})), Deleter{align});
  detail::advise_huge_pages(p.get(), bytes);  // before the first touch
  return bytes;
}
float* Workspace::get(Slot s, std::size_t n) {
  if (n_[s] < n) {
    b_[s] = workspace_alloc(p_[s], n * sizeof(float), kAlign);
    n_[s] = n;
  }
  return p_[s].get();
}
std::uint16_t* Workspace::get_half(int which, std::size_t n) {
  if (hn_[which] < n) {
    hb_[which] = workspace_alloc(h_[which], n * sizeof(std::uint16_t), kAlign);
    hn_[which] = n;
  }
  return h_[which].get();
}
std::size_t Workspace::bytes() const {
  std::size_t b = 0;
  for (std::size_t n : b_) b += n;
  for (std::size_t n : hb_) b += n;
  return b;
}

namespace {
std::mutex g_pool_mutex;
std::unique_ptr<Workspace> g_pool;  // the one workspace kept between calls
}  // namespace

WorkspaceLease::WorkspaceLease() {
  {
    std::lock_guard<std::mutex> lock(g_pool_mutex);
    ws_ = std::move(g_pool);
  }
  if (!ws_) ws_ = std::make_unique<Workspace>();
}
WorkspaceLease::~WorkspaceLease() {
  std::lock_guard<std::mutex> lock(g_pool_mutex);
  // Keep the larger of the two (the other is freed here).
  if (!g_pool || g_pool->bytes() < ws_->bytes()) g_pool = std::move(ws_);
}

std::size_t kept_workspace_bytes() {
  std::lock_guard<std::mutex> lock(g_pool_mutex);
  return g_pool ? g_pool->bytes() : 0;
}

void release_workspace() {
  std::unique_ptr<Workspace> drop;
  std::lock_guard<std::mutex> lock(g_pool_mutex);
  drop = std::move(g_pool);
}

const float* rates_from_scale(const Image& sigma, const DiffusionParams& p, int iterations, int threads,
                              Workspace& ws) {
  const float s0 = static_cast<float>(p.sigma0), Nf = static_cast<float>(iterations);
  const bool standard = p.scheme == Scheme::standard;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(sigma.data.size());
  float* rho = ws.get(Workspace::rates, sigma.data.size());
  if (standard) {
#pragma omp parallel for num_threads(thread_count(threads)) schedule(dynamic, kPixelChunk)
    for (std::ptrdiff_t i = 0; i < n; ++i) rho[i] = sh::brume_standard_rate(sigma.data[i], s0, Nf);
    return rho;
  }
  const RatesFn rates = row_kernels().rates;
  const int W = sigma.width, H = sigma.height;
  const std::size_t Ws = static_cast<std::size_t>(W);
#pragma omp parallel for num_threads(thread_count(threads)) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y) rates(sigma.data.data() + y * Ws, rho + y * Ws, Ws, s0, Nf);
  return rho;
}

namespace {
// The result is in the partner after an odd number of passes: copied back
// by the threads, a band of rows each (one thread's memcpy of 28.7 MB took
// ~3 ms).
void copy_back(Image& f, const float* src, int nt) {
  if (src == f.data.data()) return;
  const int H = f.height;
  const std::size_t Ws4 = static_cast<std::size_t>(f.width) * static_cast<std::size_t>(f.channels);
  float* out = f.data.data();
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y) std::memcpy(out + y * Ws4, src + y * Ws4, Ws4 * sizeof(float));
}
// The partner image of the fused schedule, where some group of it runs
// ping-pong (plan_scratch), else null: most schedules run in place
// (diffusion_fusion.hpp) and need no second image-sized buffer, nor its
// first-touch page faults. Not zero-filled (every value is written before
// it is read; a new one is first touched by the threads that use it).
float* partner_if_needed(Workspace& ws, const Radii& radii, const std::vector<FusedGroup>& groups, const Image& f,
                         int nt) {
  return fusion_needs_partner(radii, groups, f.height, nt) ? ws.get(Workspace::partner, f.data.size()) : nullptr;
}
// What both entry points derive from the parameters once per call.
struct FastCall {
  float s0;
  bool f16, exact;
  int nt, edge_mode;
  RowKernels kern;
  FastCall(const DiffusionParams& p, int threads)
      : s0(static_cast<float>(p.sigma0)),
        f16(p.precision == Precision::f16),
        exact(p.scheme == Scheme::invariant_exact),
        nt(thread_count(threads)),
        edge_mode(static_cast<int>(p.edge_rate)),
        kern(row_kernels()) {}
};
}  // namespace

void diffuse_conductance_fast(Image& f, const float* wx, const float* wy, int iterations, bool f16, int threads,
                              Workspace& ws) {
  const int W = f.width, H = f.height;
  const std::size_t Ws = static_cast<std::size_t>(W);
  const int nt = thread_count(threads);
  float* src = f.data.data();
  if (f16) round_to_half(src, f.data.size());
  const std::vector<float> zero(Ws, 0.0f);
  const RowKernels kern = row_kernels();
  // Every iteration reads rows y - 1 .. y + 1 (radius 1, clamped at the
  // top and bottom, where the edge weights are 0), so many iterations share
  // a pass: the fused schedule of the invariant schemes (diffusion_fusion.hpp,
  // in place), with this stencil as its row. At 1600 x 1120, 2 threads, 21
  // iterations a pass (the rings' limit), so a standard-scheme blur of
  // hundreds of iterations reads and writes the image a few dozen times
  // instead of hundreds. Same rows from the same inputs, hence the same bits.
  const Radii radii(static_cast<std::size_t>(std::max(0, iterations)), 1);
  const std::vector<FusedGroup> groups = plan_fusion(radii, W, H, nt, sizeof(float));
  float* scratch =
      ws.get(Workspace::ring, std::max<std::size_t>(1, fusion_scratch_values(radii, groups, W, H, nt)));
  src = iterations_fused(src, partner_if_needed(ws, radii, groups, f, nt), W, H, radii, groups, nt, scratch,
                         [&](int, int y, const RowSource<float>& in, float* o) {
                           const float* wdu = y > 0 ? wy + (y - 1) * Ws : zero.data();
                           kern.standard(in(y), in(y > 0 ? y - 1 : 0), in(y < H - 1 ? y + 1 : y), wx + y * Ws, wdu,
                                         wy + y * Ws, o, W);
                           if (f16) round_to_half(o, Ws * 4);
                         });
  copy_back(f, src, nt);
}

void diffuse_fast_uniform(Image& f, float rho, int iterations, const DiffusionParams& p, int threads, Workspace& ws) {
  const int W = f.width, H = f.height, N = iterations;
  const int C = f.channels;  // 4, or 3: RGB rows without an alpha to carry
  const std::size_t Ws = static_cast<std::size_t>(W);
  const FastCall c(p, threads);
  const float s0 = c.s0;
  const bool f16 = c.f16, exact = c.exact;
  const int nt = c.nt, edge_mode = c.edge_mode;
  const RowKernels kern = c.kern;
  float* src = f.data.data();
  if (f16) round_to_half(src, f.data.size());
  // (Level 0 keeps binary16 values in float storage, rounded by
  // round_to_half: the tests' peer of the F16C storage.)
  // Every iteration's offset and weight, and which iterations share a pass
  // (diffusion_fusion.hpp).
  const std::vector<UniformStep> steps = uniform_steps(N, s0, rho, exact, edge_mode);
  const Radii radii = uniform_radii(steps);
  std::vector<FusedGroup> groups;
  if (f16 && C == 4 && diffusion_simd_level() >= 1) {
    groups = plan_fusion(radii, W, H, nt, sizeof(std::uint16_t));
    const std::size_t scratch_values = std::max<std::size_t>(1, fusion_scratch_values(radii, groups, W, H, nt));
    std::uint16_t* partner =
        fusion_needs_partner(radii, groups, H, nt) ? ws.get_half(1, f.data.size()) : nullptr;
    if (uniform_iterations_f16(src, W, H, steps, groups, nt, ws.get_half(0, f.data.size()), partner,
                               ws.get_half(2, scratch_values)))
      return;  // done in binary16 storage (result in f)
  }
  groups = plan_fusion(radii, W, H, nt, sizeof(float), C);
  // Every offset and weight is the same for the whole image: one row
  // function (vectorised interior, mirrored border columns), run over the
  // iterations either one pass per iteration or, where the offsets are
  // small, several iterations per pass (temporal blocking:
  // diffusion_fusion.hpp), in f's own buffer. Same rows from the same inputs
  // either way.
  float* scratch =
      ws.get(Workspace::ring, std::max<std::size_t>(1, fusion_scratch_values(radii, groups, W, H, nt, C)));
  const std::ptrdiff_t px = C;
  auto row = [&](const float* s, const float* u0, const float* u1, const float* d0, const float* d1, float* o,
                 const UniformStep& st) {
    const int n = st.n;
    // Columns whose taps x-n-1 .. x+n+1 all lie inside the row.
    const int xa = std::min(n + 1, W), xb = std::max(W - n - 1, xa);
    kern.uniform(s, u0, u1, d0, d1, o, static_cast<std::size_t>(xa) * C, static_cast<std::size_t>(xb) * C, n * px, px,
                 st.fr, st.w);
    if (C == 4) {
      for (int x = 0; x < xa; ++x) uniform_border_pixel(s, u0, u1, d0, d1, o, W, x, n, st.fr, st.w);
      for (int x = xb; x < W; ++x) uniform_border_pixel(s, u0, u1, d0, d1, o, W, x, n, st.fr, st.w);
    } else {
      for (int x = 0; x < xa; ++x) uniform_border_values(s, u0, u1, d0, d1, o, W, x, n, st.fr, st.w, C);
      for (int x = xb; x < W; ++x) uniform_border_values(s, u0, u1, d0, d1, o, W, x, n, st.fr, st.w, C);
    }
    if (f16) round_to_half(o, Ws * C);
  };
  copy_back(f, uniform_iterations_fused(src, partner_if_needed(ws, radii, groups, f, nt), W, H, steps, groups, nt,
                                       scratch, row, C),
            nt);
}

void diffuse_fast(Image& f, const float* rates, int iterations, const DiffusionParams& p, int threads,
                  Workspace& ws) {
  const int W = f.width, H = f.height, N = iterations;
  const int C = f.channels;  // 4, or 3: RGB rows of the invariant schemes
  if (C != 4 && (C != 3 || p.scheme == Scheme::standard))
    throw std::logic_error("diffuse_fast: RGBA, or RGB rows of an invariant scheme");
  const std::size_t np = f.pixels();
  const std::size_t Ws = static_cast<std::size_t>(W);
  const FastCall c(p, threads);
  const float s0 = c.s0;
  const bool f16 = c.f16, exact = c.exact;
  const int nt = c.nt, edge_mode = c.edge_mode;
  const RowKernels kern = c.kern;

  if (p.scheme == Scheme::standard) {
    // Edge weights of eq. 12, fixed for all iterations: the conductance path.
    float* wr = ws.get(Workspace::edge_x, np);
    float* wd = ws.get(Workspace::edge_y, np);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = y * Ws + x;
        const float rc = rates[i];
        wr[i] = x < W - 1 ? sh::brume_edge_rate(rc, rates[i + 1], edge_mode) : 0.0f;
        wd[i] = y < H - 1 ? sh::brume_edge_rate(rc, rates[i + Ws], edge_mode) : 0.0f;
      }
    diffuse_conductance_fast(f, wr, wd, N, f16, threads, ws);
    return;
  }

  // A constant rate needs no per-pixel rate, offset or scale arrays.
  if (std::all_of(rates, rates + np, [&](float v) { return v == rates[0]; })) {
    diffuse_fast_uniform(f, rates[0], N, p, threads, ws);
    return;
  }

  float* src = f.data.data();
  if (f16) round_to_half(src, f.data.size());
  // Per-pixel rate, growth e^rho of the running product sigma_k (formed
  // per row: row_offsets), and the exact scheme's variance ratio
  // (e^{2 rho} - 1)/(2 rho).
  const float* rho = rates;
  float* growth = ws.get(Workspace::growth, np);
  float* vratio = ws.get(Workspace::vratio, np);
  const GrowthFn growth_rows = row_kernels().growth;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y) growth_rows(rho + y * Ws, growth + y * Ws, vratio + y * Ws, Ws);
  std::vector<RowScratch> scratch(static_cast<std::size_t>(nt), RowScratch(W));
  // Temporal blocking as on the constant path (diffusion_fusion.hpp), with
  // each iteration's radius bounded over the whole map.
  const Radii radii = general_radii(rates, np, N, s0, exact);
  const std::vector<FusedGroup> groups = plan_fusion(radii, W, H, nt, sizeof(float), C);
  float* fusion =
      ws.get(Workspace::ring, std::max<std::size_t>(1, fusion_scratch_values(radii, groups, W, H, nt, C)));
  const GeneralRow general = C == 3 ? kern.general_rgb : kern.general;
  src = iterations_fused(
      src, partner_if_needed(ws, radii, groups, f, nt), W, H, radii, groups, nt, fusion,
      [&](int k, int y, const RowSource<float>& in, float* out) {
        RowScratch& t = scratch[static_cast<std::size_t>(omp_get_thread_num())];
        const std::size_t r0 = static_cast<std::size_t>(y) * Ws;
        general(in, out, rho, s0, k, growth + r0, vratio + r0, exact, edge_mode, W, H, y, t);
        if (f16) round_to_half(out, Ws * C);
      },
      C);
  copy_back(f, src, nt);
}

float rate_from_scale(float sigma, const DiffusionParams& p, int iterations) {
  const float s0 = static_cast<float>(p.sigma0), Nf = static_cast<float>(iterations);
  if (p.scheme == Scheme::standard) return sh::brume_standard_rate(sigma, s0, Nf);
  // rates_from_scale's kernel on one value (padded lanes), so the same bits.
  float rho = 0.0f;
  row_kernels().rates(&sigma, &rho, 1, s0, Nf);
  return rho;
}

}  // namespace brume::cpu
