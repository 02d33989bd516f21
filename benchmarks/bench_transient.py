# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the nonlinear time-domain simulation (issue 13), and the effect of --modes.

    .venv/bin/python benchmarks/bench_transient.py [--duration S] [--modes K ...]

1. 0.2 s of simulated time at Table 1 with all 18 modes, (20 rad/s, 200 N), on one core
   (OpenBLAS and OpenMP limited to one thread before numpy loads): CPU time of the process
   and wall time, and their ratio to the target of 60 s.
2. The same run with the K lowest-frequency modes (default 6, 12 and all): time, the fitted
   growth and frequency of the dominant component, and the limit cycle (peak surface velocity
   and torsion angle at the nut centre, fundamental, time to saturation).

Prints a Markdown table and an environment line (date, Python, numpy, scipy, load average at
start and end).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, before numpy loads
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy  # noqa: E402

from leadscrew_ros.model.nonlinear.transient import TransientSettings, simulate  # noqa: E402
from leadscrew_ros.model.nonlinear.transient_analysis import analyse  # noqa: E402
from leadscrew_ros.model.physics.parameters import ScrewParameters  # noqa: E402

SPEED_RAD_S, LOAD_N = 20.0, 200.0
TARGET_S = 60.0


def one(modes: int, duration: float) -> dict:
    """Simulate and analyse one run; times and results."""
    wall, cpu = time.perf_counter(), time.process_time()
    run = simulate(
        ScrewParameters(), SPEED_RAD_S, LOAD_N, TransientSettings(duration_s=duration, modes=modes)
    )
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    result = analyse(run)
    return {
        "modes": len(run.labels),
        "cpu_s": cpu,
        "wall_s": wall,
        "evaluations": run.evaluations,
        "result": result,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=0.2, help="simulated time [s]")
    parser.add_argument(
        "--modes", type=int, nargs="*", default=[0, 6, 12], help="modes kept per row (0: all)"
    )
    args = parser.parse_args()
    load0 = os.getloadavg()[0]
    rows = [one(k, args.duration) for k in args.modes]
    print(f"{args.duration:g} s simulated at ({SPEED_RAD_S:g} rad/s, {LOAD_N:g} N), Table 1\n")
    print(
        "| modes | CPU [s] | wall [s] | CPU / 60 s target | evaluations | regime | fit: mode, "
        "growth [1/s], frequency [Hz] | limit cycle: surface velocity [m/s], torsion [rad], "
        "fundamental [Hz], saturation [ms] |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        fit, cycle = r["result"].linear_fit, r["result"].limit_cycle
        lc = (
            "–"
            if cycle is None
            else f"{cycle.surface_velocity_m_s:.4g}, {cycle.torsion_rad:.4g}, "
            f"{cycle.fundamental_hz:.1f}, {cycle.time_to_saturation_s * 1e3:.1f}"
        )
        print(
            f"| {r['modes']} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} | "
            f"{r['cpu_s'] / TARGET_S:.2f} | {r['evaluations']} | {r['result'].regime} | "
            f"{fit.mode}, {fit.growth_rate:+.2f}, {fit.frequency_hz:.2f} | {lc} |"
        )
    print(
        f"\n{time.strftime('%Y-%m-%d %H:%M')} Python {platform.python_version()}, numpy "
        f"{np.__version__}, scipy {scipy.__version__}, {os.cpu_count()} CPUs, load "
        f"{load0:.2f} -> {os.getloadavg()[0]:.2f}"
    )


if __name__ == "__main__":
    main()
