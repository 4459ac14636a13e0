// brume benchmark — the sky: render 1024x512 (equirectangular) on the CPU
// against its peer in the same run, the double-precision reference model
// evaluated per pixel (one thread); and the full turbidity fit (100 samples,
// RANSAC, the default 8 repeats) on a 1024x512 panorama with 20 % clouds.
// Targets (issue #11): render >= 50 Mpx/s, fit < 50 ms, on 2 cores.
#include <cmath>
#include <cstdio>
#include <omp.h>
#include <random>

#include "bench_util.hpp"
#include "brume/sky.hpp"

using namespace brume;

int main(int argc, char** argv) {
  const int runs = argc > 1 ? std::atoi(argv[1]) : 15;
  const int w = 1024, h = 512;
  SkyRenderParams p;
  p.turbidity = 4.0;
  const SkyGeometry g = sky_geometry(p.view, w, h);
  const SkyDirection sun{40.0, 135.0};
  std::printf("brume sky benchmark: %s, %d threads, %dx%d, %d runs (median [min..max])\n", bench::cpu_name().c_str(),
              omp_get_max_threads(), w, h, runs);
  Image img;
  const bench::Spread r = bench::time_ms([&] { img = render_sky(p, sun, g); }, runs);
  const double kDeg = 3.14159265358979323846 / 180.0;
  volatile double sink = 0;
  const bench::Spread ref = bench::time_ms(
      [&] {
        double s = 0;
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x) {
            const SkyDirection d = *direction_of_pixel(g, x, y);
            if (d.zenith_deg > 90) continue;
            const double gm = angle_between(d.zenith_deg * kDeg, d.azimuth_deg * kDeg, sun.zenith_deg * kDeg,
                                            sun.azimuth_deg * kDeg);
            s += sky_xyY(p.turbidity, d.zenith_deg * kDeg, gm, sun.zenith_deg * kDeg)[0];
          }
        sink = s;
      },
      std::max(3, runs / 5));
  const double mpx = w * h / 1e3 / r.median;
  std::printf("render (shared float maths, OpenMP)  %8.2f ms [%.2f..%.2f]  %7.1f Mpx/s\n", r.median, r.lo, r.hi, mpx);
  std::printf("peer: double reference, 1 thread     %8.2f ms [%.2f..%.2f]  %7.1f Mpx/s  (render is %.1fx faster)\n",
              ref.median, ref.lo, ref.hi, w * h / 1e3 / ref.median, ref.median / r.median);
  // 20 % bright cloud blobs.
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> ux(0, w), uy(0, h / 2), ur(8, 30);
  std::size_t covered = 0;
  std::vector<char> c(img.pixels(), 0);
  while (covered < 0.2 * img.pixels() / 2) {
    const double cx = ux(rng), cy = uy(rng), rad = ur(rng);
    for (int y = std::max(0, int(cy - rad)); y < std::min(h / 2, int(cy + rad + 1)); ++y)
      for (int x = std::max(0, int(cx - rad)); x < std::min(w, int(cx + rad + 1)); ++x)
        if (std::hypot(x - cx, y - cy) <= rad) {
          if (!c[y * w + x]) ++covered;
          c[y * w + x] = 1;
          for (int k = 0; k < 3; ++k) img.at(x, y, k) = 2.0f * img.at(x, y, 1);
        }
  }
  SkyFitOptions o;
  SkyFitResult f;
  const bench::Spread fit = bench::time_ms([&] { f = fit_sky_image(img, false, g, sun, nullptr, o); }, runs);
  std::printf("fit (100 samples x %d repeats, RANSAC %d, LM)  %8.2f ms [%.2f..%.2f]  T^ = %.4f (true 4), inliers %.0f %%\n",
              o.repeats, o.ransac_iterations, fit.median, fit.lo, fit.hi, f.turbidity, 100 * f.inlier_fraction);
  o.repeats = 1;
  const bench::Spread fit1 = bench::time_ms([&] { f = fit_sky_image(img, false, g, sun, nullptr, o); }, runs);
  std::printf("fit, one sampling (no spread)                 %8.2f ms [%.2f..%.2f]  = %.0f samples/s (thesis: 200)\n",
              fit1.median, fit1.lo, fit1.hi, 100.0 / (fit1.median / 1e3));
  return sink > 0 ? 0 : 1;
}
