// brume — spectral aerial perspective: the parameter declaration, the analysis
// (image-wide statistics, once) and the per-pixel apply of render, re-render
// and remove, with the optional per-channel scattering blur. The equations,
// units and conventions are stated in include/brume/aerial.hpp; the per-pixel
// formulas the GPU shares are src/effects/aerial/aerial_math.glsl.
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <type_traits>
#include <vector>

#include "brume/aerial.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "core/text.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

namespace {

const ParamTable<Atmosphere>& aerial_atmosphere_table() {
  static const ParamTable<Atmosphere> t = [] {
    // The aerial block's own fields, not a block of their own; the turbidity
    // is declared by aerial_param_table, beside its rule (--turbidity contrast).
    ParamTable<Atmosphere> d("aerial");
    d.real("altitude", &Atmosphere::altitude_m, "m", Range::closed(-500.0, 9000.0),
           "observer altitude h0 above sea level (scales beta_R by e^{-h0/7994 m}, beta_M by e^{-h0/1200 m})");
    return d;
  }();
  return t;
}

// `im` as a w x h x c image, keeping its buffer (and so its already-touched
// pages) when the size is already right; only then are its old values left
// in place, to be overwritten by the caller.
void ensure_image(Image& im, int w, int h, int c) {
  if (im.width == w && im.height == h && im.channels == c && im.data.size() == static_cast<std::size_t>(w) * h * c)
    return;
  im = Image(w, h, c);  // fresh, with the huge-page hint (brume/image.hpp)
}

// An order-preserving map of a float's bits to an unsigned integer (negative
// values reversed, -0 just below +0, NaNs beyond +-inf): integer order is the
// order nth_element sees for non-NaN values, so a k-th smallest found by
// counting keys is the very value nth_element would return.
std::uint32_t order_key(float v) {
  std::uint32_t u;
  std::memcpy(&u, &v, sizeof u);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

// Per-channel k-th smallest (k = n/2: the median nth_element gave) of the
// sky pixels, exact, without gathering and partially sorting every sky
// value per channel: a histogram of the keys' top
// 16 bits (thread-local, any order, so the pass runs in parallel), then only
// the values in the one bin holding rank k -- a smooth sky spreads over many
// bins, so that is a small fraction; a flat sky falls back to the full
// selection, never worse than before.
constexpr int kSkyBins = 1 << 16;
// [lo, hi) bounds the sky pixels (from the range scan): a sky above the land
// spares both passes the rest of the frame.
std::array<float, 3> sky_median(DenseImageRef rgb, const float* sky, std::size_t n_sky, std::ptrdiff_t lo,
                                std::ptrdiff_t hi, int nt) {
  std::vector<std::uint32_t> hist(3 * static_cast<std::size_t>(kSkyBins), 0u);
#pragma omp parallel num_threads(nt)
  {
    std::vector<std::uint32_t> h(3 * static_cast<std::size_t>(kSkyBins), 0u);
#pragma omp for schedule(dynamic, 16384) nowait
    for (std::ptrdiff_t i = lo; i < hi; ++i)
      if (sky[i] > 0.0f)
        for (int c = 0; c < 3; ++c)
          ++h[static_cast<std::size_t>(c) * kSkyBins + (order_key(rgb.data[3 * i + c]) >> 16)];
#pragma omp critical(brume_aerial_sky_hist)
    for (std::size_t b = 0; b < h.size(); ++b) hist[b] += h[b];
  }
  const std::size_t k = n_sky / 2;
  std::array<std::uint32_t, 3> bin{};
  std::array<std::size_t, 3> rank{};  // k's rank inside its bin
  for (int c = 0; c < 3; ++c) {
    std::size_t below = 0;
    std::uint32_t b = 0;
    const std::uint32_t* hc = hist.data() + static_cast<std::size_t>(c) * kSkyBins;
    while (below + hc[b] <= k) below += hc[b++];  // ends: the counts sum to n_sky > k
    bin[c] = b, rank[c] = k - below;
  }
  std::array<std::vector<float>, 3> v;
#pragma omp parallel num_threads(nt)
  {
    std::array<std::vector<float>, 3> mine;
#pragma omp for schedule(dynamic, 16384) nowait
    for (std::ptrdiff_t i = lo; i < hi; ++i)
      if (sky[i] > 0.0f)
        for (int c = 0; c < 3; ++c)
          if ((order_key(rgb.data[3 * i + c]) >> 16) == bin[c]) mine[c].push_back(rgb.data[3 * i + c]);
#pragma omp critical(brume_aerial_sky_bin)
    for (int c = 0; c < 3; ++c) v[c].insert(v[c].end(), mine[c].begin(), mine[c].end());
  }
  std::array<float, 3> m{};
  for (int c = 0; c < 3; ++c) {
    // The k-th value is the same whatever order the threads appended in.
    auto mid = v[c].begin() + static_cast<std::ptrdiff_t>(rank[c]);
    std::nth_element(v[c].begin(), mid, v[c].end());
    m[c] = *mid;
  }
  return m;
}

float aerial_luminance(const float* c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

// Per-channel median of the listed pixels.
std::array<float, 3> channel_median(DenseImageRef rgb, const std::vector<std::size_t>& px) {
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
    // auto (NaN in the struct): fitted on --sky-image by `brume aerial` (run_aerial_job) before anything runs;
    // contrast (turbidity_rule, NaN in the struct): fitted on the image by run_aerial.
    d.real_or_word("turbidity", &AerialParams::atmosphere, &Atmosphere::turbidity, &AerialParams::turbidity_rule,
                   {"contrast"}, "1", Range::closed(1.0, 20.0),
                   "atmospheric turbidity T (1: pure air; by Table 3.1 corrected: clear from about 2.7, light haze "
                   "4.5, haze 9.8, fog 19.3); auto: fitted on --sky-image; contrast (--remove, and brume insert): fitted on the image "
                   "from how its terrain's contrast falls with distance",
                   NAN)
        .nest(&AerialParams::atmosphere, aerial_atmosphere_table())
        .text("sensitivity", &AerialParams::sensitivity,
              "camera spectral sensitivities q_c(lambda): default, a CSV of wavelength_nm,r,g,b, or "
              "DATABASE.txt#CAMERA NAME")
        .reads_file("default", '#')
        .rgb_or_word("airlight", &AerialParams::airlight, &AerialParams::airlight_rule, {"horizon"}, "linear RGB",
                     Range::at_least(0.0),
                     "horizon colour Iinf; auto: the median sky colour (unknown range >= 0.5 % of the frame), else "
                     "the median of the brightest 10 % of the 1 % most distant pixels; horizon: the median of the sky "
                     "just above the farthest skyline (a photo's horizon, docs/aerial.md)")
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
        .nest(&AerialParams::diffusion, diffusion_param_table())
        .choice("path", &AerialParams::path, aerial_path_names(),
                "the light's path to each pixel: level (the coefficients at --altitude all along: the thesis, right "
                "for level paths) or slant (the air thins with height along each pixel's ray, e^{-dh/7994 m} for "
                "Rayleigh and e^{-dh/1200 m} for Mie, flat Earth, paths <= 30 km; the target's altitude from the "
                "intrinsics and --pitch/--roll, or from --target-altitude)")
        .since(4, "level")
        // The pose's orientation only: the observer's height is --altitude
        // (above sea level), not a height above fog's ground plane.
        .nest_except(&AerialParams::camera, camera_pose_param_table(), {"camera-height", "camera-x", "camera-z"});
    return d;
  }();
  return t;
}

void validate_aerial(const AerialParams& p, const std::set<std::string>& given) {
  const auto& t = aerial_param_table();
  t.validate(p);
  if (p.turbidity_rule == "contrast") {
    // The turbidity the photo shows: only a removal has a photo to measure.
    if (!p.remove)
      throw Error(std::string("--turbidity contrast fits the turbidity a photo shows, which only --remove takes "
                              "as --turbidity; ") +
                  (p.from_turbidity ? "a re-render's photo turbidity is --from-turbidity: fit it with `brume aerial "
                                      "--remove --turbidity contrast --record R.json` and give the recorded T"
                                    : "a render adds haze to a clean image: give --turbidity T") +
                  ", or add --remove");
    Atmosphere a = p.atmosphere;
    a.turbidity = 1.0;  // the altitude's check; T is fitted later
    validate_atmosphere(a);
  } else {
    if (std::isnan(p.atmosphere.turbidity))
      throw Error("--turbidity auto fits T on a photo of the sky: give --sky-image FILE (and its --sky- flags), or "
                  "--turbidity T");
    validate_atmosphere(p.atmosphere);
  }
  if (p.sensitivity.empty())
    throw Error("--sensitivity is empty; give default, a CSV file or DATABASE.txt#CAMERA NAME");
  if (p.remove && p.from_turbidity)
    throw Error("--remove recovers the clean image and --from-turbidity re-renders at another turbidity; give one "
                "of them (to re-render, drop --remove)");
  if (p.from_airlight && !p.from_turbidity)
    throw Error("--from-horizon is the photo's horizon for a re-render; it needs --from-turbidity T1");
  // By value, not by `given`: a record names every parameter.
  const CameraPose& c = p.camera;
  const char* oriented = c.pitch_deg != 0.0 ? "pitch" : c.roll_deg != 0.0 ? "roll" : c.yaw_deg != 0.0 ? "yaw"
                         : !c.view_matrix_file.empty() ? "view-matrix" : nullptr;
  if (p.path == AerialPath::level && oriented)
    throw Error(std::string("--") + oriented + " orients the camera for --path slant (the rays' elevations); "
                "--path level takes the coefficients at --altitude along every ray and would ignore it: give --path "
                "slant, or drop --" + oriented);
  if (p.remove && (p.lambda > 0.0 || t.is_set(p, "lambda", given)))
    throw Error("--lambda " + std::to_string(p.lambda) +
                " with --remove: the scattering blur cannot be undone; drop --lambda (remove uses Gamma only)");
}

AerialAnalysis analyse_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, int threads) {
  AerialAnalysis a;
  analyse_aerial(rgb, range, p, a, threads);
  return a;
}

std::array<float, 3> horizon_airlight(DenseImageRef rgb, DenseImageRef range, nlohmann::json& where) {
  const int W = range.width, H = range.height;
  constexpr int kGap = 3, kBand = 6, kAbove = 20;  // rows: skipped, taken, compared against above them
  // The skyline: per column, the topmost known pixel with sky right above it.
  std::vector<int> top(static_cast<std::size_t>(W), -1);
  std::vector<float> far;
  for (int x = 0; x < W; ++x) {
    int y = 0;
    while (y < H && !known_range(range.data[static_cast<std::size_t>(y) * W + x])) ++y;
    if (y < H && y >= kGap + kBand) {
      top[static_cast<std::size_t>(x)] = y;
      far.push_back(range.data[static_cast<std::size_t>(y) * W + x]);
    }
  }
  if (far.empty())
    throw Error("--airlight horizon: no column has sky above its land (at least " + std::to_string(kGap + kBand) +
                " rows of unknown range above the topmost known pixel); give --airlight R,G,B");
  // The farthest quarter of the skyline.
  std::vector<float> sorted = far;
  const std::size_t q = sorted.size() * 3 / 4;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(q), sorted.end());
  const float r_far = sorted[q];
  auto lum = [&](std::size_t i) { return aerial_luminance(&rgb.data[3 * i]); };
  auto sky_at = [&](int x, int y) { return !known_range(range.data[static_cast<std::size_t>(y) * W + x]); };
  std::vector<std::size_t> kept;
  std::size_t columns = 0, dark = 0, black = 0;
  std::vector<float> up;
  for (int x = 0; x < W; ++x) {
    const int y0 = top[static_cast<std::size_t>(x)];
    if (y0 < 0 || range.data[static_cast<std::size_t>(y0) * W + x] < r_far) continue;
    ++columns;
    up.clear();  // the sky higher up in this column
    for (int y = std::max(0, y0 - kGap - kBand - kAbove); y < y0 - kGap - kBand; ++y)
      if (sky_at(x, y)) up.push_back(lum(static_cast<std::size_t>(y) * W + x));
    float l_up = -INFINITY;
    if (!up.empty()) {
      std::nth_element(up.begin(), up.begin() + static_cast<std::ptrdiff_t>(up.size() / 2), up.end());
      l_up = up[up.size() / 2];
    }
    for (int y = y0 - kGap - kBand; y < y0 - kGap; ++y) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      if (!sky_at(x, y)) continue;
      const float* c = &rgb.data[3 * i];
      if (std::max({c[0], c[1], c[2]}) < 0.02f) { ++black; continue; }  // a stitch border, not sky
      if (lum(i) < l_up) { ++dark; continue; }                           // land the skyline missed
      kept.push_back(i);
    }
  }
  if (kept.size() < 16)
    throw Error("--airlight horizon: only " + std::to_string(kept.size()) + " sky pixels above the farthest skyline (" +
                std::to_string(columns) + " columns with land beyond " + text::g(r_far) + " m; " +
                std::to_string(dark) + " darker than the sky above them, " + std::to_string(black) +
                " near black) are usable; at least 16 are needed: give --airlight R,G,B");
  const std::array<float, 3> m = channel_median(rgb, kept);
  where = {{"pixels", kept.size()},
           {"columns", columns},
           {"skyline_range_min_m", r_far},
           {"rows_above_skyline", {kGap, kGap + kBand - 1}},
           {"rejected_darker_than_the_sky_above", dark},
           {"rejected_near_black", black}};
  return m;
}

namespace {

// --path slant: each pixel's dh = s slope + offset (AerialAnalysis::slant_dh),
// checked where the range is known (h1 >= -500 m, s <= 30 km), and the two
// tables over the equivalent distances every pixel reaches.
void analyse_slant(DenseImageRef range, const AerialParams& p, const AerialGeometry* geo, AerialAnalysis& a, int nt) {
  const bool from_file = geo && !geo->target_altitude.empty();
  if (!geo || (!from_file && !geo->camera))
    throw Error("--path slant needs each pixel's target altitude: give the camera's intrinsics (--fx.., --fov-x or "
                "--focal-length with --sensor-width) and its pose (--pitch, --roll), or --target-altitude FILE "
                "(metres above sea level per pixel)");
  const int W = range.width, H = range.height;
  if (from_file && (geo->target_altitude.width != W || geo->target_altitude.height != H ||
                    geo->target_altitude.channels != 1))
    throw Error(geo->target_altitude_name + " is " + geo->target_altitude.size_string() + "; it must have one channel "
                "and the image's size " + range.size_string() + " (metres above sea level per pixel)");
  const double h0 = p.atmosphere.altitude_m, scale = p.distance_scale, far_m = a.range_max_m * p.distance_scale;
  a.slant_dh = Image(W, H, 2);
  double sr_max = 0.0, sm_max = 0.0, dh_lo = INFINITY, dh_hi = -INFINITY;
  std::ptrdiff_t bad = -1;  // the first known pixel that breaks a limit
  int why = 0;              // 1: beyond 30 km, 2: below -500 m, 3: no finite target altitude
#pragma omp parallel for num_threads(nt) schedule(dynamic, 16) reduction(max : sr_max, sm_max, dh_hi) \
    reduction(min : dh_lo)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      double slope = 0.0, offset = 0.0;
      if (from_file) {
        offset = static_cast<double>(geo->target_altitude.data[i]) - h0;
      } else {
        slope = geo->camera->world_ray(x, y).y;
      }
      const float r = range.data[i];
      const bool known = known_range(r) && r >= 0.0f;
      if (!known && !std::isfinite(offset)) offset = 0.0;  // the sky of a DEM: not a target
      a.slant_dh.data[2 * i] = static_cast<float>(slope);
      a.slant_dh.data[2 * i + 1] = static_cast<float>(offset);
      const double s = known ? static_cast<double>(r) * scale : far_m;
      // The apply recomputes dh from the stored floats: the checks and the
      // grid's extent use the same values.
      const double dh = s * static_cast<double>(static_cast<float>(slope)) + static_cast<double>(static_cast<float>(offset));
      int w = 0;
      if (known && s > kSlantPathMaxM) w = 1;
      else if (known && !std::isfinite(dh)) w = 3;
      else if (known && h0 + dh < kSlantTargetMinAltitudeM) w = 2;
      if (w) {
#pragma omp critical(brume_aerial_slant_bad)
        if (bad < 0 || static_cast<std::ptrdiff_t>(i) < bad) bad = static_cast<std::ptrdiff_t>(i), why = w;
        continue;
      }
      const SlantDistances d = slant_distances(s, std::isfinite(dh) ? dh : 0.0);
      sr_max = std::max(sr_max, d.rayleigh_m), sm_max = std::max(sm_max, d.mie_m);
      if (known) dh_lo = std::min(dh_lo, dh), dh_hi = std::max(dh_hi, dh);
    }
  if (bad >= 0) {
    const std::size_t i = static_cast<std::size_t>(bad);
    const int x = static_cast<int>(i % W), y = static_cast<int>(i / W);
    const double s = static_cast<double>(range.data[i]) * scale;
    const std::string px = "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")";
    if (why == 1)
      throw Error("--path slant: " + px + " is " + text::g(s) + " m away; the flat-Earth closed form holds to " +
                  text::g(kSlantPathMaxM) + " m (beyond, the Earth's curvature lifts the path by more than 71 m): "
                  "use --path level for this image, or crop it to nearer land");
    const double dh = s * a.slant_dh.data[2 * i] + a.slant_dh.data[2 * i + 1];
    if (why == 3)
      throw Error(geo->target_altitude_name + " has no finite altitude at " + px + ", where the range is known (" +
                  text::g(s) + " m); give every target pixel its altitude in metres above sea level");
    throw Error("--path slant: " + px + " at " + text::g(s) + " m lies at " + text::g(h0 + dh) +
                " m above sea level" + (from_file ? " (" + geo->target_altitude_name + ")" :
                " (--altitude " + text::g(h0) + " m, its ray's elevation from --pitch/--roll and the intrinsics)") +
                ", below the model's " + text::g(kSlantTargetMinAltitudeM) + " m; check " +
                (from_file ? geo->target_altitude_name + "'s units (metres above sea level)" :
                 "--altitude, --pitch and the intrinsics (a ray pointing too far down)"));
  }
  const double guard = 1e-3;  // [m] a grid for a scene of zero depth still has a cell
  a.slant_gamma = slant_attenuation_table(p.atmosphere, a.sensitivity, std::max(sr_max, guard), std::max(sm_max, guard),
                                          kSlantSamples, kSlantSamples, nt);
  if (p.from_turbidity) {
    Atmosphere from = p.atmosphere;
    from.turbidity = *p.from_turbidity;
    a.slant_gamma_from = slant_attenuation_table(from, a.sensitivity, std::max(sr_max, guard),
                                                 std::max(sm_max, guard), kSlantSamples, kSlantSamples, nt);
  }
  a.slant_record = {
      {"target_altitude", from_file ? "per pixel from " + geo->target_altitude_name
                                    : std::string("h0 + s sin(elevation of the pixel's ray): the intrinsics and the pose")},
      {"dh_min_m", std::isfinite(dh_lo) ? nlohmann::json(dh_lo) : nlohmann::json()},
      {"dh_max_m", std::isfinite(dh_hi) ? nlohmann::json(dh_hi) : nlohmann::json()},
      {"scale_heights_m", {{"rayleigh", kRayleighScaleHeightM}, {"mie", kMieScaleHeightM}}},
      {"optical_depth", "beta(h0) s (1 - e^{-dh/H})/dh*H, flat Earth (docs/aerial.md)"},
      {"gamma_table", {{"nodes", {kSlantSamples, kSlantSamples}},
                       {"rayleigh_distance_max_m", std::max(sr_max, guard)},
                       {"mie_distance_max_m", std::max(sm_max, guard)},
                       {"interpolation", "bilinear in ln Gamma; beyond the grid its edge"}}}};
}

}  // namespace

void analyse_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, AerialAnalysis& a, int threads,
                    const AerialGeometry* geo) {
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  validate_aerial(p);
  if (!p.turbidity_rule.empty())
    throw Error("--turbidity " + p.turbidity_rule + " is fitted before the analysis: run_aerial (brume "
                "aerial, brume.aerial) does it; a library caller fits it with fit_turbidity_contrast and gives the "
                "fitted T");
  if (rgb.channels != 3)
    throw Error("aerial needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  if (range.channels != 1) throw Error("the range map must have one channel");
  if (rgb.width != range.width || rgb.height != range.height)
    throw Error("range map " + range.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the range map, or crop both)");

  {
    Image sky = std::move(a.sky);  // the one buffer worth keeping; every other field starts afresh
    a = AerialAnalysis{};
    a.sky = std::move(sky);
  }
  a.mode = p.remove ? AerialMode::remove : (p.from_turbidity ? AerialMode::rerender : AerialMode::render);
  ensure_image(a.sky, range.width, range.height, 1);
  const std::ptrdiff_t npx = static_cast<std::ptrdiff_t>(range.pixels());
  float rmax = 0.0f, rmin = INFINITY;
  std::size_t unknown = 0;
  std::ptrdiff_t first_negative = npx;  // the first (in scan order) negative range, for the error
  std::ptrdiff_t sky_lo = npx, sky_hi = 0;  // [first, last + 1) unknown pixel, for the sky median
  // Dynamic chunks: on a shared host one preempted thread would otherwise
  // hold up the whole pass (the same choice as apply_aerial's rows).
#pragma omp parallel for num_threads(nt) schedule(dynamic, 65536) reduction(max : rmax, sky_hi) \
    reduction(min : rmin, first_negative, sky_lo) reduction(+ : unknown)
  for (std::ptrdiff_t i = 0; i < npx; ++i) {
    const float r = range.data[i];
    const bool known = known_range(r);
    a.sky.data[i] = known ? 0.0f : 1.0f;  // every pixel: the buffer may hold a previous frame's mask
    if (!known) {
      ++unknown;
      sky_lo = std::min(sky_lo, i), sky_hi = std::max(sky_hi, i + 1);
    } else if (r < 0.0f) {
      first_negative = std::min(first_negative, i);
    } else {
      rmax = std::max(rmax, r);
      rmin = std::min(rmin, r);
    }
  }
  if (first_negative < npx) {
    const std::size_t i = static_cast<std::size_t>(first_negative);
    std::ostringstream m;
    m << "range map pixel (" << i % range.width << ", " << i / range.width << ") is " << range.data[i]
      << " m; ranges must be >= 0 (0, NaN and inf mark unknown pixels)";
    throw Error(m.str());
  }
  a.unknown_pixels = unknown;
  if (unknown == range.pixels()) throw Error("the range map has no known value (every pixel is NaN, inf or 0)");
  if (!(rmax > 0.0f)) throw Error("every known range is 0 m; aerial perspective needs distances in metres");
  a.range_max_m = rmax;
  a.range_min_m = rmin;

  a.sensitivity = load_sensitivity(p.sensitivity);
  const double s_max = a.range_max_m * p.distance_scale;
  a.gamma = attenuation_table(p.atmosphere, a.sensitivity, s_max, kAttenuationSamples, nt);
  if (p.from_turbidity) {
    Atmosphere from = p.atmosphere;
    from.turbidity = *p.from_turbidity;
    a.gamma_from = attenuation_table(from, a.sensitivity, s_max, kAttenuationSamples, nt);
  }
  if (p.path == AerialPath::slant) analyse_slant(range, p, geo, a, nt);

  // kappa_s' for haze's sigma law: the optical depth at the far end at 550 nm.
  a.beta_550_per_m = rayleigh_beta_per_m(550.0, p.atmosphere.altitude_m) +
                     mie_beta_per_m(550.0, p.atmosphere.turbidity, p.atmosphere.altitude_m);
  a.kappa_s = a.beta_550_per_m * s_max;
  a.sigma_max = sh::brume_sigma_max(static_cast<float>(p.diffusion.sigma0), static_cast<float>(p.lambda),
                                    static_cast<float>(a.kappa_s));
  // Bounded where it is decided (brume/diffusion.hpp).
  a.plan = plan_diffusion(p.diffusion, a.sigma_max, rgb.width, rgb.height,
                          "sigma0 + lambda sqrt(kappa_s), kappa_s the optical depth at 550 nm to R_max, with --lambda " +
                              text::g(p.lambda) + ", --turbidity " + text::g(p.atmosphere.turbidity) + ", R_max " +
                              text::g(a.range_max_m) + " m (the range map's farthest known pixel), --distance-scale " +
                              text::g(p.distance_scale) + " and --sigma0 " + text::g(p.diffusion.sigma0) +
                              " px: lower --lambda");

  std::array<float, 3> estimated{};
  std::string estimated_source;
  if (!p.airlight || (a.mode == AerialMode::rerender && !p.from_airlight)) {
    if (p.airlight_rule == "horizon") {
      estimated = horizon_airlight(rgb, range, a.airlight_where);
      estimated_source = "per-channel median of the sky just above the farthest skyline (--airlight horizon)";
    } else if (a.unknown_pixels >= std::max<std::size_t>(1, rgb.pixels() / 200)) {
      estimated = sky_median(rgb, a.sky.data.data(), a.unknown_pixels, sky_lo, sky_hi, nt);
      estimated_source = "per-channel median of the unknown-range (sky) pixels";
    } else {
      // The thesis' "brightest pixels near the horizon": the 1 % most distant
      // known pixels, then the brightest 10 % of those by aerial_luminance.
      std::vector<std::size_t> known;
      known.reserve(range.pixels() - a.unknown_pixels);
      for (std::size_t i = 0; i < range.pixels(); ++i)
        if (a.sky.data[i] == 0.0f) known.push_back(i);
      const std::size_t nfar = std::max<std::size_t>(1, known.size() / 100);
      std::nth_element(known.begin(), known.begin() + static_cast<std::ptrdiff_t>(nfar - 1), known.end(),
                       [&](std::size_t i, std::size_t j) { return range.data[i] > range.data[j]; });
      std::vector<std::size_t> far(known.begin(), known.begin() + static_cast<std::ptrdiff_t>(nfar));
      const std::size_t nb = std::max<std::size_t>(1, far.size() / 10);
      std::nth_element(far.begin(), far.begin() + static_cast<std::ptrdiff_t>(nb - 1), far.end(),
                       [&](std::size_t i, std::size_t j) {
                         return aerial_luminance(&rgb.data[i * 3]) > aerial_luminance(&rgb.data[j * 3]);
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
}

namespace {

// What the per-pixel pass needs, fixed for the frame.
struct Frame {
  const DenseImageRef* rgb;
  const DenseImageRef* range;
  const float* sky;  // the analysis' mask, or null
  const AttenuationTable* gamma;
  const AttenuationTable* gamma_from;
  double distance_scale, far_m, inv_step, inv_step_from;
  float s0, smax, inv_rmax, floor_g;
  std::array<float, 3> A, A1;  // Iinf (Iinf2), Iinf1 in the sensitivity's space
  int W;
  // --path slant (null: level): dh per pixel and the tables over (s_R, s_M).
  const float* slant_dh;
  const SlantAttenuationTable *slant, *slant_from;
  double inv_step_r, inv_step_m;
};

// Where one row writes: out_rgb (fused) or f (the blur's six channels), and
// the maps a caller asked for (null: skipped).
struct RowOut {
  float* rgb;    // 3 channels, fused only
  float* att;    // 3 channels or null, fused only
  float* scale;  // 1 channel or null
  float* f;      // 6 channels, blur only
};

// One row of the per-pixel pass, the mode and space fixed at compile time so
// that the inner loops carry no branch on them. Gamma is AttenuationTable::at
// split in two: log_at per pixel (the table's gather), then exp_f over the
// row's 3 W values as one vector loop (the same operations, bit for bit).
// Fused (no blur): the image and the attenuation map are written directly, with the
// same operations the composite pass applies to F, so the result is the one
// the six-channel route gives without diffusion. Else F = (rho E', rho) for
// the diffusion.
// flatten: inline every call (GCC left AttenuationTable::log_at as a call per
// pixel returning its array through registers: 4.5 % of the single-thread
// steady-state profile by itself, plus the spills around it).
template <AerialMode M, bool Xyz>
[[gnu::flatten]] std::size_t aerial_row(const Frame& fr, int y, float* lg, float* lg1, unsigned char* skyrow,
                                        bool fused, const RowOut& out) {
  const int W = fr.W;
  const std::size_t row0 = static_cast<std::size_t>(y) * W;
  const float* range = fr.range->data.data() + row0;
  if (out.scale)
    for (int x = 0; x < W; ++x) {
      const float r = range[x];
      out.scale[row0 + x] = sh::brume_target_scale(known_range(r) ? r * fr.inv_rmax : 1.0f, fr.s0, fr.smax);
    }
  for (int x = 0; x < W; ++x) {
    const float r = range[x];
    const bool known = known_range(r);
    skyrow[x] = (fr.sky && fr.sky[row0 + x] > 0.0f) || !known;
    // Unknown here (preparation off) is sky at the far end, as haze does.
    const double s = known ? static_cast<double>(r) * fr.distance_scale : fr.far_m;
    if (fr.slant_dh) {
      // The slant path: dh from the analysis' slope and offset (as it checked
      // them), the equivalent distances in double, the grid's cells in f32.
      const float* g = fr.slant_dh + 2 * (row0 + x);
      const double dh = s * static_cast<double>(g[0]) + static_cast<double>(g[1]);
      const SlantDistances d = slant_distances(s, std::isfinite(dh) ? dh : 0.0);
      const float tr = static_cast<float>(d.rayleigh_m * fr.inv_step_r), tm = static_cast<float>(d.mie_m * fr.inv_step_m);
      const std::array<float, 3> l = fr.slant->log_at(tr, tm);
      lg[3 * x] = l[0], lg[3 * x + 1] = l[1], lg[3 * x + 2] = l[2];
      if constexpr (M == AerialMode::rerender) {
        const std::array<float, 3> l1 = fr.slant_from->log_at(tr, tm);
        lg1[3 * x] = l1[0], lg1[3 * x + 1] = l1[1], lg1[3 * x + 2] = l1[2];
      }
      continue;
    }
    const std::array<float, 3> l = fr.gamma->log_at(AttenuationTable::cell(s, fr.inv_step));
    lg[3 * x] = l[0], lg[3 * x + 1] = l[1], lg[3 * x + 2] = l[2];
    if constexpr (M == AerialMode::rerender) {
      const std::array<float, 3> l1 = fr.gamma_from->log_at(AttenuationTable::cell(s, fr.inv_step_from));
      lg1[3 * x] = l1[0], lg1[3 * x + 1] = l1[1], lg1[3 * x + 2] = l1[2];
    }
  }
  for (int k = 0; k < 3 * W; ++k) lg[k] = AttenuationTable::exp_f(lg[k]);
  if constexpr (M == AerialMode::rerender)
    for (int k = 0; k < 3 * W; ++k) lg1[k] = AttenuationTable::exp_f(lg1[k]);

  const float* in = fr.rgb->data.data() + 3 * row0;
  // The pixel loop with the output layout fixed at compile time and the sky
  // as a select instead of a branch (the sky's output is computed and thrown
  // away), so that the compiler may vectorise it; the arithmetic per output
  // value is unchanged, so are the bits.
  auto pass = [&](auto fused_c, auto att_c) {
    constexpr bool kFused = decltype(fused_c)::value, kAtt = decltype(att_c)::value;
    std::size_t floored = 0;
    for (int x = 0; x < W; ++x) {
      const std::size_t i = row0 + x;
      const bool sky = skyrow[x] != 0;
      const float* px = in + 3 * x;
      std::array<float, 3> e = {px[0], px[1], px[2]};
      if constexpr (Xyz)
        e = {sh::brume_srgb_to_x(px[0], px[1], px[2]), sh::brume_srgb_to_y(px[0], px[1], px[2]),
             sh::brume_srgb_to_z(px[0], px[1], px[2])};
      const float* g = lg + 3 * x;
      std::array<float, 3> fc{}, rho{};
      if constexpr (M == AerialMode::render) {
        for (int c = 0; c < 3; ++c) rho[c] = g[c], fc[c] = g[c] * e[c];
      } else if constexpr (M == AerialMode::rerender) {
        const float* g1 = lg1 + 3 * x;
        floored += !sky && (g1[0] < fr.floor_g || g1[1] < fr.floor_g || g1[2] < fr.floor_g) ? 1 : 0;
        for (int c = 0; c < 3; ++c) {
          rho[c] = sh::brume_aerial_rerender_rho(g[c], g1[c], fr.floor_g);
          fc[c] = rho[c] * sh::brume_aerial_rerender_radiance(e[c], fr.A[c], fr.A1[c]);
        }
      } else {
        floored += !sky && (g[0] < fr.floor_g || g[1] < fr.floor_g || g[2] < fr.floor_g) ? 1 : 0;
        for (int c = 0; c < 3; ++c)
          rho[c] = g[c], fc[c] = sh::brume_aerial_remove(e[c], g[c], fr.A[c], fr.floor_g);  // the result itself
      }
      if constexpr (!kFused) {
        for (int c = 0; c < 3; ++c) out.f[i * 6 + c] = fc[c], out.f[i * 6 + 3 + c] = rho[c];
      } else {
        std::array<float, 3> v{};
        for (int c = 0; c < 3; ++c)
          v[c] = M == AerialMode::remove ? fc[c] : sh::brume_composite_premultiplied(fc[c], rho[c], fr.A[c]);
        if constexpr (Xyz)
          v = {sh::brume_xyz_to_r(v[0], v[1], v[2]), sh::brume_xyz_to_g(v[0], v[1], v[2]),
               sh::brume_xyz_to_b(v[0], v[1], v[2])};
        if constexpr (kAtt)
          for (int c = 0; c < 3; ++c) out.att[3 * i + c] = sky ? 1.0f : rho[c];
        // The sky already is the horizon: unchanged, bit for bit (px may be
        // the output itself, in place: each value is read before its store).
        float* o = out.rgb + 3 * i;
        for (int c = 0; c < 3; ++c) o[c] = sky ? px[c] : v[c];
      }
    }
    return floored;
  };
  using T = std::true_type;
  using F = std::false_type;
  if (!fused) return pass(F{}, F{});
  return out.att ? pass(T{}, T{}) : pass(T{}, F{});
}

template <AerialMode M>
std::size_t aerial_row_space(bool xyz, const Frame& fr, int y, float* lg, float* lg1, unsigned char* skyrow,
                             bool fused, const RowOut& out) {
  return xyz ? aerial_row<M, true>(fr, y, lg, lg1, skyrow, fused, out)
             : aerial_row<M, false>(fr, y, lg, lg1, skyrow, fused, out);
}

}  // namespace

std::array<float, 3> aerial_working_colour(const AerialAnalysis& a, const std::array<float, 3>& c) {
  if (a.sensitivity.space != SensitivitySpace::xyz) return c;
  return {sh::brume_srgb_to_x(c[0], c[1], c[2]), sh::brume_srgb_to_y(c[0], c[1], c[2]),
          sh::brume_srgb_to_z(c[0], c[1], c[2])};
}

int aerial_mode_index(AerialMode m) { return m == AerialMode::render ? 0 : (m == AerialMode::rerender ? 1 : 2); }

AerialResult apply_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, const AerialAnalysis& a,
                          const Exec& exec) {
  AerialResult out;
  out.floored_pixels = apply_aerial(rgb, range, p, a, out.rgb, AerialMaps{&out.attenuation, &out.scale}, exec);
  return out;
}

std::size_t apply_aerial(DenseImageRef rgb, DenseImageRef range, const AerialParams& p, const AerialAnalysis& a,
                         Image& out, const AerialMaps& maps, const Exec& exec) {
  const int W = rgb.width, H = rgb.height;
  if (range.width != W || range.height != H || range.channels != 1 || rgb.channels != 3)
    throw Error("aerial: range map " + range.size_string() + " does not match image " + rgb.size_string());
  if (!a.sky.data.empty() && (a.sky.width != W || a.sky.height != H))
    throw Error("aerial: the analysis was made for another image size (" + a.sky.size_string() + ")");
  // Resizing a map that is an input would destroy the input mid-pass. The
  // inputs are references to pixels (an Image's or a caller's buffer), so
  // "is the same image" means "holds the same pixels".
  auto holds = [](const Image* m, DenseImageRef r) { return !r.empty() && m->data.data() == r.data.data(); };
  for (const Image* m : {maps.attenuation, maps.scale})
    if (m && (holds(m, rgb) || holds(m, range) || m == &out || m == &a.sky))
      throw Error("aerial: an output map is also the image, the range, the output or the sky mask; give each "
                  "map its own Image");
  if (holds(&out, range) || &out == &a.sky || (maps.attenuation && maps.attenuation == maps.scale))
    throw Error("aerial: the output image is also the range or the sky mask, or both maps are one Image; give "
                "each output its own Image (only out = rgb, in place, is allowed)");
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const bool xyz = a.sensitivity.space == SensitivitySpace::xyz;
  Frame fr{};
  fr.rgb = &rgb, fr.range = &range, fr.sky = a.sky.data.empty() ? nullptr : a.sky.data.data();
  fr.gamma = &a.gamma, fr.gamma_from = &a.gamma_from;
  fr.distance_scale = p.distance_scale, fr.far_m = a.range_max_m * p.distance_scale;
  fr.inv_step = 1.0 / a.gamma.step_m;
  fr.inv_step_from = a.mode == AerialMode::rerender ? 1.0 / a.gamma_from.step_m : 0.0;
  fr.s0 = static_cast<float>(p.diffusion.sigma0), fr.smax = static_cast<float>(a.sigma_max);
  fr.inv_rmax = static_cast<float>(1.0 / a.range_max_m), fr.floor_g = static_cast<float>(p.gamma_floor);
  fr.A = aerial_working_colour(a, a.airlight), fr.A1 = aerial_working_colour(a, a.from_airlight), fr.W = W;
  fr.slant_dh = nullptr, fr.slant = &a.slant_gamma, fr.slant_from = &a.slant_gamma_from;
  fr.inv_step_r = fr.inv_step_m = 0.0;
  if (p.path == AerialPath::slant) {
    if (a.slant_dh.width != W || a.slant_dh.height != H || a.slant_gamma.log_gamma.empty() ||
        (a.mode == AerialMode::rerender && a.slant_gamma_from.log_gamma.empty()))
      throw Error("aerial: --path slant, but the analysis holds no slant tables for this image (analyse it with "
                  "--path slant and the geometry)");
    fr.slant_dh = a.slant_dh.data.data();
    fr.inv_step_r = 1.0 / a.slant_gamma.step_r_m, fr.inv_step_m = 1.0 / a.slant_gamma.step_m_m;
  }
  const bool blur = a.plan.iterations > 0 && a.mode != AerialMode::remove;

  // Outputs only where asked for; the blur needs sigma and F (rho E', rho)
  // whether or not the caller keeps sigma. Without the blur the pass
  // composites directly. `out` is sized after the blur's F is made from rgb
  // (it may be rgb itself).
  Image scale_tmp;
  Image* scale = maps.scale ? maps.scale : (blur ? &scale_tmp : nullptr);
  if (scale) ensure_image(*scale, W, H, 1);
  if (maps.attenuation) ensure_image(*maps.attenuation, W, H, 3);
  ensure_image(out, W, H, 3);
  Image f = blur ? Image(W, H, 6) : Image();
  const RowOut ro{out.data.data(), maps.attenuation ? maps.attenuation->data.data() : nullptr,
                  scale ? scale->data.data() : nullptr, blur ? f.data.data() : nullptr};
  std::size_t floored = 0;
  // Rows in dynamic chunks of 16 (70 for 1120 rows): on a shared host a
  // preempted thread then delays its chunk, not half the frame, and on an
  // idle one the scheduling costs one atomic per 16 rows.
#pragma omp parallel num_threads(nt) reduction(+ : floored)
  {
    std::vector<float> lg(3 * static_cast<std::size_t>(W)), lg1(a.mode == AerialMode::rerender ? lg.size() : 0);
    std::vector<unsigned char> skyrow(static_cast<std::size_t>(W));
#pragma omp for schedule(dynamic, 16)
    for (int y = 0; y < H; ++y) {
      switch (a.mode) {
        case AerialMode::render:
          floored += aerial_row_space<AerialMode::render>(xyz, fr, y, lg.data(), lg1.data(), skyrow.data(), !blur, ro);
          break;
        case AerialMode::rerender:
          floored += aerial_row_space<AerialMode::rerender>(xyz, fr, y, lg.data(), lg1.data(), skyrow.data(), !blur, ro);
          break;
        case AerialMode::remove:
          floored += aerial_row_space<AerialMode::remove>(xyz, fr, y, lg.data(), lg1.data(), skyrow.data(), !blur, ro);
          break;
      }
    }
  }
  if (!blur) return floored;

  diffuse(f, *scale, a.sigma_max, p.diffusion, exec);
  const std::array<float, 3> A = fr.A;
  float* att = maps.attenuation ? maps.attenuation->data.data() : nullptr;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 16)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const bool sky = (!a.sky.data.empty() && a.sky.data[i] > 0.0f) || !known_range(range.data[i]);
      if (sky) {  // the sky already is the horizon: unchanged, bit for bit
        for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = rgb.data[i * 3 + c];
        if (att)
          for (int c = 0; c < 3; ++c) att[i * 3 + c] = 1.0f;
        continue;
      }
      std::array<float, 3> o{};
      for (int c = 0; c < 3; ++c) {
        const float fc = f.data[i * 6 + c], alpha = f.data[i * 6 + 3 + c];
        o[c] = sh::brume_composite_premultiplied(fc, alpha, A[c]);  // remove never blurs
        if (att) att[i * 3 + c] = alpha;
      }
      if (xyz)
        o = {sh::brume_xyz_to_r(o[0], o[1], o[2]), sh::brume_xyz_to_g(o[0], o[1], o[2]),
             sh::brume_xyz_to_b(o[0], o[1], o[2])};
      for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = o[c];
    }
  return floored;
}

}  // namespace brume
