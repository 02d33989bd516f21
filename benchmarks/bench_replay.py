"""Benchmark of the offline replay: throughput on a generated 1-hour, 100 Hz log.

    .venv/bin/python benchmarks/bench_replay.py [--hours H] [--workers N] [--report] [--json OUT.json]

The log is a seat-adjuster duty cycle (`synthetic_log.DutyCycle`: a 12 s stroke every minute,
alternating direction, small sensor noise) on /motor_speed, /axial_load (std_msgs/Float64) and
/joint_states (sensor_msgs/JointState), recorded by our `Recorder` (zstd, 10-minute splits). It is
generated once and cached in the temp directory (`--regenerate` to rebuild). One run of
`replay.replay` (default parameters and deadbands) is timed; the ratio is log duration / wall
time. Prints a Markdown table and an environment line. Target: >= 100x real time.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from leadscrew_ros.model import SqueakModel
from leadscrew_ros.replay import ReplaySettings, replay
from leadscrew_ros.synthetic_log import DutyCycle, write_log

TARGET_X_REAL_TIME = 100.0


def cached_log(cycle: DutyCycle, regenerate: bool) -> tuple[Path, float]:
    """The bag directory of `cycle` (generated if not cached) and the generation time (0 if
    cached)."""
    key = hashlib.sha256(repr(cycle).encode()).hexdigest()[:12]
    root = Path(tempfile.gettempdir()) / "leadscrew_ros_bench_replay" / key
    bags = sorted(root.glob("squeak_*")) if root.is_dir() else []
    if bags and not regenerate:
        return bags[0], 0.0
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    t0 = time.perf_counter()
    bag = write_log(cycle, root)
    return bag, time.perf_counter() - t0


def size_mb(path: Path) -> float:
    files = [path] if path.is_file() else list(path.glob("*.mcap"))
    return sum(f.stat().st_size for f in files) / 1e6


def environment() -> dict:
    return dict(date=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                python=platform.python_version(), numpy=np.__version__,
                cpu_count=os.cpu_count(), machine=platform.machine(),
                load_avg_1min_start=os.getloadavg()[0])


def table(res: dict) -> str:
    r, env = res["replay"], res["env"]
    ratio = r["x_real_time"]
    rows = [
        ("log", f"{res['hours']:g} h at {res['rate_hz']:g} Hz, {res['files']} files "
                f"(zstd), {res['log_mb']:.1f} MB", f"{r['messages']:,} messages"),
        ("inputs", ", ".join(f"{k} {v:,}" for k, v in r["input_messages"].items()),
         f"{sum(r['input_messages'].values()):,}"),
        ("recomputes (deadbands 0.1 rad/s, 1 N, 0.5 mm)",
         f"{r['predictions']:,} predictions + {sum(r['no_prediction'].values()):,} outside "
         "validity", f"{r['recomputes']:,} = {r['recomputes'] / sum(r['input_messages'].values()):.1%} "
                     "of inputs"),
        ("squeak", f"{r['episodes']} episodes", f"{r['time_in_squeak_s']:.0f} s in squeak"),
        ("wall time (replay: read, predict, write annotated MCAP + episodes)",
         f"{res['workers']} prediction worker(s)", f"{r['wall_s']:.1f} s"),
        ("throughput", "log duration / wall time",
         f"**{ratio:.0f}× real time** (target ≥ {TARGET_X_REAL_TIME:g}×: "
         f"{'met' if ratio >= TARGET_X_REAL_TIME else 'MISSED'})"),
        ("annotated MCAP", "originals + 4 prediction topics", f"{res['annotated_mb']:.1f} MB"),
    ]
    if "report_s" in res:
        rows.append(("report (PNG plots, not in the ratio)", "", f"{res['report_s']:.1f} s"))
    head = "| | | |\n|---|---|---:|"
    body = "\n".join("| " + " | ".join(row) + " |" for row in rows)
    envline = (f"{env['date']} · Python {env['python']} · numpy {env['numpy']} · "
               f"{env['cpu_count']} CPUs ({env['machine']}) · load avg "
               f"{env['load_avg_1min_start']:.2f} → {env['load_avg_1min_end']:.2f} · log "
               + ("cached" if not res["generate_s"] else f"generated in {res['generate_s']:.0f} s"))
    return f"{head}\n{body}\n\n{envline}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0, help="log duration (default 1 h)")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate [Hz] (default 100)")
    ap.add_argument("--workers", type=int, default=ReplaySettings().workers,
                    help="prediction worker processes (default %(default)s; 0: one process)")
    ap.add_argument("--report", action="store_true", help="also time the PNG report")
    ap.add_argument("--regenerate", action="store_true", help="rebuild the cached log")
    ap.add_argument("--json", metavar="OUT.json", help="also write the raw numbers here")
    args = ap.parse_args(argv)
    cycle = DutyCycle(duration_s=args.hours * 3600.0, rate_hz=args.rate)
    res = dict(env=environment(), hours=args.hours, rate_hz=args.rate, workers=args.workers)
    bag, res["generate_s"] = cached_log(cycle, args.regenerate)
    res["files"], res["log_mb"] = len(list(bag.glob("*.mcap"))), size_mb(bag)
    model = SqueakModel()
    with tempfile.TemporaryDirectory(prefix="bench_replay_") as out:
        result = replay(bag, model, out, ReplaySettings(workers=args.workers, progress=False))
        res["replay"] = result.summary()
        res["annotated_mb"] = size_mb(result.annotated)
        if args.report:
            from leadscrew_ros.report import write_report
            t0 = time.perf_counter()
            write_report(result, model, Path(out))
            res["report_s"] = time.perf_counter() - t0
    res["env"]["load_avg_1min_end"] = os.getloadavg()[0]
    print(table(res))
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
