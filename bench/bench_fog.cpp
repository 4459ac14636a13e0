// brume benchmark — `brume fog` apply as the library runs it, against the
// memory floor of any per-pixel post-process (issue #12: >= 150 Mpx/s on 2
// cores, within 3x of the floor, in one run).
//
// On the demo scene's 1600x1120 frame (range 3 m .. 1.25 km, sky NaN), the
// camera of the scene (1.6 m, pitch -5, 55 deg vertical field of view),
// exponential density, no blur, the threads OpenMP gives (all cores):
//   (a) apply:   apply_fog into reused output images (ray, optical depth,
//                transmission, composite; the optical-depth and transmission
//                maps written too), a renderer's per-frame loop;
//   (e) per-pixel: the same through the per-pixel loop (libm expf, the
//                schedule before the vector rows; every other profile's path);
//   (b) fresh:   apply_fog returning new images (allocation, zero fill and
//                first-touch page faults included);
//   (d) full:    analyse_fog (range scan, airlight from the sky) + apply_fog;
//   (c) floor:   read depth and colour, write colour once (out = c * (r > 0)):
//                what any per-pixel pass over these images must at least move.
// Rounds interleave (a), (e), (b), (d), (c) (one warm-up round first), so a busy host
// slows all alike; each figure is the median (min..max) of its rounds.
//
// Usage: brume_bench_fog [ROUNDS]
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "bench_util.hpp"
#include "brume/demo_scene.hpp"
#include "brume/fog.hpp"
#include "effects/fog/fog_fast.hpp"

using namespace brume;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

}  // namespace

int main(int argc, char** argv) {
  const int rounds = argc > 1 ? std::atoi(argv[1]) : 9;
  const int W = 1600, H = 1120;
  const DemoScene s = render_demo_scene(W, H);
  FogParams p;
  p.profile = HeightProfile::exponential;
  p.density_per_m = 0.03, p.falloff_per_m = 0.06, p.base_height_m = 0.0;
  p.camera.height_m = 1.6, p.camera.pitch_deg = -5.0;
  p.airlight = Rgb{0.7f, 0.72f, 0.75f};
  Intrinsics k = intrinsics_from_fov(W, H, NAN, s.fov_y_deg);
  const Camera cam = make_camera(k, W, H, p.camera);
  const FogAnalysis a = analyse_fog(s.rgb, s.range, s.range, cam, p);
  const int threads = omp_get_max_threads();

  Image floor_out(W, H, 3);
  auto floor_pass = [&] {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        const float m = s.range.data[i] > 0.0f ? 1.0f : 0.5f;
        for (int c = 0; c < 3; ++c) floor_out.data[i * 3 + c] = m * s.rgb.data[i * 3 + c];
      }
  };
  std::vector<double> ta, tb, tc, td, te, floor_ratio, loop_ratio;
  volatile float sink = 0.0f;
  FogResult reused, reused_pp;
  for (int r = 0; r <= rounds; ++r) {
    auto t = Clock::now();
    apply_fog(s.rgb, s.range, p, a, reused);
    const double da = ms_since(t);
    sink = sink + reused.rgb.data[12345];
    t = Clock::now();
    detail::apply_fog_rows(s.rgb, s.range, p, a, reused_pp, Exec{}, false);
    const double de = ms_since(t);
    sink = sink + reused_pp.rgb.data[12345];
    t = Clock::now();
    FogResult o = apply_fog(s.rgb, s.range, p, a);
    const double dd = ms_since(t);
    sink = sink + o.rgb.data[12345];
    t = Clock::now();
    FogAnalysis a2 = analyse_fog(s.rgb, s.range, s.range, cam, p);
    FogResult o2 = apply_fog(s.rgb, s.range, p, a2);
    const double db = ms_since(t);
    sink = sink + o2.rgb.data[12345];
    t = Clock::now();
    floor_pass();
    const double dc = ms_since(t);
    sink = sink + floor_out.data[12345];
    if (r == 0) continue;  // warm-up round
    ta.push_back(da), tb.push_back(db), tc.push_back(dc), td.push_back(dd), te.push_back(de);
    floor_ratio.push_back(da / dc), loop_ratio.push_back(de / da);  // per round: both under the same load
  }
  const double mpx = W * static_cast<double>(H) / 1e6;
  const bench::Spread A = bench::spread(ta), B = bench::spread(tb), C = bench::spread(tc), D = bench::spread(td), E = bench::spread(te);
  std::printf("brume_bench_fog: %dx%d exponential, no blur, %d threads, %s, %d rounds (median, min..max)\n", W, H,
              threads, bench::cpu_name().c_str(), rounds);
  std::printf("  (a) apply_fog, reused    %7.2f ms (%.2f..%.2f)  %6.1f Mpx/s\n", A.median, A.lo, A.hi, mpx / A.median * 1e3);
  std::printf("  (e) per-pixel loop, reused %7.2f ms (%.2f..%.2f)  %6.1f Mpx/s\n", E.median, E.lo, E.hi, mpx / E.median * 1e3);
  std::printf("  (b) apply_fog, new images %7.2f ms (%.2f..%.2f)  %6.1f Mpx/s\n", D.median, D.lo, D.hi, mpx / D.median * 1e3);
  std::printf("  (d) analyse + apply      %7.2f ms (%.2f..%.2f)  %6.1f Mpx/s\n", B.median, B.lo, B.hi, mpx / B.median * 1e3);
  std::printf("  (c) memory floor         %7.2f ms (%.2f..%.2f)  %6.1f Mpx/s\n", C.median, C.lo, C.hi, mpx / C.median * 1e3);
  const bench::Spread FR = bench::spread(floor_ratio), LR = bench::spread(loop_ratio);
  std::printf("  apply / floor     = %.2fx (%.2f..%.2f), ratio per round\n", FR.median, FR.lo, FR.hi);
  std::printf("  per-pixel / apply = %.2fx (%.2f..%.2f), ratio per round\n", LR.median, LR.lo, LR.hi);
  return 0;
}
