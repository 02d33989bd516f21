# SPDX-License-Identifier: Apache-2.0
"""The guard's policy, free of rclpy: a speed command filter that steers around squeak bands.

Per speed-command message a node calls `GuardPolicy.step` (O(1): a dict look-up of cached
bands and a few float operations, no prediction). The bands, |speed| intervals where P(squeak)
>= `GuardSettings.p_max` (`model.studies.advice.speed_bands`), are computed per (load bin, nut
bin, direction) by `GuardBands.compute` outside the step (a background thread in a node, all at
once offline) and stored in `GuardPolicy.bands`; a step whose bin is missing passes the command
through and lists the bin in `GuardPolicy.wanted`.

Policy, per step at time t with command c:

* `enabled` false: the output is c, exactly.
* c == 0: the output is 0 at once (a stop; the tracker restarts from rest).
* Fail-safe: load or nut position missing, not finite or older than `stale_timeout_s`, the
  step later than `deadline_s`, the bin's band search failed or not ready: the target is c
  (rate limits aside) and `GuardStep.reason` says why. A command that is not finite is not
  taken: the target stays the last good command.
* Else the target is c unless |c| lies in a band [lo, hi] of c's direction: then it is the
  nearer of the safe speeds lo (1 - margin) and hi (1 + margin) (hi only up to
  `max_speed_rad_s`), same sign as c. Leaving one safe speed for the
  other crosses the band at the tracker's highest acceleration.
* Delay bound: a target is a command value c0 held from t0 on. The plain tracker (no bands)
  reaches it from the state at t0 by t0 + `reach_time` (state, c0). The guard deflects only
  while it can still reach c0 by t0 + reach_time + `max_delay_s`; then it commits to c0
  until the command changes (`GuardStep.reason` 'max_delay_s'). Reached: |v - c0| <= 1e-9
  |c0| and staying; the property tests (fixed step dt) find it within 4 steps of that bound
  (the continuous-time bound against the discrete tracker). The check looks one step ahead
  with the last step's dt: with steps of varying length the bound holds up to the longest.

The tracker: the output v and its acceleration a = (v_k - v_{k-1}) / dt_k, jerk
(a_k - a_{k-1}) / dt_k. Each step picks a_k in [a_{k-1} - J dt, a_{k-1} + J dt] intersected
with [-A, A], so |a| <= A and |jerk| <= J hold by construction (to float rounding, a relative
1e-9 in the tests); aiming at the target along the braking curve a^2 / (2 J) (time-optimal,
no overshoot from a state on the curve), and landing on it exactly when one step can. |v| <=
V holds because the target is clipped to V and the output stays within the braking curve of
V. Exceptions, both stops (output 0, acceleration reset to 0): a zero command, and an output
that would cross zero to the side opposite to the command (no reversal).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..model.physics.metadata import check, documented, setting
from ..model.squeak_model import SqueakModel
from ..model.studies.advice import speed_bands
from .recompute import band_bin, bin_centre


@documented
@dataclass(frozen=True)
class GuardSettings:
    """The guard's policy and limits (SI units; see the field metadata)."""

    enabled: bool = setting(True, "", "steer the speed command around squeak bands")
    p_max: float = setting(
        0.1, "1", "a speed is in a squeak band where P(squeak) >= this", 0.0, 1.0, lo_open=True
    )
    margin: float = setting(0.05, "1", "relative distance kept from a squeak band edge", 0.0, 0.5)
    max_speed_rad_s: float = setting(
        200.0, "rad/s", "largest absolute speed the guard outputs", 0.0, 1e5, lo_open=True
    )
    max_accel_rad_s2: float = setting(
        1000.0,
        "rad/s^2",
        "largest absolute acceleration of the guarded command",
        0.0,
        1e7,
        lo_open=True,
    )
    max_jerk_rad_s3: float = setting(
        50000.0, "rad/s^3", "largest absolute jerk of the guarded command", 0.0, 1e9, lo_open=True
    )
    max_delay_s: float = setting(
        1.0, "s", "largest delay the guard adds to reaching a commanded speed", 0.0, 3600.0
    )
    stale_timeout_s: float = setting(
        1.0, "s", "pass through when load or nut position is older than this", 0.001, 3600.0
    )
    deadline_s: float = setting(
        0.01, "s", "pass through when a step runs later than this after its command", 1e-6, 10.0
    )

    def __post_init__(self) -> None:
        check(self)


@dataclass(frozen=True)
class GuardBands:
    """The squeak bands of one (load bin, nut bin, direction) bin: |speed| intervals [rad/s]
    where P(squeak) >= p_max, or why they could not be found.

    Attributes
    ----------
    key : tuple
        The bin (`live.recompute.band_bin`).
    intervals : tuple of (float, float)
        Bands, ascending.
    error : str
        '' or why the search failed (the guard then passes through).
    """

    key: tuple
    intervals: tuple[tuple[float, float], ...] = ()
    error: str = ""

    @classmethod
    def compute(cls, model: SqueakModel, key: tuple, p_max: float) -> GuardBands:
        """Search the bands of a bin at its centre (slow: tens of predictions; never in a step).

        Parameters
        ----------
        model : SqueakModel
            The model (its nut position is replaced by the bin's).
        key : tuple
            The bin.
        p_max : float
            The threshold of P(squeak).

        Returns
        -------
        GuardBands
            The bands, or the error as text.
        """
        load, nut, direction = bin_centre(key)
        try:
            at = model.with_params(nut_position_m=nut)
            found = speed_bands(at, load, direction, safe_probability=p_max)
        except Exception as exc:  # any model failure: the guard passes through, says why
            return cls(key, (), f"squeak band search failed: {' '.join(str(exc).split())}")
        return cls(key, tuple((float(lo), float(hi)) for lo, hi in found))


@dataclass(frozen=True)
class GuardStep:
    """One step's output.

    Attributes
    ----------
    speed_rad_s : float
        The guarded command [rad/s].
    target_rad_s : float
        What the tracker aimed at [rad/s].
    active : bool
        The target differs from the command (a band was avoided).
    reason : str
        Why the target differs from the command, or why the guard passed it through ('' when
        neither).
    stopped : bool
        A stop: output 0 with the acceleration reset (zero command, or no reversal).
    fault : str
        The fail-safe's kind when a fault made the guard pass the command through (one of
        `FAULTS`), '' otherwise (guarding, disabled, or the bin's bands not computed yet).
    """

    speed_rad_s: float
    target_rad_s: float
    active: bool
    reason: str
    stopped: bool = False
    fault: str = ""


# The fail-safe's kinds (`GuardStep.fault`): what a node reports as a warning, once per kind.
NO_INPUT = "no load or nut position"
INPUT_NOT_FINITE = "load or nut position not finite"
INPUT_STALE = "load or nut position stale"
DEADLINE_MISSED = "deadline missed"
MODEL_ERROR = "model error"
COMMAND_NOT_FINITE = "command not finite"
FAULTS = (NO_INPUT, INPUT_NOT_FINITE, INPUT_STALE, DEADLINE_MISSED, MODEL_ERROR, COMMAND_NOT_FINITE)


def reach_time(v: float, a: float, target: float, s: GuardSettings) -> float:
    """Upper bound of the time [s] the plain tracker needs from speed v [rad/s] and
    acceleration a [rad/s^2] to reach `target` [rad/s] (continuous time; a discrete step adds
    a few steps): bring a to 0 at the jerk limit, then a jerk-limited trapezoid."""
    jerk, accel = s.max_jerk_rad_s3, s.max_accel_rad_s2
    v1 = v + a * abs(a) / (2 * jerk)
    gap = abs(target - v1)
    move = gap / accel + accel / jerk if gap >= accel**2 / jerk else 2 * math.sqrt(gap / jerk)
    return abs(a) / jerk + move


def _curve(gap: float, jerk: float, dt: float) -> float:
    """Acceleration towards a target `gap` away [rad/s] after which braking at the jerk
    limit lands on it: a^2 / (2 J) + a dt = |gap|, signed like gap."""
    g = abs(gap)
    return math.copysign(-jerk * dt + math.sqrt((jerk * dt) ** 2 + 2 * jerk * g), gap)


@dataclass
class GuardPolicy:
    """The guard's state: tracker, current target and the band cache (`GuardBands` per bin).

    Parameters
    ----------
    settings : GuardSettings
        Policy and limits.
    clock : callable
        Seconds, for the step's own deadline check (`time.monotonic` by default).
    """

    settings: GuardSettings = field(default_factory=GuardSettings)
    clock: Callable[[], float] = time.monotonic
    bands: dict[tuple, GuardBands] = field(default_factory=dict)
    wanted: set[tuple] = field(default_factory=set)
    _v: float = 0.0
    _a: float = 0.0
    _t: float | None = None
    _command: float = 0.0  # last good command
    _deadline: float = math.inf  # reach it by then
    _committed: bool = False
    _aim: float = 0.0  # the last step's target

    def step(
        self,
        now_s: float,
        command_rad_s: float,
        load_n: float | None,
        nut_position_m: float | None,
        input_age_s: float = 0.0,
        arrived_s: float | None = None,
    ) -> GuardStep:
        """The guarded command for one speed command.

        Parameters
        ----------
        now_s : float
            The command's time [s] (its stamp or arrival); steps come in time order.
        command_rad_s : float
            The command [rad/s].
        load_n, nut_position_m : float or None
            The latest axial load [N] and nut position [m] (None: none yet).
        input_age_s : float
            Age of the older of the two [s].
        arrived_s : float, optional
            When the command arrived on `clock` [s]: the step checks its deadline against it.

        Returns
        -------
        GuardStep
            The output and why.
        """
        s = self.settings
        if not s.enabled:
            self._v, self._a, self._t = command_rad_s, 0.0, now_s
            self._aim = command_rad_s
            return GuardStep(command_rad_s, command_rad_s, False, "")
        dt = 0.0 if self._t is None else now_s - self._t
        if not math.isfinite(dt) or dt < 0:
            dt = 0.0  # out of order or broken time: no motion this step
        self._t = now_s if math.isfinite(now_s) else self._t
        reason = fault = ""
        if not isinstance(command_rad_s, (int, float)) or not math.isfinite(command_rad_s):
            reason = f"command {command_rad_s!r} is not a finite number: kept {self._command:g}"
            fault = COMMAND_NOT_FINITE
        else:
            c = max(-s.max_speed_rad_s, min(s.max_speed_rad_s, float(command_rad_s)))
            if c != self._command:
                self._command, self._committed = c, False
                self._deadline = now_s + reach_time(self._v, self._a, c, s) + s.max_delay_s
        c = self._command
        if c == 0.0:
            self._v = self._a = self._aim = 0.0
            return GuardStep(0.0, 0.0, False, reason, stopped=True, fault=fault)
        target, why, failed = self._target(c, load_n, nut_position_m, input_age_s, arrived_s)
        reason, fault = reason or why, fault or failed
        if target != c and dt > 0:  # deflect only while c stays reachable in time
            v, a = self._next(target, dt)
            if now_s + dt + reach_time(v, a, c, s) > self._deadline:
                self._committed = True
        if self._committed:
            target, reason = c, reason or "max_delay_s: reaching the command"
        if dt == 0:
            return GuardStep(self._v, target, target != c, reason, fault=fault)
        v, a = self._next(target, dt)
        self._aim = target
        if v * c < 0 and self._v * c >= 0:  # would cross zero away from the command
            self._v = self._a = 0.0
            return GuardStep(
                0.0, target, target != c, reason or "no reversal", stopped=True, fault=fault
            )
        self._v, self._a = v, a
        return GuardStep(v, target, target != c, reason, fault=fault)

    def _target(
        self,
        c: float,
        load: float | None,
        nut: float | None,
        age: float,
        arrived: float | None,
    ) -> tuple[float, str, str]:
        """The target for command c, why it is not the guarded one ('' when guarded) and the
        fail-safe's kind ('' when no fault)."""
        s = self.settings
        if load is None or nut is None:
            return c, "no load or nut position yet: passed through", NO_INPUT
        if not (math.isfinite(load) and math.isfinite(nut) and math.isfinite(age)):
            return c, "load or nut position not finite: passed through", INPUT_NOT_FINITE
        if age > s.stale_timeout_s:
            return (
                c,
                f"load or nut position older than {s.stale_timeout_s:g} s: passed through",
                INPUT_STALE,
            )
        if arrived is not None and self.clock() - arrived > s.deadline_s:
            return (
                c,
                f"step later than deadline_s = {s.deadline_s:g} s: passed through",
                DEADLINE_MISSED,
            )
        key = band_bin(load, nut, c)
        bands = self.bands.get(key)
        if bands is None:
            self.wanted.add(key)
            return c, "squeak bands of this load and nut position not ready: passed through", ""
        if bands.error:
            return c, f"{bands.error}: passed through", MODEL_ERROR
        w = abs(c)
        for lo, hi in bands.intervals:
            if lo <= w <= hi:
                below = lo * (1 - s.margin)
                above = hi * (1 + s.margin)
                safe = below if above > s.max_speed_rad_s or w - below <= above - w else above
                return (
                    math.copysign(safe, c),
                    f"squeak band {lo:.3g}-{hi:.3g} rad/s avoided",
                    "",
                )
        return c, "", ""

    def _next(self, target: float, dt: float) -> tuple[float, float]:
        """Speed and acceleration after one step of dt towards `target` (limits hold)."""
        s = self.settings
        jerk, accel, vmax = s.max_jerk_rad_s3, s.max_accel_rad_s2, s.max_speed_rad_s
        v, a = self._v, self._a
        lo = max(-accel, a - jerk * dt)
        hi = min(accel, a + jerk * dt)
        # Stay within the braking curves of +-vmax (|v| <= vmax ever after).
        hi = min(hi, max(lo, _curve(vmax - v, jerk, dt)))
        lo = max(lo, min(hi, _curve(-vmax - v, jerk, dt)))
        exact = (target - v) / dt  # lands on the target in this step
        if lo <= exact <= hi and abs(exact) <= jerk * dt:
            return target, exact
        if v == self._aim and lo <= exact <= hi and _within_curve(target, exact, s):
            return target, exact  # on a target that moves within the limits: follow it
        a_new = min(hi, max(lo, _curve(target - v, jerk, dt)))
        return v + a_new * dt, a_new


def _within_curve(v: float, a: float, s: GuardSettings) -> bool:
    """(v, a) can brake at the jerk limit without passing +-max_speed."""
    stop = v + a * abs(a) / (2 * s.max_jerk_rad_s3)
    return abs(stop) <= s.max_speed_rad_s


class BandWorker:
    """Computes the bins a `GuardPolicy` wants (`GuardPolicy.wanted`) with `GuardBands.compute`
    on a background thread and stores them in `GuardPolicy.bands`: a node's steps never
    predict. rclpy-free.

    `poke` after a step wakes the thread when a bin is wanted; it takes the wanted bins one by
    one (a set pop and a dict store: atomic under the GIL, no lock shared with the step) and
    sleeps when none is left. A `compute` that raises is stored as the bin's error (the guard
    passes through there and says why). `close` ends the thread.

    Parameters
    ----------
    policy : GuardPolicy
        Whose bins to compute.
    model : SqueakModel
        The model the bands come from.
    name : str
        The thread's name.
    """

    def __init__(self, policy: GuardPolicy, model: SqueakModel, name: str = "squeak-guard-bands"):
        self.policy, self.model = policy, model
        self.computed = 0  # bins computed (with or without an error)
        self._computing = False
        self._cv = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def poke(self) -> None:
        """Wake the thread if a bin is wanted (cheap: a set's truth value)."""
        if self.policy.wanted:
            with self._cv:
                self._cv.notify()

    @property
    def busy(self) -> bool:
        """A bin is wanted or being computed."""
        return self._computing or bool(self.policy.wanted)

    @property
    def alive(self) -> bool:
        """The thread runs."""
        return self._thread.is_alive()

    def close(self, timeout: float = 5.0) -> None:
        """End the thread (after the bin being computed; joined for at most `timeout` s)."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _run(self) -> None:
        policy = self.policy
        while True:
            with self._cv:
                self._cv.wait_for(lambda: self._closed or bool(policy.wanted))
                if self._closed:
                    return
            self._computing = True
            try:
                key = policy.wanted.pop()
            except KeyError:  # taken meanwhile
                self._computing = False
                continue
            if key not in policy.bands:
                p_max = policy.settings.p_max
                try:
                    bands = GuardBands.compute(self.model, key, p_max)
                except Exception as exc:  # never lost: the bin says why the guard passes
                    bands = GuardBands(key, (), f"squeak band search failed: {exc}")
                policy.bands[key] = bands
                self.computed += 1
            self._computing = False
