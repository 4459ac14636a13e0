// brume — the binary16 storage type of the f16 diffusion precision (the
// F16C check is Highway's: diffusion_fast_f16.cpp). GCC 12 has _Float16 on x86-64; clang has it there only
// from clang 15, and clang-14 (the sanitizer and fuzzing builds,
// scripts/test-sanitize.sh) has the storage-only __fp16 instead; GCC 12 has
// no _Float16 in C++ on aarch64 (from GCC 13), but __fp16, IEEE binary16
// there (scripts/test-aarch64.sh). All convert float -> binary16 by IEEE
// round-to-nearest-even and back exactly, so the rounding is the same.
#pragma once

namespace brume {
#if (defined(__clang__) && __clang_major__ < 15) || (defined(__aarch64__) && !defined(__clang__) && __GNUC__ < 13)
using half_t = __fp16;
#else
using half_t = _Float16;
#endif

}  // namespace brume
