// brume — haze and fog with scattering blur (Hansard eq. 1-7); the equations
// and units are stated in include/brume/haze.hpp. This file holds the
// analysis step (image-wide statistics, once) and the per-pixel apply.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/haze.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "core/schedule.hpp"
#include "core/text.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

const EnumNames<Composite>& composite_names() {
  static const EnumNames<Composite> n = {{Composite::premultiplied, "premultiplied"}, {Composite::naive, "naive"}};
  return n;
}
std::string to_string(Composite c) { return enum_name(composite_names(), c); }
const EnumNames<SkyRule>& sky_rule_names() {
  static const EnumNames<SkyRule> n = {{SkyRule::automatic, "auto"}, {SkyRule::s_max, "s-max"}};
  return n;
}

const ParamTable<HazeParams>& haze_param_table() {
  static const ParamTable<HazeParams> t = [] {
    ParamTable<HazeParams> d("haze");
    d.real("kappa-a", &HazeParams::kappa_a, "1 (per R_max)", Range::at_least(0.0),
           "absorption coefficient times R_max (optical depth of absorption at the far end)")
        .real("kappa-s", &HazeParams::kappa_s, "1 (per R_max)", Range::at_least(0.0),
              "scattering coefficient times R_max (optical depth of scattering at the far end)")
        .real("visibility", &HazeParams::visibility_m, "m", Range::above(0.0),
              "meteorological visibility (extinction 3.912/V per metre, Koschmieder); auto: use --kappa-a/--kappa-s")
        .real("albedo", &HazeParams::albedo, "1", Range::closed(0.0, 1.0),
              "single-scattering albedo splitting --visibility's extinction into kappa_s = albedo beta and "
              "kappa_a = (1 - albedo) beta")
        .real("lambda", &HazeParams::lambda, "px", Range::at_least(0.0),
              "blur gain: sigma_max = sigma0 + lambda sqrt(kappa_s) px, kappa_s the normalised scattering "
              "(omega 3.912 R_max / V with --visibility); pixels at any image size, so scale it with the image "
              "(the default 15 blurs a 64 px render's far field over a quarter of its width)")
        .real("range-max", &HazeParams::range_max_m, "m", Range::above(0.0),
              "R_max, the range that normalises R and kappa; auto: the largest finite range")
        .rgb("airlight", &HazeParams::airlight, "linear RGB", Range::at_least(0.0),
             "colour of the medium B; auto: the median sky colour (unknown range >= 0.5 % of the frame), else a "
             "grey at the 99th percentile of luminance")
        .alias("fog-color")
        .alias("horizon")
        .choice("composite", &HazeParams::composite, composite_names(),
                "premultiplied (eq. 4), or naive (the ghost-edged composite the paper warns against, for comparison)")
        .choice("sky-rule", &HazeParams::sky_rule, sky_rule_names(),
                "where the prepared sky lies: auto (with --visibility beyond the medium: at infinity, transmission "
                "0, or at --sky-distance; with --kappa-a/--kappa-s at S_max = s-max-factor R_max), or s-max (S_max "
                "whatever the units: the rule of records before schema 3)")
        .since(3, "s-max")
        .real("sky-distance", &HazeParams::sky_distance_m, "m", Range::above(0.0),
              "distance of the prepared sky: its transmission is exp(-beta M), blended across the horizon margin; "
              "auto: as --sky-rule says")
        .nest(&HazeParams::diffusion, diffusion_param_table());
    return d;
  }();
  return t;
}

void validate_haze(const HazeParams& p, const std::set<std::string>& given) {
  const auto& t = haze_param_table();
  t.validate(p);
  if (p.visibility_m && (t.is_set(p, "kappa-a", given) || t.is_set(p, "kappa-s", given)))
    throw Error("--visibility sets the extinction; do not also give --kappa-a/--kappa-s (use --albedo to split it)");
  if (!p.visibility_m && t.is_set(p, "albedo", given))
    throw Error("--albedo only applies with --visibility; with --kappa-a/--kappa-s the split is explicit");
  if (p.sky_rule == SkyRule::s_max && p.sky_distance_m) {
    std::ostringstream m;
    m << "--sky-distance " << *p.sky_distance_m
      << " m places the sky, but --sky-rule s-max puts it at S_max = s-max-factor R_max; drop one of them";
    throw Error(m.str());
  }
}

namespace {

float luminance(const float* c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

}  // namespace

AirlightEstimate estimate_airlight(ConstImageView rgb, ConstImageView range, std::size_t unknown_pixels) {
  AirlightEstimate a;
  if (unknown_pixels >= std::max<std::size_t>(1, rgb.pixels() / 200)) {
    // Sky (unknown range, >= 0.5 % of the frame): per-channel median colour.
    std::array<std::vector<float>, 3> ch;
    for (int y = 0; y < range.height(); ++y)
      for (int x = 0; x < range.width(); ++x)
        if (!known_range(range.at(x, y)))
          for (int c = 0; c < 3; ++c) ch[c].push_back(rgb.at(x, y, c));
    for (int c = 0; c < 3; ++c) {
      auto mid = ch[c].begin() + ch[c].size() / 2;
      std::nth_element(ch[c].begin(), mid, ch[c].end());
      a.rgb[c] = *mid;
    }
    a.source = "median colour of the unknown-range (sky) pixels";
  } else {
    // No sky in view: an achromatic airlight as bright as the 99th percentile
    // of the image's luminance, the usual look of a bright overcast haze.
    std::vector<float> y(rgb.pixels());
    for (int v = 0; v < rgb.height(); ++v)
      for (int u = 0; u < rgb.width(); ++u)
        y[static_cast<std::size_t>(v) * rgb.width() + u] = luminance(&rgb.at(u, v, 0));
    auto q = y.begin() + static_cast<std::ptrdiff_t>(0.99 * (y.size() - 1));
    std::nth_element(y.begin(), q, y.end());
    a.rgb = {*q, *q, *q};
    a.source = "achromatic, 99th percentile of image luminance (no sky in view)";
  }
  return a;
}

std::optional<double> haze_extinction_per_m(const HazeParams& p) {
  if (p.visibility_m) return 3.912 / *p.visibility_m;  // Koschmieder, 2 % contrast: -ln 0.02 / V
  if (p.range_max_m) return (p.kappa_a + p.kappa_s) / *p.range_max_m;
  return std::nullopt;
}

HazeAnalysis analyse_haze(ConstImageView rgb, ConstImageView range, const HazeParams& p) {
  validate_haze(p);
  if (rgb.channels() != 3) throw Error("haze needs an RGB image, got " + std::to_string(rgb.channels()) + " channels");
  if (range.channels() != 1) throw Error("the range map must have one channel");
  if (rgb.width() != range.width() || rgb.height() != range.height())
    throw Error("range map " + range.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the range map, or crop both)");

  HazeAnalysis a;
  double rmax = 0.0, rmin = INFINITY;
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    const float r = range.at(static_cast<int>(i % range.width()), static_cast<int>(i / range.width()));
    if (!known_range(r)) {
      ++a.unknown_pixels;
      continue;
    }
    if (r < 0.0f) {
      std::ostringstream m;
      m << "range map pixel (" << i % range.width() << ", " << i / range.width() << ") is " << r
        << " m; ranges must be >= 0 (0, NaN and inf mark unknown pixels). Is this a signed depth "
           "(OpenGL eye-space z is negative in front of the camera)? If the file marks unknown pixels with a "
           "negative value such as -1, give it as --unknown-value -1.";
      throw Error(m.str());
    }
    rmax = std::max(rmax, static_cast<double>(r));
    rmin = std::min(rmin, static_cast<double>(r));
  }
  if (a.unknown_pixels == range.pixels())
    throw Error("the range map has no known value (every pixel is NaN, inf or 0)");
  a.range_min_m = rmin;
  a.range_max_m = p.range_max_m ? *p.range_max_m : rmax;
  if (!(a.range_max_m > 0.0))
    throw Error("R_max is 0: every known range is 0 m; give --range-max in metres");

  if (p.visibility_m) {
    const double beta = 3.912 / *p.visibility_m;  // Koschmieder, 2 % contrast
    a.kappa_s = p.albedo * beta * a.range_max_m;
    a.kappa_a = (1.0 - p.albedo) * beta * a.range_max_m;
  } else {
    a.kappa_a = p.kappa_a;
    a.kappa_s = p.kappa_s;
  }
  // In metres, the one definition the LiDAR reads too (3.912/V exactly, not
  // (kappa_a + kappa_s)/R_max, which can differ in the last bit).
  const std::optional<double> metres = haze_extinction_per_m(p);
  a.extinction_per_m = metres ? *metres : (a.kappa_a + a.kappa_s) / a.range_max_m;
  a.sigma_max = sh::brume_sigma_max(static_cast<float>(p.diffusion.sigma0), static_cast<float>(p.lambda),
                                    static_cast<float>(a.kappa_s));
  // Bounded here, where sigma_max is decided (brume/diffusion.hpp): the
  // same check for the CLI, Python, brume run and brume view's plan.
  const std::string set_by =
      p.visibility_m
          ? "sigma0 + lambda sqrt(kappa_s) with --lambda " + text::g(p.lambda) + ", --visibility " +
                text::g(*p.visibility_m) + " m, --albedo " + text::g(p.albedo) + ", R_max " + text::g(a.range_max_m) +
                " m (" + (p.range_max_m ? "--range-max" : "the range map's farthest known pixel") + ") and --sigma0 " +
                text::g(p.diffusion.sigma0) + " px: lower --lambda or raise --visibility"
          : "sigma0 + lambda sqrt(kappa_s) with --lambda " + text::g(p.lambda) + ", --kappa-s " + text::g(p.kappa_s) +
                " and --sigma0 " + text::g(p.diffusion.sigma0) + " px: lower --lambda or --kappa-s";
  a.plan = plan_diffusion(p.diffusion, a.sigma_max, rgb.width(), rgb.height(), set_by);

  // The sky (brume/haze.hpp): beyond the medium when it is in metres or the
  // user places it; else (normalised units, or --sky-rule s-max) at S_max.
  if (p.sky_rule == SkyRule::automatic && p.sky_distance_m) {
    a.sky_beyond = true;
    a.sky_transmission = static_cast<float>(std::exp(-a.extinction_per_m * *p.sky_distance_m));
    a.sky_rule = "sky at --sky-distance: transmission exp(-extinction_per_m sky_distance), blended across the "
                 "horizon margin by the preparation's sky weight";
  } else if (p.sky_rule == SkyRule::automatic && p.visibility_m) {
    a.sky_beyond = true;
    a.sky_transmission = 0.0f;
    a.sky_rule = "physical units (visibility): the sky lies beyond the unbounded medium, transmission 0 (the "
                 "airlight), blended across the horizon margin by the preparation's sky weight";
  } else {
    a.sky_rule = p.sky_rule == SkyRule::s_max ? "--sky-rule s-max: the sky at S_max = s-max-factor R_max"
                                              : "normalised units: the sky at S_max = s-max-factor R_max (Hansard)";
  }

  if (p.airlight) {
    a.airlight = *p.airlight;
    a.airlight_source = "given";
  } else {
    AirlightEstimate e = estimate_airlight(rgb, range, a.unknown_pixels);
    a.airlight = e.rgb;
    a.airlight_source = std::move(e.source);
  }
  return a;
}

ScatterBlur scatter_blur(ConstImageView rgb, const Image& tau0, const Image& sigma, double sigma_max,
                         const DiffusionParams& p, Composite composite, const std::array<float, 3>& airlight,
                         const Exec& exec) {
  const int W = rgb.width(), H = rgb.height();
  const std::ptrdiff_t ps = rgb.pixel_stride();
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const bool naive = composite == Composite::naive;
  Image f(W, H, 4);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const float t = tau0.data[i];
      const float w = naive ? 1.0f : t;  // eq. 2 premultiplies; naive blurs E itself
      const float* e = rgb.row(y) + x * ps;
      for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = w * e[c];
      f.data[i * 4 + 3] = t;
    }

  diffuse(f, sigma, sigma_max, p, exec);

  ScatterBlur out;
  out.rgb = Image(W, H, 3);
  out.transmission = Image(W, H, 1);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const float alpha = f.data[i * 4 + 3];
      out.transmission.data[i] = alpha;
      for (int c = 0; c < 3; ++c) {
        const float v = f.data[i * 4 + c];
        out.rgb.data[i * 3 + c] = naive ? sh::brume_composite_naive(v, tau0.data[i], airlight[c])
                                        : sh::brume_composite_premultiplied(v, alpha, airlight[c]);
      }
    }
  return out;
}

HazeResult apply_haze(ConstImageView rgb, ConstImageView range, const HazeParams& p,
                      const HazeAnalysis& a, const Exec& exec, ConstImageView sky_weight) {
  const int W = rgb.width(), H = rgb.height();
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const float kappa = static_cast<float>(a.kappa_a + a.kappa_s);
  const float s0 = static_cast<float>(p.diffusion.sigma0), smax = static_cast<float>(a.sigma_max);
  const float inv_rmax = static_cast<float>(1.0 / a.range_max_m);
  const bool blend = a.sky_beyond && !sky_weight.empty();
  if (blend && (sky_weight.width() != W || sky_weight.height() != H || sky_weight.channels() != 1))
    throw Error("internal: the sky weight is " + sky_weight.size_string() + ", the image " + rgb.size_string());
  const float tau_sky = a.sky_transmission;

  HazeResult out;
  Image tau0(W, H, 1);
  out.scale = Image(W, H, 1);
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const float r = range.at(x, y);
      const float rn = known_range(r) ? r * inv_rmax : 1.0f;  // unknown -> R_max
      const float tau = sh::brume_transmission(kappa, rn);
      tau0.data[i] = blend ? sh::brume_sky_blend(tau, tau_sky, sky_weight.at(x, y)) : tau;
      out.scale.data[i] = sh::brume_target_scale(rn, s0, smax);
    }
  ScatterBlur b = scatter_blur(rgb, tau0, out.scale, a.sigma_max, p.diffusion, p.composite, a.airlight, exec);
  out.rgb = std::move(b.rgb);
  out.transmission = std::move(b.transmission);
  return out;
}

}  // namespace brume
