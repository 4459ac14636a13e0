// brume._brume — the Python binding (pybind11). Every keyword of every
// function comes from the parameter tables that make the CLI's flags and the
// JSON records (brume/params.hpp): a function's table is the effect's own
// table nested with the shared blocks it takes (range preparation, execution,
// intrinsics), and ONE generic routine (set_keywords) turns **kwargs into the
// parameter structs -- names (flag `--f-number` -> keyword `f_number`,
// `lambda` -> `lambda_`, aliases too), Python types, ranges. Docstrings and
// the type stubs (_brume.pyi, written at build time by python/gen_stubs.py)
// are generated from the same tables, so help(brume.haze) shows the CLI's help.
//
// Adding a function: a table (usually `call_table<P>(its table, blocks)`) and
// one def_effect / def_function line with a lambda calling the library.
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
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/aerial.hpp"
#include "brume/batch.hpp"
#include "brume/blur.hpp"
#include "brume/command.hpp"
#include "brume/depth.hpp"
#include "brume/depth_pipeline.hpp"
#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/fog.hpp"
#include "brume/gpu.hpp"
#include "brume/haze.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"
#include "brume/prepare.hpp"
#include "brume/record.hpp"
#include "brume/sample.hpp"
#include "brume/sky.hpp"

namespace py = pybind11;
using json = nlohmann::json;

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

// ==== keyword names from flag names ===========================================
bool is_py_keyword(const std::string& s) {
  static const std::set<std::string> kw = {"False", "None", "True", "and", "as", "assert", "async", "await",
                                           "break", "class", "continue", "def", "del", "elif", "else", "except",
                                           "finally", "for", "from", "global", "if", "import", "in", "is",
                                           "lambda", "nonlocal", "not", "or", "pass", "raise", "return", "try",
                                           "while", "with", "yield"};
  return kw.count(s) > 0;
}
// `--f-number` -> f_number; a Python keyword gets a trailing underscore
// (lambda -> lambda_), and the bare name is accepted too via **{"lambda": ...}.
std::string py_name(const std::string& flag) {
  std::string n = flag;
  for (char& c : n)
    if (c == '-') c = '_';
  return is_py_keyword(n) ? n + "_" : n;
}

// ==== the generic keyword -> parameter routine =================================
// The value a keyword holds, as the JSON the table's setter takes. Python
// types are checked here (TypeError); ranges by the declaration (ValueError).
// A str as UTF-8 text. A str holding lone surrogates (os.fsdecode of a file
// name that is not UTF-8) has no UTF-8 form: its original bytes get brume's
// message (check_utf8: the name, its bad bytes as \xHH, the fix) instead of
// pybind11's "Unable to cast Python instance to C++ type".
std::string utf8_of(py::handle v, const std::string& what) {
  Py_ssize_t n = 0;
  if (const char* p = PyUnicode_AsUTF8AndSize(v.ptr(), &n)) return std::string(p, static_cast<std::size_t>(n));
  PyErr_Clear();
  const std::string raw =
      py::cast<std::string>(py::reinterpret_borrow<py::object>(v).attr("encode")("utf-8", "surrogateescape"));
  check_utf8(raw, what);
  return raw;
}

json keyword_value(const ParamSpec& s, py::handle v, const std::string& where) {
  const std::string kwd = py_name(s.name);
  auto wrong = [&](const char* expected) -> py::type_error {
    return py::type_error(where + ": keyword " + kwd + " takes " + expected + ", got " + type_name(v) + " " +
                          py::cast<std::string>(py::repr(v)) + " (" + s.describe() + ")");
  };
  if (v.is_none()) {
    if (s.optional) return nullptr;
    throw wrong("a value (None only for parameters that can be unset)");
  }
  // The word that means "unset" (auto, none), as on the command line.
  if (s.optional && py::isinstance<py::str>(v) && utf8_of(v, where + ": " + kwd) == s.unset_word) return nullptr;
  const bool is_bool = py::isinstance<py::bool_>(v) || py::isinstance(v, py::module_::import("numpy").attr("bool_"));
  switch (s.kind) {
    case ParamKind::real: {
      if (is_bool || !(PyLong_Check(v.ptr()) || PyFloat_Check(v.ptr()) ||
                       py::isinstance(v, py::module_::import("numpy").attr("number"))))
        throw wrong(s.optional ? ("a number or None/'" + s.unset_word + "'").c_str() : "a number");
      return py::cast<double>(py::float_(py::reinterpret_borrow<py::object>(v)));
    }
    case ParamKind::integer: {
      if (is_bool || !(PyLong_Check(v.ptr()) || py::isinstance(v, py::module_::import("numpy").attr("integer"))))
        throw wrong("an int");
      return py::cast<long long>(py::int_(py::reinterpret_borrow<py::object>(v)));
    }
    case ParamKind::boolean:
      if (!is_bool) throw wrong("a bool");
      return py::cast<bool>(v);
    case ParamKind::choice:
      if (!py::isinstance<py::str>(v)) throw wrong("a str");
      return py::cast<std::string>(v);
    case ParamKind::rgb: {
      if (py::isinstance<py::str>(v)) throw wrong("a sequence of 3 numbers (linear R, G, B)");
      json j;
      try {
        j = from_py(v, where);
      } catch (const py::type_error&) {
        throw wrong("a sequence of 3 numbers (linear R, G, B)");
      }
      if (!j.is_array() || j.size() != 3) throw wrong("a sequence of 3 numbers (linear R, G, B)");
      for (auto& e : j)
        if (!e.is_number() || e.is_boolean()) throw wrong("a sequence of 3 numbers (linear R, G, B)");
      for (auto& e : j) e = e.get<double>();
      return j;
    }
    case ParamKind::text:
      if (py::isinstance<py::str>(v)) return utf8_of(v, where + ": " + kwd);
      if (py::hasattr(v, "__fspath__")) {
        const py::object p = py::module_::import("os").attr("fspath")(v);
        if (py::isinstance<py::str>(p)) return utf8_of(p, where + ": " + kwd);
        const std::string raw = py::cast<std::string>(p);  // a bytes path
        check_utf8(raw, where + ": " + kwd);
        return raw;
      }
      throw wrong("a str (or os.PathLike)");
  }
  throw wrong("a value");
}

ParamSpec path_spec() {
  ParamSpec s;
  s.name = "path";
  s.kind = ParamKind::text;
  s.help = "a file name";
  return s;
}

template <class P>
const Param<P>* find_keyword(const ParamTable<P>& t, const std::string& k) {
  for (const Param<P>& d : t.params()) {
    if (k == py_name(d.spec.name) || k == d.spec.name) return &d;
    std::string bare = d.spec.name;
    for (char& c : bare)
      if (c == '-') c = '_';
    if (k == bare) return &d;  // lambda via **{"lambda": ...}
    for (const std::string& a : d.spec.aliases)
      if (k == py_name(a) || k == a) return &d;
  }
  return nullptr;
}

template <class P>
std::vector<std::string> keyword_names(const ParamTable<P>& t) {
  std::vector<std::string> n;
  for (const Param<P>& d : t.params()) n.push_back(py_name(d.spec.name));
  return n;
}

// kwargs -> p, every value type- and range-checked by its declaration.
// Returns the parameter names given (the CLI's "given": a value the run
// would ignore is refused even when it equals the default).
template <class P>
std::set<std::string> set_keywords(const ParamTable<P>& t, P& p, const py::dict& kw, const std::string& fn) {
  std::set<std::string> given;
  for (auto [key, value] : kw) {
    const std::string k = py::cast<std::string>(key);
    const Param<P>* d = find_keyword(t, k);
    if (!d) {
      py::list names;
      for (const std::string& n : keyword_names(t)) names.append(n);
      py::list close = py::module_::import("difflib").attr("get_close_matches")(k, names, 3, 0.5);
      std::string hint;
      for (auto c : close) hint += (hint.empty() ? "" : ", ") + py::cast<std::string>(c);
      throw py::type_error(fn + "() got an unexpected keyword argument '" + k + "'" +
                           (hint.empty() ? "" : "; did you mean: " + hint + "?") + " (help(" + fn +
                           ") lists the keywords)");
    }
    if (given.count(d->spec.name))
      throw py::type_error(fn + "(): keyword " + py_name(d->spec.name) + " given twice (as '" + k +
                           "' and another of its names)");
    const json v = keyword_value(d->spec, value, fn + "()");
    try {
      d->spec.check(v);
    } catch (const Error& e) {
      throw py::value_error(fn + "(): keyword " + py_name(d->spec.name) + ": " + e.what());
    }
    d->set(p, v);
    given.insert(d->spec.name);
  }
  return given;
}

// A record's "job" ({block: {flag name: value}}) read back into p, as `brume
// run` reads one: every value checked by its declaration and none counted as
// "given" -- a record holds every parameter, so the CLI's rule against
// flags the run would ignore (visibility with kappa-a, say) judges them
// against the defaults, as for a library caller. A CLI record's "input",
// "depth" and "output" blocks describe files and how to read them (the depth
// source, its scale and unknown value), which the arrays and the Result
// stand for: their camera keywords (fx, fov-y ...) are read where this table
// has them, the rest skipped. Anything else unknown is refused.
template <class P>
void apply_job(const ParamTable<P>& t, P& p, py::handle job, const std::string& fn) {
  if (!py::isinstance<py::dict>(job))
    throw py::type_error(fn + "(): job takes a record's \"job\" dict ({block: {name: value}}), got " +
                         type_name(job));
  const json j = from_py(job, fn + "(): job");
  for (const auto& [block, vals] : j.items()) {
    if (!vals.is_object())
      throw py::value_error(fn + "(): job: block '" + block + "' is not a dict; give a record's \"job\" as it is");
    const bool files = block == "input" || block == "output" || block == "depth";
    for (const auto& [name, v] : vals.items()) {
      const Param<P>* d = nullptr;
      for (const Param<P>& q : t.params())
        if (q.spec.name == name && (q.spec.block == block || files)) {
          d = &q;
          break;
        }
      if (!d) {
        if (files) continue;
        throw py::value_error(fn + "(): job: '" + block + "." + name + "' is not a parameter of " + fn +
                              "; give the \"job\" of a record of the same command");
      }
      try {
        d->spec.check(v);
      } catch (const Error& e) {
        throw py::value_error(fn + "(): job: " + block + "." + name + ": " + e.what());
      }
      d->set(p, v);
    }
  }
}

// ==== the call tables: an effect's table nested with shared blocks ===========
// Every Python function sets one Call<P>: the effect's parameters and the
// blocks it takes. Which members a function exposes is its table's choice.
template <class P>
struct Call {
  P p;
  RangeStep prepare;
  DepthSource depth;  // intrinsics only (fog, dof): fx, fy, cx, cy, fov-x, fov-y, calib
  ExecOptions exec;
};

// The intrinsics flags of the depth block (the camera of fog and dof): the
// rest of that block names files, which a numpy range does not have.
std::set<std::string> depth_file_keywords() {
  static const std::set<std::string> keep = {"fx", "fy", "cx", "cy", "fov-x", "fov-y", "calib"};
  std::set<std::string> skip;
  for (const auto& d : depth_param_table().params())
    if (!keep.count(d.spec.name)) skip.insert(d.spec.name);
  return skip;
}

enum Blocks : unsigned { kNone = 0, kPrepare = 1, kIntrinsics = 2, kExec = 4 };

template <class P>
ParamTable<Call<P>> call_table(const ParamTable<P>& own, unsigned blocks, const std::set<std::string>& skip = {}) {
  ParamTable<Call<P>> t(own.block());
  t.nest_except(&Call<P>::p, own, skip);
  if (blocks & kPrepare) t.nest(&Call<P>::prepare, range_step_param_table());
  if (blocks & kIntrinsics) t.nest_except(&Call<P>::depth, depth_param_table(), depth_file_keywords());
  if (blocks & kExec) t.nest(&Call<P>::exec, exec_param_table());
  return t;
}

template <class T>
std::set<std::string> names_of(const ParamTable<T>& t) {
  std::set<std::string> n;
  for (const auto& d : t.params()) n.insert(d.spec.name);
  return n;
}

// The job's parameters for the record, as the CLI's "job" (without the
// execution block, which the record holds under "execution").
template <class P>
json job_json(const ParamTable<Call<P>>& t, const Call<P>& c) {
  json j = t.to_json(c);
  j.erase("execution");
  return j;
}

// ==== documentation from the tables ===============================================
struct Extra {  // a keyword of the binding itself (not a parameter of the run)
  std::string name, stub_type, help;
};
struct FunctionDoc {
  std::string name;        // as bound in _brume: haze, depth_convert, ...
  std::string public_name; // brume.haze, brume.depth.convert, ...
  std::string positional;  // stub text of the positional parameters
  std::string summary;
  std::vector<std::pair<ParamSpec, json>> params;  // spec and default
  std::vector<Extra> extras;
  std::vector<std::string> fields;  // result fields
  std::string returns = "Result";
  std::string command = {};  // the command of the library's list it runs on arrays ("" for none)
  bool replays = false;  // takes job= (a record's job), so brume.rerun repeats that command with it
};
std::vector<FunctionDoc>& registry() {
  static std::vector<FunctionDoc> r;
  return r;
}

std::string stub_type(const ParamSpec& s) {
  std::string t;
  switch (s.kind) {
    case ParamKind::real: t = "float"; break;
    case ParamKind::integer: t = "int"; break;
    case ParamKind::boolean: t = "bool"; break;
    case ParamKind::rgb: t = "tuple[float, float, float] | Sequence[float]"; break;
    case ParamKind::text: t = "str | os.PathLike[str]"; break;
    case ParamKind::choice: {
      t = "Literal[";
      for (std::size_t i = 0; i < s.choices.size(); ++i) t += (i ? ", \"" : "\"") + s.choices[i] + "\"";
      t += "]";
      break;
    }
  }
  if (s.optional) t += " | Literal[\"" + s.unset_word + "\"] | None";
  return t;
}

std::string docstring(const FunctionDoc& f) {
  std::ostringstream o;
  o << f.public_name << "(" << f.positional << ", **keywords) -> " << f.returns << "\n\n" << f.summary << "\n";
  std::string block;
  for (const auto& [s, def] : f.params) {
    if (s.block != block) {
      block = s.block;
      o << "\n" << block << ":\n";
    }
    o << "  " << py_name(s.name) << " = " << s.format(def);
    if (s.kind == ParamKind::choice || s.kind == ParamKind::boolean || s.kind == ParamKind::text) o << "";
    o << "\n      " << s.describe();
    if (s.optional) o << " (or None)";
    if (!s.aliases.empty()) {
      o << " [also:";
      for (const auto& a : s.aliases) o << " " << py_name(a);
      o << "]";
    }
    o << "\n";
  }
  if (!f.extras.empty()) {
    o << "\nbinding:\n";
    for (const Extra& e : f.extras) o << "  " << e.name << "\n      " << e.help << "\n";
  }
  if (!f.fields.empty()) {
    o << "\nReturns a brume.Result with:";
    for (const auto& x : f.fields) o << " " << x;
    o << "\n";
  }
  return o.str();
}

std::string stub_text() {
  std::ostringstream o;
  o << "# Generated at build time from brume's parameter tables (python/src/module.cpp). Do not edit.\n"
       "import os\nfrom typing import Any, Literal, Sequence\n\nimport numpy as np\nimport numpy.typing as npt\n\n"
       "from ._result import Result\n\n";
  for (const FunctionDoc& f : registry()) {
    o << "def " << f.name << "(" << f.positional;
    if (!f.params.empty() || !f.extras.empty()) o << (f.positional.empty() ? "*" : ", *");
    for (const Extra& e : f.extras) o << ", " << e.name << ": " << e.stub_type << " = ...";
    for (const auto& [s, def] : f.params) o << ", " << py_name(s.name) << ": " << stub_type(s) << " = ...";
    o << ") -> " << f.returns << ":\n    \"\"\"" << f.summary;
    if (!f.fields.empty()) {
      o << " Result fields:";
      for (const auto& x : f.fields) o << " " << x;
      o << ".";
    }
    o << "\"\"\"\n\n";
  }
  std::string effects;  // the sampleable commands of the list (brume/command.hpp)
  for (const std::string& e : sample_effects()) effects += (effects.empty() ? "'" : ", '") + e + "'";
  o << "def random_params(effect: Literal[" << effects << "], seed: int, key: str,\n"
       "                  **ranges: str | float | int | bool | Sequence[str | float]) -> dict[str, Any]:\n"
       "    \"\"\"Plausible parameters of an effect for the frame `key`, keyed by (seed, key, name).\"\"\"\n\n";
  o << "def set_max_pixels(pixels: int) -> None:\n"
       "    \"\"\"The largest image or depth map read from a file, in pixels (process-wide, as brume --max-pixels).\"\"\"\n\n"
       "def max_pixels() -> int: ...\n\n";
  o << "def _stub_text() -> str: ...\n"
       "def _debug_last_inputs() -> dict[str, dict[str, Any]]: ...\n"
       "def _debug_thread_gpu() -> int | None: ...\n"
       "def _bench_blur_cpp(rgb: npt.NDArray[np.float32], sigma: float, repeats: int, threads: int) -> list[float]: ...\n";
  return o.str();
}

template <class C>
FunctionDoc make_doc(const char* name, const char* public_name, const char* positional, const char* summary,
                     const ParamTable<C>& t, std::vector<Extra> extras, std::vector<std::string> fields) {
  FunctionDoc f{name, public_name, positional, summary, {}, std::move(extras), std::move(fields)};
  const C defaults{};
  for (const auto& d : t.params()) f.params.emplace_back(d.spec, d.get(defaults));
  return f;
}

// ==== one GPU context per thread ==========================================================
// A context belongs to the thread that made it (EGL makes it current there),
// so each Python thread gets its own: made lazily, without the GIL, by its
// first call with backend gpu/auto, and reused by its later calls --
// per-call creation cost tens of ms (llvmpipe: ~30-60 ms). The thread_local
// is destroyed at the thread's exit, on that thread (the main thread's at
// process exit, before the atexit handlers of the GL driver). A thread on
// which creation failed does not retry here: choose_backend then makes its
// own attempt per call and reports it exactly as before (auto: CPU with the
// reason in the record; gpu: RuntimeError).
thread_local std::unique_ptr<GpuContext> t_gpu;
GpuContext* thread_gpu(const Exec& exec) {
  std::unique_ptr<GpuContext>& ctx = t_gpu;
  thread_local bool failed = false;
  if (exec.backend == Backend::cpu || exec.path == Path::reference || exec.gpu) return exec.gpu;
  if (!ctx && !failed) {
    try {
      ctx = std::make_unique<GpuContext>();
    } catch (const Error&) {
      failed = true;
    }
  }
  return ctx.get();
}
// The execution options of a call with this thread's context (call without the GIL).
Exec with_thread_gpu(Exec e) {
  e.gpu = thread_gpu(e);
  return e;
}

// ==== arrays in =========================================================================
// What each input of the last call on this thread became (the zero-copy test
// reads it): the address the library read and whether that was a copy.
struct InputTrace {
  std::uintptr_t address = 0;
  bool copied = false;
  std::string how;
};
thread_local std::map<std::string, InputTrace> g_last_inputs;

// One input image as the library sees it: a view of the caller's pixels
// (float32 with contiguous channels), or of `owned` (a conversion).
struct Input {
  ConstImageView view;
  Image owned;
  py::object keep;  // the array the view points into
  json record;
  DenseImageRef dense;  // as_dense: the same pixels for the dense-image APIs
};

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
Input read_input(py::handle obj, const std::string& arg, int channels, Transfer transfer, const std::string& fn) {
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
  if (a.shape(0) > (1 << 20) || a.shape(1) > (1 << 20)) throw bad("it is too large");
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
                       const std::map<std::string, py::object>& more = {}) {
  py::dict kw;
  for (auto& [k, v] : images) kw[py::str(k)] = v.empty() ? py::none() : py::object(to_numpy(std::move(v)));
  for (const auto& [k, v] : more) kw[py::str(k)] = v;
  kw["record"] = to_py(record);
  return py::module_::import("brume._result").attr("Result")(**kw);
}

json python_header(const std::string& command, const std::string& fn) {
  return run_record_header(command, {"python", fn});
}

// ==== effects: (rgb, range, **keywords) -> Result =========================================
struct EffectOut {
  std::map<std::string, Image> images;
  json record;
};
// The body runs without the GIL. It reads `.view` (pixels in place) when the
// library function takes views, else `.dense` (def_effect made it: the
// caller's pixels in place when C-contiguous).
template <class P>
using EffectBody = std::function<EffectOut(const Input& rgb, const Input& range, Call<P>& c, const Exec& exec,
                                           const std::set<std::string>& given)>;
enum class Takes { views, dense };

template <class P>
void def_effect(py::module_& m, const char* name, const char* command, const ParamTable<Call<P>>* table,
                Takes takes, const char* summary, std::vector<std::string> fields, EffectBody<P> body) {
  const std::string fn = std::string("brume.") + name;
  FunctionDoc doc = make_doc(name, fn.c_str(), "rgb: npt.NDArray[Any], range: npt.NDArray[Any]", summary, *table,
                             {{"transfer", "Literal[\"srgb\", \"linear\"] | None",
                               "uint8/uint16 rgb only: 'srgb' (PNG/JPEG-like) or 'linear'; float arrays are linear"},
                              {"job", "dict[str, Any] | None",
                               "a record's \"job\" (Result.record['job'], or a CLI record's): replays that run, "
                               "bit for bit on the CPU, as `brume run` does; other keywords override its values"}},
                             fields);
  doc.command = command;
  doc.replays = true;
  registry().push_back(doc);
  m.def(
      name,
      [=](py::object rgb_obj, py::object range_obj, py::kwargs kw) {
        py::dict k = py::dict(kw);
        const Transfer tr = parse_transfer_kw(k.contains("transfer") ? py::object(k["transfer"]) : py::object(py::none()), fn + "()");
        if (k.contains("transfer")) PyDict_DelItemString(k.ptr(), "transfer");
        Call<P> c;
        if (k.contains("job")) {
          py::object job = k["job"];
          PyDict_DelItemString(k.ptr(), "job");
          if (!job.is_none()) apply_job(*table, c, job, fn);
        }
        const std::set<std::string> given = set_keywords(*table, c, k, fn);
        g_last_inputs.clear();
        Input rgb = read_input(rgb_obj, "rgb", 3, tr, fn);
        Input range = read_input(range_obj, "range", 1, Transfer::automatic, fn);
        if (takes == Takes::dense) {
          as_dense(rgb, "rgb");
          as_dense(range, "range");
        }
        const Exec exec = c.exec.exec();
        EffectOut out;
        {
          py::gil_scoped_release nogil;
          out = body(rgb, range, c, with_thread_gpu(exec), given);
        }
        json rec = python_header(command, fn);
        rec["job"] = job_json(*table, c);
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
      PyErr_SetString(PyExc_ValueError, e.what());
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

  // ---- the effects -----------------------------------------------------------------
  def_effect<HazeParams>(
      m, "haze", "haze", keep(call_table(haze_param_table(), kPrepare | kExec)), Takes::views,
      "Haze and fog with scattering blur (Hansard): Beer-Lambert transmission from the range, premultiplied "
      "compositing with the airlight, depth-dependent blur by inhomogeneous diffusion. As `brume haze`.",
      {"rgb", "transmission", "scale", "record"},
      [](const Input& rgb, const Input& range, Call<HazeParams>& c, const Exec& e, const std::set<std::string>& g) {
        HazeRun r = run_haze(rgb.view, range.view, c.p, c.prepare, e, g);
        return EffectOut{{{"rgb", std::move(r.result.rgb)}, {"transmission", std::move(r.result.transmission)},
                          {"scale", std::move(r.result.scale)}}, r.record};
      });
  {
    // aerial takes the whole `brume aerial` job but its files: the turbidity
    // from a sky fit's JSON (turbidity_from=) or fitted on a sky photo
    // (turbidity="auto", sky_image=, the sky_* keywords) resolve as the CLI
    // resolves them (resolve_aerial_turbidity), and the record holds the same
    // "turbidity_fit" and inputs' "sky_image". sky_image is a file, as on the
    // command line (its record hashes it, so `brume run` can refit it); for a
    // sky already in memory call brume.sky.fit and pass turbidity=.
    std::set<std::string> skip = names_of(input_param_table(true));
    for (const auto& n : names_of(output_param_table(aerial_map_outputs()))) skip.insert(n);
    def_effect<AerialJob>(
        m, "aerial", "aerial", keep(call_table(aerial_job_table(), kExec, skip)), Takes::dense,
        "Spectral aerial perspective from turbidity (Morales): render, re-render (from_turbidity) or remove, with "
        "optional scattering blur (lambda_). The turbidity is given, read from a `brume sky fit` JSON "
        "(turbidity_from=) or fitted on a sky photo (turbidity='auto', sky_image=FILE, sky_* keywords), refused "
        "when the fit is unreliable. As `brume aerial`.",
        {"rgb", "attenuation", "scale", "record"},
        [](const Input& rgb, const Input& range, Call<AerialJob>& c, const Exec& e, const std::set<std::string>& g) {
          const AerialTurbidity tf = resolve_aerial_turbidity(c.p, g);
          AerialRun r = run_aerial(rgb.dense, range.dense, c.p.aerial, c.p.prepare, e, g);
          if (!tf.fit_record.is_null()) {
            r.record["turbidity_fit"] = tf.fit_record;
            r.record["sky_image"] = tf.image_record;  // moved under "inputs" by def_effect
            c.p.aerial.atmosphere.turbidity = NAN;     // recorded as given (auto), as the CLI does
          }
          return EffectOut{{{"rgb", std::move(r.result.rgb)}, {"attenuation", std::move(r.result.attenuation)},
                            {"scale", std::move(r.result.scale)}}, r.record};
        });
  }
  def_effect<FogParams>(
      m, "fog", "fog", keep(call_table(fog_param_table(), kPrepare | kIntrinsics | kExec)), Takes::dense,
      "Layered fog from the range and the camera (Zhou, Chen, Smith), with scattering blur for lambda_ > 0. "
      "The intrinsics (fx.. or fov_x/fov_y) and the pose are keywords. As `brume fog`.",
      {"rgb", "optical_depth", "transmission", "record"},
      [](const Input& rgb, const Input& range, Call<FogParams>& c, const Exec& e, const std::set<std::string>& g) {
        FogRun r = run_fog(rgb.dense, range.dense, c.depth, c.p, c.prepare, e, g);
        return EffectOut{{{"rgb", std::move(r.result.rgb)}, {"optical_depth", std::move(r.result.optical_depth)},
                          {"transmission", std::move(r.result.transmission)}}, r.record};
      });
  def_effect<DofParams>(
      m, "dof", "dof", keep(call_table(dof_param_table(), kPrepare | kIntrinsics | kExec)), Takes::dense,
      "Depth of field by leak-free diffusion (thin-lens circle of confusion). `range` is metres along the ray; "
      "planar depth comes from the intrinsics or the lens. As `brume dof`.",
      {"rgb", "scale", "record"},
      [](const Input& rgb, const Input& range, Call<DofParams>& c, const Exec& e, const std::set<std::string>& g) {
        const Intrinsics k = dof_intrinsics(c.depth, c.p, rgb.dense.width, rgb.dense.height);
        // run_dof reads a given context as backend gpu (its CPU-only schemes
        // would be refused), so with auto it makes its own, as before.
        Exec ex = e;
        if (ex.backend != Backend::gpu) ex.gpu = nullptr;
        DofRun r = run_dof(rgb.dense, range.dense, k, c.p, c.prepare, ex, g);
        return EffectOut{{{"rgb", std::move(r.result.rgb)}, {"scale", std::move(r.result.scale)}}, r.record};
      });

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
