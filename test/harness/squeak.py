# SPDX-License-Identifier: Apache-2.0
"""The squeak_predictor node's world: a probe in a unique namespace subscribed to every output
(checked for non-finite numbers as it arrives), publishers for the inputs, and optionally the
predictor itself, all on the node's own executor (`make_executor`)."""

from __future__ import annotations

import math

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray

from leadscrew_ros.bag.messages import modes_payload
from leadscrew_ros.live.settings import LiveSettings
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.ros.node import SqueakPredictorNode

from .ros import COLLECT, RosWorld

# Table 1, default scatter: nominal squeak band ~0.81..55.2 rad/s at 200 N; P(squeak) 0.997 at
# 20 rad/s, 0 at 100 rad/s
MODEL = SqueakModel()
LOAD, SQUEAK, STABLE = 200.0, 20.0, 100.0
SAFE = LiveSettings().safe_probability
OUTPUTS = {
    "squeak/risk": Float64,
    "squeak/margin": Float64,
    "squeak/unstable_frequencies": Float64MultiArray,
    "squeak/active": Bool,
    "squeak/modes": Float64MultiArray,
    "squeak/safe_speed": Float64,
    "/diagnostics": DiagnosticArray,
}
INPUTS = {
    "motor_speed": Float64,
    "axial_load": Float64,
    "nut_position": Float64,
    "joint_states": JointState,
}


def non_finite(msg) -> list[str]:
    """Numbers in an output message that are NaN or infinite (squeak/margin is +inf without an
    oscillatory mode, never in these tests)."""
    if isinstance(msg, Float64):
        values = [msg.data]
    elif isinstance(msg, Float64MultiArray):
        values = list(msg.data)
    elif isinstance(msg, DiagnosticArray):
        values = []
        for s in msg.status:
            for kv in s.values:
                for token in kv.value.split(","):
                    try:
                        values.append(float(token))
                    except ValueError:
                        pass
    else:
        values = []
    return [f"{type(msg).__name__}: {v}" for v in values if not math.isfinite(v)]


class SqueakWorld(RosWorld):
    """One test's ROS world: a private context, a probe node (and optionally the predictor)
    in a unique namespace, and the node's executor for both."""

    def __init__(self, ns: str | None = None, **kwargs):
        super().__init__(ns=ns, executor="events", **kwargs)
        self.hardware_id = f"hw_{self.ns[2:]}"
        self.probe = self.make_node("probe")
        self.node: SqueakPredictorNode | None = None  # the predictor, once started
        self.latest: dict[str, object] = {}
        self.count = dict.fromkeys(OUTPUTS, 0)
        self.violations: list[str] = []
        self.pubs = {}
        for topic, msg_type in OUTPUTS.items():
            self.probe.create_subscription(
                msg_type, topic, lambda msg, t=topic: self._received(t, msg), COLLECT
            )

    def _received(self, topic: str, msg) -> None:
        if topic == "/diagnostics":  # absolute topic: keep this test's status only
            status = [s for s in msg.status if s.hardware_id == self.hardware_id]
            if not status:
                return
            msg.status = status
        self.violations += non_finite(msg)
        self.latest[topic] = msg
        self.count[topic] += 1

    def describe(self) -> str:
        return f"; latest outputs: {self.latest}"

    def start(self, autostart: bool = True, **params) -> SqueakPredictorNode:
        """The predictor in this test's namespace, with parameter overrides (`autostart`
        False: unconfigured, for lifecycle transitions)."""
        overrides = [
            Parameter(k, value=v) for k, v in {"hardware_id": self.hardware_id, **params}.items()
        ]
        self.node = self.add(
            SqueakPredictorNode(
                autostart, context=self.ctx, namespace=self.ns, parameter_overrides=overrides
            )
        )
        return self.node

    def remove(self, node) -> None:
        super().remove(node)
        if node is self.node:
            self.node = None

    def publisher(self, topic: str, timeout: float = 10.0):
        if topic not in self.pubs:
            pub = self.probe.create_publisher(INPUTS[topic], topic, 10)
            self.wait_matched(pub, timeout)
            self.pubs[topic] = pub
        return self.pubs[topic]

    def send(self, topic: str, value) -> None:
        msg = value if isinstance(value, JointState) else Float64(data=float(value))
        self.publisher(topic).publish(msg)

    def wait_for(self, topic: str, predicate, timeout: float = 10.0):
        """The latest message on an output topic, once it satisfies `predicate`."""
        self.spin_until(
            lambda: topic in self.latest and predicate(self.latest[topic]),
            timeout,
            f"a matching message on {topic}",
        )
        return self.latest[topic]

    def status(self, predicate, timeout: float = 10.0) -> DiagnosticStatus:
        return self.wait_for("/diagnostics", lambda m: predicate(m.status[0]), timeout).status[0]


def modes_data(p) -> list[float]:
    """The values of the squeak/modes message of a prediction."""
    return list(deserialize_message(modes_payload(p), Float64MultiArray).data)


def at(ros: SqueakWorld, speed: float, load: float = LOAD, model: SqueakModel = MODEL):
    """Send an operating point and wait for the prediction published for it (its modes: the
    probability alone is the same at many points)."""
    core = model.predict(speed, load)
    ros.send("motor_speed", speed)
    ros.send("axial_load", load)
    ros.wait_for(
        "squeak/modes", lambda m: list(m.data) == pytest.approx(modes_data(core), rel=1e-9)
    )
    ros.wait_for("squeak/risk", lambda m: m.data == core.probability)
    ros.wait_for("squeak/margin", lambda m: m.data == pytest.approx(core.margin, rel=1e-9))
    # safe-speed advice comes from a background search: wait for it to be published too
    live = ros.node.live
    ros.spin_until(lambda: not live.advice_pending, 30.0, "safe-speed advice")
    ros.wait_for("squeak/safe_speed", lambda m: m.data == live.safe_speed_rad_s)
    return core


def recording_status(ros: SqueakWorld, predicate, timeout: float = 3.0):
    """The latest 'recording' diagnostic of this test's node, once it satisfies predicate."""
    found = []

    def check():
        msg = ros.latest.get("/diagnostics")
        found[:] = [s for s in (msg.status if msg else []) if s.name.endswith(": recording")]
        return bool(found) and predicate(found[0])

    ros.spin_until(check, timeout, "a matching recording diagnostic")
    return found[0]
