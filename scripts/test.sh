#!/usr/bin/env bash
# The whole test suite from a fresh Debian 12 machine: install the
# dependencies, build, and run every test with ctest. Real-data tests read
# ../shared/data (or the folder named by BRUME_DATA_DIR) in place and skip
# with a message when it is absent (docs/testing.md, "The real data").
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
# A unity build (CMake joins each target's sources, eight to a translation
# unit): on 2 cores a clean build takes ~3.5 min instead of ~6, and the
# outputs are bit-identical (strict ISO mode, no FP contraction: joining files
# changes no arithmetic; the files with their own flags are compiled alone;
# compared on every effect, 2026-12-01). Rebuilding one file at a time while
# editing: configure your own build folder with -DCMAKE_UNITY_BUILD=OFF.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=ON
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)"
