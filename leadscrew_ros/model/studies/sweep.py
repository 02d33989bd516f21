# SPDX-License-Identifier: Apache-2.0
"""Predictions along one axis (`sweep`), batched, with the stability boundaries refined by
root finding on the largest squeak growth rate (`roots.refine_crossings`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from ..physics.parameters import ParameterError, field_info
from ..squeak_model import Prediction, SqueakModel, Validity
from .fields import (OPERATING_AXES, PROBABILITY_LEVELS, _fixed, _growth_at, _levels_key, _native,
                     check_axis)
from .roots import level_crossings, refine_crossings, unstable_intervals
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
    """

    axis: str
    values: np.ndarray
    fixed: dict[str, float]
    predictions: list[Prediction]
    boundaries: list[float]
    unstable_bands: list[tuple[float, float]] = field(default_factory=list)

    @property
    def max_growth_rate(self) -> np.ndarray:
        """Largest squeak growth rate per value [1/s]; NaN where not valid."""
        return np.array([p.max_growth_rate if p.valid else np.nan for p in self.predictions])

    @property
    def probability(self) -> np.ndarray:
        """P(squeak) per value (`Prediction.probability`); NaN where not valid."""
        return np.array([p.probability if p.valid else np.nan for p in self.predictions])

    def probability_crossings(self, levels: Iterable[float] = PROBABILITY_LEVELS
                              ) -> dict[float, list[float]]:
        """Where P(squeak) crosses each level along the axis (`level_crossings`).

        Parameters
        ----------
        levels : iterable of float
            Probabilities in [0, 1]; default 1, 10, 50 and 90 %.

        Returns
        -------
        dict of float to list of float
            Level -> axis values of its crossings (linear between grid points), in the axis
            unit.
        """
        return {level: level_crossings(self.values, self.probability, level)
                for level in levels}

    def as_dict(self) -> dict:
        """JSON-ready result.

        Returns
        -------
        dict
            Axis values, validity, growth rates [1/s], P(squeak) and its standard error,
            squeak modes and frequencies [Hz], boundaries and bands (keyed with the axis unit,
            e.g. ``unstable_bands_rad_s``), and where P crosses 1, 10, 50 and 90 %
            (``probability_crossings``, keyed '0.01', ...).
        """
        return {
            "axis": self.axis, self.axis: self.values.tolist(), "fixed": self.fixed,
            "valid": [p.valid for p in self.predictions],
            "max_growth_rate": [None if math.isnan(g) else g for g in self.max_growth_rate],
            "probability": [p.probability for p in self.predictions],
            "probability_stderr": [p.probability_stderr for p in self.predictions],
            "probability_crossings": {_levels_key(k): v
                                      for k, v in self.probability_crossings().items()},
            "unstable_modes": [[m.label for m in p.squeak_modes] for p in self.predictions],
            "unstable_frequencies_hz": [p.unstable_frequencies_hz for p in self.predictions],
            "stability_boundaries": self.boundaries,
            f"unstable_bands_{_unit_suffix(self.axis)}": [list(b) for b in self.unstable_bands],
        }


def _unit_suffix(axis: str) -> str:
    """`speed_rad_s` -> `rad_s`, `load_n` -> `n`, `radius_m` -> `m` (unit part of the name)."""
    units = {"speed_rad_s": "rad_s", "load_n": "n"}
    if axis in units:
        return units[axis]
    unit = field_info(axis)["unit"] or "1"
    return unit.replace("/", "_").replace("^", "").replace(" ", "") if unit != "1" else "1"


def sweep(model: SqueakModel, axis: str, values, speed_rad_s: float | None = None,
          load_n: float | None = None, progress: Callable[[int], None] | None = None
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
        Predictions, refined boundaries and unstable bands along the axis.

    Raises
    ------
    ParameterError
        `axis` is not sweepable.
    WorkSizeError
        Too many points or too much memory, before any work.
    """
    check_axis(axis)
    values = np.asarray(values, float)
    sweep_work(model, axis, values).check()
    fixed = _fixed(model, speed_rad_s, load_n)
    fixed.pop(axis, None)
    if axis in OPERATING_AXES:
        point = dict(fixed, **{axis: values})
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
                predictions.append(Prediction(fixed["speed_rad_s"], fixed["load_n"],
                                              model.params.formulation,
                                              Validity.PARAMETERS_REJECTED, str(exc)))
                continue
            predictions.append(sub.predict(fixed["speed_rad_s"], fixed["load_n"]))
    growth = np.array([p.max_growth_rate if p.valid else np.nan for p in predictions])
    f = _growth_at(model, fixed, (axis,), np.zeros((1, 1)), np.zeros(1, int))  # one cell
    boundaries = refine_crossings(lambda v: f(v, np.zeros(v.size, int)), values, growth)
    return SweepResult(axis, values, fixed, predictions, boundaries,
                       unstable_intervals(values, growth, boundaries))


