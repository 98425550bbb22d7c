#!/usr/bin/env bash
# Sets up (Debian packages), builds everything (Release), and runs every test through CTest.
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DHEMIBAKE_BUILD_TESTS=ON -DHEMIBAKE_BUILD_BENCH=ON >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)" "$@"
