// An installed-brume consumer: diffusion of a wrapped buffer, checked against
// two exact invariants. Exit status 0 on success.
#include <cmath>
#include <cstdio>
#include <vector>

// Every installed public header, so that one needing a private header (or a
// dependency the package does not provide) fails this build.
#include <brume/depth.hpp>
#include <brume/depth_source.hpp>
#include <brume/diffusion.hpp>
#include <brume/error.hpp>
#include <brume/exec.hpp>
#include <brume/gpu.hpp>
#include <brume/haze.hpp>
#include <brume/image.hpp>
#include <brume/io.hpp>
#include <brume/params.hpp>
#include <brume/prepare.hpp>
#include <brume/record.hpp>

int main() {
  // A caller-owned RGBA buffer (as a renderer would hold it), seen through a
  // view and copied into the Image the engine takes.
  const int W = 64, H = 48;
  std::vector<float> pixels(static_cast<std::size_t>(W) * H * 4, 0.25f);
  pixels[(static_cast<std::size_t>(H / 2) * W + W / 2) * 4 + 0] += 1.0f;  // an impulse in red
  brume::Image f = brume::copy_of(brume::ConstImageView(pixels.data(), W, H, 4, W * 4, 4));
  const brume::Image sigma(W, H, 1, 4.0f);
  const brume::DiffusionPlan plan = brume::diffuse(f, sigma, 4.0, brume::DiffusionParams{});

  // Green is constant, so it must stay 0.25 (the stencil weights sum to 1;
  // float rounding over the iterations stays far below 1e-5). Red must keep
  // its mass 0.25 W H + 1 (the mirror boundary loses none; float sum of 3072
  // values, relative 1e-5), and the impulse must have spread (centre < 0.5).
  double red = 0.0, worst_green = 0.0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      red += f.at(x, y, 0);
      worst_green = std::max(worst_green, std::abs(f.at(x, y, 1) - 0.25));
    }
  const double mass = 0.25 * W * H + 1.0;
  const double centre = f.at(W / 2, H / 2, 0);
  std::printf("brume consumer: %d iterations, red mass %.6f (expected %.6f), green error %.2e, centre %.4f\n",
              plan.iterations, red, mass, worst_green, centre);
  const bool ok = plan.iterations > 0 && std::abs(red - mass) <= 1e-5 * mass && worst_green <= 1e-5 &&
                  centre < 0.5 && centre > 0.25;
  return ok ? 0 : 1;
}
