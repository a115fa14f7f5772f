#!/usr/bin/env bash
# Configures and builds toolbench in build/ (Release). Extra arguments go to cmake --build,
# e.g. scripts/build.sh --target toolbench
set -euo pipefail
cd "$(dirname "$0")/.."
jobs="${TOOLBENCH_JOBS:-$(nproc)}"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release ${TOOLBENCH_CMAKE_ARGS:-} >/dev/null
cmake --build build -j "$jobs" "$@"
