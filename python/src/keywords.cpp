// brume._brume — keywords from the parameter tables: names (flag -> keyword),
// Python types and ranges checked by the declarations, a record's job read
// back, and the docstrings and type stubs generated from the same tables.
#include "binding.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <sstream>
#include "brume/error.hpp"
#include "brume/sample.hpp"

namespace brume::python {

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

// ==== messages in Python's words ================================================
// The library's messages name flags as the command line spells them
// (--camera-height 1.6, --profile exponential). In Python each becomes its
// keyword, and a value that follows it becomes the keyword's argument:
// camera_height=METRES, profile='exponential', lambda_=6, airlight=(0.8,
// 0.8, 0.9). Which words are flags, and whether the word after one is its
// value, is decided by the declarations (every command's table and array
// form, aliases too): a value is a word the declaration's parser takes, a
// quoted text, or a placeholder in capitals (METRES, FILE, T). Anything
// else -- a "--" that names no parameter -- is left as it is.
namespace {

const std::map<std::string, const ParamSpec*>& flag_specs() {
  static const std::map<std::string, const ParamSpec*> m = [] {
    std::map<std::string, const ParamSpec*> out;
    auto add = [&](const std::vector<ParamSpec>& specs) {
      for (const ParamSpec& s : specs) {
        out.emplace(s.name, &s);
        for (const std::string& a : s.aliases) out.emplace(a, &s);
      }
    };
    for (const CommandDef& c : commands()) {
      add(c.specs);
      if (c.arrays) add(c.arrays->specs);
      if (c.sampling) add(c.sampling->specs);
    }
    return out;
  }();
  return m;
}

// A placeholder: capitals (METRES, T, R,G,B), a file's with its extension (FILE.csv, OUT.bin).
bool placeholder(const std::string& w) {
  if (w.empty() || !std::isupper(static_cast<unsigned char>(w[0]))) return false;
  std::size_t i = 0;
  while (i < w.size() && (std::isupper(static_cast<unsigned char>(w[i])) ||
                          std::isdigit(static_cast<unsigned char>(w[i])) || w[i] == '_' || w[i] == ','))
    ++i;
  if (i == w.size()) return true;
  if (w[i] != '.' || i + 1 == w.size()) return false;
  return std::all_of(w.begin() + static_cast<std::ptrdiff_t>(i) + 1, w.end(), [](char ch) {
    return std::islower(static_cast<unsigned char>(ch)) || std::isdigit(static_cast<unsigned char>(ch));
  });
}

// The value `word` as Python writes it for `s`, or "" when it is not one.
std::string python_value(const ParamSpec& s, const std::string& word) {
  if (word.empty() || s.kind == ParamKind::boolean) return "";
  if (placeholder(word)) return word;
  if (word.size() >= 2 && word.front() == '\'' && word.back() == '\'') return word;
  if (s.kind == ParamKind::text) {  // a file's name (calib.txt, a/b.csv): quoted
    const std::size_t dot = word.rfind('.');
    const bool file = dot != std::string::npos && dot > 0 && dot + 1 < word.size() &&
                      std::all_of(word.begin(), word.end(), [](char ch) {
                        return std::isalnum(static_cast<unsigned char>(ch)) || std::strchr("_./-", ch);
                      });
    return file ? "'" + word + "'" : "";
  }
  json v;
  try {
    v = s.parse(word);
  } catch (const std::exception&) {
    return "";
  }
  if (v.is_null() || v.is_string()) return "'" + word + "'";  // a choice's name, the unset word
  if (v.is_array()) {
    std::string t;
    for (std::size_t i = 0; i < word.size(); ++i) t += word[i] == ',' ? std::string(", ") : std::string(1, word[i]);
    return "(" + t + ")";
  }
  return word;
}

}  // namespace

std::string python_spelling(const std::string& text) {
  const auto& flags = flag_specs();
  std::string out;
  std::size_t i = 0;
  auto word_char = [](char ch) {
    return std::islower(static_cast<unsigned char>(ch)) || std::isdigit(static_cast<unsigned char>(ch)) || ch == '-';
  };
  while (i < text.size()) {
    const bool starts = text.compare(i, 2, "--") == 0 && i + 2 < text.size() &&
                        std::islower(static_cast<unsigned char>(text[i + 2])) &&
                        (i == 0 || !(std::isalnum(static_cast<unsigned char>(text[i - 1])) || text[i - 1] == '-'));
    if (!starts) {
      out += text[i++];
      continue;
    }
    std::size_t j = i + 2;
    while (j < text.size() && word_char(text[j])) ++j;
    std::string name = text.substr(i + 2, j - i - 2);
    // "--sky-*": the flags that begin so.
    if (!name.empty() && name.back() == '-') {
      const bool family = std::any_of(flags.begin(), flags.end(),
                                      [&](const auto& f) { return f.first.rfind(name, 0) == 0; });
      if (family) {
        out += py_name(name.substr(0, name.size() - 1)) + "_";
        i = j;
        continue;
      }
    }
    while (!name.empty() && name.back() == '-') --j, name.pop_back();
    const auto f = flags.find(name);
    if (f == flags.end()) {
      out += text.substr(i, j - i);
      i = j;
      continue;
    }
    out += py_name(name);
    i = j;
    // The value that follows, if the declaration takes it as one.
    if (i < text.size() && text[i] == ' ' && i + 1 < text.size()) {
      std::size_t k = i + 1, end = k;
      if (text[k] == '\'') {
        end = text.find('\'', k + 1);
        end = end == std::string::npos ? k : end + 1;
      } else {
        while (end < text.size() && text[end] != ' ') ++end;
        // trailing punctuation belongs to the sentence
        while (end > k && std::strchr(",;:)", text[end - 1])) --end;
        if (end > k + 1 && text[end - 1] == '.' && !placeholder(text.substr(k, end - k))) {
          const std::string cut = text.substr(k, end - k - 1);
          if (!python_value(*f->second, cut).empty()) --end;
        }
      }
      const std::string value = python_value(*f->second, text.substr(k, end - k));
      if (!value.empty()) {
        out += "=" + value;
        i = end;
      }
    }
  }
  return out;
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
      if (py::isinstance<py::str>(v) && !s.words.empty()) {
        const std::string w = utf8_of(v, where + ": " + kwd);
        for (const std::string& name : s.words)
          if (w == name) return w;
        throw wrong(("a number or '" + s.words[0] + "'").c_str());
      }
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
      if (py::isinstance<py::str>(v)) {
        const std::string w = utf8_of(v, where + ": " + kwd);
        for (const std::string& name : s.words)
          if (w == name) return w;
        throw wrong(s.words.empty() ? "a sequence of 3 numbers (linear R, G, B)"
                                    : ("a sequence of 3 numbers (linear R, G, B) or '" + s.words[0] + "'").c_str());
      }
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
    case ParamKind::pair: {
      const char* what = "a sequence of 2 numbers (x, y)";
      if (py::isinstance<py::str>(v)) throw wrong(what);
      json j;
      try {
        j = from_py(v, where);
      } catch (const py::type_error&) {
        throw wrong(what);
      }
      if (!j.is_array() || j.size() != 2) throw wrong(what);
      for (auto& e : j)
        if (!e.is_number() || e.is_boolean()) throw wrong(what);
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

// The declaration a keyword names: the flag's name with '_' for '-' (a
// Python keyword with its trailing '_'), the bare name (**{"lambda": ...}),
// or an alias.
const ParamSpec* find_keyword(const std::vector<ParamSpec>& specs, const std::string& k) {
  for (const ParamSpec& s : specs) {
    if (k == py_name(s.name) || k == s.name) return &s;
    std::string bare = s.name;
    for (char& c : bare)
      if (c == '-') c = '_';
    if (k == bare) return &s;  // lambda via **{"lambda": ...}
    for (const std::string& a : s.aliases)
      if (k == py_name(a) || k == a) return &s;
  }
  return nullptr;
}

// kwargs as checked values, every value type- and range-checked by its
// declaration; `given` gets the parameter names given (the CLI's "given": a
// value the run would ignore is refused even when it equals the default).
JobValues keyword_values(const std::vector<ParamSpec>& specs, const py::dict& kw, const std::string& fn,
                         std::set<std::string>& given) {
  JobValues values;
  for (auto [key, value] : kw) {
    const std::string k = py::cast<std::string>(key);
    const ParamSpec* d = find_keyword(specs, k);
    if (!d) {
      py::list names;
      for (const ParamSpec& s : specs) names.append(py_name(s.name));
      py::list close = py::module_::import("difflib").attr("get_close_matches")(k, names, 3, 0.5);
      std::string hint;
      for (auto c : close) hint += (hint.empty() ? "" : ", ") + py::cast<std::string>(c);
      throw py::type_error(fn + "() got an unexpected keyword argument '" + k + "'" +
                           (hint.empty() ? "" : "; did you mean: " + hint + "?") + " (help(" + fn +
                           ") lists the keywords)");
    }
    if (given.count(d->name))
      throw py::type_error(fn + "(): keyword " + py_name(d->name) + " given twice (as '" + k +
                           "' and another of its names)");
    json v = keyword_value(*d, value, fn + "()");
    try {
      d->check(v);
    } catch (const Error& e) {
      throw Error(fn + "(): " + e.what());  // (the message names the keyword: python_spelling)
    }
    values.emplace_back(d->name, std::move(v));
    given.insert(d->name);
  }
  return values;
}

// A record's "job" ({block: {flag name: value}}) as checked values, read as
// `brume run` reads one: every value checked by its declaration and none
// counted as "given" -- a record holds every parameter, so the CLI's rule
// against flags the run would ignore (visibility with kappa-a, say) judges
// them against the defaults, as for a library caller. A CLI record's
// "input", "depth", "stereo" and "output" blocks describe files and how to
// read them (the depth source, its scale and unknown value, the matching of a
// --stereo-right pair), which the arrays and the
// Result stand for: their camera keywords (fx, fov-y ...) are read where
// these declarations have them, the rest skipped. Anything else unknown is
// refused.
JobValues job_values(const std::vector<ParamSpec>& specs, py::handle job, const std::string& fn,
                     const CommandDef* cli) {
  if (!py::isinstance<py::dict>(job))
    throw py::type_error(fn + "(): job takes a record's \"job\" dict ({block: {name: value}}), got " +
                         type_name(job));
  const json j = from_py(job, fn + "(): job");
  JobValues values;
  for (const auto& [block, vals] : j.items()) {
    if (!vals.is_object())
      throw py::value_error(fn + "(): job: block '" + block + "' is not a dict; give a record's \"job\" as it is");
    // A CLI record's camera LiDAR block names files too (--lidar, --lidar-out):
    // without a scan it fogged none, and its settings are no call's; with one
    // its settings are taken and the scan comes as the lidar= array (the form
    // refuses the settings without it). An array form's record holds the
    // settings alone.
    if (block == "lidar" && vals.contains("lidar") && vals["lidar"] == "") continue;
    const bool files = block == "input" || block == "output" || block == "depth" || block == "stereo";
    // The camera's scan settings that no array form has: haze's and fog's "lidar.lidar-…" (brume lidar
    // fog's own "lidar" block is its parameters), and those the camera effects keep in their own block
    // (rain's "rain.lidar", "rain.lidar-out", "rain.lidar-frame" -- which a record of schema 4 without
    // it reads as "scan"): the array form takes the scan as the lidar= array, in its own frame.
    // Only the names the command declares are passed over: a mistyped one ("lidar-gamam") is refused.
    const auto camera_lidar = [&](const std::string& name) {
      if (name.rfind("lidar", 0) != 0 || !cli) return false;
      for (const ParamSpec& q : cli->specs)
        if (q.block == block && q.name == name) return true;
      return false;
    };
    for (const auto& [name, v] : vals.items()) {
      const ParamSpec* d = nullptr;
      for (const ParamSpec& q : specs)
        if (q.name == name && (q.block == block || files)) {
          d = &q;
          break;
        }
      if (!d) {
        if (files || camera_lidar(name)) continue;
        throw py::value_error(fn + "(): job: '" + block + "." + name + "' is not a parameter of " + fn +
                              "; give the \"job\" of a record of the same command");
      }
      try {
        d->check(v);
      } catch (const Error& e) {
        throw Error(fn + "(): job: " + block + "." + name + ": " + e.what());
      }
      values.emplace_back(d->name, v);
    }
  }
  return values;
}

// ==== documentation from the tables ===============================================
std::vector<FunctionDoc>& registry() {
  static std::vector<FunctionDoc> r;
  return r;
}

std::string stub_type(const ParamSpec& s) {
  std::string t;
  switch (s.kind) {
    case ParamKind::real:
      t = "float";
      for (const std::string& w : s.words) t += " | Literal[\"" + w + "\"]";
      break;
    case ParamKind::integer: t = "int"; break;
    case ParamKind::boolean: t = "bool"; break;
    case ParamKind::rgb:
      t = "tuple[float, float, float] | Sequence[float]";
      for (const std::string& w : s.words) t += " | Literal[\"" + w + "\"]";
      break;
    case ParamKind::pair: t = "tuple[float, float] | Sequence[float]"; break;
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

// `defaults`: the table's JSON of a default call ({block: {name: value}}).
FunctionDoc make_doc(const std::string& name, const std::string& public_name, const char* positional,
                     const std::string& summary, const std::vector<ParamSpec>& specs, const json& defaults,
                     std::vector<Extra> extras, std::vector<std::string> fields) {
  FunctionDoc f{name, public_name, positional, summary, {}, std::move(extras), std::move(fields)};
  for (const ParamSpec& s : specs) f.params.emplace_back(s, defaults.at(s.block).at(s.name));
  return f;
}

}  // namespace brume::python
