#!/usr/bin/env bash
# Sets up (Debian packages), builds everything (Release with assertions), and runs every test
# through CTest.
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh
# Release optimisation with assertions kept on: the solver's invariants are checked in tests.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O2" >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)" "$@"
