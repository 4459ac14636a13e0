// brume — the turbidity a photograph shows (--turbidity contrast, issue #59):
// T fitted from how the terrain's contrast falls with distance. The model and
// its assumptions are stated in include/brume/aerial.hpp (TurbidityContrastFit)
// and docs/aerial.md ("The turbidity the photo shows").
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "brume/aerial.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "core/text.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

namespace {

// One distance bin's sums over its pairs.
struct ContrastBin {
  double pairs = 0, s_rayleigh = 0, s_mie = 0, distance = 0;
  std::array<double, 3> abs_diff{};
  void add(const ContrastBin& o) {
    pairs += o.pairs, s_rayleigh += o.s_rayleigh, s_mie += o.s_mie, distance += o.distance;
    for (int c = 0; c < 3; ++c) abs_diff[c] += o.abs_diff[c];
  }
};

struct Excluded {
  std::size_t depth_edge = 0, clipped = 0, dark = 0;
};

// The least-squares misfit of ln contrast = a_c + ln Gamma_c(bin; T) over the
// bins in `use` (a_c, the scene's own contrast per channel, eliminated: the
// mean residual per channel).
double misfit(const std::vector<std::array<double, 3>>& y, const std::vector<std::array<double, 3>>& ln_gamma,
              const std::vector<char>& use) {
  double e = 0.0;
  for (int c = 0; c < 3; ++c) {
    double mean = 0.0;
    int n = 0;
    for (std::size_t b = 0; b < y.size(); ++b)
      if (use[b]) mean += y[b][c] - ln_gamma[b][c], ++n;
    mean /= n;
    for (std::size_t b = 0; b < y.size(); ++b)
      if (use[b]) {
        const double r = y[b][c] - ln_gamma[b][c] - mean;
        e += r * r;
      }
  }
  return e;
}

}  // namespace

TurbidityContrastFit fit_turbidity_contrast(DenseImageRef rgb, DenseImageRef range, const AerialParams& p,
                                            const AerialGeometry* geo, int threads) {
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  if (rgb.channels != 3) throw Error("--turbidity contrast needs an RGB image, got " + std::to_string(rgb.channels) +
                                     " channels");
  if (range.channels != 1 || range.width != rgb.width || range.height != rgb.height)
    throw Error("--turbidity contrast: the range map " + range.size_string() + " must have one channel and the "
                "image's size " + rgb.size_string());
  const int W = rgb.width, H = rgb.height;
  const bool slant = p.path == AerialPath::slant;
  const bool from_file = slant && geo && !geo->target_altitude.empty();
  if (slant && (!geo || (!from_file && !geo->camera)))
    throw Error("--path slant needs each pixel's target altitude: give the camera's intrinsics and its pose "
                "(--pitch, --roll), or --target-altitude FILE");
  const SpectralSensitivity q = load_sensitivity(p.sensitivity);
  const bool xyz = q.space == SensitivitySpace::xyz;

  // Clipping: a channel whose brightest value is a plateau (at least 0.1 %
  // of the pixels, 16 at least, at exactly that value: snow or a sky edge at
  // the sensor's or the encoding's maximum) did not record contrast there;
  // pixels within 0.1 % of the plateau are left out. Without a plateau (a
  // float render whose far land approaches the airlight) nothing is, since a
  // cut by value would leave a biased sample of the far land's texture.
  std::array<float, 3> top{};
  std::array<std::size_t, 3> at_top{};
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) {
      const float v = rgb.data[3 * i + c];
      if (!std::isfinite(v)) continue;
      if (v > top[c]) top[c] = v, at_top[c] = 0;
      if (v == top[c]) ++at_top[c];
    }
  std::array<float, 3> clip{};
  for (int c = 0; c < 3; ++c)
    clip[c] = at_top[c] >= std::max<std::size_t>(16, rgb.pixels() / 1000) ? kContrastClippedFraction * top[c]
                                                                          : INFINITY;

  // Distance bins, log-spaced from the nearest to the farthest known range.
  float rmin = INFINITY, rmax = 0.0f;
  for (std::size_t i = 0; i < range.pixels(); ++i) {
    const float r = range.data[i];
    if (known_range(r) && r > 0.0f) rmin = std::min(rmin, r), rmax = std::max(rmax, r);
  }
  if (!(rmax > 0.0f)) throw Error("--turbidity contrast: the range map has no known distance to measure contrast at");
  const double s_lo = static_cast<double>(rmin) * p.distance_scale, s_hi = static_cast<double>(rmax) * p.distance_scale;
  const double step = std::log(kContrastBinRatio);
  const int nb = std::max(1, static_cast<int>(std::ceil(std::log(s_hi / s_lo) / step)) + 1);

  std::vector<ContrastBin> bins(static_cast<std::size_t>(nb));
  Excluded ex;
#pragma omp parallel num_threads(nt)
  {
    std::vector<ContrastBin> mine(static_cast<std::size_t>(nb));
    Excluded e;
    auto working = [&](std::size_t i) -> std::array<double, 3> {
      const float* c = &rgb.data[3 * i];
      if (!xyz) return {c[0], c[1], c[2]};
      return {sh::brume_srgb_to_x(c[0], c[1], c[2]), sh::brume_srgb_to_y(c[0], c[1], c[2]),
              sh::brume_srgb_to_z(c[0], c[1], c[2])};
    };
    auto usable = [&](std::size_t i) {
      const float* c = &rgb.data[3 * i];
      for (int k = 0; k < 3; ++k) {
        if (!(c[k] > 0.0f)) return 1;  // a crushed shadow or a stitch border: no contrast left
        if (c[k] >= clip[k]) return 2;
      }
      return 0;
    };
#pragma omp for schedule(dynamic, 8)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        const float ri = range.data[i];
        if (!known_range(ri) || ri <= 0.0f) continue;
        const std::size_t next[2] = {x + 1 < W ? i + 1 : i, y + 1 < H ? i + W : i};
        for (std::size_t j : next) {
          if (j == i) continue;
          const float rj = range.data[j];
          if (!known_range(rj) || rj <= 0.0f) continue;
          if (std::fabs(ri - rj) > kContrastSameSurface * std::max(ri, rj)) {
            ++e.depth_edge;
            continue;
          }
          const int ui = usable(i), uj = usable(j);
          if (ui || uj) {
            (ui == 2 || uj == 2 ? e.clipped : e.dark) += 1;
            continue;
          }
          const double s = 0.5 * (static_cast<double>(ri) + static_cast<double>(rj)) * p.distance_scale;
          SlantDistances d{s, s};
          if (slant) {
            const double dh = from_file ? 0.5 * (static_cast<double>(geo->target_altitude.data[i]) +
                                                 static_cast<double>(geo->target_altitude.data[j])) -
                                              p.atmosphere.altitude_m
                                        : s * geo->camera->world_ray(x, y).y;
            if (!std::isfinite(dh)) continue;
            d = slant_distances(s, dh);
          }
          const int b = std::clamp(static_cast<int>(std::floor(std::log(s / s_lo) / step)), 0, nb - 1);
          const auto a = working(i), c = working(j);
          ContrastBin& bin = mine[static_cast<std::size_t>(b)];
          bin.pairs += 1, bin.distance += s, bin.s_rayleigh += d.rayleigh_m, bin.s_mie += d.mie_m;
          for (int k = 0; k < 3; ++k) bin.abs_diff[k] += std::fabs(a[k] - c[k]);
        }
      }
#pragma omp critical(brume_aerial_contrast)
    {
      for (int b = 0; b < nb; ++b) bins[static_cast<std::size_t>(b)].add(mine[static_cast<std::size_t>(b)]);
      ex.depth_edge += e.depth_edge, ex.clipped += e.clipped, ex.dark += e.dark;
    }
  }

  // The bins that count, their mean distances and ln contrast.
  std::vector<ContrastBin> used;
  std::vector<std::array<double, 3>> y;
  std::size_t pairs = 0;
  for (const ContrastBin& b : bins) {
    if (b.pairs < kContrastMinPairs) continue;
    bool positive = true;
    for (int c = 0; c < 3; ++c) positive = positive && b.abs_diff[c] > 0.0;
    if (!positive) continue;  // a flat bin (one colour): no contrast to compare
    ContrastBin m = b;
    m.distance /= b.pairs, m.s_rayleigh /= b.pairs, m.s_mie /= b.pairs;
    std::array<double, 3> l{};
    for (int c = 0; c < 3; ++c) m.abs_diff[c] /= b.pairs, l[c] = std::log(m.abs_diff[c]);
    used.push_back(m);
    y.push_back(l);
    pairs += static_cast<std::size_t>(b.pairs);
  }
  // The floor: a bin whose contrast in a channel is below kContrastFloor of
  // that channel's highest bin is left out (an 8-bit photo's quantisation and
  // compression noise, ~1/255, is much of what is measured there; a float
  // render's far land is at the airlight to f32's last bits).
  std::size_t below_floor = 0;
  {
    std::array<double, 3> best{};
    for (const ContrastBin& b : used)
      for (int c = 0; c < 3; ++c) best[c] = std::max(best[c], b.abs_diff[c]);
    std::vector<ContrastBin> kept;
    std::vector<std::array<double, 3>> ky;
    pairs = 0;
    for (std::size_t k = 0; k < used.size(); ++k) {
      bool above = true;
      for (int c = 0; c < 3; ++c) above = above && used[k].abs_diff[c] >= kContrastFloor * best[c];
      if (!above) {
        ++below_floor;
        continue;
      }
      kept.push_back(used[k]), ky.push_back(y[k]);
      pairs += static_cast<std::size_t>(used[k].pairs);
    }
    used = std::move(kept), y = std::move(ky);
  }
  const int n = static_cast<int>(used.size());
  const double span = n ? used.back().distance / used.front().distance : 0.0;
  if (n < kContrastMinBins || span < kContrastMinSpan)
    throw Error("--turbidity contrast needs textured land over a range of distances: it found " + std::to_string(n) +
                " distance bins with at least " + std::to_string(static_cast<int>(kContrastMinPairs)) +
                " pairs of neighbouring pixels on one surface (" + std::to_string(pairs) + " pairs" +
                (n ? ", from " + text::g(used.front().distance, 4) + " to " + text::g(used.back().distance, 4) + " m"
                   : std::string()) +
                "), and needs " + std::to_string(kContrastMinBins) + " bins spanning a factor of " +
                text::g(kContrastMinSpan) + " in distance; give --turbidity T (or auto with --sky-image)");

  // ln Gamma per bin on a grid of T, then the best grid node refined by
  // golden-section search between its neighbours.
  // ln Gamma per bin at T (each call its own atmosphere: the grid's nodes run in parallel).
  auto ln_gamma_at = [&](double T) {
    Atmosphere atm = p.atmosphere;
    atm.turbidity = T;
    std::vector<std::array<double, 3>> g(static_cast<std::size_t>(n));
    for (int b = 0; b < n; ++b) {
      const auto& u = used[static_cast<std::size_t>(b)];
      const std::array<double, 3> v = attenuation_slant_direct(atm, q, u.s_rayleigh, u.s_mie);
      for (int c = 0; c < 3; ++c) g[static_cast<std::size_t>(b)][c] = std::log(v[c]);
    }
    return g;
  };
  const std::vector<char> all(static_cast<std::size_t>(n), 1);
  const double t_lo = 1.0, t_hi = 20.0, grid = 0.25;
  const int ng = static_cast<int>(std::lround((t_hi - t_lo) / grid)) + 1;
  std::vector<std::vector<std::array<double, 3>>> table(static_cast<std::size_t>(ng));
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
  for (int k = 0; k < ng; ++k) table[static_cast<std::size_t>(k)] = ln_gamma_at(t_lo + grid * k);
  // The best grid node for a subset of bins, refined by a parabola through it
  // and its neighbours (the jackknife's cheap fit; the full fit refines exactly).
  auto grid_fit = [&](const std::vector<char>& use) {
    int best = 0;
    double eb = INFINITY;
    std::vector<double> e(static_cast<std::size_t>(ng));
    for (int k = 0; k < ng; ++k) {
      e[static_cast<std::size_t>(k)] = misfit(y, table[static_cast<std::size_t>(k)], use);
      if (e[static_cast<std::size_t>(k)] < eb) eb = e[static_cast<std::size_t>(k)], best = k;
    }
    double t = t_lo + grid * best;
    if (best > 0 && best + 1 < ng) {
      const double a = e[static_cast<std::size_t>(best - 1)], b = e[static_cast<std::size_t>(best)],
                   c = e[static_cast<std::size_t>(best + 1)];
      const double den = a - 2.0 * b + c;
      if (den > 0.0) t += grid * 0.5 * (a - c) / den;
    }
    return std::pair<int, double>(best, t);
  };
  const int best = grid_fit(all).first;
  double a = std::max(t_lo, t_lo + grid * (best - 1)), b = std::min(t_hi, t_lo + grid * (best + 1));
  const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = b - phi * (b - a), x2 = a + phi * (b - a);
  double f1 = misfit(y, ln_gamma_at(x1), all), f2 = misfit(y, ln_gamma_at(x2), all);
  while (b - a > 1e-5) {
    if (f1 <= f2) {
      b = x2, x2 = x1, f2 = f1, x1 = b - phi * (b - a), f1 = misfit(y, ln_gamma_at(x1), all);
    } else {
      a = x1, x1 = x2, f1 = f2, x2 = a + phi * (b - a), f2 = misfit(y, ln_gamma_at(x2), all);
    }
  }
  double t_fit = 0.5 * (a + b);
  // The grid's ends: the interval search cannot step onto them exactly.
  const double e_fit = misfit(y, ln_gamma_at(t_fit), all);
  for (double end : {t_lo, t_hi}) {
    const double e_end = misfit(y, ln_gamma_at(end), all);
    if (e_end <= e_fit && std::fabs(end - t_fit) < 2.0 * grid) t_fit = end;
  }
  const std::vector<std::array<double, 3>> model = ln_gamma_at(t_fit);

  // The jackknife over bins: how far T moves when one bin is left out.
  double spread = 0.0;
  {
    std::vector<double> ts;
    for (int k = 0; k < n; ++k) {
      std::vector<char> use = all;
      use[static_cast<std::size_t>(k)] = 0;
      ts.push_back(std::clamp(grid_fit(use).second, t_lo, t_hi));
    }
    double mean = 0.0;
    for (double t : ts) mean += t;
    mean /= n;
    for (double t : ts) spread += (t - mean) * (t - mean);
    spread = std::sqrt(spread * (n - 1) / n);
  }

  TurbidityContrastFit f;
  f.turbidity = t_fit;
  f.at_lower_bound = t_fit <= t_lo + 1e-3;
  f.at_upper_bound = t_fit >= t_hi - 1e-3;
  nlohmann::json jb = nlohmann::json::array();
  double rms = 0.0;
  for (int c = 0; c < 3; ++c) {
    double mean = 0.0;
    for (int k = 0; k < n; ++k) mean += y[static_cast<std::size_t>(k)][c] - model[static_cast<std::size_t>(k)][c];
    mean /= n;
    for (int k = 0; k < n; ++k) {
      const double r = y[static_cast<std::size_t>(k)][c] - model[static_cast<std::size_t>(k)][c] - mean;
      rms += r * r;
    }
  }
  rms = std::sqrt(rms / (3.0 * n));
  for (int k = 0; k < n; ++k) {
    const auto& u = used[static_cast<std::size_t>(k)];
    jb.push_back({{"distance_m", u.distance},
                  {"pairs", static_cast<std::size_t>(u.pairs)},
                  {"mean_abs_difference", u.abs_diff},
                  {"gamma", {std::exp(model[static_cast<std::size_t>(k)][0]), std::exp(model[static_cast<std::size_t>(k)][1]),
                             std::exp(model[static_cast<std::size_t>(k)][2])}}});
  }
  f.record = {
      {"rule", "contrast"},
      {"turbidity", t_fit},
      {"turbidity_spread", spread},
      {"at_lower_bound", f.at_lower_bound},
      {"at_upper_bound", f.at_upper_bound},
      {"residual_rms_ln", rms},
      {"pairs", pairs},
      {"excluded_pairs", {{"depth_edge", ex.depth_edge}, {"clipped", ex.clipped}, {"dark", ex.dark}}},
      {"bins_below_floor", below_floor},
      {"bins", jb},
      {"space", xyz ? "xyz" : "camera_rgb"},
      {"method",
       "the mean |difference| of right and lower neighbours on one surface (ranges within " +
           text::g(100.0 * kContrastSameSurface) + " %, no channel <= 0 or >= " +
           text::g(100.0 * kContrastClippedFraction) + " % of a channel's clipped plateau) per distance bin (ratio " +
           text::g(kContrastBinRatio, 4) + ", >= " + std::to_string(static_cast<int>(kContrastMinPairs)) +
           " pairs, each channel's contrast >= " + text::g(100.0 * kContrastFloor) +
           " % of its highest bin's): ln contrast_c = a_c + ln Gamma_c(bin; T), a_c free per channel (the scene's own contrast), T "
           "by least squares on [1, 20] (" +
           std::string(slant ? "the slant path at each bin's mean equivalent distances" : "the level path") +
           "); turbidity_spread: the jackknife over bins"}};
  if (f.at_lower_bound)
    f.warning = "--turbidity contrast: the terrain's contrast falls no faster with distance than pure air allows, so "
                "the fit sits on its lower bound T = 1 (the photo is clearer than the model's clearest air, or its "
                "tone mapping lifts far contrast); the removal uses T = 1";
  else if (f.at_upper_bound)
    f.warning = "--turbidity contrast: the fit sits on its upper bound T = 20 (fog, or a contrast that falls with "
                "distance for another reason); the removal uses T = 20";
  return f;
}

}  // namespace brume
