// brume — depth of field by leak-free diffusion (Bertalmio et al. eq. 1-2,
// 14, 16, §3.4); the equations, units and rules are stated in
// include/brume/dof.hpp. This file holds the declaration of the parameters,
// the scale map (CoC, cap, foreground rule) and the CPU apply of each
// scheme, every one of them on the engine's one stencil (brume/diffusion.hpp).
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "core/huge_pages.hpp"
#include "core/schedule.hpp"
#include "core/text.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

const EnumNames<DofScheme>& dof_scheme_names() {
  static const EnumNames<DofScheme> n = {{DofScheme::invariant_exact, "invariant-exact"},
                                         {DofScheme::standard, "standard"},
                                         {DofScheme::bertalmio, "bertalmio"},
                                         {DofScheme::leaky, "leaky"}};
  return n;
}
std::string to_string(DofScheme s) { return enum_name(dof_scheme_names(), s); }

const EnumNames<Foreground>& foreground_names() {
  static const EnumNames<Foreground> n = {{Foreground::soft, "soft"}, {Foreground::sharp, "sharp"}};
  return n;
}

const ParamTable<DofParams>& dof_param_table() {
  static const ParamTable<DofParams> t = [] {
    ParamTable<DofParams> d("dof");
    d.real("focus-distance", &DofParams::focus_distance_m, "m", Range::above(0.0),
           "focus distance Zf, planar depth of the plane in focus (required)", "none")
        .real("f-number", &DofParams::f_number, "1", Range::above(0.0),
              "f-number n of the lens (with the camera's --focal-length and --sensor-width)", "none")
        .real("coc-infinity", &DofParams::coc_infinity_px, "px", Range::at_least(0.0),
              "CoC diameter at infinity, alpha in pixels, instead of the lens (for artists)", "none")
        .real("coc-limit", &DofParams::coc_limit_px, "px", Range::above(0.0),
              "cap on the target scale sigma = sqrt(sigma0^2 + (c/4)^2), so that a near pixel cannot set the "
              "iteration count")
        .choice("scheme", &DofParams::scheme, dof_scheme_names(),
                "invariant-exact (default: the engine's geometric steps, leak-free, tens of iterations), standard "
                "(eq. 16 with a symmetric edge weight, leak-free, 2 sigma^2 iterations), bertalmio (eq. 16 as "
                "published: leaks across the left/top edges of in-focus objects; CPU), leaky (eq. 14, g Laplacian; "
                "CPU)")
        .choice("foreground", &DofParams::foreground, foreground_names(),
                "soft (default, the paper's §3.4: near-field blur spreads over the background) or sharp (the "
                "unprocessed CoC map: blurred near objects keep a sharp silhouette)")
        .nest_except(&DofParams::diffusion, diffusion_param_table(), {"scheme"});
    return d;
  }();
  return t;
}

namespace {


}  // namespace

void validate_dof(const DofParams& p, const std::set<std::string>& given) {
  const auto& t = dof_param_table();
  t.validate(p);
  if (!p.focus_distance_m)
    throw Error("--focus-distance is required: the planar depth in metres of the plane in focus");
  // The camera's focal length and sensor may be given for the intrinsics
  // whatever the CoC; the aperture is the CoC's alone.
  if (p.coc_infinity_px && p.f_number)
    throw Error("--coc-infinity gives the CoC at infinity directly; do not also give the lens's --f-number, which "
                "would set it too");
  if (!p.coc_infinity_px) {
    const bool sensor = p.lens.sensor_fit == SensorFit::vertical ? p.lens.sensor_height_mm.has_value()
                                                                 : p.lens.sensor_width_mm.has_value();
    if (!(p.f_number && p.lens.focal_length_mm && sensor)) {
      std::string missing;
      if (!p.f_number) missing += " --f-number";
      if (!p.lens.focal_length_mm) missing += " --focal-length";
      if (!sensor) missing += p.lens.sensor_fit == SensorFit::vertical ? " --sensor-height" : " --sensor-width";
      throw Error("the circle of confusion needs the lens (--f-number N --focal-length MM --sensor-width MM; missing:" +
                  missing + ") or --coc-infinity PX");
    }
    const double zf_mm = *p.focus_distance_m * 1000.0;
    if (!(zf_mm > *p.lens.focal_length_mm)) {
      std::ostringstream m;
      m << "--focus-distance " << *p.focus_distance_m << " m is not beyond the focal length --focal-length "
        << *p.lens.focal_length_mm << " mm; a thin lens focuses only on planes farther than F (alpha = F^2/(n (Zf - F))): "
        << "give a focus distance > " << *p.lens.focal_length_mm / 1000.0 << " m";
      throw Error(m.str());
    }
  }
  if (p.coc_limit_px < p.diffusion.sigma0) {
    std::ostringstream m;
    m << "--coc-limit " << p.coc_limit_px << " px is below the inner scale --sigma0 " << p.diffusion.sigma0
      << " px; the cap is on the target scale sigma, which is at least sigma0: give --coc-limit >= --sigma0";
    throw Error(m.str());
  }
  if (p.scheme == DofScheme::leaky && p.diffusion.precision == Precision::f16)
    throw Error("--scheme leaky (eq. 14, a comparison mode) runs in f32 only; drop --precision f16");
  const bool edge_schemes = p.scheme == DofScheme::invariant_exact || p.scheme == DofScheme::standard;
  if (!edge_schemes && t.is_set(p, "edge-rate", given))
    throw Error("--edge-rate is not used by --scheme " + to_string(p.scheme) +
                " (its edge weight is fixed by the paper's equation); drop it, or use --scheme invariant-exact or "
                "standard");
}

DiffusionParams dof_diffusion_params(const DofParams& p) {
  DiffusionParams d = p.diffusion;
  // bertalmio and leaky plan and form their rates as the standard scheme:
  // rho = g/4 = (sigma^2 - sigma0^2)/(2N), N = ceil((smax^2 - s0^2)/(2 rho_max)),
  // which at rho_max = 1/4 is eq. 16's g <= 1 with the corrected N = 2 sigma^2.
  d.scheme = p.scheme == DofScheme::invariant_exact ? Scheme::invariant_exact : Scheme::standard;
  return d;
}

std::optional<double> lens_fx_px(const DofParams& p, int width, int height) {
  if (!p.lens.focal_length_mm) return std::nullopt;
  return lens_intrinsics(p.lens, width, height).fx;
}

double coc_infinity_px(const DofParams& p, int width, int height) {
  if (p.coc_infinity_px) return *p.coc_infinity_px;
  const double F = *p.lens.focal_length_mm, n = *p.f_number, zf_mm = *p.focus_distance_m * 1000.0;
  const double alpha_mm = F * F / (n * (zf_mm - F));  // eq. 2, on the sensor
  // px per mm = s / sensor (s the side the fit spans; before schema 4 the width).
  const LensScale l = lens_scale(p.lens, width, height);
  return alpha_mm * l.side_px / l.sensor_mm;
}

Image planar_depth(const Image& range, const Intrinsics& k) {
  Image z = range_to_z(range, k);
  for (float& v : z.data)
    if (!std::isfinite(v) || v <= 0.0f) v = NAN;
  return z;
}

namespace {

// Half-sample mirror (the diffusion engine's boundary): -1 -> 0, n -> n-1.
int mirror(int i, int n) {
  while (i < 0 || i >= n) i = i < 0 ? -1 - i : 2 * n - 1 - i;
  return i;
}

// Eight floats (GCC's vector extension; two SSE registers on the baseline).
typedef float BlurLanes __attribute__((vector_size(32)));

// In place: a sampled Gaussian of standard deviation s px (radius ceil(4 s),
// weights normalised: truncation < 7e-5 of the mass), separable, mirrored
// borders; rows, then columns, in parallel.
void gaussian_blur(Image& img, double s, int nt) {
  const int W = img.width, H = img.height, r = static_cast<int>(std::ceil(4.0 * s));
  std::vector<float> k(2 * r + 1);
  double sum = 0.0;
  for (int i = -r; i <= r; ++i) sum += std::exp(-0.5 * i * i / (s * s));
  for (int i = -r; i <= r; ++i) k[i + r] = static_cast<float>(std::exp(-0.5 * i * i / (s * s)) / sum);
  Image tmp(W, H, 1);
#pragma omp parallel num_threads(nt)
  {
    std::vector<float> row(static_cast<std::size_t>(W + 2 * r));
    std::vector<const float*> taps(static_cast<std::size_t>(2 * r + 1));  // the column pass's rows
#pragma omp for schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y) {
      std::memcpy(row.data() + r, &img.at(0, y), static_cast<std::size_t>(W) * sizeof(float));
      for (int x = -r; x < 0; ++x) row[x + r] = img.at(mirror(x, W), y);
      for (int x = W; x < W + r; ++x) row[x + r] = img.at(mirror(x, W), y);
      float* o = &tmp.at(0, y);
      // Eight columns at a time, each lane the scalar loop's sum in its
      // order (GCC's vector extension: the same multiplies and adds, lane by
      // lane), then the rest one at a time.
      int x = 0;
      for (; x + 8 <= W; x += 8) {
        BlurLanes acc = {};
        for (int i = 0; i <= 2 * r; ++i) {
          BlurLanes v;
          std::memcpy(&v, &row[static_cast<std::size_t>(x + i)], sizeof v);
          acc += k[i] * v;
        }
        std::memcpy(o + x, &acc, sizeof acc);
      }
      for (; x < W; ++x) {
        float acc = 0.0f;
        for (int i = 0; i <= 2 * r; ++i) acc += k[i] * row[x + i];
        o[x] = acc;
      }
    }
#pragma omp for schedule(dynamic, kRowChunk)
    for (int y = 0; y < H; ++y) {
      float* o = &img.at(0, y);
      for (int i = -r; i <= r; ++i) taps[static_cast<std::size_t>(i + r)] = &tmp.at(0, mirror(y + i, H));
      // o = 0, then o += w_i src_i for i = -r .. r: eight columns at a time
      // kept in a register through the taps (the same operations in the
      // same order, lane by lane), then the rest.
      int x = 0;
      for (; x + 8 <= W; x += 8) {
        BlurLanes acc = {};
        for (int i = 0; i <= 2 * r; ++i) {
          BlurLanes v;
          std::memcpy(&v, taps[static_cast<std::size_t>(i)] + x, sizeof v);
          acc += k[i] * v;
        }
        std::memcpy(o + x, &acc, sizeof acc);
      }
      for (; x < W; ++x) {
        float acc = 0.0f;
        for (int i = 0; i <= 2 * r; ++i) acc += k[i] * taps[static_cast<std::size_t>(i)][x];
        o[x] = acc;
      }
    }
  }
}

// §3.4's foreground rule (stated in dof.hpp): the near field's scale map is
// split into octave bands of sigma, [2^j, 2^{j+1}) px, band j (sigma0
// elsewhere) is blurred by a Gaussian of 2^j px, and every pixel takes the
// largest of its own sigma and the blurred bands, capped at the limit. Each
// near pixel so spreads by about its own scale, as its blur disc (radius c/2
// = 2 sigma) overlaps its neighbours. (One blur by the largest near sigma let
// a strongly blurred near ground raise an in-focus house 60 px above it,
// measured against the thin-lens render.)
//
// A blurred band is smooth, so it is formed at 1/k resolution, k =
// floor(2^j / 2) (>= 1): box-averaged down, blurred by s_c = sqrt((2^j/k)^2
// - 1/4) coarse px (a box-averaged coarse pixel is taken as sigma 0.5: the
// variance 2^{2j}/k^2 in all), read back bilinearly; it shapes a soft rim,
// not an image. The blur is a separable sampled Gaussian (s_c <= 1.94 coarse
// px: 17 taps), where it was the diffusion engine's invariant-exact scheme at
// that constant scale (a Gaussian to ~1e-3, tests/test_diffusion.cpp): the
// same map to within the engine's own accuracy (tests/test_dof.cpp bounds the
// difference against the definition), at a fraction of the cost (the engine
// ran a full-resolution 4-channel iteration per step for the bands j <= 1;
// 249 of the default's 455 ms at 1024 x 768, sigma up to 20 px).
void near_field_raise(const Image& z, float zf, float s0, float limit, Image& sigma, int nt) {
  const int W = z.width, H = z.height;
  const long np = static_cast<long>(z.pixels());
  std::vector<signed char> band(z.pixels(), -1);
  int top_band = -1;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk) reduction(max : top_band)
  for (long i = 0; i < np; ++i) {
    const float zi = z.data[static_cast<std::size_t>(i)], si = sigma.data[static_cast<std::size_t>(i)];
    if (std::isfinite(zi) && zi < zf && si > s0) {
      const int j = std::max(0, static_cast<int>(std::floor(std::log2(si))));
      band[static_cast<std::size_t>(i)] = static_cast<signed char>(j);
      top_band = std::max(top_band, j);
    }
  }
  // Bilinear reads of a coarse map at the pixel centres, clamped at the
  // borders: the taps and weights of each column (and row) computed once.
  struct Axis {
    std::vector<int> i0, i1;
    std::vector<float> a;
  };
  auto axis = [](int n, int k, int coarse) {
    Axis t{std::vector<int>(n), std::vector<int>(n), std::vector<float>(n)};
    for (int x = 0; x < n; ++x) {
      const float f = std::clamp((x + 0.5f) / k - 0.5f, 0.0f, static_cast<float>(coarse - 1));
      t.i0[x] = static_cast<int>(f);
      t.i1[x] = std::min(t.i0[x] + 1, coarse - 1);
      t.a[x] = f - t.i0[x];
    }
    return t;
  };
  // A blurred band, its axes, and (k > 1) its rows read bilinearly along x
  // at every pixel centre: horiz(x, cy) = the coarse row cy at column x,
  // formed once per coarse row rather than twice per pixel row.
  struct Coarse {
    Image map;
    Axis ax, ay;
    Image horiz;
  };
  std::vector<Coarse> bands;
  for (int j = 0; j <= top_band; ++j) {
    const float s_band = std::ldexp(1.0f, j);  // the band's lower edge: every member's sigma is >= it
    const int k = std::max(1, static_cast<int>(s_band / 2.0f));
    const int w = (W + k - 1) / k, h = (H + k - 1) / k;
    Image small(w, h, 1);
    int members = 0;
    if (k == 1) {
      // Each coarse pixel is one pixel: the average below is (0.0 + v) / 1,
      // v itself, so the band's values are taken as they are (a pass the
      // compiler vectorises instead of the blocks' nested loops).
      const std::size_t n = z.pixels();
      const signed char* b = band.data();
      const float* sg = sigma.data.data();
      float* out = small.data.data();
      for (std::size_t i = 0; i < n; ++i) {
        const bool in = b[i] == j;
        out[i] = in ? sg[i] : s0;
        members += in;
      }
    } else {
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk) reduction(+ : members)
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          double acc = 0.0;
          int n = 0;
          for (int yy = y * k; yy < std::min(H, (y + 1) * k); ++yy)
            for (int xx = x * k; xx < std::min(W, (x + 1) * k); ++xx) {
              const std::size_t i = static_cast<std::size_t>(yy) * W + xx;
              const bool in = band[i] == j;
              acc += in ? sigma.data[i] : s0;
              members += in;
              ++n;
            }
          small.at(x, y) = static_cast<float>(acc / n);
        }
    }
    if (members == 0) continue;
    const double s_small = std::max(1.0, static_cast<double>(s_band) / k);
    gaussian_blur(small, std::sqrt(s_small * s_small - 0.25), nt);
    Coarse c{std::move(small), axis(W, k, w), axis(H, k, h), Image()};
    if (k > 1) {
      c.horiz = Image(W, h, 1);
      const int *x0 = c.ax.i0.data(), *x1 = c.ax.i1.data();
      const float* ax = c.ax.a.data();
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
      for (int cy = 0; cy < h; ++cy) {
        const float* rc = c.map.data.data() + static_cast<std::size_t>(cy) * w;
        float* o = &c.horiz.at(0, cy);
        for (int x = 0; x < W; ++x) o[x] = rc[x0[x]] + ax[x] * (rc[x1[x]] - rc[x0[x]]);
      }
    }
    bands.push_back(std::move(c));
  }
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y) {
    float* v = &sigma.at(0, y);
    for (const Coarse& c : bands) {
      if (c.map.width == W && c.map.height == H) {
        // A full-resolution band (k = 1): every pixel's bilinear weights are
        // 0 (its centre is a coarse pixel's), so the read is the band's own
        // value, t + 0 (b - t) with t = r0[x] + 0 (r0[x + 1] - r0[x]), and
        // the values are positive and finite: r0[x] itself.
        const float* r = c.map.data.data() + static_cast<std::size_t>(y) * W;
        for (int x = 0; x < W; ++x) v[x] = std::max(v[x], r[x]);
        continue;
      }
      // t and b: the coarse rows above and below, read at x (horiz).
      const float* t = c.horiz.row(c.ay.i0[y]);
      const float* b = c.horiz.row(c.ay.i1[y]);
      const float ay = c.ay.a[y];
      for (int x = 0; x < W; ++x) v[x] = std::max(v[x], t[x] + ay * (b[x] - t[x]));
    }
    for (int x = 0; x < W; ++x) v[x] = std::min(limit, v[x]);
  }
}

}  // namespace

Image dof_scale_map(const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec) {
  validate_dof(p);
  if (z.channels != 1) throw Error("the depth map must have one channel");
  const int W = z.width, H = z.height;
  a.alpha_px = coc_infinity_px(p, W, H);
  const float alpha = static_cast<float>(a.alpha_px), zf = static_cast<float>(*p.focus_distance_m);
  const float s0 = static_cast<float>(p.diffusion.sigma0), limit = static_cast<float>(p.coc_limit_px);
  Image sigma(W, H, 1);
  // The map's ~17 parallel regions are light (1-3 ms each at 1024x768), and
  // each ends when every thread has arrived: on a loaded host the second
  // thread's wait for a core cost more than it shares (1024x768, AMD EPYC
  // family 26, 2 vCPU, load average 6.5, 2026-12-06: 39-44 ms on one
  // thread, 155-264 ms on two; on a quiet host two threads took 21.6 ms,
  // 2026-12-01). brume_bench_dof ROUNDS map.
  // One thread below kDofMapParallelPixels (4 Mpx), whatever the call's count.
  constexpr std::size_t kDofMapParallelPixels = std::size_t{1} << 22;
  const int nt = z.pixels() < kDofMapParallelPixels ? 1 : exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const long np = static_cast<long>(z.pixels());
  long unknown = 0, near = 0, capped = 0;
  double zmin = INFINITY, zmax = 0.0;
#pragma omp parallel for num_threads(nt) schedule(dynamic, kPixelChunk) reduction(+ : unknown, near, capped) \
    reduction(min : zmin) reduction(max : zmax)
  for (long i = 0; i < np; ++i) {
    const float zi = z.data[static_cast<std::size_t>(i)];
    const bool known = std::isfinite(zi) && zi > 0.0f;
    // Unknown depth is infinitely far (sky): c = alpha.
    const float c = known ? sh::brume_coc(alpha, zi, zf) : alpha;
    if (!known) {
      ++unknown;
    } else {
      zmin = std::min(zmin, static_cast<double>(zi));
      zmax = std::max(zmax, static_cast<double>(zi));
      if (zi < zf) ++near;
    }
    if (sh::brume_dof_scale(c, s0, INFINITY) > limit) ++capped;
    sigma.data[static_cast<std::size_t>(i)] = sh::brume_dof_scale(c, s0, limit);
  }
  a.unknown_pixels = static_cast<std::size_t>(unknown);
  a.near_pixels = static_cast<std::size_t>(near);
  a.capped_pixels = static_cast<std::size_t>(capped);
  a.z_min_m = std::isfinite(zmin) ? zmin : 0.0;
  a.z_max_m = zmax;

  if (p.foreground == Foreground::soft && a.near_pixels > 0) near_field_raise(z, zf, s0, limit, sigma, nt);
  // The largest scale: every value is finite and at least s0 (no NaN), so
  // the order of the comparisons cannot change it: sixteen running maxima,
  // a loop that vectorises (one loop-carried max took ~1 ms at 1024 x 768).
  float m16[16];
  std::fill(m16, m16 + 16, s0);
  const std::size_t nv = sigma.data.size();
  const float* sv = sigma.data.data();
  std::size_t i16 = 0;
  for (; i16 + 16 <= nv; i16 += 16)
    for (int j = 0; j < 16; ++j) m16[j] = std::max(m16[j], sv[i16 + j]);
  float smax = s0;
  for (; i16 < nv; ++i16) smax = std::max(smax, sv[i16]);
  for (const float m : m16) smax = std::max(smax, m);
  a.sigma_max = smax;
  // Bounded where it is decided (brume/diffusion.hpp).
  a.plan = plan_diffusion(dof_diffusion_params(p), a.sigma_max, W, H,
                          "sqrt(sigma0^2 + (c/4)^2) at the most blurred pixel, c the circle of confusion (CoC at "
                          "infinity " + text::g(a.alpha_px) + " px: --coc-infinity, or --f-number, --focal-length and "
                          "--sensor-width; --focus-distance), capped by --coc-limit " + text::g(p.coc_limit_px) +
                          " px: lower --coc-limit or the CoC");
  return sigma;
}

namespace {

// The rates eq. 16 uses, rho = g/4 = (sigma^2 - sigma0^2)/(2N), per pixel.
Image standard_rates(const Image& sigma, double sigma0, int N) {
  Image rho(sigma.width, sigma.height, 1, 0.0f);
  if (N > 0)
    for (std::size_t i = 0; i < rho.data.size(); ++i)
    rho.data[i] = sh::brume_standard_rate(sigma.data[i], static_cast<float>(sigma0), static_cast<float>(N));
  return rho;
}

}  // namespace

DofResult apply_dof(DenseImageRef rgb, const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec) {
  if (rgb.channels != 3) throw Error("depth of field needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  if (rgb.width != z.width || rgb.height != z.height)
    throw Error("depth map " + z.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the depth map, or crop both)");
  DofResult out;
  out.scale = dof_scale_map(z, p, a, exec);
  const DiffusionParams dp = dof_diffusion_params(p);
  const int W = rgb.width, H = rgb.height, N = a.plan.iterations;
  // The default scheme in f32 diffuses the RGB values themselves, as `brume
  // blur` does (rows of three values a pixel: the bits each channel gets in
  // four, DiffusionChannels.RgbRowsGiveTheRgbaBits), in the result's own
  // buffer: no RGBA image (12.6 MB at 1024 x 768, zero-filled and first
  // touched in every call), no packing into it nor out of it, and a quarter
  // less arithmetic and traffic. The other schemes' conductance rows and
  // binary16 storage take four channels.
  if (p.scheme == DofScheme::invariant_exact && dp.precision == Precision::f32) {
    detail::reserve_huge(out.rgb.data, rgb.data.size());
    out.rgb.data.assign(rgb.data.begin(), rgb.data.end());
    out.rgb.width = W, out.rgb.height = H, out.rgb.channels = 3;
    diffuse(out.rgb, out.scale, a.sigma_max, dp, exec);
    return out;
  }
  // RGB and a constant fourth channel (the engine's vector width; mass
  // conservation keeps it 1 except with eq. 14, which does not conserve).
  Image f(W, H, 4);
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = rgb.data[i * 3 + c];
    f.data[i * 4 + 3] = 1.0f;
  }
  switch (p.scheme) {
    case DofScheme::invariant_exact:
    case DofScheme::standard:
      diffuse(f, out.scale, a.sigma_max, dp, exec);
      break;
    case DofScheme::bertalmio: {
      // Eq. 16: the edge (x, x+1) and (y, y+1) weighted by g/4 of the pixel
      // holding the forward difference, i.e. wx = wy = rho(x, y).
      const Image w = standard_rates(out.scale, dp.sigma0, N);
      diffuse_conductance(f, w, w, N, dp.precision, exec);
      break;
    }
    case DofScheme::leaky: {
      // Eq. 14: I <- I + g/4 Delta I = I + g (J - I) with J one isotropic
      // step of weight 1/4 on every edge (the engine's conductance step).
      const Image rho = standard_rates(out.scale, dp.sigma0, N);
      const Image quarter(W, H, 1, 0.25f);
      for (int k = 0; k < N; ++k) {
        Image j = f;
        diffuse_conductance(j, quarter, quarter, 1, dp.precision, exec);
        for (std::size_t i = 0; i < f.pixels(); ++i) {
          const float g = 4.0f * rho.data[i];
          for (int c = 0; c < 4; ++c) f.data[i * 4 + c] += g * (j.data[i * 4 + c] - f.data[i * 4 + c]);
        }
      }
      break;
    }
  }
  out.rgb = Image(W, H, 3);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) out.rgb.data[i * 3 + c] = f.data[i * 4 + c];
  return out;
}

}  // namespace brume
