# SPDX-License-Identifier: Apache-2.0
"""Benchmark of safe-speed advice: the band search offline, and the node's responsiveness.

    .venv/bin/python benchmarks/bench_advice.py [--quick] [--no-node] [--json OUT.json]

Prints Markdown tables (no asserts):
(1) offline, the full search of every band of P(squeak) >= safe_probability (`speed_bands`,
what the node ran inside its executor before) against `band_around` (only the band the speed
sits in, as the node now runs it on a background thread), at 6/6, 20/20 and 40/40 modes, inside
the Table-1 band (20 rad/s) and near its upper edge (50 rad/s), default scatter: wall time
(calls alternate within each round, ratio = median of per-round ratios) and eigen-solves (one
LAPACK dgeev per prediction);
(2) the node, in-process with 20/20 and 40/40 modes, speed and load at 50 Hz through the
squeak band and several load bins (test/test_node_stall.py's `stall_run`, the same scenario as
the test): `get_parameters` latency (max, p99, median), recomputes, the longest prediction and
the longest gap between squeak/risk (P(squeak)) messages, on the machine as it is and with a CPU hog
(`python -c 'while 1: pass'`) on the other core. Run it with an older checkout on PYTHONPATH to
measure that code's node (the offline table needs the current one). BLAS is single-threaded,
as in the node's process. See benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

ROOT = Path(__file__).resolve().parent.parent
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(101 + os.getpid() % 100))
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="bench_advice_log_"))
sys.path[:0] = [str(ROOT / "test"), str(ROOT / "benchmarks")]

from scipy.linalg import lapack  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from bench_model import interleaved, paired_ratio  # noqa: E402
from leadscrew_ros.live.settings import LiveSettings  # noqa: E402
from leadscrew_ros.model import SqueakModel  # noqa: E402
from leadscrew_ros.model.studies.advice import speed_bands  # noqa: E402

LOAD_N = 200.0
SAFE = LiveSettings().safe_probability  # the node's default: bands of P(squeak) >= 0.01
SPEEDS = (20.0, 50.0)  # rad/s: inside the Table-1 band (0.81..55.2), near its top
MODES = (6, 20, 40)
CONFIGS = {
    "default": dict(rounds={6: 20, 20: 5, 40: 3}, node_s=10.0),
    "quick": dict(rounds={6: 5, 20: 2, 40: 1}, node_s=5.0),
}


def count_solves(fn) -> int:
    """Eigen-solves (LAPACK dgeev, one per prediction) that `fn()` runs."""
    dgeev, count = lapack.dgeev, [0]

    def counted(*args, **kwargs):
        count[0] += 1
        return dgeev(*args, **kwargs)

    lapack.dgeev = counted
    try:
        fn()
    finally:
        lapack.dgeev = dgeev
    return count[0]


def offline(rounds: dict[int, int]) -> list[dict]:
    from leadscrew_ros.model.studies.advice import band_around

    rows = []
    for n in MODES:
        model = SqueakModel(SqueakModel().params.with_(n_bending=n, n_torsion=n))
        for speed in SPEEDS:
            fns = {
                "full": lambda model=model, speed=speed: speed_bands(
                    model, LOAD_N, speed, safe_probability=SAFE
                ),
                "band": lambda model=model, speed=speed: band_around(
                    model, LOAD_N, speed, safe_probability=SAFE
                ),
            }
            wall, _ = interleaved(fns, rounds[n])
            rows.append(
                {
                    "modes": n,
                    "speed_rad_s": speed,
                    "full_s": median(wall["full"]),
                    "band_s": median(wall["band"]),
                    "ratio": paired_ratio(wall["full"], wall["band"]),
                    "full_solves": count_solves(fns["full"]),
                    "band_solves": count_solves(fns["band"]),
                }
            )
    return rows


def node(duration_s: float) -> list[dict]:
    from test_node_stall import stall_run

    rows = []
    for hog in (False, True):
        proc = subprocess.Popen([sys.executable, "-c", "while 1: pass"]) if hog else None
        try:
            for n in (20, 40):
                s = stall_run(n, duration_s)
                lat = sorted(s.latencies_s)
                rows.append(
                    {
                        "modes": n,
                        "hog": hog,
                        "calls": len(lat),
                        "max_s": lat[-1],
                        "p99_s": lat[int(0.99 * (len(lat) - 1))],
                        "median_s": lat[len(lat) // 2],
                        "recomputes": s.recomputes,
                        "risks": len(s.risk_times),
                        "longest_prediction_s": max(s.predictions_s),
                        "longest_risk_gap_s": s.max_risk_gap_s,
                    }
                )
        finally:
            if proc is not None:
                proc.kill()
                proc.wait()
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-node", action="store_true", help="offline band search only")
    ap.add_argument("--no-offline", action="store_true", help="node latency only")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    cfg = CONFIGS["quick" if args.quick else "default"]
    threadpool_limits(limits=1, user_api="blas")
    import leadscrew_ros

    print(
        f"leadscrew_ros from {Path(leadscrew_ros.__file__).parent}; load average "
        f"{os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs; BLAS single-threaded\n"
    )
    out: dict = {}
    start = time.monotonic()
    if not args.no_offline:
        out["offline"] = offline(cfg["rounds"])
        print(
            "| modes | speed rad/s | full search s | band_around s | ratio | solves full"
            " | solves band |\n|---|---|---|---|---|---|---|"
        )
        for r in out["offline"]:
            print(
                f"| {r['modes']}/{r['modes']} | {r['speed_rad_s']:g} | {r['full_s']:.4f} | "
                f"{r['band_s']:.4f} | {r['ratio']:.1f}x | {r['full_solves']} | "
                f"{r['band_solves']} |"
            )
        print()
    if not args.no_node:
        out["node"] = node(cfg["node_s"])
        print(
            "| modes | CPU hog | get_parameters calls | max s | p99 s | median s | recomputes"
            " (risk msgs) | longest prediction s | longest risk gap s |\n"
            "|---|---|---|---|---|---|---|---|---|"
        )
        for r in out["node"]:
            print(
                f"| {r['modes']}/{r['modes']} | {'yes' if r['hog'] else 'no'} | "
                f"{r['calls']} | {r['max_s']:.3f} | {r['p99_s']:.3f} | "
                f"{r['median_s']:.4f} | {r['recomputes']} ({r['risks']}) | "
                f"{r['longest_prediction_s']:.3f} | {r['longest_risk_gap_s']:.3f} |"
            )
    print(
        f"\nwall {time.monotonic() - start:.0f} s; load average at the end {os.getloadavg()[0]:.2f}"
    )
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
