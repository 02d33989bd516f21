# SPDX-License-Identifier: Apache-2.0
"""The model commands: `modes` (natural frequencies), `predict` (one operating point, with
P(squeak) over the scatter, its sensitivities and countermeasures), `sweep` (one axis) and `map`
(two axes, with the refined stability boundary and, with --probability, iso-P contours).

Which P(squeak) is which: `predict` reports the reference estimate (`probability.monte_carlo`,
`REFERENCE_SAMPLES` samples, with its standard error) as `probability`, and the fast first-order
estimate the node publishes (`Prediction.probability`, --samples samples) as
`probability_live`; sweeps, maps and figures use the fast one at every point.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from dataclasses import dataclass

import numpy as np

from ..model.physics.parameters import field_info
from ..model.squeak_model import Prediction, SqueakModel
from ..model.studies.countermeasures import STEP, Countermeasure, advice_text, countermeasures
from ..model.studies.fields import axis_names, check_axis, integer_axis
from ..model.studies.probability import ProbabilityEstimate, monte_carlo
from ..model.studies.sensitivity import Sensitivity, sensitivities
from ..model.studies.stability_map import MapResult
from ..model.studies.sweep import SweepResult, sweep
from ..model.studies.work import sweep_work
from ..model.uncertainty.scatter import samples_for
from .args import (
    SPEED_AXIS,
    WORK_LIMITS,
    CliError,
    Parser,
    build_model,
    finite,
    finite_float,
    parse_axis_spec,
    parse_range,
    plot_file,
    print_json,
)

REFERENCE_SAMPLES = 4096  # Monte Carlo samples of predict's `probability`
SENSITIVITIES_SHOWN = 4  # largest growth-rate sensitivities in the text output


def axis_unit(name: str) -> str:
    """SI unit of a sweep axis (the unit of the values on the command line)."""
    return {SPEED_AXIS: "rad/s", "load_n": "N"}.get(name) or field_info(name)["unit"] or "1"


# ----------------------------------------------------------------------------- output
def _mode_table(prediction: Prediction, count: int) -> list[str]:
    lines = [f"  {'mode':<6}{'frequency [Hz]':>16}{'growth [1/s]':>15}{'damping ratio':>15}"]
    for m in prediction.modes[:count]:
        lines.append(
            f"  {m.label:<6}{m.frequency_hz:>16.2f}{m.growth_rate:>+15.3f}"
            f"{m.damping_ratio:>+15.2e}{'  squeak' if m.unstable else ''}"
        )
    return lines


@dataclass(frozen=True)
class Assessment:
    """What `predict` adds to the prediction at one operating point (`assess`).

    Attributes
    ----------
    reference : ProbabilityEstimate or None
        Reference P(squeak) (Monte Carlo over REFERENCE_SAMPLES scatter samples) and its
        standard error (None without scatter); None outside validity.
    live : float or None
        The fast estimate of `Prediction.probability` (what the node publishes).
    sensitivity : Sensitivity or None
        Growth-rate sensitivities d Re(lambda) / d ln p [1/s] of the least stable mode.
    measures : list of Countermeasure or None
        10 % changes that lower P, most effective first, each with the new P (fast estimator
        on the reference samples).
    """

    reference: ProbabilityEstimate | None
    live: float | None
    sensitivity: Sensitivity | None = None
    measures: list[Countermeasure] | None = None

    def as_dict(self) -> dict:
        """The keys `predict --json` adds to `Prediction.as_dict()`."""
        ref, sens = self.reference, self.sensitivity
        return {
            "probability": None if ref is None else ref.probability,
            "probability_stderr": None if ref is None else ref.stderr,
            "probability_samples": 0 if ref is None else ref.count,
            "probability_live": self.live,
            "sensitivities": None if sens is None else sens.growth_per_log,
            "countermeasures": None
            if self.measures is None
            else [
                {
                    "parameter": c.name,
                    "change": STEP if c.factor > 1 else -STEP,
                    "probability": c.probability,
                    "advice": c.text,
                }
                for c in self.measures
            ],
        }

    def line(self) -> str:
        """'P(squeak) 0.13 ± 0.003: raise the radius or raise the speed' (`advice_text` with
        the standard error); '' outside validity."""
        if self.reference is None:
            return ""
        assert self.measures is not None  # assessed with the reference (`assess`)
        head, sep, rest = advice_text(self.reference.probability, self.measures).partition(":")
        if self.reference.stderr is not None:
            head += f" ± {self.reference.stderr:.1g}"
        return head + sep + rest


def assess(model: SqueakModel, p: Prediction) -> Assessment:
    """The reference P(squeak), sensitivities and countermeasures at the point of `p`."""
    if not p.valid:
        return Assessment(None, p.probability)
    samples = samples_for(model.params, model.scatter, REFERENCE_SAMPLES)
    found = countermeasures(model, p.speed_rad_s, p.load_n, samples)
    return Assessment(
        monte_carlo(model, p.speed_rad_s, p.load_n, samples),
        p.probability,
        sensitivities(model, p.speed_rad_s, p.load_n),
        found and found[1],
    )


def prediction_text(p: Prediction, extra: Assessment, top: int = 5) -> str:
    """The text output of `predict`; `extra` from `assess`."""
    head = f"speed {p.speed_rad_s:g} rad/s, load {p.load_n:g} N, {p.formulation} formulation"
    if not p.valid:
        return f"{head}\nno prediction: {p.reason}"
    if p.stable:
        verdict = "stable at the nominal parameters: no squeak"
    else:
        squeak = (
            ", ".join(
                f"{m.label} {m.frequency_hz:.1f} Hz (Re {m.growth_rate:+.2f} 1/s)"
                for m in p.squeak_modes
            )
            or "none"
        )
        verdict = f"UNSTABLE at the nominal parameters: squeak predicted; squeak modes: {squeak}"
    lines = [head, verdict, extra.line()]
    assert extra.sensitivity is not None  # assessed at a valid point (`assess`)
    largest = sorted(extra.sensitivity.growth_per_log.items(), key=lambda kv: -abs(kv[1]))
    lines.append(
        "growth rate d Re(lambda) / d ln p [1/s]: "
        + ", ".join(f"{name} {value:+.3g}" for name, value in largest[:SENSITIVITIES_SHOWN])
    )
    if p.divergence_rates:
        lines.append(
            "divergence (real eigenvalues > 0): "
            + ", ".join(f"{r:.4g} 1/s" for r in p.divergence_rates)
        )
    lines.append(f"least stable of {len(p.modes)} oscillatory modes:")
    return "\n".join(lines + _mode_table(p, top))


def _unstable_labels(p: Prediction) -> str:
    return ";".join(m.label for m in p.squeak_modes)


def _cell(value: float | None) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.10g}"


def write_sweep_csv(result: SweepResult) -> None:
    """Write a sweep's predictions to stdout as CSV."""
    out = csv.writer(sys.stdout, lineterminator="\n")
    out.writerow(
        [
            result.axis,
            "valid",
            "max_growth_rate",
            "probability",
            "probability_stderr",
            "unstable_modes",
            "unstable_frequencies_hz",
        ]
    )
    for value, p in zip(result.values.tolist(), result.predictions, strict=True):
        out.writerow(
            [
                repr(value),
                p.valid,
                _cell(p.max_growth_rate),
                _cell(p.probability),
                _cell(p.probability_stderr),
                _unstable_labels(p),
                ";".join(f"{f:.6g}" for f in p.unstable_frequencies_hz),
            ]
        )


def _percent(level: float) -> str:
    return f"{100 * level:g} %"


def crossings_text(crossings: dict[float, list], unit: str) -> str:
    """'P(squeak) crosses 1 % at 65.4, 10 % at 60.6, 50 % at 54.6, 90 % nowhere [rad/s]'."""
    return (
        "P(squeak) crosses "
        + ", ".join(
            f"{_percent(level)} at {', '.join(f'{v:.4g}' for v in values)}"
            if values
            else f"{_percent(level)} nowhere"
            for level, values in crossings.items()
        )
        + f" [{unit}]"
    )


def sweep_text(result: SweepResult, probability: bool = False) -> str:
    """A sweep as text: the grid, the unstable bands and boundaries (and P(squeak) levels)."""
    unit, g = axis_unit(result.axis), result.max_growth_rate
    fixed = ", ".join(f"{k} = {v:g} {axis_unit(k)}" for k, v in result.fixed.items())
    n_valid = int(np.isfinite(g).sum())
    bands = ", ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in result.unstable_bands) or "none"
    lines = [
        f"sweep of {result.axis} [{unit}] from {result.values[0]:g} to "
        f"{result.values[-1]:g} ({len(result.values)} points; fixed {fixed}; "
        f"{result.predictions[0].formulation} formulation)",
        f"valid points: {n_valid}/{len(g)}",
        f"unstable bands [{unit}]: {bands}",
        "stability boundaries ["
        + unit
        + "]: "
        + (", ".join(f"{b:.6g}" for b in result.boundaries) or "none"),
    ]
    if n_valid:
        p = result.predictions[int(np.nanargmin(np.abs(result.values - result.peak_value)))]
        lines.append(
            f"largest growth rate {result.peak_growth_rate:.5g} 1/s at {result.axis} = "
            f"{result.peak_value:.6g} {unit} (refined between grid points"
            + (
                f"; squeak modes at the nearest grid point {_unstable_labels(p).replace(';', ', ')}"
                if p.squeak_modes
                else ""
            )
            + ")"
        )
    if probability and n_valid:
        prob = result.probability
        i = int(np.nanargmax(prob))
        lines += [
            crossings_text(result.probability_crossings, unit),
            f"largest P(squeak) {prob[i]:.3g} at {result.axis} = {result.values[i]:g} {unit}",
        ]
    reasons = {p.reason for p in result.predictions if not p.valid}
    lines += [f"invalid: {r}" for r in sorted(reasons)]
    return "\n".join(lines)


def map_text(result: MapResult) -> str:
    """A stability map as text: grid, valid and unstable points, boundary and iso-P counts."""
    g = result.field.max_growth_rate
    valid = np.isfinite(g)
    fixed = ", ".join(f"{k} = {v:g} {axis_unit(k)}" for k, v in result.fixed.items())
    lines = [
        f"stability map: x = {result.x_axis} [{axis_unit(result.x_axis)}] "
        f"{result.x[0]:g}..{result.x[-1]:g} ({len(result.x)}), y = {result.y_axis} "
        f"[{axis_unit(result.y_axis)}] {result.y[0]:g}..{result.y[-1]:g} "
        f"({len(result.y)})" + (f"; fixed {fixed}" if fixed else ""),
        f"valid points: {int(valid.sum())}/{g.size}",
    ]
    if valid.any():
        j, i = np.unravel_index(np.nanargmax(g), g.shape)
        lines += [
            f"unstable fraction of valid points: {np.mean(g[valid] > 0):.3f}",
            f"largest growth rate {g[j, i]:.4g} 1/s at {result.x_axis} = {result.x[i]:g}, "
            f"{result.y_axis} = {result.y[j]:g}",
        ]
    lines.append(f"refined boundary points: {len(result.boundary)}")
    if result.probability is not None:
        lines.append(
            "iso-P(squeak) points: "
            + ", ".join(
                f"{_percent(level)}: {len(points)}"
                for level, points in result.probability_contours().items()
            )
        )
    return "\n".join(lines)


# ----------------------------------------------------------------------------- commands
def cmd_modes(args: argparse.Namespace) -> int:
    """`modes`: print the model's modes and frequencies; exit status."""
    basis = build_model(args).geometry.basis
    order = np.argsort(basis.frequency_hz, kind="stable")
    modes = [
        {"label": basis.labels[i], "frequency_hz": float(basis.frequency_hz[i])} for i in order
    ]
    if args.json:
        print_json({"modes": modes})
    else:
        print(f"{'mode':<6}{'frequency [Hz]':>16}")
        print("\n".join(f"{m['label']:<6}{m['frequency_hz']:>16.1f}" for m in modes))
    return 0


def cmd_predict(args: argparse.Namespace) -> int:
    """`predict`: print the prediction at one operating point; exit status."""
    model = build_model(args)
    p = model.predict(args.speed, args.load)
    extra = assess(model, p)
    if args.json:
        print_json({**p.as_dict(), **extra.as_dict()})
    else:
        print(prediction_text(p, extra))
    return 0


def _sweep_axis(args: argparse.Namespace) -> tuple[str, np.ndarray, float | None, float | None]:
    """(axis, values, fixed speed, fixed load) from `--speed RANGE` or `--axis/--values`."""
    axis = args.axis or SPEED_AXIS
    check_axis(axis)
    if axis == SPEED_AXIS:
        if (args.values is None) == (args.speed is None):
            raise CliError(
                "a speed sweep needs exactly one of --speed START:STOP:COUNT and "
                "--values START:STOP:COUNT"
            )
        option = "--values" if args.values else "--speed"
        return axis, parse_range(args.values or args.speed, f"argument {option}"), None, args.load
    if args.values is None:
        raise CliError(f"--axis {axis} needs --values START:STOP:COUNT")
    if axis == "load_n" and args.load is not None:
        raise CliError("--load cannot be combined with --axis load_n")
    speed = None if args.speed is None else finite_float(args.speed, "argument --speed")
    return (
        axis,
        parse_range(args.values, "argument --values", integer_axis(axis)),
        speed,
        args.load,
    )


def cmd_sweep(args: argparse.Namespace) -> int:
    """`sweep`: sweep one axis and print the result; exit status."""
    model = build_model(args)
    axis, values, speed, load = _sweep_axis(args)
    plot = plot_file(args.plot)
    sweep_work(model, axis, values).check()  # before a progress bar shows
    from ..review.progress import progress_bar

    with progress_bar(len(values), "sweep") as update:
        result = sweep(model, axis, values, speed, load, progress=update)
    if args.json:
        print_json(result.as_dict())
    elif args.csv:
        write_sweep_csv(result)
    else:
        print(sweep_text(result, args.probability))
    if plot:
        from ..review.plots import plot_sweep

        plot_sweep(result, probability=args.probability).savefig(plot, dpi=120)
    return 0


def cmd_map(args: argparse.Namespace) -> int:
    """`map`: compute a stability map over two axes and print it; exit status."""
    model = build_model(args)
    x_axis, x = parse_axis_spec(args.x, "argument --x")
    y_axis, y = parse_axis_spec(args.y, "argument --y")
    plot = plot_file(args.plot)
    for option, name, value in (
        ("--speed", SPEED_AXIS, args.speed),
        ("--load", "load_n", args.load),
    ):
        if value is not None and name in (x_axis, y_axis):
            raise CliError(f"{option} cannot be combined with a {name} map axis")
    from .figures import run_map

    result = run_map(
        model, x_axis, x, y_axis, y, args.speed, args.load, probability=args.probability
    )
    if args.json:
        print_json(result.as_dict())
    else:
        print(map_text(result))
    if plot:
        from ..review.plots import plot_map, probability_overlay

        plot_map(
            result,
            formulation=model.params.formulation,
            overlay=probability_overlay(result) if args.probability else None,
        ).savefig(plot, dpi=120)
    return 0


# ----------------------------------------------------------------------------- parsers
def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `modes`, `predict`, `sweep` and `map` to `sub`; `common`: the model options."""
    p = sub.add_parser("modes", parents=common, help="natural frequencies of the uncoupled screw")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=cmd_modes)

    p = sub.add_parser("predict", parents=common, help="squeak prediction at one operating point")
    p.add_argument(
        "--speed", type=finite, required=True, metavar="RAD_S", help="rotation speed Omega [rad/s]"
    )
    p.add_argument(
        "--load",
        type=finite,
        metavar="N",
        help="axial load F_z [N] (default: parameter axial_load_n)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print JSON: Prediction.as_dict() with probability = the reference "
        f"Monte Carlo P(squeak) over {REFERENCE_SAMPLES} scatter samples and "
        "probability_stderr (null without scatter), probability_live (the "
        "fast estimate the node publishes), sensitivities (d growth rate / "
        "d ln p [1/s] by parameter) and countermeasures (ranked, with the new "
        "P)",
    )
    p.set_defaults(run=cmd_predict)

    p = sub.add_parser(
        "sweep", parents=common, help="predictions along one axis", epilog=WORK_LIMITS
    )
    p.add_argument(
        "--speed",
        metavar="START:STOP:COUNT | RAD_S",
        help="speed range of a speed sweep, or the fixed speed of another sweep (default 20 rad/s)",
    )
    p.add_argument(
        "--axis",
        metavar="NAME",
        help=f"axis to sweep (default {SPEED_AXIS}); one of {', '.join(axis_names())}",
    )
    p.add_argument("--values", metavar="START:STOP:COUNT", help="range of the swept axis (SI)")
    p.add_argument(
        "--load", type=finite, metavar="N", help="fixed axial load [N] (default axial_load_n)"
    )
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print SweepResult.as_dict() as JSON")
    out.add_argument("--csv", action="store_true", help="print one CSV row per point")
    p.add_argument("--plot", metavar="FILE.png", help="plot growth rates vs the axis")
    p.add_argument(
        "--probability",
        action="store_true",
        help="also where P(squeak) (the fast estimator, in every output) crosses "
        "1, 10, 50 and 90 %% (text; JSON always has probability_crossings), "
        "and P on a second axis of --plot",
    )
    p.set_defaults(run=cmd_sweep)

    p = sub.add_parser(
        "map", parents=common, help="2-D stability map with refined boundary", epilog=WORK_LIMITS
    )
    p.add_argument("--x", required=True, metavar="NAME:START:STOP:COUNT", help="x axis")
    p.add_argument("--y", required=True, metavar="NAME:START:STOP:COUNT", help="y axis")
    p.add_argument("--speed", type=finite, metavar="RAD_S", help="fixed speed [rad/s] (default 20)")
    p.add_argument(
        "--load", type=finite, metavar="N", help="fixed axial load [N] (default axial_load_n)"
    )
    p.add_argument("--json", action="store_true", help="print MapResult.as_dict() as JSON")
    p.add_argument("--plot", metavar="FILE.png", help="filled contour of the growth rate")
    p.add_argument(
        "--probability",
        action="store_true",
        help="also P(squeak) at every grid point (the fast estimator: about twice "
        "the work): in JSON probability, probability_stderr and "
        "probability_contours (points where P crosses 1, 10, 50 and 90 %%), "
        "iso-P lines and the 10-90 %% band in --plot",
    )
    p.set_defaults(run=cmd_map)
