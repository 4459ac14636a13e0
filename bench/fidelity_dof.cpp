// brume — depth of field against a true thin lens (issue #13, "Fidelity").
//
// The demo scene is ray-cast by brume itself, so it can also be rendered
// through a thin lens (render_demo_scene_thin_lens: many rays per pixel over
// the aperture disc, the same Zf and the CoC at infinity alpha). That is
// ground truth no diffusion method has been compared with. Each method
// blurs the pinhole render with the scale map of the same CoC (brume dof's
// σ = sqrt(σ0² + (c/4)²), σ0 = 0.5 px for the supersampled render, cap
// 64 px) and is compared with the thin-lens render: PSNR on linear RGB
// (peak 1) and SSIM on sRGB-encoded luminance (Wang et al. 2004: 11x11
// Gaussian window of σ 1.5, K1 0.01, K2 0.03; OpenCV 4.6 in Debian 12 has no
// SSIM of its own outside opencv_contrib). Methods: invariant-exact (the
// default), standard, bertalmio (eq. 16), leaky (eq. 14), and the study's
// direct gather (per-pixel Gaussian of the pixel's own scale over 3σ).
// Not a pass mark: a post-process on a pinhole image cannot show partial
// occlusion (the lens sees behind a blurred near edge).
//
// Usage: brume_fidelity_dof OUT_DIR [WIDTH HEIGHT SAMPLES]
// Writes OUT_DIR/fidelity.csv, the thin-lens images and each method's image
// (PNG, sRGB) for focus on the ball (3.9 m) and on the house (35 m).
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "brume/compare.hpp"
#include "brume/demo_scene.hpp"
#include "brume/dof.hpp"
#include "brume/io.hpp"
#include "brume/peers.hpp"

using namespace brume;
namespace fs = std::filesystem;

namespace {

// sRGB-encoded luminance in [0, 1].
std::vector<double> luma(const Image& im) {
  std::vector<double> y(im.pixels());
  for (std::size_t i = 0; i < y.size(); ++i) {
    const float* c = &im.data[i * 3];
    const float l = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
    y[i] = linear_to_srgb(std::min(1.0f, std::max(0.0f, l)));
  }
  return y;
}

// Mean SSIM (Wang et al. 2004) with an 11x11 Gaussian window (sigma 1.5),
// over the pixels whose window lies inside the image.
double ssim(const Image& a, const Image& b) {
  const int W = a.width, H = a.height, r = 5;
  const std::vector<double> x = luma(a), y = luma(b);
  double g[11], gs = 0;
  for (int i = -r; i <= r; ++i) gs += g[i + r] = std::exp(-0.5 * i * i / (1.5 * 1.5));
  for (double& v : g) v /= gs;
  const double C1 = 0.01 * 0.01, C2 = 0.03 * 0.03;
  double sum = 0;
  long n = 0;
#pragma omp parallel for reduction(+ : sum, n)
  for (int py = r; py < H - r; ++py)
    for (int px = r; px < W - r; ++px) {
      double mx = 0, my = 0, xx = 0, yy = 0, xy = 0;
      for (int j = -r; j <= r; ++j)
        for (int i = -r; i <= r; ++i) {
          const double w = g[i + r] * g[j + r];
          const std::size_t k = static_cast<std::size_t>(py + j) * W + (px + i);
          mx += w * x[k], my += w * y[k], xx += w * x[k] * x[k], yy += w * y[k] * y[k], xy += w * x[k] * y[k];
        }
      const double vx = xx - mx * mx, vy = yy - my * my, cxy = xy - mx * my;
      sum += ((2 * mx * my + C1) * (2 * cxy + C2)) / ((mx * mx + my * my + C1) * (vx + vy + C2));
      ++n;
    }
  return sum / n;
}

void write_png(const fs::path& p, const Image& im) {
  WriteOptions o;
  o.bits = "8";
  write_image(p.string(), im, o);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: brume_fidelity_dof OUT_DIR [WIDTH HEIGHT SAMPLES]\n");
    return 2;
  }
  const fs::path dir = argv[1];
  const int W = argc > 3 ? std::atoi(argv[2]) : 400, H = argc > 3 ? std::atoi(argv[3]) : 280;
  const int S = argc > 4 ? std::atoi(argv[4]) : 256;
  fs::create_directories(dir);
  const DemoScene pin = render_demo_scene(W, H);
  Intrinsics k;
  k.fx = k.fy = 0.5 * H / std::tan(0.5 * pin.fov_y_deg * M_PI / 180.0);
  k = resolve(k, W, H);
  const Image z = planar_depth(pin.range, k);
  write_png(dir / "pinhole.png", pin.rgb);

  std::ofstream csv(dir / "fidelity.csv");
  csv << "focus,focus_distance_m,coc_infinity_px,method,psnr_linear_db,ssim,iterations,seconds\n";
  struct Focus {
    const char* name;
    double zf, alpha;
  };
  // alpha in px of a W = 400 frame; scaled with the width.
  const Focus focus[] = {{"ball", 3.9, 16.0 * W / 400.0}, {"house", 35.0, 12.0 * W / 400.0}};
  // The leak comparison: the house's top-left (in focus, against the blurred
  // hills and tree) from the thin lens and each method, 3x, side by side.
  std::vector<Image> panels;
  for (const Focus& f : focus) {
    const auto t0 = std::chrono::steady_clock::now();
    const DemoScene lens = render_demo_scene_thin_lens(W, H, f.zf, f.alpha, S);
    const double lens_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::fprintf(stderr, "thin lens, focus on the %s: %d rays per pixel, %.1f s\n", f.name, S, lens_s);
    write_png(dir / (std::string("thinlens-") + f.name + ".png"), lens.rgb);
    DofParams p;
    p.focus_distance_m = f.zf;
    p.coc_infinity_px = f.alpha;
    p.diffusion.sigma0 = 0.5;  // the render is supersampled: a sharp pixel is about a box of 1 px (sigma 0.29)
    auto report = [&](const std::string& m, const Image& out, int iters, double secs) {
      const CompareResult c = compare_images(out, lens.rgb);
      const double s = ssim(out, lens.rgb);
      csv << f.name << "," << f.zf << "," << f.alpha << "," << m << "," << c.psnr_linear_db << "," << s << "," << iters
          << "," << secs << "\n";
      std::fprintf(stderr, "  %-16s PSNR %6.2f dB  SSIM %.4f  (%d iterations, %.2f s)\n", m.c_str(), c.psnr_linear_db,
                   s, iters, secs);
      write_png(dir / ("dof-" + std::string(f.name) + "-" + m + ".png"), out);
      if (std::string(f.name) == "house" && m != "standard") panels.push_back(out);
    };
    if (std::string(f.name) == "house") panels.push_back(lens.rgb);
    {
      const CompareResult c = compare_images(pin.rgb, lens.rgb);
      csv << f.name << "," << f.zf << "," << f.alpha << ",pinhole," << c.psnr_linear_db << "," << ssim(pin.rgb, lens.rgb)
          << ",0,0\n";
    }
    for (DofScheme s : {DofScheme::invariant_exact, DofScheme::standard, DofScheme::bertalmio, DofScheme::leaky}) {
      p.scheme = s;
      DofAnalysis a;
      const auto t1 = std::chrono::steady_clock::now();
      const DofResult r = apply_dof(pin.rgb, z, p, a);
      report(to_string(s), r.rgb, a.plan.iterations,
             std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count());
    }
    // The study's direct gather on the same scale map (foreground rule
    // included), each pixel a Gaussian of its own scale: it leaks both ways.
    DofAnalysis a;
    p.scheme = DofScheme::invariant_exact;
    const Image sigma = dof_scale_map(z, p, a);
    Image g(W, H, 4, 1.0f);
    for (std::size_t i = 0; i < pin.rgb.pixels(); ++i)
      for (int c = 0; c < 3; ++c) g.data[i * 4 + c] = pin.rgb.data[i * 3 + c];
    const auto t2 = std::chrono::steady_clock::now();
    peers::gather_blur(g, sigma, p.diffusion.sigma0);
    const double gs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t2).count();
    Image gr(W, H, 3);
    for (std::size_t i = 0; i < pin.rgb.pixels(); ++i)
      for (int c = 0; c < 3; ++c) gr.data[i * 3 + c] = g.data[i * 4 + c];
    report("gather", gr, 0, gs);
  }
  {
    const int cx0 = static_cast<int>(0.06 * W), cy0 = static_cast<int>(0.17 * H);
    const int cw = static_cast<int>(0.22 * W), ch = static_cast<int>(0.2 * H), z = 3, gap = 4;
    const int n = static_cast<int>(panels.size());
    Image fig(n * cw * z + (n - 1) * gap, ch * z, 3, 1.0f);
    for (int k = 0; k < n; ++k)
      for (int y = 0; y < ch * z; ++y)
        for (int x = 0; x < cw * z; ++x)
          for (int c = 0; c < 3; ++c)
            fig.at(k * (cw * z + gap) + x, y, c) = panels[static_cast<std::size_t>(k)].at(cx0 + x / z, cy0 + y / z, c);
    write_png(dir / "leak-house.png", fig);
  }
  std::fprintf(stderr, "wrote %s\n", (dir / "fidelity.csv").c_str());
  return 0;
}
