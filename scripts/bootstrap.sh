#!/usr/bin/env bash
# One command from a fresh Debian 12 machine to brume's demo: install the
# dependencies, build, and render the built-in scene clean, with haze and with
# fog into demo-out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j"$(nproc)"
./build/brume demo --out-dir demo-out
echo "bootstrap: the demo images are in $(pwd)/demo-out (clean.png, haze.png, fog.png, range-preview.png)"
