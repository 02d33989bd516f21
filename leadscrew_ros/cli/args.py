# SPDX-License-Identifier: Apache-2.0
"""What the command groups share: the error type and parser class, argument types (finite
numbers, ranges, map axes), the model-parameter options and the model they build, JSON output.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from ..model.display import exact
from ..model.parameters import FORMULATIONS, ScrewParameters, field_names
from ..model.predictor import SqueakModel
from ..model.sweep import MAX_MEMORY_BYTES, MAX_POINTS, REFERENCE_STATE_SIZE, check_axis
from ..review.jsonsafe import json_safe

PROG = "leadscrew-squeak"
SPEED_AXIS = "speed_rad_s"
MAX_COUNT = 100_000          # points per range axis (a map is COUNT_x * COUNT_y eigenproblems)
WORK_LIMITS = (f"At most {MAX_POINTS} points (fewer for a model with more modes: the limit "
               f"scales with ({REFERENCE_STATE_SIZE} / state size)^3) and about "
               f"{MAX_MEMORY_BYTES / 1e9:g} GB; a larger request is refused before it starts. "
               f"Progress on a terminal; Ctrl-C stops (exit 130).")
ROS_ARGS_HELP = ("ROS arguments follow --ros-args, as for any ROS executable (up to --): "
                 "namespace (-r __ns:=/seat_left), remaps (-r OLD:=NEW), parameters, log level")


class CliError(Exception):
    """A bad command line or input file (exit code 2)."""


class Parser(argparse.ArgumentParser):
    """argparse that raises instead of printing usage and exiting, so `main` reports one line."""

    def error(self, message: str) -> NoReturn:
        raise CliError(message)


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


def parse_range(text: str, what: str) -> np.ndarray:
    """`START:STOP:COUNT` -> COUNT evenly spaced values (finite ends that differ, COUNT >= 2)."""
    parts = text.split(":")
    if len(parts) != 3:
        raise CliError(f"{what}: expected START:STOP:COUNT, got {text!r}")
    start, stop = (finite_float(p, f"{what} {name}") for p, name in zip(parts, ("START", "STOP")))
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


def parse_axis_spec(text: str, what: str) -> tuple[str, np.ndarray]:
    """`NAME:START:STOP:COUNT` for a map axis."""
    name, _, rest = text.partition(":")
    if not rest:
        raise CliError(f"{what}: expected NAME:START:STOP:COUNT, got {text!r}")
    check_axis(name)
    return name, parse_range(rest, what)


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


def read_params_file(path: str) -> dict[str, Any]:
    """ScrewParameters fields from a ROS parameter file (other keys are ignored)."""
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise CliError(f"--params-file: cannot read {path}: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise CliError(f"--params-file: {path} is not valid YAML: "
                       f"{' '.join(str(exc).split())}") from None
    values = _ros_parameters(doc)
    if not values:
        raise CliError(f"--params-file: {path} has no '<node>: ros__parameters:' section")
    return {k: v for k, v in values.items() if k in field_names()}


def yaml_parameters(path: str) -> dict[str, Any]:
    """Every `ros__parameters` value of a parameter file already checked by read_params_file."""
    return _ros_parameters(yaml.safe_load(Path(path).read_text(encoding="utf-8")))


def build_model(args: argparse.Namespace) -> SqueakModel:
    """Defaults <- --params-file <- --param NAME=VALUE <- --formulation (validated together)."""
    changes: dict[str, Any] = read_params_file(args.params_file) if args.params_file else {}
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise CliError(f"--param: expected NAME=VALUE, got {item!r}")
        changes[name.strip()] = value.strip()
    if args.formulation:
        changes["formulation"] = args.formulation
    return SqueakModel(ScrewParameters().with_(**changes))


def common_parser() -> Parser:
    """The parent parser of the commands that build a model: the model parameter options."""
    common = Parser(add_help=False)
    group = common.add_argument_group("model parameters")
    group.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                       help="set a ScrewParameters field (repeatable; SI units)")
    group.add_argument("--formulation", choices=FORMULATIONS,
                       help="friction matrices: Appendix A as printed (paper, the default) or "
                            "the first-principles linearisation (consistent)")
    group.add_argument("--params-file", metavar="FILE.yaml",
                       help="ROS parameter file (<node>: ros__parameters: {...}); keys that are "
                            "not model parameters are ignored")
    return common


# ----------------------------------------------------------------------------- output
def print_json(obj: Any) -> None:
    """Print `obj` as one line of strict JSON (non-finite numbers as null)."""
    print(json.dumps(json_safe(obj), allow_nan=False))
