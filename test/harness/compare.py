# SPDX-License-Identifier: Apache-2.0
"""Predictions of two code paths (one point or many, one BLAS kernel or another) compared by
what LAPACK defines, not bit for bit.

No LAPACK promises the same rounding from a batched and a single solve, from dgeev with and
without left vectors, or from two kernels of one library (SkylakeX and Haswell OpenBLAS differ
in the last bits). An eigenvalue's rounding error is of the order of eps times a norm of the
balanced state matrix times its condition number, not of its own size: on the OpenBLAS
SkylakeX kernel, dgeev with against without left vectors moved a B1x mode at 469 Hz by 7e-13
of its |lambda| and one near critical damping (7 Hz, |lambda| 1781 1/s, about to become two
real roots) by 2e-11 of its frequency. So:

- every eigenvalue's frequency (2 pi f) and growth rate are compared within REL of the
  spectral radius of the modes (the largest |lambda|, 1.5e5 1/s for the default screw: a
  lower bound of any norm of the state matrix), a damping ratio (-Re / |lambda|) within that
  over its |lambda|;
- where an order or a verdict rests on a near-tie at that scale, what is defined: the modes
  as a set (ordered by frequency, which separates even a whirl pair by ~1e-5 |lambda|), a
  verdict only where the growth rate is clear of its threshold, and P(squeak) to `P_SAMPLES`
  of its scatter samples (a sample at its own threshold can flip).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from leadscrew_ros.model.physics.stability import GROWTH_TOL

REL = 1e-12  # of the spectral radius
P_SAMPLES = 2  # P(squeak) may differ by this many of its samples' share


def _modulus(mode: Sequence) -> float:
    return math.hypot(mode[2], 2 * math.pi * mode[1])


def mode_differences(a: Sequence[Sequence], b: Sequence[Sequence], rel: float = REL) -> list[str]:
    """What differs between two mode lists beyond rounding (empty: the same modes).

    Parameters
    ----------
    a, b : sequences of (label, frequency_hz, growth_rate, damping_ratio[, unstable])
        `ModeResult`s or tuples; the verdict is compared when both carry one.
    rel : float
        Tolerance relative to the spectral radius (the largest |lambda| of `a` and `b`).

    Returns
    -------
    list of str
        One line per difference.
    """
    if len(a) != len(b):
        return [f"{len(a)} modes against {len(b)}"]
    tol = rel * max((_modulus(m) for m in (*a, *b)), default=0.0)
    out = []
    for x, y in zip(sorted(a, key=lambda m: m[1]), sorted(b, key=lambda m: m[1]), strict=True):
        if x[0] != y[0]:
            out.append(f"label {x[0]} against {y[0]} at {x[1]:.6g} Hz")
        if abs(x[1] - y[1]) * 2 * math.pi > tol or abs(x[2] - y[2]) > tol:
            out.append(f"{x[0]}: ({x[1]!r} Hz, {x[2]!r} 1/s) against ({y[1]!r}, {y[2]!r})")
        if abs(x[3] - y[3]) > tol / _modulus(x):
            out.append(f"{x[0]}: damping ratio {x[3]!r} against {y[3]!r}")
        tie = abs(x[2] - GROWTH_TOL * _modulus(x)) <= tol
        if len(x) > 4 and len(y) > 4 and x[4] != y[4] and not tie:
            out.append(f"{x[0]}: unstable {x[4]} against {y[4]}")
    return out


def same_probability(p: float | None, q: float | None, samples: int) -> bool:
    """P(squeak) of two paths: both None, or within `P_SAMPLES` of `samples` scatter samples."""
    if p is None or q is None:
        return p is q
    return abs(p - q) <= P_SAMPLES / samples + 1e-15


def prediction_differences(a, b, samples: int, rel: float = REL) -> list[str]:
    """What differs between two `Prediction`s beyond rounding (empty: the same prediction);
    `samples` is the number of scatter samples behind P(squeak)."""
    out = []
    for name in ("speed_rad_s", "load_n", "formulation", "validity", "reason"):
        if getattr(a, name) != getattr(b, name):
            out.append(f"{name} {getattr(a, name)!r} against {getattr(b, name)!r}")
    out += mode_differences(a.modes, b.modes, rel)
    da, db = a.divergence_rates, b.divergence_rates
    tol = rel * max((_modulus(m) for m in (*a.modes, *b.modes)), default=0.0)
    if len(da) != len(db) or any(
        abs(x - y) > max(tol, rel * x) for x, y in zip(da, db, strict=True)
    ):
        out.append(f"divergence rates {da} against {db}")
    if not same_probability(a.probability, b.probability, samples):
        out.append(f"P(squeak) {a.probability} against {b.probability}")
    return out
