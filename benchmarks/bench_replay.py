# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the offline replay: throughput on a generated 1-hour, 100 Hz log, and peak
memory against log length.

    .venv/bin/python benchmarks/bench_replay.py [--hours H] [--workers N] [--report] [--json OUT.json]
    .venv/bin/python benchmarks/bench_replay.py --rss [--minutes 10 60] [--rate HZ] [--src DIR]

The log is a seat-adjuster duty cycle (`synthetic_log.DutyCycle`: a 12 s stroke every minute,
alternating direction, small sensor noise) on /motor_speed, /axial_load (std_msgs/Float64) and
/joint_states (sensor_msgs/JointState), recorded by our `Recorder` (zstd, 10-minute splits). It is
generated once and cached in the temp directory (`--regenerate` to rebuild). One run of
`replay.replay` (default parameters and deadbands, the log's screw joint as `joint_name`) is
timed; the ratio is log duration / wall
time. Prints a Markdown table and an environment line. Target: >= 100x real time.

`--rss`: for each log length (default 10 and 60 minutes), one replay with the report (QUICK
grids) in a fresh child process; its peak resident memory (VmHWM of /proc/self/status, the
replaying process; the prediction workers' peak from RUSAGE_CHILDREN) is printed. Streaming
means equal peaks (target: within 20 %). `--src DIR` runs the child with the package from
another checkout (e.g. `git worktree add /tmp/old f76cdbf`), on the same cached logs.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from leadscrew_ros.bag.messages import PREDICTION_TOPICS
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.review.timeline import InputSettings

TARGET_X_REAL_TIME = 100.0
TARGET_RSS_RATIO = 1.2
# Runs in the child: replay + report, then the peak memory of this process and its workers.
_CHILD = """
import json, resource, sys, time
from pathlib import Path
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.bag.synthetic import DutyCycle
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.report import QUICK, write_report
from leadscrew_ros.review.timeline import InputSettings
bag, out, workers = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
model, t0 = SqueakModel(), time.perf_counter()
result = replay(bag, model, out, ReplaySettings(InputSettings(joint_name=DutyCycle().joint_name),
                                                workers=workers, progress=False))
write_report(result, model, out, QUICK)
status = dict(line.split(":", 1) for line in open("/proc/self/status"))
print(json.dumps(dict(
    peak_mb=int(status["VmHWM"].split()[0]) / 1024, wall_s=time.perf_counter() - t0,
    workers_peak_mb=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
    messages=result.messages, predictions=result.predictions)))
"""


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
        (f"P(squeak) (default scatter, {r['scatter_samples']} samples)",
         f"peak {r['peak_probability']:.3f}",
         f"{r['time_above_warn_s']:.0f} s >= WARN {r['warn_probability']:g}, "
         f"{r['time_above_error_s']:.0f} s >= ERROR {r['error_probability']:g}"),
        ("wall time (replay: read, predict, write annotated MCAP + episodes)",
         f"{res['workers']} prediction worker(s)", f"{r['wall_s']:.1f} s"),
        ("throughput", "log duration / wall time",
         f"**{ratio:.0f}× real time** (target ≥ {TARGET_X_REAL_TIME:g}×: "
         f"{'met' if ratio >= TARGET_X_REAL_TIME else 'MISSED'})"),
        ("annotated MCAP", f"originals + {len(PREDICTION_TOPICS)} prediction topics",
         f"{res['annotated_mb']:.1f} MB"),
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


def peak_rss(bag: Path, workers: int, src: str | None) -> dict:
    """Replay + report of `bag` in a fresh child process: its peak memory and wall time."""
    env = dict(os.environ)        # the child runs in `out`: `-c` puts its cwd first on the path
    if src:
        env["PYTHONPATH"] = str(Path(src).resolve())
    with tempfile.TemporaryDirectory(prefix="bench_replay_rss_") as out:
        done = subprocess.run([sys.executable, "-c", _CHILD, str(bag), out, str(workers)],
                              env=env, cwd=out, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"replay of {bag} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.splitlines()[-1])


def rss_table(rows: list[dict], src: str | None) -> str:
    lines = ["| log | messages | file size | peak RSS (replaying process) | "
             "peak RSS (a worker) | wall (replay + report) |", "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['minutes']:g} min at {r['rate_hz']:g} Hz | {r['messages']:,} | "
                     f"{r['log_mb']:.0f} MB | {r['peak_mb']:.0f} MB | "
                     f"{r['workers_peak_mb']:.0f} MB | {r['wall_s']:.0f} s |")
    ratio = rows[-1]["peak_mb"] / rows[0]["peak_mb"]
    lines.append(f"\npeak ratio longest / shortest: **{ratio:.2f}** (target ≤ "
                 f"{TARGET_RSS_RATIO:g}: {'met' if ratio <= TARGET_RSS_RATIO else 'MISSED'}); "
                 f"package from {src or 'this checkout'}")
    return "\n".join(lines)


def rss_main(args: argparse.Namespace) -> int:
    rows = []
    for minutes in args.minutes:
        cycle = DutyCycle(duration_s=minutes * 60.0, rate_hz=args.rate)
        bag, _ = cached_log(cycle, args.regenerate)
        row = dict(minutes=minutes, rate_hz=args.rate, log_mb=size_mb(bag))
        row.update(peak_rss(bag, args.workers, args.src))
        rows.append(row)
        print(f"{minutes:g} min: {row['peak_mb']:.0f} MB", file=sys.stderr, flush=True)
    print(rss_table(rows, args.src))
    if args.json:
        Path(args.json).write_text(json.dumps(dict(env=environment(), rows=rows), indent=1))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0, help="log duration (default 1 h)")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate [Hz] (default 100)")
    ap.add_argument("--workers", type=int, default=ReplaySettings().workers,
                    help="prediction worker processes (default %(default)s; 0: one process)")
    ap.add_argument("--report", action="store_true", help="also time the PNG report")
    ap.add_argument("--regenerate", action="store_true", help="rebuild the cached log")
    ap.add_argument("--json", metavar="OUT.json", help="also write the raw numbers here")
    ap.add_argument("--rss", action="store_true",
                    help="peak memory of replay + report vs log length instead")
    ap.add_argument("--minutes", type=float, nargs="+", default=[10.0, 60.0],
                    help="log lengths of --rss (default 10 60)")
    ap.add_argument("--src", metavar="DIR", help="--rss: import leadscrew_ros from this checkout")
    args = ap.parse_args(argv)
    if args.rss:
        return rss_main(args)
    cycle = DutyCycle(duration_s=args.hours * 3600.0, rate_hz=args.rate)
    res = dict(env=environment(), hours=args.hours, rate_hz=args.rate, workers=args.workers)
    bag, res["generate_s"] = cached_log(cycle, args.regenerate)
    res["files"], res["log_mb"] = len(list(bag.glob("*.mcap"))), size_mb(bag)
    model = SqueakModel()
    with tempfile.TemporaryDirectory(prefix="bench_replay_") as out:
        result = replay(bag, model, out, ReplaySettings(
            InputSettings(joint_name=cycle.joint_name), workers=args.workers, progress=False))
        res["replay"] = result.summary()
        res["annotated_mb"] = size_mb(result.annotated)
        if args.report:
            from leadscrew_ros.review.report import write_report
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
