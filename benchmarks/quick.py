# SPDX-License-Identifier: Apache-2.0
"""Quick regression guard: the benchmarks' key ratios in one short run (~10 s on 2 cores).

    .venv/bin/python benchmarks/quick.py

Prints one Markdown table of ratios (each measured in this run against a bare LAPACK
eigen-solve, or the log duration over the wall time for the replay) with the target of the
full benchmark it stands for, and the machine load (1-minute load average at start and end).
The ratios come from the full benchmarks' own functions at smaller sizes: `bench_point`,
`bench_scatter_point` and `bench_map` (48x48) of bench_model.py, `live_update_ratio` of
bench_probability.py, `run` of bench_contact.py (6/6 modes), and `replay` of a 2-minute
duty-cycle log.
A ratio above its target prints "MISSED" and the exit code stays 0: the runs are short
and the machine may be busy, so a slowdown shows in every CI log (.ci/run) without failing it.
Only a ratio worse than `FAIL_FACTOR` (2) times its target prints "FAILED" and exits 1 (so
does a crash): a lost factor stops CI, noise does not. A ratio over that line is measured again
up to `RETRIES` times and fails only if every run is over it (the scatter row, above its
target even on a quiet machine, came out over it once at load 6). Read a MISSED against the
load, then run the full benchmark (its name is in the table) before concluding anything.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections.abc import Callable
from statistics import median

import bench_contact
import bench_model
import bench_probability
import bench_replay
from leadscrew_ros.bag.synthetic import DutyCycle
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.uncertainty.scatter import Scatter
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings

MAP_GRID = 48  # speed x load points per side (the full benchmark: 200)
REPLAY_LOG_S = 120.0  # the duty-cycle log of bench_replay.py, shortened
REPLAY_ROUNDS = 1
FAIL_FACTOR = 2.0  # a ratio above this multiple of its target fails the run (exit 1)
RETRIES = 2  # more runs of a row above that line: it fails only if all are above


def replay_ratio(duration_s: float, rounds: int) -> float:
    """Log duration over the median wall time of `replay` of a duty-cycle log (generated once
    and cached, as bench_replay.py does; one process: no worker start-up in so short a
    log)."""
    cycle = DutyCycle(duration_s=duration_s)
    bag, _ = bench_replay.cached_log(cycle, regenerate=False)
    model, walls = SqueakModel(), []
    for _ in range(rounds):
        with tempfile.TemporaryDirectory(prefix="bench_quick_") as out:
            t0 = time.perf_counter()
            replay(
                bag,
                model,
                out,
                ReplaySettings(
                    InputSettings(joint_name=cycle.joint_name), workers=0, progress=False
                ),
            )
            walls.append(time.perf_counter() - t0)
    return duration_s / median(walls)


def verdict(ratio: float, target: float | None) -> str:
    """'' without a target; 'met' at or below it (every target is an upper bound of its
    ratio), 'MISSED' above it, 'FAILED' above `FAIL_FACTOR` times it."""
    if target is None:
        return ""
    if ratio > FAIL_FACTOR * target:
        return "FAILED"
    return "met" if ratio <= target else "MISSED"


Row = tuple[str, str, float, "float | None", "Callable[[], float] | None"]


def rows() -> list[Row]:
    """(what, full benchmark, ratio, target: its upper bound or None, a function measuring
    the ratio again or None) per measurement."""
    model = SqueakModel()
    no_scatter = model.with_scatter(Scatter({}))

    def point() -> float:
        return bench_model.bench_point(model, rounds=9, loops=2)["ratio"]

    def scatter() -> float:
        return bench_model.bench_scatter_point(model, rounds=9, loops=1)["ratio"]

    def live() -> float:
        return bench_probability.live_update_ratio(SqueakModel(), rounds=5, repeat=50)[2]

    def map_ratio(key: str) -> Callable[[], float]:
        return lambda: bench_model.bench_map(no_scatter, MAP_GRID, rounds=3, naive_points=4)[key]

    def contact() -> float:  # 15 rounds: 5 gave 0.27-0.69x in one minute at load 10
        return bench_contact.run(6, rounds=15, calls=30)["rebuild_ratio"]

    first_point, first_scatter, first_live = point(), scatter(), live()
    mp = bench_model.bench_map(no_scatter, MAP_GRID, rounds=3, naive_points=4)
    first_contact = contact()
    x_real_time = replay_ratio(REPLAY_LOG_S, REPLAY_ROUNDS)
    return [
        (
            "`predict` without scatter / bare `eig`",
            "bench_model.py 1",
            first_point,
            bench_model.TARGET_POINT_RATIO,
            point,
        ),
        (
            f"`predict` with the default scatter at {len(bench_model.random_points())} random "
            "points / bare `eig`",
            "bench_model.py 1",
            first_scatter,
            bench_model.TARGET_SCATTER_RATIO,
            scatter,
        ),
        (
            "live update with P(squeak) (`predict`) / bare `eig`",
            "bench_probability.py",
            first_live,
            bench_probability.TARGET_LIVE_RATIO,
            live,
        ),
        (
            f"`growth_field` {MAP_GRID}×{MAP_GRID} map / bare batched `eigvals`",
            "bench_model.py 2",
            mp["ratio"],
            bench_model.TARGET_MAP_RATIO,
            map_ratio("ratio"),
        ),
        (
            f"`stability_map` {MAP_GRID}×{MAP_GRID} (grid + refined boundary, "
            f"{mp['boundary_points']} points) / bare batched `eigvals` (the target is for "
            "200×200: a small grid has more boundary per point)",
            "bench_model.py 2",
            mp["refined_ratio"],
            bench_model.TARGET_REFINED_MAP_RATIO,
            map_ratio("refined_ratio"),
        ),
        (
            "new nut position (model rebuild) / bare `eig`",
            "bench_contact.py",
            first_contact,
            bench_contact.TARGET,
            contact,
        ),
        (
            f"replay of a {REPLAY_LOG_S:g} s duty-cycle log, one process: real time / wall time "
            f"(opening and closing the bags dominate so short a log; the target ≥ "
            f"{bench_replay.TARGET_X_REAL_TIME['duty']:g}× is for the 1 h log)",
            "bench_replay.py",
            x_real_time,
            None,
            None,
        ),
    ]


def confirmed(ratio: float, target: float | None, again: Callable[[], float] | None) -> list:
    """The runs of a row: `ratio`, and while each run is FAILED, up to `RETRIES` more."""
    runs = [ratio]
    while again is not None and verdict(runs[-1], target) == "FAILED" and len(runs) <= RETRIES:
        runs.append(again())
    return runs


def main() -> int:
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    table = rows()
    print("| measure | full benchmark | ratio | target |\n|---|---|---:|---|")
    failed = []
    for what, full, ratio, target, again in table:
        runs = confirmed(ratio, target, again)
        v = verdict(min(runs), target)
        shown = "–" if target is None else f"≤ {target:g}× {v}"
        if len(runs) > 1:
            shown += " (runs: " + ", ".join(f"{r:.2f}×" for r in runs) + ")"
        print(f"| {what} | {full} | {min(runs):.2f}× | {shown} |")
        if v == "FAILED":
            failed.append(f"{what}: {min(runs):.2f}× against ≤ {target:g}×")
    print(
        f"\nquick mode (ratios from this run; MISSED never fails, FAILED above {FAIL_FACTOR:g}× "
        f"a target in {RETRIES + 1} runs) · {os.cpu_count()} CPUs · load avg {load0:.2f} → "
        f"{os.getloadavg()[0]:.2f} · {time.perf_counter() - t0:.1f} s"
    )
    for line in failed:
        print(f"quick.py: FAILED, more than {FAIL_FACTOR:g}× the target: {line}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
