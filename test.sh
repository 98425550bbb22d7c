#!/usr/bin/env bash
# Sets up (Debian packages), builds everything (Release), and runs every test through CTest.
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh --test
# The node tools of tests/e2e, at the versions in package-lock.json.
if [[ ! -f tests/e2e/node_modules/.package-lock.json || tests/e2e/package-lock.json -nt tests/e2e/node_modules/.package-lock.json ]]; then
  (cd tests/e2e && npm ci --no-audit --no-fund --loglevel=error)
fi
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DHEMIBAKE_BUILD_TESTS=ON -DHEMIBAKE_BUILD_BENCH=ON >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)" "$@"
