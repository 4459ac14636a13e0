// brume — height profiles of extinction: their flags, density tables, the
// density relative to a reference height and its optical depth along rays
// (brume/height_profile.hpp; the per-ray maths in src/media/height_profile.glsl).
#include "brume/height_profile.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "core/text.hpp"
#include "media/height_profile_shared.hpp"

namespace brume {
namespace sh = brume::shared;

const EnumNames<HeightProfile>& height_profile_names() {
  static const EnumNames<HeightProfile> n = {{HeightProfile::exponential, "exponential"},
                                             {HeightProfile::band, "band"},
                                             {HeightProfile::ramp, "ramp"},
                                             {HeightProfile::constant, "constant"},
                                             {HeightProfile::table, "table"}};
  return n;
}

const ParamTable<HeightProfileParams>& height_profile_param_table() {
  static const ParamTable<HeightProfileParams> t = [] {
    using P = HeightProfileParams;
    ParamTable<P> d("fog");
    d.choice("profile", &P::profile, height_profile_names(),
             "height density: exponential D0 exp(-B (y - Y0)), band (Zhou's sinusoidal band), ramp (D0 below "
             "--ramp-bottom, linear to 0 at --ramp-top), constant D0, table (--table CSV, piecewise linear)")
        .real("density", &P::density_per_m, "1/m", Range::at_least(0.0),
              "D0: extinction coefficient (exponential: at --base-height; band: at its centre; ramp: below its bottom)")
        .real("falloff", &P::falloff_per_m, "1/m", Range::at_least(0.0),
              "B: exponential decrease of the density with height (0: constant)")
        .real("base-height", &P::base_height_m, "m", Range::any(),
              "Y0: height where the exponential density equals --density")
        .real("band-center", &P::band_center_m, "m", Range::any(), "Yc: height of the band's densest level")
        .real("band-half-width", &P::band_half_width_m, "m", Range::above(0.0),
              "Wb: the band's density falls to 0 at Yc +- Wb")
        .real("ramp-bottom", &P::ramp_bottom_m, "m", Range::any(), "height below which the ramp density is D0")
        .real("ramp-top", &P::ramp_top_m, "m", Range::any(),
              "height above which the ramp density is 0 (must exceed --ramp-bottom)")
        .text("table", &P::table_file,
              "CSV of rows height_m,density_per_m (heights increasing; a header line and # comments allowed): "
              "piecewise linear, end values held")
        .reads_file();
    return d;
  }();
  return t;
}

void validate_height_profile(const HeightProfileParams& p, const std::set<std::string>& given) {
  const auto& t = height_profile_param_table();
  auto refuse = [&](std::initializer_list<const char*> names, const std::string& why) {
    for (const char* n : names)
      if (t.is_set(p, n, given)) throw Error(std::string("--") + n + " " + why);
  };
  const std::string prof = "--profile " + enum_name(height_profile_names(), p.profile);
  if (p.profile != HeightProfile::exponential)
    refuse({"falloff", "base-height"}, "is only used by --profile exponential, not " + prof);
  if (p.profile != HeightProfile::band)
    refuse({"band-center", "band-half-width"}, "is only used by --profile band, not " + prof);
  if (p.profile != HeightProfile::ramp) refuse({"ramp-bottom", "ramp-top"}, "is only used by --profile ramp, not " + prof);
  if (p.profile != HeightProfile::table) refuse({"table"}, "is only used by --profile table, not " + prof);
  if (p.profile == HeightProfile::table) {
    refuse({"density"}, "is not used by --profile table (the table gives the densities)");
    if (p.table_file.empty()) throw Error("--profile table needs --table FILE.csv (rows height_m,density_per_m)");
  }
  if (p.profile == HeightProfile::ramp && !(p.ramp_top_m > p.ramp_bottom_m))
    throw Error("--ramp-top " + text::g(p.ramp_top_m) + " must exceed --ramp-bottom " + text::g(p.ramp_bottom_m) +
                " m (the density falls from --density at the bottom to 0 at the top)");
}

const ParamTable<HeightMedium>& height_medium_param_table() {
  static const ParamTable<HeightMedium> t = [] {
    ParamTable<HeightMedium> d("fog");
    d.extend_base(height_profile_param_table()).nest(&HeightMedium::camera, camera_pose_param_table());
    return d;
  }();
  return t;
}

void validate_height_medium(const HeightMedium& m) {
  const auto& t = height_medium_param_table();
  t.validate(m);
  validate_height_profile(m);
  if (m.profile != HeightProfile::constant) return;
  for (const char* n : {"yaw", "pitch", "roll", "camera-height", "camera-x", "camera-z", "view-matrix"})
    if (t.is_set(m, n, {}))
      throw Error(std::string("--") + n + " poses the camera, but --profile constant does not depend on height; "
                  "drop it");
}

// ---- the density table ----------------------------------------------------------------

DensityTable read_density_table(const std::string& path) {
  const std::string what = "--table '" + path + "'";
  // A regular file (brume/io.hpp) of at most 16 MiB: the table's row limit
  // below is far smaller.
  std::istringstream in(read_input_file(path, "--table", {16u << 20, "a density table of height,density rows"}));
  DensityTable t;
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
      throw Error(at + ": height " + text::g(v[0]) + " m, density " + text::g(v[1]) +
                  " /m: both must be finite numbers");
    if (v[1] < 0.0) throw Error(at + ": density " + text::g(v[1]) + " /m is negative; densities must be >= 0");
    if (!t.height_m.empty() && !(v[0] > t.height_m.back()))
      throw Error(at + ": height " + text::g(v[0]) + " m does not exceed the previous row's " +
                  text::g(t.height_m.back()) +
                  " m; heights must be strictly increasing (sort the table, remove repeated heights)");
    t.height_m.push_back(v[0]);
    t.density_per_m.push_back(v[1]);
  }
  if (t.height_m.empty()) throw Error(what + " has no rows; give rows height_m,density_per_m");
  t.sha256 = sha256_file(path);
  return t;
}

// ---- the density relative to the reference height ------------------------------------

HeightDensity height_density(const HeightProfileParams& p, const DensityTable& table, double yr) {
  HeightDensity d;
  d.profile = p.profile;
  d.d0 = p.density_per_m;
  switch (p.profile) {
    case HeightProfile::exponential:
      d.falloff = p.falloff_per_m;
      d.exponent_c = -p.falloff_per_m * (yr - p.base_height_m);
      break;
    case HeightProfile::band:
      d.band_offset = yr - p.band_center_m;
      d.band_half_width = p.band_half_width_m;
      break;
    case HeightProfile::ramp:
      d.knot_u = {p.ramp_bottom_m - yr, p.ramp_top_m - yr};
      d.knot_density = {p.density_per_m, 0.0};
      break;
    case HeightProfile::constant:
      d.knot_u = {0.0};
      d.knot_density = {p.density_per_m};
      break;
    case HeightProfile::table:
      for (std::size_t i = 0; i < table.height_m.size(); ++i) {
        d.knot_u.push_back(table.height_m[i] - yr);
        d.knot_density.push_back(table.density_per_m[i]);
      }
      break;
  }
  return d;
}

double HeightDensity::at(double u) const {
  switch (profile) {
    case HeightProfile::exponential: return d0 * std::exp(exponent_c - falloff * u);
    case HeightProfile::band: {
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

int HeightDensity::kind() const {
  if (profile == HeightProfile::exponential) return 0;
  return profile == HeightProfile::band ? 1 : 2;
}

sh::BrumeProfile shared_profile(const HeightDensity& d) {
  sh::BrumeProfile f{};
  f.kind = d.kind();
  f.d0 = static_cast<float>(d.d0);
  f.falloff = static_cast<float>(d.falloff);
  f.exponent_c = static_cast<float>(d.exponent_c);
  f.band_offset = static_cast<float>(d.band_offset);
  f.band_half_width = static_cast<float>(d.band_half_width);
  if (d.knot_u.size() > BRUME_PROFILE_MAX_KNOTS)
    throw Error("the density table has " + std::to_string(d.knot_u.size()) + " rows; at most " +
                std::to_string(BRUME_PROFILE_MAX_KNOTS) + " are allowed (resample it)");
  f.n = static_cast<int>(d.knot_u.size());
  for (int i = 0; i < f.n; ++i) {
    f.ku[i] = static_cast<float>(d.knot_u[i]);
    f.kd[i] = static_cast<float>(d.knot_density[i]);
  }
  return f;
}

void height_optical_depths(const HeightDensity& d, const float* range_m, const float* ray_y, float* out,
                           std::size_t n) {
  const sh::BrumeProfile f = shared_profile(d);
  for (std::size_t i = 0; i < n; ++i) out[i] = sh::brume_profile_along(f, range_m[i], ray_y[i]);
}

double height_density_max(const HeightDensity& d, double u0, double u1) {
  if (u1 < u0) std::swap(u0, u1);
  double m = std::max(d.at(u0), d.at(u1));  // exponential: monotone
  if (d.profile == HeightProfile::band) {
    if (u0 + d.band_offset <= 0.0 && u1 + d.band_offset >= 0.0) m = std::max(m, d.d0);  // monotone on each side
  } else if (d.profile != HeightProfile::exponential) {
    for (std::size_t i = 0; i < d.knot_u.size(); ++i)
      if (d.knot_u[i] > u0 && d.knot_u[i] < u1) m = std::max(m, d.knot_density[i]);
  }
  return m;
}

}  // namespace brume
