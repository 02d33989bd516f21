# SPDX-License-Identifier: Apache-2.0
"""What a unit's logs say for calibration: heard / not-heard detector frames, thinned to
distinct operating points (speed, load, nut position).

The detector decides every `hop` seconds on a window of `DetectorSettings.frame_s`; a log gives
about a hundred frames a second, at a few hundred distinct operating points. The likelihood
needs one eigen-solve per distinct point, so frames are binned (`ThinSettings`, one place for
the steps):

- speed: bins of `speed_step_rad_s` below `speed_step_rad_s / speed_step_relative` (2.5 rad/s
  by default) and of relative width `speed_step_relative` above it (logarithmic). The friction
  terms of (27) scale with 1 / |Omega| (W3, W4) and exp(-d R |Omega| / cos beta) (the
  slope), so a relative step moves them by the same share everywhere; the absolute step keeps
  the low-speed edge of the squeak band (about 1 rad/s at Table 1, moving by about 0.3 rad/s
  for a 10 % change of mu_s or mu_k) resolved.
- load: bins of `load_step_n`; the friction terms are proportional to |F_z|, so 2 N is 1-2 %
  of the loads of a seat stroke (about the change of a speed bin).
- nut position: bins of `nut_step_m`, the node's `nut_deadband_m` (0.5 mm) at the same grid
  (multiples of the step, as the virtual bench moves its nut): the growth rate oscillates with
  the nut's phase against the thread (2 pi R tan(beta) = 2.7 mm per turn at Table 1), which
  a coarser step would smear. The geometry is integrated once per nut bin.

A point's speed and load are its frames' means, its nut position the bin's centre.

The frames also stay in time order (`Observations.sequence`: each frame's point), for the
observation model (`amplitude`): the squeak's amplitude grows and decays along a stroke, so
whether a frame is heard depends on the frames before it. Frames the likelihood must not count
(at an episode's edge, `gather.counted`) still carry the amplitude; frames where the model does
not hold (the drive standing, outside its speed range) hold no point and let it decay to the
floor. Each heard onset's measured growth rate (`Growth`) is kept with its frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from ..physics.metadata import check, documented, setting


class CalibrationError(ValueError):
    """Calibration input that cannot give a number (NaN, mismatched arrays, no frames, ...);
    the message is one line naming what is wrong."""


@documented
@dataclass(frozen=True)
class ThinSettings:
    """Bin steps of `thin` (see the module docstring for the choice)."""

    speed_step_rad_s: float = setting(
        0.05, "rad/s", "width of a speed bin at low speed (below step / relative step)", 1e-4, 100.0
    )
    speed_step_relative: float = setting(
        0.02, "1", "relative width of a speed bin above the low-speed range", 1e-4, 1.0
    )
    load_step_n: float = setting(2.0, "N", "width of a load bin", 1e-3, 1e5)
    nut_step_m: float = setting(
        0.0005, "m", "width of a nut-position bin (the node's nut_deadband_m)", 1e-6, 1.0
    )

    def __post_init__(self) -> None:
        check(self, CalibrationError, "thin.")

    def keys(
        self, speed_rad_s: np.ndarray, load_n: np.ndarray, nut_position_m: np.ndarray
    ) -> np.ndarray:
        """Integer bin keys of operating points: points with equal keys are one distinct
        point.

        Parameters
        ----------
        speed_rad_s, load_n, nut_position_m : numpy.ndarray
            (n,) operating points [rad/s], [N], [m].

        Returns
        -------
        numpy.ndarray
            (n, 3) int keys (nut, speed, load): the nut first, so that sorted keys group a
            nut's points, which share a geometry.
        """
        w, a, r = np.abs(speed_rad_s), self.speed_step_rad_s, self.speed_step_relative
        corner = a / r  # where a relative bin is as wide as an absolute one
        u = np.where(w < corner, w / a, corner / a + np.log(np.maximum(w, corner) / corner) / r)
        return np.column_stack(
            [
                np.round(nut_position_m / self.nut_step_m),
                np.sign(speed_rad_s) * np.round(u),
                np.round(load_n / self.load_step_n),
            ]
        ).astype(np.int64)


@dataclass(frozen=True)
class Observations:
    """A unit's heard / not-heard frames at distinct operating points (from `thin`, `merge`).

    Attributes
    ----------
    unit_id : str
        The unit.
    logs : tuple of str
        The logs the frames came from.
    speed_rad_s : numpy.ndarray
        (P,) speed of each distinct point [rad/s] (signed).
    load_n : numpy.ndarray
        (P,) axial load [N] (signed).
    nut_position_m : numpy.ndarray
        (P,) nut position [m] (a multiple of `ThinSettings.nut_step_m`).
    frames : numpy.ndarray
        (P,) int: detector frames counted at the point (>= 0; 0 where every frame there only
        carries the amplitude).
    heard : numpy.ndarray
        (P,) int: of which the detector heard squeak.
    heard_hz : numpy.ndarray
        (P,) median heard frequency there [Hz], nan where none was heard.
    frame_s : float
        Detector hop: time between frames [s].
    sequence : numpy.ndarray
        (n,) int: every frame of the logs in time order, its point (-1 where the model does
        not hold there); empty for observations made without their order.
    frame_heard : numpy.ndarray
        (n,) bool: the detector heard squeak in the frame.
    frame_counted : numpy.ndarray
        (n,) bool: the frame enters the likelihood (the counts above are of these).
    frame_reset : numpy.ndarray
        (n,) bool: a log starts here, or the frame follows a gap of more than one hop (the
        squeak's amplitude starts from the floor).
    onsets : numpy.ndarray
        (m, 3): per heard onset with a measured growth rate, its frame (index into
        `sequence`), the rate and its standard error [1/s].
    motor_off_frames : int
        Frames where the drive stood (below the model's minimum speed) and had stood long
        enough for a squeak to ring down (`gather.RING_DOWN_S`): no squeak there.
    motor_off_heard : int
        Of which the detector heard squeak: its own false alarms in the room.
    """

    unit_id: str
    logs: tuple[str, ...]
    speed_rad_s: np.ndarray
    load_n: np.ndarray
    nut_position_m: np.ndarray
    frames: np.ndarray
    heard: np.ndarray
    heard_hz: np.ndarray
    frame_s: float
    sequence: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    frame_heard: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    frame_counted: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    frame_reset: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    onsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    motor_off_frames: int = 0
    motor_off_heard: int = 0

    def __post_init__(self) -> None:
        sizes = {np.shape(getattr(self, name)) for name in _POINT_ARRAYS}
        if len(sizes) != 1 or len(next(iter(sizes))) != 1:
            raise CalibrationError(f"unit {self.unit_id}: observation arrays differ in shape")
        frames = {np.shape(getattr(self, name)) for name in _FRAME_ARRAYS}
        if len(frames) != 1 or len(next(iter(frames))) != 1:
            raise CalibrationError(f"unit {self.unit_id}: frame sequence arrays differ in shape")
        n = len(self.sequence)
        if n and (np.any(self.sequence < -1) or np.any(self.sequence >= self.points)):
            raise CalibrationError(
                f"unit {self.unit_id}: the frame sequence names a point that does not exist"
            )
        if n and not self.frame_reset[0]:
            raise CalibrationError(
                f"unit {self.unit_id}: the frame sequence must start a log (frame_reset[0])"
            )
        if np.shape(self.onsets)[1:] != (3,) or (
            len(self.onsets) and not np.all((self.onsets[:, 0] >= 0) & (self.onsets[:, 0] < n))
        ):
            raise CalibrationError(f"unit {self.unit_id}: onsets must be (frame, rate, se) rows")
        _finite(self.unit_id, speed_rad_s=self.speed_rad_s, load_n=self.load_n)
        _finite(self.unit_id, nut_position_m=self.nut_position_m)
        if not (isinstance(self.frame_s, float) and math.isfinite(self.frame_s)) or not (
            self.frame_s > 0
        ):
            raise CalibrationError(
                f"unit {self.unit_id}: frame_s = {self.frame_s!r} must be a number > 0 [s]"
            )
        if np.any(self.heard < 0) or np.any(self.heard > self.frames):
            raise CalibrationError(f"unit {self.unit_id}: need 0 <= heard <= frames at every point")
        if not self.frames.sum():
            raise CalibrationError(f"unit {self.unit_id}: no counted frame")

    @property
    def points(self) -> int:
        """Number of distinct operating points P."""
        return len(self.frames)


_POINT_ARRAYS = ("speed_rad_s", "load_n", "nut_position_m", "frames", "heard", "heard_hz")
_FRAME_ARRAYS = ("sequence", "frame_heard", "frame_counted", "frame_reset")


def _finite(unit_id: str, **arrays: np.ndarray) -> None:
    for name, a in arrays.items():
        bad = ~np.isfinite(a)
        if bad.any():
            raise CalibrationError(
                f"unit {unit_id}: {name} is not finite at {int(bad.sum())} of {a.size} "
                f"frames (first at index {int(np.flatnonzero(bad)[0])}): no calibration from NaN"
            )


def _binned(
    unit_id: str,
    logs: tuple[str, ...],
    speed: np.ndarray,
    load: np.ndarray,
    nut: np.ndarray,
    frames: np.ndarray,
    heard: np.ndarray,
    heard_hz: np.ndarray,
    frame_s: float,
    settings: ThinSettings,
) -> tuple[Observations, np.ndarray]:
    """Points with equal bin keys merged: frame-weighted mean speed and load (the counted
    frames', or all of them where none is counted), the bin's nut, summed counts, the median
    of the heard frequencies (each entry weighted by its heard frames); and each input row's
    point."""
    keys, inverse = np.unique(settings.keys(speed, load, nut), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    count = np.bincount(inverse, weights=frames, minlength=len(keys))
    weight = np.where(count[inverse] > 0, frames, 1.0)  # uncounted points: all their frames
    total = np.bincount(inverse, weights=weight, minlength=len(keys))
    hz = np.full(len(keys), np.nan)
    with_hz = np.flatnonzero((heard > 0) & np.isfinite(heard_hz))
    order = with_hz[np.lexsort((heard_hz[with_hz], inverse[with_hz]))]
    for k, rows in zip(*_groups(inverse[order]), strict=True):  # few heard points: a loop
        w = np.cumsum(heard[order[rows]])
        hz[k] = heard_hz[order[rows]][np.searchsorted(w, w[-1] / 2)]
    obs = Observations(
        unit_id=unit_id,
        logs=logs,
        speed_rad_s=np.bincount(inverse, weights=weight * speed, minlength=len(keys)) / total,
        load_n=np.bincount(inverse, weights=weight * load, minlength=len(keys)) / total,
        nut_position_m=keys[:, 0] * settings.nut_step_m,
        frames=count.astype(np.int64),
        heard=np.bincount(inverse, weights=heard, minlength=len(keys)).astype(np.int64),
        heard_hz=hz,
        frame_s=frame_s,
    )
    return obs, inverse


def _groups(sorted_ids: np.ndarray) -> tuple[list[int], list[slice]]:
    """The distinct values of a sorted array and the slice of each."""
    if not len(sorted_ids):
        return [], []
    cut = np.flatnonzero(np.diff(sorted_ids)) + 1
    starts, ends = np.r_[0, cut], np.r_[cut, len(sorted_ids)]
    return sorted_ids[starts].tolist(), [slice(a, b) for a, b in zip(starts, ends, strict=True)]


def thin(
    unit_id: str,
    logs: tuple[str, ...] | list[str],
    times_s: ArrayLike,
    speed_rad_s: ArrayLike,
    load_n: ArrayLike,
    nut_position_m: ArrayLike,
    heard: ArrayLike,
    heard_hz: ArrayLike,
    frame_s: float,
    settings: ThinSettings | None = None,
    counted: ArrayLike | None = None,
    valid: ArrayLike | None = None,
    onsets: Sequence[tuple[float, float, float]] = (),
    motor_off: ArrayLike | None = None,
) -> Observations:
    """Detector frames binned to distinct operating points, and kept in order (module
    docstring).

    Parameters
    ----------
    unit_id : str
        The unit the frames belong to.
    logs : sequence of str
        The log(s) they came from.
    times_s : array_like
        (n,) frame centres [s], in time order.
    speed_rad_s, load_n, nut_position_m : array_like
        (n,) the operating point at each frame centre (interpolated by the caller) [rad/s],
        [N], [m]; finite where `valid`.
    heard : array_like
        (n,) bool: the detector heard squeak in the frame.
    heard_hz : array_like
        (n,) heard frequency [Hz] where heard (nan elsewhere; ignored where not heard).
    frame_s : float
        Detector hop: time between frames [s].
    settings : ThinSettings, optional
        Bin steps; the defaults when None.
    counted : array_like, optional
        (n,) bool: the frames the likelihood counts (all valid ones when None); the others
        only carry the amplitude.
    valid : array_like, optional
        (n,) bool: the model holds at the frame's operating point (all when None); the
        others have no point.
    onsets : sequence of (float, float, float)
        Heard onsets' (time [s], measured growth rate [1/s], its standard error [1/s]); each
        is kept at the frame nearest its time.
    motor_off : array_like, optional
        (n,) bool: the drive stood (none when None): counted with its heard frames apart
        (`Observations.motor_off_frames`), the detector's false alarms.

    Returns
    -------
    Observations
        Points sorted by nut position, then speed and load.

    Raises
    ------
    CalibrationError
        Arrays of different lengths, no counted frame, a NaN or inf in the times or valid
        operating points, times not in order, or a bad hop: one line, never a number.
    """
    settings = settings or ThinSettings()
    arrays = {
        "times_s": np.asarray(times_s, float),
        "speed_rad_s": np.asarray(speed_rad_s, float),
        "load_n": np.asarray(load_n, float),
        "nut_position_m": np.asarray(nut_position_m, float),
        "heard_hz": np.asarray(heard_hz, float),
    }
    flags = np.asarray(heard)
    masks = {
        name: np.full(flags.shape, default) if m is None else np.asarray(m)
        for name, m, default in (
            ("valid", valid, True),
            ("counted", counted, True),
            ("motor_off", motor_off, False),
        )
    }
    shapes = {a.shape for a in arrays.values()} | {flags.shape} | {m.shape for m in masks.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 1:
        raise CalibrationError(
            f"unit {unit_id}: frame arrays must be 1-D of one length, got shapes {sorted(shapes)}"
        )
    if not flags.size:
        raise CalibrationError(f"unit {unit_id}: no detector frames")
    for name, a in (("heard", flags), *masks.items()):
        if a.dtype != bool:
            raise CalibrationError(f"unit {unit_id}: {name} must be booleans, got {a.dtype}")
    ok = masks["valid"]
    use = masks["counted"] & ok
    _finite(unit_id, times_s=arrays["times_s"])
    _finite(unit_id, **{k: v[ok] for k, v in arrays.items() if k not in ("heard_hz", "times_s")})
    times = arrays["times_s"]
    if np.any(np.diff(times) < 0):
        raise CalibrationError(f"unit {unit_id}: frame times are not in order")
    if isinstance(frame_s, bool) or not isinstance(frame_s, (int, float)):
        raise CalibrationError(f"unit {unit_id}: frame_s = {frame_s!r} is not a number [s]")
    if not use.any():
        raise CalibrationError(f"unit {unit_id}: no counted frame at a valid operating point")
    obs, inverse = _binned(
        unit_id,
        tuple(logs),
        arrays["speed_rad_s"][ok],
        arrays["load_n"][ok],
        arrays["nut_position_m"][ok],
        use[ok].astype(float),
        (flags & use)[ok].astype(float),
        arrays["heard_hz"][ok],
        float(frame_s),
        settings,
    )
    sequence = np.full(flags.size, -1, np.int64)
    sequence[ok] = inverse
    reset = np.r_[True, np.diff(times) > 1.5 * float(frame_s)]
    rows = np.zeros((0, 3))
    if len(onsets):
        rows = np.array(onsets, float).reshape(-1, 3)
        rows = rows[np.all(np.isfinite(rows), axis=1)]
        rows[:, 0] = np.clip(np.searchsorted(times, rows[:, 0]), 0, flags.size - 1)
    off = masks["motor_off"]
    return replace(
        obs,
        sequence=sequence,
        frame_heard=flags.copy(),
        frame_counted=use,
        frame_reset=reset,
        onsets=rows,
        motor_off_frames=int(off.sum()),
        motor_off_heard=int((off & flags).sum()),
    )


def merge(observations: list[Observations], settings: ThinSettings | None = None) -> Observations:
    """The observations of several logs of one unit as one (points in the same bins merged,
    the frame sequences one after another, each starting from the floor).

    Parameters
    ----------
    observations : list of Observations
        Of one `unit_id`, with one detector hop.
    settings : ThinSettings, optional
        The bin steps they were thinned with; the defaults when None.

    Returns
    -------
    Observations
        With every log, the points re-binned.

    Raises
    ------
    CalibrationError
        No observations, different units or different detector hops.
    """
    if not observations:
        raise CalibrationError("no observations to merge")
    units = sorted({o.unit_id for o in observations})
    if len(units) > 1:
        raise CalibrationError(f"cannot merge observations of different units: {', '.join(units)}")
    hops = sorted({o.frame_s for o in observations})
    if len(hops) > 1:
        raise CalibrationError(
            f"unit {units[0]}: logs with different detector hops "
            f"({', '.join(f'{h:g}' for h in hops)} s) cannot be merged: detect with one hop"
        )

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(o, name) for o in observations])

    obs, inverse = _binned(
        units[0],
        tuple(log for o in observations for log in o.logs),
        cat("speed_rad_s"),
        cat("load_n"),
        cat("nut_position_m"),
        cat("frames").astype(float),
        cat("heard").astype(float),
        cat("heard_hz"),
        hops[0],
        settings or ThinSettings(),
    )
    obs = replace(
        obs,
        motor_off_frames=sum(o.motor_off_frames for o in observations),
        motor_off_heard=sum(o.motor_off_heard for o in observations),
    )
    if any(not len(o.sequence) for o in observations):
        return obs  # one without its order: the merged frames have none either
    point0 = np.cumsum([0] + [o.points for o in observations[:-1]])
    frame0 = np.cumsum([0] + [len(o.sequence) for o in observations[:-1]])
    sequence = np.concatenate(
        [
            np.where(o.sequence >= 0, inverse[o.sequence + p0], -1)
            for o, p0 in zip(observations, point0, strict=True)
        ]
    )
    onsets = np.concatenate(
        [o.onsets + [f0, 0.0, 0.0] for o, f0 in zip(observations, frame0, strict=True)]
    )
    return replace(
        obs,
        sequence=sequence,
        frame_heard=cat("frame_heard"),
        frame_counted=cat("frame_counted"),
        frame_reset=cat("frame_reset"),
        onsets=onsets,
    )
