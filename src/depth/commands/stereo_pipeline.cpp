// brume — `brume depth stereo` (stereo_job.hpp).
#include "depth/commands/stereo_job.hpp"

#include <cstdio>

#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/record.hpp"

namespace brume {

const ParamTable<DepthStereoJob>& depth_stereo_job_table() {
  static const ParamTable<DepthStereoJob> t = [] {
    ParamTable<DepthStereoJob> d("output");
    d.text("left", &DepthStereoJob::left, "left view of a rectified pair (the disparity is the left view's)")
        .reads_file()
        .text("right", &DepthStereoJob::right, "right view of the pair (same size)")
        .reads_file()
        .text("left-layer", &DepthStereoJob::left_layer,
              "the layer of --left in a file with layers (NAME.R, NAME.G, NAME.B of a multilayer OpenEXR)")
        .text("right-layer", &DepthStereoJob::right_layer, "the layer of --right in a file with layers")
        .text("calib", &DepthStereoJob::calib, "Middlebury 2014 / ETH3D calib.txt (cam0, doffs, baseline in mm)")
        .reads_file("", 0, 4)
        .real_or_unset("fx", &DepthStereoJob::fx_px, "px", Range::above(0.0),
                       "focal length in pixels (without --calib; with --baseline)", 0.0)
        .real_or_unset("baseline", &DepthStereoJob::baseline_m, "m", Range::above(0.0),
                       "stereo baseline (without --calib; with --fx)", NAN)
        .nest(&DepthStereoJob::stereo, stereo_param_table())
        .text("out", &DepthStereoJob::out, "disparity in px of the left view, 1-channel float file (.pfm, .exr, .tif); NaN unknown")
        .writes_file()
        .text("confidence", &DepthStereoJob::confidence, "per-pixel confidence 0-1 (0 unknown, 0.2 filled)")
        .writes_file()
        .text("record", &DepthStereoJob::record, "write a JSON record of the matching")
        .writes_file();
    return d;
  }();
  return t;
}

namespace {

// The camera, checked before any matching: exactly one of --calib and
// (--fx, --baseline); a calib.txt's size must be the pair's.
nlohmann::json stereo_camera(const DepthStereoJob& job) {
  const bool direct = job.fx_px > 0.0 || !std::isnan(job.baseline_m);
  if (!job.calib.empty() && direct)
    throw Error("give the camera once: --calib '" + job.calib + "' or --fx and --baseline, not both");
  if (!job.calib.empty()) {
    const StereoCalib c = read_stereo_calib(job.calib);
    nlohmann::json j = {{"calib", job.calib}, {"f_px", c.f_px}, {"baseline_m", c.baseline_m}, {"doffs_px", c.doffs_px}};
    if (c.width > 0) j["width"] = c.width, j["height"] = c.height;
    return j;
  }
  if (!(job.fx_px > 0.0) || !(job.baseline_m > 0.0))
    throw Error("depth stereo needs the camera, to record how the disparity converts to depth: --calib calib.txt, "
                "or --fx F (px) and --baseline B (m)");
  return {{"f_px", job.fx_px}, {"baseline_m", job.baseline_m}, {"doffs_px", 0.0}};
}

WriteOptions disparity_options() {
  WriteOptions w;
  w.is_color = false;
  w.float_reason = "a disparity in pixels needs a float file";
  return w;
}

WriteOptions confidence_options() {
  WriteOptions w;
  w.is_color = false;
  return w;
}

struct StereoRun {
  StereoResult result;
  nlohmann::json record;  // camera, left, right, stereo
};

StereoRun stereo_run(const DepthStereoJob& job) {
  depth_stereo_job_table().validate(job);
  StereoRun r;
  r.record["camera"] = stereo_camera(job);
  nlohmann::json lrec, rrec;
  const StereoView L = read_stereo_view(job.left, "--left", &lrec, job.left_layer);
  const StereoView R = read_stereo_view(job.right, "--right", &rrec, job.right_layer);
  const nlohmann::json& cam = r.record["camera"];
  if (cam.contains("width") && (cam["width"].get<int>() != L.width || cam["height"].get<int>() != L.height))
    throw Error("--left '" + job.left + "' is " + std::to_string(L.width) + "x" + std::to_string(L.height) +
                " but --calib '" + job.calib + "' says " + std::to_string(cam["width"].get<int>()) + "x" +
                std::to_string(cam["height"].get<int>()) +
                "; the calibration must be the pair's (rescale it with the images)");
  r.result = compute_stereo(L, R, job.stereo, "--left '" + job.left + "'", "--right '" + job.right + "'");
  r.record["left"] = lrec;
  r.record["right"] = rrec;
  r.record["stereo"] = r.result.record;
  r.record["convention"] = "d = x_left - x_right [px] of the left view; Z = f B / (d + doffs) (brume depth convert "
                           "--disparity OUT with the same --calib, or --fx and --baseline)";
  return r;
}

}  // namespace

nlohmann::json run_depth_stereo_job(const DepthStereoJob& job, const RunContext& ctx) {
  depth_stereo_job_table().validate(job);
  if (job.out.empty()) throw Error("no output given: use --out FILE (a .pfm of the disparity in pixels)");
  check_writable(job.out, disparity_options(), "--out");
  if (!job.confidence.empty()) check_writable(job.confidence, confidence_options(), "--confidence");
  if (!job.record.empty()) check_record_path(job.record);
  StereoRun r = stereo_run(job);
  nlohmann::json rec = run_record_header("depth stereo", ctx.argv);
  rec["job"] = depth_stereo_job_table().to_json(job);
  rec.update(r.record);
  WriteOptions w = disparity_options();
  w.description = rec.dump();
  OutputSet outs;
  outs.write(job.out, r.result.disparity, w, "--out");
  if (!job.confidence.empty()) outs.write(job.confidence, r.result.confidence, confidence_options(), "--confidence");
  if (!job.record.empty()) outs.write_text(job.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  return rec;
}

CommandDef depth_stereo_command() {
  CommandDef c = make_command<DepthStereoJob>({
      .name = "depth stereo",
      .cli = "depth stereo",
      .summary = "disparity of a rectified stereo pair (semi-global matching, left-right checked), in pixels",
      .table = &depth_stereo_job_table(),
      .writes_record = true,
      .run = [](const DepthStereoJob& j, const ExecOptions&, const RunContext& ctx) {
        return run_depth_stereo_job(j, ctx);
      },
      .report = [](const DepthStereoJob& job, const nlohmann::json& rec) {
        const auto& s = rec["stereo"];
        std::fprintf(stderr,
                     "brume depth stereo: %s  disparities 0-%d px searched, %.1f %% matched, %.1f %% filled, "
                     "%.1f %% unknown, %.0f ms\n",
                     job.out.c_str(), s["searched_px"][1].get<int>(), 100 * s["matched_fraction"].get<double>(),
                     100 * s["filled_fraction"].get<double>(), 100 * s["unknown_fraction"].get<double>(),
                     s["timing_ms"]["total"].get<double>());
      },
  });
  // brume.depth.stereo(left=, right=, calib=, ...): the files in, the maps out as arrays.
  static const auto call = array_call_table(depth_stereo_job_table(), kArrayNone, {"out", "confidence", "record"});
  c.arrays = make_array_form<DepthStereoJob>(
      "depth_stereo", "brume.depth.stereo",
      "Disparity in pixels of a rectified pair's left view (semi-global matching, both views, left-right check, "
      "speckle filter, occlusion fill), read from the files left= and right=, with calib= or fx= and baseline=. As "
      "`brume depth stereo`.",
      {}, call, {"disparity", "confidence", "record"}, false,
      [](const std::vector<ArrayIn>&, ArrayCall<DepthStereoJob>& k, const Exec&, const std::set<std::string>&) {
        StereoRun run = stereo_run(k.p);
        ArrayResult r;
        r.record = std::move(run.record);
        r.images["disparity"] = std::move(run.result.disparity);
        r.images["confidence"] = std::move(run.result.confidence);
        return r;
      });
  return c;
}

}  // namespace brume
