# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the squeak probability estimators against bare LAPACK eigen-solves, one run.

    .venv/bin/python benchmarks/bench_probability.py [--rounds N]

(1) A live update with probability: `SqueakModel.predict` (modes, labels and P(squeak) from the
first-order estimator on its 1024 default scatter samples, one LAPACK solve) against a bare
`numpy.linalg.eig` of the same 36x36 state matrix (target <= 2, issue 10). (2) The Monte Carlo
reference: samples per second of `probability.monte_carlo` (4096 samples) against bare batched
`numpy.linalg.eigvals` of the same number of pre-built matrices. Table 1, 200 N, 55 rad/s
(paper). The calls alternate within each round; ratios are
medians of the per-round ratios.
"""

from __future__ import annotations

import argparse
import time
from statistics import median

import numpy as np

from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.studies.probability import monte_carlo
from leadscrew_ros.model.uncertainty.scatter import Scatter, draw

SPEED_RAD_S, LOAD_N = 55.0, 200.0
TARGET_LIVE_RATIO = 2.0  # a live update with P / bare eig (issue 10)


def _time(fn, repeat: int) -> float:
    start = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - start) / repeat


def live_update_ratio(
    model: SqueakModel, rounds: int, repeat: int = 200
) -> tuple[float, float, float]:
    """A live update with P(squeak) (`predict`) vs a bare `eig` of its state matrix, the two
    alternating `rounds` times (`repeat` calls each): median seconds per call of each and the
    median of the per-round ratios."""
    model.predict(SPEED_RAD_S, LOAD_N)  # samples drawn, estimator built
    a = model.state_matrix(SPEED_RAD_S, LOAD_N)
    eig, update = [], []
    for _ in range(rounds):
        eig.append(_time(lambda: np.linalg.eig(a), repeat))
        update.append(_time(lambda: model.predict(SPEED_RAD_S, LOAD_N), repeat))
    return median(update), median(eig), median(u / e for u, e in zip(update, eig, strict=True))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7, help="alternating rounds (default 7)")
    args = ap.parse_args(argv)
    model = SqueakModel()
    ref = draw(model.params, Scatter(), 4096)
    update, eig, ratio = live_update_ratio(model, args.rounds)
    batch = model.geometry.state_matrices(
        SPEED_RAD_S, LOAD_N, {k: v.ravel() for k, v in ref.values.items()}
    )
    mc_ratio, rows = [], []
    for _ in range(args.rounds):
        eigvals = _time(lambda: np.linalg.eigvals(batch), 2)
        mc = _time(lambda: monte_carlo(model, SPEED_RAD_S, LOAD_N, ref), 2)
        mc_ratio.append(mc / eigvals)
        rows.append((eigvals, mc))
    eigvals, mc = (median(r[k] for r in rows) for k in range(2))
    print("| measure | ours | bare LAPACK | ratio (median of rounds) |")
    print("|---|---:|---:|---:|")
    print(
        f"| live update with probability (`predict` with P, 1024 samples) vs eig "
        f"36x36 | {update * 1e3:.3f} ms | {eig * 1e3:.3f} ms | {ratio:.2f} "
        f"(target <= {TARGET_LIVE_RATIO:g}) |"
    )
    print(
        f"| Monte Carlo, 4096 samples | {ref.count / mc:,.0f} samples/s | "
        f"{ref.count / eigvals:,.0f} eigvals/s | {median(mc_ratio):.2f} |"
    )
    print(
        f"\n{args.rounds} rounds; Table 1, {LOAD_N:g} N, {SPEED_RAD_S:g} rad/s, paper; "
        f"Monte Carlo {mc:.2f} s per 4096 samples (target <= 2 s)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
