// brume — layered fog (Zhou, Chen, Smith); the equations, units and the sky
// rule are stated in include/brume/fog.hpp, the per-pixel maths in
// src/effects/fog/fog_math.glsl (the height profile's: brume/height_profile.hpp).
// This file holds the declaration, the analysis step (image-wide statistics,
// once) and the pure apply.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "core/schedule.hpp"
#include "core/text.hpp"
#include "effects/fog/fog_fast.hpp"
#include "media/height_profile_shared.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

const EnumNames<ClassicFog>& classic_fog_names() {
  static const EnumNames<ClassicFog> n = {
      {ClassicFog::none, "none"}, {ClassicFog::linear, "linear"}, {ClassicFog::exp2, "exp2"}};
  return n;
}

const ParamTable<FogParams>& fog_param_table() {
  static const ParamTable<FogParams> t = [] {
    ParamTable<FogParams> d("fog");
    d.extend_base(height_profile_param_table())
        .choice("classic", &FogParams::classic, classic_fog_names(),
                "classic OpenGL fog on the range instead of a height profile: linear (--fog-start, --fog-end) or "
                "exp2 (--density); classic exp is --profile constant")
        .real("fog-start", &FogParams::fog_start_m, "m", Range::at_least(0.0), "classic linear: no fog nearer than this")
        .real("fog-end", &FogParams::fog_end_m, "m", Range::above(0.0),
              "classic linear: full fog beyond this (must exceed --fog-start)")
        .real("sky-distance", &FogParams::sky_distance_m, "m", Range::above(0.0),
              "distance sky rays integrate over where the fog does not vanish along them, and the sky's blur "
              "distance; auto: infinity (transmission 0; the blur as at S_max = s-max-factor R_max)")
        .choice("sky-rule", &FogParams::sky_rule, sky_rule_names(),
                "auto (the sky beyond the medium, blended across the horizon margin), or s-max (diverging sky rays "
                "over --sky-distance or S_max, the margin as sky: the rule of records before schema 3)")
        .since(3, "s-max")
        .rgb("airlight", &FogParams::airlight, "linear RGB", Range::at_least(0.0),
             "fog colour C_fog; auto: the median sky colour (unknown range >= 0.5 % of the frame), else a grey at "
             "the 99th percentile of luminance")
        .alias("fog-color")
        .alias("horizon")
        .real("lambda", &FogParams::lambda, "px", Range::at_least(0.0),
              "scattering blur gain: sigma = sigma0 + lambda sqrt(albedo F) l / R_max (0: no blur)")
        .real("albedo", &FogParams::albedo, "1", Range::closed(0.0, 1.0),
              "single-scattering albedo: the part of the optical depth F that scatters (blur only)")
        .nest(&FogParams::diffusion, diffusion_param_table())
        .nest<CameraPose>(&FogParams::camera, camera_pose_param_table());
    return d;
  }();
  return t;
}

namespace {

std::string fog_num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

bool needs_heights(const FogParams& p) {
  return p.classic == ClassicFog::none && p.profile != HeightProfile::constant;
}

}  // namespace

void validate_fog(const FogParams& p, const std::set<std::string>& given) {
  const auto& t = fog_param_table();
  t.validate(p);
  auto set = [&](const char* n) { return t.is_set(p, n, given); };
  auto refuse = [&](std::initializer_list<const char*> names, const std::string& why) {
    for (const char* n : names)
      if (set(n)) throw Error(std::string("--") + n + " " + why);
  };
  if (p.classic != ClassicFog::none) {
    const std::string cl = "--classic " + enum_name(classic_fog_names(), p.classic);
    if (given.count("profile"))
      throw Error("--profile and " + cl + " both choose the fog; give one (classic fog has no height profile)");
    refuse({"falloff", "base-height", "band-center", "band-half-width", "ramp-bottom", "ramp-top", "table"},
           "sets a height profile, which " + cl + " does not use; drop it or drop --classic");
    if (p.classic == ClassicFog::linear) {
      refuse({"density"}, "is not used by --classic linear (it uses --fog-start and --fog-end); use --classic exp2");
      if (!(p.fog_end_m > p.fog_start_m))
        throw Error("--fog-end " + fog_num(p.fog_end_m) + " must exceed --fog-start " + fog_num(p.fog_start_m) + " m");
      if (p.lambda > 0.0)
        throw Error("--lambda " + fog_num(p.lambda) + " needs an optical depth, which --classic linear does not have "
                    "beyond --fog-end (it is infinite there); use --classic exp2 or a height profile");
    } else {
      refuse({"fog-start", "fog-end"}, "is only used by --classic linear");
    }
  } else {
    refuse({"fog-start", "fog-end"}, "is only used by --classic linear");
    validate_height_profile(p, given);
  }
  if (p.lambda == 0.0)
    refuse({"albedo", "scheme", "precision", "sigma0", "rho-max", "edge-rate"},
           "only shapes the scattering blur, which --lambda 0 (the default) turns off; give --lambda > 0 or drop it");
  if (!needs_heights(p))
    refuse({"yaw", "pitch", "roll", "camera-height", "camera-x", "camera-z", "view-matrix"},
           "poses the camera, but " +
               (p.classic != ClassicFog::none ? "--classic " + enum_name(classic_fog_names(), p.classic)
                                              : std::string("--profile constant")) +
               " does not depend on height; drop it");
}

// ---- the density relative to the camera ---------------------------------------------

FogDensity fog_density(const FogParams& p, const DensityTable& table, double yc) {
  FogDensity d;
  d.classic = p.classic;
  d.fog_start = p.fog_start_m;
  d.fog_end = p.fog_end_m;
  if (p.classic == ClassicFog::none) {
    static_cast<HeightDensity&>(d) = height_density(p, table, yc);
    return d;
  }
  d.profile = p.profile;
  d.d0 = p.density_per_m;
  return d;
}

int FogDensity::kind() const {
  if (classic == ClassicFog::linear) return 3;
  if (classic == ClassicFog::exp2) return 4;
  return HeightDensity::kind();
}

namespace {

// The frame's fog in the shared form (fog_math.glsl), once per image.
sh::BrumeFog to_shared(const FogDensity& d) {
  sh::BrumeFog f{};
  f.profile = shared_profile(d);
  f.profile.kind = d.kind();
  f.fog_start = static_cast<float>(d.fog_start);
  f.fog_end = static_cast<float>(d.fog_end);
  return f;
}

}  // namespace

float fog_optical_depth(const FogDensity& d, float l, float ray_y, bool sky, float sky_distance) {
  const sh::BrumeFog f = to_shared(d);
  return sky ? sh::brume_fog_sky(f, ray_y, sky_distance) : sh::brume_fog_along(f, l, ray_y);
}

// ---- analysis and apply ------------------------------------------------------------------

namespace {

// The constants of each pixel's world-up ray component (brume_fog_ray_y).
struct RayY {
  float r0 = 0, r1 = 0, r2 = 0, cx = 0, cy = 0, ifx = 0, ify = 0;
  explicit RayY(const Camera& c) {
    const Mat3 R = c.world_from_camera().rotation;
    r0 = static_cast<float>(R.m[1][0]), r1 = static_cast<float>(R.m[1][1]), r2 = static_cast<float>(R.m[1][2]);
    cx = static_cast<float>(c.k.cx), cy = static_cast<float>(c.k.cy);
    ifx = static_cast<float>(1.0 / c.k.fx), ify = static_cast<float>(1.0 / c.k.fy);
  }
  float at(int u, int v) const {
    return sh::brume_fog_ray_y(r0, r1, r2, cx, cy, ifx, ify, static_cast<float>(u), static_cast<float>(v));
  }
};

}  // namespace

FogAnalysis analyse_fog(DenseImageRef rgb, DenseImageRef measured, DenseImageRef range, const Camera& camera,
                        const FogParams& p, double s_max_factor) {
  validate_fog(p);
  if (rgb.channels != 3) throw Error("fog needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  for (const DenseImageRef* r : {&measured, &range}) {
    if (r->channels != 1) throw Error("the range map must have one channel");
    if (rgb.width != r->width || rgb.height != r->height)
      throw Error("range map " + r->size_string() + " does not match image " + rgb.size_string() +
                  "; they must be the same size (resample the range map, or crop both)");
  }
  if (camera.width != rgb.width || camera.height != rgb.height)
    throw Error("internal: the camera is " + std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                ", the image " + rgb.size_string());

  FogAnalysis a;
  a.camera = camera;
  a.camera_used = needs_heights(p);
  double rmax = 0.0, rmin = INFINITY;
  for (std::size_t i = 0; i < measured.pixels(); ++i) {
    const float r = measured.data[i];
    if (!known_range(r)) {
      ++a.unknown_pixels;
      continue;
    }
    if (r < 0.0f) {
      std::ostringstream m;
      m << "range map pixel (" << i % measured.width << ", " << i / measured.width << ") is " << r
        << " m; ranges must be >= 0 (0, NaN and inf mark unknown pixels, which are sky for fog). Is this a signed "
           "depth (OpenGL eye-space z is negative in front of the camera)?";
      throw Error(m.str());
    }
    rmax = std::max(rmax, static_cast<double>(r));
    rmin = std::min(rmin, static_cast<double>(r));
  }
  if (a.unknown_pixels == measured.pixels())
    throw Error("the range map has no known value (every pixel is NaN, inf or 0)");
  a.range_max_m = rmax;
  a.range_min_m = rmin;
  if (!(rmax > 0.0)) throw Error("R_max is 0: every known range is 0 m");
  if (p.sky_distance_m) {
    a.sky_distance_m = *p.sky_distance_m;
    a.sky_distance_source = "given";
  } else {
    a.sky_distance_m = s_max_factor * rmax;
    a.sky_distance_source = "S_max = s-max-factor R_max";
  }
  // The densities are in metres: diverging sky rays cross an unbounded
  // medium (brume/fog.hpp), unless placed by --sky-distance or the old rule.
  a.sky_blend = p.sky_rule == SkyRule::automatic;
  a.sky_at_infinity = a.sky_blend && !p.sky_distance_m;
  if (a.sky_at_infinity) a.sky_distance_source = "infinity (the blur: S_max = s-max-factor R_max)";

  double yc = NAN;
  if (a.camera_used) {
    camera.require_height("--profile " + enum_name(height_profile_names(), p.profile) +
                          " (the fog depends on height)");
    yc = camera.position_m.y;
  }
  if (p.classic == ClassicFog::none && p.profile == HeightProfile::table) a.table = read_density_table(p.table_file);
  a.density = fog_density(p, a.table, std::isfinite(yc) ? yc : 0.0);

  if (p.airlight) {
    a.airlight = *p.airlight;
    a.airlight_source = "given";
  } else {
    AirlightEstimate e = estimate_airlight(rgb.view(), measured.view(), a.unknown_pixels);
    a.airlight = e.rgb;
    a.airlight_source = std::move(e.source);
  }

  // The largest blur scale over the frame, so that the diffusion is planned
  // before it runs (sky pixels blur as at the sky distance).
  a.sigma_max = p.diffusion.sigma0;
  if (p.lambda > 0.0) {
    const RayY ray(camera);
    const float s0 = static_cast<float>(p.diffusion.sigma0), lam = static_cast<float>(p.lambda),
                om = static_cast<float>(p.albedo), inv_rmax = static_cast<float>(1.0 / rmax),
                sky_l = static_cast<float>(a.sky_distance_m);
    const sh::BrumeFog f = to_shared(a.density);
    float smax = s0;
    for (int v = 0; v < range.height; ++v)
      for (int u = 0; u < range.width; ++u) {
        const float r = range.data[static_cast<std::size_t>(v) * range.width + u];
        const bool sky = !known_range(r);
        const float l = sky ? sky_l : r;
        const float dy = a.camera_used ? ray.at(u, v) : 0.0f;
        const float F = sh::brume_fog_along(f, l, dy);
        smax = std::max(smax, sh::brume_fog_scale(s0, lam, om, F, l * inv_rmax));
      }
    if (!std::isfinite(smax))
      throw Error("the scattering blur's largest scale is not finite (the fog's optical depth overflows); lower "
                  "--density or --lambda");
    a.sigma_max = smax;
  }
  // Bounded where it is decided (brume/diffusion.hpp).
  if (p.lambda > 0.0)
    a.plan = plan_diffusion(p.diffusion, a.sigma_max, range.width, range.height,
                            "sigma0 + lambda sqrt(albedo F) l / R_max at the frame's most blurred pixel, with --lambda " +
                                text::g(p.lambda) + ", --albedo " + text::g(p.albedo) +
                                ", the fog's optical depth F (--density, --falloff, the profile) and --sigma0 " +
                                text::g(p.diffusion.sigma0) + " px: lower --lambda or the fog's density");
  return a;
}

FogResult apply_fog(DenseImageRef rgb, DenseImageRef range, const FogParams& p, const FogAnalysis& a, const Exec& exec,
                    DenseImageRef sky_weight) {
  FogResult out;
  apply_fog(rgb, range, p, a, out, exec, sky_weight);
  return out;
}

void apply_fog(DenseImageRef rgb, DenseImageRef range, const FogParams& p, const FogAnalysis& a, FogResult& out,
               const Exec& exec, DenseImageRef sky_weight) {
  detail::apply_fog_rows(rgb, range, p, a, out, exec, true, sky_weight);
}

namespace detail {

void apply_fog_rows(DenseImageRef rgb, DenseImageRef range, const FogParams& p, const FogAnalysis& a, FogResult& out,
                    const Exec& exec, bool vector_rows, DenseImageRef sky_weight) {
  const int W = rgb.width, H = rgb.height;
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const RayY ray(a.camera);
  const bool blur = p.lambda > 0.0, heights = a.camera_used;
  const float s0 = static_cast<float>(p.diffusion.sigma0), lam = static_cast<float>(p.lambda),
              om = static_cast<float>(p.albedo), inv_rmax = static_cast<float>(1.0 / a.range_max_m),
              sky_l = static_cast<float>(a.sky_distance_m);
  // The sky's transmission distance (< 0: infinity), and its blur's (sky_l).
  const float sky_t = a.sky_at_infinity ? -1.0f : sky_l;
  const bool blend = a.sky_blend && !sky_weight.empty();
  if (blend && (sky_weight.width != W || sky_weight.height != H || sky_weight.channels != 1))
    throw Error("internal: the sky weight is " + sky_weight.size_string() + ", the image " + rgb.size_string());
  const sh::BrumeFog fog = to_shared(a.density);

  auto sized = [&](Image& m, int c) {
    if (m.width != W || m.height != H || m.channels != c) m = Image(W, H, c);
  };
  sized(out.optical_depth, 1);
  sized(out.transmission, 1);
  Image sigma = blur ? Image(W, H, 1) : Image();
  if (!blur) sized(out.rgb, 3);
  // The exponential profile without blur (a renderer's per-frame fog) runs
  // as vector code (fog_fast.cpp: the same f32 maths with a polynomial e^x,
  // F within ~3e-7 relative of this loop); every other case, and an input
  // that is also the output, takes the per-pixel loop below.
  if (vector_rows && !blur && heights && fog.profile.kind == 0 && fog.profile.d0 > 0.0f && out.rgb.data.data() != rgb.data.data()) {
    detail::FogExpFrame fr;
    fr.rgb = rgb.data.data(), fr.range = range.data.data(), fr.out_rgb = out.rgb.data.data();
    fr.optical_depth = out.optical_depth.data.data(), fr.transmission = out.transmission.data.data();
    fr.width = W;
    fr.r0 = ray.r0, fr.r1 = ray.r1, fr.r2 = ray.r2, fr.cx = ray.cx, fr.cy = ray.cy, fr.ifx = ray.ifx, fr.ify = ray.ify;
    fr.d0 = fog.profile.d0, fr.falloff = fog.profile.falloff, fr.exponent_c = fog.profile.exponent_c, fr.sky_distance = sky_l;
    fr.sky_infinite = a.sky_at_infinity;
    for (int c = 0; c < 3; ++c) fr.airlight[c] = a.airlight[c];
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
    for (int v = 0; v < H; ++v) {
      detail::fog_exponential_row(fr, v);
      if (!blend) continue;
      // The horizon margin's few pixels: the per-pixel blend (brume_fog_pixel).
      for (int u = 0; u < W; ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * W + u;
        const float w = sky_weight.data[i];
        if (!(w > 0.0f) || !known_range(range.data[i])) continue;
        const float F = sh::brume_fog_pixel(fog, range.data[i], ray.at(u, v), false, sky_t, w);
        const float f = std::exp(-F);
        out.optical_depth.data[i] = F;
        out.transmission.data[i] = f;
        for (int c = 0; c < 3; ++c)
          out.rgb.data[i * 3 + c] = sh::brume_fog_composite(rgb.data[i * 3 + c], f, a.airlight[c]);
      }
    }
    return;
  }
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * W + u;
      const float r = range.data[i];
      const bool sky = !known_range(r);
      const float ry = heights ? ray.at(u, v) : 0.0f;
      const float w = blend ? sky_weight.data[i] : 0.0f;
      const float F = sh::brume_fog_pixel(fog, r, ry, sky, sky_t, w);
      const float f = std::exp(-F);
      out.optical_depth.data[i] = F;
      out.transmission.data[i] = f;
      if (blur) {
        // Sky pixels blur as at the sky distance (F over it), bounded in
        // advance; a margin pixel as at its range.
        const float l = sky ? sky_l : r;
        const float Fb = sky || w > 0.0f ? sh::brume_fog_along(fog, l, ry) : F;
        sigma.data[i] = std::min(sh::brume_fog_scale(s0, lam, om, Fb, l * inv_rmax), static_cast<float>(a.sigma_max));
      } else {
        for (int c = 0; c < 3; ++c)
          out.rgb.data[i * 3 + c] = sh::brume_fog_composite(rgb.data[i * 3 + c], f, a.airlight[c]);
      }
    }
  if (blur) {
    ScatterBlur b = scatter_blur(rgb.view(), out.transmission, sigma, a.sigma_max, p.diffusion, Composite::premultiplied,
                                 a.airlight, exec);
    out.rgb = std::move(b.rgb);
    out.transmission = std::move(b.transmission);
  }
}

}  // namespace detail

}  // namespace brume
