// brume — an effect's frame as data, for the browser preview (`brume view`,
// docs/view.md): the passes to draw, with their inputs, render targets and
// uniforms, so that the page runs the native backend's passes (the same
// GLSL, src/gpu/passes.hpp) in WebGL2 without knowing any effect.
//
// A plan is JSON:
//   {"targets": {NAME: "RGBA32F" | "RGBA16F" | "RG32F" | "R32F", ...},   image-sized
//    "steps": [{"pass": PASS, "in": [TEXTURE, ...], "out": [TARGET, ...],
//               "uniforms": {NAME: [TYPE, value...]},                     TYPE 1f 3f 1i
//               "iterate": {"count": N, "uniform": "uK", "ping": A, "pong": B, "last": ALIAS}}
//              | {"copy": {"from": TEXTURE, "to": TARGET}}],                 a plain copy (no pass)
//    "result": TEXTURE}
// TEXTURE: a target, or "image" (linear RGB, alpha 1), "range" (the prepared
// range, -1 unknown), "sky" (the preparation's sky weight, 0 without one),
// one of the plan's "data" (names of the frame's maps, PreviewFrame::maps,
// fetched by the page when it has no map of that name: any size, 1, 2, 3 or
// 4 channels, the values as the passes read them; a name "KIND:KEY" replaces
// the page's older map of that KIND), or an iterate step's ALIAS. Uniform TYPEs: 1f 2f 3f 4f 1i, and 1fv with an array. An iterate step draws its pass `count` times,
// reading "$src" (A first) and writing the other, and names the last written
// ALIAS. Every texture is NEAREST: samples between texels are interpolated
// in the shader, as `--gpu-filter shader` does natively.
#pragma once

#include <map>
#include <string>

#include <nlohmann/json.hpp>

#include "brume/depth.hpp"
#include "brume/diffusion.hpp"
#include "brume/image.hpp"

namespace brume {

struct PreparedRange;

// What an effect's preview plan is made from: the colour image, the
// measured range (after completion) and the prepared range, as the
// command's own run would have them; at 1/scale of the files' size when the
// browser's largest texture is smaller than the image (the colour
// box-averaged, the range sampled at each block's pixel (k/2, k/2)).
struct PreviewInputs {
  const Image& rgb;
  const Image& measured;
  const PreparedRange& prepared;
  int scale = 1;
  int full_width = 0, full_height = 0;  // the files' size (0: the inputs')
};

// The camera intrinsics of the inputs at 1/scale, from those of the files'
// size (the depth flags' --fx, --cx, --calib are in its pixels): the ray
// through pixel x' of the smaller image is the ray through the pixel its
// range was sampled at, x = scale x' + scale/2 (integer division), so
// fx' = fx / scale and cx' = (cx - scale/2) / scale.
Intrinsics preview_intrinsics(const Intrinsics& full, int scale);
// The files' size of the inputs.
inline int preview_full_width(const PreviewInputs& in) { return in.full_width > 0 ? in.full_width : in.rgb.width; }
inline int preview_full_height(const PreviewInputs& in) { return in.full_height > 0 ? in.full_height : in.rgb.height; }

// ---- where the page starts (brume view opens on a picture) ----------------------------
// What the page knows of the scene before its first frame: statistics of the
// measured range at the files' size over its known pixels (finite, > 0; the
// sky and holes excluded).
struct PreviewScene {
  double median_range_m = NAN;  // the median known range
  double centre_range_m = NAN;  // the median known range in the central tenth (each side) of the image, else the median
  double range_min_m = NAN, range_max_m = NAN;
  int width = 0, height = 0;  // the files' size
  bool camera_given = false;  // the command line's depth flags give the intrinsics (--fx.., --fov-x/-y, --calib)
};
PreviewScene preview_scene(const Image& measured, bool camera_given);
// A value the page starts from instead of the table's default, where the
// default would show nothing on this scene (a command's
// CommandDef::preview_start): the copied command spells it out, and the
// page says why.
struct PreviewStart {
  std::string name;      // a parameter the page sets (the effect's, or the camera's: fov-x)
  nlohmann::json value;  // as the table holds it
  std::string why;       // one line for the page
};
// v to two significant digits: a starting value a user reads and edits.
double preview_round(double v);
// v as the page's reasons print it (three significant digits).
std::string preview_text(double v);
// The camera the page assumes where the command needs one and the command
// line gave none: a 60 degree horizontal field of view (between the usual
// datasets': Middlebury ~53, KITTI ~82; the demo's 55 degree vertical is
// ~73), which the page's camera controls change.
PreviewStart preview_assumed_camera(const PreviewScene& s);

// A uniform of a plan step.
inline nlohmann::json preview_f(double v) { return {"1f", v}; }
inline nlohmann::json preview_i(int v) { return {"1i", v}; }
inline nlohmann::json preview_f3(const float* v) { return {"3f", v[0], v[1], v[2]}; }
inline nlohmann::json preview_f2(float a, float b) { return {"2f", a, b}; }
inline nlohmann::json preview_f3(float a, float b, float c) { return {"3f", a, b, c}; }
inline nlohmann::json preview_f4(float a, float b, float c, float d) { return {"4f", a, b, c, d}; }

// A frame: its plan, and the maps the plan names in "data" (made on the
// host with the plan, as the native path makes them: fog's range with its
// sky unknown, dof's scale map, aerial's ln Gamma tables and sky mask).
struct PreviewFrame {
  nlohmann::json plan;
  std::map<std::string, Image> maps;
  // Adds a map, named "KIND:" and a hash of its size and values (so the page
  // fetches it again only when it changes), to maps and plan["data"];
  // returns the name.
  std::string add_map(const std::string& kind, Image m);
};

// The map with unknown values (0, NaN, inf) as -1, as the GPU backend
// uploads a range (gpu::upload_color_and_range).
Image preview_unknown_negative(Image m);

// The scattering blur's steps (src/diffusion/diffusion_gpu.cpp with --gpu-filter
// shader): the rate pass from `sigma` (.r) into target "rates", then the
// diffusion of `f_ping` (ping-ponging with `f_pong`) whose last texture is
// named `last`. Appended to plan["steps"].
void preview_diffusion_steps(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d,
                             const std::string& sigma, const std::string& f_ping, const std::string& f_pong,
                             const std::string& last);
// Its two parts: the rate pass into "rates", and the diffusion of one
// texture with those rates (aerial diffuses two with one rate map).
void preview_rates_step(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d, const std::string& sigma);
void preview_iterate_step(nlohmann::json& plan, const DiffusionParams& p, const DiffusionPlan& d,
                          const std::string& f_ping, const std::string& f_pong, const std::string& last);

}  // namespace brume
