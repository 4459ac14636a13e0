// brume — `brume lidar rain`: a KITTI .bin scan in, the points that return
// through the rain out, with their labels and the run's record
// (brume/rain.hpp; docs/rain.md).
#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/rain.hpp"
#include "brume/record.hpp"
#include "pipeline/scan_job.hpp"

namespace brume {

namespace fs = std::filesystem;

const ParamTable<LidarRainJob>& lidar_rain_job_table() {
  static const ParamTable<LidarRainJob> t = [] {
    ParamTable<LidarRainJob> d("files");
    d.text("points", &LidarRainJob::points, "the scan: KITTI velodyne .bin (float32 x, y, z, reflectance)")
        .reads_file()
        .nest(&LidarRainJob::rain, lidar_rain_param_table())
        .text("out", &LidarRainJob::out,
              "the rainy scan, KITTI .bin: the points that return, in input order (kept ones attenuated, others "
              "moved to a drop); lost points are left out")
        .writes_file()
        .text("labels", &LidarRainJob::labels,
              "write one byte per input point: 0 kept, 1 moved to a drop, 2 lost")
        .writes_file()
        .text("record", &LidarRainJob::record, "write a JSON record that `brume run` repeats")
        .writes_file();
    return d;
  }();
  return t;
}

namespace {

nlohmann::json run_lidar_rain_job(const LidarRainJob& job, const RunContext& ctx) {
  lidar_rain_job_table().validate(job);
  validate_lidar_rain(job.rain);
  return run_scan_file_job("lidar rain", ctx, lidar_rain_job_table().to_json(job),
                           {job.points, job.out, job.labels, job.record},
                           [&](const float* in, float* out, std::size_t n, std::uint8_t* labels, const std::string& what,
                               nlohmann::json& blocks) {
                             const LidarRainStats st = lidar_rain(in, out, n, job.rain, labels, what);
                             blocks["rain"] = lidar_rain_record(job.rain, st);
                             return st.run.lost;
                           });
}

}  // namespace

CommandDef lidar_rain_command() {
  CommandDef c = make_command<LidarRainJob>({
      .name = "lidar rain",
      .cli = "lidar rain",
      .summary = "rain on a LiDAR scan (KITTI .bin): attenuated returns, drop echoes, lost points (Marshall-Palmer "
                 "drops, Kilic et al. 2021)",
      .table = &lidar_rain_job_table(),
      .writes_record = true,
      .check = [](const LidarRainJob& j, const std::set<std::string>&) { validate_lidar_rain(j.rain); },
      .run = [](const LidarRainJob& j, const ExecOptions&, const RunContext& ctx) { return run_lidar_rain_job(j, ctx); },
      .report =
          [](const LidarRainJob& j, const nlohmann::json& rec) {
            const auto& r = rec["rain"];
            const auto n = r["points"].get<std::size_t>();
            const auto pct = [n](std::size_t k) { return n ? 100.0 * static_cast<double>(k) / n : 0.0; };
            const auto kept = r["kept"].get<std::size_t>(), moved = r["moved_to_drops"].get<std::size_t>(),
                       lost = r["lost"].get<std::size_t>();
            std::fprintf(stderr,
                         "brume lidar rain: %s  %.4g mm/h, extinction %.4g 1/m  of %zu points: %zu kept (%.2f %%), "
                         "%zu moved to drops (%.2f %%), %zu lost (%.2f %%)\n",
                         j.out.c_str(), r["rate_mm_h"].get<double>(), r["extinction_per_m"].get<double>(), n, kept,
                         pct(kept), moved, pct(moved), lost, pct(lost));
          },
  });
  // brume.lidar.rain(points): an (N, 4) float32 array (x, y, z, intensity),
  // read in place when C-contiguous; the points that return as a new (K, 4)
  // array and the labels as N bytes.
  static const auto call = array_call_table(lidar_rain_param_table(), kArrayNone);
  c.arrays = make_array_form<LidarRainParams>(
      "lidar_rain", "brume.lidar.rain",
      "Rain on a LiDAR scan (Marshall-Palmer drops; drop echoes in each beam's cone, Kilic et al. 2021): points is an "
      "(N, 4) float32 array of x, y, z [m] and intensity (KITTI's reflectance in [0, 1]). Returns points, the (K, 4) "
      "points that return in input order (None when none does), and labels, one uint8 per input point: 0 kept "
      "(attenuated), 1 moved to a drop, 2 lost. rate in mm/h is required. As `brume lidar rain`.",
      {{"points", 1, false, ArrayArg::As::view, false, true}}, call, {"points", "labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<LidarRainParams>& k, const Exec&, const std::set<std::string>&) {
        const std::string what = "brume.lidar.rain(): points";
        LidarRainStats st;
        ArrayResult r = scan_array_result(in[0].view, what,
                                          [&](const float* src, float* out, std::size_t n, std::uint8_t* labels) {
                                            st = lidar_rain(src, out, n, k.p, labels, what);
                                            return st.run.lost;
                                          });
        r.record["rain"] = lidar_rain_record(k.p, st);
        return r;
      },
      [](const ArrayCall<LidarRainParams>& k, const std::set<std::string>&) { validate_lidar_rain(k.p); });
  return c;
}

}  // namespace brume
