# SPDX-License-Identifier: Apache-2.0
"""A recording squeak_node process and the feed it answers (crash and recovery tests)."""

from __future__ import annotations

import contextlib
import os
import subprocess
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from .processes import node_command, stop, wait_initialised
from .ros import COLLECT, RosWorld
from .squeak import LOAD, SQUEAK


def start_recording_node(
    tmp_path: Path, ns: str, extra: list[str] = (), preexec_fn=None
) -> tuple[subprocess.Popen, Path]:
    directory = tmp_path / "bags"
    directory.mkdir()
    err = open(tmp_path / "node.stderr", "w+")
    proc = subprocess.Popen(
        [
            *node_command(),
            "--ros-args",
            "-r",
            f"__ns:={ns}",
            "-p",
            f"hardware_id:=hw_{ns[2:]}",
            "-p",
            "record.enabled:=true",
            "-p",
            f"record.directory:={directory}",
            *extra,
        ],
        stdout=subprocess.DEVNULL,
        stderr=err,
        env=dict(os.environ),
        preexec_fn=preexec_fn,
    )
    proc.files = [err, err]  # `output(proc)`: the node writes to stderr only
    return proc, directory


class Feed:
    """Probe side of a node process: publishes inputs, collects risk and recording status."""

    def __init__(self, ns: str):
        self.ros = RosWorld(ns=ns, executor="events")
        self.node = self.ros.make_node("feed")
        self.risk, self.recording = [], []
        self.recording_stamps_ns: list[int] = []  # the node's clock when it sent each status
        self.node.create_subscription(Float64, "squeak/risk", self.risk.append, COLLECT)

        def collect(m: DiagnosticArray) -> None:
            for s in m.status:
                if s.hardware_id == f"hw_{ns[2:]}" and s.name.endswith(": recording"):
                    self.recording.append(s)
                    self.recording_stamps_ns.append(
                        m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
                    )

        self.node.create_subscription(DiagnosticArray, "/diagnostics", collect, COLLECT)
        self.pubs = [
            self.node.create_publisher(type_, topic, 10)
            for type_, topic in (
                (Float64, "motor_speed"),
                (Float64, "axial_load"),
                (JointState, "joint_states"),
            )
        ]
        for pub in self.pubs:
            self.ros.wait_matched(pub)
        self.sent = 0

    def send(self, i: int, joints: int = 1) -> None:
        self.pubs[0].publish(Float64(data=SQUEAK + i % 20))
        self.pubs[1].publish(Float64(data=LOAD))
        if joints > 1:
            self.pubs[2].publish(
                JointState(name=[f"joint_{k:04d}" for k in range(joints)], position=[0.0] * joints)
            )
        self.sent += 1
        self.ros.executor.spin_once(timeout_sec=0.0)

    def run(self, seconds: float, rate_hz: float = 200.0, **kw) -> None:
        t0 = time.monotonic()
        k = 0
        while (now := time.monotonic()) < t0 + seconds:
            if now >= t0 + k / rate_hz:
                self.send(k, **kw)
                k += 1
            self.ros.executor.spin_once(timeout_sec=0.001)

    def close(self) -> None:
        self.ros.close()


@contextlib.contextmanager
def answering_node(tmp_path: Path, ns: str, extra: list[str] = (), preexec_fn=None):
    """A recording node process and a Feed it already answers; both cleaned up on exit."""
    proc, directory = start_recording_node(tmp_path, ns, extra, preexec_fn)
    feed = None
    try:
        wait_initialised([proc])
        feed = Feed(ns)
        deadline = time.monotonic() + 10
        while not feed.risk:
            assert time.monotonic() < deadline, "no answer from the node process"
            feed.run(0.05)
        yield proc, directory, feed
    finally:
        stop(proc)
        if feed is not None:
            feed.close()
