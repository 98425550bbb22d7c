#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan and UBSan, in build-fuzz/) and runs each for SECONDS
# (default 60), starting from its seed corpus in tests/fuzz/corpus and keeping what it finds in
# build-fuzz/corpus. Prints each target's executions, coverage and crashes; a crash's input is
# left in build-fuzz/artifacts and the script fails.
#   scripts/fuzz.sh [SECONDS] [TARGET...]   targets: gltf params multipart http (default all)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
shift || true
targets=("$@")
((${#targets[@]})) || targets=(gltf params multipart http)
cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ -DHEMIBAKE_FUZZ=ON \
      -DHEMIBAKE_BUILD_TESTS=OFF -DHEMIBAKE_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target "${targets[@]/%/_fuzz}"
mkdir -p build-fuzz/artifacts
failed=0
for t in "${targets[@]}"; do
  corpus=build-fuzz/corpus/$t
  mkdir -p "$corpus"
  log=build-fuzz/fuzz-$t.log
  status=0
  ASAN_OPTIONS=detect_leaks=0 "build-fuzz/bin/${t}_fuzz" -max_total_time="$seconds" -timeout=20 -rss_limit_mb=4096 \
    -print_final_stats=1 -artifact_prefix=build-fuzz/artifacts/"$t"- "$corpus" "tests/fuzz/corpus/$t" >"$log" 2>&1 || status=$?
  execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
  cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$log" | tail -1 || echo "cov: ?")
  if ((status != 0)); then
    failed=1
    echo "fuzz $t: FAILED after $execs executions ($cov); see $log and build-fuzz/artifacts/$t-*"
  else
    echo "fuzz $t: $execs executions in ${seconds} s, $cov, corpus $(ls "$corpus" | wc -l) inputs, no crash"
  fi
done
exit $failed
