# SPDX-License-Identifier: Apache-2.0
"""The squeak-prediction diagnostic status, free of rclpy: its levels (those of
diagnostic_msgs/DiagnosticStatus), its key names, and the verdict of a valid prediction.

`LivePredictor.status` (live.recompute) builds it; the node publishes it as a
DiagnosticStatus, the crash recovery and the demo read it back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from ..model import Prediction
from ..model.physics.display import exact
from .settings import LiveSettings

# Key names of the squeak-prediction diagnostic status (`LivePredictor.status`).
KEY_SPEED = "speed_rad_s"
KEY_LOAD = "load_n"
KEY_NUT_POSITION = "nut_position_m"
KEY_FORMULATION = "formulation"
KEY_VALID = "valid"  # "true" when the latest point has a prediction
KEY_VALIDITY = "validity"  # Validity name of the latest point ('' before one)
KEY_PROBABILITY = "probability"  # P(squeak) of the latest prediction
KEY_PROBABILITY_STDERR = "probability_stderr"  # its standard error ('' when not sampled)
KEY_MARGIN = "margin"  # least damping ratio (< 0: a nominal mode squeaks)
KEY_MAX_GROWTH_RATE = "max_growth_rate_1_s"
KEY_SQUEAK_FREQUENCIES = "squeak_frequencies_hz"
KEY_SAFE_SPEED = "safe_speed_rad_s"
KEY_SAFE_SPEED_PENDING = "safe_speed_pending"
KEY_SAFE_SPEED_ERROR = "safe_speed_error"
KEY_RECOMPUTES = "recomputes"
KEY_LIFECYCLE_STATE = "lifecycle_state"  # only while the node is not active: "inactive"
INACTIVE = (
    "inactive (lifecycle): inputs not taken, nothing predicted, published or recorded "
    "until activated"
)


class Level(IntEnum):
    """diagnostic_msgs/DiagnosticStatus levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class Status:
    """A diagnostic verdict: level, one-line message and key/value pairs."""

    level: Level
    message: str
    values: dict[str, str] = field(default_factory=dict)


def prediction_status(
    p: Prediction, s: LiveSettings, values: dict[str, str] | None = None
) -> Status:
    """The diagnostic level and message of a valid prediction: ERROR when P(squeak) >=
    error_probability or a divergence (non-oscillatory growth) is predicted, WARN when P >=
    warn_probability, else OK; the message gives P (never rounded across a threshold) and
    the modes that squeak at the nominal parameters."""
    assert p.probability is not None, "a valid prediction has its P(squeak)"
    text = f"{p.probability:.2g}"
    if any(
        (float(text) >= t) != (p.probability >= t)
        for t in (s.warn_probability, s.error_probability)
    ):
        text = exact(p.probability)
    prob = f"P(squeak) {text}"
    notes = [f"{m.label} {m.frequency_hz:.0f} Hz" for m in p.squeak_modes]
    notes += [f"divergence {r:.3g} 1/s" for r in p.divergence_rates[:1]]
    detail = f" ({', '.join(notes)})" if notes else ""
    values = values or {}
    if p.probability >= s.error_probability:
        return Status(Level.ERROR, f"squeak predicted: {prob}{detail}", values)
    if p.divergence_rates:
        return Status(Level.ERROR, f"divergence predicted: {prob}{detail}", values)
    if p.probability >= s.warn_probability:
        return Status(
            Level.WARN, f"squeak possible: {prob} >= {s.warn_probability:g}{detail}", values
        )
    return Status(Level.OK, f"no squeak: {prob} < {s.warn_probability:g}{detail}", values)


def inactive_status(last: Status) -> Status:
    """The verdict of a managed node that is configured but not active: STALE (the outputs
    keep their last values and are not updated), the message `INACTIVE`, the values of the
    predictor's `last` verdict and `lifecycle_state` 'inactive'."""
    return Status(Level.STALE, INACTIVE, {**last.values, KEY_LIFECYCLE_STATE: "inactive"})


def value_text(v: float | None) -> str:
    """A status value: 6 significant digits, empty for None."""
    return "" if v is None else f"{v:.6g}"
