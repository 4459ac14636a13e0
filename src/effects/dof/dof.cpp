// brume — depth of field by leak-free diffusion (Bertalmio et al. eq. 1-2,
// 14, 16, §3.4); the equations, units and rules are stated in
// include/brume/dof.hpp. This file holds the declaration of the parameters
// and the CPU apply of each scheme, every one of them on the engine's one
// stencil (brume/diffusion.hpp); the scale map (CoC, cap, foreground rule)
// is dof_map.cpp.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "brume/dof.hpp"
#include "brume/error.hpp"
#include "brume/pipeline.hpp"  // the shared parameter blocks
#include "core/huge_pages.hpp"
#include "shared/prelude_cpp.h"

namespace brume {
namespace sh = brume::shared;

const EnumNames<DofScheme>& dof_scheme_names() {
  static const EnumNames<DofScheme> n = {{DofScheme::invariant_exact, "invariant-exact"},
                                         {DofScheme::standard, "standard"},
                                         {DofScheme::bertalmio, "bertalmio"},
                                         {DofScheme::leaky, "leaky"}};
  return n;
}
std::string to_string(DofScheme s) { return enum_name(dof_scheme_names(), s); }

const EnumNames<Foreground>& foreground_names() {
  static const EnumNames<Foreground> n = {{Foreground::soft, "soft"}, {Foreground::sharp, "sharp"}};
  return n;
}

const ParamTable<DofParams>& dof_param_table() {
  static const ParamTable<DofParams> t = [] {
    ParamTable<DofParams> d("dof");
    d.real("focus-distance", &DofParams::focus_distance_m, "m", Range::above(0.0),
           "focus distance Zf, planar depth of the plane in focus (required)", "none")
        .real("f-number", &DofParams::f_number, "1", Range::above(0.0),
              "f-number n of the lens (with the camera's --focal-length and --sensor-width)", "none")
        .real("coc-infinity", &DofParams::coc_infinity_px, "px", Range::at_least(0.0),
              "CoC diameter at infinity, alpha in pixels, instead of the lens (for artists)", "none")
        .real("coc-limit", &DofParams::coc_limit_px, "px", Range::left_open(0.0, 1e6),
              "cap on the target scale sigma = sqrt(sigma0^2 + (c/4)^2), so that a near pixel cannot set the "
              "iteration count")
        .choice("scheme", &DofParams::scheme, dof_scheme_names(),
                "invariant-exact (default: the engine's geometric steps, leak-free, tens of iterations), standard "
                "(eq. 16 with a symmetric edge weight, leak-free, 2 sigma^2 iterations), bertalmio (eq. 16 as "
                "published: leaks across the left/top edges of in-focus objects; CPU), leaky (eq. 14, g Laplacian; "
                "CPU)")
        .choice("foreground", &DofParams::foreground, foreground_names(),
                "soft (default, the paper's §3.4: near-field blur spreads over the background) or sharp (the "
                "unprocessed CoC map: blurred near objects keep a sharp silhouette)")
        .nest_except(&DofParams::diffusion, diffusion_param_table(), {"scheme"});
    return d;
  }();
  return t;
}

void validate_dof(const DofParams& p, const std::set<std::string>& given) {
  const auto& t = dof_param_table();
  t.validate(p);
  if (!p.focus_distance_m)
    throw Error("--focus-distance is required: the planar depth in metres of the plane in focus");
  // The camera's focal length and sensor may be given for the intrinsics
  // whatever the CoC; the aperture is the CoC's alone.
  if (p.coc_infinity_px && p.f_number)
    throw Error("--coc-infinity gives the CoC at infinity directly; do not also give the lens's --f-number, which "
                "would set it too");
  if (!p.coc_infinity_px) {
    const bool sensor = p.lens.sensor_fit == SensorFit::vertical ? p.lens.sensor_height_mm.has_value()
                                                                 : p.lens.sensor_width_mm.has_value();
    if (!(p.f_number && p.lens.focal_length_mm && sensor)) {
      std::string missing;
      if (!p.f_number) missing += " --f-number";
      if (!p.lens.focal_length_mm) missing += " --focal-length";
      if (!sensor) missing += p.lens.sensor_fit == SensorFit::vertical ? " --sensor-height" : " --sensor-width";
      throw Error("the circle of confusion needs the lens (--f-number N --focal-length MM --sensor-width MM; missing:" +
                  missing + ") or --coc-infinity PX");
    }
    const double zf_mm = *p.focus_distance_m * 1000.0;
    if (!(zf_mm > *p.lens.focal_length_mm)) {
      std::ostringstream m;
      m << "--focus-distance " << *p.focus_distance_m << " m is not beyond the focal length --focal-length "
        << *p.lens.focal_length_mm << " mm; a thin lens focuses only on planes farther than F (alpha = F^2/(n (Zf - F))): "
        << "give a focus distance > " << *p.lens.focal_length_mm / 1000.0 << " m";
      throw Error(m.str());
    }
  }
  if (p.coc_limit_px < p.diffusion.sigma0) {
    std::ostringstream m;
    m << "--coc-limit " << p.coc_limit_px << " px is below the inner scale --sigma0 " << p.diffusion.sigma0
      << " px; the cap is on the target scale sigma, which is at least sigma0: give --coc-limit >= --sigma0";
    throw Error(m.str());
  }
  if (p.scheme == DofScheme::leaky && p.diffusion.precision == Precision::f16)
    throw Error("--scheme leaky (eq. 14, a comparison mode) runs in f32 only; drop --precision f16");
  const bool edge_schemes = p.scheme == DofScheme::invariant_exact || p.scheme == DofScheme::standard;
  if (!edge_schemes && t.is_set(p, "edge-rate", given))
    throw Error("--edge-rate is not used by --scheme " + to_string(p.scheme) +
                " (its edge weight is fixed by the paper's equation); drop it, or use --scheme invariant-exact or "
                "standard");
}

DiffusionParams dof_diffusion_params(const DofParams& p) {
  DiffusionParams d = p.diffusion;
  // bertalmio and leaky plan and form their rates as the standard scheme:
  // rho = g/4 = (sigma^2 - sigma0^2)/(2N), N = ceil((smax^2 - s0^2)/(2 rho_max)),
  // which at rho_max = 1/4 is eq. 16's g <= 1 with the corrected N = 2 sigma^2.
  d.scheme = p.scheme == DofScheme::invariant_exact ? Scheme::invariant_exact : Scheme::standard;
  return d;
}

std::optional<double> lens_fx_px(const DofParams& p, int width, int height) {
  if (!p.lens.focal_length_mm) return std::nullopt;
  return lens_intrinsics(p.lens, width, height).fx;
}

double coc_infinity_px(const DofParams& p, int width, int height) {
  if (p.coc_infinity_px) return *p.coc_infinity_px;
  const double F = *p.lens.focal_length_mm, n = *p.f_number, zf_mm = *p.focus_distance_m * 1000.0;
  const double alpha_mm = F * F / (n * (zf_mm - F));  // eq. 2, on the sensor
  // px per mm = s / sensor (s the side the fit spans; before schema 4 the width).
  const LensScale l = lens_scale(p.lens, width, height);
  return alpha_mm * l.side_px / l.sensor_mm;
}

Image planar_depth(const Image& range, const Intrinsics& k) {
  Image z = range_to_z(range, k);
  for (float& v : z.data)
    if (!std::isfinite(v) || v <= 0.0f) v = NAN;
  return z;
}

namespace {

// The rates eq. 16 uses, rho = g/4 = (sigma^2 - sigma0^2)/(2N), per pixel.
Image standard_rates(const Image& sigma, double sigma0, int N) {
  Image rho(sigma.width, sigma.height, 1, 0.0f);
  if (N > 0)
    for (std::size_t i = 0; i < rho.data.size(); ++i)
    rho.data[i] = sh::brume_standard_rate(sigma.data[i], static_cast<float>(sigma0), static_cast<float>(N));
  return rho;
}

}  // namespace

DofResult apply_dof(DenseImageRef rgb, const Image& z, const DofParams& p, DofAnalysis& a, const Exec& exec) {
  if (rgb.channels != 3) throw Error("depth of field needs an RGB image, got " + std::to_string(rgb.channels) + " channels");
  if (rgb.width != z.width || rgb.height != z.height)
    throw Error("depth map " + z.size_string() + " does not match image " + rgb.size_string() +
                "; they must be the same size (resample the depth map, or crop both)");
  DofResult out;
  out.scale = dof_scale_map(z, p, a, exec);
  const DiffusionParams dp = dof_diffusion_params(p);
  const int W = rgb.width, H = rgb.height, N = a.plan.iterations;
  // The default scheme in f32 diffuses the RGB values themselves, as `brume
  // blur` does (rows of three values a pixel: the bits each channel gets in
  // four, DiffusionChannels.RgbRowsGiveTheRgbaBits), in the result's own
  // buffer: no RGBA image (12.6 MB at 1024 x 768, zero-filled and first
  // touched in every call), no packing into it nor out of it, and a quarter
  // less arithmetic and traffic. The other schemes' conductance rows and
  // binary16 storage take four channels.
  if (p.scheme == DofScheme::invariant_exact && dp.precision == Precision::f32) {
    detail::reserve_huge(out.rgb.data, rgb.data.size());
    out.rgb.data.assign(rgb.data.begin(), rgb.data.end());
    out.rgb.width = W, out.rgb.height = H, out.rgb.channels = 3;
    diffuse(out.rgb, out.scale, a.sigma_max, dp, exec);
    return out;
  }
  // RGB and a constant fourth channel (the engine's vector width; mass
  // conservation keeps it 1 except with eq. 14, which does not conserve).
  Image f(W, H, 4);
  for (std::size_t i = 0; i < rgb.pixels(); ++i) {
    for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = rgb.data[i * 3 + c];
    f.data[i * 4 + 3] = 1.0f;
  }
  switch (p.scheme) {
    case DofScheme::invariant_exact:
    case DofScheme::standard:
      diffuse(f, out.scale, a.sigma_max, dp, exec);
      break;
    case DofScheme::bertalmio: {
      // Eq. 16: the edge (x, x+1) and (y, y+1) weighted by g/4 of the pixel
      // holding the forward difference, i.e. wx = wy = rho(x, y).
      const Image w = standard_rates(out.scale, dp.sigma0, N);
      diffuse_conductance(f, w, w, N, dp.precision, exec);
      break;
    }
    case DofScheme::leaky: {
      // Eq. 14: I <- I + g/4 Delta I = I + g (J - I) with J one isotropic
      // step of weight 1/4 on every edge (the engine's conductance step).
      const Image rho = standard_rates(out.scale, dp.sigma0, N);
      const Image quarter(W, H, 1, 0.25f);
      for (int k = 0; k < N; ++k) {
        Image j = f;
        diffuse_conductance(j, quarter, quarter, 1, dp.precision, exec);
        for (std::size_t i = 0; i < f.pixels(); ++i) {
          const float g = 4.0f * rho.data[i];
          for (int c = 0; c < 4; ++c) f.data[i * 4 + c] += g * (j.data[i * 4 + c] - f.data[i * 4 + c]);
        }
      }
      break;
    }
  }
  out.rgb = Image(W, H, 3);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) out.rgb.data[i * 3 + c] = f.data[i * 4 + c];
  return out;
}

}  // namespace brume
