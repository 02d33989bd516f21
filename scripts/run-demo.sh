#!/usr/bin/env bash
# README set-up command: create .venv if needed, install, run the demo.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/_venv.sh
ensure_venv

export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export MPLBACKEND="${MPLBACKEND:-Agg}"
mkdir -p out

# The demo: one command per line.
.venv/bin/leadscrew-squeak predict --speed 20 --load 200
.venv/bin/leadscrew-squeak sweep --speed 0.5:120:120 --load 200 --plot out/sweep.png
