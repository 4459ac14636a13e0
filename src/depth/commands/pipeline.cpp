// brume — depth conversion, preparation and completion as pipelines (depth_jobs.hpp).
#include "brume/command.hpp"
#include "depth/commands/depth_jobs.hpp"

#include <cstdio>
#include <filesystem>

#include "brume/complete.hpp"
#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/prepare.hpp"
#include "brume/record.hpp"
#include "core/warnings.hpp"

namespace fs = std::filesystem;

namespace brume {

namespace {

WriteOptions metres(const char* why) {
  WriteOptions w;
  w.is_color = false;
  w.float_reason = why;
  return w;
}

}  // namespace

const ParamTable<DepthConvertJob>& depth_convert_job_table() {
  static const ParamTable<DepthConvertJob> t = [] {
    ParamTable<DepthConvertJob> d("output");
    d.nest(&DepthConvertJob::depth, depth_param_table())
        .choice("kind", &DepthConvertJob::kind, {"range", "z"}, "range (metres along the ray) or z (planar depth)")
        .text("out", &DepthConvertJob::out, "output float file (.exr, .pfm, .tif)")
        .writes_file()
        .text("record", &DepthConvertJob::record, "write a JSON record of the conversion")
        .writes_file();
    return d;
  }();
  return t;
}

nlohmann::json run_depth_convert_job(const DepthConvertJob& job, const RunContext& ctx) {
  depth_convert_job_table().validate(job);
  const WriteOptions data = metres("depth in metres needs a float file");
  if (job.out.empty()) throw Error("no output given: use --out FILE");
  check_writable(job.out, data, "--out");
  if (!job.record.empty()) check_record_path(job.record);
  refuse_fusion(job.depth, "depth convert");
  LoadedDepth ld = load_depth(job.depth);
  Image result = ld.range;
  nlohmann::json rec = run_record_header("depth convert", ctx.argv);
  rec["job"] = depth_convert_job_table().to_json(job);
  rec["depth"] = ld.record;
  rec["kind"] = job.kind;
  if (job.kind == "z") {
    const Intrinsics k = depth_camera(job.depth, result.width, result.height).k;  // KITTI: camera 2's K from P2
    result = range_to_z(result, k);
    rec["z_intrinsics"] = {{"fx_px", k.fx}, {"fy_px", k.fy}, {"cx_px", k.cx}, {"cy_px", k.cy}};
  }
  rec["result"] = {{"width", result.width}, {"height", result.height},
                   {"unknown_pixels", unknown_range_pixels(result)}};
  WriteOptions w = data;
  w.description = rec.dump();
  OutputSet outs;
  outs.write(job.out, result, w, "--out");
  if (!job.record.empty()) outs.write_text(job.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  return rec;
}

const ParamTable<DepthPrepareJob>& depth_prepare_job_table() {
  static const ParamTable<DepthPrepareJob> t = [] {
    ParamTable<DepthPrepareJob> d("output");
    d.nest(&DepthPrepareJob::depth, depth_param_table())
        .nest(&DepthPrepareJob::prepare, prepare_param_table())
        .choice("complete", &DepthPrepareJob::complete, complete_mode_names(),
                "depth completion guided by --image (brume depth complete) before the preparation: auto (when "
                "the known pixels cover less than --min-coverage), on (always), off (never: such maps are refused)")
        .nest(&DepthPrepareJob::completion, complete_param_table())
        .text("image", &DepthPrepareJob::image,
              "colour image that guides the completion (needed when it runs) and sizes a --velodyne scan")
        .reads_file()
        .text("image-layer", &DepthPrepareJob::image_layer,
              "the layer of --image in a file with layers (NAME.R, NAME.G, NAME.B of a multilayer OpenEXR)")
        .text("out", &DepthPrepareJob::out, "prepared range, float file (.exr, .pfm, .tif)")
        .writes_file()
        .text("masks", &DepthPrepareJob::masks, "directory for sky.png, holes.png, margin.png and prepared-preview.png")
        .writes_file()  // a directory the run writes into
        .text("record", &DepthPrepareJob::record, "write a JSON record of what was done")
        .writes_file();
    return d;
  }();
  return t;
}

nlohmann::json run_depth_prepare_job(const DepthPrepareJob& job, const RunContext& ctx) {
  depth_prepare_job_table().validate(job);
  const WriteOptions data = metres("a range in metres needs a float file");
  if (job.out.empty()) throw Error("no output given: use --out FILE");
  check_writable(job.out, data, "--out");
  if (!job.record.empty()) check_record_path(job.record);
  if (!job.masks.empty()) {
    std::error_code ec;
    fs::create_directories(job.masks, ec);
    if (!fs::is_directory(job.masks)) throw Error("--masks '" + job.masks + "' cannot be created: " + ec.message());
  }
  const RangeStep step{PrepareMode::automatic, job.prepare, job.complete, job.completion, {}, {}};
  check_range_step(step, ctx.given);
  Image rgb;
  nlohmann::json image_record;
  if (!job.image.empty()) {
    FileInfo info;
    ColorRead how;
    how.layer = job.image_layer;
    rgb = read_color(job.image, how, &info);
    image_record = file_record(job.image, info, rgb);
  }
  DepthSource source = job.depth;  // a pair fused with a scan: its left view is --image unless named
  if (source.fused() && source.stereo_left.empty()) source.stereo_left = job.image, source.stereo_left_layer = job.image_layer;
  LoadedDepth ld = load_depth(source, rgb.width, rgb.height);
  ld.offset_scan = !job.depth.velodyne.empty();
  if (!rgb.empty() && (ld.range.width != rgb.width || ld.range.height != rgb.height))
    throw Error("depth '" + ld.path + "' is " + ld.range.size_string() + " but --image '" + job.image + "' is " +
                rgb.size_string() + "; they must be the same size (resample the depth map, or crop both)");
  const CompletedRange done = complete_step(ld.range, rgb, with_camera(step, ld), ctx.given);
  PrepareResult pr = prepare_range(done.applied ? done.range : ld.range, job.prepare);
  nlohmann::json rec = run_record_header("depth prepare", ctx.argv);
  rec["job"] = depth_prepare_job_table().to_json(job);
  rec["depth"] = ld.record;
  if (!image_record.is_null()) rec["image"] = image_record;
  rec["complete"] = done.record;
  if (done.record.contains("warnings"))
    for (const auto& w : done.record["warnings"])
      print_warning("depth prepare", w.get<std::string>());
  rec["prepare"] = prepare_record(job.prepare, pr);
  WriteOptions w = data;
  w.description = rec.dump();
  OutputSet outs;
  outs.write(job.out, pr.range, w, "--out");
  if (!job.masks.empty()) {
    WriteOptions m;
    m.is_color = false;
    m.bits = "8";
    outs.write((fs::path(job.masks) / "sky.png").string(), pr.sky_mask, m, "--masks");
    outs.write((fs::path(job.masks) / "holes.png").string(), pr.hole_mask, m, "--masks");
    outs.write((fs::path(job.masks) / "margin.png").string(), pr.margin_mask, m, "--masks");
    WriteOptions c;
    c.bits = "8";
    outs.write((fs::path(job.masks) / "prepared-preview.png").string(), range_preview(pr.range), c, "--masks");
  }
  if (!job.record.empty()) outs.write_text(job.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  return rec;
}

const ParamTable<DepthCompleteJob>& depth_complete_job_table() {
  static const ParamTable<DepthCompleteJob> t = [] {
    ParamTable<DepthCompleteJob> d("output");
    d.nest(&DepthCompleteJob::input, input_param_table(true))
        .nest(&DepthCompleteJob::complete, complete_param_table())
        .text("out", &DepthCompleteJob::out, "completed range in metres along the ray, float file (.exr, .pfm, .tif); "
                                             "NaN at the sky")
        .writes_file()
        .text("confidence", &DepthCompleteJob::confidence, "per-pixel confidence in [0, 1] (1 at measurements)")
        .writes_file()
        .text("record", &DepthCompleteJob::record, "write a JSON record of the completion")
        .writes_file();
    return d;
  }();
  return t;
}

nlohmann::json run_depth_complete_job(const DepthCompleteJob& job, const ExecOptions& eo, const RunContext& ctx) {
  depth_complete_job_table().validate(job);
  const WriteOptions data = metres("a range in metres needs a float file");
  WriteOptions conf;
  conf.is_color = false;
  if (job.out.empty()) throw Error("no output given: use --out FILE");
  check_writable(job.out, data, "--out");
  if (!job.confidence.empty()) check_writable(job.confidence, conf, "--confidence");
  if (!job.record.empty()) check_record_path(job.record);
  LoadedInputs in = load_inputs(job.input, true);
  check_stereo_fattening_given(in.depth.fusion != nullptr, ctx.given);
  CompleteParams cp = job.complete;
  cp.offset_scan = in.depth.offset_scan;
  CompleteResult cr = complete_range(in.depth.range, in.rgb, cp, eo.threads,
                                     in.depth.camera ? &*in.depth.camera : nullptr);
  nlohmann::json fusion;
  if (in.depth.fusion) fusion = fuse_stereo(cr, in.depth.range, *in.depth.fusion, cp.radius_px, cp.stereo_fattening_px);
  nlohmann::json rec = run_record_header("depth complete", ctx.argv);
  rec["job"] = depth_complete_job_table().to_json(job);
  rec["inputs"] = in.record;
  rec["complete"] = complete_record(cp, cr);
  if (in.depth.fusion) rec["complete"]["stereo_fusion"] = fusion, rec["complete"]["stereo_fusion"]["fit"] = in.depth.fusion->record;
  WriteOptions w = data;
  w.description = rec.dump();
  OutputSet outs;
  outs.write(job.out, cr.range, w, "--out");
  if (!job.confidence.empty()) outs.write(job.confidence, cr.confidence, conf, "--confidence");
  if (!job.record.empty()) outs.write_text(job.record, rec.dump(2) + "\n", "--record");
  outs.commit();
  return rec;
}

CommandDef depth_complete_command() {
  CommandDef c = make_command<DepthCompleteJob>({
      .name = "depth complete",
      .cli = "depth complete",
      .summary = "complete a sparse range map (a lidar scan) guided by its colour image; the sky stays unknown",
      .table = &depth_complete_job_table(),
      .takes_exec_flags = true,
      .writes_record = true,
      .run = [](const DepthCompleteJob& j, const ExecOptions& eo, const RunContext& ctx) {
        return run_depth_complete_job(j, eo, ctx);
      },
      .report = [](const DepthCompleteJob& job, const nlohmann::json& rec) {
        const auto& c = rec["complete"];
        std::fprintf(stderr,
                     "brume depth complete: %s  measured %.2f %% -> completed %.1f %% (refined %.1f %%, "
                     "extrapolated %.1f %%), sky %.1f %%, unknown %.2f %%\n",
                     job.out.c_str(), 100 * c["known_fraction"].get<double>(),
                     100 * c["completed_fraction"].get<double>(), 100 * c["refined_fraction"].get<double>(),
                     100 * c["extrapolated_fraction"].get<double>(), 100 * c["sky_fraction"].get<double>(),
                     100 * c["unknown_fraction"].get<double>());
        if (c.contains("stereo_fusion"))
          std::fprintf(stderr, "brume depth complete: the second view: %.1f %% of the pixels from the pair (fit d_s = "
                       "%.4f d %+.3f px over %zu pixels both see)\n",
                       100 * c["stereo_fusion"]["stereo_fraction"].get<double>(),
                       c["stereo_fusion"]["fit"]["scale"].get<double>(),
                       c["stereo_fusion"]["fit"]["offset_px"].get<double>(),
                       c["stereo_fusion"]["fit"]["pixels_both_see"].get<std::size_t>());
      },
  });
  // brume.depth.complete(rgb, range): the completion on arrays.
  static const auto call = array_call_table(complete_param_table(), kArrayExec);
  c.arrays = make_array_form<CompleteParams>(
      "depth_complete", "brume.depth.complete",
      "Depth completion guided by the colour image: a sparse range map (NaN, inf or 0 unknown) to a dense one "
      "(metres along the ray; NaN at the sky) with a per-pixel confidence. As `brume depth complete`, on arrays.",
      {{"rgb", 3, false, ArrayArg::As::dense}, {"range", 1, false, ArrayArg::As::dense}}, call,
      {"range", "confidence", "sky_mask", "record"}, true,
      [](const std::vector<ArrayIn>& in, ArrayCall<CompleteParams>& k, const Exec& exec,
         const std::set<std::string>& given) {
        complete_param_table().validate(k.p);
        check_stereo_fattening_given(false, given);  // (arrays have no second view)
        CompleteResult cr = complete_range(in[1].dense, in[0].dense, k.p, exec.threads);
        ArrayResult r;
        r.record["complete"] = complete_record(k.p, cr);
        r.images = {{"range", std::move(cr.range)},
                    {"confidence", std::move(cr.confidence)},
                    {"sky_mask", std::move(cr.sky_mask)}};
        return r;
      });
  return c;
}

CommandDef depth_convert_command() {
  CommandDef c = make_command<DepthConvertJob>({
      .name = "depth convert",
      .cli = "depth convert",
      .summary = "convert a depth source to a range (or z) map in metres",
      .table = &depth_convert_job_table(),
      .writes_record = true,
      .run = [](const DepthConvertJob& j, const ExecOptions&, const RunContext& ctx) {
        return run_depth_convert_job(j, ctx);
      },
      .report = [](const DepthConvertJob& job, const nlohmann::json& rec) {
        const auto& d = rec["depth"];
        const double w = rec["result"]["width"].get<double>(), h = rec["result"]["height"].get<double>();
        const std::size_t unknown = rec["result"]["unknown_pixels"].get<std::size_t>();
        std::fprintf(stderr, "brume depth convert: %s  %s  %.0fx%.0f  %.2f %% unknown", job.out.c_str(),
                     job.kind.c_str(), w, h, w * h > 0 ? 100.0 * unknown / (w * h) : 0.0);
        if (!job.depth.velodyne.empty())
          std::fprintf(stderr, "  (lidar: %zu of %zu points in view, coverage %.2f %% of pixels)",
                       d["points_in_view"].get<std::size_t>(), d["points"].get<std::size_t>(),
                       100.0 * d["coverage"].get<double>());
        std::fprintf(stderr, "\n");
      },
  });
  // brume.depth.convert(**sources): the file in, the map out as an array.
  static const auto call = array_call_table(depth_convert_job_table(), kArrayNone, {"out", "record"});
  c.arrays = make_array_form<DepthConvertJob>(
      "depth_convert", "brume.depth.convert",
      "Every depth source to a range map (metres along the ray; kind='z': planar depth), read from its file with "
      "its conventions. Exactly one source keyword (range=, z=, disparity=, depth_buffer=, inverse_depth=, "
      "normalized_depth=, velodyne=). As `brume depth convert`.",
      {}, call, {"range", "record"}, false,
      [](const std::vector<ArrayIn>&, ArrayCall<DepthConvertJob>& k, const Exec&, const std::set<std::string>&) {
        ArrayResult r;
        depth_convert_job_table().validate(k.p);
        refuse_fusion(k.p.depth, "brume.depth.convert");
        LoadedDepth ld = load_depth(k.p.depth);
        Image result = std::move(ld.range);
        r.record["depth"] = ld.record;
        if (k.p.kind == "z") {
          const Intrinsics ki = depth_camera(k.p.depth, result.width, result.height).k;
          result = range_to_z(result, ki);
          r.record["z_intrinsics"] = {{"fx_px", ki.fx}, {"fy_px", ki.fy}, {"cx_px", ki.cx}, {"cy_px", ki.cy}};
        }
        r.record["kind"] = k.p.kind;
        r.record["result"] = {{"width", result.width}, {"height", result.height},
                              {"unknown_pixels", unknown_range_pixels(result)}};
        r.images[k.p.kind == "z" ? "z" : "range"] = std::move(result);
        return r;
      });
  return c;
}

CommandDef depth_prepare_command() {
  CommandDef c = make_command<DepthPrepareJob>({
      .name = "depth prepare",
      .cli = "depth prepare",
      .summary = "fill holes, identify the sky and matte the horizon (Hansard 4.1)",
      .table = &depth_prepare_job_table(),
      .writes_record = true,
      .run = [](const DepthPrepareJob& j, const ExecOptions&, const RunContext& ctx) {
        return run_depth_prepare_job(j, ctx);
      },
      .report = [](const DepthPrepareJob& job, const nlohmann::json& rec) {
        const auto& p = rec["prepare"];
        std::fprintf(stderr,
                     "brume depth prepare: %s  known %.1f %%, %zu holes (%.2f %%), sky %.1f %% at S_max %.4g m "
                     "(R_max %.4g m), margin %.2f %% solved to residual %.2g in %d iterations\n",
                     job.out.c_str(), 100 * p["known_fraction"].get<double>(), p["holes"].get<std::size_t>(),
                     100 * p["hole_fraction"].get<double>(), 100 * p["sky_fraction"].get<double>(),
                     p["s_max_m"].get<double>(), p["range_max_m"].get<double>(),
                     100 * p["margin_fraction"].get<double>(), p["margin_residual"].get<double>(),
                     p["solver_iterations"].get<int>());
      },
  });
  // brume.depth.prepare(range): the preparation on an array.
  static const auto call = array_call_table(prepare_param_table(), kArrayNone);
  c.arrays = make_array_form<PrepareParams>(
      "depth_prepare", "brume.depth.prepare",
      "Range preparation (Hansard 4.1): fill holes, identify the sky (set to S_max) and matte the horizon. As "
      "`brume depth prepare`, on an array.",
      {{"range", 1, false, ArrayArg::As::dense}}, call, {"range", "sky_mask", "hole_mask", "margin_mask", "record"},
      false, [](const std::vector<ArrayIn>& in, ArrayCall<PrepareParams>& k, const Exec&, const std::set<std::string>&) {
        prepare_param_table().validate(k.p);
        PrepareResult pr = prepare_range(in[0].dense, k.p);
        ArrayResult r;
        r.record["prepare"] = prepare_record(k.p, pr);
        r.images = {{"range", std::move(pr.range)},
                    {"sky_mask", std::move(pr.sky_mask)},
                    {"hole_mask", std::move(pr.hole_mask)},
                    {"margin_mask", std::move(pr.margin_mask)}};
        return r;
      });
  return c;
}

}  // namespace brume
