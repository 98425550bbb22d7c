#!/usr/bin/env bash
# Sets up (Debian packages), builds everything (Release) and runs every test through CTest; then
# builds Debug with AddressSanitizer and UndefinedBehaviorSanitizer (HEMIBAKE_DCHECK on) and runs
# the unit and integration tests again there. Arguments go to both ctest runs (e.g. -R Solver).
# HEMIBAKE_SKIP_SANITIZE=1 skips the second build. Then the fuzz targets are built with clang
# (HEMIBAKE_FUZZ=ON, in build-fuzz/) and each runs for 10 s from its seeds; HEMIBAKE_SKIP_FUZZ=1
# skips that.
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh --test
# The node tools of tests/e2e, at the versions in package-lock.json.
if [[ ! -f tests/e2e/node_modules/.package-lock.json || tests/e2e/package-lock.json -nt tests/e2e/node_modules/.package-lock.json ]]; then
  (cd tests/e2e && npm ci --no-audit --no-fund --loglevel=error)
fi
jobs=$(nproc)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DHEMIBAKE_BUILD_TESTS=ON -DHEMIBAKE_BUILD_BENCH=ON >/dev/null
cmake --build build -j"$jobs"
ctest --test-dir build --output-on-failure -j"$jobs" "$@"
if [[ "${HEMIBAKE_SKIP_SANITIZE:-0}" != 1 ]]; then
  echo "test.sh: Debug build with AddressSanitizer and UndefinedBehaviorSanitizer (unit and integration tests)"
  cmake -S . -B build-sanitize -DCMAKE_BUILD_TYPE=Debug -DHEMIBAKE_SANITIZE=ON -DHEMIBAKE_BUILD_TESTS=ON \
        -DHEMIBAKE_BUILD_BENCH=OFF >/dev/null
  cmake --build build-sanitize -j"$jobs"
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir build-sanitize --output-on-failure -j"$jobs" -LE e2e "$@"
fi
if [[ "${HEMIBAKE_SKIP_FUZZ:-0}" != 1 ]]; then
  echo "test.sh: fuzz targets (clang, AddressSanitizer and UndefinedBehaviorSanitizer), 10 s each"
  cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ -DHEMIBAKE_FUZZ=ON \
        -DHEMIBAKE_BUILD_TESTS=OFF -DHEMIBAKE_BUILD_BENCH=OFF -DHEMIBAKE_FUZZ_SECONDS=10 >/dev/null
  cmake --build build-fuzz -j"$jobs" --target gltf_fuzz params_fuzz multipart_fuzz http_fuzz
  ctest --test-dir build-fuzz --output-on-failure -L fuzz
fi
