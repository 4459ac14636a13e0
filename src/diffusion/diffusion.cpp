// brume — diffusion front end: planning (eq. 13 / eq. 18), validation of the
// inputs, and dispatch to the CPU schedules. The target-scale path computes
// the per-pixel rates and then runs the rate path; the standard scheme of
// the rate path is the conductance path with eq. 12's edge weights.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "diffusion/diffusion_kernels.hpp"

namespace brume {

// ---- the engine's names and its parameter block (brume/diffusion.hpp) ----
const EnumNames<Scheme>& scheme_names() {
  static const EnumNames<Scheme> n = {
      {Scheme::standard, "standard"}, {Scheme::invariant, "invariant"}, {Scheme::invariant_exact, "invariant-exact"}};
  return n;
}
const EnumNames<Precision>& precision_names() {
  static const EnumNames<Precision> n = {{Precision::f32, "f32"}, {Precision::f16, "f16"}};
  return n;
}
const EnumNames<EdgeRate>& edge_rate_names() {
  static const EnumNames<EdgeRate> n = {{EdgeRate::harmonic, "harmonic"}, {EdgeRate::mean, "mean"}, {EdgeRate::min, "min"}};
  return n;
}

const ParamTable<DiffusionParams>& diffusion_param_table() {
  static const ParamTable<DiffusionParams> t = [] {
    ParamTable<DiffusionParams> d("diffusion");
    d.choice("scheme", &DiffusionParams::scheme, scheme_names(),
             "diffusion scheme: standard (explicit Euler, eq. 11-13), invariant (eq. 17-18 as published), "
             "invariant-exact (offsets that reach the target variance exactly)")
        .choice("precision", &DiffusionParams::precision, precision_names(),
                "storage between iterations: f32, or f16 rounded like an RGBA16F texture")
        .real("sigma0", &DiffusionParams::sigma0, "px", Range::left_open(0.0, 1000.0),
              "inner scale of the input image (its own blur)")
        .real("rho-max", &DiffusionParams::rho_max, "1", Range::left_open(0.0, 0.25),
              "largest diffusion rate per iteration (0.25 is the 2-D stability limit); auto: 0.2 for "
              "invariant-exact, 0.25 for the others")
        .choice("edge-rate", &DiffusionParams::edge_rate, edge_rate_names(),
                "rate on the edge between a pixel and its neighbour sample: harmonic (default; leak-free), "
                "mean (the paper's eq. 12), min")
        .real("max-sigma-diagonals", &DiffusionParams::max_sigma_diagonals, "1", Range::at_least(0.0),
              "refuse a blur whose largest scale sigma_max exceeds this many image diagonals (past twice the "
              "longer side a pixel's blur is the image's mean: more only costs work); 0: no such bound")
        .since(4, 0.0);
    return d;
  }();
  return t;
}


// Names come from the one name table of each enum (brume/pipeline.hpp).
std::string to_string(Scheme s) { return enum_name(scheme_names(), s); }
std::string to_string(Precision p) { return enum_name(precision_names(), p); }
std::string to_string(EdgeRate e) { return enum_name(edge_rate_names(), e); }

double effective_rho_max(const DiffusionParams& p) {
  if (p.rho_max) return *p.rho_max;
  return p.scheme == Scheme::invariant_exact ? 0.2 : 0.25;
}

namespace {
// T of eq. 13 (standard) or eq. 18 (invariant), before rounding up.
double diffusion_iterations_exact(const DiffusionParams& p, double rho_max, double sigma_max) {
  return p.scheme == Scheme::standard ? (sigma_max * sigma_max - p.sigma0 * p.sigma0) / (2.0 * rho_max)  // eq. 13
                                      : std::log(sigma_max / p.sigma0) / rho_max;                         // eq. 18
}
}  // namespace

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
  // A relative slack of 1e-12 keeps T = 1248.0000000001 (rounding noise) at 1248.
  const double n = std::ceil(diffusion_iterations_exact(p, rho_max, sigma_max) * (1.0 - 1e-12));
  // Compared in double before the conversion, which would be undefined past
  // int's range (sigma_max 4e4 px once planned "1 iteration": issue #51).
  if (!(n <= kMaxDiffusionIterations)) {
    std::ostringstream m;
    m << "the " << to_string(p.scheme) << " scheme would need " << n << " iterations to reach sigma_max "
      << sigma_max << " px, more than " << kMaxDiffusionIterations << "; lower the blur";
    throw Error(m.str());
  }
  plan.iterations = std::max(1, static_cast<int>(n));
  return plan;
}

DiffusionPlan plan_diffusion(const DiffusionParams& p, double sigma_max, std::int64_t width, std::int64_t height,
                             const std::string& set_by) {
  const double rho_max = effective_rho_max(p);
  if (std::isfinite(sigma_max) && sigma_max > p.sigma0 && width > 0 && height > 0 && rho_max > 0.0 &&
      rho_max <= 0.25 && p.sigma0 > 0.0 && std::isfinite(p.sigma0)) {
    const double w = static_cast<double>(width), h = static_cast<double>(height);
    const double diagonal = std::sqrt(w * w + h * h);
    const std::string size = std::to_string(width) + " x " + std::to_string(height);
    if (p.max_sigma_diagonals > 0.0 && sigma_max > p.max_sigma_diagonals * diagonal) {
      std::ostringstream m;
      m.precision(4);
      m << "the blur's largest scale sigma_max = " << sigma_max << " px is " << sigma_max / diagonal
        << " times the image's diagonal (" << diagonal << " px for " << size << "); brume refuses more than "
        << p.max_sigma_diagonals << " diagonals (" << p.max_sigma_diagonals * diagonal
        << " px here: past twice the image's longer side a pixel's blur leaves the image's mean, so more changes "
           "nothing but the work). sigma_max is set by "
        << set_by << ". If so wide a blur is meant, --max-sigma-diagonals sets the bound (0: none; the haze+dof "
           "chain's depth of field: --dof-max-sigma-diagonals)";
      throw Error(m.str());
    }
    const double n = std::ceil(diffusion_iterations_exact(p, rho_max, sigma_max) * (1.0 - 1e-12));
    const double work = n * w * h;
    if (work > kMaxDiffusionWork) {
      std::ostringstream m;
      m.precision(4);
      m << "the " << to_string(p.scheme) << " scheme needs " << n << " iterations for sigma_max = " << sigma_max
        << " px (--rho-max " << rho_max << "), which on " << size << " pixels are " << work
        << " pixel-iterations; brume refuses more than " << kMaxDiffusionWork
        << " (~100 s of one core).";
      if (p.scheme == Scheme::standard) {
        DiffusionParams e = p;
        e.scheme = Scheme::invariant_exact;
        e.rho_max.reset();
        m << " The invariant-exact scheme reaches the same scale in "
          << std::ceil(diffusion_iterations_exact(e, effective_rho_max(e), sigma_max)) << " iterations: give --scheme "
          << "invariant-exact (the default), or lower sigma_max, set by " << set_by;
      } else {
        m << " Raise --rho-max (at most 0.25), or lower sigma_max, set by " << set_by;
      }
      throw Error(m.str());
    }
  }
  return plan_diffusion(p, sigma_max);
}

namespace {

void check_image(const Image& f) {
  if (f.channels < 1)
    throw Error("diffusion needs an image with at least one channel, got " + std::to_string(f.channels) +
                " channels; pass the channels to blur (e.g. RGBA, or the six Gamma_c E_c, Gamma_c planes)");
  if (f.width < 1 || f.height < 1 ||
      f.data.size() != f.pixels() * static_cast<std::size_t>(f.channels))
    throw Error("diffusion image " + f.size_string() + " x " + std::to_string(f.channels) + " channels holds " +
                std::to_string(f.data.size()) + " values; it must be non-empty and hold width x height x channels");
}

// A per-pixel map (scale, rate or edge weight) must be one channel of F's size.
void check_map_shape(const Image& m, const Image& f, const std::string& what) {
  if (m.channels != 1 || m.width != f.width || m.height != f.height ||
      m.data.size() != m.pixels())
    throw Error(what + " " + m.size_string() + " (" + std::to_string(m.channels) +
                " channels) does not match image " + f.size_string() + "; it must be one channel of the same size");
}

// Every value of a rate or weight map finite and in [0, 1/4]; returns the largest.
double check_unit_quarter(const Image& m, const std::string& what, const std::string& meaning) {
  float hi = 0.0f;
  for (int y = 0; y < m.height; ++y) {
    const float* r = m.row(y);
    // As check_scale_problem: a branch-free pass (in [0, 0.25] excludes NaN
    // and infinities), then the row's largest value, and a search for the
    // first bad pixel only in a row that has one.
    int bad = 0;
    for (int x = 0; x < m.width; ++x) bad |= !((r[x] >= 0.0f) & (r[x] <= 0.25f));
    if (!bad) {
      hi = std::max(hi, cpu::largest_nonnegative(r, static_cast<std::size_t>(m.width)));
      continue;
    }
    for (int x = 0; x < m.width; ++x) {
      if (!std::isfinite(r[x]) || r[x] < 0.0f || r[x] > 0.25f) {
        std::ostringstream msg;
        msg << what << " pixel (" << x << ", " << y << ") is " << r[x] << "; every " << meaning
            << " must be finite and in [0, 0.25] (0.25 is the stability limit of the explicit 2-D step";
        if (r[x] > 0.25f) msg << "; for more blur raise the iteration count instead";
        msg << ")";
        throw Error(msg.str());
      }
      hi = std::max(hi, r[x]);
    }
  }
  return hi;
}

void check_iterations(int iterations) {
  if (iterations < 0)
    throw Error("diffusion iteration count " + std::to_string(iterations) + " is not allowed; it must be >= 0");
}

// Every check of a target-scale problem except the channel count.
DiffusionPlan check_scale_problem(const Image& f, const Image& sigma, double sigma_max, const DiffusionParams& p) {
  check_map_shape(sigma, f, "scale map");
  // Compared in float, the map's own precision: a map filled with
  // float(sigma) must pass for sigma_max = sigma whichever way it rounded.
  const float lo = static_cast<float>(p.sigma0), hi = static_cast<float>(sigma_max);
  for (int y = 0; y < sigma.height; ++y) {
    const float* s = sigma.row(y);
    // A branch-free pass over the row first (it vectorises: & rather than
    // &&, which GCC 12 leaves as control flow; s - s is 0 only for finite s,
    // and NaN fails every comparison); only a row with a bad pixel is
    // searched for the first one, to name it. 1.8-2.7 -> 0.3-0.5 ms for a
    // 1600 x 1120 map (Zen 4, 2026-12-03).
    int bad = 0;
    for (int x = 0; x < sigma.width; ++x) bad |= !((s[x] >= lo) & (s[x] <= hi) & (s[x] - s[x] == 0.0f));
    if (!bad) continue;
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

// Run a four-channel CPU schedule on F of any channel count: F itself when it
// has four channels (no copy), else each group of four channels in turn, the
// last padded with zeros. The rates never depend on F, so the groups are
// independent and the result is what one C-channel kernel would give.
// Measured (one thread, CPU time, median of 9, 800x560, invariant-exact,
// sigma ramp 1..25 px, 17 iterations; 2-core host shared with other builds):
// C = 1: 55 ms, 2: 54, 4: 53, 6: 110, 8: 109. The copies in and out are
// noise; 6 channels cost 2.07x four, where a C-channel kernel could at best
// reach ~1.5x. A 1-channel map pays for four lanes: a scalar kernel would be
// the thing to write if single-channel blurs ever matter for speed.
template <class Run>
void by_groups_of_four(Image& f, Run&& run) {
  const int C = f.channels;
  if (C == 4) {
    run(f);
    return;
  }
  const std::size_t np = f.pixels();
  for (int c0 = 0; c0 < C; c0 += 4) {
    const int nc = std::min(4, C - c0);
    Image g(f.width, f.height, 4, 0.0f);
    for (std::size_t i = 0; i < np; ++i)
      for (int c = 0; c < nc; ++c) g.data[i * 4 + c] = f.data[i * C + c0 + c];
    run(g);
    for (std::size_t i = 0; i < np; ++i)
      for (int c = 0; c < nc; ++c) f.data[i * C + c0 + c] = g.data[i * 4 + c];
  }
}

// The fast rate path once its inputs are checked: `rho` is the float map
// (one value per pixel of f).
void run_rates_fast(Image& f, const float* rho, int iterations, const DiffusionParams& p, const Exec& exec,
                    cpu::Workspace& ws) {
  // Three channels (RGB without an alpha) in f32 take rows of three values a
  // pixel on the invariant schemes, as a constant scale does (diffuse(f,
  // sigma) below): no fourth channel to carry, a quarter less arithmetic and
  // traffic, and no copy into and out of a four-channel group; the same
  // bits (test: DiffusionChannels.RgbRowsGiveTheRgbaBits). The standard
  // scheme's conductance rows and binary16 storage take groups of four.
  if (f.channels == 3 && p.precision == Precision::f32 && p.scheme != Scheme::standard) {
    cpu::diffuse_fast(f, rho, iterations, p, exec.threads, ws);
    return;
  }
  by_groups_of_four(f, [&](Image& g) { cpu::diffuse_fast(g, rho, iterations, p, exec.threads, ws); });
}

}  // namespace

DiffusionPlan validate_diffusion(const Image& f, const Image& sigma, double sigma_max,
                                 const DiffusionParams& p) {
  if (f.channels != 4)
    throw Error("the GPU diffusion backend needs a 4-channel image, got " + std::to_string(f.channels) +
                " channels; diffuse other channel counts on the CPU backend");
  check_image(f);
  return check_scale_problem(f, sigma, sigma_max, p);
}

DiffusionPlan diffuse(Image& f, const Image& sigma, double sigma_max,
                      const DiffusionParams& p, const Exec& exec) {
  check_image(f);
  const DiffusionPlan plan = check_scale_problem(f, sigma, sigma_max, p);
  const int N = plan.iterations;
  if (N == 0) {
    if (p.precision == Precision::f16) cpu::round_to_half(f.data.data(), f.data.size());
    return plan;
  }
  // Rates from the target scales (eq. 13 / eq. 18): in double for the
  // reference, in float (the shared formulas) for the fast path.
  if (exec.path == Path::reference) {
    const double s0 = p.sigma0;
    std::vector<double> rho(f.pixels());
    for (std::size_t i = 0; i < rho.size(); ++i) {
      const double s = sigma.data[i];
      rho[i] = p.scheme == Scheme::standard ? (s * s - s0 * s0) / (2.0 * N)  // eq. 13
                                            : std::log(s / s0) / N;          // eq. 18
    }
    cpu::diffuse_reference(f, rho, N, p);
  } else {
    cpu::WorkspaceLease ws;
    run_rates_fast(f, cpu::rates_from_scale(sigma, p, N, exec.threads, *ws), N, p, exec, *ws);
  }
  return plan;
}

DiffusionPlan diffuse(Image& f, double sigma, const DiffusionParams& p, const Exec& exec) {
  check_image(f);
  // The map this stands for holds float(sigma), checked in float against
  // sigma0 and sigma_max = sigma, as check_scale_problem checks it.
  const float s = static_cast<float>(sigma);
  if (!std::isfinite(sigma) || !(s >= static_cast<float>(p.sigma0))) {
    std::ostringstream m;
    m << "target scale " << sigma << " px is not allowed; it must be finite and at least the inner scale sigma0 = "
      << p.sigma0 << " px (diffusion can only add blur)";
    throw Error(m.str());
  }
  // The fast path of the invariant schemes needs only the one rate. Every
  // other path (the reference, the standard scheme's per-edge weights) takes
  // the map, whose result this is by definition.
  if (exec.path == Path::reference || p.scheme == Scheme::standard)
    return diffuse(f, Image(f.width, f.height, 1, s), sigma, p, exec);
  const DiffusionPlan plan = plan_diffusion(p, sigma);
  const int N = plan.iterations;
  if (N == 0) {
    if (p.precision == Precision::f16) cpu::round_to_half(f.data.data(), f.data.size());
    return plan;
  }
  const float rho = cpu::rate_from_scale(s, p, N);
  cpu::WorkspaceLease ws;
  // Three channels (RGB without an alpha) in f32 take rows of three values
  // a pixel: the constant-scale row is a loop over values, so it needs no
  // fourth channel, and the copy into and out of one -- a quarter of the
  // arithmetic and traffic, and an image-sized buffer, saved; the same bits
  // (test: DiffusionFastPath.ConstantScaleWithoutAMapGivesTheMapsBits).
  // binary16 storage converts four channels at a time: groups of four.
  if (f.channels == 3 && p.precision == Precision::f32) {
    cpu::diffuse_fast_uniform(f, rho, N, p, exec.threads, *ws);
    return plan;
  }
  by_groups_of_four(f, [&](Image& g) { cpu::diffuse_fast_uniform(g, rho, N, p, exec.threads, *ws); });
  return plan;
}

DiffusionPlan diffuse_rates(Image& f, const Image& rho, int iterations, const DiffusionParams& p,
                            const Exec& exec) {
  check_image(f);
  check_map_shape(rho, f, "rate map");
  check_iterations(iterations);
  const double rho_hi = check_unit_quarter(rho, "rate map", "rate per iteration");
  const bool standard = p.scheme == Scheme::standard;
  // sigma0 places the invariant schemes' first offsets and, for every
  // scheme, the scale the plan reports.
  if (!(p.sigma0 > 0.0) || !std::isfinite(p.sigma0))
    throw Error("--sigma0 " + std::to_string(p.sigma0) + " px is not allowed; the inner scale must be a finite number > 0 (typically 0.5 to 1 px)");
  DiffusionPlan plan;
  plan.iterations = iterations;
  plan.rho_max = rho_hi;
  plan.sigma_max = standard ? std::sqrt(p.sigma0 * p.sigma0 + 2.0 * iterations * rho_hi)
                            : p.sigma0 * std::exp(iterations * rho_hi);
  // The invariant offsets grow as sigma0 e^{k rho}; past ~1e6 px they are
  // beyond any image and, as floats converted to tap indices, meaningless.
  if (!standard && !(plan.sigma_max <= 1e6)) {
    std::ostringstream m;
    m << "rate map's largest rate " << rho_hi << " over " << iterations << " iterations reaches a scale sigma0 e^{N rho} = "
      << plan.sigma_max << " px, beyond the 1e6 px the invariant schemes' offsets allow; lower the rates or the iteration count";
    throw Error(m.str());
  }
  if (iterations == 0) {
    if (p.precision == Precision::f16) cpu::round_to_half(f.data.data(), f.data.size());
    return plan;
  }
  if (exec.path == Path::reference) {
    cpu::diffuse_reference(f, std::vector<double>(rho.data.begin(), rho.data.end()), iterations, p);
  } else {
    cpu::WorkspaceLease ws;
    run_rates_fast(f, rho.data.data(), iterations, p, exec, *ws);
  }
  return plan;
}

void release_diffusion_buffers() { cpu::release_workspace(); }

void diffuse_conductance(Image& f, const Image& wx, const Image& wy, int iterations, Precision precision,
                         const Exec& exec) {
  check_image(f);
  check_map_shape(wx, f, "conductance map wx");
  check_map_shape(wy, f, "conductance map wy");
  check_iterations(iterations);
  check_unit_quarter(wx, "conductance map wx", "edge weight");
  check_unit_quarter(wy, "conductance map wy", "edge weight");
  const bool f16 = precision == Precision::f16;
  if (iterations == 0) {
    if (f16) cpu::round_to_half(f.data.data(), f.data.size());
    return;
  }
  const int W = f.width, H = f.height;
  // The edges onto the mirror carry no flux: their weights become 0 (the
  // schedules rely on it rather than on the mirror tap's difference being 0).
  auto edges = [&](auto& ex, auto& ey) {
    ex.assign(wx.data.begin(), wx.data.end());
    ey.assign(wy.data.begin(), wy.data.end());
    for (int y = 0; y < H; ++y) ex[static_cast<std::size_t>(y) * W + (W - 1)] = 0;
    for (int x = 0; x < W; ++x) ey[static_cast<std::size_t>(H - 1) * W + x] = 0;
  };
  if (exec.path == Path::reference) {
    std::vector<double> ex, ey;
    edges(ex, ey);
    cpu::diffuse_conductance_reference(f, ex, ey, iterations, f16);
    return;
  }
  std::vector<float> ex, ey;
  edges(ex, ey);
  cpu::WorkspaceLease ws;
  by_groups_of_four(f, [&](Image& g) {
    cpu::diffuse_conductance_fast(g, ex.data(), ey.data(), iterations, f16, exec.threads, *ws);
  });
}

}  // namespace brume
