// brume — spectral aerial perspective: the parameter declaration, the analysis
// (image-wide statistics, once) and the per-pixel apply of render, re-render
// and remove, with the optional per-channel scattering blur. The equations,
// units and conventions are stated in include/brume/aerial.hpp; the per-pixel
// formulas the GPU shares are src/shared/aerial_math.glsl.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "brume/aerial.hpp"
#include "brume/error.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

namespace {

const ParamTable<Atmosphere>& atmosphere_param_table() {
  static const ParamTable<Atmosphere> t = [] {
    ParamTable<Atmosphere> d("aerial");  // the aerial block's own fields, not a block of their own
    d.real("turbidity", &Atmosphere::turbidity, "1", Range::closed(1.0, 20.0),
           "atmospheric turbidity T (1: pure air; by Table 3.1 corrected: clear from about 2.7, light haze 4.5, haze 9.8, fog 19.3)")
        .real("altitude", &Atmosphere::altitude_m, "m", Range::closed(-500.0, 9000.0),
              "observer altitude h0 above sea level (scales beta_R by e^{-h0/7994 m}, beta_M by e^{-h0/1200 m})");
    return d;
  }();
  return t;
}

bool known_range(float r) { return std::isfinite(r) && r != 0.0f; }

float luminance(const float* c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

// Per-channel median of the listed pixels.
std::array<float, 3> channel_median(const Image& rgb, const std::vector<std::size_t>& px) {
  std::array<float, 3> m{};
  std::vector<float> v(px.size());
  for (int c = 0; c < 3; ++c) {
    for (std::size_t k = 0; k < px.size(); ++k) v[k] = rgb.data[px[k] * 3 + c];
    auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    m[c] = *mid;
  }
  return m;
}

std::string rgb_text(const Rgb& c) {
  std::ostringstream o;
  o << c[0] << "," << c[1] << "," << c[2];
  return o.str();
}

}  // namespace

std::string to_string(AerialMode m) {
  switch (m) {
    case AerialMode::render: return "render";
    case AerialMode::rerender: return "re-render";
    case AerialMode::remove: return "remove";
  }
  return "?";
}

const ParamTable<AerialParams>& aerial_param_table() {
  static const ParamTable<AerialParams> t = [] {
    ParamTable<AerialParams> d("aerial");
    d.nest(&AerialParams::atmosphere, atmosphere_param_table())
        .text("sensitivity", &AerialParams::sensitivity,
              "camera spectral sensitivities q_c(lambda): default, a CSV of wavelength_nm,r,g,b, or "
              "DATABASE.txt#CAMERA NAME")
        .rgb("airlight", &AerialParams::airlight, "linear RGB", Range::at_least(0.0),
             "horizon colour Iinf; auto: the median sky colour (unknown range >= 0.5 % of the frame), else the "
             "median of the brightest 10 % of the 1 % most distant pixels")
        .alias("horizon")
        .alias("fog-color")
        .real("distance-scale", &AerialParams::distance_scale, "1", Range::above(0.0),
              "scene scale: the light travels range x this factor (a 1:100 model: 100)")
        .real("from-turbidity", &AerialParams::from_turbidity, "1", Range::closed(1.0, 20.0),
              "re-render: the turbidity T1 the photo was taken at (eq. 3.13); none: render a clean image", "none")
        .rgb("from-airlight", &AerialParams::from_airlight, "linear RGB", Range::above(0.0),
             "re-render: the photo's own horizon colour Iinf1; auto: the same as --airlight")
        .alias("from-horizon")
        .boolean("remove", &AerialParams::remove, "remove the aerial perspective: I0 = (I - Iinf (1 - Gamma)) / Gamma")
        .real("gamma-floor", &AerialParams::gamma_floor, "1", Range{0.0, 1.0, true, true},
              "smallest Gamma divided by (--remove, and Gamma1 of a re-render): the gain is at most 1/floor")
        .real("lambda", &AerialParams::lambda, "px", Range::at_least(0.0),
              "scattering blur gain: sigma_max = sigma0 + lambda sqrt(kappa_s'), kappa_s' = beta(550 nm) R_max; "
              "0: no blur (the thesis)")
        .nest(&AerialParams::diffusion, diffusion_param_table());
    return d;
  }();
  return t;
}

void validate_aerial(const AerialParams& p, const std::set<std::string>& given) {
  const auto& t = aerial_param_table();
  t.validate(p);
  validate_atmosphere(p.atmosphere);
  if (p.sensitivity.empty())
    throw Error("--sensitivity is empty; give default, a CSV file or DATABASE.txt#CAMERA NAME");
  if (p.remove && p.from_turbidity)
    throw Error("--remove recovers the clean image and --from-turbidity re-renders at another turbidity; give one "
                "of them (to re-render, drop --remove)");
  if (p.from_airlight && !p.from_turbidity)
    throw Error("--from-horizon is the photo's horizon for a re-render; it needs --from-turbidity T1");
  if (p.remove && (p.lambda > 0.0 || t.is_set(p, "lambda", given)))
    throw Error("--lambda " + std::to_string(p.lambda) +
                " with --remove: the scattering blur cannot be undone; drop --lambda (remove uses Gamma only)");
}

AerialAnalysis analyse_aerial(const Image& rgb, const Image& range, const AerialParams& p) {
  validate_aerial(p);
  if (rgb.channels != 3)
    throw Error("aerial needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  if (range.channels != 1) throw Error("the range map must have one channel");
  if (rgb.width != range.width || rgb.height != range.height)
    throw Error("range map " + range.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the range map, or crop both)");

  AerialAnalysis a;
  a.mode = p.remove ? AerialMode::remove : (p.from_turbidity ? AerialMode::rerender : AerialMode::render);
  a.sky = Image(range.width, range.height, 1, 0.0f);
  double rmax = 0.0, rmin = INFINITY;
  std::vector<std::size_t> known;
  known.reserve(range.pixels());
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    const float r = range.data[i];
    if (!known_range(r)) {
      ++a.unknown_pixels;
      a.sky.data[i] = 1.0f;
      continue;
    }
    if (r < 0.0f) {
      std::ostringstream m;
      m << "range map pixel (" << i % range.width << ", " << i / range.width << ") is " << r
        << " m; ranges must be >= 0 (0, NaN and inf mark unknown pixels)";
      throw Error(m.str());
    }
    known.push_back(i);
    rmax = std::max(rmax, static_cast<double>(r));
    rmin = std::min(rmin, static_cast<double>(r));
  }
  if (known.empty()) throw Error("the range map has no known value (every pixel is NaN, inf or 0)");
  if (!(rmax > 0.0)) throw Error("every known range is 0 m; aerial perspective needs distances in metres");
  a.range_max_m = rmax;
  a.range_min_m = rmin;

  a.sensitivity = load_sensitivity(p.sensitivity);
  const double s_max = a.range_max_m * p.distance_scale;
  a.gamma = attenuation_table(p.atmosphere, a.sensitivity, s_max);
  if (p.from_turbidity) {
    Atmosphere from = p.atmosphere;
    from.turbidity = *p.from_turbidity;
    a.gamma_from = attenuation_table(from, a.sensitivity, s_max);
  }

  // kappa_s' for haze's sigma law: the optical depth at the far end at 550 nm.
  a.beta_550_per_m = rayleigh_beta_per_m(550.0, p.atmosphere.altitude_m) +
                     mie_beta_per_m(550.0, p.atmosphere.turbidity, p.atmosphere.altitude_m);
  a.kappa_s = a.beta_550_per_m * s_max;
  a.sigma_max = sh::brume_sigma_max(static_cast<float>(p.diffusion.sigma0), static_cast<float>(p.lambda),
                                    static_cast<float>(a.kappa_s));
  a.plan = plan_diffusion(p.diffusion, a.sigma_max);

  std::array<float, 3> estimated{};
  std::string estimated_source;
  if (!p.airlight || (a.mode == AerialMode::rerender && !p.from_airlight)) {
    if (a.unknown_pixels >= std::max<std::size_t>(1, rgb.pixels() / 200)) {
      std::vector<std::size_t> sky;
      for (std::size_t i = 0; i < range.pixels(); ++i)
        if (a.sky.data[i] > 0.0f) sky.push_back(i);
      estimated = channel_median(rgb, sky);
      estimated_source = "per-channel median of the unknown-range (sky) pixels";
    } else {
      // The thesis' "brightest pixels near the horizon": the 1 % most distant
      // known pixels, then the brightest 10 % of those by luminance.
      const std::size_t nfar = std::max<std::size_t>(1, known.size() / 100);
      std::nth_element(known.begin(), known.begin() + static_cast<std::ptrdiff_t>(nfar - 1), known.end(),
                       [&](std::size_t i, std::size_t j) { return range.data[i] > range.data[j]; });
      std::vector<std::size_t> far(known.begin(), known.begin() + static_cast<std::ptrdiff_t>(nfar));
      const std::size_t nb = std::max<std::size_t>(1, far.size() / 10);
      std::nth_element(far.begin(), far.begin() + static_cast<std::ptrdiff_t>(nb - 1), far.end(),
                       [&](std::size_t i, std::size_t j) {
                         return luminance(&rgb.data[i * 3]) > luminance(&rgb.data[j * 3]);
                       });
      far.resize(nb);
      estimated = channel_median(rgb, far);
      estimated_source = "per-channel median of the brightest 10 % of the 1 % most distant pixels (no sky in view)";
    }
  }
  if (p.airlight) {
    a.airlight = *p.airlight;
    a.airlight_source = "given";
  } else {
    a.airlight = estimated;
    a.airlight_source = estimated_source;
  }
  if (a.mode == AerialMode::rerender) {
    if (p.from_airlight) {
      a.from_airlight = *p.from_airlight;
      a.from_airlight_source = "given";
    } else if (p.airlight) {
      a.from_airlight = *p.airlight;
      a.from_airlight_source = "the same as --airlight";
    } else {
      a.from_airlight = estimated;
      a.from_airlight_source = estimated_source;
    }
    // Eq. 3.13 divides by Iinf1 (in the sensitivity's space).
    Rgb f = a.from_airlight;
    if (a.sensitivity.space == SensitivitySpace::xyz)
      f = {sh::brume_srgb_to_x(f[0], f[1], f[2]), sh::brume_srgb_to_y(f[0], f[1], f[2]),
           sh::brume_srgb_to_z(f[0], f[1], f[2])};
    if (!(f[0] > 0.0f && f[1] > 0.0f && f[2] > 0.0f))
      throw Error("the photo's horizon colour Iinf1 (" + rgb_text(a.from_airlight) + ", " + a.from_airlight_source +
                  ") has a channel <= 0; eq. 3.13 divides by it: give --from-horizon R,G,B with every value > 0");
  }
  return a;
}

AerialResult apply_aerial(const Image& rgb, const Image& range, const AerialParams& p, const AerialAnalysis& a,
                          const Exec& exec) {
  const int W = rgb.width, H = rgb.height;
  if (range.width != W || range.height != H || range.channels != 1 || rgb.channels != 3)
    throw Error("aerial: range map " + range.size_string() + " does not match image " + rgb.size_string());
  if (!a.sky.data.empty() && (a.sky.width != W || a.sky.height != H))
    throw Error("aerial: the analysis was made for another image size (" + a.sky.size_string() + ")");
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const bool xyz = a.sensitivity.space == SensitivitySpace::xyz;
  const float s0 = static_cast<float>(p.diffusion.sigma0), smax = static_cast<float>(a.sigma_max);
  const float inv_rmax = static_cast<float>(1.0 / a.range_max_m);
  const double far_m = a.range_max_m * p.distance_scale;
  const float floor_g = static_cast<float>(p.gamma_floor);
  auto to_space = [xyz](const std::array<float, 3>& c) {
    if (!xyz) return c;
    return std::array<float, 3>{sh::brume_srgb_to_x(c[0], c[1], c[2]), sh::brume_srgb_to_y(c[0], c[1], c[2]),
                                sh::brume_srgb_to_z(c[0], c[1], c[2])};
  };
  const std::array<float, 3> A = to_space(a.airlight), A1 = to_space(a.from_airlight);
  const bool blur = a.plan.iterations > 0 && a.mode != AerialMode::remove;

  AerialResult out;
  out.rgb = Image(W, H, 3);
  out.attenuation = Image(W, H, 3);
  out.scale = Image(W, H, 1);
  Image f(W, H, 6);  // (rho E', rho): the premultiplied colour and the per-channel transfer
  std::size_t floored = 0;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : floored)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const float r = range.data[i];
      const bool known = known_range(r);
      const bool sky = (!a.sky.data.empty() && a.sky.data[i] > 0.0f) || !known;
      // Unknown here (preparation off) is sky at the far end, as haze does.
      const double s = known ? static_cast<double>(r) * p.distance_scale : far_m;
      out.scale.data[i] = sh::brume_target_scale(known ? r * inv_rmax : 1.0f, s0, smax);
      const std::array<float, 3> e = to_space({rgb.data[i * 3], rgb.data[i * 3 + 1], rgb.data[i * 3 + 2]});
      const std::array<float, 3> g = a.gamma.at(s);
      std::array<float, 3> rho{}, ep{};
      if (a.mode == AerialMode::render) {
        rho = g;
        ep = e;
      } else if (a.mode == AerialMode::rerender) {
        const std::array<float, 3> g1 = a.gamma_from.at(s);
        floored += !sky && (g1[0] < floor_g || g1[1] < floor_g || g1[2] < floor_g) ? 1 : 0;
        for (int c = 0; c < 3; ++c) {
          rho[c] = sh::brume_aerial_rerender_rho(g[c], g1[c], floor_g);
          ep[c] = sh::brume_aerial_rerender_radiance(e[c], A[c], A1[c]);
        }
      } else {
        floored += !sky && (g[0] < floor_g || g[1] < floor_g || g[2] < floor_g) ? 1 : 0;
        for (int c = 0; c < 3; ++c) {
          rho[c] = g[c];
          ep[c] = sh::brume_aerial_remove(e[c], g[c], A[c], floor_g);  // the result itself
        }
      }
      for (int c = 0; c < 3; ++c) {
        f.data[i * 6 + c] = a.mode == AerialMode::remove ? ep[c] : rho[c] * ep[c];
        f.data[i * 6 + 3 + c] = rho[c];
      }
    }
  out.floored_pixels = floored;

  if (blur) diffuse(f, out.scale, a.sigma_max, p.diffusion, exec);

#pragma omp parallel for num_threads(nt) schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const bool sky = (!a.sky.data.empty() && a.sky.data[i] > 0.0f) || !known_range(range.data[i]);
      if (sky) {  // the sky already is the horizon: unchanged, bit for bit
        for (int c = 0; c < 3; ++c) out.rgb.data[i * 3 + c] = rgb.data[i * 3 + c], out.attenuation.data[i * 3 + c] = 1.0f;
        continue;
      }
      std::array<float, 3> o{};
      for (int c = 0; c < 3; ++c) {
        const float fc = f.data[i * 6 + c], alpha = f.data[i * 6 + 3 + c];
        o[c] = a.mode == AerialMode::remove ? fc : sh::brume_composite_premultiplied(fc, alpha, A[c]);
        out.attenuation.data[i * 3 + c] = alpha;
      }
      if (xyz)
        o = {sh::brume_xyz_to_r(o[0], o[1], o[2]), sh::brume_xyz_to_g(o[0], o[1], o[2]),
             sh::brume_xyz_to_b(o[0], o[1], o[2])};
      for (int c = 0; c < 3; ++c) out.rgb.data[i * 3 + c] = o[c];
    }
  return out;
}

}  // namespace brume
