// brume._brume — JSON and numpy arrays in and out: records and parameter values as
// Python objects, input arrays read in place (views) or converted once, and
// result Images handed to numpy without a copy.
#include "binding.hpp"

#include <cmath>
#include <limits>
#include <cstring>
#include <string>
#include "brume/error.hpp"

namespace brume::python {

// ==== JSON <-> Python (records, parameter values; random_params reuses it) ====
py::object to_py(const json& j) {
  switch (j.type()) {
    case json::value_t::null: return py::none();
    case json::value_t::boolean: return py::bool_(j.get<bool>());
    case json::value_t::number_integer: return py::int_(j.get<long long>());
    case json::value_t::number_unsigned: return py::int_(j.get<unsigned long long>());
    case json::value_t::number_float: return py::float_(j.get<double>());
    case json::value_t::string: return py::str(j.get<std::string>());
    case json::value_t::array: {
      py::list l;
      for (const auto& e : j) l.append(to_py(e));
      return l;
    }
    case json::value_t::object: {
      py::dict d;
      for (const auto& [k, v] : j.items()) d[py::str(k)] = to_py(v);
      return d;
    }
    default: return py::none();
  }
}

std::string type_name(py::handle o) { return py::str(py::type::handle_of(o).attr("__name__")); }

// dict / list / tuple / str / int / float / bool / None / numpy scalars and
// arrays / os.PathLike. Anything else: TypeError naming `where`.
json from_py(py::handle o, const std::string& where) {
  if (o.is_none()) return nullptr;
  if (py::isinstance<py::bool_>(o) || py::isinstance(o, py::module_::import("numpy").attr("bool_")))
    return py::cast<bool>(o);
  if (PyLong_Check(o.ptr())) return py::cast<long long>(o);
  if (PyFloat_Check(o.ptr())) return py::cast<double>(o);
  if (py::isinstance<py::str>(o)) return py::cast<std::string>(o);
  if (py::isinstance<py::dict>(o)) {
    json j = json::object();
    for (auto [k, v] : py::reinterpret_borrow<py::dict>(o)) {
      if (!py::isinstance<py::str>(k)) throw py::type_error(where + ": dict keys must be str, got " + type_name(k));
      const std::string key = py::cast<std::string>(k);
      j[key] = from_py(v, where + "['" + key + "']");
    }
    return j;
  }
  if (py::isinstance<py::array>(o)) return from_py(o.attr("tolist")(), where);
  py::module_ np = py::module_::import("numpy");
  if (py::isinstance(o, np.attr("integer"))) return py::cast<long long>(o.attr("item")());
  if (py::isinstance(o, np.attr("floating"))) return py::cast<double>(o.attr("item")());
  if (py::isinstance<py::list>(o) || py::isinstance<py::tuple>(o)) {
    json j = json::array();
    std::size_t i = 0;
    for (auto e : o) j.push_back(from_py(e, where + "[" + std::to_string(i++) + "]"));
    return j;
  }
  if (py::hasattr(o, "__fspath__")) return py::cast<std::string>(py::module_::import("os").attr("fspath")(o));
  throw py::type_error(where + ": cannot be stored as JSON (got " + type_name(o) + ")");
}

// ==== arrays in =========================================================================
// (InputTrace: binding.hpp)
thread_local std::map<std::string, InputTrace> g_last_inputs;

Transfer parse_transfer_kw(py::handle t, const std::string& where) {
  if (t.is_none()) return Transfer::automatic;
  if (!py::isinstance<py::str>(t)) throw py::type_error(where + ": transfer takes 'srgb' or 'linear' (or None)");
  const std::string s = py::cast<std::string>(t);
  if (s == "srgb") return Transfer::srgb;
  if (s == "linear") return Transfer::linear;
  if (s == "auto") return Transfer::automatic;
  throw py::value_error(where + ": transfer '" + s + "' is not allowed; use 'srgb' or 'linear' (integer arrays), or None");
}

std::string shape_text(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s += (i ? ", " : "") + std::to_string(a.shape(i));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

// `channels`: 3 for colour (4 accepted, alpha ignored), 1 for a scalar map
// (H x W or H x W x 1). Integer colour needs `transfer`; integer scalars are refused.
Input read_input(py::handle obj, const std::string& arg, int channels, Transfer transfer, const std::string& fn,
                 long long max_rows) {
  const bool color = channels == 3;
  const std::string expected =
      color ? "an H x W x 3 (or x 4) array of linear RGB, float32 (read in place) or float64 (converted once), or "
              "uint8/uint16 with transfer='srgb'|'linear'"
            : "an H x W (or H x W x 1) float32 or float64 array in metres (NaN: unknown)";
  if (!py::isinstance<py::array>(obj))
    throw py::type_error(fn + "(): " + arg + " must be a numpy.ndarray, " + expected + "; got " + type_name(obj));
  py::array a = py::reinterpret_borrow<py::array>(obj);
  py::module_ np = py::module_::import("numpy");
  const std::string dtype = py::cast<std::string>(py::str(a.dtype()));
  auto bad = [&](const std::string& why) {
    return py::value_error(fn + "(): " + arg + " has shape " + shape_text(a) + " and dtype " + dtype + ": " + why +
                           "; expected " + expected);
  };
  const bool shape_ok = color ? (a.ndim() == 3 && (a.shape(2) == 3 || a.shape(2) == 4))
                              : (a.ndim() == 2 || (a.ndim() == 3 && a.shape(2) == 1));
  if (!shape_ok) throw bad(color ? "not H x W x 3 or H x W x 4" : "not H x W");
  if (a.shape(0) < 1 || a.shape(1) < 1) throw bad("it is empty");
  if (a.shape(0) > max_rows || a.shape(1) > (1 << 20)) throw bad("it is too large");
  const int h = static_cast<int>(a.shape(0)), w = static_cast<int>(a.shape(1));
  const int nc = a.ndim() == 3 ? static_cast<int>(a.shape(2)) : 1;
  Input in;
  in.keep = py::reinterpret_borrow<py::object>(obj);
  in.record = {{"source", "numpy"}, {"shape", json::array()}, {"dtype", dtype}};
  for (py::ssize_t i = 0; i < a.ndim(); ++i) in.record["shape"].push_back(a.shape(i));
  const char kind = a.dtype().kind();
  const bool integer = kind == 'u' || kind == 'i';
  if (integer && !color)
    throw bad("a range needs metres; convert it (range.astype(np.float32) * metres_per_count) or use "
              "brume.depth.convert with depth_scale");
  if (integer) {
    if (!(a.dtype().is(py::dtype::of<std::uint8_t>()) || a.dtype().is(py::dtype::of<std::uint16_t>())))
      throw bad("integer pixels must be uint8 or uint16");
    if (transfer == Transfer::automatic)
      throw bad("integer pixels need an explicit transfer='srgb' (sRGB-encoded, as PNG/JPEG files) or "
                "transfer='linear'");
  } else if (transfer != Transfer::automatic) {
    throw py::value_error(fn + "(): transfer='" + to_string(transfer) + "' applies to uint8/uint16 " + arg +
                          " only; " + arg + " is " + dtype + " (float arrays are linear)");
  }
  if (!integer && kind != 'f') throw bad("dtype not supported");
  in.record["transfer"] = integer ? to_string(transfer) : "linear";
  // float32 with contiguous channels: a view, no copy.
  if (a.dtype().is(py::dtype::of<float>())) {
    const py::ssize_t rs = a.strides(0), ps = a.strides(1), cs = a.ndim() == 3 ? a.strides(2) : 4;
    if (cs == 4 && rs > 0 && ps > 0 && rs % 4 == 0 && ps % 4 == 0 && (nc == 1 || ps >= 4 * nc)) {
      try {
        in.view = ConstImageView::from_byte_strides(static_cast<const float*>(a.data()), w, h, nc, rs, ps);
        if (color && nc == 4) in.view = in.view.channel_range(0, 3);
        in.record["copied"] = false;
        g_last_inputs[arg] = {reinterpret_cast<std::uintptr_t>(in.view.data()), false, "view"};
        return in;
      } catch (const Error&) {
        // overlapping rows (a broadcast array): fall through to a copy
      }
    }
  }
  // Everything else: one conversion into a dense float image.
  py::array_t<double, py::array::c_style | py::array::forcecast> dense(a);
  const int oc = color ? 3 : 1;
  in.owned = Image(w, h, oc);
  const double* src = dense.data();
  const double maxval = a.dtype().is(py::dtype::of<std::uint8_t>()) ? 255.0 : 65535.0;
  for (std::size_t i = 0; i < in.owned.pixels(); ++i)
    for (int c = 0; c < oc; ++c) {
      const double v = src[i * nc + c];
      float f;
      if (integer) {
        // As OpenImageIO reads an integer file: count / max in float, then the transfer.
        f = static_cast<float>(v) * (1.0f / static_cast<float>(maxval));
        if (transfer == Transfer::srgb) f = srgb_to_linear(f);
      } else {
        f = static_cast<float>(v);
      }
      in.owned.data[i * oc + c] = f;
    }
  in.view = ConstImageView(in.owned);
  in.record["copied"] = true;
  g_last_inputs[arg] = {reinterpret_cast<std::uintptr_t>(in.view.data()), true, "converted"};
  return in;
}

// A LiDAR scan (brume.lidar.fog's points, a camera effect's lidar=): an
// (N, 4) array of x, y, z, intensity read as an N x 4 map, float32 in place
// (rows of 16 bytes or strided), float64 converted once; anything else a
// ValueError naming the argument, its shape and dtype.
Input read_points(py::handle obj, const std::string& arg, const std::string& fn) {
  const std::string expected =
      "an (N, 4) array of x, y, z [m] and intensity (KITTI's velodyne layout), float32 (read in place) or float64 "
      "(converted once)";
  if (!py::isinstance<py::array>(obj))
    throw py::type_error(fn + "(): " + arg + " must be a numpy.ndarray, " + expected + "; got " + type_name(obj));
  py::array a = py::reinterpret_borrow<py::array>(obj);
  const bool floats = a.dtype().is(py::dtype::of<float>()) || a.dtype().is(py::dtype::of<double>());
  if (a.ndim() != 2 || a.shape(1) != 4 || !floats)
    throw py::value_error(fn + "(): " + arg + " has shape " + shape_text(a) + " and dtype " +
                          py::cast<std::string>(py::str(a.dtype())) + ": " +
                          (floats ? "not (N, 4)" : "not float32 or float64") + "; expected " + expected);
  // A scan is not an image: any number of points a 32-bit count holds (merged
  // sweeps exceed the images' 2^20 rows); an empty one has nothing to fog.
  if (a.shape(0) < 1)
    throw py::value_error(fn + "(): " + arg + " holds no points (shape " + shape_text(a) +
                          "): a scan needs at least one; skip the call for an empty sweep");
  Input in = read_input(obj, arg, 1, Transfer::automatic, fn, std::numeric_limits<int>::max());
  in.record.erase("transfer");
  in.record["points"] = a.shape(0);
  return in;
}

Input read_mask(py::handle obj, const std::string& arg, const std::string& fn) {
  const std::string expected = "an H x W bool array (True marks it) or a float32/float64 one whose values above 0.5 "
                               "mark it";
  if (!py::isinstance<py::array>(obj))
    throw py::type_error(fn + "(): " + arg + " must be a numpy.ndarray, " + expected + "; got " + type_name(obj));
  py::array a = py::reinterpret_borrow<py::array>(obj);
  const std::string dtype = py::cast<std::string>(py::str(a.dtype()));
  const char kind = a.dtype().kind();
  auto bad = [&](const std::string& why) {
    return py::value_error(fn + "(): " + arg + " has shape " + shape_text(a) + " and dtype " + dtype + ": " + why +
                           "; expected " + expected);
  };
  if (kind == 'u' || kind == 'i')
    throw bad("an integer mask is ambiguous (0/1 or 0/255?); pass " + arg + "=m > 0 (bool) or a float array");
  if (kind != 'b' && kind != 'f') throw bad("dtype not supported");
  if (!(a.ndim() == 2 || (a.ndim() == 3 && a.shape(2) == 1))) throw bad("not H x W");
  if (a.shape(0) < 1 || a.shape(1) < 1) throw bad("it is empty");
  if (a.shape(0) > (1 << 20) || a.shape(1) > (1 << 20)) throw bad("it is too large");
  // one conversion, whatever the strides: numpy casts to float64 (bool to 0/1), then > 1/2
  py::module_ np = py::module_::import("numpy");
  auto d = np.attr("ascontiguousarray")(a, "float64").cast<py::array_t<double, py::array::c_style>>();
  const int h = static_cast<int>(a.shape(0)), w = static_cast<int>(a.shape(1));
  Input in;
  in.owned = Image(w, h, 1);
  const double* src = d.data();
  std::size_t marked = 0;
  for (std::size_t i = 0; i < in.owned.data.size(); ++i) {
    if (std::isnan(src[i]))
      throw py::value_error(fn + "(): " + arg + " holds NaN at pixel (" + std::to_string(i % w) + ", " +
                            std::to_string(i / w) + "); give " + expected);
    in.owned.data[i] = src[i] > 0.5 ? 1.0f : 0.0f;
    marked += src[i] > 0.5;
  }
  in.view = ConstImageView(in.owned);
  in.record = {{"source", "numpy"}, {"shape", json::array()}, {"dtype", dtype}, {"marked", marked}};
  for (py::ssize_t i = 0; i < a.ndim(); ++i) in.record["shape"].push_back(a.shape(i));
  g_last_inputs[arg] = {reinterpret_cast<std::uintptr_t>(in.owned.data.data()), true, "copied: a mask of 0 and 1"};
  return in;
}

// Library functions that take a dense image (DenseImageRef: aerial, fog,
// dof, depth.prepare, sky.fit): a C-contiguous float32 array is read in
// place, like haze's and blur's views. A strided float32 array (a crop, the
// RGB of an RGBA buffer) has no dense form, so it is copied once -- recorded
// in the trace and in the record's inputs ("copied": true).
DenseImageRef as_dense(Input& in, const std::string& arg) {
  if (in.owned.empty() && !in.view.contiguous()) {
    in.owned = copy_of(in.view);
    in.view = ConstImageView(in.owned);
    in.record["copied"] = true;
    g_last_inputs[arg] = {reinterpret_cast<std::uintptr_t>(in.owned.data.data()), true,
                          "copied: strided, the function needs a dense image"};
  }
  in.dense = DenseImageRef(in.view);
  return in.dense;
}

// The few APIs that still take an Image (blur's scale map, sky.fit's mask,
// which the binding binarises): a view becomes one -- a copy, recorded.
const Image& as_image(Input& in, const std::string& arg) {
  if (in.owned.empty()) {
    in.owned = copy_of(in.view);
    in.record["copied"] = true;
    g_last_inputs[arg] = {reinterpret_cast<std::uintptr_t>(in.owned.data.data()), true, "copied for an Image API"};
  }
  return in.owned;
}

// ==== arrays out: the Image's buffer becomes the array's (no copy) ==============
py::array to_numpy(Image&& img) {
  auto* owner = new Image(std::move(img));
  py::capsule cap(owner, [](void* p) { delete static_cast<Image*>(p); });
  const py::ssize_t h = owner->height, w = owner->width, c = owner->channels, f = sizeof(float);
  if (c == 1) return py::array_t<float>({h, w}, {w * f, f}, owner->data.data(), cap);
  return py::array_t<float>({h, w, c}, {w * c * f, c * f, f}, owner->data.data(), cap);
}

py::object make_result(std::map<std::string, Image>&& images, const json& record,
                       const std::map<std::string, py::object>& more) {
  py::dict kw;
  for (auto& [k, v] : images) kw[py::str(k)] = v.empty() ? py::none() : py::object(to_numpy(std::move(v)));
  for (const auto& [k, v] : more) kw[py::str(k)] = v;
  kw["record"] = to_py(record);
  return py::module_::import("brume._result").attr("Result")(**kw);
}

json python_header(const std::string& command, const std::string& fn) {
  return run_record_header(command, {"python", fn});
}

}  // namespace brume::python
