// brume — diffusion front end: planning (eq. 13 / eq. 18), validation of the
// inputs, and dispatch to the CPU schedules.
#include <cmath>
#include <sstream>

#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "cpu/diffusion_kernels.hpp"

namespace brume {

std::string to_string(Scheme s) {
  switch (s) {
    case Scheme::standard: return "standard";
    case Scheme::invariant: return "invariant";
    case Scheme::invariant_exact: return "invariant-exact";
  }
  return "?";
}

std::string to_string(Precision p) { return p == Precision::f16 ? "f16" : "f32"; }

Scheme parse_scheme(const std::string& s) {
  if (s == "standard") return Scheme::standard;
  if (s == "invariant") return Scheme::invariant;
  if (s == "invariant-exact") return Scheme::invariant_exact;
  throw Error("--scheme '" + s + "' is not a diffusion scheme; use standard, invariant or invariant-exact");
}

Precision parse_precision(const std::string& s) {
  if (s == "f32") return Precision::f32;
  if (s == "f16") return Precision::f16;
  throw Error("--precision '" + s + "' is not supported; use f32 or f16");
}

std::string to_string(EdgeRate e) {
  switch (e) {
    case EdgeRate::mean: return "mean";
    case EdgeRate::min: return "min";
    case EdgeRate::harmonic: return "harmonic";
  }
  return "?";
}

EdgeRate parse_edge_rate(const std::string& s) {
  if (s == "mean") return EdgeRate::mean;
  if (s == "min") return EdgeRate::min;
  if (s == "harmonic") return EdgeRate::harmonic;
  throw Error("--edge-rate '" + s + "' is not an edge rate; use mean (the paper's eq. 12), min or harmonic");
}

double effective_rho_max(const DiffusionParams& p) {
  if (p.rho_max) return *p.rho_max;
  return p.scheme == Scheme::invariant_exact ? 0.2 : 0.25;
}

DiffusionPlan plan_diffusion(const DiffusionParams& p, double sigma_max) {
  const double rho_max = effective_rho_max(p);
  if (!(p.sigma0 > 0.0) || !std::isfinite(p.sigma0))
    throw Error("--sigma0 " + std::to_string(p.sigma0) + " px is not allowed; the inner scale must be a finite number > 0 (typically 0.5 to 1 px)");
  if (!(rho_max > 0.0 && rho_max <= 0.25))
    throw Error("--rho-max " + std::to_string(rho_max) + " is not allowed: it must be in (0, 0.25], the stability limit of the 2-D explicit scheme (auto = the scheme's default)");
  if (!std::isfinite(sigma_max) || sigma_max < p.sigma0) {
    std::ostringstream m;
    m << "largest target scale " << sigma_max << " px is below the inner scale --sigma0 "
      << p.sigma0 << " px; diffusion can only add blur";
    throw Error(m.str());
  }
  DiffusionPlan plan;
  plan.sigma_max = sigma_max;
  plan.rho_max = rho_max;
  if (sigma_max == p.sigma0) return plan;  // nothing to do: N = 0
  double t = p.scheme == Scheme::standard
                 ? (sigma_max * sigma_max - p.sigma0 * p.sigma0) / (2.0 * rho_max)  // eq. 13
                 : std::log(sigma_max / p.sigma0) / rho_max;                         // eq. 18
  // A relative slack of 1e-12 keeps T = 1248.0000000001 (rounding noise) at 1248.
  plan.iterations = static_cast<int>(std::ceil(t * (1.0 - 1e-12)));
  if (plan.iterations < 1) plan.iterations = 1;
  return plan;
}

DiffusionPlan validate_diffusion(const Image& f, const Image& sigma, double sigma_max,
                                 const DiffusionParams& p) {
  if (f.channels != 4)
    throw Error("diffusion needs a 4-channel image, got " + std::to_string(f.channels) + " channels");
  if (sigma.channels != 1 || sigma.width != f.width || sigma.height != f.height)
    throw Error("scale map " + sigma.size_string() + " (" + std::to_string(sigma.channels) +
                " channels) does not match image " + f.size_string() + "; it must be one channel of the same size");
  // Compared in float, the map's own precision: a map filled with
  // float(sigma) must pass for sigma_max = sigma whichever way it rounded.
  const float lo = static_cast<float>(p.sigma0), hi = static_cast<float>(sigma_max);
  for (int y = 0; y < sigma.height; ++y) {
    const float* s = sigma.row(y);
    for (int x = 0; x < sigma.width; ++x) {
      if (!std::isfinite(s[x]) || s[x] < lo || s[x] > hi) {
        std::ostringstream m;
        m << "scale map pixel (" << x << ", " << y << ") is " << s[x] << " px; every target scale must be finite and in [sigma0, sigma_max] = ["
          << p.sigma0 << ", " << sigma_max << "] px";
        if (s[x] < lo) m << " (a target below the inner scale --sigma0 would need sharpening; lower --sigma0 or raise the map)";
        throw Error(m.str());
      }
    }
  }
  return plan_diffusion(p, sigma_max);
}

DiffusionPlan diffuse(Image& f, const Image& sigma, double sigma_max,
                      const DiffusionParams& p, const Exec& exec) {
  const DiffusionPlan plan = validate_diffusion(f, sigma, sigma_max, p);
  if (plan.iterations == 0) {
    if (p.precision == Precision::f16) cpu::round_to_half(f.data.data(), f.data.size());
    return plan;
  }
  if (exec.path == Path::reference)
    cpu::diffuse_reference(f, sigma, plan, p);
  else
    cpu::diffuse_fast(f, sigma, plan, p, exec.threads);
  return plan;
}

}  // namespace brume
