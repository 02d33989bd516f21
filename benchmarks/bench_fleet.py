# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the fleet review: a serial loop of `replay` against `review` on a local Dask
cluster of 1 and 2 workers, on the same generated logs.

    .venv/bin/python benchmarks/bench_fleet.py [--logs N] [--minutes M] [--quick]
        [--workers 1 2] [--no-serial] [--src DIR] [--regenerate] [--json OUT.json]

The logs are bench_replay's `dense` case (`bench_replay.cycle_of`: back-to-back 12 s strokes,
the nut position published, 100 Hz, recorded by our `Recorder`), `--logs` of them (default 100,
`--quick`: 10) of `--minutes` each (default 2), each with its own noise seed; generated once
and cached in the temp directory. Every run writes what `replay` writes (annotated MCAP,
episodes.json, summary.json/.txt; no PNG report on either side) with the default parameters and
the logs' screw joint as `joint_name`. `--src DIR` runs the review's Dask workers with the
package of another checkout (PYTHONPATH of the worker processes; the serial loop needs
`--no-serial` then), for a before / after comparison on the same logs.

- serial: `replay.replay` of one log after the other in this process (no prediction
  workers, BLAS limited to one thread as Dask's worker processes are: one core, the same
  work as one Dask task);
- review, N workers: `fleet.review_logs` on a new `LocalCluster` (N worker processes, one
  thread each, 127.0.0.1); the cluster's start is timed apart from the review.

Printed: logs per minute, the ratio to the serial loop, the scheduling overhead per log
(with 1 worker: (wall time - the replays' own time inside the tasks) / logs: task submission
and transfer, the content hash, the metadata read, the resume index; the replay in a task
against the serial loop is given apart) and an ESTIMATE for a cluster of 10 machines like this one
(10 x the rate with all of this machine's cores, less nothing for the scheduler: its cost per
task is the overhead measured here, paid in parallel); a Markdown table and an environment line
with the machine's load average at start and end.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from bench_replay import cycle_of  # the dense log of the replay benchmark
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.review.fleet import FleetSettings, cluster, review_logs
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings

MACHINES = 10  # of the cluster estimate


def cached_logs(count: int, minutes: float, rate_hz: float, regenerate: bool) -> list[Path]:
    """`count` dense logs (seeds 0..count-1), generated if not cached."""
    base = cycle_of("dense", argparse.Namespace(minutes=[minutes], rate=rate_hz))
    root = (
        Path(tempfile.gettempdir())
        / "leadscrew_ros_bench_fleet"
        / f"{minutes:g}min_{rate_hz:g}Hz_spread{base.stroke_spread:g}"
    )
    if regenerate:
        shutil.rmtree(root, ignore_errors=True)
    logs = []
    for seed in range(count):
        folder = root / f"log{seed:04d}"
        bags = sorted(folder.glob("squeak_*")) if folder.is_dir() else []
        if not bags:
            shutil.rmtree(folder, ignore_errors=True)
            bags = [write_log(dataclasses.replace(base, seed=seed), folder)]
        logs.append(bags[0])
    return logs


def serial(logs: list[Path], joint: str) -> float:
    """Wall time of replaying `logs` one after the other in this process."""
    model, settings = (
        SqueakModel(),
        ReplaySettings(InputSettings(joint_name=joint), workers=0, progress=False),
    )
    with tempfile.TemporaryDirectory(prefix="bench_fleet_serial_") as out, threadpool_limits(1):
        t0 = time.perf_counter()
        for k, log in enumerate(logs):
            replay(log, model, Path(out) / str(k), settings)
        return time.perf_counter() - t0


def _cpu_s() -> float:
    """User + system CPU seconds of this process (run in each Dask worker)."""
    import resource

    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def review(logs: list[Path], joint: str, workers: int) -> dict:
    """Wall times of starting a LocalCluster of `workers` and of the review on it, and the
    CPU time its worker processes spent (user + system: less sensitive to other load on the
    machine than the wall time)."""
    settings = FleetSettings(inputs=InputSettings(joint_name=joint), report=False)
    with tempfile.TemporaryDirectory(prefix="bench_fleet_review_") as out:
        t0 = time.perf_counter()
        with cluster(workers) as client:
            start = time.perf_counter() - t0
            packages = set(client.run(lambda: __import__("leadscrew_ros").__file__).values())
            print(f"workers' package: {', '.join(sorted(packages))}", file=sys.stderr)
            cpu0 = sum(client.run(_cpu_s).values())
            run = review_logs(logs, out, settings, client, progress=False)
            cpu = sum(client.run(_cpu_s).values()) - cpu0
    if run.failed:
        raise SystemExit(f"{run.failed} logs failed: {run.rows[0]['error']}")
    return {
        "start_s": start,
        "wall_s": run.wall_s,
        "task_s": sum(r["wall_s"] for r in run.rows),
        "cpu_s": cpu,
    }


def table(res: dict) -> str:
    n, serial_s = res["logs"], res["serial_s"]
    rate = {} if serial_s is None else {"serial": 60.0 * n / serial_s}
    lines = [
        "| run | wall | logs per minute | vs serial | cluster start | workers' CPU per log |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    if serial_s is not None:
        lines.append(
            f"| serial loop of `replay` (one process) | {serial_s:.1f} s | "
            f"{rate['serial']:.1f} | 1.00× | – | – |"
        )
    package = f" (package of {res['src']})" if res.get("src") else ""
    for w, r in res["review"].items():
        rate[w] = 60.0 * n / r["wall_s"]
        versus = "–" if serial_s is None else f"{serial_s / r['wall_s']:.2f}×"
        lines.append(
            f"| `review`, LocalCluster {w} worker(s){package} | {r['wall_s']:.1f} s | "
            f"{rate[w]:.1f} | {versus} | {r['start_s']:.1f} s | {r['cpu_s'] / n:.2f} s |"
        )
    one = res["review"].get("1")
    if one:
        lines.append(
            f"\nScheduling overhead per log (1 worker: (wall − the replays' own time "
            f"in the tasks) / {n} logs): {1e3 * (one['wall_s'] - one['task_s']) / n:.0f}"
            f" ms."
        )
    lines += [
        f"A replay in a task of {w} worker(s) took {r['task_s'] / serial_s:.2f}× its time "
        f"in the serial loop."
        for w, r in res["review"].items()
        if serial_s is not None
    ]
    best = max((w for w in res["review"]), key=lambda w: rate[w])
    per_core = rate[best] / int(best)
    cores = res["env"]["cpu_count"]
    lines.append(
        f"ESTIMATE (not measured) for {MACHINES} machines like this one "
        f"({cores} cores each, one worker per core): ≈ "
        f"{MACHINES * cores * per_core:.0f} logs per minute "
        f"({MACHINES} × {cores} × {per_core:.1f} logs/min per worker as measured "
        f"with {best}), if the logs are on storage that serves them as fast."
    )
    env = res["env"]
    lines.append(
        f"\n{env['date']} · Python {env['python']} · numpy {env['numpy']} · "
        f"{cores} CPUs ({env['machine']}) · load avg {env['load_start']:.2f} → "
        f"{env['load_end']:.2f} · {n} dense logs of {res['minutes']:g} min at "
        f"{res['rate_hz']:g} Hz ({res['messages']:,} messages each)"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", type=int, default=100)
    ap.add_argument("--minutes", type=float, default=2.0)
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate [Hz]")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--quick", action="store_true", help="10 logs")
    ap.add_argument("--no-serial", action="store_true", help="only the review on the cluster")
    ap.add_argument(
        "--src", metavar="DIR", help="the review's workers with the package of this checkout"
    )
    ap.add_argument("--regenerate", action="store_true")
    ap.add_argument("--json", metavar="OUT.json")
    args = ap.parse_args(argv)
    n = 10 if args.quick else args.logs
    env = dict(
        date=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        python=platform.python_version(),
        numpy=np.__version__,
        cpu_count=os.cpu_count(),
        machine=platform.machine(),
        load_start=os.getloadavg()[0],
    )
    t0 = time.perf_counter()
    logs = cached_logs(n, args.minutes, args.rate, args.regenerate)
    print(f"{n} logs ready in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    joint = DutyCycle().joint_name
    res = {
        "env": env,
        "logs": n,
        "minutes": args.minutes,
        "rate_hz": args.rate,
        "messages": 4 * int(round(args.minutes * 60 * args.rate)),
        "serial_s": None if args.no_serial else serial(logs, joint),
        "review": {},
        "src": args.src,
    }
    if res["serial_s"] is not None:
        print(f"serial: {res['serial_s']:.1f} s", file=sys.stderr)
    if args.src:  # the Dask workers are spawned with this process's sys.path: there first
        sys.path.insert(0, str(Path(args.src).resolve()))
    for w in args.workers:
        res["review"][str(w)] = review(logs, joint, w)
        print(f"review, {w} worker(s): {res['review'][str(w)]['wall_s']:.1f} s", file=sys.stderr)
    res["env"]["load_end"] = os.getloadavg()[0]
    print(table(res))
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
