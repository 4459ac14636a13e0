// brume — the scattering blur's steps of a preview plan (brume/preview.hpp):
// the uniforms src/gpu/diffusion.cpp sets, with the shader's interpolation.
#include "brume/preview.hpp"

namespace brume {

void preview_diffusion_steps(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d,
                             const std::string& sigma, const std::string& f_ping, const std::string& f_pong,
                             const std::string& last) {
  plan["targets"]["rates"] = "R32F";
  plan["steps"].push_back({{"pass", "diffusion.rates"},
                           {"in", nlohmann::json::array({sigma})},
                           {"out", nlohmann::json::array({"rates"})},
                           {"uniforms",
                            {{"uSigma0", preview_f(p.sigma0)},
                             {"uIterations", preview_f(d.iterations)},
                             {"uScheme", preview_i(static_cast<int>(p.scheme))}}}});
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

}  // namespace brume
