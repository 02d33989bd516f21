#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# README set-up command: create .venv if needed, install, run the test suite.
# Extra arguments go to pytest, e.g. scripts/run-tests.sh test/test_config.py -x
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/_venv.sh
ensure_venv ros,test,doc

# ROS 2 traffic stays on loopback, on a domain of our own, with logs in a temp dir.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( $$ % 100 + 1 ))}"
ROS_LOG_DIR="$(mktemp -d "${TMPDIR:-/tmp}/leadscrew_ros_log.XXXXXX")"
export ROS_LOG_DIR
trap 'rm -rf "$ROS_LOG_DIR"' EXIT
export MPLBACKEND=Agg

# No arguments: the whole suite in test/. With arguments (files, -k, -x ...) pytest gets them
# as they are (setup.cfg's testpaths keeps a bare option list to test/).
if [[ $# -eq 0 ]]; then
    set -- test
fi
# A hang fails loudly (faulthandler dumps the stacks) instead of eating CI's time.
timeout 1500 .venv/bin/python -m pytest -q -o faulthandler_timeout=300 "$@"
