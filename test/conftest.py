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
# One domain per test process avoids the Fast DDS teardown deadlock seen when several
# processes share a domain (see shared notes); 1..200, never the default 0.
os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 200 + 1))
if "ROS_LOG_DIR" not in os.environ:
    _log_dir = tempfile.mkdtemp(prefix="leadscrew_ros_test_log_")
    atexit.register(shutil.rmtree, _log_dir, ignore_errors=True)
    os.environ["ROS_LOG_DIR"] = _log_dir
os.environ.setdefault("MPLBACKEND", "Agg")

# ----------------------------------------------------------------------------- ROS fixtures
# One implementation of the launch-free harness (test/harness/); imported lazily, so rclpy is
# loaded only by the tests that use it, after the environment above is set.
import pytest  # noqa: E402


@pytest.fixture
def ros_world():
    """A `harness.ros.RosWorld`: a private Context, a SingleThreadedExecutor, `make_node`,
    `spin_until(condition, timeout, what)`, `spin_for`, `drain`, `remove`; closed after the
    test."""
    from harness.ros import RosWorld

    with RosWorld() as world:
        yield world


@pytest.fixture
def make_ros_world():
    """`make_ros_world(ns=, args=, domain_id=, executor="single"|"events")`: as many RosWorlds
    as a test needs (own ROS arguments, another domain), all closed after it, newest first."""
    from harness.ros import RosWorld

    made = []

    def make(**kwargs):
        made.append(RosWorld(**kwargs))
        return made[-1]

    try:
        yield make
    finally:
        for world in reversed(made):
            world.close()


@pytest.fixture
def ros():
    """A `harness.squeak.SqueakWorld` (probe on every output, `start(**params)` the
    predictor); the test fails if any output carried a non-finite number."""
    from harness.squeak import SqueakWorld

    with SqueakWorld() as world:
        yield world
        assert not world.violations, world.violations[:10]


@pytest.fixture
def ns():
    """A topic namespace of this test alone."""
    from harness.ros import unique_ns

    return unique_ns()
