# SPDX-License-Identifier: Apache-2.0
"""Root finding on a grid: sign changes of a quantity between grid points refined by
Chandrupatla's method, batched over all brackets (`find_roots`), the stability boundaries
(`refine_crossings`) and the unstable intervals they close, level crossings refined by
bisection (`refine_level_crossings`) or interpolated on the grid (`level_crossings`). Pure
numpy: the quantity is any batched function."""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from numpy.typing import ArrayLike

ROOT_RTOL = 1e-9  # boundaries, crossings: tolerance relative to the grid span


def level_crossings(x: np.ndarray, values: np.ndarray, level: float) -> list[float]:
    """Where `values` on the grid `x` cross `level`, interpolated linearly between
    consecutive valid grid points (NaN: not valid, no crossing next to it).

    Parameters
    ----------
    x : numpy.ndarray
        Grid along an axis, in the axis unit.
    values : numpy.ndarray
        A quantity on the grid, e.g. P(squeak); NaN where invalid.
    level : float
        The level, in the quantity's unit.

    Returns
    -------
    list of float
        The crossings in the axis unit, in grid order.
    """
    out = []
    for i in range(len(x) - 1):
        a, b = values[i], values[i + 1]
        if np.isfinite(a) and np.isfinite(b) and (a > level) != (b > level):
            out.append(float(x[i] + (level - a) / (b - a) * (x[i + 1] - x[i])))
    return out


def find_roots(
    f: Callable[[np.ndarray, np.ndarray], np.ndarray],
    lo: np.ndarray,
    hi: np.ndarray,
    f_lo: np.ndarray,
    f_hi: np.ndarray,
    xtol: ArrayLike,
) -> np.ndarray:
    """Roots of many bracketed scalar functions at once (Chandrupatla's method: inverse
    quadratic interpolation, bisection when it would be slow), one batched call of `f` per
    iteration over the brackets not yet converged.

    Parameters
    ----------
    f : callable
        ``f(x, cells)``: the functions of the brackets `cells` (indices) at `x`, both arrays
        of the same length; NaN where a function is undefined.
    lo : numpy.ndarray
        Lower ends of the brackets, in the unit of x.
    hi : numpy.ndarray
        Upper ends of the brackets, in the unit of x.
    f_lo : numpy.ndarray
        The functions at `lo`; of the opposite sign to `f_hi`, or zero (that end is the root).
    f_hi : numpy.ndarray
        The functions at `hi`.
    xtol : numpy.ndarray
        Absolute tolerance per bracket, in the unit of x: a bracket ends narrower than
        ``xtol + 4 eps |x|``.

    Returns
    -------
    numpy.ndarray
        Per bracket the root of the straight line through the ends of the last bracket
        (within it: far closer to the root than its width when f is smooth); where an end is
        a root, or `f` is NaN inside the bracket, the end with the smaller ``|f|``.
    """
    x1, x2, f1, f2 = (np.array(v, float) for v in (lo, hi, f_lo, f_hi))
    x3, f3 = x2.copy(), f2.copy()
    half_tol = 0.5 * np.broadcast_to(np.asarray(xtol, float), x1.shape)
    eps2 = 2 * np.finfo(float).eps
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(f1 != f2, f1 / (f1 - f2), 0.5)  # regula falsi first
        tl = np.zeros_like(x1)
        active = np.flatnonzero(np.sign(f1) * np.sign(f2) < 0)
        while active.size:
            c = active
            step = np.clip(t[c], tl[c], 1 - tl[c])
            xt = x1[c] + step * (x2[c] - x1[c])
            ft = f(xt, c)
            bad = c[~np.isfinite(ft)]  # undefined inside: stop at the best end
            better = np.abs(f1[bad]) <= np.abs(f2[bad])
            x1[bad] = x2[bad] = np.where(better, x1[bad], x2[bad])
            f1[bad] = f2[bad] = np.where(better, f1[bad], f2[bad])
            ok = np.isfinite(ft)
            c, xt, ft = c[ok], xt[ok], ft[ok]
            same = np.sign(ft) == np.sign(f1[c])
            x3[c], f3[c] = np.where(same, x1[c], x2[c]), np.where(same, f1[c], f2[c])
            x2[c], f2[c] = np.where(same, x2[c], x1[c]), np.where(same, f2[c], f1[c])
            x1[c], f1[c] = xt, ft
            best = np.where(np.abs(f1[c]) < np.abs(f2[c]), x1[c], x2[c])
            tl[c] = (eps2 * np.abs(best) + half_tol[c]) / np.abs(x2[c] - x1[c])
            c = c[(f1[c] != 0) & (tl[c] <= 0.5)]
            xi = (x1[c] - x2[c]) / (x3[c] - x2[c])
            phi = (f1[c] - f2[c]) / (f3[c] - f2[c])
            t_iqi = f1[c] / (f2[c] - f1[c]) * f3[c] / (f2[c] - f3[c]) + (x3[c] - x1[c]) / (
                x2[c] - x1[c]
            ) * f1[c] / (f3[c] - f1[c]) * f2[c] / (f3[c] - f2[c])
            use = (phi**2 < xi) & ((1 - phi) ** 2 < 1 - xi) & np.isfinite(t_iqi)
            t[c] = np.where(use, t_iqi, 0.5)
            active = c
        inside = x1 + np.where(f1 != f2, f1 / (f1 - f2), 0.0) * (x2 - x1)
    ends = np.where(np.abs(f1) <= np.abs(f2), x1, x2)
    return np.where(np.sign(f1) * np.sign(f2) < 0, inside, ends)


def _crossings(g: np.ndarray) -> np.ndarray:
    """Indices i (along the last axis, with the leading indices first) where g changes sign
    between i and i + 1, both finite; in row-major order."""
    a, b = g[..., :-1], g[..., 1:]
    return np.argwhere(np.isfinite(a) & np.isfinite(b) & ((a > 0) != (b > 0)))


def refine_crossings(
    f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, g: np.ndarray, rtol: float = ROOT_RTOL
) -> list[float]:
    """Roots of f between consecutive grid points where g changes sign (both valid), all
    refined together (`find_roots`: one call of f per iteration).

    Parameters
    ----------
    f : callable
        Growth rate [1/s] at an array of axis values (in the axis unit), of the same shape.
    x : numpy.ndarray
        Grid along the axis, in the axis unit.
    g : numpy.ndarray
        ``f`` on the grid [1/s]; NaN where invalid (no root is sought next to NaN).
    rtol : float, optional
        Root tolerance relative to the grid span (dimensionless).

    Returns
    -------
    list of float
        The refined roots (stability boundaries) in the axis unit, in grid order.
    """
    x, g = np.asarray(x, float), np.asarray(g, float)
    i = _crossings(g)[:, 0]
    return find_roots(
        lambda values, cells: f(values), x[i], x[i + 1], g[i], g[i + 1], _xtol(x, rtol)
    ).tolist()


def refine_level_crossings(
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    values: np.ndarray,
    levels: Iterable[float],
    rtol: float = ROOT_RTOL,
) -> dict[float, list[float]]:
    """Where a quantity reaches each level between grid points, refined by bisection, all
    levels and crossings together (`find_roots`: one call of f per iteration).

    A crossing of `level` is sought in every cell of the grid where ``values >= level`` holds
    at one end only (both ends valid). It is where ``f(x) >= level`` switches: the midpoint of
    the last bracket, narrower than ``rtol`` times the grid span, with ``f >= level`` at one
    end and ``f < level`` at the other. The quantity need not be continuous: P(squeak), a
    share of scatter samples, is a step function of the axis. Where it crosses the level more
    than once inside a cell, one of the switches is found.

    Parameters
    ----------
    f : callable
        The quantity at an array of axis values (in the axis unit), of the same shape; NaN
        where invalid.
    x : numpy.ndarray
        Grid along the axis, in the axis unit.
    values : numpy.ndarray
        ``f`` on the grid; NaN where invalid (no crossing is sought next to NaN).
    levels : iterable of float
        The levels, in the quantity's unit.
    rtol : float, optional
        Tolerance relative to the grid span (dimensionless).

    Returns
    -------
    dict of float to list of float
        Level -> its crossings in the axis unit, in grid order.
    """
    x, values, levels = np.asarray(x, float), np.asarray(values, float), list(levels)

    def reached(v: np.ndarray, level: ArrayLike) -> np.ndarray:
        """+1/2 where v >= level, -1/2 below: a sign change without a zero, so Chandrupatla's
        steps are bisections."""
        return np.where(np.isnan(v), np.nan, (v >= level) - 0.5)

    cells = [_crossings(reached(values, level))[:, 0] for level in levels]
    i = np.concatenate([np.zeros(0, int), *cells])
    at = np.repeat(np.asarray(levels, float), [len(c) for c in cells])  # level per bracket
    found = find_roots(
        lambda v, c: reached(f(v), at[c]),
        x[i],
        x[i + 1],
        reached(values[i], at),
        reached(values[i + 1], at),
        _xtol(x, rtol),
    )
    return {
        level: part.tolist()
        for level, part in zip(
            levels, np.split(found, np.cumsum([len(c) for c in cells])), strict=False
        )
    }


def _xtol(x: np.ndarray, rtol: float) -> float:
    """Absolute root tolerance on a grid: `rtol` times its span."""
    return rtol * float(np.ptp(x)) if len(x) > 1 else 0.0


def unstable_intervals(
    values: np.ndarray, growth: np.ndarray, boundaries: list[float]
) -> list[tuple[float, float]]:
    """Intervals of the axis with squeak, closed by refined boundaries or the grid ends.

    Parameters
    ----------
    values : numpy.ndarray
        Grid along the axis, in the axis unit.
    growth : numpy.ndarray
        Largest squeak growth rate on the grid [1/s]; NaN where invalid.
    boundaries : list of float
        Refined roots from `refine_crossings` on the same grid, in the axis unit.

    Returns
    -------
    list of tuple of float
        ``(start, end)`` of every unstable interval, in the axis unit.
    """
    bands, start, roots = [], None, iter(boundaries)
    for i, g in enumerate(growth):
        unstable = bool(np.isfinite(g) and g > 0)
        if unstable and start is None:
            start = next(roots) if i > 0 and np.isfinite(growth[i - 1]) else float(values[i])
        elif not unstable and start is not None:
            bands.append((start, next(roots) if np.isfinite(g) else float(values[i - 1])))
            start = None
    if start is not None:
        bands.append((start, float(values[-1])))
    return bands
