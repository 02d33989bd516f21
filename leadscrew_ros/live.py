"""Live prediction logic of the node, free of rclpy: input checks, deadbands, rate limit,
coalescing, last good state, staleness and the diagnostic verdict.

The node feeds it the latest inputs and asks `due(now)`; bursts are coalesced because only the
latest value of each input is kept and one recompute serves all of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

from .model import OperatingPointError, ParameterError, Prediction, SqueakModel
from .model.advice import safe_speed, speed_bands
from .model.predictor import check_operating_point


_LOAD_BIN = 0.05          # relative load bin of the cached squeak bands (safe-speed advice)
_NUT_BIN_M = 0.005        # nut position bin of the cached squeak bands


class Level(IntEnum):
    """diagnostic_msgs/DiagnosticStatus levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class LiveSettings:
    speed_deadband_rad_s: float = 0.1
    load_deadband_n: float = 1.0
    nut_deadband_m: float = 0.0005
    max_rate_hz: float = 100.0
    risk_warn_threshold: float = 0.5
    stale_timeout_s: float = 1.0
    safe_speed_margin: float = 0.05


def moved(point: tuple[float, float, float], last: tuple[float, float, float],
          deadbands) -> bool:
    """(speed, load, nut) moved beyond a deadband from `last` (deadbands: any object with
    speed_deadband_rad_s, load_deadband_n, nut_deadband_m)."""
    limits = (deadbands.speed_deadband_rad_s, deadbands.load_deadband_n,
              deadbands.nut_deadband_m)
    return any(abs(a - b) > lim for a, b, lim in zip(point, last, limits))


@dataclass
class Inputs:
    """Latest accepted value of each input and when it arrived (monotonic seconds)."""

    speed_rad_s: float | None = None
    load_n: float | None = None
    nut_position_m: float | None = None
    speed_time: float = -math.inf
    load_time: float = -math.inf


@dataclass(frozen=True)
class Status:
    level: Level
    message: str
    values: dict[str, str] = field(default_factory=dict)


class LivePredictor:
    def __init__(self, model: SqueakModel, settings: LiveSettings = LiveSettings()):
        self.model = model
        self._nut_model = model                        # model at the nut position in use
        self.settings = settings
        self.inputs = Inputs()
        self.prediction: Prediction | None = None        # last good (valid) prediction
        self.safe_speed_rad_s: float | None = None
        self.recomputes = 0
        self._computed_at: tuple[float, float, float] | None = None  # speed, load, nut
        self._last_update = -math.inf
        self._input_errors: dict[str, str] = {}        # input -> why its latest value was
                                                       # rejected, until a good one arrives
        self._validity = ""                            # why the latest point has no prediction
        self._bands: dict[tuple, list[tuple[float, float]]] = {}

    # ---------------------------------------------------------------- inputs
    def set_speed(self, value: object, now: float) -> str:
        """Accept a speed (rad/s); returns '' or why it was rejected."""
        return self._accept("speed", value, now)

    def set_load(self, value: object, now: float) -> str:
        return self._accept("load", value, now)

    def set_nut_position(self, value: object, now: float) -> str:
        """Nut position z_o along the screw (m), 0 <= z_o <= L - b."""
        p = self.model.params
        try:
            z = float(value)                                        # type: ignore[arg-type]
        except (TypeError, ValueError, OverflowError):             # OverflowError: huge int
            return self._reject("nut", f"nut position {value!r} is not a number")
        if not (math.isfinite(z) and 0.0 <= z <= p.length_m - p.nut_length_m):
            return self._reject("nut", f"nut position {z:g} m is off the screw: allowed "
                                       f"[0, {p.length_m - p.nut_length_m:g}] m (z_o + b <= L)")
        self.inputs.nut_position_m = z
        self._input_errors.pop("nut", None)
        return ""

    def _accept(self, kind: str, value: object, now: float) -> str:
        try:
            if kind == "speed":
                v, _ = check_operating_point(value, 0.0)
            else:
                _, v = check_operating_point(0.0, value)
        except OperatingPointError as exc:
            return self._reject(kind, str(exc))
        if kind == "speed":
            self.inputs.speed_rad_s, self.inputs.speed_time = v, now
        else:
            self.inputs.load_n, self.inputs.load_time = v, now
        self._input_errors.pop(kind, None)
        return ""

    def _reject(self, kind: str, reason: str) -> str:
        self._input_errors[kind] = reason
        return reason

    # ---------------------------------------------------------------- model
    def set_model(self, model: SqueakModel, settings: LiveSettings | None = None) -> None:
        """New parameters: the next `due` is true and recomputes with them."""
        self.model, self.settings = model, settings or self.settings
        self._nut_model = model
        self._computed_at, self._bands = None, {}

    def _operating_point(self) -> tuple[float, float, float] | None:
        i = self.inputs
        if i.speed_rad_s is None or i.load_n is None:
            return None
        nut = self.model.params.nut_position_m if i.nut_position_m is None else i.nut_position_m
        return i.speed_rad_s, i.load_n, nut

    def changed(self) -> bool:
        """The operating point moved beyond a deadband since the last recompute."""
        point = self._operating_point()
        if point is None:
            return False
        return self._computed_at is None or moved(point, self._computed_at, self.settings)

    def due(self, now: float) -> bool:
        """A change is waiting and the rate limit allows a recompute now."""
        return self.changed() and now - self._last_update >= 1.0 / self.settings.max_rate_hz

    def update(self, now: float) -> Prediction | None:
        """Recompute at the latest inputs. Returns the new prediction, or None when the point
        is outside the model's validity (the last good prediction is kept)."""
        point = self._operating_point()
        if point is None:
            return None
        speed, load, nut = point
        self._computed_at, self._last_update = point, now
        self.recomputes += 1
        model = self._model_at(nut)
        if model is None:
            return None
        p = model.predict(speed, load)
        self._validity = p.reason
        if not p.valid:
            return None
        self.prediction = p
        self.safe_speed_rad_s = self._safe_speed(model, p)
        return p

    def _model_at(self, nut: float) -> SqueakModel | None:
        """The model with the contact at the nut; rebuilt (contact re-integrated) only when the
        nut moved more than nut_deadband_m from where the current one was built."""
        if abs(nut - self._nut_model.params.nut_position_m) <= self.settings.nut_deadband_m:
            return self._nut_model
        try:                            # geometry is cached: a revisited position is free
            self._nut_model = self.model.with_params(nut_position_m=nut)
        except ParameterError as exc:
            self._validity = f"nut position {nut:g} m: {exc}"
            return None
        return self._nut_model

    def _safe_speed(self, model: SqueakModel, p: Prediction) -> float:
        if p.stable:
            return p.speed_rad_s
        # Band edges move slowly with load and nut position: reuse them within a bin (one band
        # computation costs ~15 ms, a recompute ~0.4 ms).
        load_bin = round(math.log(abs(p.load_n)) / math.log(1 + _LOAD_BIN)) if p.load_n else None
        key = (load_bin, round(model.params.nut_position_m / _NUT_BIN_M),
               math.copysign(1, p.speed_rad_s))
        if key not in self._bands:
            self._bands = {key: speed_bands(model, p.load_n, p.speed_rad_s)}   # keep one
        return safe_speed(self._bands[key], p.speed_rad_s, model.params.min_speed_rad_s,
                          model.critical_speed_rad_s, self.settings.safe_speed_margin)

    # ---------------------------------------------------------------- verdict
    def status(self, now: float) -> Status:
        i, s, p = self.inputs, self.settings, self.prediction
        values = {
            "speed_rad_s": _fmt(i.speed_rad_s), "load_n": _fmt(i.load_n),
            "nut_position_m": _fmt(self.model.params.nut_position_m if i.nut_position_m is None
                                   else i.nut_position_m),
            "formulation": self.model.params.formulation,
            "valid": str(p is not None and not self._validity).lower(),
            "risk": _fmt(p.risk if p else None),
            "max_growth_rate_1_s": _fmt(p.max_growth_rate if p else None),
            "squeak_frequencies_hz": ", ".join(f"{f:.1f}" for f in p.unstable_frequencies_hz)
            if p else "",
            "safe_speed_rad_s": _fmt(self.safe_speed_rad_s),
            "recomputes": str(self.recomputes),
        }
        if self._input_errors:
            errors = "; ".join(self._input_errors.values())
            return Status(Level.ERROR, f"invalid input: {errors}", values)
        stale = [n for n, t in (("motor_speed", i.speed_time), ("axial_load", i.load_time))
                 if now - t > s.stale_timeout_s]
        if stale:
            return Status(Level.STALE, f"no fresh input on {', '.join(stale)} for more than "
                                       f"{s.stale_timeout_s:g} s", values)
        if self._validity:
            return Status(Level.WARN, f"no prediction: {self._validity}", values)
        if p is None:
            return Status(Level.STALE, "waiting for the first prediction", values)
        if not p.stable:
            squeak = ", ".join(f"{m.label} {m.frequency_hz:.0f} Hz" for m in p.squeak_modes)
            return Status(Level.ERROR, f"squeak predicted: {squeak or 'divergence'}", values)
        if p.risk > s.risk_warn_threshold:
            return Status(Level.WARN, f"squeak risk {p.risk:.2f} above "
                                      f"{s.risk_warn_threshold:g}", values)
        return Status(Level.OK, f"no squeak (risk {p.risk:.2f})", values)


def _fmt(v: float | None) -> str:
    return "" if v is None else f"{v:.6g}"
