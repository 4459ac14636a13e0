// brume — layered fog (Zhou, Chen, Smith); the equations, units and the sky
// rule are stated in include/brume/fog.hpp, the per-pixel maths in
// src/effects/fog/fog_math.glsl. This file holds the declaration, the density
// table, the analysis step (image-wide statistics, once) and the pure apply.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "core/text.hpp"
#include "brume/fog.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "effects/fog/fog_fast.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

const EnumNames<FogProfile>& fog_profile_names() {
  static const EnumNames<FogProfile> n = {{FogProfile::exponential, "exponential"},
                                          {FogProfile::band, "band"},
                                          {FogProfile::ramp, "ramp"},
                                          {FogProfile::constant, "constant"},
                                          {FogProfile::table, "table"}};
  return n;
}
const EnumNames<ClassicFog>& classic_fog_names() {
  static const EnumNames<ClassicFog> n = {
      {ClassicFog::none, "none"}, {ClassicFog::linear, "linear"}, {ClassicFog::exp2, "exp2"}};
  return n;
}

const ParamTable<FogParams>& fog_param_table() {
  static const ParamTable<FogParams> t = [] {
    ParamTable<FogParams> d("fog");
    d.choice("profile", &FogParams::profile, fog_profile_names(),
             "height density: exponential D0 exp(-B (y - Y0)), band (Zhou's sinusoidal band), ramp (D0 below "
             "--ramp-bottom, linear to 0 at --ramp-top), constant D0, table (--table CSV, piecewise linear)")
        .real("density", &FogParams::density_per_m, "1/m", Range::at_least(0.0),
              "D0: extinction coefficient (exponential: at --base-height; band: at its centre; ramp: below its bottom)")
        .real("falloff", &FogParams::falloff_per_m, "1/m", Range::at_least(0.0),
              "B: exponential decrease of the density with height (0: constant)")
        .real("base-height", &FogParams::base_height_m, "m", Range::any(),
              "Y0: height where the exponential density equals --density")
        .real("band-center", &FogParams::band_center_m, "m", Range::any(), "Yc: height of the band's densest level")
        .real("band-half-width", &FogParams::band_half_width_m, "m", Range::above(0.0),
              "Wb: the band's density falls to 0 at Yc +- Wb")
        .real("ramp-bottom", &FogParams::ramp_bottom_m, "m", Range::any(), "height below which the ramp density is D0")
        .real("ramp-top", &FogParams::ramp_top_m, "m", Range::any(),
              "height above which the ramp density is 0 (must exceed --ramp-bottom)")
        .text("table", &FogParams::table_file,
              "CSV of rows height_m,density_per_m (heights increasing; a header line and # comments allowed): "
              "piecewise linear, end values held")
        .reads_file()
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
        .nest(&FogParams::camera, camera_pose_param_table());
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
  return p.classic == ClassicFog::none && p.profile != FogProfile::constant;
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
  const std::string prof = "--profile " + enum_name(fog_profile_names(), p.profile);
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
    if (p.profile != FogProfile::exponential)
      refuse({"falloff", "base-height"}, "is only used by --profile exponential, not " + prof);
    if (p.profile != FogProfile::band)
      refuse({"band-center", "band-half-width"}, "is only used by --profile band, not " + prof);
    if (p.profile != FogProfile::ramp) refuse({"ramp-bottom", "ramp-top"}, "is only used by --profile ramp, not " + prof);
    if (p.profile != FogProfile::table) refuse({"table"}, "is only used by --profile table, not " + prof);
    if (p.profile == FogProfile::table) {
      refuse({"density"}, "is not used by --profile table (the table gives the densities)");
      if (p.table_file.empty()) throw Error("--profile table needs --table FILE.csv (rows height_m,density_per_m)");
    }
    if (p.profile == FogProfile::ramp && !(p.ramp_top_m > p.ramp_bottom_m))
      throw Error("--ramp-top " + fog_num(p.ramp_top_m) + " must exceed --ramp-bottom " + fog_num(p.ramp_bottom_m) +
                  " m (the density falls from --density at the bottom to 0 at the top)");
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

// ---- the density table ----------------------------------------------------------------

FogTable read_fog_table(const std::string& path) {
  const std::string what = "--table '" + path + "'";
  // A regular file (brume/io.hpp) of at most 16 MiB: the table's row limit
  // below is far smaller.
  std::istringstream in(read_input_file(path, "--table", {16u << 20, "a density table of height,density rows"}));
  FogTable t;
  t.path = path;
  std::string line;
  int line_no = 0;
  bool header_allowed = true;
  while (std::getline(in, line)) {
    ++line_no;
    line = line.substr(0, line.find('#'));
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream s(line);
    std::vector<std::string> tok;
    for (std::string w; s >> w;) tok.push_back(w);
    if (tok.empty()) continue;
    double v[2] = {};
    bool numeric = tok.size() == 2;
    for (std::size_t i = 0; numeric && i < 2; ++i) {
      char* end = nullptr;
      v[i] = std::strtod(tok[i].c_str(), &end);
      numeric = end != tok[i].c_str() && *end == '\0';
    }
    if (!numeric && header_allowed) {  // one header line ("height_m,density_per_m") before the data
      header_allowed = false;
      continue;
    }
    const std::string at = what + ", line " + std::to_string(line_no);
    if (!numeric)
      throw Error(at + ": '" + line + "' is not two numbers; each row is height_m,density_per_m");
    header_allowed = false;
    if (!std::isfinite(v[0]) || !std::isfinite(v[1]))
      throw Error(at + ": height " + fog_num(v[0]) + " m, density " + fog_num(v[1]) + " /m: both must be finite numbers");
    if (v[1] < 0.0) throw Error(at + ": density " + fog_num(v[1]) + " /m is negative; densities must be >= 0");
    if (!t.height_m.empty() && !(v[0] > t.height_m.back()))
      throw Error(at + ": height " + fog_num(v[0]) + " m does not exceed the previous row's " + fog_num(t.height_m.back()) +
                  " m; heights must be strictly increasing (sort the table, remove repeated heights)");
    t.height_m.push_back(v[0]);
    t.density_per_m.push_back(v[1]);
  }
  if (t.height_m.empty()) throw Error(what + " has no rows; give rows height_m,density_per_m");
  t.sha256 = sha256_file(path);
  return t;
}

// ---- the density relative to the camera ---------------------------------------------

FogDensity fog_density(const FogParams& p, const FogTable& table, double yc) {
  FogDensity d;
  d.classic = p.classic;
  d.profile = p.profile;
  d.d0 = p.density_per_m;
  d.fog_start = p.fog_start_m;
  d.fog_end = p.fog_end_m;
  if (p.classic != ClassicFog::none) return d;
  switch (p.profile) {
    case FogProfile::exponential:
      d.falloff = p.falloff_per_m;
      d.exponent_c = -p.falloff_per_m * (yc - p.base_height_m);
      break;
    case FogProfile::band:
      d.band_offset = yc - p.band_center_m;
      d.band_half_width = p.band_half_width_m;
      break;
    case FogProfile::ramp:
      d.knot_u = {p.ramp_bottom_m - yc, p.ramp_top_m - yc};
      d.knot_density = {p.density_per_m, 0.0};
      break;
    case FogProfile::constant:
      d.knot_u = {0.0};
      d.knot_density = {p.density_per_m};
      break;
    case FogProfile::table:
      for (std::size_t i = 0; i < table.height_m.size(); ++i) {
        d.knot_u.push_back(table.height_m[i] - yc);
        d.knot_density.push_back(table.density_per_m[i]);
      }
      break;
  }
  return d;
}

double FogDensity::at(double u) const {
  switch (profile) {
    case FogProfile::exponential: return d0 * std::exp(exponent_c - falloff * u);
    case FogProfile::band: {
      const double s = u + band_offset;
      return std::abs(s) <= band_half_width ? 0.5 * d0 * (1.0 + std::cos(M_PI * s / band_half_width)) : 0.0;
    }
    default: break;
  }
  if (u <= knot_u.front()) return knot_density.front();
  if (u >= knot_u.back()) return knot_density.back();
  const std::size_t j = std::upper_bound(knot_u.begin(), knot_u.end(), u) - knot_u.begin();
  const double t = (u - knot_u[j - 1]) / (knot_u[j] - knot_u[j - 1]);
  return knot_density[j - 1] + t * (knot_density[j] - knot_density[j - 1]);
}

int FogDensity::kind() const {
  if (classic == ClassicFog::linear) return 3;
  if (classic == ClassicFog::exp2) return 4;
  if (profile == FogProfile::exponential) return 0;
  return profile == FogProfile::band ? 1 : 2;
}

namespace {

// The frame's density in the shared form (fog_math.glsl), once per image.
sh::BrumeFog to_shared(const FogDensity& d) {
  sh::BrumeFog f{};
  f.kind = d.kind();
  f.d0 = static_cast<float>(d.d0);
  f.falloff = static_cast<float>(d.falloff);
  f.exponent_c = static_cast<float>(d.exponent_c);
  f.band_offset = static_cast<float>(d.band_offset);
  f.band_half_width = static_cast<float>(d.band_half_width);
  f.fog_start = static_cast<float>(d.fog_start);
  f.fog_end = static_cast<float>(d.fog_end);
  if (d.knot_u.size() > BRUME_FOG_MAX_KNOTS)
    throw Error("the density table has " + std::to_string(d.knot_u.size()) + " rows; at most " +
                std::to_string(BRUME_FOG_MAX_KNOTS) + " are allowed (resample it)");
  f.n = static_cast<int>(d.knot_u.size());
  for (int i = 0; i < f.n; ++i) {
    f.ku[i] = static_cast<float>(d.knot_u[i]);
    f.kd[i] = static_cast<float>(d.knot_density[i]);
  }
  return f;
}

}  // namespace

float fog_optical_depth(const FogDensity& d, float l, float ray_y, bool sky, float sky_distance) {
  const sh::BrumeFog f = to_shared(d);
  return sky ? sh::brume_fog_sky(f, ray_y, sky_distance) : sh::brume_fog_along(f, l, ray_y);
}

void fog_optical_depths(const FogDensity& d, const float* range_m, const float* ray_y, float* out, std::size_t n) {
  const sh::BrumeFog f = to_shared(d);
  for (std::size_t i = 0; i < n; ++i) out[i] = sh::brume_fog_along(f, range_m[i], ray_y[i]);
}

double fog_max_density(const FogDensity& d, double u0, double u1) {
  if (u1 < u0) std::swap(u0, u1);
  double m = std::max(d.at(u0), d.at(u1));  // exponential: monotone
  if (d.profile == FogProfile::band) {
    if (u0 + d.band_offset <= 0.0 && u1 + d.band_offset >= 0.0) m = std::max(m, d.d0);  // monotone on each side
  } else if (d.profile != FogProfile::exponential) {
    for (std::size_t i = 0; i < d.knot_u.size(); ++i)
      if (d.knot_u[i] > u0 && d.knot_u[i] < u1) m = std::max(m, d.knot_density[i]);
  }
  return m;
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
    camera.require_height("--profile " + enum_name(fog_profile_names(), p.profile) +
                          " (the fog depends on height)");
    yc = camera.position_m.y;
  }
  if (p.classic == ClassicFog::none && p.profile == FogProfile::table) a.table = read_fog_table(p.table_file);
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
  if (vector_rows && !blur && heights && fog.kind == 0 && fog.d0 > 0.0f && out.rgb.data.data() != rgb.data.data()) {
    detail::FogExpFrame fr;
    fr.rgb = rgb.data.data(), fr.range = range.data.data(), fr.out_rgb = out.rgb.data.data();
    fr.optical_depth = out.optical_depth.data.data(), fr.transmission = out.transmission.data.data();
    fr.width = W;
    fr.r0 = ray.r0, fr.r1 = ray.r1, fr.r2 = ray.r2, fr.cx = ray.cx, fr.cy = ray.cy, fr.ifx = ray.ifx, fr.ify = ray.ify;
    fr.d0 = fog.d0, fr.falloff = fog.falloff, fr.exponent_c = fog.exponent_c, fr.sky_distance = sky_l;
    fr.sky_infinite = a.sky_at_infinity;
    for (int c = 0; c < 3; ++c) fr.airlight[c] = a.airlight[c];
#pragma omp parallel for num_threads(nt) schedule(static)
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
#pragma omp parallel for num_threads(nt) schedule(static)
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
