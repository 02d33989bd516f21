# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the squeak model core against bare LAPACK eigen-solves, all in one run.

    .venv/bin/python benchmarks/bench_model.py [--quick] [--json OUT.json]

Prints a Markdown table: (1) one operating-point update, `SqueakModel.predict`, against a bare
`numpy.linalg.eig` of the same state matrix, without scatter on 16 points and with the default
scatter (P(squeak) from 1024 samples) on random operating points; (2) the throughput of a
speed x load map with `growth_field` against bare batched `numpy.linalg.eigvals` on the same
pre-built matrices, and against a naive map that integrates the contact again at every point;
(3) the uncached geometry precompute. `--profile` adds the budget of `predict` with scatter
(what it needs beside the eigen-solve, `bench_budget`), where its time goes, and its
eigen-solve against issue 23's eigenvalues-first alternative (`inverse_iteration`) for one point
and for the batch path. Calls being compared alternate within each round, so a
load change on the machine hits both; ratios are medians of the per-round ratios. See
benchmarks/README.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from statistics import median

import numpy as np
import scipy
from scipy.linalg import lapack

from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.physics import assembly
from leadscrew_ros.model.physics.contact import contact_integrals
from leadscrew_ros.model.physics.modes import modal_basis
from leadscrew_ros.model.physics.stability import (
    classify,
    eig_both,
    eig_right_many,
    left_rows,
    oscillatory_mask,
)
from leadscrew_ros.model.studies.fields import growth_field
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.work import _CHUNK
from leadscrew_ros.model.uncertainty.scatter import Scatter
from selective_vectors import SelectiveSolver

TARGET_POINT_RATIO = 1.5  # predict / bare eig
TARGET_SCATTER_RATIO = 1.3  # predict with the default scatter / bare eig (issue 34)
RANDOM_POINTS = 64  # random operating points of the scatter row
RANDOM_SPEED_RAD_S, RANDOM_LOAD_N = (1.0, 150.0), (10.0, 500.0)
SHIFT = 2.0**-50  # relative shift of an eigenvalue for its inverse iteration (4 ulp of 1)
SHIFT_TURNS = (1.0, 1j, -1.0, -1j)  # the shift's directions, tried in turn
TARGET_MAP_RATIO = 1.2  # growth_field / bare eigvals, per point
TARGET_REFINED_MAP_RATIO = 1.1  # stability_map (grid + refined boundary) / bare eigvals

# Work per benchmark: default run ~70 s, --quick ~5 s (2-core machine).
CONFIGS = {
    "default": dict(
        point_rounds=41,
        point_loops=4,
        map_grid=200,
        map_rounds=5,
        naive_points=50,
        geometry_rounds=31,
    ),
    "quick": dict(
        point_rounds=15,
        point_loops=2,
        map_grid=64,
        map_rounds=3,
        naive_points=20,
        geometry_rounds=11,
    ),
}


def interleaved(
    fns: dict[str, Callable[[], object]], rounds: int, warmup: int = 1
) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Wall and process-CPU seconds per call of each function, `rounds` samples each, the
    functions alternating within a round (order reversed every other round) after `warmup`
    untimed calls each."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    wall: dict[str, list[float]] = {name: [] for name in fns}
    cpu: dict[str, list[float]] = {name: [] for name in fns}
    for r in range(rounds):
        for name in list(fns) if r % 2 == 0 else list(fns)[::-1]:
            c0, t0 = time.process_time(), time.perf_counter()
            fns[name]()
            wall[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0)
    return wall, cpu


def paired_ratio(a: list[float], b: list[float]) -> float:
    """Median over rounds of a/b (robust to the machine's load changing between rounds)."""
    return median([x / y for x, y in zip(a, b, strict=True)])


def operating_points(n: int = 16) -> list[tuple[float, float]]:
    """n distinct points, speeds 5..100 rad/s and loads 50..400 N in shuffled pairings."""
    speeds = np.linspace(5.0, 100.0, n)
    loads = np.linspace(50.0, 400.0, n)[np.random.default_rng(0).permutation(n)]
    return list(zip(speeds.tolist(), loads.tolist(), strict=True))


def bench_point(model: SqueakModel, rounds: int, loops: int) -> dict:
    """Per operating point: full `predict` vs bare `eig` of the pre-built state matrix, plus
    the two model-side pieces (rescale, labels) to show where the overhead goes. Without scatter:
    the probability's share is benchmarks/bench_probability.py."""
    model = model.with_scatter(Scatter({}))
    points = operating_points()
    mats = [model.state_matrix(s, f) for s, f in points]
    eigs = [eig_both(a) for a in mats]
    labels = model.labels

    def predict():
        for _ in range(loops):
            for s, f in points:
                model.predict(s, f)

    def eig():
        for _ in range(loops):
            for a in mats:
                np.linalg.eig(a)

    def rescale():
        for _ in range(loops):
            for s, f in points:
                model.state_matrix(s, f)

    def label():
        for _ in range(loops):
            for eigen in eigs:
                classify(eigen, labels)

    calls = loops * len(points)
    raw, _ = interleaved(dict(predict=predict, eig=eig, rescale=rescale, label=label), rounds)
    us = {k: [t / calls * 1e6 for t in v] for k, v in raw.items()}
    return dict(
        points=points,
        calls_per_sample=calls,
        samples_us=us,
        median_us={k: median(v) for k, v in us.items()},
        ratio=paired_ratio(us["predict"], us["eig"]),
    )


def random_points(n: int = RANDOM_POINTS, seed: int = 0) -> list[tuple[float, float]]:
    """n operating points drawn uniformly: speed in RANDOM_SPEED_RAD_S, load in RANDOM_LOAD_N."""
    rng = np.random.default_rng(seed)
    speeds = rng.uniform(*RANDOM_SPEED_RAD_S, n)
    loads = rng.uniform(*RANDOM_LOAD_N, n)
    return list(zip(speeds.tolist(), loads.tolist(), strict=True))


def bench_scatter_point(model: SqueakModel, rounds: int, loops: int) -> dict:
    """`predict` with the model's scatter (the default: P(squeak) from 1024 samples) at random
    operating points against a bare `eig` of the same pre-built state matrices."""
    points = random_points()
    mats = [model.state_matrix(s, f) for s, f in points]
    predictions = [model.predict(s, f) for s, f in points]  # samples drawn, estimator built

    def predict():
        for _ in range(loops):
            for s, f in points:
                model.predict(s, f)

    def eig():
        for _ in range(loops):
            for a in mats:
                np.linalg.eig(a)

    calls = loops * len(points)
    raw, _ = interleaved(dict(predict=predict, eig=eig), rounds)
    us = {k: [t / calls * 1e6 for t in v] for k, v in raw.items()}
    between = sum(0.0 < (p.probability or 0.0) < 1.0 for p in predictions)
    return dict(
        points=points,
        calls_per_sample=calls,
        samples_us=us,
        median_us={k: median(v) for k, v in us.items()},
        ratio=paired_ratio(us["predict"], us["eig"]),
        uncertain=between,
    )


def profile_predict(model: SqueakModel, loops: int = 20) -> str:
    """Where the time of `predict` with the model's scatter goes at the random points: each
    stage's share (time in the functions that do it, the calls wrapped with a timer), then
    the cProfile entries that take most of it."""
    import cProfile
    import io
    import pstats
    from unittest import mock

    from leadscrew_ros.model import squeak_model
    from leadscrew_ros.model.uncertainty.perturbation import FirstOrderProbability

    # stage -> the functions that do it (also those of the code before issue 23, for --src)
    stages = {
        "state matrix (rescale)": [(SqueakModel, "state_matrix")],
        "eigen-solve (LAPACK dgeev)": [(squeak_model, "eig_both")],
        "labels and modes (`classify`)": [(squeak_model, "classify")],
        "P(squeak) (first-order estimate over the samples)": [
            (FirstOrderProbability, "probability"),
            (FirstOrderProbability, "hits"),
            (squeak_model, "EigenPairs"),
        ],
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

    points = random_points()
    mats = [model.state_matrix(s, f) for s, f in points]
    for s, f in points:
        model.predict(s, f)
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
        for _ in range(loops):
            for s, f in points:
                model.predict(s, f)
        total = time.perf_counter() - t0
    finally:
        for patch in patches:
            patch.stop()
    t0 = time.perf_counter()
    for _ in range(loops):
        for a in mats:
            np.linalg.eig(a)
    eig = time.perf_counter() - t0
    calls = loops * len(points)
    rows = [
        f"| {name} | {t / calls * 1e6:.1f} µs | {t / total:.0%} | {t / eig:.2f}× |"
        for name, t in spent.items()
    ]
    rest = total - sum(spent.values())
    rows.append(
        f"| the rest (checks, validity, `Prediction`) | {rest / calls * 1e6:.1f} µs | "
        f"{rest / total:.0%} | {rest / eig:.2f}× |"
    )
    rows.append(f"| **`predict`** | {total / calls * 1e6:.1f} µs | 100% | {total / eig:.2f}× |")
    rows.append(f"| bare `numpy.linalg.eig` (after it) | {eig / calls * 1e6:.1f} µs | | 1.00× |")
    head = (
        f"Where `predict` spends its time ({calls} calls, default scatter, random points; the "
        "stages timed inside it, one run):\n\n| stage | per call | share | / bare `eig` |\n"
        "|---|---:|---:|---:|\n"
    )
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(loops):
        for s, f in points:
            model.predict(s, f)
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).strip_dirs().sort_stats("tottime").print_stats(15)
    return head + "\n".join(rows) + "\n\ncProfile (tottime):\n" + out.getvalue()


def inverse_iteration(a: np.ndarray, n: int, left: bool) -> tuple[np.ndarray, ...]:
    """Issue 23's eigenvalues-first alternative to the vectors of LAPACK: `dgeev` without
    vectors, then each oscillatory mode's displacement half q (Q(lam) q = 0, Q(lam) = lam^2 I +
    lam D + K from the lower half [-K, -D] of the state matrix `a`) by one step of inverse
    iteration, Q(lam (1 + SHIFT)) z = 1, all modes in one batched `numpy.linalg.solve`; with
    `left` also the lower halves y2^H of the left vectors (y2^H Q(lam) = 0) by the transposed
    systems in the same call, normalised y^H x = y2^H (2 lam I + D) q = 1. The shift is a few
    ulp: the LU is not exactly singular (at lam itself it can be), and the error of a vector,
    about SHIFT |lam| / the distance to the nearest other eigenvalue, stays ~1e-10 for the
    whirl pairs (their eigenvalues ~1e-5 |lam| apart). Some BLAS kernels round one mode's LU
    at lam (1 + SHIFT) to an exact zero pivot (a point of the test grid on OpenBLAS SkylakeX):
    the shift turns by a quarter turn, same size, until every LU is regular
    (`shifted_solve`). Returns (lam, osc, q (N, M), y2^H (M, N) or None)."""
    lam, osc = eigenvalues(a)
    m, lower = len(osc), a[n:]
    z, turn = shifted_solve(lambda turn: pencils(a, n, lam[osc] * (1.0 + turn * SHIFT), left))
    shift, z = lam[osc] * (1.0 + turn * SHIFT), z[..., 0]
    if not left:
        return lam, osc, z.T, None
    right, rows = z[:m], z[m:]
    dq = 2 * shift[:, None] * right - np.einsum("ij,mj->mi", lower[:, n:], right)  # (2 lam + D) q
    return lam, osc, right.T, rows / np.einsum("mi,mi->m", rows, dq)[:, None]


def shifted_solve(pencils_at: Callable[[complex], np.ndarray]) -> tuple[np.ndarray, complex]:
    """Q z = 1 for the stack of pencils `pencils_at(turn)` gives at the shifts lam (1 + turn
    SHIFT), the first turn of `SHIFT_TURNS` whose every LU is regular; (z, that turn)."""
    for turn in SHIFT_TURNS:
        q = pencils_at(turn)
        try:
            return np.linalg.solve(q, np.ones((*q.shape[:2], 1))), turn
        except np.linalg.LinAlgError:
            continue
    raise np.linalg.LinAlgError("every shift of the inverse iteration met a singular LU")


def eigenvalues(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All eigenvalues of `a` by `dgeev` without vectors, and the indices of the oscillatory."""
    wr, wi, _, _, info = lapack.dgeev(a, compute_vl=0, compute_vr=0)
    assert info == 0
    lam = wr + 1j * wi
    return lam, np.flatnonzero(oscillatory_mask(lam))


def pencils(a: np.ndarray, n: int, shift: np.ndarray, left: bool) -> np.ndarray:
    """Q(shift) = shift^2 I + shift D + K of the state matrix `a` (lower half [-K, -D]) at each
    of the M `shift`s, (M, N, N) complex, and with `left` their transposes after them."""
    m, lower = len(shift), a[n:]
    q = np.empty(((1 + left) * m, n, n), complex)
    np.multiply(shift[:, None, None], lower[:, n:], out=q[:m])  # -lam D
    q[:m] += lower[:, :n]  # -K
    np.negative(q[:m], out=q[:m])
    q[:m].reshape(m, n * n)[:, :: n + 1] += (shift * shift)[:, None]
    if left:
        q[m:] = q[:m].transpose(0, 2, 1)  # Q^T conj(y2) = 0: the rows y2^H
    return q


def bench_eigen_paths(model: SqueakModel, rounds: int) -> str:
    """The eigen-solve of `predict` with scatter (LAPACK's right vectors, the left ones from
    their inverse) against issue 23's eigenvalues-first alternative (`inverse_iteration`) at
    the random points, interleaved; first checked: the alternative's labels are LAPACK's, its
    eigenvalues the same to the bit, its left vectors `left_rows`' to 1e-9."""
    n, points = model.geometry.n, random_points()
    mats = [model.state_matrix(s, f) for s, f in points]
    worst = 0.0
    for a in mats:
        e = eig_both(a, False)
        lam, osc, q, y_h = inverse_iteration(a, n, True)
        x = e.vr[:n, e.osc] + 1j * e.vr[:n, e.osc + 1]
        assert np.array_equal(lam, e.lam) and np.array_equal(osc, e.osc)
        dominant = np.abs(x).argmax(axis=0)
        assert np.array_equal(np.abs(q).argmax(axis=0), dominant), "labels differ"
        cols = np.arange(len(osc))
        scale = q[dominant, cols] / x[dominant, cols]  # q = scale x: y2^H scales by 1 / scale
        reference = left_rows(e.vr, e.osc, n)
        error = np.abs(y_h * scale[:, None] - reference).max(axis=1)
        worst = max(worst, float((error / np.abs(reference).max(axis=1)).max()))
    assert worst < 1e-9, worst
    selective, unconverged, columns, wrong = SelectiveSolver(2 * n), 0, 0, 0
    for a in mats:  # the selective routine's eigenvalues are LAPACK's; its labels?
        e = eig_both(a, False)
        lam, osc, vr = selective.solve(a)
        x = e.vr[:n, e.osc] + 1j * e.vr[:n, e.osc + 1]
        assert np.array_equal(osc, e.osc), "oscillatory modes differ"
        np.testing.assert_allclose(lam, e.lam, rtol=1e-12, atol=0.0)
        q = vr[:n, 0::2] + 1j * vr[:n, 1::2]
        wrong += int((np.abs(q).argmax(axis=0) != np.abs(x).argmax(axis=0)).sum())
        unconverged, columns = unconverged + selective.unconverged, columns + vr.shape[1]

    def run(fn):
        return lambda: [fn(a) for a in mats]

    def with_left(a):
        e = eig_both(a, False)
        return e, left_rows(e.vr, e.osc, n)

    stack = np.array(mats)

    def batch():  # predict_many's: the solves stacked, the left vectors of each
        groups, failed = eig_right_many(stack, n)
        assert not failed
        return [
            left_rows(vr, osc, n) for _, g in groups for vr, osc in zip(g.vr, g.osc, strict=True)
        ]

    def batch_inverse():  # every point's pencils (right and left) in one stacked solve
        points = [(a, lam[osc]) for a, (lam, osc) in zip(mats, map(eigenvalues, mats), strict=True)]
        return shifted_solve(
            lambda turn: np.concatenate(
                [pencils(a, n, lam * (1.0 + turn * SHIFT), True) for a, lam in points]
            )
        )[0]

    fns = {
        "bare `numpy.linalg.eig`": run(np.linalg.eig),
        "`dgeev`, eigenvalues only": run(lambda a: lapack.dgeev(a, compute_vl=0, compute_vr=0)),
        "`dgeev`, right vectors (the labels)": run(lambda a: eig_both(a, False)),
        "`predict`'s: `dgeev` right vectors + `left_rows`": run(with_left),
        "`dgeev` eigenvalues + right vectors by inverse iteration": run(
            lambda a: inverse_iteration(a, n, False)
        ),
        "… + left vectors by the transposed solves (one call)": run(
            lambda a: inverse_iteration(a, n, True)
        ),
        "balanced Hessenberg + eigenvalues (`dhseqr`), right vectors by `dhsein` (selective "
        "inverse iteration), back-transformed": run(selective.solve),
        "batch (`predict_many`'s): `eig_right_many` + `left_rows` of each": batch,
        "batch alternative: eigenvalues of each, all points' pencils (right + left) in one "
        "stacked solve": batch_inverse,
    }
    wall, cpu = interleaved(fns, rounds)
    bare = wall["bare `numpy.linalg.eig`"]
    # the LU per mode: one point's modes per call against all points' in one stack
    each = [
        pencils(a, n, lam[osc], False)
        for a, (lam, osc) in zip(mats, map(eigenvalues, mats), strict=True)
    ]
    stacked = np.concatenate(each)
    systems = len(stacked)
    lu, _ = interleaved(
        {
            "per point": lambda: [np.linalg.solve(q, np.ones((len(q), n, 1))) for q in each],
            "stacked": lambda: np.linalg.solve(stacked, np.ones((systems, n, 1))),
        },
        rounds,
    )
    per_system = {k: median(t) / systems * 1e6 for k, t in lu.items()}
    rows = [
        f"| {name} | {median(t) / len(mats) * 1e6:.1f} µs | {paired_ratio(t, bare):.2f}× | "
        f"{paired_ratio(cpu[name], t):.2f} |"
        for name, t in wall.items()
    ]
    return (
        f"The eigen-solve with scatter and issue 23's eigenvalues-first alternative ({len(mats)} "
        f"random points, {rounds} interleaved rounds; the alternative's labels equal LAPACK's, "
        f"its left vectors within {worst:.1e} of `left_rows`):\n\n"
        "| eigen-solve | per point | / bare `eig` | CPU / wall |\n|---|---:|---:|---:|\n"
        + "\n".join(rows)
        + f"\n\n`dhsein`'s convergence test rejected {unconverged} of its {columns} vector columns "
        f"(it returns the last iterate), and {wrong} of its {columns // 2} labels differ from "
        "LAPACK's." + f"\n\nA complex {n} x {n} solve (the LU of one mode's pencil): "
        f"{per_system['per point']:.2f} µs per system with one point's modes per call, "
        f"{per_system['stacked']:.2f} µs in one stack of all {systems}."
    )


def bench_budget(model: SqueakModel, rounds: int) -> str:
    """What `predict` with scatter has to spend beside its eigen-solve, interleaved at the
    random points against a bare `numpy.linalg.eig`: the LAPACK calls it cannot skip (`dgeev`
    with right vectors for the labels, `dgesv` for the estimate's left vectors), `predict`
    without scatter (state matrix, eigen-solve, labels, `Prediction`: no estimate at all) and
    with the default scatter. The target's margin over the first row is what the estimate, the
    state matrix and the labels may take together."""
    n, points = model.geometry.n, random_points()
    mats = [model.state_matrix(s, f) for s, f in points]
    bare_model = model.with_scatter(Scatter({}))

    def lapack_only(a):
        e = eig_both(a, False)
        return left_rows(e.vr, e.osc, n)

    fns = {
        "bare `numpy.linalg.eig`": lambda: [np.linalg.eig(a) for a in mats],
        "the LAPACK calls `predict` with scatter needs (`dgeev` right vectors + `dgesv` "
        "for the left ones)": lambda: [lapack_only(a) for a in mats],
        "`predict` without scatter (no estimate)": lambda: [
            bare_model.predict(s, f) for s, f in points
        ],
        "`predict` with the default scatter": lambda: [model.predict(s, f) for s, f in points],
    }
    wall, _ = interleaved(fns, rounds)
    bare = wall["bare `numpy.linalg.eig`"]
    return per_call_table(
        f"The budget of `predict` with scatter ({len(mats)} random points, {rounds} interleaved "
        f"rounds; target ≤ {TARGET_SCATTER_RATIO}× a bare `eig`)",
        "calls | per point | / bare `eig`",
        wall,
        len(mats),
        lambda t: paired_ratio(t, bare),
    )


def per_call_table(
    intro: str,
    header: str,
    times: dict[str, list[float]],
    calls: int,
    ratio: Callable[[list[float]], float],
) -> str:
    """A Markdown table after `intro`: per row its name, the median of its `times` [s] over
    `calls` calls [µs] and its `ratio`."""
    rows = [
        f"| {name} | {median(t) / calls * 1e6:.1f} µs | {ratio(t):.2f}× |"
        for name, t in times.items()
    ]
    return f"{intro}:\n\n| {header} |\n|---|---:|---:|\n" + "\n".join(rows)


def bench_paced(model: SqueakModel, rounds: int, period_s: float = 0.005) -> str:
    """`predict` at the random points back to back against the same calls with a pause of one
    200 Hz input period before each (sleeping, as a node between its inputs, or spinning):
    the per-call cost the node sees on this machine. Rounds interleave the three."""
    points = random_points()

    def paced(pause):
        times = []
        for s, f in points:
            pause()
            t = time.perf_counter()
            model.predict(s, f)
            times.append(time.perf_counter() - t)
        return times

    def spin():
        end = time.perf_counter() + period_s
        while time.perf_counter() < end:
            pass

    kinds = {
        "back to back": lambda: None,
        f"after a {period_s * 1e3:g} ms sleep": lambda: time.sleep(period_s),
        f"after {period_s * 1e3:g} ms of spinning": spin,
    }
    samples: dict[str, list[float]] = {k: [] for k in kinds}
    for _ in range(rounds):
        for name, pause in kinds.items():
            samples[name] += paced(pause)
    base = median(samples["back to back"])
    return per_call_table(
        f"`predict` (default scatter) paced as a node's inputs ({len(points)} random points, "
        f"{rounds} interleaved rounds, median per call)",
        "calls | per call | / back to back",
        samples,
        1,
        lambda t: median(t) / base,
    )


def naive_state_matrix(model: SqueakModel, speed: float, load: float) -> np.ndarray:
    """State matrix with every contact-matrix entry integrated again (no precomputation)."""
    g = model.geometry
    m = replace(g, contact=contact_integrals(g.params, g.basis)).matrices(speed, load)
    n = g.n
    return np.block([[np.zeros((n, n)), np.eye(n)], [-m.stiffness, -m.damping]])


def bench_map(model: SqueakModel, grid: int, rounds: int, naive_points: int) -> dict:
    """points/s of growth_field on a grid x grid speed x load map, and of stability_map (the
    same grid plus its refined stability boundary), vs bare batched eigvals on the same
    matrices (pre-built in growth_field's chunks) vs a naive per-point assembly."""
    speed = np.linspace(1.0, 100.0, grid)
    load = np.linspace(10.0, 600.0, grid)
    s_flat, f_flat = (a.ravel() for a in np.broadcast_arrays(speed[None, :], load[:, None]))
    assert np.all(model.validity_code(s_flat, f_flat) == 0), "map must be all valid points"
    chunks = [
        model.geometry.state_matrices(s_flat[i : i + _CHUNK], f_flat[i : i + _CHUNK])
        for i in range(0, s_flat.size, _CHUNK)
    ]
    pick = np.linspace(0, s_flat.size - 1, naive_points).astype(int)
    naive_pts = list(zip(s_flat[pick].tolist(), f_flat[pick].tolist(), strict=True))
    s0, f0 = naive_pts[0]
    assert np.allclose(
        naive_state_matrix(model, s0, f0), model.state_matrix(s0, f0), rtol=1e-9, atol=1e-6
    ), "naive assembly must give the same matrix"

    def map_():
        growth_field(model, speed[None, :], load[:, None])

    boundary_points = []

    def refined():
        boundary_points[:] = [
            len(stability_map(model, "speed_rad_s", speed, "load_n", load).boundary)
        ]

    def eigvals():
        for a in chunks:
            np.linalg.eigvals(a)

    def naive():
        for s, f in naive_pts:
            np.linalg.eigvals(naive_state_matrix(model, s, f))

    growth_field(model, speed[None, :8], load[:8, None])  # warm up on a small map only
    np.linalg.eigvals(chunks[0])
    stability_map(model, "speed_rad_s", speed[:8], "load_n", load[:8])
    raw, cpu = interleaved(
        dict(map=map_, refined=refined, eigvals=eigvals, naive=naive), rounds, warmup=0
    )
    n = {"map": s_flat.size, "refined": s_flat.size, "eigvals": s_flat.size, "naive": naive_points}
    pps = {k: [n[k] / t for t in v] for k, v in raw.items()}
    med = {k: median(v) for k, v in pps.items()}
    return dict(
        grid=[grid, grid],
        points=s_flat.size,
        chunk=_CHUNK,
        naive_points=naive_points,
        samples_s=raw,
        samples_points_per_s=pps,
        median_points_per_s=med,
        samples_cpu_s=cpu,
        cpu_per_wall={k: paired_ratio(cpu[k], raw[k]) for k in raw},
        ratio=paired_ratio(raw["map"], raw["eigvals"]),
        boundary_points=boundary_points[0],
        refined_ratio=paired_ratio(raw["refined"], raw["eigvals"]),
        speedup_over_naive=med["map"] / med["naive"],
    )


def bench_geometry(model: SqueakModel, rounds: int) -> dict:
    """Uncached geometry precompute, and its two parts: modal basis and contact integrals
    (both closed form; a new nut position alone is benchmarks/bench_contact.py)."""
    p = model.params.geometry_only()
    basis = modal_basis(p)

    def total():
        assembly._screw_of.cache_clear()
        return assembly._geometry_of.__wrapped__(assembly._Key(p, assembly._GEOMETRY_FIELDS))

    raw, _ = interleaved(
        dict(
            total=total,
            modal_basis=lambda: modal_basis(p),
            contact_integrals=lambda: contact_integrals(p, basis),
        ),
        rounds,
    )
    ms = {k: [t * 1e3 for t in v] for k, v in raw.items()}
    return dict(samples_ms=ms, median_ms={k: median(v) for k, v in ms.items()})


def environment() -> dict:
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        blas = f"{blas['name']} {blas['version']}"
    except Exception:  # pragma: no cover
        blas = "unknown"
    return dict(
        date=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        python=platform.python_version(),
        numpy=np.__version__,
        scipy=scipy.__version__,
        blas=blas,
        cpu_count=os.cpu_count(),
        openblas_coretype=os.environ.get("OPENBLAS_CORETYPE", ""),
        machine=platform.machine(),
        load_avg_1min_start=os.getloadavg()[0],
    )


def verdict(ratio: float, target: float) -> str:
    return f"≤ {target}× {'met' if ratio <= target else 'MISSED'}"


def table(res: dict) -> str:
    pt, mp, geo, env = res["point"], res["map"], res["geometry"], res["env"]
    sp = res["scatter_point"]
    u, pps, ms = pt["median_us"], mp["median_points_per_s"], geo["median_ms"]
    g = "×".join(map(str, mp["grid"]))
    rows = [
        (
            "1 per point",
            f"`predict` without scatter (rescale + eig + labels), {len(pt['points'])} "
            "points cycled",
            f"{u['predict']:.1f} µs",
            f"bare `eig` {u['eig']:.1f} µs",
            f"{pt['ratio']:.2f}×",
            verdict(pt["ratio"], TARGET_POINT_RATIO),
        ),
        (
            "",
            "… of which rescale (`state_matrix`, timed alone)",
            f"{u['rescale']:.1f} µs",
            "",
            "",
            "",
        ),
        ("", "… of which labels (`classify`, timed alone)", f"{u['label']:.1f} µs", "", "", ""),
        (
            "1 per point",
            f"`predict` with the default scatter (P(squeak), {sp['samples']} samples), "
            f"{len(sp['points'])} random points (speed {RANDOM_SPEED_RAD_S[0]:g}–"
            f"{RANDOM_SPEED_RAD_S[1]:g} rad/s, load {RANDOM_LOAD_N[0]:g}–{RANDOM_LOAD_N[1]:g} N; "
            f"{sp['uncertain']} with 0 < P < 1)",
            f"{sp['median_us']['predict']:.1f} µs",
            f"bare `eig` {sp['median_us']['eig']:.1f} µs",
            f"{sp['ratio']:.2f}×",
            verdict(sp["ratio"], TARGET_SCATTER_RATIO),
        ),
        (
            "2 map",
            f"`growth_field` {g} speed×load",
            f"{pps['map']:,.0f} pts/s",
            f"bare `eigvals` (chunks of {mp['chunk']}) {pps['eigvals']:,.0f} pts/s",
            f"{mp['ratio']:.2f}×",
            verdict(mp["ratio"], TARGET_MAP_RATIO),
        ),
        (
            "",
            f"`stability_map` {g} speed×load: grid + refined boundary "
            f"({mp['boundary_points']} points)",
            f"{pps['refined']:,.0f} pts/s",
            f"bare `eigvals` {pps['eigvals']:,.0f} pts/s",
            f"{mp['refined_ratio']:.2f}×",
            verdict(mp["refined_ratio"], TARGET_REFINED_MAP_RATIO),
        ),
        (
            "",
            "CPU time / wall time of the map (1 = one busy thread; ~2 = an idle BLAS "
            "worker thread spinning on the second core)",
            f"{mp['cpu_per_wall']['map']:.2f}",
            f"bare `eigvals` {mp['cpu_per_wall']['eigvals']:.2f}",
            "",
            "",
        ),
        (
            "",
            f"naive: integrate every entry per point ({mp['naive_points']} points)",
            f"{pps['naive']:,.1f} pts/s",
            "map speed-up over naive",
            f"{mp['speedup_over_naive']:,.0f}×",
            "",
        ),
        (
            "3 geometry",
            "uncached `_geometry_of` (modal basis + contact integrals + units)",
            f"{ms['total']:.2f} ms",
            f"basis {ms['modal_basis']:.3f} ms, contact {ms['contact_integrals']:.2f} ms",
            "",
            "",
        ),
    ]
    head = (
        "| benchmark | measurement | result | reference | ratio | target |\n"
        "|---|---|---:|---|---:|---|"
    )
    body = "\n".join("| " + " | ".join(r) + " |" for r in rows)
    envline = (
        f"{env['date']} · Python {env['python']} · numpy {env['numpy']} · scipy "
        f"{env['scipy']} · BLAS {env['blas']} · {env['cpu_count']} CPUs ({env['machine']})"
        + (f" · OPENBLAS_CORETYPE={env['openblas_coretype']}" if env["openblas_coretype"] else "")
        + f" · load avg {env['load_avg_1min_start']:.2f} → {env['load_avg_1min_end']:.2f}"
        + f" · mode {res['mode']} · {res['wall_s']:.1f} s"
    )
    return f"{head}\n{body}\n\n{envline}"


def scatter_line(res: dict) -> str:
    """The scatter row alone, with the environment."""
    sp, env = res["scatter_point"], res["env"]
    return (
        f"`predict` with the default scatter at {len(sp['points'])} random points "
        f"({sp['uncertain']} with 0 < P < 1): {sp['median_us']['predict']:.1f} µs, bare `eig` "
        f"{sp['median_us']['eig']:.1f} µs: **{sp['ratio']:.2f}×** "
        f"({verdict(sp['ratio'], TARGET_SCATTER_RATIO)}) · load avg "
        f"{env['load_avg_1min_start']:.2f} → {env['load_avg_1min_end']:.2f} · {res['wall_s']:.1f} s"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller run (~5 s)")
    ap.add_argument("--json", metavar="OUT.json", help="also write the raw numbers here")
    ap.add_argument(
        "--only-scatter",
        action="store_true",
        help="only the row of predict with the default scatter at random points",
    )
    ap.add_argument(
        "--profile",
        action="store_true",
        help="also print where that predict spends its time and its eigen-solve's alternatives",
    )
    args = ap.parse_args(argv)
    mode = "quick" if args.quick else "default"
    cfg = CONFIGS[mode]
    t0 = time.perf_counter()
    model = SqueakModel()
    res = dict(
        mode=mode,
        config=cfg,
        env=environment(),
        n_modes=model.params.n_modes,
        targets=dict(
            point_ratio=TARGET_POINT_RATIO,
            scatter_ratio=TARGET_SCATTER_RATIO,
            map_ratio=TARGET_MAP_RATIO,
            refined_map_ratio=TARGET_REFINED_MAP_RATIO,
        ),
    )
    res["scatter_point"] = bench_scatter_point(model, cfg["point_rounds"], cfg["point_loops"])
    res["scatter_point"]["samples"] = model.sample_count
    if args.only_scatter:
        res["wall_s"] = time.perf_counter() - t0
        res["env"]["load_avg_1min_end"] = os.getloadavg()[0]
        print(scatter_line(res))
    else:
        res["point"] = bench_point(model, cfg["point_rounds"], cfg["point_loops"])
        res["map"] = bench_map(model, cfg["map_grid"], cfg["map_rounds"], cfg["naive_points"])
        res["geometry"] = bench_geometry(model, cfg["geometry_rounds"])
        res["wall_s"] = time.perf_counter() - t0
        res["env"]["load_avg_1min_end"] = os.getloadavg()[0]
        print(table(res))
    if args.profile:
        print("\n" + bench_budget(model, cfg["point_rounds"]))
        print("\n" + profile_predict(model))
        print("\n" + bench_eigen_paths(model, cfg["point_rounds"]))
        print("\n" + bench_paced(model, cfg["point_rounds"]))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
