// brume._brume — what the binding's files share (python/src): JSON and
// arrays in and out (convert.cpp), keywords, docstrings and stubs from the
// parameter tables (keywords.cpp), the GPU context of each Python thread
// (gpu.cpp); module.cpp holds the definitions. Conventions: module.cpp's head.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/command.hpp"
#include "brume/gpu_context.hpp"
#include "brume/image.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/pipeline.hpp"

namespace brume::python {

namespace py = pybind11;
using json = nlohmann::json;

// ---- JSON <-> Python (convert.cpp) -------------------------------------------------------
py::object to_py(const json& j);
json from_py(py::handle o, const std::string& where);
std::string type_name(py::handle o);

// ---- keywords from the parameter tables (keywords.cpp) -------------------------------------
// `--f-number` -> f_number; a Python keyword gets a trailing underscore.
std::string py_name(const std::string& flag);
// A library message in Python's words: every flag the tables declare as its
// keyword, the value after it as the keyword's argument ("--camera-height
// METRES" -> "camera_height=METRES", "--profile exponential" ->
// "profile='exponential'"). The exception translator applies it to every error.
std::string python_spelling(const std::string& text);
// A str as UTF-8 text (check_utf8's message for lone surrogates).
std::string utf8_of(py::handle v, const std::string& what);
// The value a keyword holds, as the JSON the table's setter takes (TypeError for a wrong Python type).
json keyword_value(const ParamSpec& s, py::handle v, const std::string& where);
// A text parameter named "path" (read_image, write_image).
ParamSpec path_spec();
const ParamSpec* find_keyword(const std::vector<ParamSpec>& specs, const std::string& k);
JobValues keyword_values(const std::vector<ParamSpec>& specs, const py::dict& kw, const std::string& fn,
                         std::set<std::string>& given);
// A record's "job" as the form's values; cli: the command the record's CLI run was (its camera
// LiDAR files and settings that no array form has are passed over), or null.
JobValues job_values(const std::vector<ParamSpec>& specs, py::handle job, const std::string& fn,
                     const CommandDef* cli);

// ---- docstrings and stubs (keywords.cpp) -------------------------------------------------------
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
std::vector<FunctionDoc>& registry();
std::string docstring(const FunctionDoc& f);
std::string stub_text();
// `defaults`: the table's JSON of a default call ({block: {name: value}}).
FunctionDoc make_doc(const std::string& name, const std::string& public_name, const char* positional,
                     const std::string& summary, const std::vector<ParamSpec>& specs, const json& defaults,
                     std::vector<Extra> extras, std::vector<std::string> fields);

// ---- the GPU context of each Python thread (gpu.cpp) -------------------------------------------
// The calling thread's context (made by its first GPU call; null before or when none could be made).
extern thread_local std::unique_ptr<GpuContext> t_gpu;
GpuContext* thread_gpu(const Exec& exec);
Exec with_thread_gpu(Exec e);

// ---- fork safety (fork.cpp) ------------------------------------------------------------------
// In a process forked from one that loaded the module (a multiprocessing or
// DataLoader worker), libgomp's inherited pool cannot run a parallel region
// of more than one thread on the forking thread. fork_safe: threads=0 means
// 1 there. run_fork_safe: runs f (GIL released, the library call), on a
// thread of its own when the child asked for more than one thread.
void install_fork_handlers();
bool in_forked_child();
Exec fork_safe(Exec e);
void run_fork_safe(const Exec& e, const std::function<void()>& f);

// ---- arrays in and out (convert.cpp) --------------------------------------------------------
// What each input of the last call on this thread became (the zero-copy test
// reads it): the address the library read and whether that was a copy.
struct InputTrace {
  std::uintptr_t address = 0;
  bool copied = false;
  std::string how;
};
extern thread_local std::map<std::string, InputTrace> g_last_inputs;

// One input image as the library sees it: a view of the caller's pixels
// (float32 with contiguous channels), or of `owned` (a conversion).
struct Input {
  ConstImageView view;
  Image owned;
  py::object keep;  // the array the view points into
  json record;
  DenseImageRef dense;  // as_dense: the same pixels for the dense-image APIs
};

Transfer parse_transfer_kw(py::handle t, const std::string& where);
// max_rows: the largest first dimension (images: 2^20; a scan's points: a 32-bit count).
Input read_input(py::handle obj, const std::string& arg, int channels, Transfer transfer, const std::string& fn,
                 long long max_rows = 1 << 20);
// A LiDAR scan: an (N, 4) float32 (in place) or float64 (converted once) array of x, y, z, intensity.
Input read_points(py::handle obj, const std::string& arg, const std::string& fn);
// A mask (ArrayArg::mask): H x W (or x 1) bool, or float32/float64 whose values above 1/2 mark it; an
// owned Image of 0 and 1. Integer arrays are refused (0/1 or 0/255? the caller says so with a bool).
Input read_mask(py::handle obj, const std::string& arg, const std::string& fn);
DenseImageRef as_dense(Input& in, const std::string& arg);
const Image& as_image(Input& in, const std::string& arg);
py::array to_numpy(Image&& img);
py::object make_result(std::map<std::string, Image>&& images, const json& record,
                       const std::map<std::string, py::object>& more = {});
json python_header(const std::string& command, const std::string& fn);

}  // namespace brume::python
