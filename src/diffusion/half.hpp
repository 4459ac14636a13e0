// brume — the binary16 storage type of the f16 diffusion precision (the
// F16C check is Highway's: diffusion_fast_f16.cpp). GCC 12 has _Float16 on x86-64; clang has it there only
// from clang 15, and clang-14 (the sanitizer and fuzzing builds,
// scripts/test-sanitize.sh) has the storage-only __fp16 instead. Both convert
// float -> binary16 by IEEE round-to-nearest-even and back exactly, so the
// rounding is the same.
#pragma once

namespace brume {
#if defined(__clang__) && __clang_major__ < 15
using half_t = __fp16;
#else
using half_t = _Float16;
#endif

}  // namespace brume
