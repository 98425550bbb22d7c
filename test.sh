#!/usr/bin/env bash
# Sets up (Debian packages), builds everything (Release) and runs every test through CTest; then
# one instrumented build (clang, Debug with HEMIBAKE_DCHECK, AddressSanitizer and
# UndefinedBehaviorSanitizer, libFuzzer's coverage counters on the libraries that read untrusted
# bytes; in build-sanitize/, built at the lowest priority while the Release tests run) runs the
# unit and integration tests again and gives each libFuzzer
# target a 10 s run from its seeds (CTest label fuzz); tests labelled heavy (those over 15 s
# instrumented) run in the Release build only. Tests labelled slow (the 100-run SIGKILL test) are
# left to a manual `ctest --test-dir build -L slow`. Arguments go to both ctest runs (e.g. -R
# Solver). HEMIBAKE_SKIP_SANITIZE=1 skips the second build; HEMIBAKE_SKIP_FUZZ=1 skips the fuzz
# runs in it. Each stage's wall time is printed.
set -euo pipefail
cd "$(dirname "$0")"
scripts/setup.sh --test
# The node tools of tests/e2e, at the versions in package-lock.json.
if [[ ! -f tests/e2e/node_modules/.package-lock.json || tests/e2e/package-lock.json -nt tests/e2e/node_modules/.package-lock.json ]]; then
  (cd tests/e2e && npm ci --no-audit --no-fund --loglevel=error)
fi
jobs=$(nproc)
started=$SECONDS
stage_start=$SECONDS
stage() {  # stage NAME: the wall time of the stage that just ended, and of the run so far
  echo "test.sh: stage $1 took $((SECONDS - stage_start)) s (total $((SECONDS - started)) s)"
  stage_start=$SECONDS
}
stage setup
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DHEMIBAKE_BUILD_TESTS=ON -DHEMIBAKE_BUILD_BENCH=ON >/dev/null
cmake --build build -j"$jobs"
stage release-build
sanitize=0
[[ "${HEMIBAKE_SKIP_SANITIZE:-0}" == 1 ]] || sanitize=1
if [[ $sanitize == 1 ]]; then
  # One build serves both: the tests link it without libFuzzer's main (the sanitizer runtime takes
  # the coverage counters), the fuzz targets link it with. Two builds, gcc for the tests and clang
  # for the fuzz targets, took 10.5 + 4.3 min of CI's 30. It starts now at the lowest priority
  # (nice 19), beside the Release tests, and takes only the time they leave idle (servers, browsers
  # and PostgreSQL waiting); once they end it has the machine. Its output goes to
  # build-sanitize/build.log, printed if it fails.
  echo "test.sh: clang Debug build with AddressSanitizer, UndefinedBehaviorSanitizer and the fuzz targets (beside the Release tests, at nice 19)"
  fuzz=ON
  [[ "${HEMIBAKE_SKIP_FUZZ:-0}" != 1 ]] || fuzz=OFF
  cmake -S . -B build-sanitize -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_COMPILER=clang++ -DHEMIBAKE_SANITIZE=ON \
        -DHEMIBAKE_FUZZ=$fuzz -DHEMIBAKE_BUILD_TESTS=ON -DHEMIBAKE_BUILD_BENCH=OFF -DHEMIBAKE_FUZZ_SECONDS=10 >/dev/null
  setsid nice -n 19 cmake --build build-sanitize -j"$jobs" > build-sanitize/build.log 2>&1 &
  sanitize_build=$!
  # A failing Release run ends the script: the build beside it goes with it.
  trap 'kill -- -$sanitize_build 2>/dev/null || true' EXIT
fi
ctest --test-dir build --output-on-failure -j"$jobs" -LE slow "$@"
stage release-tests
if [[ $sanitize == 1 ]]; then
  if ! wait "$sanitize_build"; then
    tail -n 200 build-sanitize/build.log
    echo "test.sh: the instrumented build failed (build-sanitize/build.log)"
    exit 1
  fi
  trap - EXIT
  stage sanitize-build-after-the-release-tests
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --test-dir build-sanitize --output-on-failure -j"$jobs" -LE 'e2e|slow|heavy' "$@"
  stage sanitize-and-fuzz-tests
fi
