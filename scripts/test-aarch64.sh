#!/usr/bin/env bash
# brume's diffusion engine on aarch64 (issue #55 item 2; docs/testing.md,
# "aarch64 under qemu"): the engine alone (tests/engine/: src/diffusion/, the
# core files it needs, tests/test_diffusion.cpp and test_diffusion_rates.cpp)
# cross-built with Debian's g++-aarch64-linux-gnu (cmake/aarch64-linux-gnu.cmake)
# and its tests run under qemu-aarch64, whose default CPU has SVE and SVE2:
# every Highway target the emulated CPU runs (SVE2, SVE, NEON) is forced in
# turn and bit-compared with the scalar reference rows by the tests
# themselves. Then the target tests again at 128- and 256-bit SVE vectors,
# where Highway adds its SVE2_128 and SVE_256 targets.
#   scripts/test-aarch64.sh [BUILD_DIR]    (default build-aarch64)
# Installs what is missing first (scripts/install-deps.sh --aarch64: root or
# sudo). Not in .ci/run: it costs more than CI's time left (docs/testing.md).
# On an aarch64 host the same project builds and runs natively.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build-aarch64}
jobs=$(nproc)
t0=$(date +%s)
if [ "$(uname -m)" = aarch64 ]; then
  toolchain=()
  run=()
else
  bash scripts/install-deps.sh --aarch64
  toolchain=(-DCMAKE_TOOLCHAIN_FILE="$PWD/cmake/aarch64-linux-gnu.cmake")
  run=(qemu-aarch64)
fi
t1=$(date +%s)
cmake -S tests/engine -B "$build" -DCMAKE_BUILD_TYPE=Release "${toolchain[@]}" ${CMAKE_CXX_COMPILER_LAUNCHER:+-DCMAKE_CXX_COMPILER_LAUNCHER=$CMAKE_CXX_COMPILER_LAUNCHER}
t2=$(date +%s)
cmake --build "$build" -j"$jobs"
t3=$(date +%s)
# The whole suite at qemu's default SVE length (512 bits): SVE2, SVE, NEON.
"${run[@]}" "$build/brume_engine_tests"
# The cases that force every target in turn (DiffusionSimd), at 128- and
# 256-bit SVE vectors (the SVE2_128 and SVE_256 targets, SVE and SVE2 there).
if [ ${#run[@]} -gt 0 ]; then
  targets='DiffusionSimd.*'
  for bytes in 16 32; do
    echo "test-aarch64: SVE vectors of $bytes bytes"
    qemu-aarch64 -cpu "max,sve-default-vector-length=$bytes" "$build/brume_engine_tests" --gtest_filter="$targets"
  done
fi
t4=$(date +%s)
echo "test-aarch64: install $((t1 - t0)) s, configure $((t2 - t1)) s, build $((t3 - t2)) s, tests $((t4 - t3)) s" \
     "($jobs cores)"
