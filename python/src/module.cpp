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
// The functions on arrays (brume.haze(rgb, range), brume.blur(rgb),
// brume.depth.prepare(range), brume.sky.fit(rgb, mask), ...) are the array
// forms of the library's list of commands (CommandDef::arrays, defined
// beside each pipeline): one loop binds them all (def_array_command). The
// process-wide functions (random_params, read_image, write_image, the limits,
// the batch hooks of brume.dask) are bound below.
//
// Conventions (docs/python.md):
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
#include "brume/blur.hpp"  // _bench_blur_cpp
#include "brume/depth.hpp"  // _read_stereo_calib
#include "brume/error.hpp"
#include "brume/rerun.hpp"
#include "brume/sample.hpp"

namespace brume::python {

// ==== the commands on arrays: brume.<function>(arrays..., **keywords) -> Result ==================
// Every command of the library's list with an array form (CommandDef::arrays)
// is bound here; nothing here names one. Its positional arrays are read as
// its ArrayArgs ask (in place as views; dense, in place when C-contiguous; or
// an Image of the call's own), its keywords through its declarations, and it
// runs without the GIL.
namespace {

std::string positional_stub(const ArrayForm& a) {
  std::string p;
  for (const ArrayArg& g : a.args)
    if (!g.keyword) p += (p.empty() ? "" : ", ") + g.name + ": npt.NDArray[Any]" + (g.optional ? " | None = None" : "");
  return p;
}

// Whether the form's colour array is checked for NaN and inf, as its
// command checks --image (its table declares --nonfinite).
bool takes_nonfinite(const ArrayForm& a, const std::string& command) {
  const CommandDef* c = find_command(command);
  return !a.args.empty() && a.args.front().channels == 3 && c && c->spec("nonfinite");
}

// The run's warnings -- every "warnings" list of its record (the preparation's sky, wet's ground
// plane, a scan's frame ...) -- as Python warnings (UserWarning) in Python's words, so that a result
// brume cannot vouch for does not pass unseen; the record keeps them as the command line's do.
void warn_record(const json& j, const std::string& fn) {
  if (j.is_object()) {
    for (const auto& [k, v] : j.items()) {
      if (k == "job") continue;
      if (k == "warnings" && v.is_array()) {
        for (const auto& w : v)
          if (w.is_string()) {
            const std::string m = fn + "(): " + python_spelling(w.get<std::string>());
            if (PyErr_WarnEx(PyExc_UserWarning, m.c_str(), 1) < 0) throw py::error_already_set();
          }
      } else {
        warn_record(v, fn);
      }
    }
  } else if (j.is_array()) {
    for (const auto& v : j) warn_record(v, fn);
  }
}

py::object call_array_form(const ArrayForm& a, const std::string& command, const std::vector<py::object>& arrays,
                           py::kwargs kw) {
  const std::string& fn = a.public_name;
  py::dict k = py::dict(kw);
  const bool colour = !a.args.empty() && a.args.front().channels == 3;
  Transfer tr = Transfer::automatic;
  NonFinite nonfinite = NonFinite::error;
  // The forms whose command reads its colour with --nonfinite (the effects,
  // blur, depth complete) take nonfinite= (takes_nonfinite).
  const bool nf = takes_nonfinite(a, command);
  if (colour) {
    tr = parse_transfer_kw(k.contains("transfer") ? py::object(k["transfer"]) : py::object(py::none()), fn + "()");
    if (k.contains("transfer")) PyDict_DelItemString(k.ptr(), "transfer");
    // nonfinite=: the CLI's --nonfinite, with its names (brume/pipeline.hpp).
    if (nf && k.contains("nonfinite")) {
      py::object v = k["nonfinite"];
      PyDict_DelItemString(k.ptr(), "nonfinite");
      if (!py::isinstance<py::str>(v))
        throw py::type_error(fn + "(): nonfinite takes a str, one of: error, zero; got " + type_name(v));
      nonfinite = parse_enum(nonfinite_names(), py::cast<std::string>(v), fn + "(): nonfinite");
    }
  }
  // The keyword arrays (lidar=points): taken from the keywords, in the form's order after the positional ones.
  std::vector<py::object> all = arrays;
  for (const ArrayArg& g : a.args) {
    if (!g.keyword) continue;
    py::object x = py::none();
    if (k.contains(g.name.c_str())) {
      x = k[g.name.c_str()];
      PyDict_DelItemString(k.ptr(), g.name.c_str());
    }
    all.push_back(x);
  }
  JobValues values;
  if (a.replays && k.contains("job")) {
    py::object job = k["job"];
    PyDict_DelItemString(k.ptr(), "job");
    if (!job.is_none()) values = job_values(a.specs, job, fn, find_command(command));
  }
  std::set<std::string> given;
  for (auto& v : keyword_values(a.specs, k, fn, given)) values.push_back(std::move(v));
  const json call = a.build(values);
  g_last_inputs.clear();
  std::vector<Input> inputs(a.args.size());
  std::vector<ArrayIn> in(a.args.size());
  for (std::size_t i = 0; i < a.args.size(); ++i) {
    const ArrayArg& g = a.args[i];
    if (all[i].is_none() && g.optional) continue;
    inputs[i] = g.points ? read_points(all[i], g.name, fn)
                : g.mask ? read_mask(all[i], g.name, fn)
                         : read_input(all[i], g.name, g.channels, g.channels == 3 ? tr : Transfer::automatic, fn);
    in[i].present = true;
    in[i].integer = py::isinstance<py::array>(all[i]) &&
                    py::reinterpret_borrow<py::array>(all[i]).dtype().kind() == 'u';
    if (nf && i == 0) {
      // NaN and inf are refused as the CLI refuses them in a file (one NaN
      // pixel became 7 186 after a blur); nonfinite='zero' replaces them in
      // the call's own copy, never in the caller's array.
      const std::size_t bad = check_nonfinite_colour(inputs[i].view, nonfinite, fn + "(): " + g.name,
                                                     "Fix the array, or pass nonfinite='zero'");
      if (bad > 0) {
        if (inputs[i].owned.empty()) inputs[i].owned = copy_of(inputs[i].view);
        replace_nonfinite(inputs[i].owned);
        inputs[i].view = ConstImageView(inputs[i].owned);
        inputs[i].record["copied"] = true;
        inputs[i].record["nonfinite_replaced"] = bad;
        g_last_inputs[g.name] = {reinterpret_cast<std::uintptr_t>(inputs[i].owned.data.data()), true,
                                 "copied: non-finite values replaced by 0"};
      }
    }
    if (g.as == ArrayArg::As::dense) as_dense(inputs[i], g.name);
    if (g.as == ArrayArg::As::image) as_image(inputs[i], g.name);
    in[i].view = inputs[i].view;
    in[i].dense = inputs[i].dense;
    if (g.as == ArrayArg::As::image) in[i].image = &inputs[i].owned;
  }
  ExecOptions eo;
  if (call.contains("execution")) exec_param_table().from_json(eo, {{"execution", call["execution"]}}, fn);
  if (const CommandDef* def = find_command(command)) refuse_gpu_without_passes(*def, eo.backend, "backend=");
  const Exec exec = fork_safe(eo.exec());
  ArrayResult out;
  {
    py::gil_scoped_release nogil;
    // What the run refuses names the function, as the keywords' errors do ("brume.wet(): ...").
    const auto named = [&fn](const Error& e) {
      const std::string m = e.what();
      return m.rfind(fn + "()", 0) == 0 ? m : fn + "(): " + m;
    };
    try {
      run_fork_safe(exec, [&] { out = a.run(in, call, with_thread_gpu(exec), given); });
    } catch (const FileNotFound& e) {
      throw FileNotFound(named(e));
    } catch (const GpuUnavailable& e) {
      throw GpuUnavailable(named(e));
    } catch (const Error& e) {
      throw Error(named(e));
    }
  }
  json rec = python_header(command, fn);
  rec["job"] = std::move(out.job);
  if (!a.args.empty()) {
    rec["inputs"] = json::object();
    for (std::size_t i = 0; i < a.args.size(); ++i)
      if (in[i].present) rec["inputs"][a.args[i].name] = inputs[i].record;
  }
  if (out.record.contains("inputs")) {  // the files a run read beside the arrays (a scan's KITTI calibration)
    for (const auto& [name, v] : out.record["inputs"].items()) rec["inputs"][name] = v;
    out.record.erase("inputs");
  }
  if (out.record.contains("sky_image")) {  // aerial's sky photo is an input, as in the CLI's record
    rec["inputs"]["sky_image"] = out.record["sky_image"];
    out.record.erase("sky_image");
  }
  rec.update(out.record);
  std::map<std::string, py::object> more;
  for (const auto& [name, v] : out.more.items()) more[name] = to_py(v);
  for (const auto& [name, v] : out.bytes)
    more[name] = py::array_t<std::uint8_t>(static_cast<py::ssize_t>(v.size()), v.data());
  warn_record(rec, fn);
  return make_result(std::move(out.images), rec, more);
}

}  // namespace

void def_array_command(py::module_& m, const CommandDef& c) {
  const ArrayForm& a = *c.arrays;
  std::vector<Extra> extras;
  if (!a.args.empty() && a.args.front().channels == 3)
    extras.push_back({"transfer", "Literal[\"srgb\", \"linear\"] | None",
                      "uint8/uint16 rgb only: 'srgb' (PNG/JPEG-like) or 'linear'; float arrays are linear"});
  if (takes_nonfinite(a, c.name)) {
    std::string lit;
    for (const auto& [e, n] : nonfinite_names()) lit += (lit.empty() ? "" : ", ") + std::string("\"") + n + "\"";
    extras.push_back({"nonfinite", "Literal[" + lit + "]",
                      "NaN or inf in " + a.args.front().name + " (the CLI's --nonfinite): 'error' (default; names the "
                      "count and the first pixel) or 'zero' (replaced by 0 in the call's own copy, the count "
                      "recorded as inputs." + a.args.front().name + ".nonfinite_replaced)"});
  }
  for (const ArrayArg& g : a.args)
    if (g.keyword)
      extras.push_back({g.name, g.mask ? "npt.NDArray[np.bool_] | npt.NDArray[np.float32] | None" : "npt.NDArray[np.float32] | None",
                        g.points ? "the frame's LiDAR scan: an (N, 4) float32 array of x, y, z [m] and intensity "
                                   "(KITTI's velodyne layout; read in place, float64 converted once), fogged by the "
                                   "same medium and returned as the Result's " + g.name
                        : g.mask ? "an H x W bool array (True marks it) or a float one whose values above 0.5 mark it"
                                 : "an array"});
  if (a.replays)
    extras.push_back({"job", "dict[str, Any] | None",
                      "a record's \"job\" (Result.record['job'], or a CLI record's): replays that run, bit for bit "
                      "on the CPU, as `brume run` does; other keywords override its values"});
  const std::string stub = positional_stub(a);
  FunctionDoc doc = make_doc(a.function, a.public_name, stub.c_str(), a.summary, a.specs, a.defaults,
                             std::move(extras), a.fields);
  doc.command = c.name;
  doc.replays = a.replays;
  registry().push_back(doc);
  const std::string command = c.name;
  const std::string ds = docstring(doc);
  std::size_t positional = 0;
  for (const ArrayArg& g : a.args) positional += g.keyword ? 0 : 1;
  switch (positional) {
    case 0:
      m.def(a.function.c_str(), [&a, command](py::kwargs kw) { return call_array_form(a, command, {}, kw); },
            ds.c_str());
      break;
    case 1:  // (a required one: no form takes a lone optional array)
      m.def(
          a.function.c_str(),
          [&a, command](py::object x, py::kwargs kw) { return call_array_form(a, command, {x}, kw); },
          py::arg(a.args[0].name.c_str()), ds.c_str());
      break;
    case 2:
      if (a.args[1].optional)
        m.def(
            a.function.c_str(),
            [&a, command](py::object x, py::object y, py::kwargs kw) { return call_array_form(a, command, {x, y}, kw); },
            py::arg(a.args[0].name.c_str()), py::arg(a.args[1].name.c_str()) = py::none(), ds.c_str());
      else
        m.def(
            a.function.c_str(),
            [&a, command](py::object x, py::object y, py::kwargs kw) { return call_array_form(a, command, {x, y}, kw); },
            py::arg(a.args[0].name.c_str()), py::arg(a.args[1].name.c_str()), ds.c_str());
      break;
    default:
      throw Error("internal: array form " + a.function + " takes more than two arrays");
  }
}

// ==== errors as Python exceptions ===========================
void register_errors() {
  // Every error the module raises passes here: the library's messages, and
  // the binding's own TypeError and ValueError, in Python's words
  // (python_spelling: keywords from the tables, not the CLI's flags).
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const FileNotFound& e) {
      PyErr_SetString(PyExc_FileNotFoundError, python_spelling(e.what()).c_str());
    } catch (const GpuUnavailable& e) {
      PyErr_SetString(PyExc_RuntimeError, python_spelling(e.what()).c_str());
    } catch (const Error& e) {
      std::string m = e.what();
      if (m.find("raise the limit with --max-pixels") != std::string::npos)
        m += " (in Python: brume.set_max_pixels(N))";
      PyErr_SetString(PyExc_ValueError, python_spelling(m).c_str());
    } catch (const py::type_error& e) {
      PyErr_SetString(PyExc_TypeError, python_spelling(e.what()).c_str());
    } catch (const py::value_error& e) {
      PyErr_SetString(PyExc_ValueError, python_spelling(e.what()).c_str());
    } catch (const nlohmann::json::exception& e) {
      PyErr_SetString(PyExc_ValueError, printable_text(e.what()).c_str());
    }
  });
}

// random_params' ranges as the sampler's spec texts: a spec string, a fixed
// number or name, or a list/tuple (a choice).
std::map<std::string, std::string> range_specs(const py::kwargs& ranges) {
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
  return specs;
}

}  // namespace brume::python

using namespace brume;
using namespace brume::python;

PYBIND11_MODULE(_brume, m) {
  m.doc() = "brume: physically based, depth-aware atmospheric and lens effects on numpy RGB-D images";
  m.attr("__version__") = BRUME_VERSION;
  register_errors();
  install_fork_handlers();

  // ---- the commands on arrays (the library's list): effects, blur, depth, sky -----------
  for (const CommandDef& c : commands())
    if (c.arrays) def_array_command(m, c);

  // ---- brume.random_params (issue #14 item 3): the library's sampler ------------------
  // Keyed by (seed, frame key, parameter name), never by call order, so the
  // batch mode, `brume sample` and any Python runner draw the same values for
  // the same frame. A range is a spec string ("loguniform(50, 5000)"), a fixed
  // number or name, or a list/tuple (a choice).
  m.def(
      "random_params",
      [](const std::string& effect, std::uint64_t seed, const std::string& key, py::kwargs ranges) {
        const std::map<std::string, std::string> specs = range_specs(ranges);
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

  // ---- the transforms' checks when they are made (brume/transforms.py) ----------------
  m.def(
      "_sample_corners",
      [](const std::string& effect, py::kwargs ranges) {
        py::list out;
        for (const json& set : sample_corners(effect, range_specs(ranges))) out.append(to_py(set));
        return out;
      },
      py::arg("effect"),
      "Every set of values the ranges can draw at their distributions' ends (both bounds, each choice), as "
      "random_params returns one (private: brume.transforms checks them all when a transform is made).");
  m.def(
      "_check_call",
      [](const std::string& function, py::kwargs kw) {
        for (const CommandDef& c : commands()) {
          if (!c.arrays || c.arrays->function != function) continue;
          const ArrayForm& a = *c.arrays;
          std::set<std::string> given;
          const JobValues values = keyword_values(a.specs, py::dict(kw), a.public_name, given);
          const json call = a.build(values);
          if (a.check) a.check(call, given);
          return;
        }
        throw py::value_error("_check_call(): no function " + function);
      },
      py::arg("function"),
      "The checks the array function `function` makes before any pixel (ranges, combinations, the camera), on "
      "these keywords, without running it (private: brume.transforms).");

  m.def(
      "_read_stereo_calib",
      [](py::object path) {
        const std::string p = keyword_value(path_spec(), path, "calib");
        StereoCalib c;
        {
          py::gil_scoped_release nogil;
          c = read_stereo_calib(p);
        }
        py::dict d;
        d["f_px"] = c.f_px, d["cx"] = c.cx, d["cy"] = c.cy, d["baseline_m"] = c.baseline_m, d["doffs_px"] = c.doffs_px;
        d["width"] = c.width, d["height"] = c.height;
        return d;
      },
      py::arg("path"),
      "A Middlebury 2014 / ETH3D calib.txt as brume.depth.convert(calib=) reads it: f_px, cx, cy, baseline_m, "
      "doffs_px, width, height (private: brume.transforms' calib=).");

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
      [](py::object path_obj, py::object transfer, py::object layer_obj) {
        const std::string path = keyword_value(path_spec(), path_obj, "brume.read_image()");
        TransferFunction t = Transfer::automatic;
        if (!transfer.is_none()) {
          if (!py::isinstance<py::str>(transfer))
            throw py::type_error("brume.read_image(): transfer takes a str ('auto', 'srgb', 'linear', 'gamma:G' or "
                                 "'table:FILE') or None, got " + type_name(transfer));
          t = parse_transfer_function(py::cast<std::string>(transfer), "brume.read_image(): transfer=");
        }
        ColorRead how;
        how.transfer = t;
        how.layer_flag = "layer=";
        if (!layer_obj.is_none()) {
          if (!py::isinstance<py::str>(layer_obj))
            throw py::type_error("brume.read_image(): layer takes a str (a layer's name, e.g. 'ViewLayer.Combined') "
                                 "or None, got " + type_name(layer_obj));
          how.layer = py::cast<std::string>(layer_obj);
        }
        FileInfo info;
        Image img;
        {
          py::gil_scoped_release nogil;
          img = read_color(path, how, &info);
        }
        json rec;
        if (!info.description.empty()) {
          rec = json::parse(info.description, nullptr, false);
          if (rec.is_discarded()) rec = nullptr;  // a description that is not brume's JSON
        }
        json file = {{"path", info.path}, {"format", info.format}, {"integer", info.integer}, {"bits", info.bits},
                     {"transfer", to_string(info.transfer)}, {"channels", info.channel_names},
                     {"layer", info.layer}, {"channels_read", info.channels_read}};
        return make_result({{"rgb", std::move(img)}}, rec, {{"file", to_py(file)}});
      },
      py::arg("path"), py::arg("transfer") = py::none(), py::arg("layer") = py::none(),
      "read_image(path, transfer=None, layer=None) -> Result\n\nA colour image as linear float32 RGB (H x W x 3) by "
      "the CLI's rules: integer files (PNG, JPEG, 8/16-bit TIFF) are sRGB and float files (EXR, PFM, HDR) linear "
      "unless transfer='srgb'|'linear'|'gamma:G'|'table:FILE' says otherwise (the CLI's --image-transfer); grey is expanded, alpha dropped. layer: the layer of a file "
      "with layers (a multilayer OpenEXR: 'ViewLayer.Combined' reads ViewLayer.Combined.R, .G, .B), as the CLI's "
      "--image-layer; None: the plain R, G, B, or the file's only colour layer (several: ValueError listing them). "
      "Result: rgb, record (the brume record embedded in the file's ImageDescription, or None), file (format, bits, "
      "transfer, channels, layer and channels_read).");
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
        eo.threads = fork_safe(Exec{threads}).threads;
        BatchFrameResult r;
        {
          py::gil_scoped_release release;
          run_fork_safe(Exec{eo.threads}, [&] { r = run_batch_frame(f, eo, argv); });
        }
        return r.line.dump();
      },
      py::arg("frame"), py::arg("argv"), py::arg("threads") = 1,
      "Run one planned frame through its pipeline, the GIL released; returns its results line as JSON (private).");
  // ---- introspection, tests and benchmarks -----------------------------------------------
  m.def("_stub_text", &stub_text, "The type stubs of this module, generated from the parameter tables.");
  m.def(
      "_record_job", [](py::handle record) { return to_py(record_job(from_py(record, "record"))); },
      py::arg("record"),
      "A record's job as `brume run` runs it (an older schema's job with the values that give its rules; private: "
      "brume.rerun).");
  m.def(
      "_commands",
      []() {
        // The library's list of commands (brume/command.hpp), with this
        // module's function that runs each one on arrays (None when a command
        // has no array form): brume.rerun and the tests walk it.
        py::list out;
        for (const CommandDef& c : commands()) {
          py::dict d;
          d["name"] = c.name;
          d["cli"] = c.cli;
          d["summary"] = c.summary;
          d["writes_record"] = c.writes_record;
          d["batchable"] = c.batchable;
          d["sample"] = c.sampling.has_value();
          d["gpu_passes"] = to_py(json(c.gpu_passes));
          d["function"] = c.arrays ? py::object(py::str(c.arrays->function)) : py::object(py::none());
          d["public_name"] = c.arrays ? py::object(py::str(c.arrays->public_name)) : py::object(py::none());
          py::list args, keyword_arrays;
          if (c.arrays)
            for (const ArrayArg& g : c.arrays->args) (g.keyword ? keyword_arrays : args).append(g.name);
          d["arrays"] = args;
          d["keyword_arrays"] = keyword_arrays;
          d["replays"] = c.arrays && c.arrays->replays;
          d["stage_prefix"] = c.stage_prefix;
          py::list keywords;  // the array form's keywords, as Python spells them (lambda_)
          if (c.arrays)
            for (const ParamSpec& s : c.arrays->specs) keywords.append(py_name(s.name));
          d["keywords"] = keywords;
          py::dict sampling;  // brume sample's table: the effect's parameters and their default ranges
          if (c.sampling) {
            py::dict params;  // {record name: [the names it also answers to]}
            for (const ParamSpec& s : c.sampling->specs) {
              py::list names;
              names.append(py_name(s.name));
              for (const std::string& al : s.aliases) names.append(al), names.append(py_name(al));
              params[py::str(s.name)] = names;
            }
            py::dict defaults;
            for (const SampleDefault& sd : c.sampling->defaults) defaults[py::str(sd.name)] = sd.spec;
            sampling["params"] = params;
            sampling["defaults"] = defaults;
          }
          d["sampling"] = sampling;
          out.append(d);
        }
        return out;
      },
      "The library's list of commands: name, cli, summary, record, batch, sample, gpu_passes, stage_prefix (a "
      "chain's later stage's flag prefix), sampling (params: {name: other names}, defaults: {name: spec}; empty "
      "when it is not sampled), and its array form (function, public_name, arrays: the positional array names, "
      "replays: takes job=, keywords: its Python keywords, keyword_arrays: the arrays it takes as keywords, "
      "lidar=).");
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
      "_sha256_file",
      [](py::object path) {
        const std::string p = py::cast<std::string>(py::module_::import("os").attr("fspath")(path));
        py::gil_scoped_release nogil;
        return sha256_file(p);
      },
      "The SHA-256 of a file as records hold it, read as brume reads inputs (a regular file: a FIFO or a device "
      "is a ValueError, not a hang).");
  m.def("_in_forked_child", &in_forked_child,
        "Whether this process was forked from one that had loaded brume (its effects then run with one thread "
        "unless threads= says otherwise; see docs/transforms.md).");
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
