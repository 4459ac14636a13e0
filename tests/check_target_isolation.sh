#!/bin/bash
# brume — the vector kernels are written once with Highway and compiled by
# hwy/foreach_target.h for every SIMD target (src/core/simd.hpp): each
# target's code lives in its own namespace (brume::cpu::N_AVX2::...,
# N_AVX3::..., N_SSE4::..., N_SCALAR or N_EMU128, the baseline fallback), is
# compiled for that target's instruction set, and is entered only through
# Highway's dispatch after a run-time CPU check. What stays outside those
# namespaces (the reference rows, the dispatch, the inline functions of the
# headers the files include: mirror, eq11, StoreF32, std::vector's members,
# ...) is shared with the rest of the library, and a build that does not
# inline it emits it from these files as weak symbols that the linker may
# keep for every caller. This compiles each file at -O0 (where those copies
# are emitted: ~150 a file; -Og emitted a subset, ~20) and -O2 (the release
# build's code) and checks every function in the object, by the namespace
# its name carries:
#   - no target namespace (shared code), or the baseline's or SSE4's: no
#     VEX- or EVEX-encoded (AVX) instruction, and outside SSE4's namespace
#     no SSSE3/SSE4 one either -- the file compiled with -mavx2 -mf16c (the
#     binary16 kernels until 2026-12-03) put 5 AVX functions there at -O0
#     (eq11, StoreF32's load and store, ...): an illegal instruction on an
#     x86-64 without AVX in such a build;
#   - N_AVX2: no EVEX-encoded (AVX-512) instruction, so that no AVX-512
#     instruction is reachable on an AVX2-only CPU;
#   - N_AVX3 (and N_AVX3_DL): anything.
# (tzcnt is allowed everywhere: GCC writes __builtin_ctz, which Highway's
# dispatch uses, as rep bsf, which CPUs without BMI1 run as bsf, the same
# result for the non-zero values it is given.)
#   check_target_isolation.sh CXX SOURCE_DIR [EXTRA_FLAGS...]
set -euo pipefail
cxx=$1
src=$2
shift 2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
files="src/diffusion/diffusion_fast_kernels.cpp src/diffusion/diffusion_fast_f16.cpp src/effects/fog/fog_fast.cpp
  src/effects/dof/dof_map_kernels.cpp src/effects/wet/wet_march.cpp"
status=0
for f in $files; do
  for opt in -O0 -O2; do
    "$cxx" -std=c++20 -fopenmp -fPIC "$opt" -fno-math-errno -fno-trapping-math -ffp-contract=off -Wno-psabi \
      -DHWY_SHARED_DEFINE "$@" -I"$src/include" -I"$src/src" -c "$src/$f" -o "$tmp/k.o"
    # objdump -w: one instruction a line, "addr:<TAB>bytes<TAB>mnemonic operands".
    objdump -d -C -w "$tmp/k.o" | awk -v what="$f $opt" '
      function kind(name) {
        if (name ~ /::N_AVX3(_DL)?::/) return "avx3"
        if (name ~ /::N_AVX2::/) return "avx2"
        if (name ~ /::N_SSE4::/) return "sse4"
        return "base"
      }
      /^[0-9a-f]+ <.*>:$/ {
        fn = substr($0, index($0, "<") + 1); fn = substr(fn, 1, length(fn) - 2); k = kind(fn); nfn++; next
      }
      /^ *[0-9a-f]+:\t/ {
        n = split($0, part, "\t"); if (n < 3) next
        split(part[2], bytes, " "); b = 1
        while (bytes[b] ~ /^(67|2e|3e|26|36|64|65)$/) b++
        insn = part[3]; mn = insn; sub(/ .*/, "", mn)
        evex = bytes[b] == "62"
        vex = evex || bytes[b] == "c4" || bytes[b] == "c5"
        sse4 = mn ~ /^(pshufb|palignr|phadd|phsub|pabs|psign|pmaddubsw|pmulhrsw|blendv|pblend|blendp|ptest|pmulld|pmin[su][bdw]|pmax[su][bdw]|insertps|extractps|pextr[bdq]|pinsr[bdq]|round[sp][sd]|dpp[sd]|pmov[sz]x|packusdw|pcmpeqq|pcmpgtq|phminposuw|mpsadbw|popcnt|lzcnt|crc32)/
        bad = ""
        if (k == "avx2" && evex) bad = "an AVX-512 (EVEX) instruction"
        else if ((k == "base" || k == "sse4") && vex) bad = "an AVX (VEX/EVEX) instruction"
        else if (k == "base" && sse4) bad = "an SSSE3/SSE4 instruction"
        if (bad != "" && !(fn in seen)) {
          seen[fn] = 1; nbad++
          printf "%s: %s holds %s: %s\n", what, fn, bad, insn
        }
      }
      END { printf "%s: %d functions, %d outside their target'"'"'s instruction set\n", what, nfn, nbad; exit nbad > 0 }
    ' || status=1
  done
done
exit $status
