# SPDX-License-Identifier: Apache-2.0
"""The /diagnostics updater (diagnostic_updater's shape) in-process: period, force_update,
task order, hardware id and names; the recording status it publishes for the node.

Each test has its own rclpy Context and namespace (harness.ros.RosWorld); time is a
fake clock, so the period is tested without sleeping.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message

from harness.ros import COLLECT, RosWorld
from harness.squeak import SQUEAK, at
from leadscrew_ros.live.status import Level, Status
from leadscrew_ros.ros.diagnostics import (
    KEY_ACTIVE,
    KEY_BAG,
    KEY_CUT_OFF_BAGS,
    KEY_FILE,
    KEY_FILES,
    KEY_LOST,
    KEY_MESSAGES,
    PREDICTION_TASK,
    RECORDING_TASK,
    RESUME_HINT,
    TOPIC,
    DiagnosticStatusWrapper,
    Updater,
    key_dds_rejected_on,
    key_lost_on,
    recording_status,
    status_task,
)
from leadscrew_ros.ros.node import LATCHED, NODE_NAME


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class World(RosWorld):
    """A node with an Updater and a probe that collects this test's /diagnostics."""

    def __init__(self):
        super().__init__(executor="events")  # the squeak_predictor node's executor
        self.hardware_id = f"hw_{self.ns[2:]}"
        self.node = self.make_node("watched")
        self.probe = self.make_node("probe")
        self.received: list[DiagnosticArray] = []
        self.probe.create_subscription(DiagnosticArray, TOPIC, self._on, COLLECT)
        self.clock = FakeClock()
        self.seen: list[tuple[str, bytes, int]] = []  # topic, CDR payload, stamp [ns]
        self.updater = Updater(
            self.node,
            LATCHED,
            period_s=1.0,
            hardware_id=self.hardware_id,
            clock=self.clock,
            publish=self._publish,
        )
        self.wait_matched(self.updater.publisher)

    def _publish(self, publisher, data: bytes, stamp_ns: int) -> None:
        self.seen.append((publisher.topic_name, data, stamp_ns))
        publisher.publish(data)

    def _on(self, msg: DiagnosticArray) -> None:
        if any(s.hardware_id == self.hardware_id for s in msg.status):
            self.received.append(msg)

    def arrived(self, n: int) -> list[DiagnosticArray]:
        """Wait for n arrays in all, then check that no more come."""
        self.spin_until(lambda: len(self.received) >= n, what=f"{n} diagnostic arrays")
        self.drain()
        assert len(self.received) == n
        return self.received


@pytest.fixture
def world():
    with World() as w:
        yield w


def level(status) -> Level:
    return Level(status.level[0])


def test_tasks_fill_named_statuses_in_order_with_the_hardware_id(world):
    calls = []

    def first(stat):
        calls.append("first")
        stat.summary(Level.WARN, "first says")
        stat.add("count", 3)
        return stat

    def second(stat):
        calls.append("second")
        stat.summary(Level.OK, "second says")
        return stat

    world.updater.add("alpha task", first)
    world.updater.add("beta task", second)
    world.updater.force_update()
    [msg] = world.arrived(1)
    assert calls == ["first", "second"]
    fqn = f"{world.ns}/watched"
    assert [s.name for s in msg.status] == [f"{fqn}: alpha task", f"{fqn}: beta task"]
    assert {s.hardware_id for s in msg.status} == {world.hardware_id}
    assert [(level(s), s.message) for s in msg.status] == [
        (Level.WARN, "first says"),
        (Level.OK, "second says"),
    ]
    assert [(kv.key, kv.value) for kv in msg.status[0].values] == [("count", "3")]
    assert msg.header.stamp.sec > 0
    [(topic, data, stamp_ns)] = world.seen
    assert topic == TOPIC and deserialize_message(data, DiagnosticArray) == msg
    assert stamp_ns == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def test_update_publishes_once_per_period(world):
    world.updater.add("t", lambda stat: stat)
    assert world.updater.update()  # nothing published yet: due at once
    assert not world.updater.update()  # same instant
    world.clock.t += 0.999
    assert not world.updater.update()
    world.clock.t += 0.001
    assert world.updater.update()
    world.updater.period_s = 5.0  # a new period applies from now on
    world.clock.t += 4.0
    assert not world.updater.update()
    world.clock.t += 1.0
    assert world.updater.update()
    world.arrived(3)
    assert world.updater.published == 3


def test_force_update_publishes_now_and_restarts_the_period(world):
    world.updater.add("t", lambda stat: stat)
    assert world.updater.update()
    world.clock.t += 0.5
    world.updater.force_update()  # e.g. the verdict changed
    world.clock.t += 0.9
    assert not world.updater.update()  # the period counts from the forced one
    world.clock.t += 0.1
    assert world.updater.update()
    world.arrived(3)


def test_status_task_reports_a_status():
    status = Status(Level.STALE, "no fresh input", {"a": "1", "b": ""})
    stat = status_task(lambda: status)(DiagnosticStatusWrapper("n", "hw"))
    assert stat.to_data() == (
        int(Level.STALE),
        "n",
        "no fresh input",
        "hw",
        (("a", "1"), ("b", "")),
    )


def test_merge_summary_keeps_the_worst_level_and_every_message():
    stat = DiagnosticStatusWrapper()
    stat.summary(Level.WARN, "one")
    stat.merge_summary(Level.OK, "two")
    assert (stat.level, stat.message) == (Level.WARN, "one; two")
    stat.merge_summary(Level.ERROR, "three")
    assert (stat.level, stat.message) == (Level.ERROR, "one; two; three")


def recorder(**changes):
    r = dict(
        error="",
        incident="",
        active=False,
        path=None,
        bag=None,
        files=[],
        messages=0,
        lost=0,
        losses={},
    )
    return SimpleNamespace(**{**r, **changes})


NO_CRASH = SimpleNamespace(message="", level=Level.OK, pending=[])


@pytest.mark.parametrize(
    "rec, crash, expected_level, words",
    [
        (recorder(), NO_CRASH, Level.OK, "not recording"),
        (
            recorder(active=True, path="/d/b_0.mcap", bag="/d/b"),
            NO_CRASH,
            Level.OK,
            "recording to /d/b_0.mcap",
        ),
        (recorder(error="disk full"), NO_CRASH, Level.ERROR, f"disk full; {RESUME_HINT}"),
        (
            recorder(active=True, path="/d/b_1.mcap", incident="/d/b_0.mcap was deleted"),
            NO_CRASH,
            Level.ERROR,
            "recording to /d/b_1.mcap; /d/b_0.mcap was deleted",
        ),
        (
            recorder(
                active=True,
                path="p",
                lost=3,
                losses={
                    "/a": SimpleNamespace(lost=3, dds_rejected=""),
                    "/b": SimpleNamespace(lost=0, dds_rejected="total_count -1: negative"),
                },
            ),
            NO_CRASH,
            Level.WARN,
            "recording to p; 3 input message(s) lost before recording (/a 3)",
        ),
        (
            recorder(error="disk full"),
            SimpleNamespace(message="1 bag(s) cut off", level=Level.WARN, pending=["/d/x", "/d/y"]),
            Level.ERROR,
            f"disk full; {RESUME_HINT}; 1 bag(s) cut off",
        ),
    ],
)
def test_recording_status(rec, crash, expected_level, words):
    stat = recording_status(DiagnosticStatusWrapper(), rec, crash)
    assert stat.level == expected_level and stat.message == words
    keys = [KEY_BAG, KEY_FILES, KEY_MESSAGES, KEY_LOST, KEY_ACTIVE, KEY_FILE]
    assert list(stat.values)[:6] == keys
    assert stat.values[KEY_ACTIVE] == str(rec.active).lower()
    assert stat.values[KEY_FILE] == (rec.path or "")
    assert stat.values[KEY_LOST] == str(rec.lost)
    for topic, loss in rec.losses.items():
        assert stat.values[key_lost_on(topic)] == str(loss.lost)
        assert stat.values.get(key_dds_rejected_on(topic)) == (loss.dds_rejected or None)
    assert stat.values.get(KEY_CUT_OFF_BAGS) == (" ".join(crash.pending) if crash.message else None)


def test_the_node_forces_diagnostics_on_a_change_of_verdict_only(ros):
    """With a period of a minute, a new verdict is published at once and nothing else."""
    node = ros.start(diagnostics_period_s=60.0, stale_timeout_s=3600.0)
    assert node.diagnostics.period_s == 60.0
    first = ros.status(lambda s: True)
    assert [s.name for s in ros.latest["/diagnostics"].status] == [
        f"{ros.ns}/{NODE_NAME}: {PREDICTION_TASK}",
        f"{ros.ns}/{NODE_NAME}: {RECORDING_TASK}",
    ]
    assert level(first) == Level.STALE
    at(ros, SQUEAK)  # a squeak verdict, well within a period
    assert level(ros.status(lambda s: s.message.startswith("squeak predicted"))) == Level.ERROR
    ros.drain()
    published = node.diagnostics.published
    assert ros.count["/diagnostics"] == published
    for _ in range(3):  # the same point again: the same verdict
        ros.send("motor_speed", SQUEAK)
        ros.drain()
    deadline = time.monotonic() + 0.5  # ten housekeeping periods
    while time.monotonic() < deadline:
        ros.executor.spin_once(timeout_sec=0.01)
    assert node.diagnostics.published == published == ros.count["/diagnostics"]
    [result] = node.set_parameters([Parameter("diagnostics_period_s", value=0.05)])
    assert result.successful and node.diagnostics.period_s == 0.05
    ros.spin_until(lambda: ros.count["/diagnostics"] >= published + 3, what="periodic updates")
