#!/usr/bin/env bash
# One command from a fresh Debian 12 machine to brume's demo: install the
# dependencies, build, and render the built-in scene clean, with haze and with
# fog into demo-out/.
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
./build/brume demo --out-dir demo-out
echo "bootstrap: the demo images are in $(pwd)/demo-out (clean.png, haze.png, fog.png, range-preview.png)"
