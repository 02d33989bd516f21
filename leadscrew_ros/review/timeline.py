# SPDX-License-Identifier: Apache-2.0
"""Operating-point timeline of a replayed log: input messages -> latest speed, load and nut
position -> recompute decisions with the node's deadbands -> batched predictions.

rclpy-free (prediction workers import it). The rules follow the node (`live.py`, `node.py`):
a rejected value (NaN, inf, |F_z| > 1e7 N, nut off the screw) keeps the previous one; nothing
is predicted before both a speed and a load are known (`nominal_load_n`: a load known from the
start, as a load published once to the node); the nut defaults to the model's `nut_position_m`; a JointState sets the speed from the joint's velocity and the nut from its
angle, `nut_position_at_zero_angle_m + angle * R tan(beta)`, and counts as one input. A
recompute happens when the point moved beyond a deadband from the last recomputed one (offline
there is no rate limit); the contact is re-integrated only when the nut moved more than the nut
deadband from where it was last integrated (geometries are cached per process, so positions
that strokes revisit, e.g. on an encoder's grid, cost nothing the second time).

Topics are found as `replay --publish` finds them (`is_input`): relative input names (the
defaults `motor_speed`, ...) resolve in a namespace, as a node's do under `__ns`; the log's
single input namespace by default (`input_namespaces`).

Log time: messages are taken in file order (the order the node received them). An input
message whose log time is earlier than the previous one on its topic is stale (a clock reset,
merged recordings): it is counted and not applied; one with the same log time as the previous
is counted and applied (the later value wins). Times of recomputes, episodes and plots are the
latest log time seen so far, so they never run backwards.
"""

from __future__ import annotations

import math
from collections import Counter, OrderedDict
from dataclasses import dataclass, replace
from typing import Callable, Iterable

import numpy as np

from ..bag.cdr import decode_float64, decode_joint_state
from .decimation import Envelope
from ..live.predictor import moved
from ..live.settings import JointSettings, LiveSettings
from ..bag.logfile import LogMessage, Topic
from ..model import ParameterError, Prediction, ScrewParameters, SqueakModel, Validity
from ..model.display import exact
from ..model.parameters import field_info

FLOAT64, JOINT_STATE = "std_msgs/msg/Float64", "sensor_msgs/msg/JointState"
_MODEL_CACHE = 1024                          # nut positions kept per process (~60 kB each)
_LOAD_LIMIT_N = field_info("axial_load_n")["hi"]    # as the node's input check
# The predictor's inputs (base name -> the type it subscribes with).
INPUTS = {"motor_speed": FLOAT64, "axial_load": FLOAT64, "nut_position": FLOAT64,
          "joint_states": JOINT_STATE}
# Namespaces of the node's and the replay's own outputs: never inputs.
OWN_NAMESPACES = {"squeak", "replay"}
TOPIC_FIELDS = ("speed_topic", "load_topic", "nut_topic", "joint_states_topic")


def matches(topic: Topic, relative: str, type_name: str) -> str | None:
    """The namespace in which `topic` is the relative input name `relative` ('/' for the
    root), or None: the root name whatever its type (a wrong type is reported when read),
    elsewhere only with the input's type, never under the outputs' namespaces."""
    if topic.name == "/" + relative:
        return "/"
    namespace = topic.name[:-len(relative) - 1]
    if not (topic.name.endswith("/" + relative) and namespace and topic.type_name == type_name):
        return None
    return None if OWN_NAMESPACES.intersection(namespace.split("/")) else namespace


def is_input(topic: Topic) -> bool:
    """A predictor input: by name, or a topic of the input's type named `.../<input>`."""
    return any(matches(topic, base, type_name) for base, type_name in INPUTS.items())


def input_namespaces(topics: Iterable[Topic], settings: InputSettings) -> list[str]:
    """The namespaces in which some relative input topic of `settings` exists, sorted."""
    needs = [(getattr(settings, f), type_name) for f, type_name in zip(TOPIC_FIELDS, (
        FLOAT64, FLOAT64, FLOAT64, JOINT_STATE)) if not getattr(settings, f).startswith("/")]
    return sorted({ns for t in topics for rel, type_name in needs
                   if (ns := matches(t, rel, type_name)) is not None})


def resolve(name: str, namespace: str) -> str:
    """A topic name as a node in `namespace` resolves it: absolute names stay."""
    return name if name.startswith("/") else f"{namespace.rstrip('/')}/{name}"


class InputError(ValueError):
    """An input topic whose type is not the one the input needs."""


@dataclass(frozen=True)
class InputSettings:
    """Where the inputs are in the log and when to recompute (node parameter names in SI)."""

    # Relative names resolve in the input namespace (`resolved`), absolute ones stay.
    speed_topic: str = "motor_speed"                    # std_msgs/Float64, rad/s
    load_topic: str = "axial_load"                      # std_msgs/Float64, N
    nut_topic: str = "nut_position"                     # std_msgs/Float64, m
    joint_states_topic: str = "joint_states"            # sensor_msgs/JointState
    joint_name: str = ""                # '' : the joint of single-joint messages
    nut_position_at_zero_angle_m: float = JointSettings.nut_position_at_zero_angle_m
    speed_deadband_rad_s: float = LiveSettings.speed_deadband_rad_s
    load_deadband_n: float = LiveSettings.load_deadband_n
    nut_deadband_m: float = LiveSettings.nut_deadband_m
    nominal_load_n: float | None = None   # load from the start (a log without load topic)

    def __post_init__(self) -> None:
        topics = self.topics
        if not all(t.strip("/") and " " not in t for t in topics) \
                or len(set(topics)) < len(topics):
            raise ValueError(f"input topics must be distinct names, got {', '.join(topics)}")
        if self.nominal_load_n is not None and not (
                math.isfinite(self.nominal_load_n) and abs(self.nominal_load_n) <= _LOAD_LIMIT_N):
            raise ValueError(f"nominal load {exact(self.nominal_load_n)} N is not a finite "
                             f"number within ±{exact(_LOAD_LIMIT_N)} N")
        for name in ("speed_deadband_rad_s", "load_deadband_n", "nut_deadband_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not math.isfinite(self.nut_position_at_zero_angle_m):
            raise ValueError("nut_position_at_zero_angle_m must be finite")

    @property
    def topics(self) -> tuple[str, str, str, str]:
        return tuple(getattr(self, f) for f in TOPIC_FIELDS)

    def resolved(self, namespace: str) -> InputSettings:
        """These settings with every topic name absolute, resolved in `namespace`."""
        return replace(self, **{f: resolve(getattr(self, f), namespace) for f in TOPIC_FIELDS})


@dataclass(frozen=True)
class Job:
    """A recompute: the operating point and the nut position the contact is integrated at."""

    index: int              # of the triggering message in its segment
    log_time_ns: int        # of the triggering message
    clock_ns: int           # latest log time so far (>= log_time_ns): episodes, plots
    speed_rad_s: float
    load_n: float
    nut_position_m: float   # true nut position
    model_nut_m: float      # where the contact is integrated


class Timeline:
    """Feeds messages in log order; `feed` returns the operating point to recompute, if any.

    `settings` topics are used as they are if absolute, else resolved in the root namespace.
    Memory is constant: counters, and the point after every input message in `trace`
    (speed, load, nut; NaN until known, the nut NaN until a nut input was taken), binned."""

    def __init__(self, params: ScrewParameters, settings: InputSettings = InputSettings()):
        self.settings = settings = settings.resolved("/")
        self.lead_m_per_rad = params.lead_per_rad_m
        self.nut_max_m = params.nut_travel_m
        self.speed: float | None = None
        self.load: float | None = settings.nominal_load_n
        self.nut = params.nut_position_m                   # until a nut input arrives
        self.nut_measured = False                          # a nut input was taken
        self._model_nut_m = params.nut_position_m          # where the contact is integrated
        self._computed_at: tuple[float, float, float] | None = None
        self.inputs: Counter[str] = Counter()              # accepted-or-not input messages
        self.rejected: Counter[str] = Counter()            # values not taken, by reason
        self.rejected_example: dict[str, str] = {}         # reason -> its first value
        self.ignored: Counter[str] = Counter()             # messages without the joint
        self.backwards: Counter[str] = Counter()           # stale inputs (not applied), by topic
        self.backwards_max_s = 0.0                         # largest step back in log time
        self.duplicates: Counter[str] = Counter()          # same log time as the previous
        self.recomputes = 0
        self.start_ns: int | None = None                   # first message: t = 0
        self.now_ns = 0                                    # latest log time seen
        self.trace = Envelope(3)
        self._last_ns: dict[str, int] = {}                 # per input topic
        self._routes: dict[str, tuple[str, Callable[[bytes], bool]]] = {
            settings.speed_topic: (FLOAT64, self._on_speed),
            settings.load_topic: (FLOAT64, self._on_load),
            settings.nut_topic: (FLOAT64, self._on_nut),
            settings.joint_states_topic: (JOINT_STATE, self._on_joint_states)}
        self._handlers: dict[tuple[str, str], Callable[[bytes], bool] | None] = {}

    @property
    def topics(self) -> list[str]:
        """Every topic seen so far."""
        return sorted({name for name, _ in self._handlers})

    def seconds(self, log_time_ns: int) -> float:
        """Seconds from the first message."""
        return (log_time_ns - (self.start_ns or 0)) / 1e9

    # ------------------------------------------------------------------ feeding
    def feed(self, m: LogMessage, index: int) -> Job | None:
        if self.start_ns is None:
            self.start_ns = self.now_ns = m.log_time_ns
        self.now_ns = max(self.now_ns, m.log_time_ns)
        key = (m.topic.name, m.topic.type_name)
        handler = self._handlers.get(key, False)
        if handler is False:
            handler = self._handlers[key] = self._handler(*key)
        if handler is None:
            return None
        name = m.topic.name
        self.inputs[name] += 1
        last = self._last_ns.get(name)
        if last is not None and m.log_time_ns <= last:
            if m.log_time_ns < last:          # stale: the newer value stays
                self.backwards[name] += 1
                self.backwards_max_s = max(self.backwards_max_s, (last - m.log_time_ns) / 1e9)
                return None
            self.duplicates[name] += 1
        self._last_ns[name] = m.log_time_ns
        try:
            accepted = handler(m.data)
        except ValueError:
            self._reject(f"{name}: undecodable payload", "")
            accepted = False
        nan = math.nan
        self.trace.add(self.seconds(self.now_ns), nan if self.speed is None else self.speed,
                       nan if self.load is None else self.load,
                       self.nut if self.nut_measured else nan)
        return self._recompute(index, m.log_time_ns) if accepted else None

    def _handler(self, topic: str, type_name: str) -> Callable[[bytes], bool] | None:
        route = self._routes.get(topic)
        if route is None:
            return None
        if type_name != route[0]:
            raise InputError(f"topic {topic} is {type_name}, expected {route[0]}")
        return route[1]

    def _reject(self, reason: str, example: str) -> bool:
        self.rejected[reason] += 1
        if example:
            self.rejected_example.setdefault(reason, example)
        return False

    def _on_speed(self, data: bytes) -> bool:
        return self._set_speed(decode_float64(data))

    def _on_load(self, data: bytes) -> bool:
        value = decode_float64(data)
        if not math.isfinite(value):
            return self._reject("load not finite", f"load {exact(value)} N")
        if abs(value) > _LOAD_LIMIT_N:
            return self._reject(f"load beyond {exact(_LOAD_LIMIT_N)} N",
                                f"{exact(value)} N exceeds {exact(_LOAD_LIMIT_N)} N")
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
            return self._reject("speed not finite", f"speed {exact(value)} rad/s")
        self.speed = value
        return True

    def _set_nut(self, value: float) -> bool:
        if not (math.isfinite(value) and 0.0 <= value <= self.nut_max_m):
            screw = f"[0, {exact(self.nut_max_m)}]"
            return self._reject(f"nut position off the screw {screw} m",
                                f"nut position {exact(value)} m is off the screw {screw}")
        self.nut, self.nut_measured = value, True
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
        return Job(index, log_time_ns, self.now_ns, *point, self._model_nut(point[2]))

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
            preds = [Prediction(float(speeds[i]), float(loads[i]), params.formulation,
                                Validity.PARAMETERS_REJECTED,
                                f"nut position {exact(nut)} m is not allowed by the parameters")
                     for i in idx]
        else:
            preds = model.predict_many(speeds[idx], loads[idx])
        for i, p in zip(idx.tolist(), preds):
            out[i] = p
    return out
