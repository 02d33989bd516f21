# SPDX-License-Identifier: Apache-2.0
"""Live prediction logic of the node, free of rclpy: rate limit, coalescing, last good state,
staleness and the diagnostic verdict around the input rules (`live.rules`: input checks,
JointState mapping, deadbands, contact re-integration; shared with the offline replay).

The node feeds it the latest inputs and asks `due(now)`; bursts are coalesced because only the
latest value of each input is kept and one recompute serves all of them.

Safe-speed advice needs the squeak band around the speed, where P(squeak) >= safe_probability
(`model.studies.advice`: tens of predictions, a few seconds with 40/40 modes), so it is searched on
a background thread (`LatestWorker`): a recompute never
waits for it, the last advice stays until the new one is ready, and `poll_advice` (or
`wait_for_advice`, for callers that want the answer now) picks it up.

A process with a LivePredictor runs BLAS single-threaded: its eigenproblems (2N <= 240) gain
nothing from BLAS threads, and two threads solving at once through one OpenBLAS thread pool
thrash (measured with 40/40 modes on 2 cores: a 240x240 `eig` takes 21 ms single-threaded,
29 ms with 2 BLAS threads; with a band search on the other thread predictions took 0.44 s
(median) instead of 0.08 s, and 0.4-2 s each with the machine busy).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import cast

from threadpoolctl import threadpool_limits

from ..model import ParameterError, Prediction, SqueakModel, Validity
from ..model.studies.advice import Band, band_around
from .rules import InputRules, Inputs, Outcome
from .settings import JointSettings, LiveSettings
from .status import (
    KEY_FORMULATION,
    KEY_LOAD,
    KEY_MARGIN,
    KEY_MAX_GROWTH_RATE,
    KEY_NUT_POSITION,
    KEY_PROBABILITY,
    KEY_PROBABILITY_STDERR,
    KEY_RECOMPUTES,
    KEY_SAFE_SPEED,
    KEY_SAFE_SPEED_ERROR,
    KEY_SAFE_SPEED_PENDING,
    KEY_SPEED,
    KEY_SQUEAK_FREQUENCIES,
    KEY_VALID,
    KEY_VALIDITY,
    Level,
    Status,
    prediction_status,
    value_text,
)

_LOAD_BIN = 0.05  # relative load bin of the cached squeak bands (safe-speed advice)
_NUT_BIN_M = 0.005  # nut position bin of the cached squeak bands
_BANDS_KEPT = 4  # bands kept for the current bin (speeds moving around within it)
_MAX_DUTY_RATIO = 2.0  # recomputes start at least this many prediction times apart


def band_bin(load_n: float, nut_position_m: float, speed_rad_s: float) -> tuple:
    """The bin of cached squeak bands an operating point falls in: band edges move slowly with
    load and nut position, so bands are reused within a bin (relative load bin _LOAD_BIN, nut
    bin _NUT_BIN_M, direction of rotation).

    Parameters
    ----------
    load_n : float
        Axial load [N] (finite).
    nut_position_m : float
        Nut position [m] (finite).
    speed_rad_s : float
        Speed [rad/s]: its sign is the direction.

    Returns
    -------
    tuple
        (load bin or None for no load, nut bin, direction +-1.0).
    """
    load_bin = round(math.log(abs(load_n)) / math.log(1 + _LOAD_BIN)) if load_n else None
    return (load_bin, round(nut_position_m / _NUT_BIN_M), math.copysign(1.0, speed_rad_s))


def bin_centre(key: tuple) -> tuple[float, float, float]:
    """Load [N], nut position [m] and direction (+-1) at the centre of a `band_bin`."""
    load_bin, nut_bin, direction = key
    load = 0.0 if load_bin is None else (1 + _LOAD_BIN) ** load_bin
    return load, nut_bin * _NUT_BIN_M, direction


class Superseded(Exception):
    """Raised at a checkpoint of a background job that a newer request replaced."""


class LatestWorker:
    """Runs one job at a time on a background thread; the latest request wins: a new one
    replaces a waiting one and abandons a running one at its next checkpoint, so no queue
    grows. rclpy-free.

    The thread starts with a request and ends when nothing is left to do, so an idle worker
    holds no thread; it is a daemon and never keeps the process alive. It runs at the normal
    priority: a lower one (nice) starved it while it held the GIL on a busy machine, and the
    executor waited for the GIL (measured: 3.7 s without a prediction)."""

    def __init__(self, name: str = "squeak-advice"):
        self._name = name
        self._cv = threading.Condition()
        self._latest = 0  # id of the newest request
        self._waiting: tuple[int, Callable] | None = None  # request not started yet
        self._running = False
        self._done: tuple[int, object, Exception | None] | None = None
        self._thread: threading.Thread | None = None
        self._closed = False

    def submit(self, job: Callable[[Callable[[], None]], object]) -> int:
        """Run `job(checkpoint)` in the background (checkpoint raises `Superseded` once the
        request is stale); returns the request's id. Any older request is dropped."""
        with self._cv:
            self._latest += 1
            self._done = None
            if self._closed:
                return self._latest
            self._waiting = (self._latest, job)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
                self._thread.start()
            self._cv.notify_all()
            return self._latest

    def cancel(self) -> None:
        """Drop the waiting request and abandon the running one."""
        with self._cv:
            self._latest += 1
            self._waiting = self._done = None
            self._cv.notify_all()

    def take(self) -> tuple[int, object, Exception | None] | None:
        """The finished latest request (id, result, error), once; None if there is none."""
        with self._cv:
            done, self._done = self._done, None
            return done

    @property
    def busy(self) -> bool:
        """True while a request waits or runs."""
        with self._cv:
            return self._waiting is not None or self._running

    def wait(self, timeout: float | None = None) -> bool:
        """Block until no request waits or runs; False if `timeout` (s) passed first."""
        with self._cv:
            return self._cv.wait_for(lambda: self._waiting is None and not self._running, timeout)

    def close(self, timeout: float = 1.0) -> None:
        """Abandon all work and let the thread end (joined for at most `timeout` s)."""
        with self._cv:
            self._closed = True
            self._latest += 1
            self._waiting = self._done = None
            thread = self._thread
            self._cv.notify_all()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)

    def _checkpoint(self, ident: int) -> None:
        if ident != self._latest:  # an int read: atomic, no lock on the hot path
            raise Superseded

    def _run(self) -> None:
        while True:
            with self._cv:
                if self._waiting is None:
                    self._thread, self._running = None, False
                    self._cv.notify_all()
                    return
                (ident, job), self._waiting, self._running = self._waiting, None, True
            try:
                result, error = job(partial(self._checkpoint, ident)), None
            except Superseded:
                continue
            except Exception as exc:  # reported through take(), never lost silently
                result, error = None, exc
            with self._cv:
                self._running = False
                if ident == self._latest:
                    self._done = (ident, result, error)
                self._cv.notify_all()


_blas_limited = False


def _single_threaded_blas() -> None:
    """Limit BLAS to one thread for this process, once (see the module docstring)."""
    global _blas_limited
    if not _blas_limited:
        threadpool_limits(limits=1, user_api="blas")
        _blas_limited = True


class LivePredictor:
    """The node's prediction logic without rclpy: takes the inputs, decides when to recompute
    (deadbands, rate limit, coalescing), keeps the last good prediction and the safe-speed
    advice, and gives the diagnostic verdict (`status`). Times `now` are the policy's clock
    [s].

    Parameters
    ----------
    model : SqueakModel
        The model (parameters, scatter) predictions are made with.
    settings : LiveSettings
        Deadbands, rate limit, thresholds of the verdict.
    clock : callable
        Seconds; times each prediction for the recompute interval.
    joints : JointSettings
        The screw joint of JointState inputs.
    """

    def __init__(
        self,
        model: SqueakModel,
        settings: LiveSettings = LiveSettings(),
        clock: Callable[[], float] = time.perf_counter,
        joints: JointSettings = JointSettings(),
    ):
        _single_threaded_blas()
        self.model = model
        self._nut_model = model  # model at the contact's nut position
        self.settings = settings
        self.rules = InputRules(model.params, settings, joints)
        self._arrived = {"speed": -math.inf, "load": -math.inf}  # input -> when last taken
        self.prediction: Prediction | None = None  # last good (valid) prediction
        self.safe_speed_rad_s: float | None = None  # last advice, kept while a new one
        #                                                   is searched in the background
        self.recomputes = 0
        self._last_update = -math.inf
        self._clock = clock
        self._cost_s = 0.0  # how long the last prediction took
        self._validity: Validity | None = None  # verdict at the latest point
        self._invalid_reason = ""  # why it has no prediction
        self._bands: dict[tuple, list[Band]] = {}  # one bin: bands found in it
        self._advised: tuple[SqueakModel, Prediction] | None = None  # what advice is for
        self._search: tuple[int, tuple] | None = None  # background request: id, bin key
        self._pending = False  # latest prediction waits for it
        self._failed: tuple | None = None  # bin whose search raised
        self._advice_error = ""
        self._worker = LatestWorker()

    # ---------------------------------------------------------------- inputs
    @property
    def inputs(self) -> Inputs:
        """The latest value taken of each input."""
        return self.rules.inputs

    def set_speed(self, value: object, now: float) -> str:
        """Take a speed.

        Parameters
        ----------
        value : object
            Speed Omega [rad/s], as received.
        now : float
            When it arrived [s, the policy's clock].

        Returns
        -------
        str
            '' when taken, else why it was rejected.
        """
        return self._arrive(self.rules.set_speed(value), now).error

    def set_load(self, value: object, now: float) -> str:
        """Take an axial load.

        Parameters
        ----------
        value : object
            Axial load F_z [N], as received.
        now : float
            When it arrived [s, the policy's clock].

        Returns
        -------
        str
            '' when taken, else why it was rejected.
        """
        return self._arrive(self.rules.set_load(value), now).error

    def set_nut_position(self, value: object, now: float) -> str:
        """Take a nut position.

        Parameters
        ----------
        value : object
            Nut position z_o [m], 0 <= z_o <= L - b, as received.
        now : float
            When it arrived [s, the policy's clock].

        Returns
        -------
        str
            '' when taken, else why it was rejected.
        """
        return self._arrive(self.rules.set_nut_position(value), now).error

    def set_joint_state(
        self,
        names: Sequence[str],
        positions: Sequence[float],
        velocities: Sequence[float],
        now: float,
        joints: JointSettings | None = None,
    ) -> Outcome:
        """Take the screw joint's speed and nut position of a JointState
        (`rules.InputRules.set_joint_state`).

        Parameters
        ----------
        names, positions, velocities : sequence
            The JointState's fields.
        now : float
            When it arrived [s, the policy's clock].
        joints : JointSettings, optional
            Replaces the joint settings first.

        Returns
        -------
        Outcome
            What was taken, and what was rejected or ignored and why.
        """
        if joints is not None:
            self.rules.joints = joints
        return self._arrive(self.rules.set_joint_state(names, positions, velocities), now)

    def _arrive(self, outcome: Outcome, now: float) -> Outcome:
        for kind in outcome.taken:
            if kind in self._arrived:
                self._arrived[kind] = now
        return outcome

    # ---------------------------------------------------------------- model
    def set_model(self, model: SqueakModel, settings: LiveSettings | None = None) -> None:
        """New parameters: the next `due` is true and recomputes with them.

        Parameters
        ----------
        model : SqueakModel
            The new model.
        settings : LiveSettings, optional
            New settings; default: keep them.
        """
        self.model, self.settings = model, settings or self.settings
        self._nut_model = model
        self.rules.reset(model.params, self.settings)
        self._bands = {}
        self._worker.cancel()
        self._search = self._failed = None
        self._pending = False

    def changed(self) -> bool:
        """Whether the operating point moved beyond a deadband since the last recompute.

        Returns
        -------
        bool
            True when a recompute would give something new.
        """
        return self.rules.changed()

    @property
    def min_interval_s(self) -> float:
        """Shortest time from one recompute's start to the next: 1 / max_rate_hz, and at least
        _MAX_DUTY_RATIO times the last prediction (with 40/40 modes one takes 20-80 ms: back to
        back they would leave parameter services and diagnostics no room)."""
        return max(1.0 / self.settings.max_rate_hz, _MAX_DUTY_RATIO * self._cost_s)

    def due(self, now: float) -> bool:
        """Whether a change is waiting and the rate limit allows a recompute now.

        Parameters
        ----------
        now : float
            The policy's time [s].

        Returns
        -------
        bool
            True: call `update`.
        """
        return self.changed() and now - self._last_update >= self.min_interval_s

    def update(self, now: float) -> Prediction | None:
        """Recompute at the latest inputs.

        Parameters
        ----------
        now : float
            The policy's time [s].

        Returns
        -------
        Prediction or None
            The new prediction, or None when the point is outside the model's validity (the
            last good prediction is kept).
        """
        computed = self.rules.compute()
        if computed is None:
            return None
        (speed, load, _), contact_nut_m = computed
        self._last_update = now
        self.recomputes += 1
        model = self._model_at(contact_nut_m)
        if model is None:
            return None
        start = self._clock()
        p = model.predict(speed, load)
        self._cost_s = self._clock() - start
        self._validity, self._invalid_reason = p.validity, p.reason
        if not p.valid:
            return None
        self.prediction = p
        self._advise(model, p)
        return p

    def _model_at(self, nut: float) -> SqueakModel | None:
        """The model with the contact at `nut` (the rules move it only beyond nut_deadband_m);
        rebuilt only when that moved."""
        if nut == self._nut_model.params.nut_position_m:
            return self._nut_model
        try:  # geometry is cached: a revisited position is free
            self._nut_model = self.model.with_params(nut_position_m=nut)
        except ParameterError as exc:
            self._validity = Validity.PARAMETERS_REJECTED
            self._invalid_reason = f"nut position {nut:g} m: {exc}"
            return None
        return self._nut_model

    # ---------------------------------------------------------------- safe-speed advice
    @property
    def advice_pending(self) -> bool:
        """A background search for the latest prediction's advice is under way; until it
        ends `safe_speed_rad_s` is the previous advice."""
        return self._pending

    def _advise(self, model: SqueakModel, p: Prediction) -> None:
        """Advice for the latest prediction: at once when the point is safe (P(squeak) below
        safe_probability) or a band found earlier in its bin decides it; else from a
        background search."""
        self._collect()
        self._advised = (model, p)
        assert p.probability is not None, "advice is for valid predictions"
        if p.probability < self.settings.safe_probability:
            return self._set_advice(p.speed_rad_s, None)
        lowest, highest = model.params.min_speed_rad_s, model.critical_speed_rad_s
        margin = self.settings.safe_speed_margin
        key = band_bin(p.load_n, model.params.nut_position_m, p.speed_rad_s)
        for band in self._bands.get(key, ()):
            safe = band.safe_speed(p.speed_rad_s, lowest, highest, margin)
            if safe is not None:
                return self._set_advice(safe, key)
        if key == self._failed:  # keep the last advice; no retry within this bin
            self._pending = False
            return
        self._pending = True
        if self._search is not None and self._search[1] == key:
            return  # a search of this bin is under way: re-checked when it ends
        known = next((b for b in self._bands.get(key, ()) if b.contains(p.speed_rad_s)), None)
        # predict is thread-safe: the search shares the executor's model (and its samples)
        job = partial(
            band_around,
            model,
            p.load_n,
            p.speed_rad_s,
            margin,
            known=known,
            safe_probability=self.settings.safe_probability,
        )
        self._search = (self._worker.submit(lambda checkpoint: job(checkpoint=checkpoint)), key)

    def _set_advice(self, safe_speed_rad_s: float, key: tuple | None) -> None:
        """Advice decided now; a search of another bin is stale and cancelled, one of this
        bin goes on (it extends the band: the next speeds in it are then decided at once)."""
        self.safe_speed_rad_s, self._pending = safe_speed_rad_s, False
        if self._search is not None and self._search[1] != key:
            self._worker.cancel()
            self._search = None

    def _collect(self) -> bool:
        """Store the band of a finished search (non-blocking); True if one arrived."""
        done = self._worker.take()
        if done is None or self._search is None or done[0] != self._search[0]:
            return False
        (_, found, error), key = done, self._search[1]
        band = cast("Band | None", found)  # what the search (`band_around`) returns
        self._search = None
        if error is not None:  # keep the last advice; no retry within this bin
            self._failed, self._advice_error = key, f"safe-speed search failed: {error}"
        elif band is not None:  # None only for a safe point, which `_advise` never searches
            others = [
                b
                for b in self._bands.get(key, ())  # minus the one it extends
                if not band.low_rad_s <= b.low_rad_s <= b.high_rad_s <= band.high_rad_s
            ]
            self._bands = {key: ([band] + others)[:_BANDS_KEPT]}
            self._advice_error = ""
        return True

    def poll_advice(self) -> bool:
        """Pick up a finished background search without blocking.

        Returns
        -------
        bool
            True when the latest prediction got its advice from it (publish
            `safe_speed_rad_s` then).
        """
        waiting = self._pending
        if not self._collect() or self._advised is None:
            return False
        self._advise(*self._advised)  # the speed may have moved on: maybe search again
        return waiting and not self._pending

    def wait_for_advice(self, timeout: float | None = None) -> bool:
        """Block until the latest prediction's advice is ready (synchronous callers, tests).

        Parameters
        ----------
        timeout : float, optional
            At most this long [s]; default: as long as it takes.

        Returns
        -------
        bool
            False if `timeout` passed first.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.advice_pending:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not self._worker.wait(remaining):
                return False
            if not self._collect():  # nothing came back (closed worker): stop waiting
                self._search, self._pending = None, False
            elif self._advised is not None:
                self._advise(*self._advised)
        return True

    def close(self) -> None:
        """Stop the background search (the owner is shutting down)."""
        self._worker.close()
        self._search, self._pending = None, False

    # ---------------------------------------------------------------- verdict
    def status(self, now: float) -> Status:
        """The diagnostic verdict: level, message and the key-value pairs of /diagnostics.

        Parameters
        ----------
        now : float
            The policy's time [s] (staleness of the inputs).

        Returns
        -------
        Status
            Level, message and values.
        """
        i, s, p = self.inputs, self.settings, self.prediction
        arrived = self._arrived
        valid = p is not None and self._validity in (None, Validity.OK)
        values = {
            KEY_SPEED: value_text(i.speed_rad_s),
            KEY_LOAD: value_text(i.load_n),
            KEY_NUT_POSITION: value_text(self.rules.nut_position_m),
            KEY_FORMULATION: self.model.params.formulation,
            KEY_VALID: str(valid).lower(),
            KEY_VALIDITY: "" if self._validity is None else self._validity.name,
            KEY_PROBABILITY: value_text(p.probability if p else None),
            KEY_PROBABILITY_STDERR: value_text(p.probability_stderr if p else None),
            KEY_MARGIN: value_text(p.margin if p else None),
            KEY_MAX_GROWTH_RATE: value_text(p.max_growth_rate if p else None),
            KEY_SQUEAK_FREQUENCIES: ", ".join(f"{f:.1f}" for f in p.unstable_frequencies_hz)
            if p
            else "",
            KEY_SAFE_SPEED: value_text(self.safe_speed_rad_s),
            KEY_SAFE_SPEED_PENDING: str(self.advice_pending).lower(),
            KEY_SAFE_SPEED_ERROR: self._advice_error,
            KEY_RECOMPUTES: str(self.recomputes),
        }
        if self.rules.errors:
            errors = "; ".join(r.message for r in self.rules.errors.values())
            return Status(Level.ERROR, f"invalid input: {errors}", values)
        stale = [
            n
            for n, t in (("motor_speed", arrived["speed"]), ("axial_load", arrived["load"]))
            if now - t > s.stale_timeout_s
        ]
        if stale:
            return Status(
                Level.STALE,
                f"no fresh input on {', '.join(stale)} for more than {s.stale_timeout_s:g} s",
                values,
            )
        if self._validity not in (None, Validity.OK):
            return Status(Level.WARN, f"no prediction: {self._invalid_reason}", values)
        if p is None:
            return Status(Level.STALE, "waiting for the first prediction", values)
        return prediction_status(p, s, values)
