# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak`: squeak predictions, sweeps, stability maps and the paper's figures; the
ROS 2 demo (`demo`: predictor node + actuator simulator) and the simulator alone (`simulate`);
MCAP logs: offline replay (`replay`), playback (`replay --publish`), `recover` and `info`.

Every error a user can cause (bad option, invalid parameter or operating point, unreadable
file) is reported as one line `leadscrew-squeak: error: <message>` with exit code 2.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any, Callable, NoReturn, Sequence

import numpy as np
import yaml

from ..review.jsonsafe import json_safe
from ..bag.logfile import (LogError, LogInfo, bag_of, cut_off_bags, inspect, log_files, recover,
                      recover_bag)
from ..model.parameters import (FORMULATIONS, ParameterError, ScrewParameters, field_info,
                               field_names)
from ..model.predictor import OperatingPointError, Prediction, SqueakModel
from ..model.display import exact
from ..model.fields import check_value, help_text
from ..live.settings import JointSettings, LiveSettings
from ..model.sweep import (MAX_MEMORY_BYTES, MAX_POINTS, REFERENCE_STATE_SIZE, MapResult,
                          SweepResult, axis_names, check_axis, sweep, sweep_work)
from ..review.timeline import InputSettings

PROG = "leadscrew-squeak"
SPEED_AXIS = "speed_rad_s"
MAX_COUNT = 100_000          # points per range axis (a map is COUNT_x * COUNT_y eigenproblems)
WORK_LIMITS = (f"At most {MAX_POINTS} points (fewer for a model with more modes: the limit "
               f"scales with ({REFERENCE_STATE_SIZE} / state size)^3) and about "
               f"{MAX_MEMORY_BYTES / 1e9:g} GB; a larger request is refused before it starts. "
               f"Progress on a terminal; Ctrl-C stops (exit 130).")


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


def axis_unit(name: str) -> str:
    """SI unit of a sweep axis (the unit of the values on the command line)."""
    return {SPEED_AXIS: "rad/s", "load_n": "N"}.get(name) or field_info(name)["unit"] or "1"


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


def _yaml_parameters(path: str) -> dict[str, Any]:
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


# ----------------------------------------------------------------------------- output


def print_json(obj: Any) -> None:
    print(json.dumps(json_safe(obj), allow_nan=False))


def _mode_table(prediction: Prediction, count: int) -> list[str]:
    lines = [f"  {'mode':<6}{'frequency [Hz]':>16}{'growth [1/s]':>15}{'damping ratio':>15}"]
    for m in prediction.modes[:count]:
        lines.append(f"  {m.label:<6}{m.frequency_hz:>16.2f}{m.growth_rate:>+15.3f}"
                     f"{m.damping_ratio:>+15.2e}{'  squeak' if m.unstable else ''}")
    return lines


def prediction_text(p: Prediction, top: int = 5) -> str:
    head = (f"speed {p.speed_rad_s:g} rad/s, load {p.load_n:g} N, "
            f"{p.formulation} formulation")
    if not p.valid:
        return f"{head}\nno prediction: {p.reason}"
    if p.stable:
        verdict = f"stable: no squeak (risk {p.risk:.3f})"
    else:
        squeak = ", ".join(f"{m.label} {m.frequency_hz:.1f} Hz (Re {m.growth_rate:+.2f} 1/s)"
                           for m in p.squeak_modes) or "none"
        verdict = f"UNSTABLE: squeak predicted (risk {p.risk:.3f}); squeak modes: {squeak}"
    lines = [head, verdict]
    if p.divergence_rates:
        lines.append("divergence (real eigenvalues > 0): "
                     + ", ".join(f"{r:.4g} 1/s" for r in p.divergence_rates))
    lines.append(f"least stable of {len(p.modes)} oscillatory modes:")
    return "\n".join(lines + _mode_table(p, top))


def _unstable_labels(p: Prediction) -> str:
    return ";".join(m.label for m in p.squeak_modes)


def _cell(value: float | None) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.10g}"


def write_sweep_csv(result: SweepResult) -> None:
    out = csv.writer(sys.stdout, lineterminator="\n")
    out.writerow([result.axis, "valid", "max_growth_rate", "risk", "unstable_modes",
                  "unstable_frequencies_hz"])
    for value, p in zip(result.values.tolist(), result.predictions):
        out.writerow([repr(value), p.valid, _cell(p.max_growth_rate), _cell(p.risk),
                      _unstable_labels(p), ";".join(f"{f:.6g}" for f in p.unstable_frequencies_hz)])


def sweep_text(result: SweepResult) -> str:
    unit, g = axis_unit(result.axis), result.max_growth_rate
    fixed = ", ".join(f"{k} = {v:g} {axis_unit(k)}" for k, v in result.fixed.items())
    n_valid = int(np.isfinite(g).sum())
    bands = ", ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in result.unstable_bands) or "none"
    lines = [f"sweep of {result.axis} [{unit}] from {result.values[0]:g} to "
             f"{result.values[-1]:g} ({len(result.values)} points; fixed {fixed}; "
             f"{result.predictions[0].formulation} formulation)",
             f"valid points: {n_valid}/{len(g)}",
             f"unstable bands [{unit}]: {bands}",
             "stability boundaries [" + unit + "]: "
             + (", ".join(f"{b:.6g}" for b in result.boundaries) or "none")]
    if n_valid:
        i = int(np.nanargmax(g))
        p = result.predictions[i]
        lines.append(f"largest growth rate {g[i]:.4g} 1/s at {result.axis} = "
                     f"{result.values[i]:g} {unit}"
                     + (f" (squeak modes {_unstable_labels(p).replace(';', ', ')})"
                        if p.squeak_modes else ""))
    reasons = {p.reason for p in result.predictions if not p.valid}
    lines += [f"invalid: {r}" for r in sorted(reasons)]
    return "\n".join(lines)


def map_text(result: MapResult) -> str:
    g = result.field.max_growth_rate
    valid = np.isfinite(g)
    fixed = ", ".join(f"{k} = {v:g} {axis_unit(k)}" for k, v in result.fixed.items())
    lines = [f"stability map: x = {result.x_axis} [{axis_unit(result.x_axis)}] "
             f"{result.x[0]:g}..{result.x[-1]:g} ({len(result.x)}), y = {result.y_axis} "
             f"[{axis_unit(result.y_axis)}] {result.y[0]:g}..{result.y[-1]:g} "
             f"({len(result.y)}); fixed {fixed}",
             f"valid points: {int(valid.sum())}/{g.size}"]
    if valid.any():
        j, i = np.unravel_index(np.nanargmax(g), g.shape)
        lines += [f"unstable fraction of valid points: {np.mean(g[valid] > 0):.3f}",
                  f"largest growth rate {g[j, i]:.4g} 1/s at {result.x_axis} = {result.x[i]:g}, "
                  f"{result.y_axis} = {result.y[j]:g}"]
    lines.append(f"refined boundary points: {len(result.boundary)}")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- commands
def cmd_modes(args: argparse.Namespace) -> int:
    basis = build_model(args).geometry.basis
    order = np.argsort(basis.frequency_hz, kind="stable")
    modes = [{"label": basis.labels[i], "frequency_hz": float(basis.frequency_hz[i])}
             for i in order]
    if args.json:
        print_json({"modes": modes})
    else:
        print(f"{'mode':<6}{'frequency [Hz]':>16}")
        print("\n".join(f"{m['label']:<6}{m['frequency_hz']:>16.1f}" for m in modes))
    return 0


def cmd_predict(args: argparse.Namespace) -> int:
    p = build_model(args).predict(args.speed, args.load)
    if args.json:
        print_json(p.as_dict())
    else:
        print(prediction_text(p))
    return 0


def _sweep_axis(args: argparse.Namespace) -> tuple[str, np.ndarray, float | None, float | None]:
    """(axis, values, fixed speed, fixed load) from `--speed RANGE` or `--axis/--values`."""
    axis = args.axis or SPEED_AXIS
    check_axis(axis)
    if axis == SPEED_AXIS:
        if (args.values is None) == (args.speed is None):
            raise CliError("a speed sweep needs exactly one of --speed START:STOP:COUNT and "
                           "--values START:STOP:COUNT")
        option = "--values" if args.values else "--speed"
        return axis, parse_range(args.values or args.speed, f"argument {option}"), None, args.load
    if args.values is None:
        raise CliError(f"--axis {axis} needs --values START:STOP:COUNT")
    if axis == "load_n" and args.load is not None:
        raise CliError("--load cannot be combined with --axis load_n")
    speed = None if args.speed is None else finite_float(args.speed, "argument --speed")
    return axis, parse_range(args.values, "argument --values"), speed, args.load


def cmd_sweep(args: argparse.Namespace) -> int:
    model = build_model(args)
    axis, values, speed, load = _sweep_axis(args)
    sweep_work(model, axis, values).check()             # before a progress bar shows
    from ..review.progress import progress_bar
    with progress_bar(len(values), "sweep") as update:
        result = sweep(model, axis, values, speed, load, progress=update)
    if args.json:
        print_json(result.as_dict())
    elif args.csv:
        write_sweep_csv(result)
    else:
        print(sweep_text(result))
    if args.plot:
        from .figures import plot_sweep
        plot_sweep(result, Path(args.plot))
    return 0


def cmd_map(args: argparse.Namespace) -> int:
    model = build_model(args)
    x_axis, x = parse_axis_spec(args.x, "argument --x")
    y_axis, y = parse_axis_spec(args.y, "argument --y")
    for option, name, value in (("--speed", SPEED_AXIS, args.speed),
                                ("--load", "load_n", args.load)):
        if value is not None and name in (x_axis, y_axis):
            raise CliError(f"{option} cannot be combined with a {name} map axis")
    from .figures import plot_map, run_map
    result = run_map(model, x_axis, x, y_axis, y, args.speed, args.load)
    if args.json:
        print_json(result.as_dict())
    else:
        print(map_text(result))
    if args.plot:
        plot_map(result, Path(args.plot), formulation=model.params.formulation)
    return 0


def cmd_figures(args: argparse.Namespace) -> int:
    from .figures import make_figures
    print(make_figures(build_model(args), Path(args.out), quick=args.quick), end="")
    return 0


def _stroke(duration_s: float | None):
    """The simulator's stroke profile (imports rclpy: only for demo and simulate)."""
    from ..live.profile import ProfileError, StrokeProfile
    try:
        return StrokeProfile() if duration_s is None else StrokeProfile(duration_s=duration_s)
    except ProfileError as exc:
        raise CliError(f"argument --duration: {exc}") from None


def cmd_demo(args: argparse.Namespace) -> int:
    profile = _stroke(args.duration)
    from ..ros.demo import run_demo
    try:
        return run_demo(profile.duration_s,
                        record_dir=None if args.no_record else Path(args.record_dir))
    except RuntimeError as exc:          # e.g. rclpy could not start, no subscription
        raise CliError(str(exc)) from None


def cmd_simulate(args: argparse.Namespace) -> int:
    profile = _stroke(args.duration)
    from ..ros.simulator import MAX_RATE_HZ, run_simulator
    if not 0 < args.rate <= MAX_RATE_HZ:
        raise CliError(f"argument --rate: must be in (0, {MAX_RATE_HZ:g}] Hz, got {args.rate:g}")
    try:
        return run_simulator(profile, rate_hz=args.rate, loop=args.loop,
                             joint_name=args.joint_name, wait_for_subscriber=not args.no_wait,
                             ros_args=args.ros_args)
    except (ValueError, RuntimeError) as exc:     # bad --ros-args; rclpy could not start
        raise CliError(str(exc)) from None


# ----------------------------------------------------------------------------- logs
REPLAY_INPUTS = [f.name for f in fields(InputSettings)]    # = option dests, node parameters
# The node's settings that replay options mirror: their metadata gives the help and the range
REPLAY_SETTINGS = {f.name: f for cls in (LiveSettings, JointSettings) for f in fields(cls)
                   if f.name in REPLAY_INPUTS}
LIVE_OPTIONS = ("rate", "loop", "start_offset", "topics", "remap", "no_wait", "ros_args")
ROS_COMMANDS = ("simulate", "replay")      # the ones that start a ROS node (replay: --publish)
ROS_ARGS_HELP = ("ROS arguments follow --ros-args, as for any ROS executable (up to --): "
                 "namespace (-r __ns:=/seat_left), remaps (-r OLD:=NEW), parameters, log level")


def _topic(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _setting_help(name: str, description: str | None = None) -> str:
    """argparse help of the replay option that sets node setting `name` (from its metadata)."""
    return help_text(REPLAY_SETTINGS[name], description).replace("%", "%%")


def _replay_inputs(args: argparse.Namespace) -> InputSettings:
    """InputSettings: defaults <- node parameters of --params-file <- options. Topic names
    stay as given: relative ones resolve in the input namespace (--namespace, or the log's)."""
    values = _yaml_parameters(args.params_file) if args.params_file else {}
    values = {name: values[name] for name in REPLAY_INPUTS if name in values}
    values.update({name: getattr(args, name) for name in REPLAY_INPUTS
                   if getattr(args, name) is not None})
    reasons = [check_value(name, values[name], f) for name, f in REPLAY_SETTINGS.items()
               if name in values]                     # the node's ranges hold here too
    if any(reasons):
        raise CliError(f"replay inputs: {next(r for r in reasons if r)}")
    try:
        return InputSettings(**values)
    except (TypeError, ValueError) as exc:
        raise CliError(f"replay inputs: {exc}") from None


def _parse_remap(items: list[str]) -> dict[str, str]:
    remap = {}
    for item in items:
        old, sep, new = item.partition(":=")
        if not sep or not old or not new:
            raise CliError(f"argument --remap: expected OLD:=NEW, got {item!r}")
        remap[_topic(old)] = new
    return remap


OFFLINE_OPTIONS = ("out", "no_report", "namespace", "out_namespace", "nominal_load_n")


def _publish(args: argparse.Namespace) -> int:
    given = [o for o in OFFLINE_OPTIONS if getattr(args, o) not in (None, False)]
    if given:
        option = {"nominal_load_n": "load"}.get(given[0], given[0])
        raise CliError(f"--{option.replace('_', '-')} is for the offline replay, not --publish "
                       f"(the namespace of --publish is --ros-args -r __ns:=NS)")
    from ..ros.replay_live import WAIT_FOR_SUBSCRIBER_S, publish_log
    try:
        publish_log(log_files(args.log), rate=1.0 if args.rate is None else args.rate,
                    loop=args.loop,
                    start_offset_s=0.0 if args.start_offset is None else args.start_offset,
                    topics=[_topic(t) for t in args.topics] if args.topics else None,
                    remap=_parse_remap(args.remap), progress=not args.quiet,
                    wait_for_subscriber_s=0.0 if args.no_wait else WAIT_FOR_SUBSCRIBER_S,
                    ros_args=args.ros_args)
    except (ValueError, RuntimeError) as exc:    # bad arguments; rclpy could not start
        raise CliError(str(exc)) from None
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    if args.publish:
        return _publish(args)
    given = [o for o in LIVE_OPTIONS if getattr(args, o) not in (None, False, [])]
    if given:
        raise CliError(f"--{given[0].replace('_', '-')} needs --publish")
    if args.episodes < 0:
        raise CliError("argument --episodes: must be >= 0")
    model = build_model(args)
    inputs = _replay_inputs(args)
    from ..review.replay import ReplaySettings, log_name, replay
    try:
        settings = ReplaySettings(
            inputs, namespace=args.namespace and _topic(args.namespace),
            out_namespace=args.out_namespace and _topic(args.out_namespace),
            workers=args.workers, progress=not args.quiet)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    out = Path(args.out) if args.out else Path(f"{log_name(Path(args.log))}_replay")
    result = replay(args.log, model, out, settings)
    if not args.no_report:
        from ..review.report import write_report
        result.outputs += write_report(result, model, out)
    if not args.quiet:
        print(result.summary_text())
        for e in result.episodes[:args.episodes]:
            print(f"  squeak {e.start_s:10.2f} - {e.end_s:10.2f} s  peak growth "
                  f"{e.peak_growth_rate:7.1f} 1/s  "
                  + ", ".join(f"{m} {f:.0f} Hz" for m, f in zip(e.modes, e.frequencies_hz)))
        if result.episode_count > args.episodes:
            print(f"  ... {result.episode_count - args.episodes} more in episodes.json")
        print("wrote: " + ", ".join(str(p) for p in result.outputs))
    return 0


def _span(info: LogInfo) -> str:
    if info.start_ns is None:
        return "no messages"
    return (f"{(info.end_ns - info.start_ns) / 1e9:.3f} s ({_utc(info.start_ns)} to "
            f"{_utc(info.end_ns)})")


def _utc(ns: int) -> str:
    import datetime
    return datetime.datetime.fromtimestamp(ns / 1e9, datetime.timezone.utc).isoformat(
        timespec="milliseconds")


def _topic_lines(info: LogInfo) -> list[str]:
    return [f"  {name:<32} {t.type_name:<36} {info.counts[name]:>10}"
            for name, t in sorted(info.topics.items())]


def _record_directory(path: Path) -> bool:
    """A directory of recordings (bag directories, loose files) rather than one bag: it has no
    metadata.yaml and holds no .mcap file or a subdirectory with one."""
    return path.is_dir() and not (path / "metadata.yaml").exists() and (
        not any(path.glob("*.mcap")) or any(path.glob("*/*.mcap")))


def cmd_recover(args: argparse.Namespace) -> int:
    src = Path(args.log)
    if args.output:                      # a copy elsewhere; the input stays as it is
        if src.is_dir():
            raise CliError("-o/--output is for one file; a bag directory is recovered in place")
        info = recover(src, Path(args.output))
        print(f"recovered {info.messages} messages on {len(info.topics)} topics from {src} "
              f"into {args.output}")
        print(f"time span: {_span(info)}")
        print("damage: " + (info.damage or "none (the file was complete)"))
        print("\n".join(_topic_lines(info)))
        return 0
    if _record_directory(src):
        targets = cut_off_bags(src)
        if not targets:
            print(f"nothing to recover: no cut-off recording in {src}")
            return 0
    else:
        targets = [src]
    for target in targets:
        result = recover_bag(target)
        for f in result.files:
            print(f.line())
        print(result.summary())
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    infos = [inspect(f) for f in log_files(args.log)]
    if args.json:
        print_json([{"file": str(i.path), "complete": i.complete, "damage": i.damage,
                     "profile": i.profile, "library": i.library, "messages": i.messages,
                     "start_ns": i.start_ns, "end_ns": i.end_ns,
                     "topics": [{"name": n, "type": t.type_name, "count": i.counts[n]}
                                for n, t in sorted(i.topics.items())]} for i in infos])
        return 0
    for i in infos:
        state = "complete" if i.complete else (
            f"TRUNCATED: {i.damage}; recover with `{PROG} recover {bag_of(i.path) or i.path}`")
        print(f"{i.path}: {state}")
        print(f"  {i.messages} messages, {_span(i)}; profile {i.profile!r}, "
              f"written by {i.library or 'unknown'}")
        print("\n".join(_topic_lines(i)))
    return 0


# ----------------------------------------------------------------------------- parser
def _common() -> Parser:
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


def _duration_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=finite, metavar="S",
                   help="stroke duration [s] (default 12; at most about 13, or the nut would "
                        "leave the screw)")


def build_parser() -> Parser:
    common = [_common()]
    parser = Parser(prog=PROG, description="Predict friction-induced squeak of a lead screw "
                                           "(continuous model, eigenvalues of eq. 27).")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=Parser)

    p = sub.add_parser("modes", parents=common, help="natural frequencies of the uncoupled screw")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=cmd_modes)

    p = sub.add_parser("predict", parents=common, help="squeak prediction at one operating point")
    p.add_argument("--speed", type=finite, required=True, metavar="RAD_S",
                   help="rotation speed Omega [rad/s]")
    p.add_argument("--load", type=finite, metavar="N",
                   help="axial load F_z [N] (default: parameter axial_load_n)")
    p.add_argument("--json", action="store_true", help="print Prediction.as_dict() as JSON")
    p.set_defaults(run=cmd_predict)

    p = sub.add_parser("sweep", parents=common, help="predictions along one axis",
                       epilog=WORK_LIMITS)
    p.add_argument("--speed", metavar="START:STOP:COUNT | RAD_S",
                   help="speed range of a speed sweep, or the fixed speed of another sweep "
                        "(default 20 rad/s)")
    p.add_argument("--axis", metavar="NAME", help=f"axis to sweep (default {SPEED_AXIS}); one of "
                                                  f"{', '.join(axis_names())}")
    p.add_argument("--values", metavar="START:STOP:COUNT", help="range of the swept axis (SI)")
    p.add_argument("--load", type=finite, metavar="N",
                   help="fixed axial load [N] (default axial_load_n)")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print SweepResult.as_dict() as JSON")
    out.add_argument("--csv", action="store_true", help="print one CSV row per point")
    p.add_argument("--plot", metavar="FILE.png", help="plot growth rates vs the axis")
    p.set_defaults(run=cmd_sweep)

    p = sub.add_parser("map", parents=common, help="2-D stability map with refined boundary",
                       epilog=WORK_LIMITS)
    p.add_argument("--x", required=True, metavar="NAME:START:STOP:COUNT", help="x axis")
    p.add_argument("--y", required=True, metavar="NAME:START:STOP:COUNT", help="y axis")
    p.add_argument("--speed", type=finite, metavar="RAD_S",
                   help="fixed speed [rad/s] (default 20)")
    p.add_argument("--load", type=finite, metavar="N",
                   help="fixed axial load [N] (default axial_load_n)")
    p.add_argument("--json", action="store_true", help="print MapResult.as_dict() as JSON")
    p.add_argument("--plot", metavar="FILE.png", help="filled contour of the growth rate")
    p.set_defaults(run=cmd_map)

    p = sub.add_parser("figures", parents=common, help="the paper's Figs. 4-11 and summary.txt",
                       epilog=WORK_LIMITS.replace("points", "points in all", 1))
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--quick", action="store_true", help="coarse grids (a few seconds)")
    p.set_defaults(run=cmd_figures)

    p = sub.add_parser("demo", help="the ROS 2 predictor node driven by the actuator simulator "
                                    "(one process, loopback, private ROS_DOMAIN_ID)")
    _duration_option(p)
    p.add_argument("--record-dir", default="squeak_demo", metavar="DIR",
                   help="the predictor records inputs and outputs into a bag in DIR (created; "
                        "default ./squeak_demo)")
    p.add_argument("--no-record", action="store_true", help="do not record")
    p.set_defaults(run=cmd_demo)

    p = sub.add_parser("simulate", help="publish a simulated power-seat stroke for a separately "
                                        "started squeak_node (same ROS_DOMAIN_ID)",
                       usage="%(prog)s [options] [--ros-args ...]",
                       epilog=ROS_ARGS_HELP + "; e.g. --ros-args -r __ns:=/seat_left publishes "
                                              "/seat_left/motor_speed, ...")
    _duration_option(p)
    p.add_argument("--rate", type=finite, default=100.0, metavar="HZ",
                   help="publishing rate [Hz] (default 100)")
    p.add_argument("--loop", action="store_true",
                   help="repeat the stroke, back and forth, until Ctrl-C")
    p.add_argument("--joint-name", default="", metavar="NAME",
                   help="also publish joint_states with this joint (screw angle, speed)")
    p.add_argument("--no-wait", action="store_true",
                   help="start the stroke at once instead of when something subscribes to "
                        "motor_speed")
    p.set_defaults(run=cmd_simulate)

    p = sub.add_parser("replay", parents=common,
                       help="recompute the node's predictions for an MCAP log (offline, into "
                            "--out), or play the log to ROS 2 topics (--publish)")
    p.add_argument("log", metavar="LOG", help="MCAP file, or a directory of split .mcap files "
                   "(offline also rosbag2 sqlite3 .db3)")
    p.add_argument("--out", metavar="DIR", help="output directory (default ./<log name>_replay): "
                   "<log name>.annotated.mcap, episodes.json, summary.json/.txt, PNG report")
    g = p.add_argument_group("inputs (defaults: the node's topics, relative names in the input "
                             "namespace; node parameters from --params-file)")
    g.add_argument("--speed-topic", metavar="TOPIC", help="std_msgs/Float64 speed [rad/s] "
                                                          "(default motor_speed)")
    g.add_argument("--load-topic", metavar="TOPIC", help="std_msgs/Float64 axial load [N] "
                                                         "(default axial_load)")
    g.add_argument("--nut-topic", metavar="TOPIC", help="std_msgs/Float64 nut position [m] "
                                                        "(default nut_position)")
    g.add_argument("--joint-states-topic", metavar="TOPIC",
                   help="sensor_msgs/JointState (default joint_states)")
    g.add_argument("--joint-name", metavar="NAME", help=_setting_help(
        "joint_name", "screw joint in the JointState messages ('': the joint of single-joint "
        "messages)"))
    g.add_argument("--nut-position-at-zero-angle", dest="nut_position_at_zero_angle_m",
                   type=finite, metavar="M", help=_setting_help("nut_position_at_zero_angle_m"))
    g.add_argument("--speed-deadband", dest="speed_deadband_rad_s", type=finite,
                   metavar="RAD_S", help=_setting_help("speed_deadband_rad_s"))
    g.add_argument("--load-deadband", dest="load_deadband_n", type=finite, metavar="N",
                   help=_setting_help("load_deadband_n"))
    g.add_argument("--nut-deadband", dest="nut_deadband_m", type=finite, metavar="M",
                   help=_setting_help("nut_deadband_m"))
    g = p.add_argument_group("offline replay")
    g.add_argument("--namespace", metavar="NS",
                   help="namespace of the input topics, as a node's __ns (default: the one "
                        "namespace of the log that has predictor inputs)")
    g.add_argument("--out-namespace", metavar="NS",
                   help="namespace of the prediction topics in the annotated log (default "
                        "/replay + the input namespace: /replay/squeak/risk, ...)")
    g.add_argument("--load", dest="nominal_load_n", type=finite, metavar="N",
                   help="nominal axial load [N] from the start, for a log without load topic "
                        "(a load topic in the log overrides it)")
    g.add_argument("--workers", type=int, default=1, metavar="N",
                   help="prediction processes for long logs (default 1; 0: one process)")
    g.add_argument("--no-report", action="store_true", help="skip the PNG report")
    g.add_argument("--episodes", type=int, default=10, metavar="N",
                   help="squeak episodes listed on stdout (default 10)")
    p.add_argument("--quiet", action="store_true", help="no progress and no summary")
    g = p.add_argument_group("playback to ROS 2 topics")
    g.add_argument("--publish", action="store_true",
                   help="publish the log's messages in real time instead")
    g.add_argument("--rate", type=finite, metavar="R", help="speed factor (default 1)")
    g.add_argument("--loop", action="store_true", help="repeat until Ctrl-C")
    g.add_argument("--start-offset", type=finite, metavar="S",
                   help="skip this much of the log [s]")
    g.add_argument("--topics", nargs="+", metavar="T",
                   help="publish exactly these topics (default: the predictor's inputs)")
    g.add_argument("--remap", action="append", default=[], metavar="OLD:=NEW",
                   help="publish log topic OLD on NEW (repeatable; a relative NEW is in the "
                        "node's namespace)")
    g.add_argument("--no-wait", action="store_true",
                   help="start at once instead of waiting (up to 5 s) for a subscriber")
    p.epilog = (ROS_ARGS_HELP + " (with --publish; in a namespace other than / the log's inputs "
                                "are published in it: --ros-args -r __ns:=/seat_right)")
    p.set_defaults(run=cmd_replay)

    p = sub.add_parser(
        "recover", help="make a recording cut off by a crash readable by every tool: each cut-off "
                        "file rewritten complete in place (the original kept as "
                        "<name>.mcap.broken until the rewrite reads back), the bag's "
                        "metadata.yaml regenerated; a second run changes nothing")
    p.add_argument("log", metavar="BAGDIR|FILE",
                   help="bag directory, one .mcap file (its bag's metadata.yaml is regenerated "
                        "too), or a record directory (every cut-off bag in it)")
    p.add_argument("-o", "--output", metavar="OUT.mcap",
                   help="write the recovered messages of one FILE to OUT.mcap instead, leaving "
                        "the input untouched")
    p.set_defaults(run=cmd_recover)

    p = sub.add_parser("info", help="topics, types, counts, time span of an MCAP log; "
                                    "complete or truncated")
    p.add_argument("log", metavar="LOG", help="MCAP file or directory of split files")
    p.add_argument("--json", action="store_true", help="print JSON (one object per file)")
    p.set_defaults(run=cmd_info)
    return parser


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(the program's arguments, the ROS arguments): every `--ros-args` section up to `--` or
    the end, as rcl delimits them (the `--` itself belongs to neither)."""
    ours: list[str] = []
    ros: list[str] = []
    inside = False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
            ros.append(arg)
        elif inside and arg == "--":
            inside = False
        else:
            (ros if inside else ours).append(arg)
    return ours, ros


def _one_line(message: str) -> str:
    return " ".join(str(message).split())


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 2 bad input, 130 interrupted, 141 closed
    pipe). The long-running ROS commands (demo, simulate, replay --publish) return 0 when
    stopped by SIGINT/SIGTERM (`ros_env.StopSignals.exit_status`); 130 is Ctrl-C of the others
    or a second Ctrl-C."""
    try:
        ours, ros_args = split_ros_args(sys.argv[1:] if argv is None else list(argv))
        args = build_parser().parse_args(ours)
        args.ros_args = ros_args
        if ros_args and args.command not in ROS_COMMANDS:
            raise CliError(f"{args.command} takes no --ros-args (only "
                           f"{' and '.join(ROS_COMMANDS)} --publish do)")
        run: Callable[[argparse.Namespace], int] = args.run
        return run(args)
    except BrokenPipeError:      # `... | head`: the reader left; stay quiet like other tools
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (CliError, ParameterError, OperatingPointError, LogError, OSError) as exc:
        # OSError: unwritable --out / --plot and the like.
        print(f"{PROG}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except SystemExit as exc:    # --help
        return exc.code if isinstance(exc.code, int) else 0
    except MemoryError:          # beyond the up-front estimates: still one line, no traceback
        print(f"{PROG}: error: out of memory; use fewer points", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
