# SPDX-License-Identifier: Apache-2.0
"""Quantities on many operating points at once: the largest squeak growth rate
(`growth_field`) and P(squeak) (`probability_field`), batched over points.

An axis is the speed (`speed_rad_s`), the load (`load_n`) or any numeric `ScrewParameters`
field. Points that share all parameter values are solved in one batched eigenproblem; only a
change of a geometry field (R, z_o, beta, ...) re-integrates the contact.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..physics.display import exact
from ..physics.parameters import ParameterError, field_info, field_names
from ..physics.stability import max_divergence_rate, max_growth_rate
from ..squeak_model import SqueakModel, Validity
from .work import _chunk_points

OPERATING_AXES = ("speed_rad_s", "load_n")
REFERENCE_SPEED_RAD_S = 20.0  # fixed speed of the paper's Figs. 9 and 10
PROBABILITY_LEVELS = (0.01, 0.1, 0.5, 0.9)  # iso-P(squeak) contours and crossings


def axis_names() -> list[str]:
    """Names a sweep or map can vary: the operating axes, then numeric parameters."""
    return list(OPERATING_AXES) + [
        n for n in field_names() if field_info(n)["type"] in ("float", "int")
    ]


def check_axis(name: str) -> None:
    """Raise ParameterError unless `name` is one of `axis_names()`."""
    if name not in axis_names():
        raise ParameterError(f"cannot sweep {name!r}; choose one of {', '.join(axis_names())}")


def integer_axis(name: str) -> bool:
    """A sweep axis of whole numbers: an int field (n_bending, n_torsion)."""
    return name not in OPERATING_AXES and field_info(name)["type"] == "int"


def check_axis_values(name: str, values: np.ndarray) -> None:
    """ParameterError if an integer axis has a value that is not a whole number (it would be
    rounded: a sweep of n_bending must not pretend to have computed n_bending = 2.5)."""
    if integer_axis(name):
        bad = values[values != np.round(values)]
        if bad.size:
            raise ParameterError(f"{name} takes whole numbers; got {exact(float(bad[0]))}")


@dataclass(frozen=True)
class GrowthField:
    """Largest squeak growth rate on a set of points; NaN where the model is not valid.

    All arrays have the shape of the broadcast points.

    Attributes
    ----------
    max_growth_rate : numpy.ndarray
        Largest Re(lambda) of the oscillatory modes [1/s] (> 0: squeak); NaN where invalid.
    valid : numpy.ndarray
        Boolean: the linearisation holds and the parameters are allowed at the point.
    peak_frequency_hz : numpy.ndarray
        Frequency of the most unstable oscillatory mode [Hz]; NaN where invalid.
    divergence_rate : numpy.ndarray
        Largest real eigenvalue > 0 (divergence, not squeak) [1/s]; 0 where none, NaN where
        invalid.
    """

    max_growth_rate: np.ndarray
    valid: np.ndarray
    peak_frequency_hz: np.ndarray
    divergence_rate: np.ndarray


def _point_models(
    model: SqueakModel, params: dict[str, np.ndarray], size: int
) -> Iterable[tuple[SqueakModel | None, np.ndarray]]:
    """Group flat point indices by their parameter values; None where the values are invalid."""
    if not params:
        yield model, np.arange(size)
        return
    names = list(params)
    uniq, inverse = np.unique(
        np.column_stack([params[n] for n in names]), axis=0, return_inverse=True
    )
    for k, row in enumerate(uniq):
        idx = np.flatnonzero(inverse.ravel() == k)
        try:
            yield (
                model.with_params(**{n: _native(n, v) for n, v in zip(names, row, strict=True)}),
                idx,
            )
        except ParameterError:
            yield None, idx


def _native(name: str, value: float) -> float | int:
    return int(round(value)) if field_info(name)["type"] == "int" else float(value)


def _flat_points(speed_rad_s: ArrayLike, load_n: ArrayLike, params: dict) -> tuple:
    """The broadcast of speeds, loads and parameter arrays: its shape and each flattened
    (parameter columns in the order of `params`); ParameterError if a value is not finite."""
    arrays = np.broadcast_arrays(
        np.asarray(speed_rad_s, float),
        np.asarray(load_n, float),
        *(np.asarray(v, float) for v in params.values()),
    )
    flat = [a.ravel() for a in arrays]
    if not all(np.all(np.isfinite(a)) for a in flat):
        raise ParameterError("sweep values must be finite numbers")
    return arrays[0].shape, flat[0], flat[1], flat[2:]


def growth_field(
    model: SqueakModel,
    speed_rad_s: ArrayLike,
    load_n: ArrayLike,
    progress: Callable[[int], None] | None = None,
    **params: Any,
) -> GrowthField:
    """Largest squeak growth rate at every point of the broadcast of all given arrays.

    Points that share all parameter values are solved in one batched eigenproblem.

    Parameters
    ----------
    model : SqueakModel
        The model; its parameters hold wherever `params` does not override them.
    speed_rad_s : array_like
        Screw speeds [rad/s].
    load_n : array_like
        Axial loads [N].
    progress : callable, optional
        Called with the number of points just finished (invalid points at once).
    **params
        Numeric `ScrewParameters` fields by name, arrays in the field's unit; all arrays
        broadcast together.

    Returns
    -------
    GrowthField
        Growth rate, validity, peak frequency and divergence rate, of the broadcast shape.

    Raises
    ------
    ParameterError
        A value is not finite, or a name is not a `ScrewParameters` field.
    """
    shape, speeds, loads, columns = _flat_points(speed_rad_s, load_n, params)
    growth, freq, diverge = (np.full(speeds.size, np.nan) for _ in range(3))
    for sub, idx in _point_models(model, dict(zip(params, columns, strict=True)), speeds.size):
        ok = (
            idx[:0]
            if sub is None
            else idx[sub.validity_code(speeds[idx], loads[idx]) == Validity.OK]
        )
        if progress and ok.size < idx.size:
            progress(idx.size - ok.size)  # invalid points: done at once
        if sub is None or not ok.size:
            continue
        chunk = _chunk_points(2 * sub.geometry.n)
        for start in range(0, ok.size, chunk):
            part = ok[start : start + chunk]
            lam = np.linalg.eigvals(sub.geometry.state_matrices(speeds[part], loads[part]))
            growth[part] = max_growth_rate(lam)
            peak = np.argmax(np.where(lam.imag > 0, lam.real, -np.inf), axis=-1)
            freq[part] = np.take_along_axis(lam.imag, peak[:, None], -1)[:, 0] / (2 * math.pi)
            diverge[part] = max_divergence_rate(lam)
            if progress:
                progress(part.size)
    valid = np.isfinite(growth)
    return GrowthField(*(a.reshape(shape) for a in (growth, valid, freq, diverge)))


def probability_field(
    model: SqueakModel,
    speed_rad_s: ArrayLike,
    load_n: ArrayLike,
    progress: Callable[[int], None] | None = None,
    **params: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """P(squeak) (`Prediction.probability`: the fast estimator over the model's scatter) at
    every point of the broadcast of all given arrays.

    Parameters
    ----------
    model : SqueakModel
        The model and its scatter; its parameters hold wherever `params` does not override
        them.
    speed_rad_s : array_like
        Screw speeds [rad/s].
    load_n : array_like
        Axial loads [N].
    progress : callable, optional
        Called with the number of points just finished (invalid points at once).
    **params
        Numeric `ScrewParameters` fields by name, arrays in the field's unit; all arrays
        broadcast together.

    Returns
    -------
    probability, stderr : numpy.ndarray
        P in [0, 1] and its standard error, of the broadcast shape; NaN where the model is not
        valid (stderr also NaN where not sampled, i.e. without scatter).

    Raises
    ------
    ParameterError
        A value is not finite, or a name is not a `ScrewParameters` field.
    """
    shape, speeds, loads, columns = _flat_points(speed_rad_s, load_n, params)
    prob, stderr = np.full(speeds.size, np.nan), np.full(speeds.size, np.nan)
    for sub, idx in _point_models(model, dict(zip(params, columns, strict=True)), speeds.size):
        if sub is None:  # parameters rejected: NaN
            if progress:
                progress(idx.size)
            continue
        chunk = _chunk_points(2 * sub.geometry.n)
        for start in range(0, idx.size, chunk):
            part = idx[start : start + chunk]
            for i, p in zip(
                part.tolist(), sub.predict_many(speeds[part], loads[part]), strict=True
            ):
                if p.valid:
                    prob[i] = p.probability
                    stderr[i] = np.nan if p.probability_stderr is None else p.probability_stderr
            if progress:
                progress(part.size)
    return prob.reshape(shape), stderr.reshape(shape)


def _levels_key(level: float) -> str:
    """JSON key of a probability level: 0.1 -> '0.1'."""
    return f"{level:g}"


def _growth_rate(
    model: SqueakModel, speed_rad_s: ArrayLike, load_n: ArrayLike, **params: Any
) -> np.ndarray:
    """`growth_field`'s largest squeak growth rate alone [1/s] (NaN where invalid)."""
    return growth_field(model, speed_rad_s, load_n, **params).max_growth_rate


def _probability(
    model: SqueakModel, speed_rad_s: ArrayLike, load_n: ArrayLike, **params: Any
) -> np.ndarray:
    """`probability_field`'s P(squeak) alone (NaN where invalid)."""
    return probability_field(model, speed_rad_s, load_n, **params)[0]


Quantity = Callable[..., np.ndarray]  # (model, speed_rad_s, load_n, **params) -> values


def _at_cells(
    quantity: Quantity,
    model: SqueakModel,
    fixed: dict[str, float],
    axes: tuple[str, ...],
    coords: np.ndarray,
    vary: np.ndarray,
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """`quantity` (`_growth_rate`, `_probability`) of cells as one batched function for
    `find_roots`: cell c sits at `coords[c]` on `axes`, its axis `vary[c]` set to the trial
    value."""

    def f(values: np.ndarray, cells: np.ndarray) -> np.ndarray:
        at = coords[cells].copy()
        at[np.arange(cells.size), vary[cells]] = values
        point = dict(fixed, **{a: at[:, k] for k, a in enumerate(axes)})
        speed, load = point.pop("speed_rad_s"), point.pop("load_n")
        return quantity(model, speed, load, **point)

    return f


def _along(
    quantity: Quantity, model: SqueakModel, fixed: dict[str, float], axis: str
) -> Callable[[np.ndarray], np.ndarray]:
    """`quantity` at an array of values of `axis`, everything else at `fixed`."""
    f = _at_cells(quantity, model, fixed, (axis,), np.zeros((1, 1)), np.zeros(1, int))
    return lambda values: f(values, np.zeros(values.size, int))  # one cell, moved


def _fixed(model: SqueakModel, speed_rad_s: float | None, load_n: float | None) -> dict[str, float]:
    return {
        "speed_rad_s": float(REFERENCE_SPEED_RAD_S if speed_rad_s is None else speed_rad_s),
        "load_n": float(model.params.axial_load_n if load_n is None else load_n),
    }
