# SPDX-License-Identifier: Apache-2.0
"""The squeak_guard managed node over loopback DDS, launch-free: pass-through, steering around
a band, exact pass-through when disabled, every lifecycle transition and its effect, and the
fail-safe (stale and missing inputs, NaN, model error, deadline missed) with its diagnostic.

Each test has its own Context, namespace and executor (`harness.guard.GuardWorld`); waits are
generous and nothing asserts on timing. Where the guard must find a band, a quiet command of
the same bin (load, nut, direction) first lets its band thread compute the bin, and
`guard.max_delay_s` is long, so that no deadline depends on the machine's speed.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
import time

import pytest
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from harness.guard import GuardWorld
from leadscrew_ros.live import guard as live_guard
from leadscrew_ros.live.guard import GuardBands
from leadscrew_ros.live.recompute import band_bin
from leadscrew_ros.live.status import Level
from leadscrew_ros.model import ParameterError
from leadscrew_ros.ros.guard_node import ACTIVE, COMMAND, GUARDED, REASON, usage

LOAD, NUT = 200.0, 0.1  # a band 0.58-62 rad/s at the defaults
QUIET, IN_BAND = 80.0, 0.8  # rad/s


@pytest.fixture
def guard():
    with GuardWorld() as world:
        yield world


def banded(world: GuardWorld, **params):
    """The guard started, its band of (LOAD, NUT, +) computed through quiet commands."""
    node = world.start(**{"guard.max_delay_s": 600.0, **params})
    key = band_bin(LOAD, NUT, QUIET)
    world.step(QUIET, LOAD, NUT)
    world.spin_until(lambda: key in node.policy.bands, 60.0, "the band thread's bin")
    return node


def test_passes_the_command_through_where_quiet(guard):
    node = banded(guard)
    assert node.policy.bands[band_bin(LOAD, NUT, QUIET)].intervals  # a band exists here
    held = 0
    for _ in range(2000):  # the tracker reaches the command from rest, then holds it
        guard.step(QUIET, LOAD, NUT)
        held = held + 1 if guard.last(GUARDED).data == QUIET else 0
        if held == 10:
            break
    assert held == 10, guard.received[GUARDED][-10:]
    assert node.last.reason == "" and not node.last.active and not node.last.fault
    status = guard.status(lambda s: "guarding" in s.message)
    assert status.level == bytes([Level.OK]), status


def test_steers_around_a_band(guard):
    node = banded(guard)
    lo, hi = node.policy.bands[band_bin(LOAD, NUT, QUIET)].intervals[0]
    assert lo <= IN_BAND <= hi
    guard.step(0.0)  # a stop: from rest
    for _ in range(200):
        guard.step(IN_BAND, LOAD, NUT)
    out = guard.last(GUARDED).data
    safe = lo * (1 - node.policy.settings.margin)
    assert out == pytest.approx(safe, rel=1e-9), out  # held below the band, not 0.8
    guard.spin_until(lambda: guard.last(ACTIVE) is not None and guard.last(ACTIVE).data)
    guard.spin_until(lambda: "squeak band" in (guard.last(REASON) or String0).data)
    status = guard.status(lambda s: "avoided" in s.message)
    assert status.level == bytes([Level.OK])


class String0:  # no guard/reason yet
    data = ""


@pytest.mark.parametrize("value", [IN_BAND, QUIET, -3.25, 0.0, 1e300, math.nan, -math.inf])
def test_disabled_is_an_exact_pass_through(guard, value):
    guard.start(**{"guard.enabled": False})
    guard.step(IN_BAND, LOAD, NUT)
    guard.step(value)  # no inputs needed either
    out = guard.last(GUARDED).data
    assert out == value or (math.isnan(value) and math.isnan(out))
    status = guard.status(lambda s: "disabled" in s.message)
    assert status.level == bytes([Level.OK])


# ----------------------------------------------------------------------------- lifecycle
def change_state(world: GuardWorld, client, transition: int) -> bool:
    future = client.call_async(ChangeState.Request(transition=Transition(id=transition)))
    world.spin_until(future.done, 30.0, f"transition {transition}")
    return future.result().success


def state(world: GuardWorld, client) -> str:
    future = client.call_async(GetState.Request())
    world.spin_until(future.done, 30.0, "get_state")
    return future.result().current_state.label


def test_every_transition_through_the_lifecycle_services(guard):
    node = guard.start(autostart=False)
    name = f"{guard.ns}/squeak_guard"
    change = guard.probe.create_client(ChangeState, f"{name}/change_state")
    get = guard.probe.create_client(GetState, f"{name}/get_state")
    guard.spin_until(lambda: change.service_is_ready() and get.service_is_ready(), 30.0)
    assert state(guard, get) == "unconfigured"
    assert node.policy is None and guard.probe.count_subscribers(f"{guard.ns}/{COMMAND}") == 0

    assert change_state(guard, change, Transition.TRANSITION_CONFIGURE)
    assert state(guard, get) == "inactive"
    assert node.policy is not None and node.worker.alive
    guard.spin_until(lambda: guard.probe.count_subscribers(f"{guard.ns}/{COMMAND}") == 1)
    guard.send(COMMAND, QUIET)  # inactive: nothing comes out
    guard.spin_for(0.5)
    assert guard.received[GUARDED] == [] and guard.received["/diagnostics"] == []

    assert change_state(guard, change, Transition.TRANSITION_ACTIVATE)
    assert state(guard, get) == "active"
    guard.step(QUIET, LOAD, NUT)
    guard.status(lambda s: True)

    assert change_state(guard, change, Transition.TRANSITION_DEACTIVATE)
    assert state(guard, get) == "inactive"
    guard.spin_for(0.3)  # what was published before arrives
    published = {t: len(v) for t, v in guard.received.items()}
    for _ in range(5):
        guard.send(COMMAND, QUIET)
    guard.spin_for(1.0)  # > the diagnostics period: nothing published while inactive
    assert {t: len(v) for t, v in guard.received.items()} == published

    assert change_state(guard, change, Transition.TRANSITION_CLEANUP)
    assert state(guard, get) == "unconfigured"
    assert node.policy is None and node.worker is None
    guard.spin_until(lambda: guard.probe.count_subscribers(f"{guard.ns}/{COMMAND}") == 0)
    assert guard.probe.count_publishers(f"{guard.ns}/{GUARDED}") == 0

    assert change_state(guard, change, Transition.TRANSITION_CONFIGURE)
    assert change_state(guard, change, Transition.TRANSITION_ACTIVATE)
    guard.step(QUIET, LOAD, NUT)  # publishing again after a new configure
    worker = node.worker
    assert change_state(guard, change, Transition.TRANSITION_ACTIVE_SHUTDOWN)
    assert state(guard, get) == "finalized"
    assert not worker.alive and node.policy is None


@pytest.mark.parametrize("start", ["unconfigured", "inactive", "active"])
def test_trigger_shutdown_releases_everything_from_any_state(guard, start):
    node = guard.start(autostart=start == "active")
    if start == "inactive":
        node.trigger_configure()
    worker = node.worker
    node.trigger_shutdown()
    assert node._state_machine.current_state[1] == "finalized"
    assert node.policy is None and (worker is None or not worker.alive)


def test_trigger_deactivate_and_activate(guard):
    node = guard.start()
    guard.step(QUIET, LOAD, NUT)
    node.trigger_deactivate()
    n = len(guard.received[GUARDED])
    guard.send(COMMAND, QUIET)
    guard.spin_for(0.5)
    assert len(guard.received[GUARDED]) == n
    node.trigger_activate()
    guard.step(QUIET, LOAD, NUT)
    assert len(guard.received[GUARDED]) == n + 1


@pytest.mark.parametrize(
    "param, value, words",
    [
        ("guard.p_max", 0.0, "p_max"),
        ("nut_position_m", 0.29, "the nut must lie on the screw"),
    ],
)
def test_a_bad_parameter_fails_configure_with_the_reason(guard, param, value, words):
    node = guard.start(autostart=False, **{param: value})
    assert node.trigger_configure().name == "FAILURE"
    assert node._state_machine.current_state[1] == "unconfigured"
    assert words in node.error and node.policy is None
    with pytest.raises(ParameterError, match=re.escape(words)):  # autostart raises it
        guard.start(**{param: value})


def test_a_bad_set_is_rejected_and_a_good_one_applied(guard):
    node = guard.start()
    [bad] = node.set_parameters([live_param("guard.p_max", 0.0)])
    assert not bad.successful and "p_max" in bad.reason
    [good] = node.set_parameters([live_param("guard.enabled", False)])
    assert good.successful and not node.policy.settings.enabled


def live_param(name, value):
    from rclpy.parameter import Parameter

    return Parameter(name, value=value)


# ----------------------------------------------------------------------------- fail-safe
def assert_fail_safe(guard: GuardWorld, command: float, words: str) -> None:
    """The step passed the command through and /diagnostics says WARN with the reason."""
    node = guard.node
    assert node.last.fault, node.last
    assert node.last.target_rad_s == command or math.isnan(command)
    assert words in node.last.reason and node.last.fault in node._logged
    status = guard.status(lambda s: s.level == bytes([Level.WARN]))
    assert words in status.message and status.message.startswith("fail-safe")


def test_missing_load_passes_through(guard):
    guard.start()
    guard.step(IN_BAND, nut=NUT)
    assert_fail_safe(guard, IN_BAND, "no load or nut position")


def test_stale_load_passes_through(guard):
    node = banded(guard, **{"guard.stale_timeout_s": 0.2})
    guard.send("nut_position", NUT)
    guard.spin_for(1.0)  # the load is older than 0.2 s now (the nut too)
    guard.step(IN_BAND)
    assert_fail_safe(guard, IN_BAND, "older than 0.2 s")
    assert node.last.fault == live_guard.INPUT_STALE


@pytest.mark.parametrize("load", [math.nan, math.inf])
def test_non_finite_load_passes_through(guard, load):
    banded(guard)
    guard.step(IN_BAND, load, NUT)
    assert_fail_safe(guard, IN_BAND, "not finite")


def test_nan_command_keeps_the_last_good_one(guard):
    node = banded(guard)
    guard.step(math.nan, LOAD, NUT)
    assert_fail_safe(guard, math.nan, "not a finite number")
    assert node.last.target_rad_s == QUIET and math.isfinite(guard.last(GUARDED).data)


def test_model_error_passes_through(guard, monkeypatch):
    def fail(cls, model, key, p_max):
        raise RuntimeError("eigensolver exploded")

    monkeypatch.setattr(GuardBands, "compute", classmethod(fail))
    node = guard.start(**{"guard.max_delay_s": 600.0})
    key = band_bin(LOAD, NUT, IN_BAND)
    guard.step(IN_BAND, LOAD, NUT)
    guard.spin_until(lambda: key in node.policy.bands, 60.0, "the failed bin")
    guard.step(IN_BAND, LOAD, NUT)
    assert_fail_safe(guard, IN_BAND, "eigensolver exploded")
    assert node.last.fault == live_guard.MODEL_ERROR


def test_deadline_missed_passes_through(guard):
    node = banded(guard)
    node.policy.clock = lambda: time.monotonic() + 1.0  # every step 1 s late
    guard.step(IN_BAND, LOAD, NUT)
    assert_fail_safe(guard, IN_BAND, "deadline_s")
    assert node.last.fault == live_guard.DEADLINE_MISSED


def test_fail_safe_then_guarding_again_is_ok(guard):
    node = banded(guard)
    guard.step(IN_BAND, math.nan, NUT)
    guard.status(lambda s: s.level == bytes([Level.WARN]))
    guard.step(IN_BAND, LOAD, NUT)
    assert not node.last.fault
    guard.status(lambda s: s.level == bytes([Level.OK]) and "avoided" in s.message)


# ----------------------------------------------------------------------------- executable
def test_help_lists_topics_parameters_and_lifecycle():
    text = usage()
    for word in (COMMAND, GUARDED, ACTIVE, REASON, "guard.p_max", "radius_m", "--no-autostart"):
        assert word in text


def test_executable_with_a_bad_parameter_exits_2_with_one_line(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "leadscrew_ros.ros.guard_node",
            "--ros-args",
            "-p",
            "guard.p_max:=0.0",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("squeak_guard: error:"), proc.stderr
    assert "guard.p_max" in lines[0]
