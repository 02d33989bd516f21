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
# pytest-xdist workers (scripts/run-tests.sh: -n 3) inherit the session's domain: each takes
# its own, 100 apart modulo 230 (Fast DDS allows 0..232): distinct for any three.
_worker = os.environ.get("PYTEST_XDIST_WORKER", "")
if _worker.startswith("gw"):
    _base = int(os.environ["ROS_DOMAIN_ID"]) - 1
    os.environ["ROS_DOMAIN_ID"] = str((_base + 100 * int(_worker[2:])) % 230 + 1)
if "ROS_LOG_DIR" not in os.environ:
    _log_dir = tempfile.mkdtemp(prefix="leadscrew_ros_test_log_")
    atexit.register(shutil.rmtree, _log_dir, ignore_errors=True)
    os.environ["ROS_LOG_DIR"] = _log_dir
os.environ.setdefault("MPLBACKEND", "Agg")

# ----------------------------------------------------------------------------- hangs
# pytest-timeout (setup.cfg: timeout, signal method) fails a hung test by name and goes on, but
# its SIGALRM handler only runs when the main thread returns to Python. A test stuck in C (the
# Fast DDS teardown deadlock of the shared notes) gets this watchdog instead: name, all stacks,
# and the session ends, rather than the outer `timeout` of scripts/run-tests.sh much later.
import faulthandler  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402

import pytest  # noqa: E402

WATCHDOG_GRACE_S = 60.0


def _hung(item, after_s: float) -> None:
    """From the watchdog's thread: output capture off (as pytest-timeout's thread method
    does), the test's name, every thread's stack, exit status 3."""
    try:
        capman = item.config.pluginmanager.getplugin("capturemanager")
        if capman is not None:
            capman.suspend_global_capture(item)
        terminal = item.config.get_terminal_writer()
        terminal.sep("+", f"HUNG: {item.nodeid} still running after {after_s:.0f} s")
        terminal.line(
            "its timeout could not interrupt it (stuck in C?); stacks follow, ending the session"
        )
        terminal.flush()
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
    finally:
        sys.stderr.flush()
        os._exit(3)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    limit = getattr(item.config, "_env_timeout", None)  # set by pytest-timeout
    marker = item.get_closest_marker("timeout")
    if marker is not None:
        limit = marker.kwargs.get("timeout", marker.args[0] if marker.args else limit)
    timer = None
    if limit:
        after = float(limit) + WATCHDOG_GRACE_S
        timer = threading.Timer(after, _hung, args=(item, after))
        timer.daemon = True
        timer.start()
    try:
        yield
    finally:
        if timer is not None:
            timer.cancel()


# ----------------------------------------------------------------------------- session deadline
# The suite ends itself on a slow machine, with its summary (harness/session_deadline.py).
from harness.session_deadline import (  # noqa: E402, F401  # hooks, found by name
    pytest_collection_finish,
    pytest_configure,
    pytest_runtest_logfinish,
    pytest_runtest_logreport,
    pytest_sessionstart,
    pytest_terminal_summary,
    pytest_xdist_node_collection_finished,
)

# ----------------------------------------------------------------------------- ROS fixtures
# One implementation of the launch-free harness (test/harness/); imported lazily, so rclpy is
# loaded only by the tests that use it, after the environment above is set.


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


# ----------------------------------------------------------------------------- order
# The modules that take minutes (fixtures that calibrate fleets, run every command, build
# venvs), longest first (--durations on a loaded 2-core machine): pytest-xdist hands out whole
# files in collection order (scripts/run-tests.sh: --dist loadfile --no-loadscope-reorder), so
# that none of them starts late and ends the run alone. The order of the rest is kept.
LONG_MODULES = (
    "test_calibrate.py",
    "test_calibration_sampling.py",
    "test_heard.py",
    "test_fleet.py",
    "test_pictures.py",
    "test_demo.py",
    "test_probability.py",
    "test_recording.py",
    "test_node.py",
    "test_replay.py",
    "test_offline_install.py",
)


def pytest_collection_modifyitems(items):
    def rank(item) -> int:
        name = item.path.name
        return LONG_MODULES.index(name) if name in LONG_MODULES else len(LONG_MODULES)

    items.sort(key=rank)  # stable
