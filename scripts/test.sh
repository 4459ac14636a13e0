#!/usr/bin/env bash
# The whole test suite from a fresh Debian 12 machine: install the
# dependencies, build, and run every test with ctest. Real-data tests read
# ../shared/data in place and skip with a message when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)"
