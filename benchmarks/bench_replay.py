# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the offline replay: throughput and CPU time on two generated 100 Hz logs, and
peak memory against log length.

    .venv/bin/python benchmarks/bench_replay.py [--cases duty dense] [--hours H] [--minutes M]
        [--workers N] [--rounds R] [--src DIR] [--report] [--json OUT.json]
    .venv/bin/python benchmarks/bench_replay.py --rss [--minutes 10 60] [--rate HZ] [--src DIR]
    .venv/bin/python benchmarks/bench_replay.py --profile [--cases dense]

Two logs (`synthetic.DutyCycle`, small sensor noise, recorded by our `Recorder`: zstd, 10-minute
splits, on /motor_speed, /axial_load (std_msgs/Float64) and /joint_states
(sensor_msgs/JointState)):
- `duty`: a seat-adjuster duty cycle of `--hours` (default 1 h): a 12 s stroke every minute,
  alternating direction;
- `dense`: `--minutes` (default 10) of back-to-back strokes with no rest between them, each
  with its own peak speed, load range and duration (12 s +- 25 %, `DutyCycle.stroke_spread`:
  no two alike, so no nut position or operating point comes back), and the nut position also
  published (/nut_position, every sample): the operating point and the nut move at almost
  every message.
`--profile`: only where a prediction worker's time goes on a log (the stages of `replay.solve`
timed inside it, in this process; with `--src DIR` in a child process with that checkout's
package). Each log is
generated once and cached in the temp directory (`--regenerate` to rebuild). One
`replay.replay` per case and round (default parameters and deadbands, the log's screw joint as
`joint_name`) runs in a fresh child process; the ratio is log duration / wall time, and the CPU
time (the replaying process and its prediction workers, user + system) is given per log hour.
`--src DIR` also runs every case with the package of another checkout (e.g. `git archive` of the
old commit), interleaved with this one round by round, on the same cached logs. Prints a
Markdown table and an environment line (machine load at start and end), then the floor lines:
the eigen-solves the predictions need alone, as x real time on two cores. Targets (issue 23):
>= 150x real time for the duty log, >= 60x for the dense log.

`--rss`: for each log length (default 10 and 60 minutes of the duty cycle), one replay with the
report (QUICK grids) in a fresh child process; its peak resident memory (VmHWM of
/proc/self/status, the replaying process; the prediction workers' peak from RUSAGE_CHILDREN) is
printed. Streaming means equal peaks (target: within 20 %). `--src DIR` runs the child with the
package from another checkout (e.g. `git worktree add /tmp/old f76cdbf`), on the same cached
logs.
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

from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.review.replay import ReplaySettings

TARGET_X_REAL_TIME = {"duty": 150.0, "dense": 60.0}  # issue 23
STROKE_SPREAD = 0.25  # of the dense log's strokes
TARGET_RSS_RATIO = 1.2
# Runs in the child: one replay (+ the report if asked); wall and CPU time of the replay.
_THROUGHPUT_CHILD = """
import json, resource, sys, time
from pathlib import Path
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings
bag, out, workers, joint, report = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3]), \\
    sys.argv[4], sys.argv[5] == "1"
def cpu(who):
    u = resource.getrusage(who)
    return u.ru_utime + u.ru_stime
model = SqueakModel()
c0, w0, t0 = cpu(resource.RUSAGE_SELF), cpu(resource.RUSAGE_CHILDREN), time.perf_counter()
result = replay(bag, model, out, ReplaySettings(InputSettings(joint_name=joint),
                                                workers=workers, progress=False))
wall = time.perf_counter() - t0
main, workers = cpu(resource.RUSAGE_SELF) - c0, cpu(resource.RUSAGE_CHILDREN) - w0
res = dict(summary=result.summary(), wall_s=wall, cpu_s=main + workers, cpu_main_s=main,
           annotated_mb=result.annotated.stat().st_size / 1e6)
if report:
    from leadscrew_ros.review.report import write_report
    t0 = time.perf_counter()
    write_report(result, model, out)
    res["report_s"] = time.perf_counter() - t0
print(json.dumps(res))
"""
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
    return dict(
        date=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        python=platform.python_version(),
        numpy=np.__version__,
        cpu_count=os.cpu_count(),
        machine=platform.machine(),
        load_avg_1min_start=os.getloadavg()[0],
    )


CASES = {
    "duty": "duty cycle (12 s stroke every minute)",
    "dense": "back-to-back strokes of varying speed, load and travel, nut position published",
}


def cycle_of(case: str, args: argparse.Namespace) -> DutyCycle:
    """The generated log of `case`."""
    if case == "duty":
        return DutyCycle(duration_s=args.hours * 3600.0, rate_hz=args.rate)
    return DutyCycle(
        duration_s=args.minutes[0] * 60.0,
        rate_hz=args.rate,
        rest_s=0.0,
        nut_position_topic=True,
        stroke_spread=STROKE_SPREAD,
    )


def run_replay(bag: Path, cycle: DutyCycle, workers: int, src: str | None, report: bool) -> dict:
    """One replay of `bag` in a fresh child process (the package of `src` if given)."""
    env = dict(os.environ)  # the child runs in `out`: `-c` puts its cwd first on the path
    if src:
        env["PYTHONPATH"] = str(Path(src).resolve())
    with tempfile.TemporaryDirectory(prefix="bench_replay_") as out:
        done = subprocess.run(
            [
                sys.executable,
                "-c",
                _THROUGHPUT_CHILD,
                str(bag),
                out,
                str(workers),
                cycle.joint_name,
                "1" if report else "0",
            ],
            env=env,
            cwd=out,
            capture_output=True,
            text=True,
        )
    if done.returncode:
        raise SystemExit(f"replay of {bag} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.splitlines()[-1])


def table(res: dict) -> str:
    """One row per case and package: medians over the rounds."""
    env, head = (
        res["env"],
        (
            "| log | package | messages | predictions | annotated MCAP | "
            "wall | x real time | CPU-s per log hour (replaying process "
            "+ workers) |\n|---|---|---:|---:|---:|---:|---:|---:|"
        ),
    )
    lines = [head]
    for case, c in res["cases"].items():
        for label, runs in c["runs"].items():
            r = runs[0]["summary"]
            wall = float(np.median([x["wall_s"] for x in runs]))
            cpu = float(np.median([x["cpu_s"] for x in runs]))
            main = float(np.median([x["cpu_main_s"] for x in runs]))
            per_hour = 3600.0 / r["duration_s"]
            ratio = r["duration_s"] / wall
            lines.append(
                f"| {CASES[case]}: {c['duration_s'] / 60:g} min at {res['rate_hz']:g} Hz, "
                f"{c['log_mb']:.1f} MB | {label} | {r['messages']:,} | {r['predictions']:,} "
                f"({r['recomputes'] / sum(r['input_messages'].values()):.0%} of inputs) | "
                f"{runs[0]['annotated_mb']:.1f} MB | {wall:.1f} s | **{ratio:.0f}×** "
                f"(≥ {TARGET_X_REAL_TIME[case]:g}× "
                f"{'met' if ratio >= TARGET_X_REAL_TIME[case] else 'MISSED'}) | "
                f"{cpu * per_hour:.0f} s ({main * per_hour:.0f} + "
                f"{(cpu - main) * per_hour:.0f}) |"
            )
    envline = (
        f"{env['date']} · Python {env['python']} · numpy {env['numpy']} · "
        f"{env['cpu_count']} CPUs ({env['machine']}) · load avg "
        f"{env['load_avg_1min_start']:.2f} → {env['load_avg_1min_end']:.2f} · "
        f"{res['workers']} prediction worker(s) · median of {res['rounds']} round(s), "
        "packages interleaved"
    )
    return f"{lines[0]}\n" + "\n".join(lines[1:]) + f"\n\n{envline}"


def solve_floor_us(rounds: int = 5, loops: int = 20) -> dict[str, float]:
    """Median time [us] of the LAPACK eigen-solves of a 36 x 36 state matrix on 16 points of
    the band: `dgeev` with right vectors (what the labels of every prediction need) and with
    left and right vectors (`stability.eig_both`, what every prediction used before issue 23):
    what a replay cannot go below without skipping predictions."""
    from scipy.linalg import lapack

    from leadscrew_ros.model import SqueakModel

    model = SqueakModel()
    mats = [
        model.state_matrix(s, f)
        for s, f in zip(np.linspace(5.0, 100.0, 16), np.linspace(50.0, 400.0, 16), strict=True)
    ]
    out = {}
    for name, left in (("right", 0), ("both", 1)):
        times = []
        for _ in range(rounds):
            t0 = time.perf_counter()
            for _ in range(loops):
                for a in mats:
                    lapack.dgeev(a, compute_vl=left, compute_vr=1)
            times.append((time.perf_counter() - t0) / (loops * len(mats)) * 1e6)
        out[name] = float(np.median(times))
    return out


def floor_lines(res: dict, solve_us: dict[str, float]) -> str:
    """Per log: x real time if both cores did nothing but the predictions' eigen-solves."""
    cores = min(os.cpu_count() or 1, 2)
    lines = [
        f"Floor (this run): one eigen-solve with right vectors (the labels) takes "
        f"{solve_us['right']:.0f} us here, with left and right vectors {solve_us['both']:.0f} us; "
        f"with {cores} cores doing nothing else a replay could reach at most"
    ]
    for case, c in res["cases"].items():
        r = next(iter(c["runs"].values()))[0]["summary"]
        right, both = (r["predictions"] * solve_us[k] * 1e-6 for k in ("right", "both"))
        lines.append(
            f"- {CASES[case]}: {r['predictions']:,} solves = {right:.1f} CPU-s (right vectors) "
            f"or {both:.1f} CPU-s (both) for {r['duration_s']:.0f} s of log: "
            f"**{r['duration_s'] / (right / cores):.0f}×** or "
            f"{r['duration_s'] / (both / cores):.0f}× real time"
        )
    return "\n".join(lines)


def profile_solve(bag: Path, joint: str, batches: int = 40) -> str:
    """Where a prediction worker's time goes on `bag`: its first `batches` segments of jobs
    (`replay._BATCH_JOBS` each, the timeline of the log as the replay makes it) solved in this
    process (BLAS on one thread), each stage timed inside (wrapped with a timer); the code of
    this checkout or of the one before issue 23 (the stages of either are looked up)."""
    from unittest import mock

    from threadpoolctl import threadpool_limits

    from leadscrew_ros.bag import messages
    from leadscrew_ros.bag.logsource import open_log, topic_types
    from leadscrew_ros.model import SqueakModel, squeak_model
    from leadscrew_ros.model.physics.assembly import Geometry
    from leadscrew_ros.model.uncertainty.perturbation import FirstOrderProbability
    from leadscrew_ros.review import replay as rp
    from leadscrew_ros.review.timeline import InputSettings, ModelSpec, Timeline

    stages = {
        "contact at the nut positions": [
            (squeak_model, "lower_half_units_at"),
            (SqueakModel, "with_params"),
        ],
        "state matrices": [(Geometry, "state_matrices")],
        "eigen-solves (LAPACK dgeev)": [
            (squeak_model, "eig_right_many"),
            (squeak_model, "eig_both"),
        ],
        "labels and modes": [(squeak_model, "classify_solves"), (squeak_model, "classify")],
        "P(squeak)": [
            (FirstOrderProbability, "estimates"),
            (FirstOrderProbability, "hits"),
            (squeak_model, "EigenPairs"),
        ],
        "CDR payloads": [(messages, "prediction_payloads")],
        "verdicts kept": [(rp.Verdict, "of")],
    }
    spent = dict.fromkeys(stages, 0.0)

    def timed(name, fn):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] += time.perf_counter() - t0

        return call

    model = SqueakModel()
    source = open_log(bag)
    timeline = Timeline(
        model.params, InputSettings(joint_name=joint).resolved("/"), topic_types(source)
    )
    jobs = []
    for i, (_, m) in enumerate(source.messages()):
        job = timeline.feed(m, i)
        if job is not None:
            jobs.append(job)
        if len(jobs) >= batches * rp._BATCH_JOBS:
            break
    spec = ModelSpec.of(model)
    args = [
        [
            np.array([getattr(j, f) for j in jobs[k : k + rp._BATCH_JOBS]])
            for f in ("speed_rad_s", "load_n", "model_nut_m")
        ]
        for k in range(0, len(jobs), rp._BATCH_JOBS)
    ]
    with threadpool_limits(1):
        rp.solve(spec, *args[0])  # the model built, caches warm
        patches = [
            mock.patch.object(owner, attr, timed(name, getattr(owner, attr)))
            for name, targets in stages.items()
            for owner, attr in targets
            if hasattr(owner, attr)
        ]
        for patch in patches:
            patch.start()
        try:
            t0 = time.perf_counter()
            for a in args:
                rp.solve(spec, *a)
            total = time.perf_counter() - t0
        finally:
            for patch in patches:
                patch.stop()
    n = len(jobs)
    rows = [f"| {k} | {t / n * 1e6:.0f} µs | {t / total:.0%} |" for k, t in spent.items()]
    rest = total - sum(spent.values())
    rows.append(
        f"| the rest (batching, validity, `Prediction`) | {rest / n * 1e6:.0f} µs | "
        f"{rest / total:.0%} |"
    )
    rows.append(
        f"| **a prediction of the worker (`replay.solve`)** | {total / n * 1e6:.0f} µs | 100% |"
    )
    return (
        f"Where a prediction worker's time goes ({n} jobs of {bag.name}, in segments of "
        f"{rp._BATCH_JOBS}; stages timed inside, one run, load avg {os.getloadavg()[0]:.2f}):"
        "\n\n| stage | per prediction | share |\n|---|---:|---:|\n" + "\n".join(rows)
    )


def peak_rss(bag: Path, workers: int, src: str | None) -> dict:
    """Replay + report of `bag` in a fresh child process: its peak memory and wall time."""
    env = dict(os.environ)  # the child runs in `out`: `-c` puts its cwd first on the path
    if src:
        env["PYTHONPATH"] = str(Path(src).resolve())
    with tempfile.TemporaryDirectory(prefix="bench_replay_rss_") as out:
        done = subprocess.run(
            [sys.executable, "-c", _CHILD, str(bag), out, str(workers)],
            env=env,
            cwd=out,
            capture_output=True,
            text=True,
        )
    if done.returncode:
        raise SystemExit(f"replay of {bag} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.splitlines()[-1])


def rss_table(rows: list[dict], src: str | None) -> str:
    lines = [
        "| log | messages | file size | peak RSS (replaying process) | "
        "peak RSS (a worker) | wall (replay + report) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['minutes']:g} min at {r['rate_hz']:g} Hz | {r['messages']:,} | "
            f"{r['log_mb']:.0f} MB | {r['peak_mb']:.0f} MB | "
            f"{r['workers_peak_mb']:.0f} MB | {r['wall_s']:.0f} s |"
        )
    ratio = rows[-1]["peak_mb"] / rows[0]["peak_mb"]
    lines.append(
        f"\npeak ratio longest / shortest: **{ratio:.2f}** (target ≤ "
        f"{TARGET_RSS_RATIO:g}: {'met' if ratio <= TARGET_RSS_RATIO else 'MISSED'}); "
        f"package from {src or 'this checkout'}"
    )
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
    ap.add_argument(
        "--cases",
        nargs="+",
        choices=list(CASES),
        default=list(CASES),
        help="logs to replay (default: both)",
    )
    ap.add_argument("--hours", type=float, default=1.0, help="duty log duration (default 1 h)")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate [Hz] (default 100)")
    ap.add_argument(
        "--workers",
        type=int,
        default=ReplaySettings().workers,
        help="prediction worker processes (default %(default)s; 0: one process)",
    )
    ap.add_argument("--rounds", type=int, default=1, help="replays per case and package")
    ap.add_argument("--report", action="store_true", help="also time the PNG report")
    ap.add_argument("--regenerate", action="store_true", help="rebuild the cached log")
    ap.add_argument("--json", metavar="OUT.json", help="also write the raw numbers here")
    ap.add_argument(
        "--rss", action="store_true", help="peak memory of replay + report vs log length instead"
    )
    ap.add_argument(
        "--minutes",
        type=float,
        nargs="+",
        default=None,
        help="dense log duration (default 10) / log lengths of --rss (10 60)",
    )
    ap.add_argument(
        "--src",
        metavar="DIR",
        help="also replay with the package of this checkout (--rss: instead)",
    )
    ap.add_argument(
        "--profile",
        action="store_true",
        help="only where a prediction worker's time goes, on the first case's log",
    )
    args = ap.parse_args(argv)
    if args.rss:
        args.minutes = args.minutes or [10.0, 60.0]
        return rss_main(args)
    args.minutes = args.minutes or [10.0]
    if args.profile:
        cycle = cycle_of(args.cases[-1], args)
        bag = cached_log(cycle, args.regenerate)[0]
        if not args.src:
            print(profile_solve(bag, cycle.joint_name))
            return 0
        child = (
            "import sys; from pathlib import Path; import bench_replay; "
            "print(bench_replay.profile_solve(Path(sys.argv[1]), sys.argv[2]))"
        )
        # `-c` puts its cwd first on the path: run in benchmarks/ (no package there)
        env = dict(os.environ, PYTHONPATH=str(Path(args.src).resolve()))
        done = subprocess.run(
            [sys.executable, "-c", child, str(bag), cycle.joint_name],
            env=env,
            cwd=Path(__file__).resolve().parent,
            text=True,
        )
        return done.returncode
    packages = {"this checkout": None, **({args.src: args.src} if args.src else {})}
    res = dict(
        env=environment(), rate_hz=args.rate, workers=args.workers, rounds=args.rounds, cases={}
    )
    for case in args.cases:
        cycle = cycle_of(case, args)
        bag, generate_s = cached_log(cycle, args.regenerate)
        res["cases"][case] = dict(
            duration_s=cycle.duration_s,
            generate_s=generate_s,
            log_mb=size_mb(bag),
            runs={label: [] for label in packages},
        )
    for _ in range(args.rounds):
        for case in args.cases:
            cycle = cycle_of(case, args)
            bag, _ = cached_log(cycle, False)
            for label, src in packages.items():
                run = run_replay(bag, cycle, args.workers, src, args.report)
                res["cases"][case]["runs"][label].append(run)
                print(f"{case} ({label}): {run['wall_s']:.1f} s", file=sys.stderr, flush=True)
    solve_us = solve_floor_us()
    res["env"]["load_avg_1min_end"] = os.getloadavg()[0]
    res["solve_floor_us"] = solve_us
    print(table(res))
    print()
    print(floor_lines(res, solve_us))
    if args.report:
        for case, c in res["cases"].items():
            for label, runs in c["runs"].items():
                print(f"report of {case} ({label}): {runs[0]['report_s']:.1f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
