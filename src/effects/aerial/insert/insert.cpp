// brume — inserting a virtual object with aerial perspective: the parameter
// declarations, reading the object, the depth test (analysis) and the
// per-pixel apply with the optional seven-channel scattering blur. The
// equations and conventions are stated in include/brume/insert.hpp.
#include <omp.h>


#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "brume/depth.hpp"
#include "brume/error.hpp"
#include "brume/insert.hpp"
#include "brume/io.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "core/schedule.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

namespace {

std::string pixel_text(std::size_t i, int w) {
  // Appended piece by piece: GCC 12's -Wrestrict misfires on "(" + to_string(...) (its bug 105329).
  std::string s = "(";
  s += std::to_string(i % static_cast<std::size_t>(w));
  s += ", ";
  s += std::to_string(i / static_cast<std::size_t>(w));
  s += ")";
  return s;
}

}  // namespace

const ParamTable<InsertObject>& insert_object_param_table() {
  static const ParamTable<InsertObject> t = [] {
    ParamTable<InsertObject> d("object");
    d.text("object", &InsertObject::object,
           "the virtual object, RGBA, same size and camera as --image: EXR (float) linear premultiplied; PNG/TIFF "
           "(integer) sRGB colour with straight alpha; no alpha channel: alpha 1 where its range is known")
        .reads_file()
        .text("object-layer", &InsertObject::object_layer,
              "the layer of --object in a file with layers (NAME.R, NAME.G, NAME.B, NAME.A of a multilayer OpenEXR, "
              "e.g. ViewLayer.Combined)")
        .text("object-range", &InsertObject::object_range,
              "the object's range map in metres along the ray (as --range); unknown (NaN, inf, 0) where the object "
              "is absent")
        .reads_file()
        .text("object-range-channel", &InsertObject::object_range_channel,
              "channel of a multi-channel object range file (e.g. Z); empty: the file's only channel")
        .real("object-depth-scale", &InsertObject::object_depth_scale, "m", Range::above(0.0),
              "metres per count of an integer object range file (required there)", "none")
        .real("object-unknown-value", &InsertObject::object_unknown_value, "file units", Range::any(),
              "a stored value of the object range file that means 'no object here' (e.g. -1)", "none");
    return d;
  }();
  return t;
}

const ParamTable<AerialParams>& insert_aerial_param_table() {
  static const ParamTable<AerialParams> t = [] {
    // Aerial's own declarations, reused (one declaration per parameter); the
    // re-render and remove parameters are not offered, since an insert
    // renders the object and would ignore them.
    ParamTable<AerialParams> d("aerial");
    for (const Param<AerialParams>& q : aerial_param_table().params()) {
      if (q.spec.block != "aerial") continue;
      if (q.spec.name == "from-turbidity" || q.spec.name == "from-airlight" || q.spec.name == "remove" ||
          q.spec.name == "gamma-floor" || q.spec.name == "path")  // the object's path: level (issue #59 left it)
        continue;
      d.custom(q.spec, q.get, q.set);
    }
    d.nest(&AerialParams::diffusion, diffusion_param_table());
    return d;
  }();
  return t;
}

void validate_insert(const AerialParams& p, const std::set<std::string>& given) {
  insert_aerial_param_table().validate(p);
  if (p.remove || p.from_turbidity || p.from_airlight)
    throw Error("insert renders the object at --turbidity; --remove, --from-turbidity and --from-horizon belong to "
                "`brume aerial` (remove or re-render the photo there first, then insert into the result)");
  if (p.turbidity_rule == "contrast") {
    // The T the photo shows, fitted by insert_object before the analysis: the
    // rest is checked as at any T.
    AerialParams q = p;
    q.turbidity_rule.clear();
    q.atmosphere.turbidity = 1.0;
    validate_aerial(q, given);
    return;
  }
  validate_aerial(p, given);
}

Image read_object_rgba(const std::string& path, FileInfo* info, const std::string& layer) {
  if (path.empty()) throw Error("no object given: use --object FILE (RGBA, same size as --image)");
  ChannelImage ci;
  const ExrChannels ec = exr_channels(path);
  if (!layer.empty() || (ec.exr && (ec.multipart || !plain_channels(ec.names)))) {
    // A file with layers (a render): the layer's R, G, B and A by name, as
    // stored (OpenEXR: linear, premultiplied).
    ColorRead how;
    how.transfer = Transfer::linear;
    how.layer = layer;
    how.layer_flag = "--object-layer";
    Image a;
    const Image rgb = read_color(path, how, &ci.info, &a);
    ci.img = Image(rgb.width, rgb.height, a.empty() ? 3 : 4);
    for (std::size_t i = 0; i < rgb.pixels(); ++i) {
      for (int c = 0; c < 3; ++c) ci.img.data[i * ci.img.channels + c] = rgb.data[i * 3 + c];
      if (!a.empty()) ci.img.data[i * 4 + 3] = a.data[i];
    }
    ci.alpha = a.empty() ? -1 : 3;
  } else {
    // Alpha kept unassociated: OpenImageIO would otherwise premultiply PNG's
    // and TIFF's sRGB-ENCODED values, which is not linear-light coverage.
    ci = read_unassociated(path, "--object");
  }
  const Image& raw = ci.img;
  const int nc = raw.channels, W = raw.width;
  const bool integer = ci.info.integer;
  FileInfo fi = ci.info;
  fi.transfer = integer ? Transfer::srgb : Transfer::linear;

  int alpha = ci.alpha;
  if (alpha < 0 && (nc == 2 || nc == 4)) alpha = nc - 1;  // grey+alpha, RGBA without a named alpha
  std::vector<int> colour;
  for (int c = 0; c < nc && colour.size() < 3; ++c)
    if (c != alpha) colour.push_back(c);
  if (colour.size() == 2) colour.resize(1);  // two colour channels: ambiguous; take the first as grey
  // Integer files are sRGB-encoded with straight alpha (PNG's definition, and
  // what a TIFF without associated alpha holds); float files are linear and
  // premultiplied (EXR's definition) unless the file says its alpha is unassociated.
  const bool straight = integer || ci.unassociated;
  Image out(W, raw.height, 4);
  for (std::size_t i = 0; i < raw.pixels(); ++i) {
    const float a = alpha >= 0 ? raw.data[i * nc + alpha] : 1.0f;
    if (!(a >= 0.0f && a <= 1.0f)) {
      std::ostringstream m;
      m << "--object '" << path << "': alpha at pixel " << pixel_text(i, W) << " is " << a
        << "; coverage must be in [0, 1] (fix the object's alpha channel)";
      throw Error(m.str());
    }
    for (int k = 0; k < 3; ++k) {
      float v = raw.data[i * nc + colour[colour.size() == 1 ? 0 : k]];
      if (!std::isfinite(v)) {
        std::ostringstream m;
        m << "--object '" << path << "': colour at pixel " << pixel_text(i, W) << " is " << v
          << "; every value must be finite";
        throw Error(m.str());
      }
      if (integer) v = srgb_to_linear(v);
      out.data[i * 4 + k] = straight ? v * a : v;
    }
    out.data[i * 4 + 3] = a;
  }
  if (info) *info = fi;
  return out;
}

InsertAnalysis analyse_insert(const Image& photo, const Image& scene_range, const Image& object_rgba,
                              const Image& object_range, const AerialParams& p, int threads) {
  validate_insert(p);
  if (object_rgba.channels != 4)
    throw Error("the object must be RGBA (4 channels, premultiplied), got " + std::to_string(object_rgba.channels));
  if (object_range.channels != 1) throw Error("the object's range map must have one channel");
  if (object_rgba.width != photo.width || object_rgba.height != photo.height)
    throw Error("the object is " + object_rgba.size_string() + " but the photo is " + photo.size_string() +
                "; the object must be rendered at the photo's size with the photo's camera");
  if (object_range.width != photo.width || object_range.height != photo.height)
    throw Error("the object's range map is " + object_range.size_string() + " but the photo is " +
                photo.size_string() + "; they must be the same size (render the object's range with the photo's camera)");

  InsertAnalysis a;
  // Iinf, the Gamma table and the sigma law exactly as `brume aerial` on the photo.
  a.aerial = analyse_aerial(photo, scene_range, p, threads);
  a.visible = Image(photo.width, photo.height, 1, 0.0f);
  double omin = INFINITY, omax = 0.0;
  for (std::size_t i = 0; i < photo.pixels(); ++i) {
    const float al = object_rgba.data[i * 4 + 3], ro = object_range.data[i];
    if (!(al > 0.0f)) continue;
    // Unknown range marks the object absent whatever its alpha (a renderer's
    // opaque background at infinity, or the scene rendered as its own object
    // with alpha 1 over the sky); counted in the record.
    if (!known_range(ro)) {
      ++a.coverage_without_range_pixels;
      continue;
    }
    if (ro < 0.0f) {
      std::ostringstream m;
      m << "the object's range at pixel " << pixel_text(i, photo.width) << " is " << ro
        << " m; ranges must be >= 0 (0, NaN and inf mark absent pixels)";
      throw Error(m.str());
    }
    ++a.object_pixels;
    const float rs = scene_range.data[i];
    // Ties go to the object: a render of the scene covers the scene itself.
    if (known_range(rs) && !(ro <= rs)) {
      ++a.hidden_pixels;
      continue;
    }
    ++a.visible_pixels;
    a.visible.data[i] = 1.0f;
    omin = std::min(omin, static_cast<double>(ro));
    omax = std::max(omax, static_cast<double>(ro));
  }
  a.object_range_min_m = a.visible_pixels ? omin : 0.0;
  a.object_range_max_m = omax;
  // An object beyond the scene's farthest point (over the sky): tabulate Gamma
  // out to it rather than extrapolating; sigma keeps the scene's law (R' is
  // clamped to 1, as the sky's).
  if (omax > a.aerial.range_max_m)
    a.aerial.gamma =
        attenuation_table(p.atmosphere, a.aerial.sensitivity, omax * p.distance_scale, kAttenuationSamples, threads);
  return a;
}

InsertResult apply_insert(const Image& photo, const Image& effect_range, const Image& object_rgba,
                          const Image& object_range, const AerialParams& p, const InsertAnalysis& a,
                          const Exec& exec) {
  const int W = photo.width, H = photo.height;
  if (photo.channels != 3 || effect_range.channels != 1 || effect_range.width != W || effect_range.height != H ||
      object_rgba.channels != 4 || object_rgba.width != W || object_rgba.height != H ||
      object_range.channels != 1 || object_range.width != W || object_range.height != H)
    throw Error("insert: photo " + photo.size_string() + ", range " + effect_range.size_string() + ", object " +
                object_rgba.size_string() + " and object range " + object_range.size_string() +
                " must be the same size (RGB, 1, RGBA, 1 channels)");
  if (a.visible.width != W || a.visible.height != H)
    throw Error("insert: the analysis was made for another image size (" + a.visible.size_string() + ")");
  const AerialAnalysis& aa = a.aerial;
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const bool xyz = aa.sensitivity.space == SensitivitySpace::xyz;
  const float s0 = static_cast<float>(p.diffusion.sigma0), smax = static_cast<float>(aa.sigma_max);
  const float inv_rmax = static_cast<float>(1.0 / aa.range_max_m);
  auto to_space = [xyz](const std::array<float, 3>& c) {
    if (!xyz) return c;
    return std::array<float, 3>{sh::brume_srgb_to_x(c[0], c[1], c[2]), sh::brume_srgb_to_y(c[0], c[1], c[2]),
                                sh::brume_srgb_to_z(c[0], c[1], c[2])};
  };
  const std::array<float, 3> A = to_space(aa.airlight);
  const bool blur = aa.plan.iterations > 0 && a.visible_pixels > 0;

  InsertResult out;
  out.rgb = photo;  // absent or hidden: the photo, bit for bit
  out.coverage = Image(W, H, 1, 0.0f);
  out.scale = Image(W, H, 1);
  Image f(W, H, 7, 0.0f);  // (Gamma alpha E, Gamma alpha, alpha); 0 where the object is not visible
#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      const bool vis = a.visible.data[i] > 0.0f;
      const float r = vis ? object_range.data[i] : effect_range.data[i];
      out.scale.data[i] = sh::brume_target_scale(known_range(r) ? r * inv_rmax : 1.0f, s0, smax);
      if (!vis) continue;
      const float al = object_rgba.data[i * 4 + 3];
      const std::array<float, 3> e =
          to_space({object_rgba.data[i * 4], object_rgba.data[i * 4 + 1], object_rgba.data[i * 4 + 2]});
      const std::array<float, 3> g = aa.gamma.at(static_cast<double>(object_range.data[i]) * p.distance_scale);
      for (int c = 0; c < 3; ++c) {
        f.data[i * 7 + c] = g[c] * e[c];
        f.data[i * 7 + 3 + c] = g[c] * al;
      }
      f.data[i * 7 + 6] = al;
    }

  if (blur) diffuse(f, out.scale, aa.sigma_max, p.diffusion, exec);

#pragma omp parallel for num_threads(nt) schedule(dynamic, kRowChunk)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + x;
      if (!(a.visible.data[i] > 0.0f)) continue;
      const float cov = f.data[i * 7 + 6];
      std::array<float, 3> o{};
      // The airlight in front of the object is weighted by its coverage:
      // alpha (1 - Gamma) = F_6 - F_{3+c}.
      for (int c = 0; c < 3; ++c) o[c] = f.data[i * 7 + c] + (cov - f.data[i * 7 + 3 + c]) * A[c];
      if (xyz)
        o = {sh::brume_xyz_to_r(o[0], o[1], o[2]), sh::brume_xyz_to_g(o[0], o[1], o[2]),
             sh::brume_xyz_to_b(o[0], o[1], o[2])};
      for (int c = 0; c < 3; ++c) out.rgb.data[i * 3 + c] = o[c] + (1.0f - cov) * photo.data[i * 3 + c];
      out.coverage.data[i] = cov;
    }
  return out;
}

}  // namespace brume
