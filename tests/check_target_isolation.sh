#!/bin/bash
# brume — src/diffusion/diffusion_fast_f16.cpp compiles its binary16 kernels for
# AVX2 + F16C (a target pragma after its includes) and is entered only after
# a run-time CPU check. The inline functions of the headers it includes
# (mirror, eq11, StoreF32, std::vector's members, ...) are shared with the
# rest of the library: a build that does not inline them emits them from
# this file as weak symbols, and the linker may keep this file's copy for
# every caller. This checks, at -O0 and -Og (where that happens: ~150 and
# ~20 such symbols), that none of those copies holds a VEX-encoded (AVX)
# instruction -- which they did while the whole file was compiled with
# -mavx2 -mf16c (5 at -O0: eq11, StoreF32's load and store, ...), an
# illegal instruction on an x86-64 without AVX in such a build.
#   check_target_isolation.sh CXX SOURCE_DIR [EXTRA_FLAGS...]
set -euo pipefail
cxx=$1
src=$2
shift 2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
status=0
for opt in -O0 -Og; do
  "$cxx" -std=c++20 -fopenmp -fPIC "$opt" -fno-math-errno -Wno-psabi "$@" -I"$src/include" -I"$src/src" \
    -c "$src/src/diffusion/diffusion_fast_f16.cpp" -o "$tmp/f16.o"
  weak=$(nm "$tmp/f16.o" | awk '$2 == "W" || $2 == "V" { print $3 }')
  count=0
  bad=0
  for s in $weak; do
    count=$((count + 1))
    if objdump -d --no-show-raw-insn --disassemble="$s" "$tmp/f16.o" | grep -E $'\t''v[a-z0-9]+ ' >/dev/null; then
      echo "$opt: weak symbol $(echo "$s" | c++filt) holds AVX instructions"
      bad=$((bad + 1))
    fi
  done
  echo "$opt: $count weak symbols, $bad with AVX instructions"
  [ "$bad" -eq 0 ] || status=1
done
exit $status
