// brume — the binary16 storage type of the f16 diffusion precision, and the
// run-time F16C check. GCC 12 has _Float16 on x86-64; clang has it there only
// from clang 15, and clang-14 (the sanitizer and fuzzing builds,
// scripts/test-sanitize.sh) has the storage-only __fp16 instead. Both convert
// float -> binary16 by IEEE round-to-nearest-even and back exactly, so the
// rounding is the same.
#pragma once

#if defined(__x86_64__)
#include <cpuid.h>
#endif

namespace brume {
#if defined(__clang__) && __clang_major__ < 15
using half_t = __fp16;
#else
using half_t = _Float16;
#endif

#if defined(__x86_64__)
// CPUID leaf 1, ECX bit 29. Read directly because clang-14's
// __builtin_cpu_supports does not know "f16c" (GCC's does); F16C's
// instructions are VEX-encoded, so callers also check "avx" (OS support).
inline bool cpu_has_f16c() {
  unsigned a = 0, b = 0, c = 0, d = 0;
  return __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C) != 0;
}
#endif
}  // namespace brume
