# SPDX-License-Identifier: Apache-2.0
"""Synthetic input logs: hours of power-seat strokes as the robot would record them.

A duty cycle of seat strokes (`simulator.StrokeProfile`, alternately forwards and backwards, the
nut going back and forth) each followed by a rest, sampled at `rate_hz` with small sensor noise,
every stroke alike or (`stroke_spread`) each with its own peak speed, load range and duration,
written by our `Recorder` (a rosbag2-style bag directory of split MCAP files) on the node's
input topics: `/motor_speed` and `/axial_load` (std_msgs/Float64), `/joint_states`
(sensor_msgs/JointState: screw angle and speed of one joint) and optionally `/nut_position`.
Used by the replay tests and benchmark.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..live.profile import StrokeProfile
from .cdr import FLOAT64, JOINT_STATE, JointStateData, encode_float64, encode_joint_state
from .recorder import Recorder, RecordSettings

SPEED_TOPIC, LOAD_TOPIC = "/motor_speed", "/axial_load"
JOINT_STATES_TOPIC, NUT_TOPIC = "/joint_states", "/nut_position"
_TOPIC_OFFSET_NS = 100_000  # topics of one sample are logged 0.1 ms apart, as on a robot


@dataclass(frozen=True)
class DutyCycle:
    """What the log contains; everything is deterministic for a given `seed`."""

    duration_s: float = 3600.0
    rate_hz: float = 100.0
    rest_s: float = 48.0  # motor off after each stroke (12 s stroke: 20 % duty)
    stroke: StrokeProfile = field(default_factory=StrokeProfile)
    joint_name: str = "seat_screw"
    nut_position_topic: bool = False  # also log the nut position (Float64, m)
    speed_noise_rad_s: float = 0.02  # standard deviation of the speed signal
    load_noise_n: float = 0.3  # standard deviation of the load cell
    encoder_counts_per_rev: int = 4096  # resolution of the screw angle
    # Relative spread (uniform, +-) of each stroke's peak speed, load range and duration, as
    # on a real bench (0: every stroke alike); a stroke that would run the nut off the screw
    # is slowed until it fits.
    stroke_spread: float = 0.0
    seed: int = 0
    start_ns: int = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z

    @property
    def samples(self) -> int:
        """Number of input samples: duration times rate, rounded."""
        return int(round(self.duration_s * self.rate_hz))


@dataclass(frozen=True)
class Samples:
    """The signals of a duty cycle, one row per sample (SI units)."""

    time_s: np.ndarray  # since the first sample
    speed_rad_s: np.ndarray  # measured (with noise)
    load_n: np.ndarray  # measured (with noise)
    nut_position_m: np.ndarray  # from the quantised screw angle
    screw_angle_rad: np.ndarray  # quantised


def samples(cycle: DutyCycle) -> Samples:
    """The samples of a duty cycle: strokes to and fro with rests, noisy inputs, quantised angle."""
    p, rng = cycle.stroke, np.random.default_rng(cycle.seed)
    t = np.arange(cycle.samples) / cycle.rate_hz
    if cycle.stroke_spread:
        states = _varied_states(cycle, t)
    else:
        period = p.duration_s + cycle.rest_s
        k = np.floor(t / period)
        # Stroke k runs at loop time k * duration: odd strokes go backwards and bring the nut
        # back; during the rest the stroke's end state holds.
        states = [
            p.state(s, loop=True)
            for s in (k * p.duration_s + np.minimum(t - k * period, p.duration_s)).tolist()
        ]
    speed, load, _, angle = (np.array(a) for a in zip(*states, strict=True))
    step = 2 * np.pi / cycle.encoder_counts_per_rev
    angle = np.round(angle / step) * step
    return Samples(
        t,
        speed + rng.normal(0.0, cycle.speed_noise_rad_s, t.size),
        load + rng.normal(0.0, cycle.load_noise_n, t.size),
        p.nut_position_at_zero_angle_m + angle * p.lead_m_per_rad,
        angle,
    )


def _varied_states(cycle: DutyCycle, t: np.ndarray) -> list:
    """Actuator states at the times `t` of strokes that each scale the profile's peak speed,
    load range and duration by their own factor in 1 +- `stroke_spread` (from a random stream
    of their own: the noise stays that of the same seed), alternately forwards and backwards
    from where the nut is."""
    p, spread = cycle.stroke, cycle.stroke_spread
    rng = np.random.default_rng([cycle.seed, 1])
    states, start, nut, forward = [], 0.0, p.start_nut_position_m, True
    i = 0
    while i < t.size:
        speed, load, duration = 1.0 + spread * rng.uniform(-1.0, 1.0, 3)
        room = p.max_nut_position_m - nut if forward else nut
        # the travel is linear in peak speed and duration: slower until it fits
        speed = min(speed, room / (p.travel_m * duration) * (1.0 - 1e-9))
        travel = p.travel_m * speed * duration
        stroke = replace(
            p,
            duration_s=p.duration_s * duration,
            peak_speed_rad_s=p.peak_speed_rad_s * speed,
            load_min_n=p.load_min_n * load,
            load_max_n=p.load_max_n * load,
            start_nut_position_m=nut if forward else nut - travel,
        )
        end = start + stroke.duration_s + cycle.rest_s
        j = int(np.searchsorted(t, end))
        d = stroke.duration_s
        # a backward stroke is the second of the profile's loop; at rest its end state holds
        states += [
            stroke.state(s) if forward else stroke.state(d + s, loop=True)
            for s in np.minimum(t[i:j] - start, d * (1.0 - 1e-12)).tolist()
        ]
        nut = stroke.end_nut_position_m if forward else stroke.start_nut_position_m
        start, forward, i = end, not forward, j
    return states


def write_log(
    cycle: DutyCycle,
    directory: Path | str,
    split_duration_s: float = RecordSettings.split_duration_s,
    compression: str = RecordSettings.compression,
    metadata: dict[str, dict[str, str]] | None = None,
) -> Path:
    """Record `cycle` into a new bag directory under `directory` (created if needed), with the
    MCAP Metadata records `metadata` in every file (e.g. a `logmeta` record, as the node
    writes); returns the bag directory."""
    s = samples(cycle)
    Path(directory).mkdir(parents=True, exist_ok=True)
    rec = Recorder(
        RecordSettings(
            directory=str(directory),
            split_size_mb=0.0,
            split_duration_s=split_duration_s,
            compression=compression,
        ),
        metadata=dict(metadata or {}),
    )
    if not rec.start(cycle.start_ns):
        raise OSError(rec.error)
    times = cycle.start_ns + np.round(s.time_s * 1e9).astype(np.int64)
    for now, speed, load, nut, angle in zip(
        times.tolist(),
        s.speed_rad_s.tolist(),
        s.load_n.tolist(),
        s.nut_position_m.tolist(),
        s.screw_angle_rad.tolist(),
        strict=True,
    ):
        rec.write_serialized(SPEED_TOPIC, FLOAT64, encode_float64(speed), now)
        rec.write_serialized(LOAD_TOPIC, FLOAT64, encode_float64(load), now + _TOPIC_OFFSET_NS)
        stamp = now + 2 * _TOPIC_OFFSET_NS  # publish time: the header stamp
        joint = JointStateData(stamp, "", (cycle.joint_name,), (angle,), (speed,), ())
        rec.write_serialized(
            JOINT_STATES_TOPIC, JOINT_STATE, encode_joint_state(joint), stamp, stamp
        )
        if cycle.nut_position_topic:
            rec.write_serialized(
                NUT_TOPIC, FLOAT64, encode_float64(nut), now + 3 * _TOPIC_OFFSET_NS
            )
        rec.tick(now)
    rec.stop()
    if rec.error:
        raise OSError(rec.error)
    assert rec.bag is not None  # set by the recording that stopped without error
    return rec.bag
