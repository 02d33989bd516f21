# SPDX-License-Identifier: Apache-2.0
"""The guard offline (`leadscrew-squeak guard`): the policy of `live.guard` applied to a
planned or recorded speed command, P(squeak) along the raw and the guarded command, and the
summary a controls engineer compares: time in squeak, peak P, motion time and travel.

P(squeak) at |speed| below the model's lowest valid speed counts as 0 (at rest), as in
`live.profile.expected_squeak`. Load and nut position are those of the profile at each time
for both commands (the guarded nut position differs by the travel difference; the bands are
binned by 5 mm anyway).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..bag.logfile import LogError
from ..bag.logsource import log_topics, open_log, topic_types
from ..live.guard import GuardBands, GuardPolicy, GuardSettings
from ..live.profile import StrokeProfile
from ..live.recompute import band_bin
from ..model.physics.parameters import ScrewParameters
from ..model.squeak_model import SqueakModel
from .timeline import InputError, InputSettings, Timeline, input_namespaces

COLUMNS = ("time_s", "speed_rad_s", "load_n", "nut_position_m")
LOG_RATE_HZ = 100.0  # a log's command is sampled at this rate (the tracker's step)
OUT_COLUMNS = COLUMNS + ("guarded_speed_rad_s", "p_squeak_raw", "p_squeak_guarded")


class ProfileFileError(ValueError):
    """A profile file that cannot be used (one line saying why)."""


@dataclass(frozen=True)
class Command:
    """A speed command over time with the load and nut position at each time (1-d arrays of
    one length, times strictly increasing) [s, rad/s, N, m]."""

    time_s: np.ndarray
    speed_rad_s: np.ndarray
    load_n: np.ndarray
    nut_position_m: np.ndarray

    @classmethod
    def of_profile(cls, profile: StrokeProfile, rate_hz: float = 100.0) -> Command:
        """A stroke (`StrokeProfile.sampled`) as a command."""
        return cls(*profile.sampled(rate_hz))


@dataclass(frozen=True)
class GuardRun:
    """A command, its guarded version and P(squeak) along both."""

    command: Command
    guarded_rad_s: np.ndarray
    p_raw: np.ndarray
    p_guarded: np.ndarray
    reasons: list[str]
    settings: GuardSettings


def read_profile(path: Path, load_n: float | None, nut_position_m: float | None) -> Command:
    """Read PROFILE.csv: a header and the columns time_s, speed_rad_s and optionally load_n,
    nut_position_m (else the constant `load_n` / `nut_position_m`).

    Raises
    ------
    ProfileFileError
        Missing columns or values, non-finite numbers, times not increasing.
    OSError
        The file cannot be read.
    """
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise ProfileFileError(f"{path}: empty, expected a header {','.join(COLUMNS[:2])}")
    header = [h.strip() for h in rows[0]]
    for name in COLUMNS[:2]:
        if name not in header:
            raise ProfileFileError(f"{path}: no column {name} in the header {','.join(header)}")
    constants = {"load_n": (load_n, "--load"), "nut_position_m": (nut_position_m, "--nut")}
    columns: dict[str, np.ndarray] = {}
    for name in COLUMNS:
        if name in header:
            k = header.index(name)
            try:
                columns[name] = np.array([float(r[k]) for r in rows[1:]])
            except (ValueError, IndexError) as exc:
                raise ProfileFileError(f"{path}: column {name}: {exc}") from None
        else:
            value, option = constants[name]
            if value is None:
                raise ProfileFileError(f"{path}: no column {name}: give {option}")
            columns[name] = np.full(len(rows) - 1, float(value))
    if len(rows) < 3:
        raise ProfileFileError(f"{path}: needs at least two rows of values")
    for name, values in columns.items():
        if not np.isfinite(values).all():
            raise ProfileFileError(f"{path}: column {name} has a value that is not finite")
    if not (np.diff(columns["time_s"]) > 0).all():
        raise ProfileFileError(f"{path}: time_s must increase strictly")
    return Command(*(columns[n] for n in COLUMNS))


def read_log(
    path: Path,
    params: ScrewParameters,
    load_n: float | None,
    nut_position_m: float | None,
    rate_hz: float = LOG_RATE_HZ,
) -> Command:
    """The motor speed of a recorded log as the command, with its axial load and nut
    position, sampled (latest value held) at `rate_hz` from the first speed on: the node's
    inputs as `replay` reads them (`review.timeline`: default topics and field paths, the
    log's one input namespace). `load_n` / `nut_position_m` stand in for an input the log
    lacks (the nut position else: the parameters').

    Raises
    ------
    LogError
        The log cannot be read, or has no speed or no load (and no `load_n`).
    """
    source = open_log(path)
    found = input_namespaces(log_topics(source).values(), InputSettings())
    inputs = InputSettings(nominal_load_n=load_n).resolved(found[0] if found else "/")
    timeline = Timeline(params, inputs, topic_types(source))
    points: list[tuple[float, float, float, float]] = []
    for f, m in source.messages():
        try:
            timeline.feed(m, 0)
        except InputError as exc:
            raise LogError(f, str(exc)) from None
        speed, load = timeline.speed, timeline.load
        if speed is not None and load is not None:
            nut = (
                timeline.nut if timeline.nut_measured or nut_position_m is None else nut_position_m
            )
            points.append((timeline.seconds(timeline.now_ns), speed, load, nut))
    if len(points) < 2:
        raise LogError(path, "no motor speed with an axial load in the log (give --load N)")
    t, *values = (np.array(a) for a in zip(*points, strict=True))
    times = t[0] + np.arange(int((t[-1] - t[0]) * rate_hz) + 1) / rate_hz
    held = np.searchsorted(t, times, side="right") - 1  # the latest value at each time
    return Command(times - times[0], *(v[held] for v in values))


def write_profile(path: Path, command: Command) -> None:
    """Write a command as PROFILE.csv (all four columns)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for row in zip(*(getattr(command, n).tolist() for n in COLUMNS), strict=True):
            w.writerow([repr(x) for x in row])


def probabilities(
    model: SqueakModel, speed: np.ndarray, load: np.ndarray, nut: np.ndarray
) -> np.ndarray:
    """P(squeak) at each point (0 below the model's lowest valid |speed|; NaN where the model
    is not valid)."""
    p = np.zeros(len(speed))
    moving = np.flatnonzero(np.abs(speed) >= model.params.min_speed_rad_s)
    if len(moving):
        for i, pred in zip(
            moving.tolist(),
            model.predict_many(speed[moving], load[moving], nut[moving]),
            strict=True,
        ):
            p[i] = pred.probability if pred.valid and pred.probability is not None else math.nan
    return p


def apply_guard(command: Command, model: SqueakModel, settings: GuardSettings) -> GuardRun:
    """Run the policy over a command (bands of every bin it visits computed first, as a node's
    background thread would) and P(squeak) along the raw and the guarded command."""
    policy = GuardPolicy(settings)
    c = command
    for load, nut, speed in zip(
        c.load_n.tolist(), c.nut_position_m.tolist(), c.speed_rad_s.tolist(), strict=True
    ):
        if speed != 0.0:
            key = band_bin(load, nut, speed)
            if key not in policy.bands:
                policy.bands[key] = GuardBands.compute(model, key, settings.p_max)
    out, reasons = np.zeros(len(c.time_s)), []
    for i, (t, speed, load, nut) in enumerate(
        zip(
            c.time_s.tolist(),
            c.speed_rad_s.tolist(),
            c.load_n.tolist(),
            c.nut_position_m.tolist(),
            strict=True,
        )
    ):
        step = policy.step(t, speed, load, nut)
        out[i] = step.speed_rad_s
        reasons.append(step.reason)
    return GuardRun(
        c,
        out,
        probabilities(model, c.speed_rad_s, c.load_n, c.nut_position_m),
        probabilities(model, out, c.load_n, c.nut_position_m),
        reasons,
        settings,
    )


@dataclass(frozen=True)
class Motion:
    """What one command does: time in squeak (P >= p_max, each sample held until the next)
    [s], peak P, motion time (first to last sample with |speed| > 0) [s], travel (integral of
    |speed|, trapezoidal) [rad]."""

    time_in_squeak_s: float
    peak_p: float
    motion_time_s: float
    travel_rad: float


def motion(time_s: np.ndarray, speed: np.ndarray, p: np.ndarray, p_max: float) -> Motion:
    """The `Motion` of one command."""
    dt = np.diff(time_s)
    squeak = float(dt[(p[:-1] >= p_max)].sum())  # NaN compares False: not counted
    moving = np.flatnonzero(speed != 0.0)
    span = float(time_s[moving[-1]] - time_s[max(moving[0] - 1, 0)]) if len(moving) else 0.0
    travel = float(np.sum(0.5 * (np.abs(speed[1:]) + np.abs(speed[:-1])) * dt))
    return Motion(squeak, float(np.nanmax(p, initial=0.0)), span, travel)


def summary(run: GuardRun) -> tuple[Motion, Motion, float]:
    """Raw and guarded `Motion` and the guarded stroke time to cover the raw travel [s]: its
    motion time scaled by raw / guarded travel (the same mean speed)."""
    p_max = run.settings.p_max
    c = run.command
    raw = motion(c.time_s, c.speed_rad_s, run.p_raw, p_max)
    guarded = motion(c.time_s, run.guarded_rad_s, run.p_guarded, p_max)
    stroke = (
        guarded.motion_time_s * raw.travel_rad / guarded.travel_rad
        if guarded.travel_rad > 0
        else math.inf
    )
    return raw, guarded, stroke


def write_run(path: Path, run: GuardRun) -> None:
    """guarded.csv: the command's columns, the guarded command and P along both."""
    c = run.command
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(OUT_COLUMNS)
        for row in zip(
            *(getattr(c, n).tolist() for n in COLUMNS),
            run.guarded_rad_s.tolist(),
            run.p_raw.tolist(),
            run.p_guarded.tolist(),
            strict=True,
        ):
            w.writerow([repr(x) for x in row])
