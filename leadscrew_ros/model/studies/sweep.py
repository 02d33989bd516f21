# SPDX-License-Identifier: Apache-2.0
"""Predictions along one axis (`sweep`), batched, with what is read off them refined between
the grid points: the stability boundaries by root finding on the largest squeak growth rate
(`roots.refine_crossings`), the largest growth rate by bounded scalar maximisation
(`peak_growth`), the P(squeak) crossings by bisection (`probability_crossings`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize_scalar

from ..physics.parameters import ParameterError, field_info
from ..squeak_model import Prediction, SqueakModel, Validity
from .fields import (
    OPERATING_AXES,
    PROBABILITY_LEVELS,
    _along,
    _fixed,
    _growth_rate,
    _levels_key,
    _native,
    _probability,
    check_axis,
    check_axis_values,
    integer_axis,
)
from .roots import ROOT_RTOL, _xtol, refine_crossings, refine_level_crossings, unstable_intervals
from .work import _chunk_points, sweep_work


@dataclass(frozen=True)
class SweepResult:
    """Predictions along one axis with refined stability boundaries (from `sweep`).

    Attributes
    ----------
    axis : str
        Swept quantity: 'speed_rad_s', 'load_n' or a numeric `ScrewParameters` field.
    values : numpy.ndarray
        Axis values, in the axis unit (rad/s, N or the field's unit).
    fixed : dict[str, float]
        The operating point held fixed: 'speed_rad_s' [rad/s] and/or 'load_n' [N] (the
        swept one left out).
    predictions : list of Prediction
        One prediction per value.
    boundaries : list of float
        Stability boundaries on the axis refined by root finding, in the axis unit.
    unstable_bands : list of tuple of float
        ``(start, end)`` intervals with squeak, in the axis unit; each end is a refined
        boundary or, at the edge of validity or of the grid, a grid point.
    peak_value : float
        Where the largest squeak growth rate along the axis is (`peak_growth`: refined between
        the grid neighbours of the best grid point), in the axis unit; NaN if no value is
        valid.
    peak_growth_rate : float
        That largest growth rate [1/s]; NaN if no value is valid.
    probability_crossings : dict of float to list of float
        Level (1, 10, 50 and 90 %) -> where P(squeak) reaches it along the axis, in the axis
        unit, in grid order (`probability_crossings`: the switch of P >= level, bisected to
        `ROOT_RTOL` of the grid span).
    """

    axis: str
    values: np.ndarray
    fixed: dict[str, float]
    predictions: list[Prediction]
    boundaries: list[float]
    unstable_bands: list[tuple[float, float]]
    peak_value: float
    peak_growth_rate: float
    probability_crossings: dict[float, list[float]]

    @property
    def max_growth_rate(self) -> np.ndarray:
        """Largest squeak growth rate per value [1/s]; NaN where not valid."""
        return _per_value(self.predictions, "max_growth_rate")

    @property
    def probability(self) -> np.ndarray:
        """P(squeak) per value (`Prediction.probability`); NaN where not valid."""
        return _per_value(self.predictions, "probability")

    def as_dict(self) -> dict:
        """JSON-ready result.

        Returns
        -------
        dict
            Axis values, validity, growth rates [1/s], P(squeak) and its standard error,
            squeak modes and frequencies [Hz], boundaries and bands (keyed with the axis unit,
            e.g. ``unstable_bands_rad_s``), the refined largest growth rate
            (``peak_growth_rate`` [1/s] at ``peak_<axis>``, e.g. ``peak_speed_rad_s``; None if
            no value is valid) and where P reaches 1, 10, 50 and 90 %
            (``probability_crossings``, keyed '0.01', ...).
        """
        return {
            "axis": self.axis,
            self.axis: self.values.tolist(),
            "fixed": self.fixed,
            "valid": [p.valid for p in self.predictions],
            "max_growth_rate": [None if math.isnan(g) else g for g in self.max_growth_rate],
            "probability": [p.probability for p in self.predictions],
            "probability_stderr": [p.probability_stderr for p in self.predictions],
            "probability_crossings": {
                _levels_key(k): v for k, v in self.probability_crossings.items()
            },
            "unstable_modes": [[m.label for m in p.squeak_modes] for p in self.predictions],
            "unstable_frequencies_hz": [p.unstable_frequencies_hz for p in self.predictions],
            "stability_boundaries": self.boundaries,
            f"unstable_bands_{_unit_suffix(self.axis)}": [list(b) for b in self.unstable_bands],
            f"peak_{self.axis}": None if math.isnan(self.peak_value) else self.peak_value,
            "peak_growth_rate": (
                None if math.isnan(self.peak_growth_rate) else self.peak_growth_rate
            ),
        }


def _per_value(predictions: list[Prediction], name: str) -> np.ndarray:
    """A number of each prediction; NaN where it is not valid."""
    return np.array([getattr(p, name) if p.valid else np.nan for p in predictions])


def _unit_suffix(axis: str) -> str:
    """`speed_rad_s` -> `rad_s`, `load_n` -> `n`, `radius_m` -> `m` (unit part of the name)."""
    units = {"speed_rad_s": "rad_s", "load_n": "n"}
    if axis in units:
        return units[axis]
    unit = field_info(axis)["unit"] or "1"
    return unit.replace("/", "_").replace("^", "").replace(" ", "") if unit != "1" else "1"


def sweep(
    model: SqueakModel,
    axis: str,
    values: ArrayLike,
    speed_rad_s: float | None = None,
    load_n: float | None = None,
    progress: Callable[[int], None] | None = None,
) -> SweepResult:
    """Predictions along one axis (batched), with refined stability boundaries and bands.

    Parameters
    ----------
    model : SqueakModel
        The model; its parameters hold except the swept one.
    axis : str
        'speed_rad_s', 'load_n' or a numeric `ScrewParameters` field.
    values : array_like
        Axis values, in the axis unit (rad/s, N or the field's unit).
    speed_rad_s : float, optional
        Fixed screw speed [rad/s] when not swept; `REFERENCE_SPEED_RAD_S` (20 rad/s) when
        None.
    load_n : float, optional
        Fixed axial load [N] when not swept; `params.axial_load_n` when None.
    progress : callable, optional
        Called with the number of points just finished.

    Returns
    -------
    SweepResult
        Predictions, refined boundaries, unstable bands, peak and P(squeak) crossings along
        the axis.

    Raises
    ------
    ParameterError
        `axis` is not sweepable.
    WorkSizeError
        Too many points or too much memory, before any work.

    Examples
    --------
    Table 1 at 200 N: squeak between 0.809 and 55.2 rad/s, refined from a grid 2 rad/s apart.

    >>> import numpy as np
    >>> from leadscrew_ros.model import SqueakModel
    >>> from leadscrew_ros.model.studies.sweep import sweep
    >>> result = sweep(SqueakModel(), "speed_rad_s", np.linspace(0.5, 200.0, 100))
    >>> [round(b, 3) for b in result.boundaries]
    [0.809, 55.207]
    >>> round(result.peak_growth_rate, 1), round(result.peak_value, 2)
    (144.5, 4.36)

    Over the default scatter P(squeak) rises to 50 % just above the lower boundary and falls
    through it just below the upper one:

    >>> {level: [round(v, 1) for v in found]
    ...  for level, found in result.probability_crossings.items()}
    {0.01: [65.5], 0.1: [0.6, 60.5], 0.5: [0.8, 54.6], 0.9: [1.4, 47.4]}
    """
    check_axis(axis)
    values = np.asarray(values, float)
    check_axis_values(axis, values)
    sweep_work(model, axis, values).check()
    fixed = _fixed(model, speed_rad_s, load_n)
    fixed.pop(axis, None)
    if axis in OPERATING_AXES:
        point: dict[str, Any] = dict(fixed, **{axis: values})
        speeds, loads = np.broadcast_arrays(point["speed_rad_s"], point["load_n"])
        predictions, chunk = [], _chunk_points(2 * model.geometry.n)
        for start in range(0, values.size, chunk):
            part = slice(start, start + chunk)
            predictions += model.predict_many(speeds[part], loads[part])
            if progress:
                progress(len(speeds[part]))
    else:
        predictions = []
        for v in values.tolist():
            if progress:
                progress(1)
            try:
                sub = model.with_params(**{axis: _native(axis, v)})
            except ParameterError as exc:
                predictions.append(
                    Prediction(
                        fixed["speed_rad_s"],
                        fixed["load_n"],
                        model.params.formulation,
                        Validity.PARAMETERS_REJECTED,
                        str(exc),
                    )
                )
                continue
            predictions.append(sub.predict(fixed["speed_rad_s"], fixed["load_n"]))
    growth = _per_value(predictions, "max_growth_rate")
    growth_along = _along(_growth_rate, model, fixed, axis)
    boundaries = refine_crossings(growth_along, values, growth)
    return SweepResult(
        axis,
        values,
        fixed,
        predictions,
        boundaries,
        unstable_intervals(values, growth, boundaries),
        *peak_growth(growth_along, values, growth, integer_axis(axis)),
        probability_crossings(model, fixed, axis, values, _per_value(predictions, "probability")),
    )


def peak_growth(
    f: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    g: np.ndarray,
    integer: bool = False,
    rtol: float = ROOT_RTOL,
) -> tuple[float, float]:
    """The largest growth rate along an axis and where it is: bounded scalar maximisation
    (Brent's method, `scipy.optimize.minimize_scalar`) between the grid neighbours of the
    largest grid value.

    Parameters
    ----------
    f : callable
        Growth rate [1/s] at an array of axis values (in the axis unit); NaN where invalid.
    x : numpy.ndarray
        Grid along the axis, in the axis unit.
    g : numpy.ndarray
        ``f`` on the grid [1/s]; NaN where invalid.
    integer : bool, optional
        The axis takes integers only (a mode count): the best grid point is the answer.
    rtol : float, optional
        Tolerance on the position relative to the grid span (dimensionless).

    Returns
    -------
    value, growth_rate : float
        Where the maximum is (axis unit) and its growth rate [1/s]; the best grid point if
        the search finds nothing larger there, NaN for both if no value is valid.
    """
    x, g = np.asarray(x, float), np.asarray(g, float)
    if not np.isfinite(g).any():
        return math.nan, math.nan
    i = int(np.nanargmax(g))
    best = float(x[i]), float(g[i])
    ends = x[max(i - 1, 0)], x[min(i + 1, len(x) - 1)]
    if integer or ends[0] == ends[1]:
        return best

    def loss(v: float) -> float:
        growth = f(np.array([v]))[0]
        return -growth if np.isfinite(growth) else math.inf  # invalid: never the peak

    found = minimize_scalar(
        loss, bounds=(min(ends), max(ends)), method="bounded", options={"xatol": _xtol(x, rtol)}
    )
    return (float(found.x), -float(found.fun)) if -found.fun > best[1] else best


def probability_crossings(
    model: SqueakModel,
    fixed: dict[str, float],
    axis: str,
    values: np.ndarray,
    probability: np.ndarray,
    levels: Iterable[float] = PROBABILITY_LEVELS,
) -> dict[float, list[float]]:
    """Where P(squeak) reaches each level along one axis, refined between the grid points.

    P (`Prediction.probability`) is a share of the scatter samples, a step function of the
    axis; a crossing is where ``P >= level`` switches between two grid points, bisected
    (`roots.refine_level_crossings`, all levels and crossings in one batch) to `ROOT_RTOL`
    times the grid span. Without scatter P is 0 or 1 and every crossing is a stability
    boundary.

    Parameters
    ----------
    model : SqueakModel
        The model and its scatter.
    fixed : dict[str, float]
        Everything held fixed: 'speed_rad_s' [rad/s] and 'load_n' [N] unless on the axis, and
        any parameter field by name.
    axis : str
        'speed_rad_s', 'load_n' or a numeric `ScrewParameters` field.
    values : numpy.ndarray
        Grid along the axis, in the axis unit.
    probability : numpy.ndarray
        P(squeak) on the grid; NaN where invalid.
    levels : iterable of float, optional
        Probabilities in [0, 1]; default 1, 10, 50 and 90 %.

    Returns
    -------
    dict of float to list of float
        Level -> its crossings in the axis unit, in grid order.
    """
    return refine_level_crossings(
        _along(_probability, model, fixed, axis), values, probability, levels
    )
