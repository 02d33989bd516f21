# SPDX-License-Identifier: Apache-2.0
"""Benchmark of a new nut position (whole model rebuild) against a bare LAPACK eigen-solve.

    .venv/bin/python benchmarks/bench_contact.py [--rounds N] [--calls N]

A new nut position is `model.with_params(nut_position_m=z)` with a nut position never seen
before, as the node and the replay move the nut: no cached geometry for it (the contact
integrals are computed, the modal basis of the screw is reused), and the model is ready to
predict with P(squeak) (the scatter samples and the estimator's per-sample friction are
shared with `model`, which has predicted once; only the estimator's expansion is new). It is
compared with a bare `numpy.linalg.eig` of the model's state matrix (Table 1 defaults, 6/6
modes: 36x36, 200 N, 20 rad/s; target <= 0.5x, issue 11), and so are its parts: the geometry
(`assembly.build_geometry`) alone and `params.with_` alone.
The calls alternate within each round (order reversed every other round); each ratio is the
median of the per-round ratios. The 20/20 and 40/40 rows give the times at more modes, without
a ratio: a bare `eig` of their 120x120 and 240x240 state matrices runs on OpenBLAS threads and
takes 7 to 170 ms on this 2-core machine depending on their state and the load.
"""

from __future__ import annotations

import argparse
import os
import time
from itertools import count
from statistics import median

import numpy as np

from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.physics.assembly import build_geometry

SPEED_RAD_S, LOAD_N = 20.0, 200.0
TARGET = 0.5
_GOLDEN = (5**0.5 - 1) / 2


def _time(fn, calls: int) -> float:
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - start) / calls


def cases(modes: int) -> dict:
    """The functions timed at `modes` bending and torsion orders, keyed by row name."""
    params = ScrewParameters(n_bending=modes, n_torsion=modes)
    model = SqueakModel(params)
    model.predict(SPEED_RAD_S, LOAD_N)  # its samples exist, as in the node
    a = model.state_matrix(SPEED_RAD_S, LOAD_N)
    fresh = count(1)

    def new_position() -> float:  # never seen before, spread over the travel
        return next(fresh) * _GOLDEN % 1.0 * params.nut_travel_m

    def rebuild():
        model.with_params(nut_position_m=new_position())

    def geometry():
        build_geometry(moved[next(fresh) % len(moved)])

    # parameters with fresh nut positions for the geometry alone; more than the geometry cache
    # holds, cycled, so that every call misses it
    moved = [params.with_(nut_position_m=new_position()) for _ in range(1000)]
    return dict(
        eig=lambda: np.linalg.eig(a),
        rebuild=rebuild,
        geometry=geometry,
        with_=lambda: params.with_(nut_position_m=new_position()),
    )


def run(modes: int, rounds: int, calls: int) -> dict[str, float]:
    """Median seconds per call of each case and the median per-round ratios to `eig`."""
    fns = cases(modes)
    if modes != 6:
        del fns["eig"]
    for fn in fns.values():  # warm up
        _time(fn, max(1, calls // 10))
    samples: dict[str, list[float]] = {k: [] for k in fns}
    for r in range(rounds):
        for name in list(fns) if r % 2 == 0 else list(fns)[::-1]:
            samples[name].append(_time(fns[name], calls))
    out = {k: median(v) for k, v in samples.items()}
    if "eig" in samples:
        for k in ("rebuild", "geometry", "with_"):
            out[k + "_ratio"] = median(
                x / e for x, e in zip(samples[k], samples["eig"], strict=True)
            )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=15, help="alternating rounds (default 15)")
    ap.add_argument(
        "--calls",
        type=int,
        default=200,
        help="calls per round at 6/6 modes (default 200; fewer at more modes)",
    )
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    start = time.perf_counter()
    res = {m: run(m, args.rounds, max(2, args.calls // (m // 6) ** 2)) for m in (6, 20, 40)}
    print("| modes (state) | measure | time | bare `eig` | ratio (median of rounds) |")
    print("|---|---|---:|---:|---:|")
    for m, r in res.items():
        size = 6 * m
        ratio = {
            k: f"{r[k + '_ratio']:.2f}×" if "eig" in r else "–"
            for k in ("rebuild", "geometry", "with_")
        }
        e = f"{r['eig'] * 1e6:,.0f} µs" if "eig" in r else "–"
        target = f" (target ≤ {TARGET}×)" if "eig" in r else ""
        print(
            f"| {m}/{m} ({size}×{size}) | new nut position: "
            f"`model.with_params(nut_position_m=…)`, ready for P(squeak) | "
            f"{r['rebuild'] * 1e6:,.0f} µs "
            f"| {e} | {ratio['rebuild']}{target} |"
        )
        print(
            f"| | … of which the geometry (`assembly.build_geometry`: contact integrals and "
            f"state-matrix parts, timed alone) | {r['geometry'] * 1e6:,.0f} µs | | "
            f"{ratio['geometry']} |"
        )
        print(
            f"| | … of which `params.with_` (timed alone) | {r['with_'] * 1e6:,.0f} µs | | "
            f"{ratio['with_']} |"
        )
    print(
        f"\n{args.rounds} rounds of {args.calls} calls (6/6); Table 1, {LOAD_N:g} N, "
        f"{SPEED_RAD_S:g} rad/s, paper; {os.cpu_count()} CPUs; load avg {load0:.2f} → "
        f"{os.getloadavg()[0]:.2f}; {time.perf_counter() - start:.0f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
