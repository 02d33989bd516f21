# SPDX-License-Identifier: Apache-2.0
"""The predictor's output messages (`leadscrew_ros.bag.messages`): byte for byte the rclpy
messages of the documented layout, squeak/modes decoded back, malformed layouts refused; the
demo's monitor decodes them; model/, live/, bag/ and review/ import and encode the outputs
with their schemas without any ROS package."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from std_msgs.msg import Bool, Float64, Float64MultiArray, MultiArrayDimension

from harness.blocker import BLOCKER
from harness.cdr_reference import cdr_payload
from leadscrew_ros.bag import cdr, messages
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.ros.demo import SqueakMonitor

MODEL = SqueakModel()
SQUEAK, STABLE, LOAD = 20.0, 100.0, 200.0


def reference_messages(p) -> dict[str, object]:
    """The outputs of a prediction built as rclpy messages by hand from the documented layout."""
    freqs = Float64MultiArray(data=list(p.unstable_frequencies_hz))
    n = len(freqs.data)
    freqs.layout.dim = [MultiArrayDimension(label="frequency_hz", size=n, stride=n)]
    modes = Float64MultiArray(
        data=[v for m in p.modes for v in (m.frequency_hz, m.growth_rate, m.damping_ratio)]
    )
    rows = len(p.modes)
    modes.layout.dim = [
        MultiArrayDimension(
            label="modes:" + ",".join(m.label for m in p.modes), size=rows, stride=3 * rows
        ),
        MultiArrayDimension(label="frequency_hz,growth_rate,damping_ratio", size=3, stride=3),
    ]
    margin = math.inf if p.margin is None else p.margin
    return {
        messages.RISK: Float64(data=p.probability),
        messages.MARGIN: Float64(data=margin),
        messages.FREQUENCIES: freqs,
        messages.ACTIVE: Bool(data=not p.stable),
        messages.MODES: modes,
    }


@pytest.mark.parametrize("speed", [SQUEAK, STABLE])
def test_prediction_payloads_are_the_rclpy_messages_of_the_layout(speed):
    p = MODEL.predict(speed, LOAD)
    payloads = messages.prediction_payloads(p)
    risk, margin = (
        cdr.decode_float64(data) for t, data in payloads if t in (messages.RISK, messages.MARGIN)
    )
    assert (risk, margin) == (p.probability, p.margin)  # P(squeak); least damping ratio
    assert (margin < 0) == (not p.stable)
    assert [t for t, _ in payloads] == list(messages.PREDICTION_TOPICS)
    want = reference_messages(p)
    for topic, data in payloads:
        assert data == cdr_payload(want[topic]), topic
    assert messages.safe_speed_payload(12.5) == cdr_payload(Float64(data=12.5))


def test_modes_decode_back():
    p = MODEL.predict(SQUEAK, LOAD)
    modes = messages.decode_modes(messages.modes_payload(p))
    assert modes == tuple(
        (m.label, m.frequency_hz, m.growth_rate, m.damping_ratio) for m in p.modes
    )
    assert any(m.growth_rate > 0 for m in modes)
    empty = MODEL.predict(0.0, 0.0)  # outside validity: no modes
    assert messages.decode_modes(messages.modes_payload(empty)) == ()


COLUMNS = cdr.Dimension("frequency_hz,growth_rate,damping_ratio", 3, 3)


@pytest.mark.parametrize(
    "dims, data, offset, problem",
    [
        ((), [], 0, "not a squeak/modes layout"),
        ((cdr.Dimension("rows:a", 1, 3), COLUMNS), [1.0, 2.0, 3.0], 0, "not a squeak/modes"),
        (
            (
                cdr.Dimension("modes:a", 1, 3),
                cdr.Dimension("frequency_hz,damping_ratio,growth_rate", 3, 3),
            ),
            [1.0, 2.0, 3.0],
            0,
            "columns",
        ),
        ((cdr.Dimension("modes:a", 1, 3), COLUMNS), [1.0, 2.0], 0, "2 values"),
        ((cdr.Dimension("modes:a,b", 1, 3), COLUMNS), [1.0, 2.0, 3.0], 0, "2 labels"),
        ((cdr.Dimension("modes:a", 1, 3), COLUMNS), [1.0, 2.0, 3.0], 1, "offset 1"),
    ],
)
def test_malformed_modes_raise_value_error(dims, data, offset, problem):
    with pytest.raises(ValueError, match=problem):
        messages.decode_modes(cdr.encode_float64_multi_array(dims, data, offset))


def test_the_monitor_decodes_the_outputs_and_counts_what_does_not_decode(ros_world):
    monitor = ros_world.add(SqueakMonitor(context=ros_world.ctx))
    p = MODEL.predict(SQUEAK, LOAD)
    handlers = {
        messages.RISK: monitor._on_risk,
        messages.MARGIN: monitor._on_margin,
        messages.FREQUENCIES: monitor._on_frequencies,
        messages.ACTIVE: monitor._on_active,
        messages.MODES: monitor._on_modes,
    }
    for topic, data in messages.prediction_payloads(p):
        monitor._decoding(handlers[topic])(data)
    monitor._decoding(monitor._on_safe_speed)(messages.safe_speed_payload(3.0))
    r = monitor.record
    assert (r.predictions, r.probability, r.max_probability, r.active, r.safe_speed) == (
        1,
        p.probability,
        p.probability,
        True,
        3.0,
    )
    assert r.margin == r.min_margin == p.margin < 0
    assert r.frequencies == list(p.unstable_frequencies_hz)
    assert r.squeak_modes == [(m.label, m.frequency_hz) for m in p.modes if m.growth_rate > 0] != []
    for handler in handlers.values():
        monitor._decoding(handler)(b"\x00\x01\x00\x00\x07")
    assert r.malformed == 5 and r.predictions == 1


def test_outputs_encode_without_any_ros_package():
    """The layers' import check is test_layers.py; here the payloads and their schemas are
    made with every ROS package blocked."""
    blocker = BLOCKER + (
        "from leadscrew_ros.bag import messages, msgdefs\n"
        "from leadscrew_ros.model import SqueakModel\n"
        "assert all(msgdefs.definition(t) for t in messages.OUTPUT_TYPES.values())\n"
        "assert messages.prediction_payloads(SqueakModel().predict(20.0, 200.0))\n"
        "print('ok')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", blocker], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
