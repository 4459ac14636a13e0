// brume — what every effect's pipeline shares: the declared parameter blocks
// (diffusion, preparation, depth source, input, output, execution), loading
// the inputs, preparing the range, choosing the backend, and writing the
// outputs with the parameter record. An effect adds only its own parameter
// block, its pipeline function (analysis + apply on each backend) and its
// passes; the CLI, `brume run` and later the Python module call the pipeline.
//
//   files ──► load_inputs (decode, depth → range) ──► prepare_step ──► effect
//         ──► write_outputs (encoding rules, record, atomic rename)
//
// Records (schema_version 4) hold the whole job — every declared parameter
// of every block, under "job" — next to what the run derived and measured,
// so `brume run record.json` repeats the run. Schema 3 (issue #40) changed the sky under a medium in metres (brume/haze.hpp, "The sky");
// schema 4 (issue #49) opens a wave whose parameters with new rules (the
// renderer's background, the completion method, the slant path, ...) come
// `since(4, …)`, no schema of their own. A parameter that a later schema introduced
// with a new rule declares the value that reproduces the older rule
// (ParamSpec::since_schema), and `brume run` gives it to an older record's
// job that lacks it; tests/records holds a record of each older schema that
// must keep repeating bit for bit (tests/test_records.cpp).
#pragma once

#include <array>
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/camera.hpp"
#include "brume/complete.hpp"
#include "brume/depth_source.hpp"
#include "brume/diffusion.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/prepare.hpp"
#include "brume/range_step.hpp"

namespace brume {

constexpr int kRecordSchemaVersion = 4;
constexpr int kOldestRecordSchemaVersion = 2;  // the oldest `brume run` repeats

// ---- shared parameter blocks --------------------------------------------------
// (The engines' blocks and name tables are declared with their enums:
// diffusion_param_table and the scheme, precision and edge-rate names in
// brume/diffusion.hpp, prepare_param_table in brume/prepare.hpp,
// transfer_names in brume/io.hpp, backend_names and gpu_filter_names in
// brume/exec.hpp.)
const ParamTable<DepthSource>& depth_param_table();          // every depth source and convention flag
// The camera in millimetres (brume/depth.hpp: LensCamera), declared once and
// nested in the depth block (every command that takes intrinsics) and the
// sky's pinhole view; `block` is the record block it lands in.
const ParamTable<LensCamera>& lens_param_table(const std::string& block);
// The names of the depth block that name files or say how to read them: all
// but the intrinsics (fx, fy, cx, cy, fov-x, fov-y, calib, and the camera in
// millimetres), which an array caller still gives for fog's and dof's camera.
const std::set<std::string>& depth_file_params();
// The depth block's parameters that give the camera's intrinsics as numbers
// (fx, fy, cx, cy, fov-x, fov-y): an array caller's camera, and the camera
// controls of brume view's page.
const std::vector<std::string>& camera_intrinsics_params();

// The camera's pose's table, camera_pose_param_table(): brume/camera.hpp.

// Execution: how, not what (results do not depend on it, except the GPU's
// float rounding); recorded, but not part of a job.
struct ExecOptions {
  int threads = 0;        // 0 = all cores
  bool reference = false; // the scalar double-precision path
  Backend backend = Backend::cpu;
  GpuFilter gpu_filter = GpuFilter::automatic;
  bool timing = false;    // print per-pass times
  // Not a parameter (no flag, never recorded: it changes no output): a GPU
  // context to run on, made by the caller on the thread that runs the job
  // (brume batch keeps one per worker, so that its frames share the
  // context and its compiled passes); null: the job makes its own.
  GpuContext* gpu = nullptr;
  Exec exec() const;      // checked: --reference only on the CPU
};
const ParamTable<ExecOptions>& exec_param_table();

// The colour image and the depth of an effect's input.
// NaN or ±inf in a colour input: a diffusion would smear one over its whole
// neighbourhood, so by default they are an error naming their count and the
// first one; `zero` replaces them by 0 (the count is recorded). Negative values
// are legitimate in linear float images and pass untouched.
enum class NonFinite { error, zero };
const EnumNames<NonFinite>& nonfinite_names();

// The one check of a colour input's values, for the CLI's files and
// Python's arrays alike: the count of NaN and +-inf values; with `error`, an
// Error naming `what` ("--image 'x.png'", "rgb"), the count, the first value
// (x, y, channel) and `fix` ("Fix the file, or pass --nonfinite zero").
// replace_nonfinite makes them 0 (the caller records the count).
std::size_t check_nonfinite_colour(ConstImageView rgb, NonFinite mode, const std::string& what,
                                   const std::string& fix);
void replace_nonfinite(Image& rgb);

struct InputFiles {
  std::string image;                       // colour image
  std::string image_layer;                 // its layer in a file with layers (brume/io.hpp: ColorRead); "": plain
  LayerRule image_layer_rule = LayerRule::names;  // --image-layer-rule: no layer named, by name or the first channels
  TransferFunction image_transfer = Transfer::automatic;  // --image-transfer (brume/io.hpp)
  NonFinite nonfinite = NonFinite::error;
  DepthSource depth;                       // needs_depth effects only
};
const ParamTable<InputFiles>& input_param_table(bool with_depth);

// The step with the camera of the loaded depth (for the planar completion)
// and its stereo view to fuse, if any, and whether it is a scan from beside
// the camera (for the occlusion rule).
inline RangeStep with_camera(RangeStep step, const LoadedDepth& depth) {
  step.camera = depth.camera;
  step.stereo = depth.fusion;
  step.completion.offset_scan = depth.offset_scan;
  return step;
}

// ---- --scene-scale: an effect's lengths given for a reference frame, scaled to this one ----
// A dataset's frames span rooms (Middlebury 2005: median range 1.8 m) and
// streets (KITTI: 14 m): one distribution of visibilities in metres fogs one
// and leaves the other clear. With --scene-scale R_ref the effect's lengths
// (its own list, e.g. haze's --visibility, fog's --density, depth of field's
// --focus-distance) are read as given for a frame whose median range is
// R_ref; the run scales them by f = (this frame's median range) / R_ref, a
// length [m] times f, a coefficient [1/m] over f, so that the optical depth
// -- and the transmission -- at the frame's median range is the one the
// values give on the reference frame, whatever the frame's size. The job and
// its record keep the values as given (what brume sample and random_params
// draw); the record's "scene_scale" block holds the frame's statistic, f and
// each value as given and as applied. 15 m suits the samplers' default ranges
// (chosen for street-level outdoor frames: KITTI 000001's median range is
// 14.3 m).
struct SceneScale {
  std::optional<double> reference_m;  // [m] > 0; unset ("off"): the lengths are metres, as given
};
const ParamTable<SceneScale>& scene_scale_param_table();
// The median of a range map's known values (finite, > 0); NaN when it has none.
double median_known_range(ConstImageView range);
// The lengths `names` of p scaled to the frame (see SceneScale); the record
// block, or null when `s` is off. Throws when the range has no known value.
template <class P>
nlohmann::json apply_scene_scale(const ParamTable<P>& t, P& p, const std::vector<std::string>& names,
                                 const SceneScale& s, ConstImageView measured) {
  if (!s.reference_m) return nullptr;
  const double median = median_known_range(measured);
  if (!(median > 0.0))
    throw Error("--scene-scale scales the effect's lengths by the frame's median range, but the range map has no "
                "known value");
  const double f = median / *s.reference_m;
  nlohmann::json scaled = nlohmann::json::object();
  for (const std::string& n : names) {
    const Param<P>& d = t.at(n);
    const nlohmann::json v = d.get(p);
    if (!v.is_number()) continue;  // unset: nothing to scale
    const double given = v.get<double>();
    double applied = 0.0;
    if (d.spec.unit == "m") applied = given * f;
    else if (d.spec.unit == "1/m") applied = given / f;
    else
      throw Error("internal: --scene-scale scales metres and coefficients per metre; --" + n + " is in " + d.spec.unit);
    d.spec.check(applied);
    d.set(p, applied);
    scaled[n] = {{"given", given}, {"applied", applied}};
  }
  return {{"reference_median_range_m", *s.reference_m},
          {"median_range_m", median},
          {"factor", f},
          {"statistic", "median of the known values of the measured range (finite, > 0), before completion"},
          {"rule", "a length [m] times factor, a coefficient [1/m] over it"},
          {"scaled", scaled}};
}

// An output map besides the main image, declared by the effect.
struct MapOutput {
  const char* name;          // flag and record key, e.g. "transmission"
  const char* help;
  const char* float_reason;  // non-empty: values leave [0, 1]; integer files are refused
};

// An OpenEXR output's alpha (docs/renderers.md): auto carries the input's
// alpha as the medium composes it (A' = T A + (1 - T)); off drops it (the
// rule of records before schema 4).
enum class OutAlpha { automatic, off };
const EnumNames<OutAlpha>& out_alpha_names();
// --image-layer-rule, --depth-channel-rule (brume/io.hpp: LayerRule): names | first.
const EnumNames<LayerRule>& layer_rule_names();

struct OutputFiles {
  std::string out;                       // main image
  std::string bits = "auto";             // auto | 8 | 16 | half | float
  Transfer transfer = Transfer::automatic;
  std::string compression = "auto";      // main image's NAME[:LEVEL] (WriteOptions::compression)
  OutAlpha alpha = OutAlpha::automatic;  // --out-alpha
  bool keep_layers = false;              // --keep-layers: the input's other channels, the medium and maps as layers
  std::string record;                    // JSON record (optional)
  std::map<std::string, std::string> maps;  // declared map outputs that were asked for
};
const ParamTable<OutputFiles>& output_param_table(const std::vector<MapOutput>& maps, bool main_required = true);
// Whether a parameter names a file the run writes: its spec's output_file
// flag, set (ParamTable::writes_file) on the output block's --out, --record
// and maps, and on depth convert's and depth prepare's --out, --record and
// --masks -- not on --compression, a setting like --bits. brume batch names
// these files from the frame's key and brume run moves them under --out-dir.
bool is_output_file(const ParamSpec& s);
// Whether a parameter of the input and depth blocks names an input file: a
// text parameter there, but for those that name a channel or a layer inside
// one (--depth-channel, --image-layer, --stereo-right-layer, ...). brume
// batch resolves these against the manifest's folder and lists them.
bool is_input_file(const ParamSpec& s);

// ---- the shared steps -------------------------------------------------------------
// Keep freed buffers for reuse within this process (glibc): blocks up to 32
// MB come from the heap and its free top is not trimmed, so that a buffer
// freed mid-run or by the previous frame is reused without the kernel
// faulting in and clearing fresh pages (pipeline.cpp says how much that
// saved). Resident memory stays at the run's peak, which the memory check
// admits. Set once per process: by the command line at start and by each
// batch frame (brume batch, brume.dask workers); a program embedding brume
// (the Python module) is left to choose for itself.
void keep_freed_heap();

struct LoadedInputs {
  Image rgb;              // linear RGB
  Image alpha;            // the image's alpha (1 channel, as stored; empty when it has none)
  FileInfo image_info;
  LoadedDepth depth;      // measured range (metres along the ray, NaN unknown) and its record
  nlohmann::json record;  // {"image": file record, "depth": ...}
};
LoadedInputs load_inputs(const InputFiles& in, bool with_depth);
// An effect that estimates its airlight from the sky (haze, fog, aerial with
// --airlight auto) on a render whose film is transparent: its sky has alpha
// 0 and colour 0 (premultiplied), not the sky's colour, so the estimate would
// be black. Refused, naming --airlight, when at least half of the unknown-
// range pixels (>= 0.5 % of the frame) have alpha below 1/2.
void check_airlight_sky(const LoadedInputs& in, const std::string& effect);

// Wall time of a run's file work, for --timing's whole-run line: reading and
// decoding the inputs, depth conversion included (load_inputs), encoding and
// writing the outputs' temporaries, and renaming them into place
// (write_outputs); `read_end`/`write_begin` bound the effect between them.
// Per thread (brume batch's workers run frames side by side).
struct RunPhases {
  double read_ms = 0.0, write_ms = 0.0, rename_ms = 0.0;
  double codec_load_ms = 0.0;  // loading brume_codec.so (OpenImageIO), inside the read or write that needed it
  std::chrono::steady_clock::time_point read_end{}, write_begin{};
};
RunPhases& run_phases();
// Before an effect starts on a frame: its working memory (`bytes_per_pixel`,
// the effect's measured peak less what is already held) must fit in what the
// process may still use (check_memory), or a brume::Error says so.
void check_working_memory(const std::string& effect, const Image& frame, double bytes_per_pixel);


// The GPU context a run uses: Exec::gpu if the caller passed one; for
// Backend::gpu a new context or an error saying why; for Backend::automatic
// a new context only when its renderer is hardware (a software rasteriser
// measured 1.7-30x slower than the CPU backend), else none with a note.
struct BackendChoice {
  GpuContext* gpu = nullptr;  // null: run on the CPU
  std::unique_ptr<GpuContext> owned;
  nlohmann::json record;      // execution.backend, execution.gpu.renderer, ...
  BackendChoice();
  ~BackendChoice();
  BackendChoice(BackendChoice&&) noexcept;
  BackendChoice& operator=(BackendChoice&&) noexcept;
};
BackendChoice choose_backend(const Exec& exec);

// The record's directory exists and is writable (before any work).
void check_record_path(const std::string& path);
// Before any work: every output location writable with its options.
void check_outputs(const OutputFiles& o, const std::vector<MapOutput>& decl);
// An OpenEXR output for a compositor (docs/renderers.md), planned before the
// record is written (the record names its channels):
//  - the colour layer read (its names: ViewLayer.Combined.R, ...; plain R, G,
//    B) with, when the input has alpha and --out-alpha auto, the alpha the
//    medium composes, premultiplied "over": A' = T A + (1 - T) (the colour
//    already is T C + (1 - T) B); no medium: A as read;
//  - with --keep-layers: every other channel of the input as stored (its
//    type kept), the medium as its own RGBA layer (<view>.Medium: (1 - T) B,
//    1 - T), and each map of the run as a layer (<view>.Transmission,
//    <view>.BlurScale, ...), <view> the colour layer's prefix (ViewLayer).
// Not OpenEXR, or nothing to add: `image` empty, the main image is written
// as it always was.
struct OutputLayers {
  Image image;
  std::vector<std::string> names;
  std::vector<int> bits;
  std::vector<std::pair<std::string, std::string>> attributes;
  nlohmann::json record;  // the record's "output_layers" (null: none)
};
// Encoding rules shared by every effect: `bits auto` keeps an 8/16-bit
// input's depth in PNG/TIFF (JPEG 8, EXR/PFM/HDR float); maps are data,
// never sRGB-encoded; the record is embedded as ImageDescription and written
// beside; everything is renamed into place together or not at all.
// A file a run writes besides its image, maps and record (a camera effect's
// foggy LiDAR scan, brume/lidar_camera.hpp): its bytes, renamed into place
// with the rest. `flag` names it in messages.
struct CompanionFile {
  std::string path, bytes, flag;
};
void write_outputs(const OutputFiles& o, const std::vector<MapOutput>& decl, const Image& main,
                   const std::map<std::string, Image>& maps, const FileInfo* input_info, const nlohmann::json& record,
                   const std::vector<CompanionFile>& companions = {}, const OutputLayers* layers = nullptr);

// tool, version, schema_version, command, argv, time
nlohmann::json run_record_header(const std::string& command, const std::vector<std::string>& argv);

// The "execution.timing" of a record: the GPU's stages (timer queries, else
// glFinish wall time; only the stages that ran), or the CPU's wall time since t0.
struct GpuTiming;
nlohmann::json gpu_timing_record(const GpuTiming& t);
nlohmann::json cpu_timing_record(std::chrono::steady_clock::time_point t0, int iterations);

// What a pipeline needs to know about the run beyond its job.
struct RunContext {
  std::vector<std::string> argv;  // for the record
  std::set<std::string> given;    // parameter names set explicitly (CLI flags, record keys)
  // Top-level blocks added to the record (an object, or null for none), e.g.
  // `brume batch`'s {"batch": {key, seed, sampling, values}}.
  nlohmann::json extra;
  // Files written with the outputs, all or none (write_outputs' companions):
  // a camera effect's foggy scan (brume/lidar_camera.hpp). Its input's
  // {"path", "sha256"} goes in extra's "inputs", which job_record merges
  // into the record's inputs (so `brume run` checks it).
  std::vector<CompanionFile> files;
  // Draws a command's figure from its result (sky fit's --plot): the command
  // line's plotter; a library caller without one gets an error naming the flag.
  Image (*plot)(const nlohmann::json& result) = nullptr;
};

// A job's record: header, the whole job, its inputs, then what the run
// derived (run_record's keys); with print_timing, the execution timing goes
// to stderr. Every effect's run_*_job ends with it.
nlohmann::json job_record(const std::string& command, const RunContext& ctx, nlohmann::json job, nlohmann::json inputs,
                          const nlohmann::json& run_record, bool print_timing);

// ---- the job of an effect on an RGB-D frame, from files to files --------------------
// What an effect's run hands its job: the main image, its declared maps and
// the record's blocks (run_record); a medium's effect names the map of the
// transmission T its colour was composed with (out = ... + (1 - T) B) and
// its airlight B, for an OpenEXR output's alpha and medium layer.
struct EffectOutput {
  Image main;
  std::map<std::string, Image> maps;
  nlohmann::json record;
  std::string medium_map = "";            // "transmission", or empty (no medium: the alpha passes through)
  std::array<float, 3> medium_airlight{};  // B, linear RGB
};

// `in` null: a command without an input image (--keep-layers refused).
OutputLayers compose_output_layers(const OutputFiles& o, const LoadedInputs* in, const EffectOutput& out);

// The steps every such job takes, in this order: every parameter checked (the
// table's ranges, the effect's `check` -- cross-field rules, backend limits
// --, the range step) and every output location, before any file is read;
// the image and depth read (load_inputs); the working memory checked
// (`bytes_per_pixel`: the effect's measured peak, docs/reliability.md);
// `apply` on the loaded inputs (it may add to in.record, the record's
// "inputs"); the record (of `recorded`, when the job recorded differs from the
// one run: aerial's fitted turbidity is recorded as auto); the outputs
// written together. Job has the members input, prepare and output.
template <class Job>
struct EffectJob {
  const char* command;
  const ParamTable<Job>& table;
  const std::vector<MapOutput>& maps;
  double bytes_per_pixel;
  std::function<void(const Job&, const ExecOptions&)> check;
  std::function<EffectOutput(const Job&, LoadedInputs&, const Exec&)> apply;
};

template <class Job>
nlohmann::json run_effect_job(const EffectJob<Job>& e, const Job& job, const ExecOptions& eo, const RunContext& ctx,
                              const Job* recorded = nullptr) {
  // Every parameter is checked before any file is touched, whatever the input.
  e.table.validate(job);
  e.check(job, eo);
  check_range_step(job.prepare, ctx.given);
  const Exec exec = eo.exec();
  check_outputs(job.output, e.maps);

  LoadedInputs in = load_inputs(job.input, true);
  check_working_memory(e.command, in.rgb, e.bytes_per_pixel);
  EffectOutput out = e.apply(job, in, exec);
  const OutputLayers layers = compose_output_layers(job.output, &in, out);
  if (!layers.record.is_null()) out.record["output_layers"] = layers.record;

  const nlohmann::json rec =
      job_record(e.command, ctx, e.table.to_json(recorded ? *recorded : job), in.record, out.record, eo.timing);
  write_outputs(job.output, e.maps, out.main, out.maps, &in.image_info, rec, ctx.files, &layers);
  return rec;
}

}  // namespace brume
