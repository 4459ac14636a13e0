// brume — which SIMD targets the vector kernels are compiled for (internal).
//
// The vector kernels (the diffusion engine's rows and an effect's vector
// row: the files that include hwy/foreach_target.h, listed in
// tests/check_target_isolation.sh) are each written once with Highway and
// compiled for every target below, the CPU choosing at run time
// (HWY_DYNAMIC_DISPATCH). Every such file includes this header first, so
// that all of them, and this list, agree on the targets.
//
// Compiled on x86-64: the baseline fallback for any x86-64 (EMU128, portable
// C++ that the compiler vectorises for SSE2; with GCC before 12.3, which
// Highway 1.0.3 counts as breaking EMU128, SCALAR: one lane), SSE4, AVX2 (with FMA and F16C; no
// contraction is allowed where these files are compiled, -ffp-contract=off,
// so FMA never changes a result), AVX3 (AVX-512 F/VL/DQ/BW). SSSE3 is left
// out: it would add a fifth compilation of every kernel (build time, which
// CI counts) for CPUs of 2006-2008, which run the fallback instead. On
// aarch64 (GCC 12): NEON, the baseline, and SVE, SVE2, SVE_256 and SVE2_128;
// the diffusion engine is built and tested there under qemu
// (scripts/test-aarch64.sh, docs/testing.md).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#ifndef HWY_DISABLED_TARGETS
#define HWY_DISABLED_TARGETS HWY_SSSE3
#endif

namespace brume::simd {

// The targets compiled above that this CPU runs (best first), as Highway's
// target bits; affected by force_target.
std::vector<std::int64_t> targets();
// Highway's name of a target ("AVX2", "EMU128", ...).
std::string target_name(std::int64_t target);
// For tests and benchmarks: the kernels' dispatch then believes the CPU runs
// `target` only (hwy::SetSupportedTargetsForTest; 0: the CPU's own set
// again). Process-wide, not thread-safe against running kernels.
void force_target(std::int64_t target);

}  // namespace brume::simd
