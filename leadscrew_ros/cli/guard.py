# SPDX-License-Identifier: Apache-2.0
"""`guard`: the guard's policy (`live.guard`) applied offline to a planned command
(PROFILE.csv) or a recorded log: DIR/guarded.csv, DIR/guarded.png and a summary of time in
squeak, peak P(squeak), motion time and travel, raw against guarded (`review.guard`)."""

from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path

from ..model.physics.metadata import help_text
from .args import CliError, Parser, build_model, finite, output_directory

CSV_NAME, PNG_NAME = "guarded.csv", "guarded.png"


def cmd_guard(args: argparse.Namespace) -> int:
    """`guard`: read, apply the policy, write the CSV and the picture, print the summary."""
    from ..live.guard import GuardSettings
    from ..review.guard import (
        ProfileFileError,
        apply_guard,
        read_log,
        read_profile,
        summary,
        write_run,
    )
    from ..review.plots import plot_guard

    out = output_directory(args.out)
    values = {f.name: getattr(args, f.name) for f in fields(GuardSettings)}
    try:
        settings = GuardSettings(**{k: v for k, v in values.items() if v is not None})
    except ValueError as exc:
        raise CliError(str(exc)) from None
    model = build_model(args)
    source = Path(args.source)
    try:
        if source.suffix.lower() == ".csv":
            command = read_profile(source, args.load, args.nut)
        else:
            command = read_log(source, model.params, args.load, args.nut)
    except ProfileFileError as exc:
        raise CliError(str(exc)) from None
    travel = model.params.nut_travel_m
    nut = command.nut_position_m
    if not ((nut >= 0) & (nut <= travel)).all():
        raise CliError(
            f"nut positions {nut.min():g}..{nut.max():g} m leave the screw (0..{travel:g} m)"
        )
    run = apply_guard(command, model, settings)
    out.mkdir(parents=True, exist_ok=True)
    write_run(out / CSV_NAME, run)
    plot_guard(run, title=f"guard on {source.name}").savefig(out / PNG_NAME, dpi=110)
    raw, guarded, stroke = summary(run)
    print(f"guard on {source} (p_max {settings.p_max:g}; {len(command.time_s)} steps)")
    print(f"  {'':26}{'raw':>10}{'guarded':>10}")
    for label, a, b, fmt in (
        ("time in squeak [s]", raw.time_in_squeak_s, guarded.time_in_squeak_s, ".2f"),
        ("peak P(squeak)", raw.peak_p, guarded.peak_p, ".3f"),
        ("motion time [s]", raw.motion_time_s, guarded.motion_time_s, ".2f"),
        ("travel [rad]", raw.travel_rad, guarded.travel_rad, ".1f"),
        ("stroke time, same travel [s]", raw.motion_time_s, stroke, ".2f"),
    ):
        print(f"  {label:26}{a:>10{fmt}}{b:>10{fmt}}")
    passed = sum(1 for r in run.reasons if "passed through" in r)
    if passed:
        print(f"  passed through (fail-safe): {passed} steps, e.g. {_first(run.reasons)}")
    print(f"  wrote {out / CSV_NAME} and {out / PNG_NAME}")
    return 0


def _first(reasons: list[str]) -> str:
    return next(r for r in reasons if "passed through" in r)


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `guard` to `sub`."""
    from ..live.guard import GuardSettings

    p = sub.add_parser(
        "guard",
        parents=common,
        help="apply the squeak guard to a speed command (PROFILE.csv or a recorded log): "
        "DIR/guarded.csv, DIR/guarded.png and time in squeak raw vs guarded",
    )
    p.add_argument(
        "source",
        metavar="PROFILE.csv|LOG",
        help="CSV with a header and columns time_s,speed_rad_s[,load_n,nut_position_m], or "
        "a recorded log (.mcap, .db3 or bag directory): its motor speed is the command",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--load", type=finite, metavar="N", help="axial load [N] where none is given")
    p.add_argument("--nut", type=finite, metavar="M", help="nut position [m] where none is given")
    for f in fields(GuardSettings):
        if f.name in ("enabled", "stale_timeout_s", "deadline_s"):
            continue  # a node's concerns: offline every input is fresh and every step on time
        p.add_argument("--" + f.name.replace("_", "-"), type=finite, metavar="X", help=help_text(f))
    p.set_defaults(run=cmd_guard, enabled=None, stale_timeout_s=None, deadline_s=None)
