#!/usr/bin/env bash
# Sets up what is missing (Debian packages), builds, and runs the default job: one full
# episode (seed 1) -- look at the table, find the ball, choose a tool on the rack, grasp it,
# pull the ball, put the tool down, grasp the ball.
# Outputs go to runs/default/ (result.json, table.png, rack.png, table_after.png) and a summary
# is printed. Usage: scripts/run.sh [toolbench episode options...]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh --target toolbench
if [ $# -eq 0 ]; then set -- --seed 1 --out runs/default; fi
build/toolbench episode "$@"
