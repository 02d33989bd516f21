# SPDX-License-Identifier: Apache-2.0
"""One test's ROS world for the squeak_guard node: a probe in a unique namespace that publishes
the guard's inputs and collects every guarded command, guard/active, guard/reason and this
test's /diagnostics status, on the node's executor."""

from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, Float64, String

from leadscrew_ros.ros.guard_node import (
    ACTIVE,
    COMMAND,
    GUARDED,
    LOAD,
    NUT,
    REASON,
    SqueakGuardNode,
)

from .ros import COLLECT, RosWorld

OUTPUTS = {GUARDED: Float64, ACTIVE: Bool, REASON: String, "/diagnostics": DiagnosticArray}
# every guarded command (published volatile: a transient-local reader would not match)
COMMANDS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class GuardWorld(RosWorld):
    """A private context, a probe node and (`start`) the guard node in a unique namespace."""

    def __init__(self, ns: str | None = None, executor: str = "events", **kwargs):
        super().__init__(ns=ns, executor=executor, **kwargs)
        self.hardware_id = f"hw_{self.ns[2:]}"
        self.probe = self.make_node("probe")
        self.node: SqueakGuardNode | None = None
        self.received: dict[str, list] = {topic: [] for topic in OUTPUTS}
        self.pubs = {}
        for topic, msg_type in OUTPUTS.items():
            self.probe.create_subscription(
                msg_type,
                topic,
                lambda msg, t=topic: self._received(t, msg),
                COMMANDS if topic == GUARDED else COLLECT,
            )

    def _received(self, topic: str, msg) -> None:
        if topic == "/diagnostics":  # absolute topic: keep this test's status only
            status = [s for s in msg.status if s.hardware_id == self.hardware_id]
            if not status:
                return
            msg = status[0]
        self.received[topic].append(msg)

    def start(self, autostart: bool = True, **params) -> SqueakGuardNode:
        """The guard in this test's namespace, with parameter overrides."""
        overrides = [
            Parameter(k, value=v) for k, v in {"hardware_id": self.hardware_id, **params}.items()
        ]
        self.node = self.add(
            SqueakGuardNode(
                autostart=autostart,
                context=self.ctx,
                namespace=self.ns,
                parameter_overrides=overrides,
            )
        )
        return self.node

    def send(self, topic: str, value: float) -> None:
        """Publish a Float64 on an input topic (waits for the guard's subscription first)."""
        if topic not in self.pubs:
            pub = self.probe.create_publisher(Float64, topic, 10)
            self.wait_matched(pub)
            self.pubs[topic] = pub
        self.pubs[topic].publish(Float64(data=float(value)))

    def step(self, command: float, load: float | None = None, nut: float | None = None) -> None:
        """Load and nut (when given), then the command; spins until the guard has taken it."""
        assert self.node is not None
        for topic, value in ((LOAD, load), (NUT, nut)):
            if value is not None:  # taken before the command (topics are not ordered)
                self.send(topic, value)
                self.spin_until(lambda t=topic, v=value: self._taken(t, v), what=f"{topic}")
        before = len(self.received[GUARDED])
        self.send(COMMAND, command)
        self.spin_until(lambda: len(self.received[GUARDED]) > before, what=f"{GUARDED}")

    def _taken(self, topic: str, value: float) -> bool:
        got = self.node._inputs.get(topic) if self.node else None
        return got is not None and (got[0] == value or (math.isnan(value) and math.isnan(got[0])))

    def last(self, topic: str):
        return self.received[topic][-1] if self.received[topic] else None

    def status(self, predicate, timeout: float = 10.0) -> DiagnosticStatus:
        """The latest /diagnostics status of this test's guard, once it satisfies
        `predicate`."""
        self.spin_until(
            lambda: (
                bool(self.received["/diagnostics"]) and predicate(self.received["/diagnostics"][-1])
            ),
            timeout,
            "a matching /diagnostics status",
        )
        return self.received["/diagnostics"][-1]

    def describe(self) -> str:
        node = self.node
        return f"; last step {node.last if node else None}, diagnostics " + str(
            [(s.level, s.message) for s in self.received["/diagnostics"][-3:]]
        )
