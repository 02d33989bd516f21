# SPDX-License-Identifier: Apache-2.0
"""Coverage per layer of the package, from the data of the last test run.

    .venv/bin/python tools/coverage_by_layer.py [--data-file .coverage] [--fail-under PCT]

scripts/run-tests.sh runs it after the suite (pytest --cov=leadscrew_ros --cov-branch, child
processes included, see .coveragerc). For each layer (a directory of leadscrew_ros/, with its
sub-packages) it prints files, statements, missed statements, line coverage, and line+branch
coverage as coverage.py counts it. The rclpy-free layers (model, live, bag, review) have a
target of 90 % line coverage: a layer below it is marked BELOW; with --fail-under the exit
status is 1 when any of them is below PCT.
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import coverage

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "leadscrew_ros"
ROS_FREE = ("model", "live", "bag", "review")
TARGET = 90.0


def layers() -> dict[str, list[Path]]:
    """Layer name -> its .py files; modules at the package root count as '(root)'."""
    out = {"(root)": sorted(PACKAGE.glob("*.py"))}
    for d in sorted(p for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__"):
        out[d.name] = sorted(d.rglob("*.py"))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data-file", default=str(ROOT / ".coverage"))
    ap.add_argument(
        "--fail-under",
        type=float,
        default=None,
        metavar="PCT",
        help="exit 1 if a rclpy-free layer's line coverage is below PCT",
    )
    args = ap.parse_args(argv)
    if not Path(args.data_file).exists():
        print(f"coverage_by_layer: no coverage data at {args.data_file}", file=sys.stderr)
        return 2
    cov = coverage.Coverage(data_file=args.data_file, config_file=str(ROOT / ".coveragerc"))
    cov.load()
    print(f"{'layer':<8} {'files':>5} {'stmts':>6} {'miss':>5} {'lines':>7} {'+branch':>8}")
    below = []
    for name, files in layers().items():
        if not files:
            continue
        statements = missed = 0
        for f in files:
            _, stmts, _, missing, _ = cov.analysis2(str(f))
            statements += len(stmts)
            missed += len(missing)
        lines = 100.0 * (statements - missed) / statements if statements else 100.0
        # coverage.py's own total over these files: lines and branches together
        combined = cov.report(
            include=[str(f) for f in files],
            file=io.StringIO(),
            skip_covered=False,
            ignore_errors=True,
        )
        mark = ""
        if name in ROS_FREE:
            ok = lines >= (args.fail_under if args.fail_under is not None else TARGET)
            mark = "  target 90 % lines: met" if lines >= TARGET else "  target 90 % lines: BELOW"
            if not ok:
                below.append(name)
        print(
            f"{name:<8} {len(files):>5} {statements:>6} {missed:>5} {lines:>6.1f}% "
            f"{combined:>7.1f}%{mark}"
        )
    if args.fail_under is not None and below:
        print(f"coverage_by_layer: below {args.fail_under} %: {', '.join(below)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
