#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# README set-up command: create .venv if needed, install, run the demo.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/_venv.sh
ensure_venv ros

export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export MPLBACKEND="${MPLBACKEND:-Agg}"

# The demo: the squeak predictor node driven by a simulated power-seat stroke (one process, on
# a ROS_DOMAIN_ID of its own); live status line, summary, exits by itself (about 15 s).
.venv/bin/leadscrew-squeak demo
