// brume — a camera effect's scan (rain, snow and wet: `--lidar IN.bin --lidar-out OUT.bin`, and
// on arrays brume.rain(..., lidar=points) and its peers): the frame's scan through the effect's
// scan model. The file form: its flags checked with the job, the scan read, run, and written with
// the job's outputs, its hash and record block in the record's extras. The array form: its points
// and labels as the Result's lidar and lidar_labels (None for both without a scan), and the call's
// job marked with an empty lidar block (the scan's settings are the call's own keywords). Private
// to the library.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"

namespace brume {

// --lidar and --lidar-out come together, the latter a .bin (checked with the job: a batch row or a
// record is refused when planned; the folder when the job runs, since brume batch plans before it
// makes the frames' folders); `labels` (--lidar-labels, where the effect has it) only with them.
// `verb` says what --lidar does ("rains on a scan").
inline void check_camera_scan_flags(const std::string& lidar, const std::string& lidar_out, const std::string& verb,
                                    const std::string& labels = "") {
  if (lidar.empty() != lidar_out.empty())
    throw Error(lidar.empty() ? "--lidar-out names the output scan of --lidar IN.bin: give --lidar too, or drop "
                                "--lidar-out"
                              : "--lidar " + verb + ": give --lidar-out OUT.bin for it, or drop --lidar");
  if (lidar.empty() && !labels.empty())
    throw Error("--lidar-labels labels the points of --lidar IN.bin: give --lidar and --lidar-out, or drop it");
  if (!lidar.empty() && std::filesystem::path(lidar_out).extension() != ".bin")
    throw Error("--lidar-out '" + lidar_out + "': a scan is written as a KITTI .bin (float32 x, y, z, "
                "intensity); name it *.bin");
}

// The scan of --lidar through `run` (the points that return into out, one label per point when
// labels is not null; it fills the record's block `block` and returns the number of points
// lost), written to --lidar-out (and its labels to --lidar-labels when given) with the job's
// outputs (ctx.files); the input's hash and the block in the record's extras.
inline void run_camera_scan_file(
    RunContext& ctx, const std::string& lidar, const std::string& lidar_out, const std::string& labels_out,
    const std::string& block,
    const std::function<std::size_t(const float* in, float* out, std::size_t n, std::uint8_t* labels,
                                    const std::string& what, nlohmann::json& block)>& run) {
  check_kitti_bin_output(lidar_out, "--lidar-out");
  if (!labels_out.empty()) check_output_dir(labels_out, "--lidar-labels");
  const std::vector<float> in = read_kitti_bin(lidar, "--lidar");
  const std::size_t n = in.size() / 4;
  std::vector<float> out(in.size());
  std::string labels(labels_out.empty() ? 0 : n, '\0');
  nlohmann::json rec;
  const std::size_t lost = run(in.data(), out.data(), n,
                               labels_out.empty() ? nullptr : reinterpret_cast<std::uint8_t*>(labels.data()),
                               "--lidar '" + lidar + "'", rec);
  ctx.files.push_back({lidar_out, kitti_bin_bytes(out.data(), n - lost), "--lidar-out"});
  if (!labels_out.empty()) ctx.files.push_back({labels_out, std::move(labels), "--lidar-labels"});
  if (!ctx.extra.is_object()) ctx.extra = nlohmann::json::object();
  ctx.extra["inputs"]["lidar"] = {{"path", lidar}, {"sha256", sha256_file(lidar)}, {"points", n}};
  ctx.extra[block] = std::move(rec);
}

// The scan argument in[at], when given, through `run` (scan_array_result's: the points that return
// into out, one label per point, the count lost); its arrays into r. Whether there was a scan.
inline bool camera_scan_arrays(const std::vector<ArrayIn>& in, std::size_t at, const std::string& what,
                               ArrayResult& r,
                               const std::function<std::size_t(const float*, float*, std::size_t, std::uint8_t*)>& run) {
  if (in.size() <= at || !in[at].present) {
    r.images["lidar"] = Image();  // None
    r.more["lidar_labels"] = nullptr;
    return false;
  }
  ArrayResult scan = scan_array_result(in[at].view, what, run);
  r.images["lidar"] = std::move(scan.images["points"]);
  r.bytes["lidar_labels"] = std::move(scan.bytes["labels"]);
  return true;
}

// The form's run, its job marked with an empty lidar block when in[at] was given.
inline void mark_scan_in_job(ArrayForm& a, std::size_t at) {
  a.run = [inner = a.run, at](const std::vector<ArrayIn>& in, const nlohmann::json& call, const Exec& e,
                              const std::set<std::string>& g) {
    ArrayResult r = inner(in, call, e, g);
    if (in.size() > at && in[at].present) r.job["lidar"] = nlohmann::json::object();
    return r;
  };
}

}  // namespace brume
