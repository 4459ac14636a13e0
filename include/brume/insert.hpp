// brume — inserting a virtual object into a photo with aerial perspective
// (Morales, "Rendering aerial perspective in mixed reality from atmospheric
// turbidity", ch. 4; the model and its symbols are brume/aerial.hpp's).
//
// Inputs, all the same size and seen by the same camera:
//   P      the photo, linear RGB, with its measured range R_s [m] (NaN, inf, 0: unknown = sky)
//   O      the object, linear RGBA premultiplied: (alpha E, alpha), alpha its coverage in [0, 1]
//   R_o    the object's range [m]; unknown where the object is absent
// Depth test: the object is VISIBLE where alpha > 0, R_o is known and
//   R_o <= R_s or R_s unknown (the sky is behind everything). Ties go to the
//   object, so a render of the scene itself (R_o = R_s) covers the scene.
//   Unknown R_o means absent whatever alpha says (an opaque render background
//   at infinity); such pixels are counted in the record.
// The object receives aerial perspective for ITS range, s = R_o distance_scale,
// with the scene's horizon Iinf (estimated from the photo and R_s exactly as
// `brume aerial` does, or given) and turbidity; the photo's own pixels are left
// as they are (their aerial perspective is real). Per channel c of the
// sensitivity's space (XYZ: M diag(Gamma) M^-1, as aerial):
//   object layer  L_c = Gamma_c alpha E_c + alpha (1 - Gamma_c) Iinf_c
//   composite     out_c = L_c + (1 - alpha) P_c        where visible; P elsewhere, bit for bit
// With --lambda > 0 the scattering blur (haze's sigma law with kappa_s' of
// aerial) diffuses the object's layer premultiplied in SEVEN channels,
//   F = (Gamma_c alpha E_c, Gamma_c alpha, alpha)   (0 where the object is not visible),
//   out_c = F_c + (F_6 - F_{3+c}) Iinf_c + (1 - F_6) P_c   where visible,
// so the coverage the photo is composited under is the BLURRED coverage F_6
// (an alpha edge softens without a dark or bright fringe), and the airlight in
// front of the object is carried by the blurred alpha (1 - Gamma) = F_6 - F_{3+c}.
// Target scale sigma(x): the object's range where it is visible, else the
// scene's (prepared) range, normalised by the scene's R_max (sigma_max beyond).
// Only visible pixels change: the blur softens the object's silhouette inwards
// (its coverage there drops towards the absent side) and never spills onto
// pixels where the object is absent or hidden.
// With alpha = 1 and R_o = R_s everywhere (the scene as its own object),
// out = Gamma E + (1 - Gamma) Iinf = `brume aerial`'s render on known pixels.
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brume/aerial.hpp"
#include "brume/exec.hpp"
#include "brume/image.hpp"
#include "brume/io.hpp"
#include "brume/params.hpp"
#include "brume/range_step.hpp"

namespace brume {

// The object's files. Its range follows --range's conventions (metres along
// the ray; an integer file needs --object-depth-scale).
struct InsertObject {
  std::string object;                        // RGBA image (EXR linear premultiplied; PNG/TIFF sRGB straight alpha)
  std::string object_layer;                  // its layer in a file with layers (brume/io.hpp): NAME.R, .G, .B, .A
  std::string object_range;                  // its range map [m]
  std::string object_range_channel;          // channel of a multi-channel range file ("" : the only one)
  std::optional<double> object_depth_scale;  // [m] per count of an integer range file
  std::optional<double> object_unknown_value;  // stored value meaning "no object here" (e.g. -1)
};
const ParamTable<InsertObject>& insert_object_param_table();

// Reads an object image as linear premultiplied RGBA (4 channels):
//   float files (EXR, float TIFF, PFM, HDR): linear and premultiplied, as EXR
//     defines it; values taken as stored;
//   integer files (PNG, 8/16-bit TIFF): sRGB-encoded colour with STRAIGHT alpha
//     (PNG's definition): colour decoded to linear, then multiplied by alpha;
//   no alpha channel: alpha 1 (the object is where its range is known); grey
//     files are expanded to RGB.
// Throws brume::Error naming the file for alpha outside [0, 1] or non-finite values.
Image read_object_rgba(const std::string& path, FileInfo* info = nullptr, const std::string& layer = "");

// The aerial parameters that apply to an insert: aerial's table without the
// re-render and remove parameters (--from-turbidity, --from-horizon,
// --remove, --gamma-floor), which an insert would ignore.
const ParamTable<AerialParams>& insert_aerial_param_table();
// Range checks; refuses remove / re-render settings (library callers).
void validate_insert(const AerialParams& p, const std::set<std::string>& given = {});

struct InsertAnalysis {
  AerialAnalysis aerial;  // Iinf, Gamma table (to the farther of the scene's and the visible object's R_max), sigma law
  Image visible;          // 1 where the object is visible (the depth test above), else 0
  std::size_t object_pixels = 0;   // alpha > 0 and range known
  std::size_t visible_pixels = 0;  // of those, in front of the scene (or over the sky)
  std::size_t hidden_pixels = 0;   // of those, behind a scene surface
  std::size_t coverage_without_range_pixels = 0;  // alpha > 0 but range unknown: absent (not an error)
  double object_range_min_m = 0.0, object_range_max_m = 0.0;  // over visible pixels (0 if none)
};
// Validates and checks sizes (messages name the photo and the object), runs
// analyse_aerial on the photo and its MEASURED range (on `threads` OpenMP
// threads, 0 = all), and depth-tests the object.
InsertAnalysis analyse_insert(const Image& photo, const Image& scene_range, const Image& object_rgba,
                              const Image& object_range, const AerialParams& p, int threads = 0);

struct InsertResult {
  Image rgb;       // linear RGB
  Image coverage;  // 1 channel: the (blurred) coverage F_6 the photo was composited under; 0 where not visible
  Image scale;     // target scale sigma(x) in px, 1 channel
};
// The per-pixel apply on the CPU. `effect_range` is the scene range sigma is
// read from where the object is not visible (the prepared one in the pipeline).
InsertResult apply_insert(const Image& photo, const Image& effect_range, const Image& object_rgba,
                          const Image& object_range, const AerialParams& p, const InsertAnalysis& a,
                          const Exec& exec = {});

// ---- the pipeline ---------------------------------------------------------------------
struct InsertRun {
  InsertResult result;
  InsertAnalysis analysis;
  nlohmann::json record;  // {"insert": ..., "prepare": ..., "execution": ...}
};
// In memory: everything `brume insert` does between reading and writing. CPU
// only: Backend::gpu is refused with a message naming --backend cpu.
InsertRun insert_object(const Image& photo, const Image& scene_range, const Image& object_rgba,
                        const Image& object_range, const AerialParams& p, const RangeStep& prepare = {},
                        const Exec& exec = {}, const std::set<std::string>& given = {});

}  // namespace brume
