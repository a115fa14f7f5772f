#!/usr/bin/env bash
# Sets up what is missing (Debian packages), builds, and runs the default job:
# one scene (seed 1) rendered from the robot's helmet camera after it turns to the rack.
# Outputs go to runs/default/ (rgb.png, depth.png, camera.json, cloud.ply, ground_truth.json).
# Usage: scripts/run.sh [toolbench render options...]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh --target toolbench
if [ $# -eq 0 ]; then set -- --seed 1 --out runs/default; fi
build/toolbench render "$@"
