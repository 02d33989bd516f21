# SPDX-License-Identifier: Apache-2.0
"""Benchmark of `calibrate`: a virtual-bench fleet of 12-s strokes calibrated on a local Dask
cluster, timed by phase.

    .venv/bin/python benchmarks/bench_calibrate.py [--units 20] [--duration 12] [--workers 2]
        [--formulation paper|consistent|both] [--clean] [--json OUT.json]

The bench (`bag.virtual_bench.run`, seed 0, drawn from the worked example's population:
tools/calibration_example.py; the realistic bench, whose squeak grows from its floor, unless
--clean) is made first and not timed. Then, as `leadscrew-squeak
calibrate` runs it: a new LocalCluster (`fleet.cluster`, its start timed apart), the gather
(`gather.gather`: each log replayed with its sound and read, one task per log) and the
calibration (`run.calibrate`: the units' tasks, the population fits, the held-out check).
Printed: a Markdown table of the wall time of each phase and in all against the issue's target
(20 units of 12-s strokes in 2 minutes on 2 cores), the time per unit (the units' own
`UnitPosterior.seconds`, inside their tasks) and per likelihood evaluation (a parameter draw:
the units' seconds over their evaluations), the population fit's time, the units that
converged; an environment line with the machine's load average at start and end. One run;
ratios and times of that run, nothing asserted.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from leadscrew_ros.bag.virtual_bench import BenchSettings, run
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.review.calibration import CalibrationSettings, GatherSettings, calibrate
from leadscrew_ros.review.calibration.gather import find_inputs, gather
from leadscrew_ros.review.fleet import cluster

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from calibration_example import POPULATION  # noqa: E402

TARGET_S = 120.0  # issue 22: 20 units of 12-s strokes, 2 cores


def measure(args: argparse.Namespace, root: Path) -> dict:
    """One run of the phases (module docstring)."""
    bench = BenchSettings(
        units=args.units,
        duration_s=args.duration,
        formulation="paper" if args.formulation == "both" else args.formulation,
        seed=0,
        population=POPULATION,
        realistic=not args.clean,
    )
    run(bench, root / "bench")
    prior = SqueakModel(ScrewParameters())
    settings = CalibrationSettings(formulation=args.formulation)
    out = root / "out"
    t0 = time.perf_counter()
    with cluster(args.workers) as client:
        t1 = time.perf_counter()
        gathered = gather(find_inputs([str(root / "bench")]), out, GatherSettings(), client)
        t2 = time.perf_counter()
        result = calibrate(gathered, prior, settings, client)
        t3 = time.perf_counter()
    units = [u for r in result.runs.values() for u in r.units if u.posterior is not None]
    seconds = sum(u.posterior.seconds for u in units if u.posterior is not None)
    evaluations = sum(u.posterior.evaluations for u in units if u.posterior is not None)
    populations = [r.population for r in result.runs.values() if r.population is not None]
    return {
        "units": args.units,
        "formulations": len(result.runs),
        "cluster_start_s": t1 - t0,
        "gather_s": t2 - t1,
        "calibrate_s": t3 - t2,
        "total_s": t3 - t1,
        "unit_s": seconds / max(len(units), 1),
        "evaluation_us": 1e6 * seconds / max(evaluations, 1),
        "evaluations_per_unit": evaluations / max(len(units), 1),
        "population_s": sum(p.seconds for p in populations) / max(len(populations), 1),
        "converged": sum(u.calibrated for u in units),
        "calibrated_units": len(units),
        "held_out_brier": {
            k: [r.held_out.brier_prior, r.held_out.brier_calibrated] for k, r in result.runs.items()
        },
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--units", type=int, default=20)
    p.add_argument("--duration", type=float, default=12.0, help="stroke duration [s]")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--formulation", default="paper", choices=("paper", "consistent", "both"))
    p.add_argument("--clean", action="store_true", help="the clean bench (a tone at once)")
    p.add_argument("--json", metavar="OUT.json")
    args = p.parse_args(argv)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench_calibrate_") as tmp:
        r = measure(args, Path(tmp))
    met = "met" if r["total_s"] <= TARGET_S else "MISSED"
    per_log = r["gather_s"] / r["units"]
    rows = [
        (
            "cluster",
            f"LocalCluster of {args.workers} workers started",
            f"{r['cluster_start_s']:.1f} s",
        ),
        (
            "gather",
            f"{r['units']} logs replayed with sound and read",
            f"{r['gather_s']:.1f} s ({per_log:.2f} s per log)",
        ),
        (
            "calibrate",
            f"{r['units']} units x {r['formulations']} formulation(s), population, held-out check",
            f"{r['calibrate_s']:.1f} s",
        ),
        (
            "total",
            f"gather + calibrate (target <= {TARGET_S:.0f} s on 2 cores)",
            f"{r['total_s']:.1f} s, {met}",
        ),
        (
            "per unit",
            "a unit's calibration inside its task",
            f"{r['unit_s']:.2f} s ({r['evaluations_per_unit']:.0f} likelihood evaluations)",
        ),
        ("per evaluation", "one parameter draw of the likelihood", f"{r['evaluation_us']:.1f} µs"),
        ("population", "the hierarchical fit, per formulation", f"{r['population_s']:.1f} s"),
        (
            "converged",
            "units calibrated and converged",
            f"{r['converged']} of {r['calibrated_units']}",
        ),
    ]
    print("| phase | measurement | result |")
    print("|---|---|---:|")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    for k, scores in r["held_out_brier"].items():
        shown = ", ".join("n/a" if b is None else f"{b:.4f}" for b in scores)
        print(f"| held out ({k}) | Brier score prior, calibrated | {shown} |")
    print(
        f"\n{datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')} · Python "
        f"{platform.python_version()} · {os.cpu_count()} CPUs · load avg {load0:.2f} → "
        f"{os.getloadavg()[0]:.2f} · {args.units} units x {args.duration:g} s, "
        f"{args.formulation}"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
