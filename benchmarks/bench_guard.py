# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the guard's step (`live.guard.GuardPolicy.step`), in-process: the latency per
speed command a node would add (issue 33's target: p99 <= 1 ms).

    .venv/bin/python benchmarks/bench_guard.py [--steps N] [--json OUT.json]
    .venv/bin/python benchmarks/bench_guard.py --node 2000    # the node in the loop, ~30 s

With `--node N`: the `squeak_guard` node (`ros.guard_node.SqueakGuardNode`) and a probe node on
one executor (the node's own, `node.make_executor`) with an own Context, DDS on loopback and a
private ROS_DOMAIN_ID: the probe publishes the demo stroke's load and nut position, then its
speed command, and times each from just before `publish` to the receipt of
`speed_command_guarded` (N samples, after one stroke of warm-up in which the node's band
thread computes the stroke's bins).

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


def node_latency(samples: int) -> tuple[np.ndarray, int]:
    """Command-to-guarded-command times [s] through the node in-process, and how many of
    the guarded commands differed from the command (band avoided)."""
    from rclpy.node import Node
    from std_msgs.msg import Float64

    from leadscrew_ros.ros.env import close, confine_to_localhost, init_context
    from leadscrew_ros.ros.guard_node import COMMAND, GUARDED, SqueakGuardNode
    from leadscrew_ros.ros.node import make_executor

    confine_to_localhost(private_domain=True)
    ctx = init_context()
    ex, nodes = None, []
    try:
        guard = SqueakGuardNode(context=ctx)
        probe = Node("guard_probe", context=ctx)
        pubs = {
            t: probe.create_publisher(Float64, t, 10)
            for t in (COMMAND, "axial_load", "nut_position")
        }
        got: list[tuple[float, float]] = []
        probe.create_subscription(
            Float64, GUARDED, lambda m: got.append((time.perf_counter(), m.data)), 10
        )
        ex = make_executor(ctx)
        nodes = [probe, guard]
        ex.add_node(guard)
        ex.add_node(probe)
        deadline = time.perf_counter() + 10.0
        while any(p.get_subscription_count() == 0 for p in pubs.values()):
            if time.perf_counter() > deadline:
                raise SystemExit("the guard did not subscribe within 10 s")
            ex.spin_once(timeout_sec=0.01)
        _, speed, load, nut = StrokeProfile().sampled(100.0)
        points = list(zip(speed.tolist(), load.tolist(), nut.tolist(), strict=True))

        def one(w: float, f: float, z: float) -> tuple[float, float] | None:
            n = len(got)
            pubs["axial_load"].publish(Float64(data=f))
            pubs["nut_position"].publish(Float64(data=z))
            t0 = time.perf_counter()
            pubs[COMMAND].publish(Float64(data=w))
            end = t0 + 1.0
            while len(got) == n and time.perf_counter() < end:
                ex.spin_once(timeout_sec=0.001)
            return (got[-1][0] - t0, got[-1][1]) if len(got) > n else None

        for w, f, z in points:  # warm-up: the band thread learns the stroke's bins
            one(w, f, z)
        deadline = time.perf_counter() + 120.0
        while guard.policy is not None and guard.policy.wanted and time.perf_counter() < deadline:
            ex.spin_once(timeout_sec=0.05)
        out, changed = [], 0
        for k in range(samples):
            w, f, z = points[k % len(points)]
            r = one(w, f, z)
            if r is not None:
                out.append(r[0])
                changed += abs(r[1] - w) > 1e-9 * max(abs(w), 1.0)
    finally:
        close(ctx, ex, nodes)
    return np.asarray(out), changed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000, help="steps timed")
    parser.add_argument("--json", type=Path, help="also write the per-step times [ns]")
    parser.add_argument("--node", type=int, default=0, help="samples through the node (0: off)")
    args = parser.parse_args()
    start = time.perf_counter()
    load_start = os.getloadavg()[0]
    if args.node:
        lat, changed = node_latency(args.node)
        us = lat * 1e6
        p99 = float(np.percentile(us, 99))
        print(
            "| through the node | samples | changed by the guard | median [us] | p99 [us] "
            "| max [us] | p99 target |"
        )
        print("|---|---|---|---|---|---|---|")
        print(
            f"| command -> guarded command | {us.size} | {changed} | {np.median(us):.0f} | "
            f"{p99:.0f} | {us.max():.0f} | <= {TARGET_P99_S * 1e6:.0f} us: "
            f"{'met' if p99 * 1e-6 <= TARGET_P99_S else 'MISSED'} |"
        )
        print(
            f"\n{time.strftime('%Y-%m-%d %H:%M')} Python {platform.python_version()}, "
            f"{os.cpu_count()} CPUs, load {load_start:.2f} -> {os.getloadavg()[0]:.2f}, "
            f"wall {time.perf_counter() - start:.1f} s"
        )
        return
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
