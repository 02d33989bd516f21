# SPDX-License-Identifier: Apache-2.0
"""Parameter sweeps and stability maps, batched over operating points, with stability
boundaries refined by root finding on the largest squeak growth rate, batched over all the
sign changes of the grid (`find_roots`).

An axis is the speed (`speed_rad_s`), the load (`load_n`) or any numeric `ScrewParameters`
field. Points that share all parameter values are solved in one batched eigenproblem; only a
change of a geometry field (R, z_o, beta, ...) re-integrates the contact.

Work is bounded up front (`Work.check`): a map or sweep may hold at most `MAX_POINTS` points
(fewer for models with more modes: an eigen-solve costs ~ state size cubed) and need at most
about `MAX_MEMORY_BYTES`; a larger request is a one-line `WorkSizeError` before any work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from .display import exact
from .parameters import ParameterError, field_info, field_names
from .predictor import Prediction, SqueakModel, Validity
from .stability import max_divergence_rate, max_growth_rate

OPERATING_AXES = ("speed_rad_s", "load_n")
REFERENCE_SPEED_RAD_S = 20.0        # fixed speed of the paper's Figs. 9 and 10
PROBABILITY_LEVELS = (0.01, 0.1, 0.5, 0.9)    # iso-P(squeak) contours and crossings
ROOT_RTOL = 1e-9                    # stability boundaries: tolerance relative to the grid span
_CHUNK = 1024                       # points per batched eigen-solve at the reference size
REFERENCE_STATE_SIZE = 36           # state size of the default model (6 bending + 6 torsion)
MAX_POINTS = 1_000_000              # points of one map or sweep at the reference state size
MAX_MEMORY_BYTES = 2_000_000_000   # estimated peak memory of one map or sweep
_MAP_POINT_BYTES = 250              # result arrays, JSON output (measured: ~40 held, ~200 JSON)
_PREDICTION_BYTES_PER_STATE = 85    # a sweep's Prediction per point (~3 kB at 36 states)


class WorkSizeError(ParameterError):
    """A map or sweep too large to compute (one line: size, limit, what to do)."""


@dataclass(frozen=True)
class Work:
    """The size of a batch of predictions, checked against the limits before it starts."""

    what: str                       # 'map of 100 x 200', 'sweep of 500 radius_m values'
    points: int
    state_size: int                 # 2 x (2 n_bending + n_torsion)
    bytes_per_point: float
    remedy: str = "use fewer points"

    @property
    def point_limit(self) -> int:
        """MAX_POINTS scaled by the cost of one eigen-solve relative to the default model."""
        scale = (REFERENCE_STATE_SIZE / self.state_size) ** 3
        return max(1, min(MAX_POINTS, int(MAX_POINTS * scale)))

    def memory_bytes(self, points: int | None = None) -> float:
        n = self.points if points is None else points
        chunk = _chunk_points(self.state_size) * self.state_size ** 2 * 16 * 4   # eig workspace
        return n * self.bytes_per_point + chunk

    def check(self) -> None:
        """Raise WorkSizeError if the work exceeds the point or memory limit."""
        limit = self.point_limit
        if self.points > limit:
            per_model = (f" for a model of {self.state_size} states ({exact(MAX_POINTS)} at "
                         f"the default {REFERENCE_STATE_SIZE})" if limit < MAX_POINTS else "")
            raise WorkSizeError(
                f"{self.what} = {exact(self.points)} points (about {_gb(self.memory_bytes())}) "
                f"exceeds the limit of {exact(limit)} points{per_model}; {self.remedy}")
        if self.memory_bytes() > MAX_MEMORY_BYTES:
            raise WorkSizeError(
                f"{self.what} = {exact(self.points)} points needs about "
                f"{_gb(self.memory_bytes())}, more than the limit of "
                f"{_gb(MAX_MEMORY_BYTES)}; {self.remedy}")


def _gb(n_bytes: float) -> str:
    return f"{exact(float(f'{n_bytes / 1e9:.2g}'))} GB"


def _chunk_points(state_size: int) -> int:
    """Points per batched eigen-solve: about the work (and Ctrl-C latency) of _CHUNK points of
    the default model, whatever the number of modes."""
    return max(1, _CHUNK * REFERENCE_STATE_SIZE ** 3 // state_size ** 3)


def _state_size(model: SqueakModel, axes: dict[str, np.ndarray]) -> int:
    """Largest state size on the axes: 2 (2 n_bending + n_torsion), the mode counts taken at
    their largest valid value where an axis varies them."""
    n = {}
    for name in ("n_bending", "n_torsion"):
        values = np.asarray(axes.get(name, getattr(model.params, name)), float)
        valid = values[(values >= field_info(name)["lo"]) & (values <= field_info(name)["hi"])]
        n[name] = int(round(valid.max())) if valid.size else getattr(model.params, name)
    return 2 * (2 * n["n_bending"] + n["n_torsion"])


def map_work(model: SqueakModel, x_axis: str, x: np.ndarray, y_axis: str, y: np.ndarray
             ) -> Work:
    """The work of `stability_map` on the grid x times y."""
    return Work(f"map of {len(x)} x {len(y)}", len(x) * len(y),
                _state_size(model, {x_axis: x, y_axis: y}), _MAP_POINT_BYTES)


def sweep_work(model: SqueakModel, axis: str, values: np.ndarray) -> Work:
    """The work of `sweep` along `values`."""
    size = _state_size(model, {axis: values})
    return Work(f"sweep of {len(values)} {axis} values", len(values), size,
                _PREDICTION_BYTES_PER_STATE * size)


def axis_names() -> list[str]:
    return list(OPERATING_AXES) + [n for n in field_names()
                                    if field_info(n)["type"] in ("float", "int")]


def check_axis(name: str) -> None:
    if name not in axis_names():
        raise ParameterError(f"cannot sweep {name!r}; choose one of {', '.join(axis_names())}")


def integer_axis(name: str) -> bool:
    """A sweep axis of whole numbers: an int field (n_bending, n_torsion)."""
    return name not in OPERATING_AXES and field_info(name)["type"] == "int"


def _check_axis_values(name: str, values: np.ndarray) -> None:
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


def _point_models(model: SqueakModel, params: dict[str, np.ndarray], size: int
                  ) -> Iterable[tuple[SqueakModel | None, np.ndarray]]:
    """Group flat point indices by their parameter values; None where the values are invalid."""
    if not params:
        yield model, np.arange(size)
        return
    names = list(params)
    uniq, inverse = np.unique(np.column_stack([params[n] for n in names]), axis=0,
                              return_inverse=True)
    for k, row in enumerate(uniq):
        idx = np.flatnonzero(inverse.ravel() == k)
        try:
            yield model.with_params(**{n: _native(n, v) for n, v in zip(names, row)}), idx
        except ParameterError:
            yield None, idx


def _native(name: str, value: float):
    return int(round(value)) if field_info(name)["type"] == "int" else float(value)


def _flat_points(speed_rad_s, load_n, params: dict) -> tuple:
    """The broadcast of speeds, loads and parameter arrays: its shape and each flattened
    (parameter columns in the order of `params`); ParameterError if a value is not finite."""
    arrays = np.broadcast_arrays(np.asarray(speed_rad_s, float), np.asarray(load_n, float),
                                 *(np.asarray(v, float) for v in params.values()))
    flat = [a.ravel() for a in arrays]
    if not all(np.all(np.isfinite(a)) for a in flat):
        raise ParameterError("sweep values must be finite numbers")
    return arrays[0].shape, flat[0], flat[1], flat[2:]


def growth_field(model: SqueakModel, speed_rad_s, load_n,
                 progress: Callable[[int], None] | None = None, **params) -> GrowthField:
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
    for sub, idx in _point_models(model, dict(zip(params, columns)), speeds.size):
        ok = idx[:0] if sub is None else \
            idx[sub.validity_code(speeds[idx], loads[idx]) == Validity.OK]
        if progress and ok.size < idx.size:
            progress(idx.size - ok.size)                 # invalid points: done at once
        if not ok.size:
            continue
        chunk = _chunk_points(2 * sub.geometry.n)
        for start in range(0, ok.size, chunk):
            part = ok[start:start + chunk]
            lam = np.linalg.eigvals(sub.geometry.state_matrices(speeds[part], loads[part]))
            growth[part] = max_growth_rate(lam)
            peak = np.argmax(np.where(lam.imag > 0, lam.real, -np.inf), axis=-1)
            freq[part] = np.take_along_axis(lam.imag, peak[:, None], -1)[:, 0] / (2 * math.pi)
            diverge[part] = max_divergence_rate(lam)
            if progress:
                progress(part.size)
    valid = np.isfinite(growth)
    return GrowthField(*(a.reshape(shape) for a in (growth, valid, freq, diverge)))


def probability_field(model: SqueakModel, speed_rad_s, load_n,
                      progress: Callable[[int], None] | None = None, **params
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
    for sub, idx in _point_models(model, dict(zip(params, columns)), speeds.size):
        if sub is None:                                  # parameters rejected: NaN
            if progress:
                progress(idx.size)
            continue
        chunk = _chunk_points(2 * sub.geometry.n)
        for start in range(0, idx.size, chunk):
            part = idx[start:start + chunk]
            for i, p in zip(part.tolist(), sub.predict_many(speeds[part], loads[part])):
                if p.valid:
                    prob[i] = p.probability
                    stderr[i] = np.nan if p.probability_stderr is None else p.probability_stderr
            if progress:
                progress(part.size)
    return prob.reshape(shape), stderr.reshape(shape)


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


def _levels_key(level: float) -> str:
    """JSON key of a probability level: 0.1 -> '0.1'."""
    return f"{level:g}"


def _growth_at(model: SqueakModel, fixed: dict[str, float], axes: tuple[str, ...],
               coords: np.ndarray, vary: np.ndarray
               ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Growth rate [1/s] of cells as one batched function for `find_roots`: cell c sits at
    `coords[c]` on `axes`, its axis `vary[c]` set to the trial value."""
    def f(values: np.ndarray, cells: np.ndarray) -> np.ndarray:
        at = coords[cells].copy()
        at[np.arange(cells.size), vary[cells]] = values
        point = dict(fixed, **{a: at[:, k] for k, a in enumerate(axes)})
        speed, load = point.pop("speed_rad_s"), point.pop("load_n")
        return growth_field(model, speed, load, **point).max_growth_rate
    return f


def find_roots(f: Callable[[np.ndarray, np.ndarray], np.ndarray], lo: np.ndarray,
               hi: np.ndarray, f_lo: np.ndarray, f_hi: np.ndarray, xtol: np.ndarray
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
        t = np.where(f1 != f2, f1 / (f1 - f2), 0.5)                   # regula falsi first
        tl = np.zeros_like(x1)
        active = np.flatnonzero(np.sign(f1) * np.sign(f2) < 0)
        while active.size:
            c = active
            step = np.clip(t[c], tl[c], 1 - tl[c])
            xt = x1[c] + step * (x2[c] - x1[c])
            ft = f(xt, c)
            bad = c[~np.isfinite(ft)]                  # undefined inside: stop at the best end
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
            t_iqi = (f1[c] / (f2[c] - f1[c]) * f3[c] / (f2[c] - f3[c])
                     + (x3[c] - x1[c]) / (x2[c] - x1[c]) * f1[c] / (f3[c] - f1[c])
                     * f2[c] / (f3[c] - f2[c]))
            use = (phi ** 2 < xi) & ((1 - phi) ** 2 < 1 - xi) & np.isfinite(t_iqi)
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


def refine_crossings(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, g: np.ndarray,
                     rtol: float = ROOT_RTOL) -> list[float]:
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
    return find_roots(lambda values, cells: f(values), x[i], x[i + 1], g[i], g[i + 1],
                      _xtol(x, rtol)).tolist()


def _xtol(x: np.ndarray, rtol: float) -> float:
    """Absolute root tolerance on a grid: `rtol` times its span."""
    return rtol * float(np.ptp(x)) if len(x) > 1 else 0.0


def _fixed(model: SqueakModel, speed_rad_s: float | None, load_n: float | None) -> dict[str, float]:
    return {"speed_rad_s": float(REFERENCE_SPEED_RAD_S if speed_rad_s is None else speed_rad_s),
            "load_n": float(model.params.axial_load_n if load_n is None else load_n)}


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


def unstable_intervals(values: np.ndarray, growth: np.ndarray, boundaries: list[float]
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
    _check_axis_values(axis, values)
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


def _refined_boundary(model: SqueakModel, fixed: dict[str, float],
                      x_axis: tuple[str, np.ndarray], y_axis: tuple[str, np.ndarray],
                      g: np.ndarray) -> list[tuple[float, float]]:
    """Zero contour of the growth rate `g` (len(y) x len(x)) refined along the rows, then the
    columns, all in one `find_roots`: ``(x, y)`` points in the axis units, in grid order."""
    (xa, x), (ya, y) = x_axis, y_axis
    rows, cols = _crossings(g), _crossings(g.T)                   # (j, i), (i, j)
    coords = np.concatenate([np.column_stack([x[rows[:, 1]], y[rows[:, 0]]]),
                             np.column_stack([x[cols[:, 0]], y[cols[:, 1]]])])
    vary = np.repeat([0, 1], [len(rows), len(cols)])
    j, i = rows.T
    ci, cj = cols.T
    roots = find_roots(
        _growth_at(model, fixed, (xa, ya), coords, vary),
        np.concatenate([x[i], y[cj]]), np.concatenate([x[i + 1], y[cj + 1]]),
        np.concatenate([g[j, i], g[cj, ci]]), np.concatenate([g[j, i + 1], g[cj + 1, ci]]),
        np.repeat([_xtol(x, ROOT_RTOL), _xtol(y, ROOT_RTOL)], [len(rows), len(cols)]))
    return [(r, yv) if k == 0 else (xv, r)
            for k, r, xv, yv in zip(vary.tolist(), roots.tolist(), coords[:, 0].tolist(),
                                    coords[:, 1].tolist())]


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

    def probability_contours(self, levels: Iterable[float] = PROBABILITY_LEVELS
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
                    points += [(c, yv) for c in level_crossings(self.x, self.probability[j],
                                                                level)]
                for i, xv in enumerate(self.x.tolist()):
                    points += [(xv, c) for c in level_crossings(self.y, self.probability[:, i],
                                                                level)]
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
        extra = {} if self.probability is None else {
            "probability": _grid_list(self.probability),
            "probability_stderr": _grid_list(self.probability_stderr),
            "probability_contours": {_levels_key(k): [list(p) for p in v]
                                     for k, v in self.probability_contours().items()}}
        return {"x_axis": self.x_axis, "x": self.x.tolist(), "y_axis": self.y_axis,
                "y": self.y.tolist(), "fixed": self.fixed,
                "max_growth_rate": _grid_list(g),
                "unstable": (np.nan_to_num(g, nan=-1.0) > 0).tolist(),
                "divergence": (np.nan_to_num(self.field.divergence_rate) > 0).tolist(),
                "boundary": [list(p) for p in self.boundary], **extra}


def _grid_list(a: np.ndarray) -> list[list[float | None]]:
    """Rows of a grid as lists, None for NaN."""
    return [[None if math.isnan(v) else v for v in row] for row in a.tolist()]


def stability_map(model: SqueakModel, x_axis: str, x, y_axis: str, y,
                  speed_rad_s: float | None = None, load_n: float | None = None,
                  progress: Callable[[int], None] | None = None,
                  probability: bool = False) -> MapResult:
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
    """
    for a in (x_axis, y_axis):
        check_axis(a)
    if x_axis == y_axis:
        raise ParameterError("map axes must differ")
    x, y = np.asarray(x, float), np.asarray(y, float)
    _check_axis_values(x_axis, x)
    _check_axis_values(y_axis, y)
    map_work(model, x_axis, x, y_axis, y).check()
    fixed = _fixed(model, speed_rad_s, load_n)
    for a in (x_axis, y_axis):
        fixed.pop(a, None)
    grid = dict(fixed, **{x_axis: x[None, :], y_axis: y[:, None]})
    speed, load = grid.pop("speed_rad_s"), grid.pop("load_n")
    gf = growth_field(model, speed, load, progress=progress, **grid)
    g = gf.max_growth_rate
    boundary = _refined_boundary(model, fixed, (x_axis, x), (y_axis, y), g)
    prob = probability_field(model, speed, load, progress=progress, **grid) \
        if probability else (None, None)
    return MapResult(x_axis, x, y_axis, y, fixed, gf, boundary, *prob)
