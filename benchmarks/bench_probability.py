# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the squeak probability estimators against bare LAPACK eigen-solves, one run.

    .venv/bin/python benchmarks/bench_probability.py [--rounds N]

(1) A live update with probability: `SqueakModel.predict` (modes, labels and P(squeak) from the
first-order estimator on its 1024 default scatter samples, one LAPACK solve) against a bare
`numpy.linalg.eig` of the same 36x36 state matrix (target <= 2, issue 10). (2) The Monte Carlo reference: samples per second of `probability.monte_carlo`
(4096 samples) against bare batched `numpy.linalg.eigvals` of the same number of pre-built
matrices. Table 1, 200 N, 55 rad/s (paper). The calls alternate within each round; ratios are
medians of the per-round ratios.
"""

from __future__ import annotations

import argparse
import time
from statistics import median

import numpy as np

from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.probability import monte_carlo
from leadscrew_ros.model.scatter import Scatter, draw

SPEED_RAD_S, LOAD_N = 55.0, 200.0


def _time(fn, repeat: int) -> float:
    start = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - start) / repeat


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7, help="alternating rounds (default 7)")
    args = ap.parse_args(argv)
    model = SqueakModel()
    ref = draw(model.params, Scatter(), 4096)
    model.predict(SPEED_RAD_S, LOAD_N)                  # samples drawn, estimator built
    a = model.state_matrix(SPEED_RAD_S, LOAD_N)
    batch = model.geometry.state_matrices(SPEED_RAD_S, LOAD_N,
                                          {k: v.ravel() for k, v in ref.values.items()})
    live_ratio, mc_ratio, rows = [], [], []
    for _ in range(args.rounds):
        eig = _time(lambda: np.linalg.eig(a), 200)
        update = _time(lambda: model.predict(SPEED_RAD_S, LOAD_N), 200)
        eigvals = _time(lambda: np.linalg.eigvals(batch), 2)
        mc = _time(lambda: monte_carlo(model, SPEED_RAD_S, LOAD_N, ref), 2)
        live_ratio.append(update / eig)
        mc_ratio.append(mc / eigvals)
        rows.append((eig, update, eigvals, mc))
    eig, update, eigvals, mc = (median(r[k] for r in rows) for k in range(4))
    print("| measure | ours | bare LAPACK | ratio (median of rounds) |")
    print("|---|---:|---:|---:|")
    print(f"| live update with probability (`predict` with P, 1024 samples) vs eig "
          f"36x36 | {update * 1e3:.3f} ms | {eig * 1e3:.3f} ms | {median(live_ratio):.2f} "
          f"(target <= 2) |")
    print(f"| Monte Carlo, 4096 samples | {ref.count / mc:,.0f} samples/s | "
          f"{ref.count / eigvals:,.0f} eigvals/s | {median(mc_ratio):.2f} |")
    print(f"\n{args.rounds} rounds; Table 1, {LOAD_N:g} N, {SPEED_RAD_S:g} rad/s, paper; "
          f"Monte Carlo {mc:.2f} s per 4096 samples (target <= 2 s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
