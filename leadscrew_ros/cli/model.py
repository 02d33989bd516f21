# SPDX-License-Identifier: Apache-2.0
"""The model commands: `modes` (natural frequencies), `predict` (one operating point), `sweep`
(one axis) and `map` (two axes, with the refined stability boundary)."""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np

from ..model.parameters import field_info
from ..model.predictor import Prediction
from ..model.sweep import MapResult, SweepResult, axis_names, check_axis, sweep, sweep_work
from .args import (SPEED_AXIS, WORK_LIMITS, CliError, Parser, build_model, finite, finite_float,
                   parse_axis_spec, parse_range, print_json)


def axis_unit(name: str) -> str:
    """SI unit of a sweep axis (the unit of the values on the command line)."""
    return {SPEED_AXIS: "rad/s", "load_n": "N"}.get(name) or field_info(name)["unit"] or "1"


# ----------------------------------------------------------------------------- output
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
        verdict = f"stable: no squeak (P(squeak) {p.probability:.3f})"
    else:
        squeak = ", ".join(f"{m.label} {m.frequency_hz:.1f} Hz (Re {m.growth_rate:+.2f} 1/s)"
                           for m in p.squeak_modes) or "none"
        verdict = f"UNSTABLE: squeak predicted (P(squeak) {p.probability:.3f}); squeak modes: {squeak}"
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
    out.writerow([result.axis, "valid", "max_growth_rate", "probability", "unstable_modes",
                  "unstable_frequencies_hz"])
    for value, p in zip(result.values.tolist(), result.predictions):
        out.writerow([repr(value), p.valid, _cell(p.max_growth_rate), _cell(p.probability),
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
    from .figures import run_map
    result = run_map(model, x_axis, x, y_axis, y, args.speed, args.load)
    if args.json:
        print_json(result.as_dict())
    else:
        print(map_text(result))
    if args.plot:
        from ..review.plots import plot_map
        plot_map(result, Path(args.plot), formulation=model.params.formulation)
    return 0


# ----------------------------------------------------------------------------- parsers
def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `modes`, `predict`, `sweep` and `map` to `sub`; `common`: the model options."""
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
