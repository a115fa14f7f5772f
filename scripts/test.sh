#!/usr/bin/env bash
# Sets up what is missing, builds everything (warnings are errors) and runs the whole test suite:
#   1. Release build: unit (fast), slow (rendering, physics) and benchmark smoke tests;
#   2. AddressSanitizer + UBSan build of the unit tests, run;
#   3. libFuzzer targets (mesh loaders, scene parser), each for a fixed time.
# Usage: scripts/test.sh [--quick]   (--quick: step 1 only)
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0
[ "${1:-}" = "--quick" ] && quick=1
jobs="${TOOLBENCH_JOBS:-$(nproc)}"
fuzz_seconds="${TOOLBENCH_FUZZ_SECONDS:-60}"
# Each stage header says how long the run has taken so far: CI has a fixed budget (90 min).
stage() { echo "== [$(date -u +%H:%M:%S), $((SECONDS / 60)) min $((SECONDS % 60)) s in] $*"; }

scripts/setup.sh

stage "release build"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOOLBENCH_WERROR=ON >/dev/null
cmake --build build -j "$jobs"
stage "release tests"
ctest --test-dir build --output-on-failure -j 2 -L 'fast|slow|bench|regression'
[ $quick -eq 1 ] && { stage "release tests passed (--quick: no sanitizer or fuzz stage)"; exit 0; }

stage "sanitizer build (ASan + UBSan) of the unit tests"
# Compiler flags of a sanitizer build: cmake/toolbench.cmake.
cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTOOLBENCH_SANITIZE=ON \
  -DTOOLBENCH_BUILD_BENCHMARKS=OFF -DTOOLBENCH_WERROR=ON >/dev/null
unit_targets=$(sed -n 's/^toolbench_add_test(\([a-z_]*_tests\) LABEL fast.*/\1/p' tests/*/CMakeLists.txt)
# shellcheck disable=SC2086
cmake --build build-asan -j "$jobs" --target $unit_targets
stage "sanitizer tests"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan --output-on-failure -j 2 -L fast

stage "fuzzing (${fuzz_seconds} s per target)"
CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DTOOLBENCH_BUILD_FUZZERS=ON -DTOOLBENCH_BUILD_TESTS=OFF -DTOOLBENCH_BUILD_BENCHMARKS=OFF >/dev/null
cmake --build build-fuzz -j "$jobs" --target mesh_loader_fuzz scene_parser_fuzz
for target in mesh_loader_fuzz:fuzz/corpus/mesh scene_parser_fuzz:fuzz/corpus/scene; do
  name="${target%%:*}"; seeds="${target#*:}"
  work="build-fuzz/corpus-$name"; mkdir -p "$work"
  TMPDIR=/dev/shm build-fuzz/fuzz/"$name" -max_total_time="$fuzz_seconds" -rss_limit_mb=2048 -print_final_stats=1 \
    "$work" "$seeds" 2>&1 | tail -n 12
done
stage "all test stages passed"
