# SPDX-License-Identifier: Apache-2.0
"""Numbers for doc/development/benchmarks.md (issue 23): why every prediction still solves for
all right eigenvectors, and why the modes of P(squeak) are pruned by exact bounds rather than
by a bound on their sensitivity found so far.

    .venv/bin/python tools/fast_path_table.py [--points 40]

On a grid of both formulations x nut positions x random operating points (speed +-1..150 rad/s,
load +-10..500 N, default scatter), from one LAPACK solve with left and right vectors each:

1. labels: the label is the largest |q_i| of a mode's displacement half. How close its two
   largest entries are (a cheaper rule would have to resolve that), and how often a
   diagonal-dominance certificate of the mode's quadratic pencil (the rows j with
   |P_jj(lambda)| > sum |P_jl(lambda)| cannot hold the largest entry) leaves one candidate row;
2. the sensitivity bound the issue proposed: per label, the largest rate of each change
   (level, slope, damping; as elasticities, rate x nominal value / |lambda|) seen at a few seed
   points (the nominal nut, speeds 1..150 rad/s, 50 and 500 N) against the rates elsewhere
   (actual / bound without a safety factor, largest), and how many modes such a bound (x 2)
   would hand to the estimate;
3. the exact bound of `perturbation.hits_of`: modes per point that some sample can move across
   the threshold (expanded over the samples) and points decided at once (no such mode: P = 0).
"""

from __future__ import annotations

import argparse

import numpy as np

from leadscrew_ros.model import ScrewParameters, SqueakModel, Validity
from leadscrew_ros.model.physics.kernels import level_slope
from leadscrew_ros.model.physics.stability import GROWTH_TOL, eig_both
from leadscrew_ros.model.uncertainty.perturbation import EigenPairs, growth_rates

NUTS = (0.0, 0.07, 0.15, 0.24)
SEED_SPEEDS, SEED_LOADS = (1.0, 5.0, 20.0, 60.0, 150.0), (50.0, 500.0)


def analyse(m: SqueakModel, speed: float, load: float) -> dict:
    """One point: the eigenpairs, labels' entries, rates, elasticities, changes."""
    e = eig_both(m.state_matrix(speed, load))
    pairs = EigenPairs(m.geometry, speed, e)
    n, lam = m.geometry.n, pairs.lam
    q = np.abs(pairs.x[:n])
    expansion = m._probability._nominal  # the estimate's units and samples
    rates = growth_rates(expansion.units, speed, lam, pairs.x[:n], pairs.y_h[:, n:])
    level, slope = level_slope(m.params, speed, load, m.geometry.contact.alpha)
    nominal = np.array([level, slope, m.params.modal_damping])[:, None]
    a = m.state_matrix(speed, load)
    k, d = -a[n:, :n], -a[n:, n:]
    pencil = lam[:, None, None] ** 2 * np.eye(n) + lam[:, None, None] * d + k
    diag = np.abs(np.diagonal(pencil, axis1=1, axis2=2))
    open_rows = (diag <= np.abs(pencil).sum(axis=2) - diag).sum(axis=1)
    return dict(
        label=q.argmax(axis=0),
        top2=np.sort(q, axis=0)[-2:],
        open_rows=open_rows,
        rates=rates,
        elasticity=rates * nominal / np.abs(lam),
        threshold=GROWTH_TOL * np.abs(lam) - lam.real,
        change=expansion.changes(speed, load, m._probability._damping),
        lam=lam,
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=40, help="per formulation and nut position")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    ratios, certified, modes = [], 0, 0
    worst, bound_modes, needed, candidates, decided, points = 0.0, [], [], [], 0, 0
    for formulation in ("paper", "consistent"):
        model = SqueakModel(ScrewParameters(formulation=formulation))
        model.predict(20.0, 200.0)
        up = np.zeros((3, model.geometry.n))  # per label: largest positive / negative
        down = np.zeros((3, model.geometry.n))  # elasticity seen at the seed points
        for s in SEED_SPEEDS:
            for f in SEED_LOADS:
                for sign in (1.0, -1.0):
                    r = analyse(model, sign * s, f)
                    for j, label in enumerate(r["label"]):
                        up[:, label] = np.maximum(up[:, label], r["elasticity"][:, j])
                        down[:, label] = np.maximum(down[:, label], -r["elasticity"][:, j])
        for nut in NUTS:
            m = model.with_params(nut_position_m=nut)
            m.predict(20.0, 200.0)
            speeds = rng.uniform(1.0, 150.0, args.points) * rng.choice([-1.0, 1.0], args.points)
            loads = rng.uniform(10.0, 500.0, args.points) * rng.choice([-1.0, 1.0], args.points)
            for s, f in zip(speeds.tolist(), loads.tolist(), strict=True):
                if m.validity(s, f)[0] is not Validity.OK:
                    continue
                r = analyse(m, s, f)
                points += 1
                modes += len(r["lam"])
                ratios += (r["top2"][1] / r["top2"][0]).tolist()
                certified += int((r["open_rows"] == 1).sum())
                # the proposed bound: seeded elasticities x the changes' ends
                change, lab = r["change"], r["label"]
                level, slope = level_slope(m.params, s, f, m.geometry.contact.alpha)
                rel = change / np.array([level, slope, m.params.modal_damping])[:, None]
                hi, lo = rel.max(axis=1)[:, None], rel.min(axis=1)[:, None]
                seeded = np.abs(r["lam"]) * np.maximum(up[:, lab] * hi, down[:, lab] * -lo).sum(0)
                actual = (r["rates"].T @ change).max(axis=1)
                worst = max(worst, float(np.max(actual / np.maximum(seeded, 1e-300))))
                bound_modes.append(int((2 * seeded > r["threshold"]).sum()))
                growth = r["rates"].T @ change - r["threshold"][:, None]
                needed.append(int((growth.max(axis=1) > 0).sum()))
                ends = np.maximum(
                    r["rates"] * change.max(axis=1)[:, None],
                    r["rates"] * change.min(axis=1)[:, None],
                )
                reach = int((ends.sum(axis=0) > r["threshold"]).sum())
                candidates.append(reach)
                decided += reach == 0
    q = np.array(ratios) - 1.0
    print(f"{points} operating points, {modes} oscillatory modes (both formulations, nuts {NUTS})")
    print(
        "| quantity | value |\n|---|---:|\n"
        f"| labels: largest / second largest |q_i| - 1, median | {np.median(q):.1e} |\n"
        f"| ... 10 % of modes below | {np.quantile(q, 0.1):.1e} |\n"
        f"| ... 1 % of modes below | {np.quantile(q, 0.01):.1e} |\n"
        f"| ... smallest | {q.min():.1e} |\n"
        f"| labels a diagonal-dominance certificate decides | {certified / modes:.0%} |\n"
        f"| sensitivity bound seeded at {len(SEED_SPEEDS) * len(SEED_LOADS) * 2} points: "
        f"largest actual / bound | {worst:.1f} |\n"
        f"| modes per point that bound (x 2) hands to the estimate | "
        f"{np.mean(bound_modes):.1f} of {modes / points:.1f} |\n"
        f"| modes per point some sample moves across the threshold | {np.mean(needed):.2f} |\n"
        f"| modes per point the exact bound expands over the samples | "
        f"{np.mean(candidates):.2f} |\n"
        f"| points decided without the samples' growth (P = 0) | {decided / points:.0%} |"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
