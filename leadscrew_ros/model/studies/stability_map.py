# SPDX-License-Identifier: Apache-2.0
"""Stability maps (`stability_map`): the largest squeak growth rate on a 2-D grid and its
zero contour refined along the rows and columns, all the sign changes in one batched
`roots.find_roots`."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..physics.parameters import ParameterError
from ..squeak_model import SqueakModel
from .fields import (
    PROBABILITY_LEVELS,
    GrowthField,
    _at_cells,
    _fixed,
    _growth_rate,
    _levels_key,
    check_axis,
    check_axis_values,
    growth_field,
    probability_field,
)
from .roots import ROOT_RTOL, _crossings, _xtol, find_roots, level_crossings
from .work import map_work


def _refined_boundary(
    model: SqueakModel,
    fixed: dict[str, float],
    x_axis: tuple[str, np.ndarray],
    y_axis: tuple[str, np.ndarray],
    g: np.ndarray,
) -> list[tuple[float, float]]:
    """Zero contour of the growth rate `g` (len(y) x len(x)) refined along the rows, then the
    columns, all in one `find_roots`: ``(x, y)`` points in the axis units, in grid order."""
    (xa, x), (ya, y) = x_axis, y_axis
    rows, cols = _crossings(g), _crossings(g.T)  # (j, i), (i, j)
    coords = np.concatenate(
        [
            np.column_stack([x[rows[:, 1]], y[rows[:, 0]]]),
            np.column_stack([x[cols[:, 0]], y[cols[:, 1]]]),
        ]
    )
    vary = np.repeat([0, 1], [len(rows), len(cols)])
    j, i = rows.T
    ci, cj = cols.T
    roots = find_roots(
        _at_cells(_growth_rate, model, fixed, (xa, ya), coords, vary),
        np.concatenate([x[i], y[cj]]),
        np.concatenate([x[i + 1], y[cj + 1]]),
        np.concatenate([g[j, i], g[cj, ci]]),
        np.concatenate([g[j, i + 1], g[cj + 1, ci]]),
        np.repeat([_xtol(x, ROOT_RTOL), _xtol(y, ROOT_RTOL)], [len(rows), len(cols)]),
    )
    return [
        (r, yv) if k == 0 else (xv, r)
        for k, r, xv, yv in zip(
            vary.tolist(), roots.tolist(), coords[:, 0].tolist(), coords[:, 1].tolist(), strict=True
        )
    ]


@dataclass(frozen=True)
class MapResult:
    """Squeak growth rate on a 2-D grid with its refined zero contour (from `stability_map`).

    Attributes
    ----------
    x_axis : str
        Quantity along x: 'speed_rad_s', 'load_n' or a numeric `ScrewParameters` field.
    x : numpy.ndarray
        Grid along x, in the x-axis unit.
    y_axis : str
        Quantity along y, as `x_axis`.
    y : numpy.ndarray
        Grid along y, in the y-axis unit.
    fixed : dict[str, float]
        The operating point held fixed: 'speed_rad_s' [rad/s] and/or 'load_n' [N] (the
        mapped ones left out).
    field : GrowthField
        Arrays of shape (len(y), len(x)).
    boundary : list of tuple of float
        ``(x, y)`` points on the stability boundary, refined along rows and columns, in the
        axis units.
    probability : numpy.ndarray or None
        P(squeak) on the grid, shape (len(y), len(x)), NaN where invalid; None when not
        computed.
    probability_stderr : numpy.ndarray or None
        Its standard error (NaN where not sampled); None when not computed.
    """

    x_axis: str
    x: np.ndarray
    y_axis: str
    y: np.ndarray
    fixed: dict[str, float]
    field: GrowthField
    boundary: list[tuple[float, float]]
    probability: np.ndarray | None = None
    probability_stderr: np.ndarray | None = None

    def probability_contours(
        self, levels: Iterable[float] = PROBABILITY_LEVELS
    ) -> dict[float, list[tuple[float, float]]]:
        """Points of the iso-P(squeak) contours.

        Parameters
        ----------
        levels : iterable of float
            Probabilities in [0, 1]; default 1, 10, 50 and 90 %.

        Returns
        -------
        dict of float to list of tuple of float
            Level -> ``(x, y)`` points (axis units) where P crosses it, interpolated linearly
            along the rows, then the columns of the grid; empty lists without `probability`.
        """
        out: dict[float, list[tuple[float, float]]] = {}
        for level in levels:
            points: list[tuple[float, float]] = []
            if self.probability is not None:
                for j, yv in enumerate(self.y.tolist()):
                    points += [(c, yv) for c in level_crossings(self.x, self.probability[j], level)]
                for i, xv in enumerate(self.x.tolist()):
                    points += [
                        (xv, c) for c in level_crossings(self.y, self.probability[:, i], level)
                    ]
            out[level] = points
        return out

    def as_dict(self) -> dict:
        """JSON-ready result.

        Returns
        -------
        dict
            Axes, fixed point, growth rate [1/s] (None where invalid), unstable and
            divergence masks (row per y value) and the boundary points; with the probability,
            P(squeak) and its standard error on the grid (None where invalid or not sampled)
            and ``probability_contours``: level ('0.01', '0.1', '0.5', '0.9') -> ``[x, y]``
            points where P crosses it.
        """
        g = self.field.max_growth_rate
        extra = (
            {}
            if self.probability is None
            else {
                "probability": _grid_list(self.probability),
                "probability_stderr": _grid_list(np.asarray(self.probability_stderr)),
                "probability_contours": {
                    _levels_key(k): [list(p) for p in v]
                    for k, v in self.probability_contours().items()
                },
            }
        )
        return {
            "x_axis": self.x_axis,
            "x": self.x.tolist(),
            "y_axis": self.y_axis,
            "y": self.y.tolist(),
            "fixed": self.fixed,
            "max_growth_rate": _grid_list(g),
            "unstable": (np.nan_to_num(g, nan=-1.0) > 0).tolist(),
            "divergence": (np.nan_to_num(self.field.divergence_rate) > 0).tolist(),
            "boundary": [list(p) for p in self.boundary],
            **extra,
        }


def _grid_list(a: np.ndarray) -> list[list[float | None]]:
    """Rows of a grid as lists, None for NaN."""
    return [[None if math.isnan(v) else v for v in row] for row in a.tolist()]


def stability_map(
    model: SqueakModel,
    x_axis: str,
    x: ArrayLike,
    y_axis: str,
    y: ArrayLike,
    speed_rad_s: float | None = None,
    load_n: float | None = None,
    progress: Callable[[int], None] | None = None,
    probability: bool = False,
) -> MapResult:
    """Largest squeak growth rate on a 2-D grid and its zero contour refined along rows and
    columns by root finding.

    Parameters
    ----------
    model : SqueakModel
        The model; its parameters hold except the mapped ones.
    x_axis : str
        Quantity along x: 'speed_rad_s', 'load_n' or a numeric `ScrewParameters` field.
    x : array_like
        Grid along x, in the x-axis unit.
    y_axis : str
        Quantity along y (different from `x_axis`).
    y : array_like
        Grid along y, in the y-axis unit.
    speed_rad_s : float, optional
        Fixed screw speed [rad/s] when not an axis; `REFERENCE_SPEED_RAD_S` (20 rad/s) when
        None.
    load_n : float, optional
        Fixed axial load [N] when not an axis; `params.axial_load_n` when None.
    progress : callable, optional
        Called with the number of grid points just finished (twice per point with
        `probability`).
    probability : bool
        Also P(squeak) on the grid (`probability_field`: a prediction per point).

    Returns
    -------
    MapResult
        The growth field on the grid and the refined boundary points (and P).

    Raises
    ------
    ParameterError
        An axis is not sweepable, or the two axes are the same.
    WorkSizeError
        Too many points or too much memory, before any work.

    Examples
    --------
    Table 1 over load and speed: the boundary on the 200 N column is the band of `sweep`.

    >>> import numpy as np
    >>> from leadscrew_ros.model import SqueakModel
    >>> from leadscrew_ros.model.studies.stability_map import stability_map
    >>> m = stability_map(SqueakModel(), "load_n", [100.0, 200.0, 300.0], "speed_rad_s",
    ...                   np.geomspace(0.5, 200.0, 30))
    >>> m.field.max_growth_rate.shape
    (30, 3)
    >>> sorted(round(y, 3) for x, y in m.boundary if x == 200.0)
    [0.809, 55.207]
    >>> bool(m.field.max_growth_rate[10, 1] > 0), m.fixed
    (True, {})
    """
    for a in (x_axis, y_axis):
        check_axis(a)
    if x_axis == y_axis:
        raise ParameterError("map axes must differ")
    x, y = np.asarray(x, float), np.asarray(y, float)
    check_axis_values(x_axis, x)
    check_axis_values(y_axis, y)
    map_work(model, x_axis, x, y_axis, y).check()
    fixed = _fixed(model, speed_rad_s, load_n)
    for a in (x_axis, y_axis):
        fixed.pop(a, None)
    grid: dict[str, Any] = dict(fixed, **{x_axis: x[None, :], y_axis: y[:, None]})
    speed, load = grid.pop("speed_rad_s"), grid.pop("load_n")
    gf = growth_field(model, speed, load, progress=progress, **grid)
    g = gf.max_growth_rate
    boundary = _refined_boundary(model, fixed, (x_axis, x), (y_axis, y), g)
    prob = (
        probability_field(model, speed, load, progress=progress, **grid)
        if probability
        else (None, None)
    )
    return MapResult(x_axis, x, y_axis, y, fixed, gf, boundary, *prob)
