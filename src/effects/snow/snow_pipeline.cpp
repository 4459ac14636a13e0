// brume — `brume lidar snow`: a KITTI .bin scan in, the points that return
// through the snow out, with their labels and the run's record
// (brume/snow.hpp; docs/snow.md).
#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/snow.hpp"
#include "brume/record.hpp"
#include "pipeline/scan_job.hpp"

namespace brume {

namespace fs = std::filesystem;

const ParamTable<LidarSnowJob>& lidar_snow_job_table() {
  static const ParamTable<LidarSnowJob> t = [] {
    ParamTable<LidarSnowJob> d("files");
    d.text("points", &LidarSnowJob::points, "the scan: KITTI velodyne .bin (float32 x, y, z, reflectance)")
        .reads_file()
        .nest(&LidarSnowJob::snow, lidar_snow_param_table())
        .text("out", &LidarSnowJob::out,
              "the snowy scan, KITTI .bin: the points that return, in input order (kept ones weakened by the flakes' "
              "occlusion, others moved to a flake); lost points are left out")
        .writes_file()
        .text("labels", &LidarSnowJob::labels,
              "write one byte per input point: 0 kept, 1 moved to a flake, 2 lost")
        .writes_file()
        .text("record", &LidarSnowJob::record, "write a JSON record that `brume run` repeats")
        .writes_file();
    return d;
  }();
  return t;
}

namespace {

nlohmann::json run_lidar_snow_job(const LidarSnowJob& job, const RunContext& ctx) {
  lidar_snow_job_table().validate(job);
  validate_lidar_snow(job.snow);
  return run_scan_file_job("lidar snow", ctx, lidar_snow_job_table().to_json(job),
                           {job.points, job.out, job.labels, job.record},
                           [&](const float* in, float* out, std::size_t n, std::uint8_t* labels, const std::string& what,
                               nlohmann::json& blocks) {
                             const LidarSnowStats st = lidar_snow(in, out, n, job.snow, labels, what);
                             blocks["snow"] = lidar_snow_record(job.snow, st);
                             return st.run.lost;
                           });
}

}  // namespace

CommandDef lidar_snow_command() {
  CommandDef c = make_command<LidarSnowJob>({
      .name = "lidar snow",
      .cli = "lidar snow",
      .summary = "snow on a LiDAR scan (KITTI .bin, no ring needed): flake echoes, occluded returns, lost points "
                 "(Gunn-Marshall flakes, the footprint model)",
      .table = &lidar_snow_job_table(),
      .writes_record = true,
      .check = [](const LidarSnowJob& j, const std::set<std::string>&) { validate_lidar_snow(j.snow); },
      .run = [](const LidarSnowJob& j, const ExecOptions&, const RunContext& ctx) { return run_lidar_snow_job(j, ctx); },
      .report =
          [](const LidarSnowJob& j, const nlohmann::json& rec) {
            const auto& r = rec["snow"];
            const auto n = r["points"].get<std::size_t>();
            const auto pct = [n](std::size_t k) { return n ? 100.0 * static_cast<double>(k) / n : 0.0; };
            const auto kept = r["kept"].get<std::size_t>(), moved = r["moved_to_flakes"].get<std::size_t>(),
                       lost = r["lost"].get<std::size_t>();
            std::fprintf(stderr,
                         "brume lidar snow: %s  %.4g mm/h (water), %.4g flakes/m^3  of %zu points: %zu kept (%.2f %%), "
                         "%zu moved to flakes (%.2f %%), %zu lost (%.2f %%)\n",
                         j.out.c_str(), r["rate_mm_h"].get<double>(), r["flakes_per_m3"].get<double>(), n, kept,
                         pct(kept), moved, pct(moved), lost, pct(lost));
          },
  });
  // brume.lidar.snow(points): an (N, 4) float32 array (x, y, z, intensity),
  // read in place when C-contiguous; the points that return as a new (K, 4)
  // array and the labels as N bytes.
  static const auto call = array_call_table(lidar_snow_param_table(), kArrayNone);
  c.arrays = make_array_form<LidarSnowParams>(
      "lidar_snow", "brume.lidar.snow",
      "Snow on a LiDAR scan (exponential flakes from the water-equivalent rate; the footprint model: flakes in each "
      "beam's cone occlude and echo): points is an "
      "(N, 4) float32 array of x, y, z [m] and intensity (KITTI's reflectance in [0, 1]). Returns points, the (K, 4) "
      "points that return in input order (None when none does), and labels, one uint8 per input point: 0 kept "
      "(weakened), 1 moved to a flake, 2 lost. rate in mm/h (water equivalent) is required. As `brume lidar snow`.",
      {{"points", 1, false, ArrayArg::As::view, false, true}}, call, {"points", "labels", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<LidarSnowParams>& k, const Exec&, const std::set<std::string>&) {
        const std::string what = "brume.lidar.snow(): points";
        LidarSnowStats st;
        ArrayResult r = scan_array_result(in[0].view, what,
                                          [&](const float* src, float* out, std::size_t n, std::uint8_t* labels) {
                                            st = lidar_snow(src, out, n, k.p, labels, what);
                                            return st.run.lost;
                                          });
        r.record["snow"] = lidar_snow_record(k.p, st);
        return r;
      },
      [](const ArrayCall<LidarSnowParams>& k, const std::set<std::string>&) { validate_lidar_snow(k.p); });
  return c;
}

}  // namespace brume
