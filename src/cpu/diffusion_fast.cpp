// brume — fast CPU schedule of the diffusion schemes.
//
// Same algorithm as diffusion_reference.cpp, scheduled for speed. Input is
// the per-pixel rate map (the sigma front end computes it, brume_standard_rate
// or brume_invariant_rate) on four interleaved channels; the front end feeds
// other channel counts as groups of four. The standard scheme forms its edge
// weights once and runs the conductance stencil, which is also the public
// per-edge (depth-of-field) path.
//  - rows in parallel (OpenMP, static schedule); every output pixel depends
//    only on the previous iteration, so results do not depend on the thread
//    count;
//  - F stays interleaved RGBA float, so a pixel is one 128-bit vector and the
//    channel loops vectorise;
//  - the invariant schemes keep sigma_k(x) as a running product
//    sigma_{k+1} = sigma_k e^{rho} (one multiply instead of an exp per pixel
//    and iteration; relative drift < 1e-6 after 13 steps, covered by the
//    fast-vs-reference test);
//  - a constant rate (a constant target scale: the accuracy experiment, `brume blur --sigma`)
//    makes every offset and weight equal, and the interior of each row is
//    then a contiguous 5-tap loop over floats that the compiler vectorises
//    (AVX2 clone selected at run time). It performs the same arithmetic in
//    the same order as the general path, so it gives the same bits;
//  - a space-variant scale splits each row into runs of pixels whose offsets
//    share their integer part; inside the image a run's rate samples, edge
//    weights and taps are contiguous, so they are computed by vector loops
//    (about 1.9x faster than per-pixel gathers on a haze map), and only the pixels
//    whose taps need the mirror take the per-pixel path.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "cpu/half.hpp"
#include "cpu/diffusion_rows.hpp"

// ThreadSanitizer instruments the ifunc resolver target_clones generates, and
// the dynamic loader runs it before TSan's runtime is up (a crash at start):
// the TSan build (scripts/test-sanitize.sh) keeps the default clone only.
#if defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define BRUME_TSAN 1
#endif
#endif
#if defined(__SANITIZE_THREAD__)
#define BRUME_TSAN 1
#endif

#if defined(__x86_64__)
#include <immintrin.h>
#endif
#if defined(__x86_64__) && !defined(BRUME_TSAN)
#define BRUME_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define BRUME_CLONES
#endif

namespace brume::cpu {

namespace {

int thread_count(int requested) { return requested > 0 ? requested : omp_get_max_threads(); }

// Interior of a row when every pixel has the same offset h = n + fr and the
// same rate w (so every eq. 12 weight is w): a contiguous loop over floats.
BRUME_CLONES
void uniform_row_interior(const float* __restrict s, const float* __restrict u0,
                          const float* __restrict u1, const float* __restrict d0,
                          const float* __restrict d1, float* __restrict o, std::size_t begin,
                          std::size_t end, std::ptrdiff_t n4, float fr, float w) {
  for (std::size_t i = begin; i < end; ++i) {
    const float fc = s[i];
    const float l = s[i - n4] + fr * (s[i - n4 - 4] - s[i - n4]);
    const float r = s[i + n4] + fr * (s[i + n4 + 4] - s[i + n4]);
    const float u = u0[i] + fr * (u1[i] - u0[i]);
    const float d = d0[i] + fr * (d1[i] - d0[i]);
    o[i] = brume_diffusion_update(fc, l, r, u, d, w, w, w, w);
  }
}

// Per-thread scratch of the general (space-variant) row: offsets, their
// integer and fractional parts, and the four eq. 12 weights of each pixel.
struct RowScratch {
  std::vector<float> h, fr, wl, wr, wu, wd;
  std::vector<int> n;
  explicit RowScratch(int W) : h(W), fr(W), wl(W), wr(W), wu(W), wd(W), n(W) {}
};

// Eq. 12 weights of the pixels [xa, xb) of a run that shares the integer
// offset n, with every tap inside the image: the rate samples are then
// contiguous loads, and the loop vectorises. Same arithmetic as update_pixel.
template <int kMode>
__attribute__((always_inline)) inline void run_weights(const float* __restrict rrow, const float* __restrict ru0,
                                                       const float* __restrict ru1, const float* __restrict rd0,
                                                       const float* __restrict rd1, const float* __restrict fr,
                                                       float* __restrict wl, float* __restrict wr,
                                                       float* __restrict wu, float* __restrict wd, int xa, int xb,
                                                       int n) {
  for (int x = xa; x < xb; ++x) {
    const float rc = rrow[x], f = fr[x];
    wl[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[x - n], rrow[x - n - 1], f, kMode), kMode);
    wr[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(rrow[x + n], rrow[x + n + 1], f, kMode), kMode);
    wu[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(ru0[x], ru1[x], f, kMode), kMode);
    wd[x] = sh::brume_edge_rate(rc, sh::brume_tap_rate(rd0[x], rd1[x], f, kMode), kMode);
  }
}

// Eq. 11 for the pixels [xa, xb) of such a run: the taps x -+ n, x -+ (n+1)
// and the rows y -+ n, y -+ (n+1) are contiguous across the run.
__attribute__((always_inline)) inline void run_update(const float* s, const float* u0, const float* u1,
                                                      const float* d0, const float* d1, float* o,
                                                      const RowScratch& t, int xa, int xb, int n) {
  const std::ptrdiff_t n4 = static_cast<std::ptrdiff_t>(n) * 4;
  const float *fr = t.fr.data(), *wl = t.wl.data(), *wr = t.wr.data(), *wu = t.wu.data(), *wd = t.wd.data();
  for (int x = xa; x < xb; ++x) {
    const std::ptrdiff_t i = static_cast<std::ptrdiff_t>(x) * 4;
    auto ld = [](const float* p) { return StoreF32::load(p); };
    StoreF32::store(o + i, eq11(ld(s + i), ld(s + i - n4), ld(s + i - n4 - 4), ld(s + i + n4), ld(s + i + n4 + 4),
                                ld(u0 + i), ld(u1 + i), ld(d0 + i), ld(d1 + i), fr[x], wl[x], wr[x], wu[x], wd[x]));
  }
}

// Offsets of the exact scheme for a row, and their integer and fractional
// parts (separate restrict-qualified loops, so that both vectorise).
__attribute__((always_inline)) inline void row_offsets(float* __restrict h, const float* __restrict sg,
                                                       const float* __restrict vr, int W) {
  for (int x = 0; x < W; ++x) h[x] = sh::brume_offset_for_moment(sg[x] * sg[x] * vr[x]);
}
__attribute__((always_inline)) inline void row_split(int* __restrict n, float* __restrict fr,
                                                     const float* __restrict h, int W) {
  for (int x = 0; x < W; ++x) {
    n[x] = static_cast<int>(h[x]);
    fr[x] = h[x] - static_cast<float>(n[x]);
  }
}

// One row of the general invariant scheme: offsets from sigma_k (and, for the
// exact variant, the variance ratio), then the update. A space-variant map
// varies slowly almost everywhere, so the row splits into long runs of
// pixels whose offsets share their integer part; inside the image those are
// updated by contiguous vector loops, and only pixels whose taps need the
// mirror (near the borders) go through the general per-pixel update_pixel.
// Both evaluate the same formulas in the same order (ISO C++, no
// reassociation or contraction), so the split does not change results.
BRUME_CLONES
void general_row(const float* src, float* dst, const float* rho, const float* sg, const float* vr, bool exact,
                 int edge_mode, int W, int H, int y, RowScratch& t) {
  float* h = t.h.data();
  if (exact) {
    row_offsets(h, sg, vr, W);
  } else {
    for (int x = 0; x < W; ++x) h[x] = sg[x];
  }
  row_split(t.n.data(), t.fr.data(), h, W);
  const std::size_t Ws = static_cast<std::size_t>(W);
  for (int x = 0; x < W;) {
    const int n = t.n[x];
    int e = x + 1;
    while (e < W && t.n[e] == n) ++e;
    // Columns of the run whose horizontal taps stay inside the row, if the
    // vertical taps stay inside the image.
    int a = std::max(x, n + 1), b = std::min(e, W - n - 1);
    if (y - n - 1 < 0 || y + n + 1 >= H || a >= b) a = b = e;
    for (int i = x; i < a; ++i) update_pixel<false>(src, dst, rho, 0.0f, W, H, i, y, h[i], edge_mode);
    if (a < b) {
      const float* rrow = rho + y * Ws;
      const float *ru0 = rho + (y - n) * Ws, *ru1 = rho + (y - n - 1) * Ws;
      const float *rd0 = rho + (y + n) * Ws, *rd1 = rho + (y + n + 1) * Ws;
      float *wl = t.wl.data(), *wr = t.wr.data(), *wu = t.wu.data(), *wd = t.wd.data();
      switch (edge_mode) {
        case 1: run_weights<1>(rrow, ru0, ru1, rd0, rd1, t.fr.data(), wl, wr, wu, wd, a, b, n); break;
        case 2: run_weights<2>(rrow, ru0, ru1, rd0, rd1, t.fr.data(), wl, wr, wu, wd, a, b, n); break;
        default: run_weights<0>(rrow, ru0, ru1, rd0, rd1, t.fr.data(), wl, wr, wu, wd, a, b, n); break;
      }
      run_update(src + y * Ws * 4, src + (y - n) * Ws * 4, src + (y - n - 1) * Ws * 4, src + (y + n) * Ws * 4,
                 src + (y + n + 1) * Ws * 4, dst + y * Ws * 4, t, a, b, n);
    }
    for (int i = std::max(b, a); i < e; ++i) update_pixel<false>(src, dst, rho, 0.0f, W, H, i, y, h[i], edge_mode);
    x = e;
  }
}

// One row of the conductance stencil (the standard scheme once its edge
// rates are formed): wr[x] couples x and x+1 (0 at the last column: zero
// flux), wd couples rows.
BRUME_CLONES
void standard_row(const float* __restrict s, const float* __restrict up,
                  const float* __restrict dn, const float* __restrict wr,
                  const float* __restrict wd_up, const float* __restrict wd, float* __restrict o,
                  int W) {
  for (int x = 0; x < W; ++x) {
    const float wl = x > 0 ? wr[x - 1] : 0.0f;
    const int xl = x > 0 ? x - 1 : 0, xr = x < W - 1 ? x + 1 : x;
    const float a = wl, b = wr[x], c = wd_up[x], e = wd[x];
    for (int ch = 0; ch < 4; ++ch)
      o[x * 4 + ch] = brume_diffusion_update(s[x * 4 + ch], s[xl * 4 + ch], s[xr * 4 + ch], up[x * 4 + ch],
                                             dn[x * 4 + ch], a, b, c, e);
  }
}

}  // namespace

#if defined(__x86_64__)
__attribute__((target("f16c,avx"))) static void round_to_half_f16c(float* v, std::size_t n) {
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    __m256 x = _mm256_loadu_ps(v + i);
    __m128i h = _mm256_cvtps_ph(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    _mm256_storeu_ps(v + i, _mm256_cvtph_ps(h));
  }
  for (; i < n; ++i) v[i] = static_cast<float>(static_cast<half_t>(v[i]));
}
#endif

void round_to_half(float* v, std::size_t n) {
#if defined(__x86_64__)
  static const bool has_f16c = cpu_has_f16c() && __builtin_cpu_supports("avx");
  if (has_f16c) {
    round_to_half_f16c(v, n);
    return;
  }
#endif
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<float>(static_cast<half_t>(v[i]));
}

Image rates_from_scale(const Image& sigma, const DiffusionParams& p, int iterations, int threads) {
  const float s0 = static_cast<float>(p.sigma0), Nf = static_cast<float>(iterations);
  const bool standard = p.scheme == Scheme::standard;
  Image rho(sigma.width, sigma.height, 1);
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(sigma.data.size());
#pragma omp parallel for num_threads(thread_count(threads)) schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    const float s = sigma.data[i];
    rho.data[i] = standard ? sh::brume_standard_rate(s, s0, Nf) : sh::brume_invariant_rate(s, s0, Nf);
  }
  return rho;
}

void diffuse_conductance_fast(Image& f, const float* wx, const float* wy, int iterations, bool f16,
                              int threads) {
  const int W = f.width, H = f.height;
  const std::size_t Ws = static_cast<std::size_t>(W);
  const int nt = thread_count(threads);
  // Ping-pong partner, deliberately not zero-filled (every value is written
  // before it is read).
  std::unique_ptr<float[]> buf(new float[f.data.size()]);
  float* src = f.data.data();
  float* dst = buf.get();
  if (f16) round_to_half(src, f.data.size());
  const std::vector<float> zero(Ws, 0.0f);
  for (int k = 0; k < iterations; ++k) {
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int y = 0; y < H; ++y) {
      const float* s = src + y * Ws * 4;
      const float* up = src + (y > 0 ? y - 1 : 0) * Ws * 4;
      const float* dn = src + (y < H - 1 ? y + 1 : y) * Ws * 4;
      const float* wdu = y > 0 ? wy + (y - 1) * Ws : zero.data();
      float* o = dst + y * Ws * 4;
      standard_row(s, up, dn, wx + y * Ws, wdu, wy + y * Ws, o, W);
      if (f16) round_to_half(o, Ws * 4);
    }
    std::swap(src, dst);
  }
  if (src != f.data.data()) std::memcpy(f.data.data(), src, f.data.size() * sizeof(float));
}

void diffuse_fast(Image& f, const Image& rho_map, int iterations, const DiffusionParams& p, int threads) {
  const int W = f.width, H = f.height, N = iterations;
  const std::size_t np = f.pixels();
  const std::size_t Ws = static_cast<std::size_t>(W);
  const float s0 = static_cast<float>(p.sigma0);
  const bool f16 = p.precision == Precision::f16;
  const bool exact = p.scheme == Scheme::invariant_exact;
  const int nt = thread_count(threads);
  const int edge_mode = static_cast<int>(p.edge_rate);
  const std::vector<float>& rates = rho_map.data;

  if (p.scheme == Scheme::standard) {
    // Edge weights of eq. 12, fixed for all iterations: the conductance path.
    std::vector<float> wr(np), wd(np);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = y * Ws + x;
        const float rc = rates[i];
        wr[i] = x < W - 1 ? sh::brume_edge_rate(rc, rates[i + 1], edge_mode) : 0.0f;
        wd[i] = y < H - 1 ? sh::brume_edge_rate(rc, rates[i + Ws], edge_mode) : 0.0f;
      }
    diffuse_conductance_fast(f, wr.data(), wd.data(), N, f16, threads);
    return;
  }

  // A constant rate needs no per-pixel rate, offset or scale arrays.
  const bool uniform = std::all_of(rates.begin(), rates.end(), [&](float v) { return v == rates[0]; });

  // Ping-pong partner, deliberately not zero-filled (every value is written
  // before it is read).
  std::unique_ptr<float[]> buf(new float[f.data.size()]);
  float* src = f.data.data();
  float* dst = buf.get();
  if (f16) round_to_half(src, f.data.size());

  if (uniform && f16 && uniform_iterations_f16(src, W, H, N, s0, rates[0], exact, edge_mode, nt)) {
    // done in binary16 storage (result in f)
  } else if (uniform) {
    const float rho = rates[0];
    const float growth = std::exp(rho);
    float sig = s0;  // sigma_k, the same running product as the general path
    for (int k = 0; k < N; ++k) {
      // Named copies, not a structured binding: clang-14 cannot capture a binding in an OpenMP region.
      const UniformStep st = uniform_step(sig, rho, exact, edge_mode);
      const float h = st.h, fr = st.fr, w = st.w;
      const int n = st.n;
      // Columns whose taps x-n-1 .. x+n+1 all lie inside the row.
      const int xa = std::min(n + 1, W), xb = std::max(W - n - 1, xa);
#pragma omp parallel for num_threads(nt) schedule(static)
      for (int y = 0; y < H; ++y) {
        const float* s = src + y * Ws * 4;
        const float* u0 = src + mirror(y - n, H) * Ws * 4;
        const float* u1 = src + mirror(y - n - 1, H) * Ws * 4;
        const float* d0 = src + mirror(y + n, H) * Ws * 4;
        const float* d1 = src + mirror(y + n + 1, H) * Ws * 4;
        float* o = dst + y * Ws * 4;
        uniform_row_interior(s, u0, u1, d0, d1, o, static_cast<std::size_t>(xa) * 4,
                             static_cast<std::size_t>(xb) * 4, static_cast<std::ptrdiff_t>(n) * 4, fr, w);
        for (int x = 0; x < xa; ++x) update_pixel<true>(src, dst, nullptr, w, W, H, x, y, h);
        for (int x = xb; x < W; ++x) update_pixel<true>(src, dst, nullptr, w, W, H, x, y, h);
        if (f16) round_to_half(o, Ws * 4);
      }
      sig *= growth;
      std::swap(src, dst);
    }
  } else {
    // Per-pixel rate, sigma_k as a running product, and the exact scheme's
    // variance ratio (e^{2 rho} - 1)/(2 rho).
    const float* rho = rates.data();
    std::vector<float> sig(np, s0), growth(np), vratio(np);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int y = 0; y < H; ++y)
      for (std::size_t i = y * Ws; i < (y + 1) * Ws; ++i) {
        growth[i] = std::exp(rho[i]);
        vratio[i] = sh::brume_step_variance_ratio(rho[i]);
      }
    std::vector<RowScratch> scratch(static_cast<std::size_t>(nt), RowScratch(W));
    for (int k = 0; k < N; ++k) {
#pragma omp parallel for num_threads(nt) schedule(static)
      for (int y = 0; y < H; ++y) {
        general_row(src, dst, rho, sig.data() + y * Ws, vratio.data() + y * Ws, exact, edge_mode, W, H, y,
                    scratch[static_cast<std::size_t>(omp_get_thread_num())]);
        if (f16) round_to_half(dst + y * Ws * 4, Ws * 4);
        // sigma_k is read only by its own pixel's offset: advance it here.
        for (std::size_t i = y * Ws; i < (y + 1) * Ws; ++i) sig[i] *= growth[i];
      }
      std::swap(src, dst);
    }
  }
  if (src != f.data.data()) std::memcpy(f.data.data(), src, f.data.size() * sizeof(float));
}

}  // namespace brume::cpu
