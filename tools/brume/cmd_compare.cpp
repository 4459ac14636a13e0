// brume compare — how alike two images are: Morales eq. 3.14 histogram
// correlations (HSV of 8-bit sRGB, OpenCV) and PSNR (brume/compare.hpp).
#include <cstdio>
#include <string>

#include "brume/compare.hpp"
#include "cli.hpp"

namespace brume::cli {

namespace {

std::string db(const nlohmann::json& v) {
  if (v.is_string()) return v.get<std::string>() + " dB (identical)";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f dB", v.get<double>());
  return buf;
}

}  // namespace

Command add_compare(CLI::App& app) {
  CLI::App* sub = app.add_subcommand(
      "compare", "compare two images: HSV histogram correlations (Morales eq. 3.14) and PSNR");
  return job_command<CompareJob>(sub, "compare", compare_job_table(), false,
                                 [](const CompareJob& job, const ExecOptions&, const RunContext& ctx) {
                                   const nlohmann::json r = run_compare_job(job, ctx)["result"];
                                   // The result is this command's product: stdout, not stderr.
                                   std::printf(
                                       "pixels compared            %zu\n"
                                       "hue-saturation correlation %.6f  (eq. 3.14, HSV of 8-bit sRGB, H x S = %d x %d bins)\n"
                                       "brightness correlation     %.6f  (eq. 3.14, V, %d bins)\n"
                                       "PSNR linear RGB            %s  (peak 1)\n"
                                       "PSNR 8-bit sRGB            %s  (peak 255)\n",
                                       r["pixels_compared"].get<std::size_t>(),
                                       r["hue_saturation_correlation"].get<double>(), kCompareHueBins,
                                       kCompareSaturationBins, r["brightness_correlation"].get<double>(),
                                       kCompareValueBins, db(r["psnr_linear_db"]).c_str(),
                                       db(r["psnr_srgb8_db"]).c_str());
                                   const auto ca = r["clipped_samples_a"].get<std::size_t>(),
                                              cb = r["clipped_samples_b"].get<std::size_t>();
                                   if (ca || cb)
                                     std::printf("clipped to [0,1] for the 8-bit encoding: %zu samples of A, %zu of B\n",
                                                 ca, cb);
                                   return 0;
                                 });
}

}  // namespace brume::cli
