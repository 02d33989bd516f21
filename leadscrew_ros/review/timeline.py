# SPDX-License-Identifier: Apache-2.0
"""Operating-point timeline of a replayed log: input messages -> latest speed, load and nut
position -> recompute decisions with the node's deadbands -> batched predictions.

rclpy-free (prediction workers import it). The input rules are the node's own
(`live.rules.InputRules`): which values are taken, the JointState mapping (joint_states are
ignored unless `joint_name` is set, and counted as ignored), the operating point, the deadbands
and where the contact is integrated. `nominal_load_n` is a load known from the start, as a load
published once to the node. Offline there is no rate limit: every input that moves the point
beyond a deadband recomputes, as the node does when each input is processed before the next
(geometries are cached per process, so nut positions that strokes revisit, e.g. on an encoder's
grid, cost nothing the second time). Predictions use the replay model's parameters, scatter and
sample count (`ModelSpec`), so P(squeak) is the node's for the same settings.

Topics are found as `replay --publish` finds them (`is_input`): relative input names (the
defaults `motor_speed`, ...) resolve in a namespace, as a node's do under `__ns`; the log's
single input namespace by default (`input_namespaces`).

Speed, load and nut position are numbers at a field path (`speed_field`, ...; default `data`)
in messages of any type the log has a definition for (its schema text, else the installed one),
times a scale (`speed_scale`, ...): `bag.fieldpath`. A path that does not fit the topic's type
is an `InputError` naming the type, its fields and the path (a topic recorded with several
types: the messages of a type the path does not fit are counted as rejected, and with a
std_msgs/Float64 among its types only those are the input).

Sample time and log time: messages are taken in file order (the order the node received them).
An input message's sample time is its header stamp when its type has a std_msgs/Header `header`
with a stamp other than zero, else its log time. A message whose sample time is earlier than
that of the previous one on its topic is stale (a clock reset, merged recordings, a late
delivery of a stamped sample): it is counted and not applied; one with the same sample time as
the previous is counted and applied (the later value wins). Stamps are compared only with
stamps of the same topic (the node does the same, `live.rules.SampleOrder`): they may come
from another clock than the log's (the robot's, sim time). Times of recomputes, episodes,
plots and the predictions in the annotated log are log times (the latest seen so far, so they
never run backwards): the one clock every topic shares.
"""

from __future__ import annotations

import math
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from functools import lru_cache, partial
from typing import Any, NamedTuple

import numpy as np

from ..bag.cdr import JointStateData, decode_float64, decode_joint_state
from ..bag.fieldpath import (
    BeyondArray,
    FieldPathError,
    compile_path,
    split_path,
    stamp_path,
    topic_schema,
)
from ..bag.logfile import LogMessage, Topic
from ..live.rules import InputRules, Outcome, SampleOrder
from ..live.settings import INPUT_FIELDS, INPUTS_PREFIX, JointSettings, LiveSettings
from ..model import (
    OperatingPointError,
    ParameterError,
    Prediction,
    ScrewParameters,
    SqueakModel,
    Validity,
)
from ..model.physics.display import exact
from ..model.squeak_model import check_operating_point
from ..model.uncertainty.perturbation import geometry_fields
from ..model.uncertainty.scatter import Samples, Scatter
from .decimation import Envelope

FLOAT64, JOINT_STATE = "std_msgs/msg/Float64", "sensor_msgs/msg/JointState"
_MODEL_CACHE = 1024  # nut positions kept per process (~60 kB each)
# The predictor's inputs (base name -> the type it subscribes with).
INPUTS = {
    "motor_speed": FLOAT64,
    "axial_load": FLOAT64,
    "nut_position": FLOAT64,
    "joint_states": JOINT_STATE,
}
# Namespaces of the node's and the replay's own outputs: never inputs.
OWN_NAMESPACES = {"squeak", "replay"}
TOPIC_FIELDS = ("speed_topic", "load_topic", "nut_topic", "joint_states_topic")
# Inputs read at a field path (live.settings.INPUT_FIELDS): their InputSettings field names
FIELD_SETTINGS = {
    f"{name}_{attr}": (name, attr) for name in INPUT_FIELDS for attr in ("field", "scale")
}


def matches(topic: Topic, relative: str, type_name: str) -> str | None:
    """The namespace in which `topic` is the relative input name `relative` ('/' for the
    root), or None: the root name whatever its type (a wrong type is reported when read),
    elsewhere only with the input's type, never under the outputs' namespaces."""
    if topic.name == "/" + relative:
        return "/"
    namespace = topic.name[: -len(relative) - 1]
    if not (topic.name.endswith("/" + relative) and namespace and topic.type_name == type_name):
        return None
    return None if OWN_NAMESPACES.intersection(namespace.split("/")) else namespace


def is_input(topic: Topic) -> bool:
    """A predictor input: by name, or a topic of the input's type named `.../<input>`."""
    return any(matches(topic, base, type_name) for base, type_name in INPUTS.items())


def fits(topic: Topic, path: str) -> bool:
    """The field path `path` leads to a number in `topic`'s type (`bag.fieldpath`)."""
    try:
        compile_path(topic_schema(topic.type_name, topic.schema), path)
    except FieldPathError:
        return False
    return True


def input_namespaces(topics: Iterable[Topic], settings: InputSettings) -> list[str]:
    """The namespaces in which some relative input topic of `settings` exists, sorted: a
    JointState by its type, speed, load and nut as std_msgs/Float64 or any type their field
    path fits."""
    needs = [
        (getattr(settings, f), type_name, path)
        for f, type_name, path in zip(
            TOPIC_FIELDS,
            (FLOAT64, FLOAT64, FLOAT64, JOINT_STATE),
            (settings.speed_field, settings.load_field, settings.nut_field, None),
            strict=True,
        )
        if not getattr(settings, f).startswith("/")
    ]
    return sorted(
        {
            ns
            for t in topics
            for rel, type_name, path in needs
            if (ns := matches(t, rel, type_name)) is not None
            or (
                path is not None
                and (ns := matches(t, rel, t.type_name)) is not None
                and fits(t, path)
            )
        }
    )


def input_parameters(values: Mapping[str, Any]) -> dict[str, Any]:
    """The `InputSettings` fields among node parameter values `values` (a params file's, a
    recording's): by their own names, and `inputs.<input>.field` / `.scale` as
    `<input>_field` / `<input>_scale` (`inputs.<input>.type` is the node's: offline the
    log says the type)."""
    out = {k: v for k, v in values.items() if k in InputSettings.__dataclass_fields__}
    for name, (kind, attr) in FIELD_SETTINGS.items():
        key = f"{INPUTS_PREFIX}{kind}.{attr}"
        if key in values:
            out[name] = values[key]
    return out


def resolve(name: str, namespace: str) -> str:
    """A topic name as a node in `namespace` resolves it: absolute names stay."""
    return name if name.startswith("/") else f"{namespace.rstrip('/')}/{name}"


class InputError(ValueError):
    """An input topic whose type is not the one the input needs, or whose type its field
    path does not fit."""


class _Handler(NamedTuple):
    """How an input topic's messages are taken: `apply` the payload (True when a recompute
    decision follows), `stamp` its header stamp [ns] (None: the type has no header)."""

    apply: Callable[[bytes], bool]
    stamp: Callable[[bytes], int] | None


def _not_taken(topic: str, type_name: str, input_type: str) -> str:
    """Why the messages of one type of a topic recorded with two are not taken."""
    return (
        f"{topic}: {type_name} messages not taken (the topic is recorded with two types; its "
        f"{input_type} messages are the input)"
    )


@dataclass(frozen=True)
class InputSettings:
    """Where the inputs are in the log, when to recompute and the verdict's P(squeak)
    thresholds: node parameter names, defaults and checks from `LiveSettings` and
    `JointSettings` (`live` and `joints`).

    Attributes
    ----------
    speed_topic, load_topic, nut_topic : str
        Speed [rad/s], axial load [N], nut position [m] inputs. Relative names resolve in the
        input namespace (`resolved`), absolute ones stay.
    speed_field, load_field, nut_field : str
        Path of the input's number in its messages (`bag.fieldpath`; default `data`, as in
        std_msgs/Float64), as the node's `inputs.<input>.field`.
    speed_scale, load_scale, nut_scale : float
        The input is this factor times that number, as the node's `inputs.<input>.scale`.
    joint_states_topic : str
        sensor_msgs/JointState input.
    joint_name : str
        The screw joint ('': joint_states are ignored).
    nut_position_at_zero_angle_m : float
        As in `JointSettings` [m].
    speed_deadband_rad_s, load_deadband_n, nut_deadband_m : float
        As in `LiveSettings`.
    warn_probability, error_probability : float
        As in `LiveSettings`: the time above them, the report's lines.
    nominal_load_n : float or None
        Load from the start [N] (a log without a load topic).
    """

    speed_topic: str = "motor_speed"
    load_topic: str = "axial_load"
    nut_topic: str = "nut_position"
    joint_states_topic: str = "joint_states"
    speed_field: str = INPUT_FIELDS["speed"].field
    speed_scale: float = INPUT_FIELDS["speed"].scale
    load_field: str = INPUT_FIELDS["load"].field
    load_scale: float = INPUT_FIELDS["load"].scale
    nut_field: str = INPUT_FIELDS["nut"].field
    nut_scale: float = INPUT_FIELDS["nut"].scale
    joint_name: str = JointSettings.joint_name
    nut_position_at_zero_angle_m: float = JointSettings.nut_position_at_zero_angle_m
    speed_deadband_rad_s: float = LiveSettings.speed_deadband_rad_s
    load_deadband_n: float = LiveSettings.load_deadband_n
    nut_deadband_m: float = LiveSettings.nut_deadband_m
    warn_probability: float = LiveSettings.warn_probability
    error_probability: float = LiveSettings.error_probability
    nominal_load_n: float | None = None

    def __post_init__(self) -> None:
        topics = self.topics
        if not all(t.strip("/") and " " not in t for t in topics) or len(set(topics)) < len(topics):
            raise ValueError(f"input topics must be distinct names, got {', '.join(topics)}")
        if self.nominal_load_n is not None:
            try:
                check_operating_point(0.0, self.nominal_load_n)
            except OperatingPointError as exc:
                raise ValueError(f"nominal {exc}") from None
        _ = self.live, self.joints  # built to be checked: their ranges raise ValueError
        for name, cls in INPUT_FIELDS.items():
            field, scale = self.field_of(name)
            try:
                cls(field=field, scale=scale)  # "scale = 0 ...", "field = 3 must be text"
            except ValueError as exc:
                raise ValueError(f"{name}_{exc}") from None
            try:
                split_path(field)
            except FieldPathError as exc:
                raise ValueError(f"{name}_field: {exc}") from None

    def field_of(self, name: str) -> tuple[str, float]:
        """Where input `name` is in its messages.

        Parameters
        ----------
        name : str
            'speed', 'load' or 'nut'.

        Returns
        -------
        tuple of (str, float)
            Its field path and scale.
        """
        return getattr(self, f"{name}_field"), getattr(self, f"{name}_scale")

    @property
    def live(self) -> LiveSettings:
        """The deadbands and the WARN / ERROR probabilities (the node's other settings at
        their defaults)."""
        return LiveSettings(
            speed_deadband_rad_s=self.speed_deadband_rad_s,
            load_deadband_n=self.load_deadband_n,
            nut_deadband_m=self.nut_deadband_m,
            warn_probability=self.warn_probability,
            error_probability=self.error_probability,
        )

    @property
    def joints(self) -> JointSettings:
        """The joint name and the nut position at angle 0 (checked by `JointSettings`)."""
        return JointSettings(
            joint_name=self.joint_name,
            nut_position_at_zero_angle_m=self.nut_position_at_zero_angle_m,
        )

    @property
    def topics(self) -> tuple[str, str, str, str]:
        """The speed, load, nut and joint_states topics."""
        return tuple(getattr(self, f) for f in TOPIC_FIELDS)

    def resolved(self, namespace: str) -> InputSettings:
        """These settings with every topic name absolute.

        Parameters
        ----------
        namespace : str
            The input namespace relative names resolve in.

        Returns
        -------
        InputSettings
            A copy with absolute topics.
        """
        return replace(
            self,
            speed_topic=resolve(self.speed_topic, namespace),
            load_topic=resolve(self.load_topic, namespace),
            nut_topic=resolve(self.nut_topic, namespace),
            joint_states_topic=resolve(self.joint_states_topic, namespace),
        )


@dataclass(frozen=True)
class Job:
    """A recompute: the operating point and the nut position the contact is integrated at."""

    index: int  # of the triggering message in its segment
    log_time_ns: int  # of the triggering message
    clock_ns: int  # latest log time so far (>= log_time_ns): episodes, plots
    speed_rad_s: float
    load_n: float
    nut_position_m: float  # true nut position
    model_nut_m: float  # where the contact is integrated


class Timeline:
    """Feeds messages in log order; `feed` returns the operating point to recompute, if any.

    `settings` topics are used as they are if absolute, else resolved in the root namespace.
    Memory is constant: counters, and the point after every input message in `trace`
    (speed, load, nut; NaN until known, the nut NaN until a nut input was taken), binned.

    `types` gives every type each topic of the log is recorded with (`logsource.topic_types`):
    an input topic recorded with its input type and another one is read in the input type,
    its messages of the other type are counted in `rejected` (a reason naming both types); an
    input topic without its input type is an `InputError`."""

    def __init__(
        self,
        params: ScrewParameters,
        settings: InputSettings = InputSettings(),
        types: dict[str, list[str]] | None = None,
    ):
        self.settings = settings = settings.resolved("/")
        self._types = types or {}
        self.rules = InputRules(params, settings.live, settings.joints)
        if settings.nominal_load_n is not None:
            self.rules.set_load(settings.nominal_load_n)
        self.inputs: Counter[str] = Counter()  # accepted-or-not input messages
        self.rejected: Counter[str] = Counter()  # values not taken, by reason
        self.rejected_example: dict[str, str] = {}  # reason -> its first message
        self.ignored: Counter[str] = Counter()  # messages ignored, by reason
        self.ignored_example: dict[str, str] = {}  # reason -> the first one's joints
        self.backwards: Counter[str] = Counter()  # stale inputs (not applied), by topic
        self.backwards_max_s = 0.0  # largest step back in sample time
        self.duplicates: Counter[str] = Counter()  # same sample time as the previous
        self.stamped: set[str] = set()  # input topics ordered by header stamps
        self.recomputes = 0
        self.start_ns: int | None = None  # first message: t = 0
        self.now_ns = 0  # latest log time seen
        self.trace = Envelope(3)
        self.order = SampleOrder()
        # input topic -> its input ('speed', 'load', 'nut', or 'joint_states')
        self._routes = {
            settings.speed_topic: "speed",
            settings.load_topic: "load",
            settings.nut_topic: "nut",
            settings.joint_states_topic: "joint_states",
        }
        self._setters = {
            "speed": self.rules.set_speed,
            "load": self.rules.set_load,
            "nut": self.rules.set_nut_position,
        }
        # (topic, type) -> its handler; None: not an input; a str: the reason it is rejected
        self._handlers: dict[tuple[str, str], _Handler | str | None] = {}
        # the JointState payload whose stamp was read last, decoded (`_joint_stamp`)
        self._decoded: tuple[bytes, JointStateData] | None = None

    @property
    def speed(self) -> float | None:
        """The latest speed taken [rad/s]."""
        return self.rules.inputs.speed_rad_s

    @property
    def load(self) -> float | None:
        """The latest load taken [N]."""
        return self.rules.inputs.load_n

    @property
    def nut(self) -> float:
        """The nut position in use [m] (the parameters' until a nut input was taken)."""
        return self.rules.nut_position_m

    @property
    def nut_measured(self) -> bool:
        """True if the nut position is measured (a nut or joint input)."""
        return self.rules.nut_measured

    @property
    def topics(self) -> list[str]:
        """Every topic seen so far."""
        return sorted({name for name, _ in self._handlers})

    def seconds(self, log_time_ns: int) -> float:
        """Seconds from the first message."""
        return (log_time_ns - (self.start_ns or 0)) / 1e9

    # ------------------------------------------------------------------ feeding
    def feed(self, m: LogMessage, index: int) -> Job | None:
        """Feed message `m` (at `index` in the log); the point to recompute, if any."""
        if self.start_ns is None:
            self.start_ns = self.now_ns = m.log_time_ns
        self.now_ns = max(self.now_ns, m.log_time_ns)
        key = (m.topic.name, m.topic.type_name)
        try:
            handler = self._handlers[key]
        except KeyError:  # a topic and type not seen yet
            handler = self._handlers[key] = self._handler(m.topic)
        if handler is None:
            return None
        if isinstance(handler, str):  # a type of an input recorded with several, not taken
            self.rejected[handler] += 1
            return None
        name = m.topic.name
        self.inputs[name] += 1
        t_ns = m.log_time_ns
        if handler.stamp is not None:
            try:
                t_ns = handler.stamp(m.data) or t_ns  # a zero stamp: none
            except ValueError:  # the value's reading rejects the payload
                pass
        back = self.order.step_back_ns(name, t_ns)
        if back:  # stale: the newer value stays
            self.backwards[name] += 1
            self.backwards_max_s = max(self.backwards_max_s, back / 1e9)
            return None
        if back == 0:
            self.duplicates[name] += 1
        try:
            accepted = handler.apply(m.data)
        except ValueError:
            self.rejected[f"{name}: undecodable payload"] += 1
            accepted = False
        i, nan = self.rules.inputs, math.nan
        self.trace.add(
            self.seconds(self.now_ns),
            nan if i.speed_rad_s is None else i.speed_rad_s,
            nan if i.load_n is None else i.load_n,
            nan if i.nut_position_m is None else i.nut_position_m,
        )
        return self._recompute(index, m.log_time_ns) if accepted else None

    def _handler(self, topic: Topic) -> _Handler | str | None:
        """How messages of `topic` (its name and type) are taken: None if it is no input, a
        reason if its type is one of several and not the input's."""
        name, type_name = topic.name, topic.type_name
        kind = self._routes.get(name)
        if kind is None:
            return None
        types = self._types.get(name, ())
        if kind == "joint_states":
            if type_name != JOINT_STATE:
                if JOINT_STATE in types:
                    return _not_taken(name, type_name, JOINT_STATE)
                raise InputError(f"topic {name} is {type_name}, expected {JOINT_STATE}")
            stamp = self._stamp(topic, name)
            return _Handler(
                self._on_joint_states,
                None if stamp is None else partial(self._joint_stamp, stamp),
            )
        path, scale = self.settings.field_of(kind)
        if path == "data" and FLOAT64 in types and type_name != FLOAT64:
            return _not_taken(name, type_name, FLOAT64)  # as the node's default subscription
        if path == "data" and type_name == FLOAT64:
            read: Callable[[bytes], float] = decode_float64  # the default, without a schema
        else:
            try:
                read = compile_path(topic_schema(type_name, topic.schema), path).read
            except FieldPathError as exc:
                if len(types) > 1:
                    return (
                        f"{name}: {type_name} messages not taken (the topic is recorded with "
                        f"several types; --{kind}-field {path} does not fit this one: {exc})"
                    )
                raise InputError(f"--{kind}-field {path}: {exc} (topic {name})") from None
        setter = self._setters[kind]

        def apply(data: bytes) -> bool:
            try:
                value = read(data)
            except BeyondArray as exc:  # this message's array is shorter
                return self._count(self.rules.missing(kind, path, str(exc)))
            return self._count(setter(scale * value))

        return _Handler(apply, self._stamp(topic, name))

    def _stamp(self, topic: Topic, name: str) -> Callable[[bytes], int] | None:
        """The header stamp [ns] of a message of `topic`, if its type has a std_msgs/Header
        `header` (the topic then counts as `stamped`)."""
        if topic.type_name == FLOAT64:
            return None
        try:
            paths = stamp_path(topic_schema(topic.type_name, topic.schema))
        except FieldPathError:  # no usable definition: log time
            return None
        if paths is None:
            return None
        self.stamped.add(name)
        sec, nanosec = paths
        return lambda data: int(sec.read(data)) * 1_000_000_000 + int(nanosec.read(data))

    def _count(self, outcome: Outcome) -> bool:
        """Count the values a message had rejected; True when a recompute decision follows."""
        for r in outcome.rejected:
            self.rejected[r.reason] += 1
            self.rejected_example.setdefault(r.reason, r.message)
        return outcome.applies

    def _joint_stamp(self, read: Callable[[bytes], int], data: bytes) -> int:
        """A JointState's header stamp [ns] from its decoding, which `_on_joint_states` takes
        next (one decoding per message); `read` (the schema's stamp fields) where it does not
        decode."""
        try:
            js = decode_joint_state(data)
        except ValueError:  # the stamp may still be there; the message is counted as undecodable
            return read(data)
        self._decoded = (data, js)
        return js.stamp_ns

    def _on_joint_states(self, data: bytes) -> bool:
        decoded, self._decoded = self._decoded, None
        js = decoded[1] if decoded is not None and decoded[0] is data else decode_joint_state(data)
        outcome = self.rules.set_joint_state(js.name, js.position, js.velocity)
        if outcome.ignored:
            hint = "" if self.settings.joint_name else "; use --joint-name"
            reason = f"{self.settings.joint_states_topic}: {outcome.ignored}{hint}"
            self.ignored[reason] += 1
            self.ignored_example.setdefault(reason, f"joints {', '.join(js.name) or 'none'}")
        return self._count(outcome)

    # ------------------------------------------------------------------ coalescing
    def _recompute(self, index: int, log_time_ns: int) -> Job | None:
        if not self.rules.changed():
            return None
        computed = self.rules.compute()
        assert computed is not None  # changed() holds only with a point
        point, contact_nut_m = computed
        self.recomputes += 1
        return Job(index, log_time_ns, self.now_ns, *point, contact_nut_m)


# ---------------------------------------------------------------------- predictions
@dataclass(frozen=True)
class ModelSpec:
    """What the predictions are made with: the parameters, the scatter behind P(squeak) and
    its sample count; hashable and picklable (it goes to the worker processes), unlike the
    model it is taken from.

    Attributes
    ----------
    params : ScrewParameters
        The nominal parameters (the nut position is the job's).
    scatter : tuple of (str, float)
        `Scatter.sd` items: parameter name -> relative SD (SD of ln for log-normal ones).
    samples : int
        Scatter samples of each P(squeak).
    """

    params: ScrewParameters
    scatter: tuple[tuple[str, float], ...]
    samples: int

    @classmethod
    def of(cls, model: SqueakModel) -> ModelSpec:
        """The spec of `model`: a replay predicts with its parameters and scatter."""
        return cls(model.params, tuple(model.scatter.sd.items()), model.sample_count)

    def at(self, nut_position_m: float) -> SqueakModel:
        """The model with the contact integrated at `nut_position_m`; ParameterError if the
        parameters reject that position."""
        return _spec_model(self).with_params(nut_position_m=nut_position_m)


_shared: dict[ModelSpec, Samples] = {}  # drawn in another process (`share_samples`)


def share_samples(spec: ModelSpec, samples: Samples) -> None:
    """Predict with `samples` for `spec` in this process: the draw of its scatter made in
    another process (`_spec_model`'s there, the same points), so that this one need not
    draw them.

    Parameters
    ----------
    spec : ModelSpec
        The parameters, scatter and sample count.
    samples : Samples
        Their samples.
    """
    _shared[spec] = samples


@lru_cache(maxsize=4)
def _spec_model(spec: ModelSpec) -> SqueakModel:
    """The model of a spec at its own nut position, whose samples the others share (kept
    here, not on the spec: the spec is pickled to the workers)."""
    model = SqueakModel(spec.params, Scatter(dict(spec.scatter)), spec.samples)
    if spec in _shared:
        model.samples = _shared[spec]
    _ = model.samples  # drawn once: with_params passes them on
    return model


_models: OrderedDict[tuple[ModelSpec, float], SqueakModel | None] = OrderedDict()


def _model_at(spec: ModelSpec, nut: float) -> SqueakModel | None:
    """The model with the contact at `nut` (None if the parameters reject it), cached."""
    key = (spec, nut)
    if key in _models:
        _models.move_to_end(key)
        return _models[key]
    try:
        model = spec.at(nut)
    except ParameterError:
        model = None
    _models[key] = model
    if len(_models) > _MODEL_CACHE:
        _models.popitem(last=False)
    return model


def predict_jobs(
    spec: ModelSpec, speeds: np.ndarray, loads: np.ndarray, model_nuts: np.ndarray
) -> list[Prediction]:
    """Predictions at the jobs' operating points, each with the contact at its nut position:
    the state matrices of all of them in one vectorised step (`SqueakModel.predict_many`).
    Outside validity a prediction has `valid=False` and the reason. With scattered geometry
    fields the estimate is per nut position: one model (cached) and batch each."""
    model = _spec_model(spec)
    if not geometry_fields(model.scatter):
        return model.predict_many(speeds, loads, model_nuts)
    out: list[Prediction | None] = [None] * len(speeds)
    nuts, inverse = np.unique(model_nuts, return_inverse=True)
    for k, nut in enumerate(nuts.tolist()):
        idx = np.flatnonzero(inverse == k)
        at = _model_at(spec, nut)
        if at is None:
            preds = [
                Prediction(
                    float(speeds[i]),
                    float(loads[i]),
                    spec.params.formulation,
                    Validity.PARAMETERS_REJECTED,
                    f"nut position {exact(nut)} m is not allowed by the parameters",
                )
                for i in idx
            ]
        else:
            preds = at.predict_many(speeds[idx], loads[idx])
        for i, p in zip(idx.tolist(), preds, strict=True):
            out[i] = p
    filled = [p for p in out if p is not None]
    assert len(filled) == len(out)  # np.unique's inverse gives every job its nut
    return filled
