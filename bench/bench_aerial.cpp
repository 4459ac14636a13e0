// brume benchmark — `brume aerial` render as the library runs it, against
// integrating the 1 nm spectrum per pixel (issue #10: >= 100 Mpx/s on 2 cores
// including the Gamma table, >= 50x the per-pixel integral, in one run).
//
// On the demo scene's 1600x1120 frame (range 3 m .. 1.25 km, sky NaN), render
// mode, lambda 0, --horizon auto (the sky's median), for T = 2 and 8 and two
// sensitivities (the default CIE fit, worked in XYZ, and a camera CSV, worked
// in camera RGB), the threads OpenMP gives (all cores):
//   (a) library, first call: analyse_aerial (range scan, sensitivity, Gamma
//       table, horizon estimate) + apply_aerial returning an AerialResult
//       (every output map, freshly allocated: allocation, zero-fill and the
//       first-touch page faults of ~57 MB of outputs and mask) -- the CLI's
//       work minus file I/O;
//   (s) library, steady state: the same analysis and render into buffers
//       kept from the previous round (analyse_aerial(..., AerialAnalysis&),
//       apply_aerial(..., Image& out), no maps) -- a video or batch caller;
//       its breakdown also times the analysis with the horizon given, so the
//       difference is the sky median's cost;
//   (b) peer:    attenuation_direct per pixel (the 1 nm Simpson sum; it also
//       re-evaluates beta(lambda) and the weights per call) + the same formula,
//       I = I0 Gamma + Iinf (1 - Gamma) in the sensitivity's space;
//   (c) peer':   the same 1 nm sum per pixel with beta and the weights hoisted
//       out of the pixel loop (the fairest per-pixel integral).
// The peers write the image only, as (s) does, so (c)/(s) is the like-for-like
// ratio; (a) also makes both maps. CPU time (all threads) is printed beside
// the wall time: on a loaded host it is the steadier figure. For ratios at
// equal thread counts run it once as is and once with OMP_NUM_THREADS=1.
// The peers run on every 16th row and are scaled to the full frame (x16).
// Rounds interleave (a), (s), (b), (c) (one warm-up round first), so a busy host
// slows all three alike; each figure is the median (min..max) of its rounds.
//
// Usage: brume_bench_aerial [CAMERA.csv] [ROUNDS] [library-only]; the CSV defaults to
// ../shared/data/spectral/Canon_5DMarkII_camspec.csv (run from the repo root).
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <time.h>
#include <fstream>
#include <string>
#include <vector>

#include "bench_util.hpp"
#include "brume/aerial.hpp"
#include "brume/demo_scene.hpp"

using namespace brume;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }
// Process CPU time (every thread) in ms. On a shared host a preempted thread
// stretches wall time but not CPU time, so CPU-time ratios between brume and
// the peers are the load-robust figure; it includes OpenMP's spin-waits.
double cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

// Linear sRGB (D65) <-> CIE XYZ: the library's matrices (src/effects/aerial/aerial_math.glsl).
constexpr float kToXyz[3][3] = {{0.4124f, 0.3576f, 0.1805f}, {0.2126f, 0.7152f, 0.0722f}, {0.0193f, 0.1192f, 0.9505f}};
constexpr float kToRgb[3][3] = {{3.2406255f, -1.5372080f, -0.4986286f},
                                {-0.9689307f, 1.8757561f, 0.0415175f},
                                {0.0557101f, -0.2040211f, 1.0569959f}};

// The render formula of one pixel in the sensitivity's space (eq. 3.11).
inline void render_pixel(const float* in, float* out, const double g[3], const float inf[3], bool xyz) {
  float e[3] = {in[0], in[1], in[2]};
  if (xyz)
    for (int r = 0; r < 3; ++r) e[r] = kToXyz[r][0] * in[0] + kToXyz[r][1] * in[1] + kToXyz[r][2] * in[2];
  float o[3];
  for (int c = 0; c < 3; ++c) {
    const float gc = static_cast<float>(g[c]);
    o[c] = gc * e[c] + (1.0f - gc) * inf[c];
  }
  for (int r = 0; r < 3; ++r)
    out[r] = xyz ? kToRgb[r][0] * o[0] + kToRgb[r][1] * o[1] + kToRgb[r][2] * o[2] : o[r];
}

struct Case {
  std::string sensitivity;
  double turbidity;
};

struct Figures {
  std::vector<double> lib, analyse, apply, table, peer_b, peer_c, steady, st_analyse, st_apply, st_given;
  std::vector<double> cpu_lib, cpu_steady, cpu_b, cpu_c;  // process CPU ms
  std::vector<double> cpu_st_analyse, cpu_st_apply, cpu_st_given;
};

}  // namespace

int main(int argc, char** argv) {
  const std::string camera = argc > 1 ? argv[1] : "../shared/data/spectral/Canon_5DMarkII_camspec.csv";
  const int rounds = argc > 2 ? std::max(1, std::atoi(argv[2])) : 7;
  const bool peers = !(argc > 3 && std::string(argv[3]) == "library-only");  // for profiling the library
  const int w = 1600, h = 1120, row_step = 16;
  const DemoScene scene = render_demo_scene(w, h);
  const int threads = omp_get_max_threads();

  std::vector<Case> cases = {{"default", 2.0}, {"default", 8.0}};
  if (std::ifstream(camera).good())
    cases.push_back({camera, 2.0}), cases.push_back({camera, 8.0});
  else
    std::printf("(camera CSV %s not found: camera cases skipped; pass its path as the first argument)\n",
                camera.c_str());

  std::vector<Figures> fig(cases.size());
  // (s)'s buffers, one set per case as a caller rendering one stream keeps them.
  std::vector<AerialAnalysis> keep_a(cases.size()), keep_given(cases.size());
  std::vector<Image> keep_out(cases.size());
  Image peer_out(w, h, 3);
  double checksum = 0.0;  // keeps every result alive
  for (int round = 0; round <= rounds; ++round)  // round 0: warm-up, not recorded
    for (std::size_t k = 0; k < cases.size(); ++k) {
      AerialParams p;
      p.sensitivity = cases[k].sensitivity;
      p.atmosphere.turbidity = cases[k].turbidity;

      // (a) the library.
      double c0 = cpu_ms();
      auto t0 = Clock::now();
      const AerialAnalysis a = analyse_aerial(scene.rgb, scene.range, p);
      const double ms_an = ms_since(t0);
      auto t1 = Clock::now();
      const AerialResult r = apply_aerial(scene.rgb, scene.range, p, a);
      const double ms_ap = ms_since(t1), ms_lib = ms_since(t0), cpu_lib = cpu_ms() - c0;
      checksum += r.rgb.data[r.rgb.data.size() / 2] + r.attenuation.data[7] + r.scale.data[11];
      // (s) the steady state: buffers from the previous round (round 0 makes them).
      c0 = cpu_ms();
      auto ts = Clock::now();
      analyse_aerial(scene.rgb, scene.range, p, keep_a[k]);
      const double ms_st_an = ms_since(ts), cpu_st_an = cpu_ms() - c0;
      const double c1 = cpu_ms();
      auto ts1 = Clock::now();
      apply_aerial(scene.rgb, scene.range, p, keep_a[k], keep_out[k]);
      const double ms_st_ap = ms_since(ts1), ms_st = ms_since(ts), cpu_st = cpu_ms() - c0, cpu_st_ap = cpu_ms() - c1;
      checksum += keep_out[k].data[keep_out[k].data.size() / 3];
      // The steady analysis with the horizon given (no sky median), for the breakdown.
      AerialParams given = p;
      given.airlight = a.airlight;
      const double c2 = cpu_ms();
      auto tg = Clock::now();
      analyse_aerial(scene.rgb, scene.range, given, keep_given[k]);
      const double ms_given = ms_since(tg), cpu_given = cpu_ms() - c2;
      // The table alone (inside (a) already), for the breakdown.
      auto t2 = Clock::now();
      const AttenuationTable tab = attenuation_table(p.atmosphere, a.sensitivity, a.range_max_m);
      const double ms_tab = ms_since(t2);
      checksum += tab.log_gamma.back()[0];

      const bool xyz = a.sensitivity.space == SensitivitySpace::xyz;
      float inf[3] = {a.airlight[0], a.airlight[1], a.airlight[2]};
      if (xyz)
        for (int r2 = 0; r2 < 3; ++r2)
          inf[r2] = kToXyz[r2][0] * a.airlight[0] + kToXyz[r2][1] * a.airlight[1] + kToXyz[r2][2] * a.airlight[2];
      auto peer = [&](auto&& gamma) {
        if (!peers) return;
#pragma omp parallel for schedule(dynamic, 1)
        for (int y = 0; y < h; y += row_step)
          for (int x = 0; x < w; ++x) {
            const float* in = scene.rgb.row(y) + 3 * x;
            float* o = &peer_out.at(x, y, 0);
            const float s = scene.range.at(x, y);
            if (!std::isfinite(s) || s <= 0.0f) {  // sky: left unchanged
              o[0] = in[0], o[1] = in[1], o[2] = in[2];
              continue;
            }
            double g[3];
            gamma(static_cast<double>(s), g);
            render_pixel(in, o, g, inf, xyz);
          }
      };

      // (b) attenuation_direct per pixel.
      c0 = cpu_ms();
      auto t3 = Clock::now();
      peer([&](double s, double* g) {
        const auto d = attenuation_direct(p.atmosphere, a.sensitivity, s);
        for (int c = 0; c < 3; ++c) g[c] = d[c];
      });
      const double ms_b = ms_since(t3) * row_step, cpu_b = (cpu_ms() - c0) * row_step;
      checksum += peer_out.data[3 * w * 16 * 40];

      // (c) the same sum with beta and the normalised Simpson weights hoisted.
      c0 = cpu_ms();
      auto t4 = Clock::now();
      std::vector<double> beta(kSensitivitySamples);
      std::vector<std::array<double, 3>> wq(kSensitivitySamples);
      std::array<double, 3> norm{};
      for (int i = 0; i < kSensitivitySamples; ++i) {
        const double l = kAerialLambdaMinNm + i;
        beta[i] = rayleigh_beta_per_m(l, p.atmosphere.altitude_m) +
                  mie_beta_per_m(l, p.atmosphere.turbidity, p.atmosphere.altitude_m);
        const double wt = (i == 0 || i == kSensitivitySamples - 1) ? 1.0 : (i % 2 ? 4.0 : 2.0);
        for (int c = 0; c < 3; ++c) norm[c] += (wq[i][c] = wt * a.sensitivity.q[i][c]);
      }
      for (auto& v : wq)
        for (int c = 0; c < 3; ++c) v[c] /= norm[c];
      peer([&](double s, double* g) {
        g[0] = g[1] = g[2] = 0.0;
        for (int i = 0; i < kSensitivitySamples; ++i) {
          const double e = std::exp(-beta[i] * s);
          for (int c = 0; c < 3; ++c) g[c] += e * wq[i][c];
        }
      });
      const double ms_c = ms_since(t4) * row_step, cpu_c = (cpu_ms() - c0) * row_step;
      checksum += peer_out.data[3 * w * 16 * 41];

      if (round == 0) continue;
      Figures& f = fig[k];
      f.lib.push_back(ms_lib), f.analyse.push_back(ms_an), f.apply.push_back(ms_ap), f.table.push_back(ms_tab);
      f.peer_b.push_back(ms_b), f.peer_c.push_back(ms_c);
      f.steady.push_back(ms_st), f.st_analyse.push_back(ms_st_an), f.st_apply.push_back(ms_st_ap);
      f.st_given.push_back(ms_given);
      f.cpu_st_analyse.push_back(cpu_st_an), f.cpu_st_apply.push_back(cpu_st_ap), f.cpu_st_given.push_back(cpu_given);
      f.cpu_lib.push_back(cpu_lib), f.cpu_steady.push_back(cpu_st), f.cpu_b.push_back(cpu_b), f.cpu_c.push_back(cpu_c);
    }

  const double mpx = static_cast<double>(w) * h / 1e6;
  char date[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof date, "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  double load[3] = {0, 0, 0};
  if (std::FILE* la = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(la, "%lf %lf %lf", &load[0], &load[1], &load[2]) != 3) load[0] = load[1] = load[2] = -1;
    std::fclose(la);
  }
  std::printf("brume bench aerial  %s  %s  %d threads  load average %.2f %.2f %.2f (at the end)\n", date,
              bench::cpu_name().c_str(), threads, load[0], load[1], load[2]);
  std::printf("  %dx%d demo scene, render, lambda 0, horizon auto; median (min..max) of %d interleaved rounds;\n"
              "  peers on every %dth row, x%d\n",
              w, h, rounds, row_step, row_step);
  for (std::size_t k = 0; k < cases.size(); ++k) {
    const Figures& f = fig[k];
    const bench::Spread L = bench::spread(f.lib), An = bench::spread(f.analyse), Ap = bench::spread(f.apply), T = bench::spread(f.table),
                        B = bench::spread(f.peer_b), C = bench::spread(f.peer_c), S = bench::spread(f.steady),
                        SAn = bench::spread(f.st_analyse), SAp = bench::spread(f.st_apply), G = bench::spread(f.st_given),
                        cL = bench::spread(f.cpu_lib), cS = bench::spread(f.cpu_steady), cB = bench::spread(f.cpu_b), cC = bench::spread(f.cpu_c),
                        cSAn = bench::spread(f.cpu_st_analyse), cSAp = bench::spread(f.cpu_st_apply), cG = bench::spread(f.cpu_st_given);
    const std::string name = cases[k].sensitivity == "default" ? "default (XYZ)" : "camera CSV (RGB)";
    std::printf("  %-16s T %2.0f\n", name.c_str(), cases[k].turbidity);
    std::printf("    (a) library analyse+apply:   %8.2f ms (%.2f..%.2f)  %7.1f Mpx/s"
                "   [analyse %.2f, of which table %.2f; apply %.2f]\n",
                L.median, L.lo, L.hi, mpx / (L.median * 1e-3), An.median, T.median, Ap.median);
    std::printf("    (s) library steady state:    %8.2f ms (%.2f..%.2f)  %7.1f Mpx/s"
                "   [analyse %.2f (horizon given: %.2f); apply, image only %.2f]\n",
                S.median, S.lo, S.hi, mpx / (S.median * 1e-3), SAn.median, G.median, SAp.median);
    std::printf("    (b) attenuation_direct/px:   %8.0f ms (%.0f..%.0f)  %7.3f Mpx/s   (b)/(a) %.0fx  (b)/(s) %.0fx\n",
                B.median, B.lo, B.hi, mpx / (B.median * 1e-3), B.median / L.median, B.median / S.median);
    std::printf("    (c) 1 nm sum/px, hoisted:    %8.0f ms (%.0f..%.0f)  %7.3f Mpx/s   (c)/(a) %.0fx  (c)/(s) %.0fx\n",
                C.median, C.lo, C.hi, mpx / (C.median * 1e-3), C.median / L.median, C.median / S.median);
    std::printf("    CPU time (all threads): (a) %.1f ms, (s) %.1f ms, (b) %.0f ms, (c) %.0f ms;"
                "  (b)/(s) %.0fx, (c)/(s) %.0fx, (c)/(a) %.0fx\n",
                cL.median, cS.median, cB.median, cC.median, cB.median / cS.median, cC.median / cS.median,
                cC.median / cL.median);
    std::printf("    CPU time of (s): analyse %.1f ms (horizon given: %.1f), apply %.1f ms\n", cSAn.median, cG.median,
                cSAp.median);
  }
  std::printf("  (checksum %.6g)\n", checksum);
  return 0;
}
