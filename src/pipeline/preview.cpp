// brume — the scattering blur's steps of a preview plan (brume/preview.hpp):
// the uniforms src/diffusion/diffusion_gpu.cpp sets, with the shader's interpolation;
// and the names and values of the plan's maps.
#include "brume/preview.hpp"
#include "core/text.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string_view>
#include <vector>

namespace brume {

std::string PreviewFrame::add_map(const std::string& kind, Image m) {
  const std::string_view bytes(reinterpret_cast<const char*>(m.data.data()), m.data.size() * sizeof(float));
  char b[64];
  std::snprintf(b, sizeof b, ":%dx%dx%d-%016zx", m.width, m.height, m.channels, std::hash<std::string_view>{}(bytes));
  const std::string name = kind + b;
  if (!maps.count(name)) {
    if (!plan.contains("data")) plan["data"] = nlohmann::json::array();
    plan["data"].push_back(name);
    maps.emplace(name, std::move(m));
  }
  return name;
}

PreviewScene preview_scene(const Image& measured, bool camera_given) {
  PreviewScene s;
  s.width = measured.width;
  s.height = measured.height;
  s.camera_given = camera_given;
  std::vector<float> known, centre;
  const int x0 = measured.width * 9 / 20, x1 = std::max(x0 + 1, measured.width * 11 / 20);
  const int y0 = measured.height * 9 / 20, y1 = std::max(y0 + 1, measured.height * 11 / 20);
  for (int y = 0; y < measured.height; ++y)
    for (int x = 0; x < measured.width; ++x) {
      const float r = measured.data[static_cast<std::size_t>(y) * measured.width + x];
      if (!(std::isfinite(r) && r > 0.0f)) continue;
      known.push_back(r);
      if (x >= x0 && x < x1 && y >= y0 && y < y1) centre.push_back(r);
    }
  if (known.empty()) return s;
  auto median = [](std::vector<float>& v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return static_cast<double>(v[v.size() / 2]);
  };
  s.range_min_m = *std::min_element(known.begin(), known.end());
  s.range_max_m = *std::max_element(known.begin(), known.end());
  s.median_range_m = median(known);
  s.centre_range_m = centre.empty() ? s.median_range_m : median(centre);
  return s;
}

double preview_round(double v) {
  if (!(std::isfinite(v) && v != 0.0)) return v;
  return std::strtod(text::g(v, 2).c_str(), nullptr);  // the double nearest the two digits: it prints as them
}

std::string preview_text(double v) {
  char b[32];
  std::snprintf(b, sizeof b, std::abs(v) >= 100.0 ? "%.0f" : "%.3g", v);
  return b;
}

PreviewStart preview_assumed_camera(const PreviewScene&) {
  return {"fov-x", 60.0,
          "the camera is assumed: 60 degrees horizontal field of view (the command line gave none); set it under "
          "camera"};
}

Intrinsics preview_intrinsics(const Intrinsics& full, int scale) {
  if (scale == 1) return full;
  const double k = scale, half = scale / 2;
  return Intrinsics{full.fx / k, full.fy / k, (full.cx - half) / k, (full.cy - half) / k};
}

Image preview_unknown_negative(Image m) {
  for (float& v : m.data)
    if (!std::isfinite(v) || v == 0.0f) v = -1.0f;
  return m;
}

void preview_rates_step(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d, const std::string& sigma) {
  plan["targets"]["rates"] = "R32F";
  plan["steps"].push_back({{"pass", "diffusion.rates"},
                           {"in", nlohmann::json::array({sigma})},
                           {"out", nlohmann::json::array({"rates"})},
                           {"uniforms",
                            {{"uSigma0", preview_f(p.sigma0)},
                             {"uIterations", preview_f(d.iterations)},
                             {"uScheme", preview_i(static_cast<int>(p.scheme))}}}});
}

void preview_iterate_step(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d,
                          const std::string& f_ping, const std::string& f_pong, const std::string& last) {
  plan["steps"].push_back({{"pass", "diffusion.iterate"},
                           {"in", nlohmann::json::array({"$src", "rates"})},
                           {"out", nlohmann::json::array()},
                           {"uniforms",
                            {{"uScheme", preview_i(static_cast<int>(p.scheme))},
                             {"uSigma0", preview_f(p.sigma0)},
                             {"uHardware", preview_i(0)},
                             {"uEdgeRate", preview_i(static_cast<int>(p.edge_rate))}}},
                           {"iterate",
                            {{"count", d.iterations}, {"uniform", "uK"}, {"ping", f_ping}, {"pong", f_pong}, {"last", last}}}});
}

void preview_diffusion_steps(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d,
                             const std::string& sigma, const std::string& f_ping, const std::string& f_pong,
                             const std::string& last) {
  preview_rates_step(plan, p, d, sigma);
  preview_iterate_step(plan, p, d, f_ping, f_pong, last);
}

}  // namespace brume
