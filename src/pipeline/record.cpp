// brume — parameter records (see brume/record.hpp).
#include "brume/record.hpp"

#include "brume/pipeline.hpp"

#include <chrono>
#include <ctime>

namespace brume {

nlohmann::json record_header(const std::string& command, const std::vector<std::string>& argv) {
  std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return {{"tool", "brume"}, {"version", BRUME_VERSION}, {"command", command},
          {"argv", argv}, {"time_utc", buf}};
}

nlohmann::json file_record(const std::string& path, const FileInfo& info, const Image& img) {
  nlohmann::json j = {{"path", path},
                      {"sha256", sha256_file(path)},
                      {"format", info.format},
                      {"width", img.width},
                      {"height", img.height},
                      {"stored_bits", info.bits},
                      {"integer", info.integer},
                      {"channels", info.channel_names},
                      {"transfer_applied", to_string(info.transfer)},
                      // What was read: the layer (empty: the plain channels) and its channels, in order.
                      {"layer", info.layer},
                      {"channels_read", info.channels_read}};
  if (!info.part.empty()) j["part"] = info.part;
  // A table's file, hashed when it was read: brume run checks it as any input.
  if (info.transfer == Transfer::table)
    j["transfer_table"] = {{"path", info.transfer.table_path},
                           {"sha256", info.transfer.table_sha256},
                           {"entries", info.transfer.table.size()}};
  if (info.blender) j["blender_multilayer"] = true;
  if (info.padded) {
    const auto box = [](const PixelWindow& w) { return nlohmann::json::array({w.x0, w.y0, w.x1, w.y1}); };
    j["data_window"] = box(info.data_window);
    j["display_window"] = box(info.display_window);
    j["padded"] = "the data window padded to the display window (colour and alpha 0, depth unknown)";
  }
  return j;
}

nlohmann::json diffusion_record(const DiffusionParams& p, const DiffusionPlan& plan) {
  return {{"scheme", enum_name(scheme_names(), p.scheme)},
          {"precision", enum_name(precision_names(), p.precision)},
          {"sigma0_px", p.sigma0},
          {"rho_max", plan.rho_max},
          {"edge_rate", enum_name(edge_rate_names(), p.edge_rate)},
          {"sigma_max_px", plan.sigma_max},
          {"iterations", plan.iterations},
          {"boundary", "half-sample mirror"}};
}

nlohmann::json prepare_record(const PrepareParams& p, const PrepareResult& r) {
  const double n = static_cast<double>(r.range.pixels());
  nlohmann::json j = {{"rule", "Hansard 4.1: holes filled by RANSAC from their boundary; unknown components touching the top "
                   "(>= sky_min_fraction) or large (>= sky_large_fraction) are sky at S_max; Laplace margin of width mu"},
          {"sky_margin_px", p.sky_margin_px},
          {"sky_min_fraction", p.sky_min_fraction},
          {"sky_large_fraction", p.sky_large_fraction},
          {"s_max_factor", p.s_max_factor},
          {"min_coverage", p.min_coverage},
          {"seed", p.seed},
          {"ransac_iterations", p.ransac_iterations},
          {"residual_tol", p.residual_tol},
          {"range_max_m", r.range_max_m},
          {"s_max_m", r.s_max_m},
          {"known_fraction", r.known_fraction},
          {"holes", r.holes},
          {"hole_fraction", r.hole_pixels / n},
          {"sky_fraction", r.sky_pixels / n},
          {"margin_fraction", r.margin_pixels / n},
          {"margin_residual", r.margin_residual},
          {"solver_iterations", r.solver_iterations}};
  if (!r.sky_weight.empty()) {  // solved for an effect whose sky lies beyond the scene
    j["sky_weight_rule"] = "harmonic across the margin: 0 at the scene, 1 at the sky beyond it (same operator)";
    j["sky_weight_residual"] = r.weight_residual;
    j["sky_weight_iterations"] = r.weight_iterations;
  }
  return j;
}

}  // namespace brume
