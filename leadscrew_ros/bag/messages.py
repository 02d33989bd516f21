# SPDX-License-Identifier: Apache-2.0
"""The squeak predictor's output messages, in one place for the node (publishes and records
them), the demo's monitor (decodes them) and the replay (annotates a log with them).

Topics (relative to the predictor's namespace) and types:
squeak/risk (std_msgs/Float64) [1]: P(squeak) over the parameter scatter
(`Prediction.probability`), squeak/margin (std_msgs/Float64) [1]: the least damping ratio of the
oscillatory modes at the nominal parameters (negative when a mode squeaks; +inf without an
oscillatory mode), squeak/unstable_frequencies (std_msgs/Float64MultiArray)
[Hz, most unstable first], squeak/active (std_msgs/Bool), squeak/modes (Float64MultiArray: one
row per oscillatory mode, growth rate descending, columns `MODE_COLUMNS`; the row dimension's
label is 'modes:' followed by the mode labels, comma separated) and squeak/safe_speed
(std_msgs/Float64) [rad/s]; with listening on, squeak/heard (std_msgs/Bool) and
squeak/heard_frequency (std_msgs/Float64) [Hz, 0 while nothing is heard]. Payloads are CDR bytes
(`cdr`), rclpy-free.

The guard's topics (`GUARD_TYPES`, published by `squeak_guard` in the same namespace), which the
predictor records beside its own while anyone publishes them: speed_command (std_msgs/Float64)
[rad/s], the command the guard takes in; speed_command_guarded (std_msgs/Float64) [rad/s],
what it hands on; guard/active (std_msgs/Bool), true while it changes the command; and
guard/reason (std_msgs/String), why.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..model import Prediction
from . import cdr

RISK, MARGIN = "squeak/risk", "squeak/margin"
FREQUENCIES, ACTIVE = "squeak/unstable_frequencies", "squeak/active"
MODES, SAFE_SPEED = "squeak/modes", "squeak/safe_speed"
OUTPUT_TYPES = {
    RISK: cdr.FLOAT64,
    MARGIN: cdr.FLOAT64,
    FREQUENCIES: cdr.FLOAT64_MULTI_ARRAY,
    ACTIVE: cdr.BOOL,
    MODES: cdr.FLOAT64_MULTI_ARRAY,
    SAFE_SPEED: cdr.FLOAT64,
}
PREDICTION_TOPICS = (RISK, MARGIN, FREQUENCIES, ACTIVE, MODES)  # one prediction publishes
# With listening on (`listen.enabled`): what the microphone hears
HEARD, HEARD_FREQUENCY = "squeak/heard", "squeak/heard_frequency"
LISTEN_TYPES = {HEARD: cdr.BOOL, HEARD_FREQUENCY: cdr.FLOAT64}
# The squeak guard (`ros.guard_node`): its command in and out, and why it changed it;
# the predictor records them beside its inputs (they are not inputs of the prediction)
SPEED_COMMAND, SPEED_COMMAND_GUARDED = "speed_command", "speed_command_guarded"
GUARD_ACTIVE, GUARD_REASON = "guard/active", "guard/reason"
GUARD_TYPES = {
    SPEED_COMMAND: cdr.FLOAT64,
    SPEED_COMMAND_GUARDED: cdr.FLOAT64,
    GUARD_ACTIVE: cdr.BOOL,
    GUARD_REASON: "std_msgs/msg/String",  # no codec in `cdr`: recorded as received
}
MODE_COLUMNS = ("frequency_hz", "growth_rate", "damping_ratio")
MODES_PREFIX = "modes:"  # of the row dimension's label
_COLUMNS = len(MODE_COLUMNS)
_COLUMNS_DIMENSION = cdr.Dimension(",".join(MODE_COLUMNS), _COLUMNS, _COLUMNS)


class Mode(NamedTuple):
    """One row of squeak/modes."""

    label: str
    frequency_hz: float
    growth_rate: float  # [1/s], > 0: the mode grows (squeak)
    damping_ratio: float  # [1]


def prediction_payloads(p: Prediction) -> tuple[tuple[str, bytes], ...]:
    """(topic, CDR payload) of every topic in `PREDICTION_TOPICS` for a valid prediction, in
    that order."""
    assert p.probability is not None  # a valid prediction has one
    return (
        (RISK, cdr.encode_float64(float(p.probability))),
        (MARGIN, cdr.encode_float64(math.inf if p.margin is None else float(p.margin))),
        (FREQUENCIES, frequencies_payload(p)),
        (ACTIVE, cdr.encode_bool(not p.stable)),
        (MODES, modes_payload(p)),
    )


def heard_payloads(heard: bool, frequency_hz: float) -> tuple[tuple[str, bytes], ...]:
    """(topic, CDR payload) of squeak/heard and squeak/heard_frequency [Hz] (0 while nothing
    is heard)."""
    return (
        (HEARD, cdr.encode_bool(heard)),
        (HEARD_FREQUENCY, cdr.encode_float64(float(frequency_hz) if heard else 0.0)),
    )


def safe_speed_payload(speed_rad_s: float) -> bytes:
    """squeak/safe_speed [rad/s]."""
    return cdr.encode_float64(float(speed_rad_s))


def frequencies_payload(p: Prediction) -> bytes:
    """squeak/unstable_frequencies: squeak frequencies [Hz], most unstable first."""
    hz = [float(f) for f in p.unstable_frequencies_hz]
    return cdr.encode_float64_multi_array((cdr.Dimension("frequency_hz", len(hz), len(hz)),), hz)


def modes_payload(p: Prediction) -> bytes:
    """squeak/modes of a prediction (layout in the module docstring)."""
    modes = p.modes
    rows = len(modes)
    return cdr.encode_float64_multi_array(
        (
            cdr.Dimension(MODES_PREFIX + ",".join([m.label for m in modes]), rows, rows * _COLUMNS),
            _COLUMNS_DIMENSION,
        ),
        # the floats as they are: CDR packs any real number (every prediction publishes this)
        [v for m in modes for v in (m.frequency_hz, m.growth_rate, m.damping_ratio)],
    )


def decode_modes(data: bytes) -> tuple[Mode, ...]:
    """The rows of a squeak/modes payload; ValueError if it is malformed or not laid out as
    `modes_payload` writes it."""
    msg = cdr.decode_float64_multi_array(data)
    if len(msg.dim) != 2 or not msg.dim[0].label.startswith(MODES_PREFIX):
        raise ValueError(f"not a squeak/modes layout: {[d.label for d in msg.dim]}")
    rows, columns = msg.dim
    labels = rows.label[len(MODES_PREFIX) :].split(",") if rows.size else []
    if columns.label.split(",") != list(MODE_COLUMNS) or columns.size != len(MODE_COLUMNS):
        raise ValueError(
            f"squeak/modes columns are {columns.label!r}, expected {','.join(MODE_COLUMNS)!r}"
        )
    if len(labels) != rows.size or msg.data_offset or len(msg.data) != rows.size * columns.size:
        raise ValueError(
            f"squeak/modes of {len(labels)} labels, {rows.size} rows, offset "
            f"{msg.data_offset} and {len(msg.data)} values"
        )
    n = len(MODE_COLUMNS)
    return tuple(Mode(label, *msg.data[i * n : (i + 1) * n]) for i, label in enumerate(labels))
