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

int main(int argc, char** argv) {
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
  bool ok = plan.iterations > 0 && std::abs(red - mass) <= 1e-5 * mass && worst_green <= 1e-5 &&
             centre < 0.5 && centre > 0.25;

  // A 16-bit PNG round trip through the installed codec module
  // (lib/brume/brume_codec.so; run.cmake points BRUME_CODEC_MODULE at it):
  // 16-bit linear storage of k/65535 reads back exactly.
  if (argc > 1) {
    brume::Image g(5, 3, 3);
    for (std::size_t i = 0; i < g.data.size(); ++i) g.data[i] = static_cast<float>(i * 1000) / 65535.0f;
    brume::WriteOptions o;
    o.bits = "16";
    o.transfer = brume::Transfer::linear;
    {
      brume::OutputSet outs;
      outs.write(argv[1], g, o, "--out");
      outs.commit();
    }
    const brume::Image back = brume::read_color(argv[1], brume::Transfer::linear);
    const bool same = back.data == g.data;
    std::printf("brume consumer: PNG round trip through the codec module %s\n", same ? "exact" : "DIFFERS");
    ok = ok && same;
  }
  return ok ? 0 : 1;
}
