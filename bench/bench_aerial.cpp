// brume benchmark — aerial perspective with the tabulated Gamma against
// integrating the 1 nm spectrum per pixel (issue #10: >= 100 Mpx/s on 2 cores
// including the table, >= 50x the per-pixel integral).
//
// On the demo scene's 1600x1120 range map (3 m .. 1.25 km, sky NaN), with the
// render formula I = I0 Gamma + I_inf (1 - Gamma) applied in CIE XYZ (the
// default sensitivity's space: linear sRGB -> XYZ, per-channel Gamma, back),
// sky pixels left unchanged, OpenMP over rows, the same threads for all:
//   (a) table:  attenuation_table over [0, R_max] (4096 samples) + a look-up per pixel;
//   (b) peer:   attenuation_direct per pixel (the 1 nm Simpson sum, which also
//               re-evaluates beta(lambda) per call);
//   (c) peer':  the same 1 nm sum per pixel with beta and the weights hoisted
//               out of the pixel loop (the fairest per-pixel integral).
// The peers run on every 16th row and are extrapolated to the full frame (x16);
// median of 5 runs for (a), of 3 for the peers, after one warm-up.
#include <omp.h>

#include <cmath>
#include <cstdio>
#include <ctime>
#include <functional>

#include "bench_util.hpp"
#include "brume/aerial.hpp"
#include "brume/demo_scene.hpp"

using namespace brume;

namespace {

// Linear sRGB (D65) <-> CIE XYZ, IEC 61966-2-1.
constexpr double kToXyz[3][3] = {{0.4124, 0.3576, 0.1805}, {0.2126, 0.7152, 0.0722}, {0.0193, 0.1192, 0.9505}};
constexpr double kToRgb[3][3] = {
    {3.2406, -1.5372, -0.4986}, {-0.9689, 1.8758, 0.0415}, {0.0557, -0.2040, 1.0570}};

inline void apply(const float* in, float* out, const float g[3], const double inf_xyz[3]) {
  double xyz[3];
  for (int r = 0; r < 3; ++r) {
    const double v = kToXyz[r][0] * in[0] + kToXyz[r][1] * in[1] + kToXyz[r][2] * in[2];
    xyz[r] = v * g[r] + inf_xyz[r] * (1.0 - g[r]);
  }
  for (int r = 0; r < 3; ++r)
    out[r] = static_cast<float>(kToRgb[r][0] * xyz[0] + kToRgb[r][1] * xyz[1] + kToRgb[r][2] * xyz[2]);
}

}  // namespace

int main() {
  const int w = 1600, h = 1120, row_step = 16;
  const DemoScene scene = render_demo_scene(w, h);
  const Atmosphere atm{8.0, 0.0};
  const SpectralSensitivity q = load_sensitivity("default");
  const double inf_rgb[3] = {0.75, 0.80, 0.90};
  double inf_xyz[3];
  for (int r = 0; r < 3; ++r)
    inf_xyz[r] = kToXyz[r][0] * inf_rgb[0] + kToXyz[r][1] * inf_rgb[1] + kToXyz[r][2] * inf_rgb[2];
  double r_max = 0.0;
  for (float s : scene.range.data)
    if (std::isfinite(s)) r_max = std::max(r_max, static_cast<double>(s));
  Image out(w, h, 3);
  const int threads = omp_get_max_threads();

  auto render = [&](int step, const std::function<void(double, float*)>& gamma) {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y += step)
      for (int x = 0; x < w; ++x) {
        const float* in = scene.rgb.row(y) + 3 * x;
        float* o = &out.at(x, y, 0);
        const float s = scene.range.at(x, y);
        if (!std::isfinite(s) || s <= 0.0f) {  // sky: left unchanged
          o[0] = in[0], o[1] = in[1], o[2] = in[2];
          continue;
        }
        float g[3];
        gamma(s, g);
        apply(in, o, g, inf_xyz);
      }
  };

  // (a) table + look-up, the loop written out (no std::function per pixel).
  AttenuationTable table;
  const bench::Spread ta = bench::time_ms(
      [&] {
        table = attenuation_table(atm, q, r_max);
#pragma omp parallel for schedule(static)
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x) {
            const float* in = scene.rgb.row(y) + 3 * x;
            float* o = &out.at(x, y, 0);
            const float s = scene.range.at(x, y);
            if (!std::isfinite(s) || s <= 0.0f) {
              o[0] = in[0], o[1] = in[1], o[2] = in[2];
              continue;
            }
            const std::array<float, 3> g = table.at(s);
            apply(in, o, g.data(), inf_xyz);
          }
      },
      5);
  const bench::Spread tt = bench::time_ms([&] { table = attenuation_table(atm, q, r_max); }, 5);

  // (b) attenuation_direct per pixel.
  const bench::Spread tb = bench::time_ms(
      [&] {
        render(row_step, [&](double s, float* g) {
          const auto d = attenuation_direct(atm, q, s);
          for (int c = 0; c < 3; ++c) g[c] = static_cast<float>(d[c]);
        });
      },
      3);

  // (c) the same sum with beta and the normalised Simpson weights hoisted.
  std::vector<double> beta(kSensitivitySamples);
  std::vector<std::array<double, 3>> wq(kSensitivitySamples);
  std::array<double, 3> norm{};
  for (int i = 0; i < kSensitivitySamples; ++i) {
    const double l = kAerialLambdaMinNm + i;
    beta[i] = rayleigh_beta_per_m(l, atm.altitude_m) + mie_beta_per_m(l, atm.turbidity, atm.altitude_m);
    const double wt = (i == 0 || i == kSensitivitySamples - 1) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    for (int c = 0; c < 3; ++c) norm[c] += (wq[i][c] = wt * q.q[i][c]);
  }
  for (auto& v : wq)
    for (int c = 0; c < 3; ++c) v[c] /= norm[c];
  const bench::Spread tc = bench::time_ms(
      [&] {
        render(row_step, [&](double s, float* g) {
          double a[3] = {0, 0, 0};
          for (int i = 0; i < kSensitivitySamples; ++i) {
            const double e = std::exp(-beta[i] * s);
            for (int c = 0; c < 3; ++c) a[c] += e * wq[i][c];
          }
          for (int c = 0; c < 3; ++c) g[c] = static_cast<float>(a[c]);
        });
      },
      3);

  const double mpx = static_cast<double>(w) * h / 1e6;
  const double ms_b = tb.median * row_step, ms_c = tc.median * row_step;  // extrapolated to the full frame
  char date[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof date, "%Y-%m-%d", std::gmtime(&now));
  std::printf("brume bench aerial  %s  %s  %d threads  %dx%d demo scene (R_max %.0f m), T %.0f, default (XYZ) "
              "sensitivity\n",
              date, bench::cpu_name().c_str(), threads, w, h, r_max, atm.turbidity);
  std::printf("  table build alone (4096 samples):      %8.2f ms (%.2f..%.2f)\n", tt.median, tt.lo, tt.hi);
  std::printf("  (a) table + look-up render:            %8.2f ms (%.2f..%.2f)  %8.1f Mpx/s\n", ta.median, ta.lo,
              ta.hi, mpx / (ta.median * 1e-3));
  std::printf("  (b) attenuation_direct per pixel:      %8.0f ms (x%d from every %dth row)  %8.3f Mpx/s  ratio %.0fx\n",
              ms_b, row_step, row_step, mpx / (ms_b * 1e-3), ms_b / ta.median);
  std::printf("  (c) 1 nm sum per pixel, beta hoisted:  %8.0f ms (x%d from every %dth row)  %8.3f Mpx/s  ratio %.0fx\n",
              ms_c, row_step, row_step, mpx / (ms_c * 1e-3), ms_c / ta.median);
  return 0;
}
