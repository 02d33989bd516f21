# SPDX-License-Identifier: Apache-2.0
"""Test-session environment: keep any ROS 2 traffic on loopback and on a private domain.

Set at import time (before any test imports rclpy); values already in the environment win,
so scripts/run-tests.sh or a developer can choose them.
"""

import atexit
import os
import shutil
import tempfile

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
# One domain per test process: test processes sharing a domain discover each other's
# participants, and Fast DDS teardown was seen to deadlock then; 1..200, never the default 0.
os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 200 + 1))
if "ROS_LOG_DIR" not in os.environ:
    _log_dir = tempfile.mkdtemp(prefix="leadscrew_ros_test_log_")
    atexit.register(shutil.rmtree, _log_dir, ignore_errors=True)
    os.environ["ROS_LOG_DIR"] = _log_dir
os.environ.setdefault("MPLBACKEND", "Agg")
