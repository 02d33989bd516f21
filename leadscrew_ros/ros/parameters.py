# SPDX-License-Identifier: Apache-2.0
"""The parameters of the nodes `squeak_predictor` and `squeak_guard`, made from the settings'
field metadata.

Every parameter is a field of one settings dataclass (`model.physics.metadata.setting`: default,
unit, range, description, read-only); `GROUPS` orders the predictor's dataclasses and gives each
its name prefix, `GUARD_GROUPS` the guard's (the model's groups, the node's own and `guard.*`).
From these tables come the ROS parameter descriptors (`descriptor`), the dataclasses built
from parameter values (`build`), the parameter lines of `squeak_node --help` and
`squeak_guard --help` (`help_lines`) and config/leadscrew.yaml (`config_yaml`, written by
tools/gen_config.py), the one file both nodes take.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import Field, dataclass, fields
from typing import Any, NamedTuple

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.parameter import Parameter

from ..bag.logmeta import LogMetadata
from ..bag.recorder import RecordSettings
from ..live.guard import GuardSettings
from ..live.settings import (
    INPUT_FIELDS,
    INPUTS_PREFIX,
    JointSettings,
    ListenSettings,
    LiveSettings,
)
from ..model.acoustics.settings import DetectorSettings
from ..model.physics.display import exact, yaml_value
from ..model.physics.metadata import check, check_value, documented, range_text, setting
from ..model.physics.parameters import ParameterError, ScrewParameters
from ..model.squeak_model import SqueakModel
from ..model.uncertainty.scatter import ScatterSettings

READ_ONLY_NOTE = "read-only: set at start-up"


@documented
@dataclass(frozen=True)
class NodeSettings:
    """The node's own settings: diagnostics, identity and input subscriptions."""

    diagnostics_period_s: float = setting(
        1.0, "s", "period of /diagnostics when nothing changes", 0.05, 60.0
    )
    hardware_id: str = setting(
        "leadscrew", "", "hardware_id of the diagnostic status", read_only=True
    )
    unit_id: str = setting(
        "",
        "",
        "identity of this drive (e.g. its serial number) in every recording's "
        "`leadscrew_ros` metadata record ('' when not set)",
        read_only=True,
    )
    input_queue_depth: int = setting(
        5, "1", "queue depth of the input subscriptions", 1, 1000, read_only=True
    )

    def __post_init__(self) -> None:
        check(self)


@documented
@dataclass(frozen=True)
class RecordingControl:
    """Whether the node records (`RecordSettings` say how) and what it does with bags an
    earlier crash cut off."""

    enabled: bool = setting(
        False,
        "",
        "record inputs and outputs to MCAP while true (also ~/record); a set is "
        "rejected with the reason when recording cannot start",
    )
    auto_recover: bool = setting(
        False,
        "",
        "on start, recover this node's bags cut off by a crash in record.directory "
        "(else only reported)",
        read_only=True,
    )

    def __post_init__(self) -> None:
        check(self)


class Group(NamedTuple):
    """Settings dataclass `cls` whose fields are the parameters `prefix` + field name."""

    cls: type
    prefix: str
    title: str  # one line: what these parameters are (YAML comment)


GROUPS = (
    Group(
        ScrewParameters,
        "",
        "model: Table 1 of the paper, the friction law of Fig. 4, mode counts, formulation",
    ),
    Group(LiveSettings, "", "node: recompute policy and verdict"),
    Group(JointSettings, "", "node: joint_states mapping"),
    Group(NodeSettings, "", "node: diagnostics, identity and inputs"),
    *(
        Group(
            cls,
            f"{INPUTS_PREFIX}{name}.",
            f"node: where the {name} input's number is in its messages (type, field path, scale)",
        )
        for name, cls in INPUT_FIELDS.items()
    ),
    Group(
        ScatterSettings,
        "scatter.",
        "model: unit-to-unit scatter of the parameters behind "
        "P(squeak) (squeak/risk); 0 switches one off",
    ),
    Group(RecordingControl, "record.", "node: MCAP recording (also ~/record)"),
    Group(RecordSettings, "record.", "node: MCAP recording, one bag per recording"),
    Group(
        ListenSettings,
        "listen.",
        "node: listening to a microphone (squeak/heard, the measurement status)",
    ),
    Group(
        DetectorSettings,
        "listen.",
        "model: the squeak detector of the microphone (model.acoustics)",
    ),
)


class Spec(NamedTuple):
    """One parameter: its full name, its field and the group it belongs to."""

    name: str
    field: Field
    group: Group

    @property
    def default(self) -> Any:
        """The parameter's default value."""
        return self.field.default

    @property
    def md(self) -> Any:
        """The parameter field's metadata."""
        return self.field.metadata


def specs(groups: tuple[Group, ...] = GROUPS) -> Iterator[Spec]:
    """Every parameter of `groups`, in declaration order."""
    for group in groups:
        for f in fields(group.cls):
            yield Spec(group.prefix + f.name, f, group)


GUARD_GROUP = Group(
    GuardSettings, "guard.", "guard node (squeak_guard): policy and limits of the speed command"
)
# The guard node's parameters: the model the predictor uses (so that one params file serves
# both), the node's own (diagnostics, identity, input queues) and its policy.
GUARD_GROUPS = (
    *(g for g in GROUPS if g.cls in (ScrewParameters, ScatterSettings, NodeSettings)),
    GUARD_GROUP,
)
PARAMETERS = tuple(specs())  # the predictor's
PARAMETER_NAMES = [s.name for s in PARAMETERS]
GUARD_PARAMETERS = tuple(specs(GUARD_GROUPS))
GUARD_PARAMETER_NAMES = [s.name for s in GUARD_PARAMETERS]
ALL_GROUPS = (*GROUPS, GUARD_GROUP)  # config/leadscrew.yaml: every parameter of both nodes
_ALL = tuple(specs(ALL_GROUPS))


def names_of(cls: type) -> set[str]:
    """Parameter names of the fields of settings dataclass `cls`."""
    return {s.name for s in _ALL if s.group.cls is cls}


def build(cls: type, values: dict[str, Any]) -> Any:
    """Settings dataclass `cls` from parameter values (name -> value, every parameter of
    `cls` present).

    Raises
    ------
    ParameterError
        A value is not allowed (the reason names the parameter), or the class's own checks
        (e.g. cross-field) fail: what the node reports for any bad parameter.
    """
    own = [s for s in _ALL if s.group.cls is cls]
    for s in own:  # full parameter names in the reason
        reason = check_value(s.name, values[s.name], s.field)
        if reason:
            raise ParameterError(reason)
    try:
        return cls(**{s.field.name: values[s.name] for s in own})
    except ValueError as exc:  # e.g. an empty record.directory, z_o + b > L
        raise ParameterError(str(exc)) from None


def log_metadata(values: dict[str, Any]) -> LogMetadata:
    """The `leadscrew_ros` metadata record of a recording made with the parameter values
    `values` (name -> value, every parameter): the model's (`ScrewParameters`, with the
    formulation), the scatter's (`scatter.*` without the prefix, with `samples`) and the
    node's own (every other parameter, by its ROS name), the hardware id and the unit id."""
    model = {s.name: s.field.name for s in PARAMETERS if s.group.cls is ScrewParameters}
    scatter = {s.name: s.field.name for s in PARAMETERS if s.group.cls is ScatterSettings}
    return LogMetadata(
        params={field: values[name] for name, field in model.items()},
        scatter={field: values[name] for name, field in scatter.items()},
        node={
            name: values[name]
            for name in PARAMETER_NAMES
            if name not in model and name not in scatter
        },
        unit_id=values["unit_id"],
        hardware_id=values["hardware_id"],
    )


def constraints(spec: Spec) -> str:
    """What a ParameterDescriptor's ranges cannot say: the choices, or an open bound."""
    md = spec.md
    if md["choices"]:
        return f"one of: {', '.join(md['choices'])}"
    if md["lo_open"] or md["hi_open"]:
        return f"allowed {range_text(md)}"
    return ""


def with_unit(description: str, unit: str) -> str:
    """A descriptor's description: 'text [unit]' ('text' without a unit); `split_unit` reads
    it back."""
    return f"{description} [{unit}]" if unit else description


def split_unit(description: str) -> tuple[str, str]:
    """(text, unit) of a descriptor's description written by `with_unit` (unit '' if none)."""
    text, bracket, unit = description.rpartition(" [")
    if bracket and unit.endswith("]") and "[" not in unit:
        return text, unit[:-1]
    return description, ""


def descriptor(spec: Spec) -> ParameterDescriptor:
    """ROS descriptor of a parameter: description with unit, range, read-only."""
    md, default = spec.md, spec.default
    d = ParameterDescriptor(
        name=spec.name,
        description=with_unit(md["description"], md["unit"]),
        read_only=md["read_only"],
        additional_constraints=constraints(spec),
    )
    if md["lo"] is not None and isinstance(default, float):
        d.floating_point_range = [
            FloatingPointRange(from_value=float(md["lo"]), to_value=float(md["hi"]))
        ]
    elif md["lo"] is not None and isinstance(default, int):
        d.integer_range = [IntegerRange(from_value=int(md["lo"]), to_value=int(md["hi"]), step=1)]
    return d


SPECS = {s.name: s for s in _ALL}


def as_declared_type(parameter: Parameter) -> Parameter:
    """`parameter` with a whole number given for a double parameter (a YAML `48000`, a
    `params set NAME 2`) as that double: ROS refuses it by type otherwise, a surprise for a
    sample rate in Hz. Anything else as it is (a wrong type is still refused)."""
    spec = SPECS.get(parameter.name)
    if (
        spec is not None
        and isinstance(spec.default, float)
        and parameter.type_ == Parameter.Type.INTEGER
    ):
        return Parameter(parameter.name, Parameter.Type.DOUBLE, float(parameter.value))
    return parameter


def declare(node: Any, parameters: tuple[Spec, ...]) -> None:
    """Declare `parameters` on `node` with their descriptors; a whole number given for a
    double (params file, overrides, later sets) is taken as that double (`as_declared_type`:
    rclpy offers no hook between the overrides and their type check at declaration).

    Raises
    ------
    rclpy.exceptions.ParameterException
        An override out of its range or of the wrong type.
    """
    overrides = node._parameter_overrides
    for name, parameter in overrides.items():
        overrides[name] = as_declared_type(parameter)
    for spec in parameters:
        node.declare_parameter(spec.name, spec.default, descriptor(spec))
    node.add_pre_set_parameters_callback(lambda ps: [as_declared_type(p) for p in ps])


def squeak_model(values: dict[str, Any]) -> SqueakModel:
    """The model of parameter values `values` (the model's and `scatter.*`): the screw and its
    scatter. One prediction draws the samples and builds the estimator, so a scatter they
    cannot take is rejected here with the reason, never later in a callback.

    Raises
    ------
    ParameterError
        A bad parameter or scatter.
    """
    scatter = build(ScatterSettings, values)
    model = SqueakModel(
        build(ScrewParameters, values), scatter=scatter.scatter, samples=scatter.samples
    )
    try:
        model.predict(model.params.min_speed_rad_s, 0.0)
    except ParameterError:
        raise
    except ValueError as exc:
        raise ParameterError(f"scatter: {exc}") from None
    return model


def help_lines(parameters: tuple[Spec, ...] = PARAMETERS) -> list[str]:
    """The parameter lines of `squeak_node --help` (or, given `GUARD_PARAMETERS`,
    `squeak_guard --help`): name [unit] = default, range: description (constraints;
    read-only)."""
    lines = []
    for spec in parameters:
        md, default, unit = spec.md, spec.default, spec.md["unit"]
        text = f"  {spec.name}{f' [{unit}]' if unit else ''} = " + (
            exact(default) if isinstance(default, float) else repr(default)
        )
        if md["lo"] is not None:
            text += ", " + "..".join(
                str(b) if isinstance(b, int) else exact(b) for b in (md["lo"], md["hi"])
            )
        notes = "; ".join(
            n for n in (constraints(spec), READ_ONLY_NOTE if md["read_only"] else "") if n
        )
        lines.append(f"{text}: {md['description']}" + (f" ({notes})" if notes else ""))
    return lines


def yaml_comment(spec: Spec) -> str:
    """'[unit] description; allowed range or choices (read-only ...)' of a YAML entry."""
    md = spec.md
    text = f"[{md['unit'] or '-'}] {md['description']}"
    if md["choices"]:
        text += f"; one of {' | '.join(md['choices'])}"
    elif md["lo"] is not None:
        text += f"; allowed {range_text({**md, 'unit': ''})}"  # the unit leads the comment
    return text + (f" ({READ_ONLY_NOTE})" if md["read_only"] else "")


CONFIG_HEADER = """\
# SPDX-License-Identifier: Apache-2.0
# Default parameters of the squeak predictor and squeak guard nodes, in SI units, generated by
# tools/gen_config.py from the settings' field metadata (leadscrew_ros.ros.parameters.GROUPS,
# GUARD_GROUP; each node takes its own and ignores the others):
# do not edit, change the metadata and run the tool; test/test_config.py checks it is current.
# Floats are written with a decimal point: ROS rejects an integer YAML value for a double
# parameter.
# Keyed `/**:` so that it applies to the node in any namespace and under any name, e.g.
#   squeak_node --ros-args -r __ns:=/seat_left --params-file config/leadscrew.yaml
# (a key `squeak_predictor:` would match only a node in the root namespace, silently).
/**:
  ros__parameters:
"""
COMMENT_COLUMN = 40


def config_yaml() -> str:
    """config/leadscrew.yaml: every parameter with its default, a dotted prefix as nested
    mappings (`record.*` under `record:`, `inputs.speed.*` under `inputs:` `speed:`), a
    comment with unit, description and range per entry."""
    lines: list[str] = []
    nested: list[str] = []
    for group in ALL_GROUPS:
        parts = [p for p in group.prefix.split(".") if p]
        common = 0
        while common < min(len(parts), len(nested)) and parts[common] == nested[common]:
            common += 1
        for depth in range(common, len(parts)):
            lines.append(f"{'  ' * (depth + 2)}{parts[depth]}:")
        nested = parts
        indent = "  " * (len(parts) + 2)
        lines.append(f"{indent}# --- {group.title}")
        for spec in specs((group,)):
            entry = f"{indent}{spec.field.name}: {yaml_value(spec.default)}"
            lines.append(f"{entry.ljust(COMMENT_COLUMN - 2)}  # {yaml_comment(spec)}")
    return CONFIG_HEADER + "\n".join(lines) + "\n"
