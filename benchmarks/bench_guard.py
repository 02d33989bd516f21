# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the guard's step (`live.guard.GuardPolicy.step`), in-process: the latency per
speed command a node would add (issue 33's target: p99 <= 1 ms).

    .venv/bin/python benchmarks/bench_guard.py [--steps N] [--json OUT.json]

The demo stroke (`StrokeProfile()`) at 100 Hz, repeated, through one policy whose bands were
computed beforehand for every bin the stroke visits (as a node's background thread does): the
step only reads the cache. Each step is timed with `time.perf_counter_ns`; prints a Markdown
table (median, p99, p99.9, max) and an environment line. No asserts: the machine is shared.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from leadscrew_ros.live.guard import GuardBands, GuardPolicy, GuardSettings
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.live.recompute import band_bin
from leadscrew_ros.model import SqueakModel

TARGET_P99_S = 1e-3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000, help="steps timed")
    parser.add_argument("--json", type=Path, help="also write the per-step times [ns]")
    args = parser.parse_args()
    start = time.perf_counter()
    load_start = os.getloadavg()[0]
    settings = GuardSettings()
    times, speed, load, nut = StrokeProfile().sampled(100.0)
    policy = GuardPolicy(settings)
    model = SqueakModel()
    for w, f, z in zip(speed.tolist(), load.tolist(), nut.tolist(), strict=True):
        key = band_bin(f, z, w)
        if w and key not in policy.bands:
            policy.bands[key] = GuardBands.compute(model, key, settings.p_max)
    n, period = len(times), float(times[-1] + times[1])
    points = list(zip(speed.tolist(), load.tolist(), nut.tolist(), strict=True))
    elapsed = np.empty(args.steps, dtype=np.int64)
    clock = time.perf_counter_ns
    active = 0
    for k in range(args.steps):
        w, f, z = points[k % n]
        t = (k // n) * period + times[k % n]
        t0 = clock()
        step = policy.step(t, w, f, z)
        elapsed[k] = clock() - t0
        active += step.active
    us = elapsed / 1e3
    print(
        "| steps | active (band avoided) | median [us] | p99 [us] | p99.9 [us] | max [us] "
        "| p99 target |"
    )
    print("|---|---|---|---|---|---|---|")
    p99 = float(np.percentile(us, 99))
    print(
        f"| {args.steps} | {active} | {np.median(us):.1f} | {p99:.1f} | "
        f"{np.percentile(us, 99.9):.1f} | {us.max():.0f} | <= {TARGET_P99_S * 1e6:.0f} us: "
        f"{'met' if p99 * 1e-6 <= TARGET_P99_S else 'MISSED'} |"
    )
    print(
        f"\n{time.strftime('%Y-%m-%d %H:%M')} Python {platform.python_version()}, numpy "
        f"{np.__version__}, {os.cpu_count()} CPUs, load {load_start:.2f} -> "
        f"{os.getloadavg()[0]:.2f}, wall {time.perf_counter() - start:.1f} s"
    )
    if args.json:
        args.json.write_text(json.dumps({"step_ns": elapsed.tolist()}))


if __name__ == "__main__":
    main()
