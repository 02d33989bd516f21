"""Operating-point timeline of a replayed log: input messages -> latest speed, load and nut
position -> recompute decisions with the node's deadbands -> batched predictions.

rclpy-free (prediction workers import it). The rules follow the node (`live.py`, `node.py`):
a rejected value (NaN, inf, |F_z| > 1e7 N, nut off the screw) keeps the previous one; nothing
is predicted before both a speed and a load are known; the nut defaults to the model's
`nut_position_m`; a JointState sets the speed from the joint's velocity and the nut from its
angle, `nut_position_at_zero_angle_m + angle * R tan(beta)`, and counts as one input. A
recompute happens when the point moved beyond a deadband from the last recomputed one (offline
there is no rate limit); the contact is re-integrated only when the nut moved more than the nut
deadband from where it was last integrated (geometries are cached per process, so positions
that strokes revisit, e.g. on an encoder's grid, cost nothing the second time).
"""

from __future__ import annotations

import math
from array import array
from collections import Counter, OrderedDict
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .cdr import decode_float64, decode_joint_state
from .live import LiveSettings, moved
from .logfile import LogMessage
from .model import ParameterError, Prediction, ScrewParameters, SqueakModel
from .model.parameters import field_info

FLOAT64, JOINT_STATE = "std_msgs/msg/Float64", "sensor_msgs/msg/JointState"
NUT_POSITION_AT_ZERO_ANGLE_M = 0.15          # the node's parameter default
_MODEL_CACHE = 1024                          # nut positions kept per process (~60 kB each)
_LOAD_LIMIT_N = field_info("axial_load_n")["hi"]    # as the node's input check


class InputError(ValueError):
    """An input topic whose type is not the one the input needs."""


@dataclass(frozen=True)
class InputSettings:
    """Where the inputs are in the log and when to recompute (node parameter names in SI)."""

    speed_topic: str = "/motor_speed"                   # std_msgs/Float64, rad/s
    load_topic: str = "/axial_load"                     # std_msgs/Float64, N
    nut_topic: str = "/nut_position"                    # std_msgs/Float64, m
    joint_states_topic: str = "/joint_states"           # sensor_msgs/JointState
    joint_name: str = ""                # '' : the joint of single-joint messages
    nut_position_at_zero_angle_m: float = NUT_POSITION_AT_ZERO_ANGLE_M
    speed_deadband_rad_s: float = LiveSettings.speed_deadband_rad_s
    load_deadband_n: float = LiveSettings.load_deadband_n
    nut_deadband_m: float = LiveSettings.nut_deadband_m

    def __post_init__(self) -> None:
        topics = (self.speed_topic, self.load_topic, self.nut_topic, self.joint_states_topic)
        if not all(t.startswith("/") for t in topics) or len(set(topics)) < len(topics):
            raise ValueError(f"input topics must be distinct absolute names, got "
                             f"{', '.join(topics)}")
        for name in ("speed_deadband_rad_s", "load_deadband_n", "nut_deadband_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not math.isfinite(self.nut_position_at_zero_angle_m):
            raise ValueError("nut_position_at_zero_angle_m must be finite")


@dataclass(frozen=True)
class Job:
    """A recompute: the operating point and the nut position the contact is integrated at."""

    index: int              # of the triggering message in its segment
    log_time_ns: int
    speed_rad_s: float
    load_n: float
    nut_position_m: float   # true nut position
    model_nut_m: float      # where the contact is integrated


class Timeline:
    """Feeds messages in log order; `feed` returns the operating point to recompute, if any."""

    def __init__(self, params: ScrewParameters, settings: InputSettings = InputSettings()):
        self.settings = settings
        self.lead_m_per_rad = params.radius_m * math.tan(params.helix_angle_rad)
        self.nut_max_m = params.length_m - params.nut_length_m
        self.speed: float | None = None
        self.load: float | None = None
        self.nut = params.nut_position_m                   # until a nut input arrives
        self._model_nut_m = params.nut_position_m          # where the contact is integrated
        self._computed_at: tuple[float, float, float] | None = None
        self.inputs: Counter[str] = Counter()              # accepted-or-not input messages
        self.rejected: Counter[str] = Counter()            # values not taken, by reason
        self.ignored: Counter[str] = Counter()             # messages without the joint
        self.recomputes = 0
        # The point after every input message (NaN: not known yet), for the report.
        self.time_ns, self.speeds, self.loads, self.nuts = (array("q"), array("d"),
                                                            array("d"), array("d"))
        s = settings
        self._routes: dict[str, tuple[str, Callable[[bytes], bool]]] = {
            s.speed_topic: (FLOAT64, self._on_speed), s.load_topic: (FLOAT64, self._on_load),
            s.nut_topic: (FLOAT64, self._on_nut),
            s.joint_states_topic: (JOINT_STATE, self._on_joint_states)}
        self._handlers: dict[tuple[str, str], Callable[[bytes], bool] | None] = {}

    @property
    def topics(self) -> list[str]:
        """Every topic seen so far."""
        return sorted({name for name, _ in self._handlers})

    # ------------------------------------------------------------------ feeding
    def feed(self, m: LogMessage, index: int) -> Job | None:
        key = (m.topic.name, m.topic.type_name)
        handler = self._handlers.get(key, False)
        if handler is False:
            handler = self._handlers[key] = self._handler(*key)
        if handler is None:
            return None
        self.inputs[m.topic.name] += 1
        try:
            accepted = handler(m.data)
        except ValueError:
            self.rejected[f"{m.topic.name}: undecodable payload"] += 1
            accepted = False
        nan = math.nan
        self.time_ns.append(m.log_time_ns)
        self.speeds.append(nan if self.speed is None else self.speed)
        self.loads.append(nan if self.load is None else self.load)
        self.nuts.append(self.nut)
        return self._recompute(index, m.log_time_ns) if accepted else None

    def _handler(self, topic: str, type_name: str) -> Callable[[bytes], bool] | None:
        route = self._routes.get(topic)
        if route is None:
            return None
        if type_name != route[0]:
            raise InputError(f"topic {topic} is {type_name}, expected {route[0]}")
        return route[1]

    def _on_speed(self, data: bytes) -> bool:
        return self._set_speed(decode_float64(data))

    def _on_load(self, data: bytes) -> bool:
        value = decode_float64(data)
        if not math.isfinite(value):
            self.rejected["load not finite"] += 1
            return False
        if abs(value) > _LOAD_LIMIT_N:
            self.rejected[f"load beyond {_LOAD_LIMIT_N:g} N"] += 1
            return False
        self.load = value
        return True

    def _on_nut(self, data: bytes) -> bool:
        return self._set_nut(decode_float64(data))

    def _on_joint_states(self, data: bytes) -> bool:
        js = decode_joint_state(data)
        name = self.settings.joint_name
        if name:
            if name not in js.name:
                self.ignored[f"joint_states without joint {name!r}"] += 1
                return False
            i = js.name.index(name)
        elif len(js.name) == 1:
            i = 0
        else:
            self.ignored[f"joint_states with {len(js.name)} joints and no --joint-name"] += 1
            return False
        # Both first, then one recompute decision, none if a value was rejected (as the node).
        taken = []
        if i < len(js.velocity):
            taken.append(self._set_speed(js.velocity[i]))
        if i < len(js.position):
            taken.append(self._set_nut(self.settings.nut_position_at_zero_angle_m
                                       + js.position[i] * self.lead_m_per_rad))
        return bool(taken) and all(taken)

    def _set_speed(self, value: float) -> bool:
        if not math.isfinite(value):
            self.rejected["speed not finite"] += 1
            return False
        self.speed = value
        return True

    def _set_nut(self, value: float) -> bool:
        if not (math.isfinite(value) and 0.0 <= value <= self.nut_max_m):
            self.rejected[f"nut position off the screw [0, {self.nut_max_m:g}] m"] += 1
            return False
        self.nut = value
        return True

    # ------------------------------------------------------------------ coalescing
    def _recompute(self, index: int, log_time_ns: int) -> Job | None:
        if self.speed is None or self.load is None:
            return None
        point = (self.speed, self.load, self.nut)
        if self._computed_at is not None and not moved(point, self._computed_at, self.settings):
            return None
        self._computed_at = point
        self.recomputes += 1
        return Job(index, log_time_ns, *point, self._model_nut(point[2]))

    def _model_nut(self, nut: float) -> float:
        if abs(nut - self._model_nut_m) > self.settings.nut_deadband_m:
            self._model_nut_m = nut
        return self._model_nut_m


# ---------------------------------------------------------------------- predictions
_models: OrderedDict[tuple[ScrewParameters, float], SqueakModel | None] = OrderedDict()


def _model_at(params: ScrewParameters, nut: float) -> SqueakModel | None:
    """The model with the contact at `nut` (None if the parameters reject it), cached."""
    key = (params, nut)
    if key in _models:
        _models.move_to_end(key)
        return _models[key]
    try:
        model = SqueakModel(params.with_(nut_position_m=nut))
    except ParameterError:
        model = None
    _models[key] = model
    if len(_models) > _MODEL_CACHE:
        _models.popitem(last=False)
    return model


def predict_jobs(params: ScrewParameters, speeds: np.ndarray, loads: np.ndarray,
                 model_nuts: np.ndarray) -> list[Prediction]:
    """Predictions at the jobs' operating points: one batched eigen-solve per nut position.
    Outside validity a prediction has `valid=False` and the reason."""
    out: list[Prediction | None] = [None] * len(speeds)
    nuts, inverse = np.unique(model_nuts, return_inverse=True)
    for k, nut in enumerate(nuts.tolist()):
        idx = np.flatnonzero(inverse == k)
        model = _model_at(params, nut)
        if model is None:
            preds = [Prediction(float(speeds[i]), float(loads[i]), params.formulation, False,
                                f"nut position {nut:g} m is not allowed by the parameters")
                     for i in idx]
        else:
            preds = model.predict_many(speeds[idx], loads[idx])
        for i, p in zip(idx.tolist(), preds):
            out[i] = p
    return out
