// brume — the scattering blur's steps of a preview plan (brume/preview.hpp):
// the uniforms src/diffusion/diffusion_gpu.cpp sets, with the shader's interpolation;
// and the names and values of the plan's maps.
#include "brume/preview.hpp"

#include <cmath>
#include <cstdio>
#include <functional>
#include <string_view>

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
