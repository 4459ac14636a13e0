// brume study — the sky fit's measured-vs-model scatter (Morales Fig. 2.5),
// drawn with the study's plotter for `brume sky fit --plot`.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "brume_study/sky_plot.hpp"
#include "plot.hpp"

namespace brume::study {

// The measured-vs-model scatter (Morales Fig. 2.5): inliers blue, outliers red,
// the line measured = model in grey; log axes (sky luminance spans decades).
Image sky_fit_scatter(const nlohmann::json& fit) {
  plot::Panel p;
  char title[160];
  std::snprintf(title, sizeof title, "sky fit: T = %.3f +- %.3f, %s", fit["turbidity"].get<double>(),
                fit["turbidity_spread"].get<double>(), fit["reliable"].get<bool>() ? "reliable" : "UNRELIABLE");
  p.title = title;
  p.xlabel = "model luminance (scale x Preetham)";
  p.ylabel = "measured luminance";
  p.log_x = p.log_y = true;
  double lo = INFINITY, hi = 0;
  bool first_in = true, first_out = true;
  for (const auto& s : fit["samples"]) {
    const double m = s["model"].get<double>(), y = s["measured"].get<double>();
    lo = std::min({lo, m, y}), hi = std::max({hi, m, y});
    plot::Series q;
    const bool in = s["inlier"].get<bool>();
    if (in) q.r = 30, q.g = 90, q.b = 200; else q.r = 210, q.g = 40, q.b = 40;
    if (in && first_in) q.label = "inlier", first_in = false;
    if (!in && first_out) q.label = "outlier (RANSAC)", first_out = false;
    q.x = {m}, q.y = {y};
    p.series.push_back(q);
  }
  plot::Series line;
  line.label = "measured = model";
  line.r = line.g = line.b = 140;
  line.markers = false;
  line.x = {lo, hi}, line.y = {lo, hi};
  p.series.insert(p.series.begin(), line);
  return plot::render({p}, 640, 480);
}

}  // namespace brume::study
