# SPDX-License-Identifier: Apache-2.0
"""What the command groups share: the error type and parser class, argument types (finite
numbers, ranges, map axes), the model-parameter and scatter options and the model they build,
JSON output.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import re
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any, NoReturn, Protocol

import numpy as np
import yaml

from ..model.physics.display import exact
from ..model.physics.metadata import default_text, help_text, range_text
from ..model.physics.parameters import FORMULATIONS, ParameterError, ScrewParameters, field_names
from ..model.squeak_model import SqueakModel
from ..model.studies.fields import check_axis, integer_axis
from ..model.studies.work import MAX_MEMORY_BYTES, MAX_POINTS, REFERENCE_STATE_SIZE
from ..model.uncertainty.perturbation import MAX_GEOMETRY_FIELDS, geometry_fields
from ..model.uncertainty.scatter import (
    LOG_NORMAL,
    REPLICATES,
    Scatter,
    ScatterSettings,
    scatterable,
)
from ..review.jsonsafe import json_safe

PROG = "leadscrew-squeak"
SPEED_AXIS = "speed_rad_s"
MAX_COUNT = 100_000  # points per range axis (a map is COUNT_x * COUNT_y eigenproblems)
WORK_LIMITS = (
    f"At most {MAX_POINTS} points (fewer for a model with more modes: the limit "
    f"scales with ({REFERENCE_STATE_SIZE} / state size)^3) and about "
    f"{MAX_MEMORY_BYTES / 1e9:g} GB; a larger request is refused before it starts. "
    f"Progress on a terminal; Ctrl-C stops (exit 130)."
)
SCATTER_PREFIX = "scatter."  # ROS parameters and params-file keys of ScatterSettings
NO_SCATTER = "none"  # --scatter none: every scatter 0 (the nominal 0/1 verdict)
ROS_ARGS_HELP = (
    "ROS arguments follow --ros-args, as for any ROS executable (up to --): "
    "namespace (-r __ns:=/seat_left), remaps (-r OLD:=NEW), parameters, log level"
)


class CliError(Exception):
    """A bad command line or input file (exit code 2)."""


class Parser(argparse.ArgumentParser):
    """argparse that raises instead of printing usage and exiting, so `main` reports one line,
    and takes an argument that begins with '-' and a digit, '.', 'inf' or 'nan' as a value
    (argparse's own rule, '-5' or '-.5' only, took `--load -1e7` and `--speed -inf` for
    options: "expected one argument"); no option of these commands looks like that."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_VALUE

    def error(self, message: str) -> NoReturn:
        """Raise CliError with `message` instead of printing usage and exiting."""
        raise CliError(message)


# ----------------------------------------------------------------------------- ROS 2 or not
INSTALL_ROS = "pip install 'leadscrew_ros[ros]'"
# Top-level modules of the ROS 2 wheels that `.[ros]` installs (rclpy, the message packages and
# what they load: rosidl_*, rcl*, rmw*, rpyutils, ...). The core install has none of them.
_ROS_MODULES = frozenset(
    {
        "rclpy",
        "std_msgs",
        "sensor_msgs",
        "geometry_msgs",
        "diagnostic_msgs",
        "std_srvs",
        "builtin_interfaces",
        "rpyutils",
        "ament_index_python",
        "service_msgs",
        "type_description_interfaces",
        "lifecycle_msgs",
        "unique_identifier_msgs",
        "action_msgs",
        "rosgraph_msgs",
    }
)
_ROS_PREFIXES = ("rosidl_", "rcl", "rmw", "ros_")


def needs_ros(command: str) -> str:
    """The one-line message for a ROS command run without ROS 2 installed."""
    return f"'{command}' needs ROS 2 (rclpy): {INSTALL_ROS}"


def import_ros(command: str, module: str) -> Any:
    """`leadscrew_ros.ros.<module>` for `command` (demo, simulate, replay --publish, watch,
    record, params, squeak_node): the only way the CLI reaches the ROS layer, so that a core
    install without the ROS 2 wheels (or with part of them) says in one line what to install (a
    CliError) instead of a traceback. Any other import error is ours and propagates."""
    try:
        return importlib.import_module(f"{__package__.rpartition('.')[0]}.ros.{module}")
    except ImportError as exc:  # ModuleNotFoundError, or an extension that fails to load
        top = (exc.name or "").partition(".")[0]
        if top in _ROS_MODULES or top.startswith(_ROS_PREFIXES):
            raise CliError(needs_ros(command)) from None
        raise


# A negative number, -inf, -nan, a range START:STOP:COUNT with a negative START
_NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)


# ----------------------------------------------------------------------------- value parsing
def finite(text: str) -> float:
    """argparse `type=`: a finite float (argparse reports 'argument --x: <message>')."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def finite_float(text: str, what: str) -> float:
    """A finite float parsed outside argparse; `what` names it in the error."""
    try:
        return finite(text)
    except argparse.ArgumentTypeError as exc:
        raise CliError(f"{what}: {exc}") from None


def parse_range(text: str, what: str, integer: bool = False) -> np.ndarray:
    """`START:STOP:COUNT` -> COUNT evenly spaced values (finite ends that differ, COUNT >= 2);
    with `integer` (an axis of whole numbers) every integer from START to STOP, step 1:
    `START:STOP`, or with COUNT, which must be their number."""
    parts = text.split(":")
    if integer and len(parts) in (2, 3):
        return _integer_range(parts, what)
    if len(parts) != 3:
        raise CliError(f"{what}: expected START:STOP:COUNT, got {text!r}")
    start, stop = (
        finite_float(p, f"{what} {name}") for p, name in zip(parts, ("START", "STOP"), strict=False)
    )
    try:
        count = int(parts[2])
    except ValueError:
        raise CliError(f"{what}: COUNT {parts[2]!r} is not an integer") from None
    if not 2 <= count <= MAX_COUNT:
        raise CliError(f"{what}: COUNT must be between 2 and {MAX_COUNT}, got {count}")
    if start == stop:
        raise CliError(f"{what}: START and STOP must differ")
    if not math.isfinite(stop - start):
        raise CliError(f"{what}: START {exact(start)} and STOP {exact(stop)} are too far apart")
    return np.linspace(start, stop, count)


def _integer_range(parts: list[str], what: str) -> np.ndarray:
    """START:STOP[:COUNT] of whole numbers -> START, START +- 1, ..., STOP (as floats)."""
    ends = []
    for text, name in zip(parts, ("START", "STOP"), strict=False):
        value = finite_float(text, f"{what} {name}")
        if not value.is_integer():
            raise CliError(
                f"{what} {name}: {text!r} is not a whole number (the axis takes integers, step 1)"
            )
        ends.append(int(value))
    start, stop = ends
    count = abs(stop - start) + 1
    if count < 2 or count > MAX_COUNT:
        raise CliError(f"{what}: START and STOP must differ by 1 to {MAX_COUNT - 1}")
    if len(parts) == 3 and parts[2].strip() != str(count):
        raise CliError(
            f"{what}: the axis takes integers, step 1: {start}:{stop} has {count} "
            f"values, not {parts[2]!r} (COUNT may be left out)"
        )
    return np.arange(
        start, stop + (1 if stop > start else -1), 1 if stop > start else -1, dtype=float
    )


def parse_axis_spec(text: str, what: str) -> tuple[str, np.ndarray]:
    """`NAME:START:STOP:COUNT` for a map axis (`NAME:START:STOP` for an integer one)."""
    name, _, rest = text.partition(":")
    if not rest:
        raise CliError(f"{what}: expected NAME:START:STOP:COUNT, got {text!r}")
    check_axis(name)
    return name, parse_range(rest, what, integer_axis(name))


def output_file(
    path: str | None, option: str, suffixes: Sequence[str], makes_directory: bool = False
) -> Path | None:
    """The file of an output option, checked before any work (a run is not lost to a typo):
    its suffix one of `suffixes` (lower case, without the dot), not a directory, in a
    directory that exists (unless the command `makes_directory`). None stays None.

    Raises
    ------
    CliError
        '--plot: out.txt: .txt is not a supported format; use one of .png, ...'.
    """
    if path is None:
        return None
    out = Path(path)
    suffix = out.suffix.lower().removeprefix(".")
    if suffix not in suffixes:
        found = f".{suffix} is not a supported format" if suffix else "no suffix"
        raise CliError(
            f"{option}: {path}: {found}; use one of {', '.join('.' + s for s in suffixes)}"
        )
    if out.is_dir():
        raise CliError(f"{option}: {path} is a directory")
    if not makes_directory and not out.resolve().parent.is_dir():
        raise CliError(f"{option}: directory of {path} does not exist")
    return out


def plot_file(path: str | None, option: str = "--plot") -> Path | None:
    """`output_file` for a figure: a format matplotlib writes (it picks it by the suffix)."""
    if path is None:
        return None
    from ..review.plots import plot_formats

    return output_file(path, option, plot_formats())


def output_directory(path: str, option: str = "--out") -> Path:
    """The directory of an output option (created later by the command), checked before any
    work: not an existing file, not under one, and the nearest existing directory writable.

    Raises
    ------
    CliError
        The path exists and is not a directory, lies under a file, or cannot be created
        or written.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise CliError(f"{option}: {path} exists and is not a directory")
    there = out.absolute()
    while not there.exists() and there != there.parent:
        there = there.parent
    if not there.is_dir():
        raise CliError(f"{option}: {path} cannot be created: {there} is a file")
    if not os.access(there, os.W_OK | os.X_OK):
        raise CliError(f"{option}: {path} cannot be written: {there} is not writable")
    return out


def make_output_directory(out: Path, option: str = "--out") -> None:
    """Create `out` (checked by `output_directory`) before any work: what the checks cannot
    foresee (a read-only or virtual file system such as /proc) as one line.

    Raises
    ------
    CliError
        It cannot be created.
    """
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CliError(f"{option}: {out} cannot be created: {exc.strerror or exc}") from None


# ----------------------------------------------------------------------------- parameters
def _ros_parameters(node: Any) -> dict[str, Any]:
    """Merge every `ros__parameters` mapping found in a ROS-style YAML document."""
    found: dict[str, Any] = {}
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "ros__parameters" and isinstance(value, dict):
                found.update(value)
            else:
                found.update(_ros_parameters(value))
    return found


def _flat(values: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested parameter mappings as dotted ROS names: {'scatter': {'mu_static': x}} ->
    {'scatter.mu_static': x}."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        name = f"{prefix}{key}"
        out.update(_flat(value, name + ".") if isinstance(value, dict) else {name: value})
    return out


def _file_parameters(path: str) -> dict[str, Any]:
    """Every `ros__parameters` value of a ROS parameter file, nested names dotted."""
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise CliError(f"--params-file: cannot read {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise CliError(
            f"--params-file: {path} is not a text file (not UTF-8); expected a "
            f"ROS parameter file in YAML"
        ) from None
    except yaml.YAMLError as exc:
        raise CliError(
            f"--params-file: {path} is not valid YAML: {' '.join(str(exc).split())}"
        ) from None
    values = _ros_parameters(doc)
    if not values:
        raise CliError(f"--params-file: {path} has no '<node>: ros__parameters:' section")
    return _flat(values)


def read_params_file(path: str) -> dict[str, Any]:
    """ScrewParameters fields from a ROS parameter file (other keys are ignored)."""
    return {k: v for k, v in _file_parameters(path).items() if k in field_names()}


def yaml_parameters(path: str) -> dict[str, Any]:
    """Every `ros__parameters` value of a parameter file already checked by read_params_file,
    nested names dotted ('inputs.speed.field')."""
    return _flat(_ros_parameters(yaml.safe_load(Path(path).read_text(encoding="utf-8"))))


def _scatter_value(item: str) -> tuple[str, float]:
    """`NAME=SD` of --scatter -> (name, SD), the name checked, the number parsed (its range
    is checked by ScatterSettings)."""
    name, sep, text = (part.strip() for part in item.partition("="))
    if not sep or not name:
        raise CliError(f"--scatter: expected NAME=SD or {NO_SCATTER}, got {item!r}")
    if name not in scatterable():
        raise CliError(
            f"--scatter {name}: not a parameter that can scatter; NAME is one of "
            f"{', '.join(scatterable())} or {NO_SCATTER}"
        )
    try:
        return name, float(text)
    except ValueError:
        raise CliError(f"--scatter {name}: {text!r} is not a number") from None


class ScatterChoice(Protocol):
    """What is used of a `ScatterSettings`: that class is made at run time (one field per
    scatterable parameter), so mypy sees none of its attributes."""

    @property
    def scatter(self) -> Scatter:
        """The scatter of the parameters."""
        ...

    @property
    def samples(self) -> int:
        """The live sample count."""
        ...


def _settings(values: dict[str, Any], what: str) -> ScatterChoice:
    try:
        settings = ScatterSettings(**values)
        geometry_fields(settings.scatter)  # more than the live estimate takes
        return settings
    except ParameterError as exc:
        raise CliError(f"{what}: {exc}") from None


def scatter_settings(
    args: argparse.Namespace, file_values: dict[str, Any] | None = None
) -> ScatterChoice:
    """The scatter of P(squeak): defaults <- `scatter.<name>` / `scatter.samples` of
    --params-file (`file_values`: its parameters, dotted) <- --scatter NAME=SD and --scatter
    none, in command-line order <- --samples; validated by ScatterSettings.

    Raises
    ------
    CliError
        An unknown or geometry name, a value that is not a number or out of its range.
    """
    known = {f.name for f in fields(ScatterSettings)}
    values: dict[str, Any] = {}
    for key, value in (file_values or {}).items():
        if key.startswith(SCATTER_PREFIX):
            name = key[len(SCATTER_PREFIX) :]
            if name not in known:
                raise CliError(
                    f"--params-file: {key} is not a scatter setting; one of "
                    f"{', '.join(SCATTER_PREFIX + n for n in sorted(known))}"
                )
            values[name] = value
    _settings(values, "--params-file")
    for item in args.scatter:
        if item.strip() == NO_SCATTER:
            values.update(dict.fromkeys(scatterable(), 0.0))
        else:
            name, sd = _scatter_value(item)
            values[name] = sd
    settings = _settings(values, "--scatter")
    if args.samples is not None:
        settings = _settings(dict(values, samples=args.samples), "--samples")
    return settings


def build_model(args: argparse.Namespace) -> SqueakModel:
    """Defaults <- --params-file <- --param NAME=VALUE <- --formulation (validated together),
    with the scatter of `scatter_settings`."""
    file_values = _file_parameters(args.params_file) if args.params_file else {}
    changes: dict[str, Any] = {k: v for k, v in file_values.items() if k in field_names()}
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise CliError(f"--param: expected NAME=VALUE, got {item!r}")
        changes[name.strip()] = value.strip()
    if args.formulation:
        changes["formulation"] = args.formulation
    settings = scatter_settings(args, file_values)
    return SqueakModel(ScrewParameters().with_(**changes), settings.scatter, settings.samples)


def _scatter_help() -> str:
    """--scatter help from the ScatterSettings field metadata (defaults, range)."""
    info = {f.name: f for f in fields(ScatterSettings)}
    on = [f"{n} {default_text(info[n])}" for n in scatterable() if info[n].default]
    allowed = range_text({**info[scatterable()[0]].metadata, "unit": ""})
    return (
        f"unit-to-unit scatter of one parameter behind P(squeak) (repeatable): NAME=SD, "
        f"the relative standard deviation (for {', '.join(sorted(LOG_NORMAL))} the SD of "
        f"its logarithm), allowed {allowed}; 0 switches one off, '{NO_SCATTER}' every one "
        f"(then P is the nominal 0/1 verdict). Defaults: {', '.join(on)}, every other 0. "
        f"NAME is any of {', '.join(scatterable())} (at most {MAX_GEOMETRY_FIELDS} "
        f"geometry fields); as the ROS parameters {SCATTER_PREFIX}<NAME> of --params-file"
    )


def common_parser(more_formulations: dict[str, str] | None = None) -> Parser:
    """The parent parser of the commands that build a model: the model parameter options;
    `more_formulations` (choice -> its help) adds choices to --formulation (calibrate's
    'both'): a parser of its own, as argparse shares a parent's actions."""
    more = more_formulations or {}
    common = Parser(add_help=False)
    group = common.add_argument_group("model parameters")
    group.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a ScrewParameters field (repeatable; SI units)",
    )
    group.add_argument(
        "--formulation",
        choices=(*FORMULATIONS, *more),
        help="friction matrices: Appendix A as printed (paper, the default) or "
        "the first-principles linearisation (consistent)"
        + "".join(f"; {choice}: {text}" for choice, text in more.items()),
    )
    group.add_argument(
        "--params-file",
        metavar="FILE.yaml",
        help="ROS parameter file (<node>: ros__parameters: {...}); keys that are "
        "not model parameters or scatter.<NAME> are ignored",
    )
    group = common.add_argument_group("scatter of P(squeak)")
    group.add_argument(
        "--scatter", action="append", default=[], metavar="NAME=SD", help=_scatter_help()
    )
    samples = next(f for f in fields(ScatterSettings) if f.name == "samples")
    group.add_argument(
        "--samples",
        type=int,
        metavar="N",
        help=help_text(
            samples,
            f"scatter samples of the fast P(squeak) estimator (sweeps, maps, figures, "
            f"replay, predict's probability_live): {REPLICATES} times a power of 2",
        ),
    )
    return common


# ----------------------------------------------------------------------------- settings
def add_settings_options(group: Any, cls: type, skip: Sequence[str] = ()) -> None:
    """One option per `setting` field of dataclass `cls` (not in `skip`): --<name with
    dashes>, dest the field's name, its type, choices and help from the field metadata; an
    option not given is None (the field's default applies, `settings_from`)."""
    for f in fields(cls):
        if "unit" not in f.metadata or f.name in skip:
            continue
        default: Any = f.default
        md, kind = f.metadata, type(default)
        option = "--" + f.name.replace("_", "-")
        text = help_text(f).replace("%", "%%")
        if kind is bool:
            group.add_argument(
                option, dest=f.name, action=argparse.BooleanOptionalAction, help=text
            )
        elif kind is str:
            group.add_argument(
                option,
                dest=f.name,
                choices=md["choices"] or None,
                metavar="TEXT" if not md["choices"] else None,
                help=text,
            )
        else:
            group.add_argument(
                option,
                dest=f.name,
                type=int if kind is int else finite,
                metavar="N" if kind is int else "X",
                help=text,
            )


def settings_from(args: argparse.Namespace, cls: type, **fixed: Any) -> Any:
    """An instance of `cls` from the options of `add_settings_options` that were given (and
    `fixed` fields); CliError with the reason when a value is not allowed."""
    given = {
        f.name: getattr(args, f.name)
        for f in fields(cls)
        if "unit" in f.metadata and getattr(args, f.name, None) is not None
    }
    try:
        return cls(**{**given, **fixed})
    except (TypeError, ValueError) as exc:
        raise CliError(" ".join(str(exc).split())) from None


# ----------------------------------------------------------------------------- output
def print_json(obj: Any) -> None:
    """Print `obj` as one line of strict JSON (non-finite numbers as null)."""
    print(json.dumps(json_safe(obj), allow_nan=False))
