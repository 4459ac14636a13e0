// brume — the methods a user would pick instead of diffusion, implemented
// here only to be measured against it (`brume study diffusion`, issue #5).
// They are peers, not effects: no CLI of their own, no GPU path.
//
// Both take the same problem as brume::diffuse: a four-channel image at
// inner scale sigma0 and a per-pixel target scale sigma(x) >= sigma0 in
// pixels; where sigma is constant the ideal result is a Gaussian of standard
// deviation sqrt(sigma^2 - sigma0^2) per axis. Boundary: half-sample mirror.
#pragma once

#include "brume/exec.hpp"
#include "brume/image.hpp"

namespace brume::peers {

// Direct space-variant Gaussian gather: every output pixel is the normalised
// sum of its neighbours weighted by a Gaussian of its own scale
// s(x) = sqrt(sigma(x)^2 - sigma0^2), over a square window of radius
// ceil(radius_sigmas * s(x)). The cost Bertalmio et al. (§4) count against
// diffusion: O(s^2) taps per pixel. At a constant scale it is a true
// (truncated) Gaussian convolution.
void gather_blur(Image& f, const Image& sigma, double sigma0, double radius_sigmas = 3.0, const Exec& exec = {});

// Mip-map interpolation blur in the style of Elek et al. 2013 and Lee et al.
// 2009: a pyramid whose level k is level k-1 blurred by a Gaussian of
// 1 level pixel and averaged 2x2 (a Gaussian-filtered mip-map, as those
// papers build on the GPU), then per pixel two bilinear look-ups in the
// levels that bracket the target scale, blended linearly (trilinear
// filtering). Improved over a naive level index log2(sigma): the blend
// weight is chosen from the exact second moment of each level (its filters
// plus the bilinear reconstruction), so the result has the target variance
// wherever sigma is locally constant. Indexing uses sigma(x) itself (no
// blurred depth or masking), so a sharp pixel reads level 0 and never mixes,
// while a blurred pixel next to it reads coarse levels that contain it.
void mipmap_blur(Image& f, const Image& sigma, double sigma0, const Exec& exec = {});

// Second moment (per axis, original pixels^2) of mip-map level k as
// mipmap_blur reconstructs it: the pyramid's filters plus the bilinear
// reconstruction averaged over the pixel grid. Exposed for the tests.
double mipmap_level_variance(int k);

}  // namespace brume::peers
