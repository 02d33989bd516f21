#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Numbers and picture of doc/user/guard.md: the guard on the demo stroke and three others.

    .venv/bin/python tools/guard_example.py [--plot [doc/images/guard.png]]  # ~40 s on 2 cores
    .venv/bin/python tools/guard_example.py --demo [doc/images/guard_demo.png]  # ~40 s more

Each stroke (`live.profile.StrokeProfile`, sampled at 100 Hz) is written as PROFILE.csv and run
through `leadscrew-squeak guard` (default settings, model and scatter), whose guarded.csv
gives the first table: time in squeak (P(squeak) >= p_max), peak P, travel, and the guarded
stroke time for the raw travel against the raw stroke's (`review.guard.summary`). Issue 33's
target: <= 0.3 s in squeak for <= 10 % longer stroke time. `--plot` copies the demo stroke's
guarded.png, made by the command, to the doc's picture. `--demo` runs `leadscrew-squeak demo
--guard` (the ROS nodes in the loop, one process), prints its output and copies its
guard_demo.png to the doc's picture of the node (as a palette PNG, as tools/doc_figures.py
stores its pictures).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from leadscrew_ros.cli import main as cli
from leadscrew_ros.live.guard import GuardSettings
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.review.guard import Command, GuardRun, read_profile, summary, write_profile

ROOT = Path(__file__).resolve().parents[1]
PICTURE = ROOT / "doc" / "images" / "guard.png"
DEMO_PICTURE = ROOT / "doc" / "images" / "guard_demo.png"
STROKES = {  # name -> StrokeProfile changes
    "demo (120-350 N, nut 0.02-0.22 m, 12 s)": {},
    "light (60-150 N)": dict(load_min_n=60.0, load_max_n=150.0),
    "heavy (250-600 N)": dict(load_min_n=250.0, load_max_n=600.0),
    "short (nut 0.10-0.17 m, 90 rad/s, 6 s)": dict(
        start_nut_position_m=0.10, peak_speed_rad_s=90.0, duration_s=6.0
    ),
}
TARGET_SQUEAK_S, TARGET_LONGER = 0.3, 0.10


def run_stroke(profile: StrokeProfile, out: Path) -> tuple[GuardRun, str]:
    """The stroke through `leadscrew-squeak guard`: its run (read back from guarded.csv) and
    what the command printed."""
    out.mkdir(parents=True, exist_ok=True)
    write_profile(out / "profile.csv", Command.of_profile(profile))
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        status = cli(["guard", str(out / "profile.csv"), "--out", str(out)])
    if status:
        raise SystemExit(f"leadscrew-squeak guard failed ({status})")
    data = np.genfromtxt(out / "guarded.csv", delimiter=",", names=True)
    command = read_profile(out / "profile.csv", None, None)
    run = GuardRun(
        command,
        data["guarded_speed_rad_s"],
        data["p_squeak_raw"],
        data["p_squeak_guarded"],
        [],
        GuardSettings(),
    )
    return run, text.getvalue()


def table(rows: list[tuple[str, GuardRun]]) -> str:
    """The Markdown table of doc/user/guard.md."""
    lines = [
        "| stroke | in squeak raw [s] | in squeak guarded [s] | peak P raw / guarded | "
        "travel raw / guarded [rad] | stroke time raw / guarded [s] | longer | target met |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, run in rows:
        raw, guarded, stroke = summary(run)
        longer = stroke / raw.motion_time_s - 1
        met = guarded.time_in_squeak_s <= TARGET_SQUEAK_S and longer <= TARGET_LONGER
        lines.append(
            f"| {name} | {raw.time_in_squeak_s:.2f} | {guarded.time_in_squeak_s:.2f} | "
            f"{raw.peak_p:.3f} / {guarded.peak_p:.3f} | {raw.travel_rad:.1f} / "
            f"{guarded.travel_rad:.1f} | {raw.motion_time_s:.2f} / {stroke:.2f} | "
            f"{100 * longer:+.1f} % | {'yes' if met else 'no'} |"
        )
    return "\n".join(lines)


def run_demo(picture: Path | None) -> str:
    """`leadscrew-squeak demo --guard` in a child process (its own ROS_DOMAIN_ID, loopback):
    its output from the summary on; its picture copied to `picture` as a palette PNG."""
    from PIL import Image

    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
        done = subprocess.run(
            [sys.executable, "-m", "leadscrew_ros.cli", "demo", "--guard", "--record-dir", tmp],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        )
        if picture is not None:
            image = Image.open(Path(tmp) / "guard_demo.png").convert("RGB")
            image.quantize(256, method=Image.Quantize.MEDIANCUT).save(picture, optimize=True)
        text = done.stdout[done.stdout.index("summary") :].replace(tmp, "squeak_demo")
    return "```\n$ leadscrew-squeak demo --guard\n...\n" + text.rstrip() + "\n```"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plot", nargs="?", const=PICTURE, type=Path, metavar="FILE.png")
    parser.add_argument(
        "--demo",
        nargs="?",
        const=DEMO_PICTURE,
        type=Path,
        metavar="FILE.png",
        help="only `leadscrew-squeak demo --guard`: its summary, its picture to FILE.png",
    )
    args = parser.parse_args()
    if args.demo:
        print(run_demo(args.demo))
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, changes) in enumerate(STROKES.items()):
            run, printed = run_stroke(StrokeProfile(**changes), Path(tmp) / f"stroke{k}")
            rows.append((name, run))
            if k == 0:
                print("```\n$ leadscrew-squeak guard demo.csv --out guard_demo")
                print(printed.replace(str(Path(tmp) / "stroke0"), "guard_demo").rstrip())
                print("```\n")
                if args.plot:
                    shutil.copy(Path(tmp) / "stroke0" / "guarded.png", args.plot)
    print(table(rows))


if __name__ == "__main__":
    main()
