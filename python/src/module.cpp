// brume._brume — the Python binding (pybind11). Every keyword of every
// function comes from the parameter tables that make the CLI's flags and the
// JSON records (brume/params.hpp): a function's table is the effect's own
// table nested with the shared blocks it takes (range preparation, execution,
// intrinsics), and ONE generic routine (keyword_values) turns **kwargs into
// checked values -- names (flag `--f-number` -> keyword `f_number`,
// `lambda` -> `lambda_`, aliases too), Python types, ranges. Docstrings and
// the type stubs (_brume.pyi, written at build time by python/gen_stubs.py)
// are generated from the same tables, so help(brume.haze) shows the CLI's help.
//
// The effects on (rgb, range) arrays are the array forms of the library's
// list of commands (CommandDef::arrays, defined beside each pipeline): one
// loop binds them all (def_array_command). The other functions (blur, depth,
// sky, random_params, I/O) are bound below, each a table and a lambda.
//
// Conventions (the README's Python section):
//  - images are numpy arrays H x W x 3 (or x 4, alpha ignored) of linear RGB;
//    ranges H x W (or H x W x 1) float metres. float32 is read in place
//    whenever its channels are contiguous (any row/pixel strides: a crop is
//    still no copy); float64 is converted once; uint8/uint16 need
//    transfer="srgb"|"linear" (the CLI's rule for integer files); anything
//    else is a ValueError naming the argument, its shape and dtype.
//  - the GIL is released while the library runs (after every Python object
//    has been read), so Python threads run effects concurrently; results do
//    not depend on threads= or on concurrency.
//  - GPU: backend="gpu"|"auto" runs on an OpenGL ES context of the calling
//    thread, made by that thread's first GPU call and reused by its later
//    ones (making one costs tens of ms), destroyed when the thread exits; a
//    context never crosses threads (thread_gpu).
//  - errors: brume::FileNotFound -> FileNotFoundError, GpuUnavailable ->
//    RuntimeError, every other brume::Error -> ValueError with the library's
//    message; wrong Python types -> TypeError; unknown keywords -> TypeError
//    naming the nearest valid ones.
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "binding.hpp"
#include "brume/batch.hpp"
#include "brume/blur.hpp"
#include "brume/depth.hpp"
#include "brume/depth_pipeline.hpp"
#include "brume/error.hpp"
#include "brume/prepare.hpp"
#include "brume/record.hpp"
#include "brume/sample.hpp"
#include "brume/sky.hpp"

namespace brume::python {

// ==== the commands on arrays: (rgb, range, **keywords) -> Result ===========================
// Every command of the library's list with an array form (CommandDef::arrays:
// haze, aerial, fog, dof) is bound here as brume.<function>; nothing here
// names one. The form runs without the GIL on the arrays in place (its
// views), or on dense images (the caller's pixels when C-contiguous).
void def_array_command(py::module_& m, const CommandDef& c) {
  const ArrayForm& a = *c.arrays;
  const std::string fn = "brume." + a.function;
  FunctionDoc doc = make_doc(a.function, fn, "rgb: npt.NDArray[Any], range: npt.NDArray[Any]", a.summary, a.specs,
                             a.defaults,
                             {{"transfer", "Literal[\"srgb\", \"linear\"] | None",
                               "uint8/uint16 rgb only: 'srgb' (PNG/JPEG-like) or 'linear'; float arrays are linear"},
                              {"job", "dict[str, Any] | None",
                               "a record's \"job\" (Result.record['job'], or a CLI record's): replays that run, "
                               "bit for bit on the CPU, as `brume run` does; other keywords override its values"}},
                             a.fields);
  doc.command = c.name;
  doc.replays = true;
  registry().push_back(doc);
  const std::string command = c.name;
  m.def(
      a.function.c_str(),
      [&a, fn, command](py::object rgb_obj, py::object range_obj, py::kwargs kw) {
        py::dict k = py::dict(kw);
        const Transfer tr = parse_transfer_kw(k.contains("transfer") ? py::object(k["transfer"]) : py::object(py::none()), fn + "()");
        if (k.contains("transfer")) PyDict_DelItemString(k.ptr(), "transfer");
        JobValues values;
        if (k.contains("job")) {
          py::object job = k["job"];
          PyDict_DelItemString(k.ptr(), "job");
          if (!job.is_none()) values = job_values(a.specs, job, fn);
        }
        std::set<std::string> given;
        for (auto& v : keyword_values(a.specs, k, fn, given)) values.push_back(std::move(v));
        const json call = a.build(values);
        g_last_inputs.clear();
        Input rgb = read_input(rgb_obj, "rgb", 3, tr, fn);
        Input range = read_input(range_obj, "range", 1, Transfer::automatic, fn);
        if (a.dense) {
          as_dense(rgb, "rgb");
          as_dense(range, "range");
        }
        ExecOptions eo;
        if (call.contains("execution")) exec_param_table().from_json(eo, {{"execution", call["execution"]}}, fn);
        const Exec exec = eo.exec();
        ArrayResult out;
        {
          py::gil_scoped_release nogil;
          out = a.run({rgb.view, range.view, rgb.dense, range.dense}, call, with_thread_gpu(exec), given);
        }
        json rec = python_header(command, fn);
        rec["job"] = std::move(out.job);
        rec["inputs"] = {{"rgb", rgb.record}, {"range", range.record}};
        if (out.record.contains("sky_image")) {  // aerial's sky photo is an input, as in the CLI's record
          rec["inputs"]["sky_image"] = out.record["sky_image"];
          out.record.erase("sky_image");
        }
        rec.update(out.record);
        return make_result(std::move(out.images), rec);
      },
      py::arg("rgb"), py::arg("range"), docstring(doc).c_str());
}

// A table that lives as long as the module (functions keep a pointer).
template <class T>
const T* keep(T t) {
  return new T(std::move(t));
}

// ==== errors as Python exceptions ===========================
void register_errors() {
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const FileNotFound& e) {
      PyErr_SetString(PyExc_FileNotFoundError, e.what());
    } catch (const GpuUnavailable& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
    } catch (const Error& e) {
      std::string m = e.what();
      if (m.find("raise the limit with --max-pixels") != std::string::npos)
        m += " (in Python: brume.set_max_pixels(N))";
      PyErr_SetString(PyExc_ValueError, m.c_str());
    } catch (const nlohmann::json::exception& e) {
      PyErr_SetString(PyExc_ValueError, printable_text(e.what()).c_str());
    }
  });
}

}  // namespace brume::python

using namespace brume;
using namespace brume::python;

PYBIND11_MODULE(_brume, m) {
  m.doc() = "brume: physically based, depth-aware atmospheric and lens effects on numpy RGB-D images";
  m.attr("__version__") = BRUME_VERSION;
  register_errors();

  // ---- the commands on arrays (the library's list) ------------------------------------
  for (const CommandDef& c : commands())
    if (c.arrays) def_array_command(m, c);

  // ---- blur: the engine alone, the image read in place ---------------------------------
  {
    std::set<std::string> skip = names_of(input_param_table(false));
    for (const auto& n : names_of(output_param_table({}))) skip.insert(n);
    skip.insert("scale-map");  // a numpy argument here, not a file
    const auto* table = keep(call_table(blur_job_table(), kExec, skip));
    FunctionDoc doc = make_doc("blur", "brume.blur", "rgb: npt.NDArray[Any], scale_map: npt.NDArray[Any] | None = None",
                               "The diffusion engine alone: a Gaussian of sqrt(sigma^2 - sigma0^2) (sigma=) or a "
                               "space-variant blur to a per-pixel scale map in px (scale_map=). As `brume blur`. "
                               "A float32 rgb is read in place (no copy).",
                               *table,
                               {{"transfer", "Literal[\"srgb\", \"linear\"] | None", "uint8/uint16 rgb only"}},
                               {"rgb", "record"});
    registry().push_back(doc);
    m.def(
        "blur",
        [table](py::object rgb_obj, py::object map_obj, py::kwargs kw) {
          const std::string fn = "brume.blur";
          py::dict k = py::dict(kw);
          const Transfer tr = parse_transfer_kw(k.contains("transfer") ? py::object(k["transfer"]) : py::object(py::none()), fn + "()");
          if (k.contains("transfer")) PyDict_DelItemString(k.ptr(), "transfer");
          Call<BlurJob> c;
          set_keywords(*table, c, k, fn);
          g_last_inputs.clear();
          Input rgb = read_input(rgb_obj, "rgb", 3, tr, fn);
          std::optional<Input> smap;
          if (!map_obj.is_none()) {
            smap = read_input(map_obj, "scale_map", 1, Transfer::automatic, fn);
            as_image(*smap, "scale_map");
          }
          const Exec exec = c.exec.exec();
          BlurRun r;
          {
            py::gil_scoped_release nogil;
            r = run_blur(rgb.view, c.p.sigma, smap ? &smap->owned : nullptr, c.p.diffusion, with_thread_gpu(exec));
          }
          json rec = python_header("blur", fn);
          rec["job"] = job_json(*table, c);
          rec["inputs"] = {{"rgb", rgb.record}};
          if (smap) rec["inputs"]["scale_map"] = smap->record;
          rec.update(r.record);
          return make_result({{"rgb", std::move(r.rgb)}}, rec);
        },
        py::arg("rgb"), py::arg("scale_map") = py::none(), docstring(doc).c_str());
  }

  // ---- depth ----------------------------------------------------------------------------
  {
    std::set<std::string> skip = {"out", "record"};
    const auto* table = keep(call_table(depth_convert_job_table(), kNone, skip));
    FunctionDoc doc = make_doc("depth_convert", "brume.depth.convert", "",
                               "Every depth source to a range map (metres along the ray; kind='z': planar depth), "
                               "read from its file with its conventions. Exactly one source keyword (range=, z=, "
                               "disparity=, depth_buffer=, inverse_depth=, normalized_depth=, velodyne=). As "
                               "`brume depth convert`.",
                               *table, {}, {"range", "record"});
    registry().push_back(doc);
    m.def(
        "depth_convert",
        [table](py::kwargs kw) {
          const std::string fn = "brume.depth.convert";
          Call<DepthConvertJob> c;
          set_keywords(*table, c, py::dict(kw), fn);
          Image result;
          json rec = python_header("depth convert", fn);
          {
            py::gil_scoped_release nogil;
            depth_convert_job_table().validate(c.p);
            LoadedDepth ld = load_depth(c.p.depth);
            result = std::move(ld.range);
            rec["depth"] = ld.record;
            if (c.p.kind == "z") {
              const Intrinsics k = depth_camera(c.p.depth, result.width, result.height).k;
              result = range_to_z(result, k);
              rec["z_intrinsics"] = {{"fx_px", k.fx}, {"fy_px", k.fy}, {"cx_px", k.cx}, {"cy_px", k.cy}};
            }
          }
          rec["job"] = table->to_json(c);
          rec["kind"] = c.p.kind;
          rec["result"] = {{"width", result.width}, {"height", result.height},
                           {"unknown_pixels", unknown_range_pixels(result)}};
          return make_result({{c.p.kind == "z" ? "z" : "range", std::move(result)}}, rec);
        },
        docstring(doc).c_str());
  }
  {
    const auto* table = keep(call_table(prepare_param_table(), kNone));
    FunctionDoc doc = make_doc("depth_prepare", "brume.depth.prepare", "range: npt.NDArray[Any]",
                               "Range preparation (Hansard 4.1): fill holes, identify the sky (set to S_max) and "
                               "matte the horizon. As `brume depth prepare`, on an array.",
                               *table, {}, {"range", "sky_mask", "hole_mask", "margin_mask", "record"});
    registry().push_back(doc);
    m.def(
        "depth_prepare",
        [table](py::object range_obj, py::kwargs kw) {
          const std::string fn = "brume.depth.prepare";
          Call<PrepareParams> c;
          set_keywords(*table, c, py::dict(kw), fn);
          g_last_inputs.clear();
          Input range = read_input(range_obj, "range", 1, Transfer::automatic, fn);
          const DenseImageRef r_img = as_dense(range, "range");
          PrepareResult pr;
          {
            py::gil_scoped_release nogil;
            prepare_param_table().validate(c.p);
            pr = prepare_range(r_img, c.p);
          }
          json rec = python_header("depth prepare", fn);
          rec["job"] = table->to_json(c);
          rec["inputs"] = {{"range", range.record}};
          rec["prepare"] = prepare_record(c.p, pr);
          return make_result({{"range", std::move(pr.range)},
                              {"sky_mask", std::move(pr.sky_mask)},
                              {"hole_mask", std::move(pr.hole_mask)},
                              {"margin_mask", std::move(pr.margin_mask)}},
                             rec);
        },
        py::arg("range"), docstring(doc).c_str());
  }

  // ---- sky ------------------------------------------------------------------------------
  {
    const auto* table = keep(call_table(sky_render_param_table(), kExec));
    FunctionDoc doc = make_doc("sky_render", "brume.sky.render", "",
                               "A Preetham sky in linear sRGB (kcd/m^2 x exposure), NaN (or ground) below the "
                               "horizon. As `brume sky render`.",
                               *table, {}, {"rgb", "record"});
    registry().push_back(doc);
    m.def(
        "sky_render",
        [table](py::kwargs kw) {
          const std::string fn = "brume.sky.render";
          Call<SkyRenderParams> c;
          set_keywords(*table, c, py::dict(kw), fn);
          const Exec exec = c.exec.exec();
          SkyRenderRun r;
          {
            py::gil_scoped_release nogil;
            r = run_sky_render(c.p, with_thread_gpu(exec));
          }
          json rec = python_header("sky render", fn);
          rec["job"] = job_json(*table, c);
          rec["inputs"] = json::object();
          rec.update(r.record);
          return make_result({{"rgb", std::move(r.rgb)}}, rec);
        },
        docstring(doc).c_str());
  }
  {
    std::set<std::string> skip = {"image", "image-transfer", "mask", "out", "plot"};
    const auto* table = keep(call_table(sky_fit_job_table(), kNone, skip));
    FunctionDoc doc = make_doc("sky_fit", "brume.sky.fit", "rgb: npt.NDArray[Any], mask: npt.NDArray[Any] | None = None",
                               "Turbidity of a sky photo (Preetham model, RANSAC against clouds). mask: > 0.5 marks "
                               "usable sky. Integer rgb (transfer=) enables saturation detection, as an 8/16-bit "
                               "file does. As `brume sky fit`; the result's `fit` is its JSON.",
                               *table,
                               {{"transfer", "Literal[\"srgb\", \"linear\"] | None", "uint8/uint16 rgb only"}},
                               {"turbidity", "reliable", "fit", "record"});
    registry().push_back(doc);
    m.def(
        "sky_fit",
        [table](py::object rgb_obj, py::object mask_obj, py::kwargs kw) {
          const std::string fn = "brume.sky.fit";
          py::dict k = py::dict(kw);
          const Transfer tr = parse_transfer_kw(k.contains("transfer") ? py::object(k["transfer"]) : py::object(py::none()), fn + "()");
          if (k.contains("transfer")) PyDict_DelItemString(k.ptr(), "transfer");
          Call<SkyFitJob> c;
          set_keywords(*table, c, k, fn);
          g_last_inputs.clear();
          Input rgb = read_input(rgb_obj, "rgb", 3, tr, fn);
          const bool integer = py::reinterpret_borrow<py::array>(rgb_obj).dtype().kind() == 'u';
          const DenseImageRef img = as_dense(rgb, "rgb");
          std::optional<Input> mask;
          if (!mask_obj.is_none()) {
            mask = read_input(mask_obj, "mask", 1, Transfer::automatic, fn);
            Image& mk = const_cast<Image&>(as_image(*mask, "mask"));
            if (mk.width != img.width || mk.height != img.height)
              throw py::value_error(fn + "(): mask is " + mk.size_string() + " but rgb is " + img.size_string() +
                                    "; give a mask of the image's size");
            for (float& v : mk.data) v = v > 0.5f ? 1.0f : 0.0f;
          }
          SkyImageFit f;
          {
            py::gil_scoped_release nogil;
            sky_fit_job_table().validate(c.p);
            f = fit_sky_data(img, integer, mask ? &mask->owned : nullptr, c.p.view, c.p.sun, c.p.fit);
          }
          json rec = python_header("sky fit", fn);
          rec["job"] = table->to_json(c);
          rec["inputs"] = {{"rgb", rgb.record}};
          if (mask) rec["inputs"]["mask"] = mask->record;
          rec["fit_ms"] = f.fit_ms;
          return make_result({}, rec,
                             {{"turbidity", to_py(f.fit.value("turbidity", json()))},
                              {"reliable", to_py(f.fit.value("reliable", json(false)))},
                              {"fit", to_py(f.fit)}});
        },
        py::arg("rgb"), py::arg("mask") = py::none(), docstring(doc).c_str());
  }

  // ---- brume.random_params (issue #14 item 3): the library's sampler ------------------
  // Keyed by (seed, frame key, parameter name), never by call order, so the
  // batch mode, `brume sample` and any Python runner draw the same values for
  // the same frame. A range is a spec string ("loguniform(50, 5000)"), a fixed
  // number or name, or a list/tuple (a choice).
  m.def(
      "random_params",
      [](const std::string& effect, std::uint64_t seed, const std::string& key, py::kwargs ranges) {
        std::map<std::string, std::string> specs;
        for (auto item : ranges) {
          const std::string name = py::str(item.first);
          py::handle v = item.second;
          std::string spec;
          if (py::isinstance<py::str>(v)) {
            spec = v.cast<std::string>();
          } else if (py::isinstance<py::bool_>(v)) {
            spec = v.cast<bool>() ? "true" : "false";
          } else if (py::isinstance<py::int_>(v) || py::isinstance<py::float_>(v)) {
            spec = py::str(py::repr(v));
          } else if (py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v)) {
            spec = "choice(";
            bool first = true;
            for (py::handle e : v) {
              spec += (first ? "" : ", ") + std::string(py::str(e));
              first = false;
            }
            spec += ")";
          } else {
            throw py::type_error("brume.random_params(): " + name + "=" + std::string(py::repr(v)) +
                                 " is neither a spec string ('uniform(a, b)', 'loguniform(a, b)', "
                                 "'choice(x, y)'), a fixed value nor a list of choices");
          }
          specs[name] = spec;
        }
        json drawn;
        {
          py::gil_scoped_release nogil;
          drawn = brume::random_params(effect, seed, key, specs);
        }
        return to_py(drawn);  // keys are flag names ("lambda"): brume.haze(rgb, rng, **drawn) takes them
      },
      py::arg("effect"), py::arg("seed"), py::arg("key"),
      "random_params(effect, seed, key, **ranges) -> dict\n\n"
      "Physically plausible parameters of `effect` (haze, fog, aerial, dof) for the frame `key`, drawn by\n"
      "the library's sampler (brume-sample-v1: SHA-256 of seed, key and parameter name, so the values do\n"
      "not depend on call order, shard or runner; `brume sample` prints the same). `ranges` override or\n"
      "extend the effect's defaults: a spec string 'uniform(a, b)', 'loguniform(a, b)', 'choice(x, y)',\n"
      "a fixed value, or a list of choices. Names are checked against the effect's parameters and every\n"
      "value a spec can produce against their ranges (ValueError). The dict's keys are the parameter\n"
      "names (e.g. 'lambda'), so brume.haze(rgb, range, **params) takes it as it is.");

  // ---- the process limit of `brume --max-pixels` ---------------------------------------
  // A module-level setting, not a keyword: like the CLI's root option (and
  // OpenImageIO's "limits:" attributes) it is a process limit against
  // hostile or corrupt file headers, not a parameter of a run (no record
  // holds it). It guards every file any function reads (read_image,
  // depth.convert, aerial's sky_image ...); arrays are already in memory. A
  // per-call keyword could not be honest: the library's limit is one
  // process-wide value, and a call on another thread would see it changed.
  m.def(
      "set_max_pixels",
      [](py::object n) {
        if (py::isinstance<py::bool_>(n) ||
            !(PyLong_Check(n.ptr()) || py::isinstance(n, py::module_::import("numpy").attr("integer"))))
          throw py::type_error("brume.set_max_pixels(): takes an int (pixels, width x height), got " + type_name(n));
        const py::int_ v(n);
        if (v < py::int_(1) || v > py::int_(1000000000000LL))
          throw py::value_error("brume.set_max_pixels(): " + py::cast<std::string>(py::repr(v)) +
                                " pixels is outside 1 .. 1e12 (the CLI's --max-pixels range); give a limit in it");
        set_max_pixels(py::cast<std::uint64_t>(v));
      },
      py::arg("pixels"),
      "set_max_pixels(pixels: int) -> None\n\nThe largest image or depth map any brume function reads from a file, "
      "in pixels (width x height); a header declaring more is refused (ValueError) before any allocation. "
      "Process-wide, as `brume --max-pixels`; default 500000000. Arrays passed in are not limited.");
  m.def("max_pixels", []() { return max_pixels(); }, "max_pixels() -> int\n\nThe limit set_max_pixels sets.");

  // ---- files ----------------------------------------------------------------------------
  m.def(
      "read_image",
      [](py::object path_obj, py::object transfer) {
        const std::string path = keyword_value(path_spec(), path_obj, "brume.read_image()");
        Transfer t = Transfer::automatic;
        if (!transfer.is_none()) t = parse_transfer(py::cast<std::string>(transfer), "transfer");
        FileInfo info;
        Image img;
        {
          py::gil_scoped_release nogil;
          img = read_color(path, t, &info);
        }
        json rec;
        if (!info.description.empty()) {
          rec = json::parse(info.description, nullptr, false);
          if (rec.is_discarded()) rec = nullptr;  // a description that is not brume's JSON
        }
        json file = {{"path", info.path}, {"format", info.format}, {"integer", info.integer}, {"bits", info.bits},
                     {"transfer", to_string(info.transfer)}, {"channels", info.channel_names}};
        return make_result({{"rgb", std::move(img)}}, rec, {{"file", to_py(file)}});
      },
      py::arg("path"), py::arg("transfer") = py::none(),
      "read_image(path, transfer=None) -> Result\n\nA colour image as linear float32 RGB (H x W x 3) by the CLI's "
      "rules: integer files (PNG, JPEG, 8/16-bit TIFF) are sRGB and float files (EXR, PFM, HDR) linear unless "
      "transfer='srgb'|'linear' says otherwise; grey is expanded, alpha dropped. Result: rgb, record (the brume "
      "record embedded in the file's ImageDescription, or None), file (format, bits, transfer).");
  m.def(
      "write_image",
      [](py::object path_obj, py::object img_obj, std::string bits, py::object transfer, py::object record,
         bool data, std::string compression) {
        const std::string fn = "brume.write_image";
        const std::string path = keyword_value(path_spec(), path_obj, fn + "()");
        if (!py::isinstance<py::array>(img_obj))
          throw py::type_error(fn + "(): image must be a numpy.ndarray (H x W x 3 colour, or H x W data)");
        py::array a = py::reinterpret_borrow<py::array>(img_obj);
        g_last_inputs.clear();
        Input in = read_input(img_obj, "image", a.ndim() == 2 ? 1 : 3, Transfer::automatic, fn);
        WriteOptions o;
        o.bits = bits;
        o.compression = compression;
        if (!transfer.is_none()) o.transfer = parse_transfer(py::cast<std::string>(transfer), "transfer");
        o.is_color = in.view.channels() == 3 && !data;
        if (!record.is_none()) o.description = from_py(record, fn + "(): record").dump();
        const Image& img = as_image(in, "image");
        {
          py::gil_scoped_release nogil;
          check_writable(path, o, "path");
          write_image(path, img, o, "path");
        }
      },
      py::arg("path"), py::arg("image"), py::arg("bits") = "auto", py::arg("transfer") = py::none(),
      py::arg("record") = py::none(), py::arg("data") = false, py::arg("compression") = "auto",
      "write_image(path, image, bits='auto', transfer=None, record=None, data=False, compression='auto')\n\nWrite "
      "linear float pixels "
      "(H x W x 3 colour, or H x W data) atomically, by the CLI's encoding rules: integer outputs (bits 8/16, PNG, "
      "JPEG) of colour are sRGB-encoded unless transfer='linear'; data=True (or a 2-D array) is never "
      "sRGB-encoded; bits auto: PNG/TIFF 16, JPEG 8, EXR/PFM/HDR float. record (a dict, e.g. a Result's) is "
      "embedded as ImageDescription where the format allows (PNG, TIFF, JPEG, EXR); read_image returns it. "
      "compression: the CLI's --compression (NAME[:LEVEL], e.g. 'rle' for a fast PNG).");

  // ---- brume batch's frames, for brume.dask (the same planning and pipelines as the CLI) ----
  m.def(
      "_batch_plan",
      [](const std::string& manifest, const std::string& out_dir, std::uint64_t seed, const std::string& format,
         const std::string& effect, const std::vector<std::pair<std::string, std::string>>& params,
         const std::vector<std::string>& maps) {
        BatchOptions o;
        o.manifest = manifest;
        o.out_dir = out_dir;
        o.seed = seed;
        o.format = format;
        o.effect = effect;
        o.params = params;
        o.maps = maps;
        nlohmann::json j = {{"argv", batch_record_argv(o)}, {"frames", nlohmann::json::array()}};
        for (const BatchFrame& f : plan_batch(o)) j["frames"].push_back(batch_frame_to_json(f));
        return j.dump();
      },
      py::arg("manifest"), py::arg("out_dir"), py::arg("seed") = 0, py::arg("format") = "", py::arg("effect") = "",
      py::arg("params") = std::vector<std::pair<std::string, std::string>>{},
      py::arg("maps") = std::vector<std::string>{},
      "brume batch's plan of a manifest as JSON: {argv, frames} (private; brume.dask uses it).");
  m.def(
      "_batch_frame_done", [](const std::string& frame) { return batch_frame_done(batch_frame_from_json(nlohmann::json::parse(frame))); },
      py::arg("frame"), "Whether a planned frame is done (private; brume.dask --resume).");
  m.def(
      "_batch_run_frame",
      [](const std::string& frame, const std::vector<std::string>& argv, int threads) {
        const BatchFrame f = batch_frame_from_json(nlohmann::json::parse(frame));
        ExecOptions eo;
        eo.threads = threads;
        BatchFrameResult r;
        {
          py::gil_scoped_release release;
          r = run_batch_frame(f, eo, argv);
        }
        return r.line.dump();
      },
      py::arg("frame"), py::arg("argv"), py::arg("threads") = 1,
      "Run one planned frame through its pipeline, the GIL released; returns its results line as JSON (private).");
  // ---- introspection, tests and benchmarks -----------------------------------------------
  m.def("_stub_text", &stub_text, "The type stubs of this module, generated from the parameter tables.");
  m.def(
      "_commands",
      []() {
        // The library's list of commands (brume/command.hpp), with the name of
        // this module's function that runs each one on arrays (None when a
        // command has no array form): brume.rerun and the tests walk it.
        py::list out;
        for (const CommandDef& c : commands()) {
          py::dict d;
          d["name"] = c.name;
          d["cli"] = c.cli;
          d["summary"] = c.summary;
          d["record"] = c.record;
          d["batch"] = c.batch;
          d["sample"] = c.sampling.has_value();
          d["gpu_passes"] = to_py(json(c.gpu_passes));
          std::string fn;
          for (const FunctionDoc& f : registry())
            if (f.command == c.name && f.replays) fn = f.name;
          d["function"] = fn.empty() ? py::object(py::none()) : py::object(py::str(fn));
          out.append(d);
        }
        return out;
      },
      "The library's list of commands: name, cli, summary, record, batch, sample, gpu_passes, function.");
  m.def(
      "_debug_last_inputs",
      []() {
        py::dict d;
        for (const auto& [k, t] : g_last_inputs)
          d[py::str(k)] = py::dict(py::arg("address") = t.address, py::arg("copied") = t.copied,
                                   py::arg("how") = t.how);
        return d;
      },
      "For the zero-copy test: per input of this thread's last call, the address of the pixels the library "
      "read and whether they were a copy.");
  m.def(
      "_debug_thread_gpu",
      []() -> py::object {
        if (!t_gpu) return py::none();
        return py::int_(reinterpret_cast<std::uintptr_t>(t_gpu.get()));
      },
      "For the GPU-context test: the address of this thread's GPU context, or None before its first GPU call.");
  m.def(
      "_bench_blur_cpp",
      [](py::object rgb_obj, double sigma, int repeats, int threads) {
        Input rgb = read_input(rgb_obj, "rgb", 3, Transfer::automatic, "_bench_blur_cpp");
        DiffusionParams dp;
        Exec e;
        e.threads = threads;
        std::vector<double> s;
        py::gil_scoped_release nogil;
        for (int i = 0; i < repeats; ++i) {
          const auto t0 = std::chrono::steady_clock::now();
          BlurRun r = run_blur(rgb.view, sigma, nullptr, dp, e);
          s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        }
        return s;
      },
      "The C++ side of bench/bench_python.py: run_blur on the same pixels, timed in C++ (seconds per call).");
}
