# SPDX-License-Identifier: Apache-2.0
"""The squeak predictor: geometry once, then one small eigenproblem per operating point."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from functools import cached_property
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .physics.assembly import build_geometry, lower_half_units_at
from .physics.display import exact
from .physics.friction import mu_o
from .physics.parameters import GEOMETRY_FIELDS, ParameterError, ScrewParameters, field_info
from .physics.stability import (
    Eigen,
    ModeResult,
    Solves,
    classify,
    classify_solves,
    eig_both,
    eig_right_many,
)
from .uncertainty.perturbation import FirstOrderProbability, geometry_fields
from .uncertainty.scatter import LIVE_SAMPLES, Samples, Scatter, check_count, involved, samples_for

_LOAD_LIMIT_N = field_info("axial_load_n")["hi"]


class Validity(IntEnum):
    """Whether the model's linearisation holds at an operating point, and if not, why.

    An IntEnum so that the vectorised `SqueakModel.validity_code` arrays compare with it.
    Each member has a `label` (a short name: a counter key, a status-line note) and a
    `sentence` (what it means); `Prediction.reason` is the sentence for one point, with its
    numbers.
    """

    OK = 0
    BELOW_MIN_SPEED = 1
    AT_CRITICAL_SPEED = 2
    SELF_LOCKING = 3
    SOLVER_FAILED = 4
    PARAMETERS_REJECTED = 5

    @property
    def label(self) -> str:
        """Short name, e.g. 'speed below min_speed_rad_s'."""
        return _VALIDITY_TEXT[self][0]

    @property
    def sentence(self) -> str:
        """What the verdict means, without numbers."""
        return _VALIDITY_TEXT[self][1]


_VALIDITY_TEXT = {
    Validity.OK: ("valid", "the sliding linearisation holds at this operating point"),
    Validity.BELOW_MIN_SPEED: (
        "speed below min_speed_rad_s",
        "near stick the sliding linearisation does not hold; a nonlinear analysis is needed",
    ),
    Validity.AT_CRITICAL_SPEED: (
        "speed at or above the first critical speed",
        "the model holds below the first critical speed, where the backward whirl of the "
        "lowest mode reaches zero frequency",
    ),
    Validity.SELF_LOCKING: (
        "overhauling load on a self-locking thread",
        "with mu_o tan(beta) >= 1 an overhauling load gives no steady sliding: the thread "
        "self-locks",
    ),
    Validity.SOLVER_FAILED: (
        "eigen-solver failed",
        "LAPACK did not converge at this operating point: no number is given",
    ),
    Validity.PARAMETERS_REJECTED: (
        "parameters not allowed at this point",
        "the parameters at this point (e.g. the nut position) do not make a valid screw",
    ),
}


class OperatingPointError(ValueError):
    """Speed or load is not a usable number (NaN, inf, absurd magnitude, wrong type)."""


@dataclass(frozen=True)
class Prediction:
    """The squeak verdict at one operating point (from `SqueakModel.predict`).

    Attributes
    ----------
    speed_rad_s : float
        Screw speed Omega [rad/s] (signed).
    load_n : float
        Axial load F_z [N] (signed).
    formulation : str
        Kernel formulation used, 'paper' or 'consistent'.
    validity : Validity
        Whether the linearisation holds here; `Validity.OK` when it does.
    reason : str
        Why the point is outside validity, with its numbers; '' when valid.
    modes : tuple of ModeResult
        Oscillatory modes, growth rate descending; empty when not valid.
    divergence_rates : tuple of float
        Real eigenvalues > 0 (non-oscillatory growth, not squeak) [1/s], descending.
    probability : float or None
        P(squeak) in [0, 1]: the probability over the model's parameter scatter that some
        oscillatory mode grows (`perturbation.FirstOrderProbability`); exactly the nominal
        verdict (0 or 1) without scatter; None when not valid.
    probability_stderr : float or None
        Standard error of `probability` from its sample replicates; None when not sampled.
    """

    speed_rad_s: float
    load_n: float
    formulation: str
    validity: Validity
    reason: str  # why the point is outside validity ("" when valid)
    modes: tuple[ModeResult, ...] = ()  # oscillatory modes, growth rate descending
    divergence_rates: tuple[float, ...] = ()
    probability: float | None = None
    probability_stderr: float | None = None

    @property
    def valid(self) -> bool:
        """The linearisation holds: modes and probability are given."""
        return self.validity is Validity.OK

    @property
    def stable(self) -> bool | None:
        """No squeak mode and no divergence; None when the point is not valid."""
        if not self.valid:
            return None
        return not self.divergence_rates and not self.squeak_modes

    @cached_property  # every published prediction asks several times (a frozen dataclass)
    def squeak_modes(self) -> tuple[ModeResult, ...]:
        """The unstable oscillatory modes (squeak), most unstable first."""
        return tuple(m for m in self.modes if m.unstable)

    @property
    def unstable_frequencies_hz(self) -> list[float]:
        """Squeak frequencies [Hz], most unstable first."""
        return [m.frequency_hz for m in self.squeak_modes]

    @property
    def max_growth_rate(self) -> float | None:
        """Largest Re(lambda) of the oscillatory modes [1/s] (> 0: squeak); None when not
        valid or without oscillatory modes."""
        return self.modes[0].growth_rate if self.valid and self.modes else None

    @property
    def margin(self) -> float | None:
        """Least damping ratio -Re(lambda)/|lambda| of the oscillatory modes (dimensionless):
        the deterministic stability margin, negative when a mode squeaks; None when not valid
        or without oscillatory modes."""
        return min([m.damping_ratio for m in self.modes]) if self.valid and self.modes else None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary.

        Returns
        -------
        dict[str, Any]
            The fields and derived properties, in the same units; modes as dicts.
        """
        return {
            "speed_rad_s": self.speed_rad_s,
            "load_n": self.load_n,
            "formulation": self.formulation,
            "valid": self.valid,
            "reason": self.reason,
            "stable": self.stable,
            "probability": self.probability,
            "probability_stderr": self.probability_stderr,
            "margin": self.margin,
            "max_growth_rate": self.max_growth_rate,
            "unstable_frequencies_hz": self.unstable_frequencies_hz,
            "divergence_rates": list(self.divergence_rates),
            "modes": [m.as_dict() for m in self.modes],
        }


def check_operating_point(speed_rad_s: Any, load_n: Any) -> tuple[float, float]:
    """Reject values that are not finite real numbers of sane magnitude.

    Parameters
    ----------
    speed_rad_s : float
        Screw speed [rad/s].
    load_n : float
        Axial load [N]; its magnitude may not exceed the upper limit of
        `ScrewParameters.axial_load_n`.

    Returns
    -------
    tuple of float
        ``(speed_rad_s, load_n)`` as Python floats.

    Raises
    ------
    OperatingPointError
        A value is not a real number, not finite, or the load is implausibly large.
    """
    if (
        type(speed_rad_s) is float
        and type(load_n) is float
        and math.isfinite(speed_rad_s)
        and abs(load_n) <= _LOAD_LIMIT_N
    ):  # the common case, per input message
        return speed_rad_s, load_n
    out = []
    for name, unit, v in (("speed", "rad/s", speed_rad_s), ("load", "N", load_n)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise OperatingPointError(f"{name} = {v!r} is not a number ({unit})")
        try:
            v = float(v)
        except OverflowError:  # an int beyond the float range
            raise OperatingPointError(f"{name} = {v!r} is not finite ({unit})") from None
        if not math.isfinite(v):
            raise OperatingPointError(f"{name} = {v} is not finite ({unit})")
        out.append(v)
    if abs(out[1]) > _LOAD_LIMIT_N:
        raise OperatingPointError(
            f"load = {exact(out[1])} N exceeds the plausible magnitude {_LOAD_LIMIT_N:g} N"
        )
    return out[0], out[1]


class SqueakModel:
    """Precomputes modes and contact integrals for one parameter set; `predict` is cheap.

    Parameters
    ----------
    params : ScrewParameters, optional
        Screw, contact and friction parameters (SI units); the defaults (Table 1) when None.
    scatter : Scatter, optional
        Unit-to-unit scatter of the parameters behind `Prediction.probability`; the default
        scatter (`scatter.DEFAULT_SCATTER`) when None, ``Scatter({})`` for none.
    samples : int
        Scatter samples of the probability (`scatter.REPLICATES` times a power of 2).

    Raises
    ------
    ParameterError
        A bad sample count, or more geometry fields scatter than the live estimate takes.

    Attributes
    ----------
    params : ScrewParameters
        The parameters of this model.
    scatter : Scatter
        The scatter of the probability.
    geometry : Geometry
        Modal basis and precomputed contact integrals.
    """

    def __init__(
        self,
        params: ScrewParameters | None = None,
        scatter: Scatter | None = None,
        samples: int = LIVE_SAMPLES,
    ):
        self.geometry = build_geometry(params or ScrewParameters())
        self.params = self.geometry.params
        self.scatter = Scatter() if scatter is None else scatter
        self.sample_count = check_count(samples)
        geometry_fields(self.scatter)  # what the live estimate cannot take: say now

    @cached_property
    def samples(self) -> Samples:
        """The scatter samples around these parameters (points shared between models)."""
        return samples_for(self.params, self.scatter, self.sample_count)

    @cached_property
    def _probability(self) -> FirstOrderProbability | None:
        if not self.scatter.names:
            return None
        return FirstOrderProbability(self.params, self.geometry, self.samples)

    @property
    def labels(self) -> tuple[str, ...]:
        """Names of the modal coordinates, e.g. 'B1x', 'B1y', 'T1' (N entries)."""
        return self.geometry.basis.labels

    @cached_property
    def critical_speed_rad_s(self) -> float:
        """First critical speed [rad/s]: the backward whirl of the lowest mode reaches zero
        frequency; the model holds below it."""
        return float(self.geometry.basis.omega_rad_s.min())

    def with_params(self, **changes: Any) -> SqueakModel:
        """A model with changed parameters, re-integrating only if the geometry changed.

        Parameters
        ----------
        **changes
            `ScrewParameters` field names and new values, each in the field's unit.

        Returns
        -------
        SqueakModel
            A model for the changed parameters.

        Raises
        ------
        ParameterError
            An unknown field or a value out of its allowed range.
        """
        model = SqueakModel(self.params.with_(**changes), self.scatter, self.sample_count)
        if not (set(changes) & involved(self.scatter)) and "samples" in self.__dict__:
            # the samples do not depend on the changed fields: share them (and, for geometry
            # changes, the estimate's per-sample friction), a moved nut costs its contact only
            model.samples = self.samples
            if self._probability is not None and GEOMETRY_FIELDS.issuperset(changes):
                model._probability = self._probability.with_geometry(model.params, model.geometry)
        return model

    def with_scatter(self, scatter: Scatter, samples: int | None = None) -> SqueakModel:
        """A copy of this model with another scatter (and sample count); the geometry is reused.

        Parameters
        ----------
        scatter : Scatter
            The unit-to-unit scatter behind `Prediction.probability`.
        samples : int, optional
            Scatter samples; this model's count when None.

        Returns
        -------
        SqueakModel
            A model with the same parameters and geometry.

        Raises
        ------
        ParameterError
            A bad sample count, or more geometry fields scatter than the live estimate takes.
        """
        return SqueakModel(self.params, scatter, self.sample_count if samples is None else samples)

    def validity_code(
        self, speed_rad_s: ArrayLike, load_n: ArrayLike, scattered: dict | None = None
    ) -> np.ndarray:
        """Vectorised validity: `Validity` codes (Validity.OK where the linearisation holds).

        Parameters
        ----------
        speed_rad_s : array_like
            Screw speeds [rad/s].
        load_n : array_like
            Axial loads [N], broadcast against `speed_rad_s`.
        scattered : dict of str to array_like, optional
            Non-geometry parameter values replacing the nominal ones (broadcast), as in
            `Geometry.state_matrices`.

        Returns
        -------
        numpy.ndarray
            Integer `Validity` codes of the broadcast shape (SOLVER_FAILED and
            PARAMETERS_REJECTED never occur here: they need a solve or a parameter change).
        """
        p = self.params
        friction = SimpleNamespace(**{**p.as_dict(), **scattered}) if scattered else p
        w = np.abs(np.asarray(speed_rad_s, float))
        code = np.where(
            w < p.min_speed_rad_s,
            Validity.BELOW_MIN_SPEED,
            np.where(w >= self.critical_speed_rad_s, Validity.AT_CRITICAL_SPEED, Validity.OK),
        )
        if p.formulation == "consistent":  # overhauling load on a self-locking thread
            locks = (np.sign(speed_rad_s) * np.sign(load_n) < 0) & (
                mu_o(friction, w) * math.tan(p.helix_angle_rad) >= 1
            )
            code = np.where((code == Validity.OK) & locks, Validity.SELF_LOCKING, code)
        return code

    def validity(self, speed_rad_s: float, load_n: float) -> tuple[Validity, str]:
        """The verdict at this point and, when the linearisation fails, why.

        Parameters
        ----------
        speed_rad_s : float
            Screw speed [rad/s].
        load_n : float
            Axial load [N].

        Returns
        -------
        validity : Validity
            The verdict.
        reason : str
            Why the linearisation fails, in words with the numbers; '' when it holds.
        """
        w, p = abs(speed_rad_s), self.params
        if p.formulation == "paper" and p.min_speed_rad_s <= w < self.critical_speed_rad_s:
            return Validity.OK, ""  # the common case, as validity_code decides it
        code = Validity(int(self.validity_code(speed_rad_s, load_n)))
        if code is Validity.OK:
            return code, ""
        return code, {
            Validity.BELOW_MIN_SPEED: (
                f"outside the model's validity: |speed| = {w:g} rad/s is below "
                f"min_speed_rad_s = {p.min_speed_rad_s:g} rad/s (near stick the sliding "
                "linearisation does not hold; a nonlinear analysis is needed)"
            ),
            Validity.AT_CRITICAL_SPEED: (
                f"outside the model's validity: |speed| = {w:g} rad/s is not below the first "
                f"critical speed {self.critical_speed_rad_s:.1f} rad/s"
            ),
            Validity.SELF_LOCKING: (
                "outside the model's validity: overhauling load with mu_o tan(beta) >= 1 (no "
                "steady sliding, the thread self-locks)"
            ),
        }[code]

    def state_matrix(self, speed_rad_s: float, load_n: float) -> np.ndarray:
        """State matrix of (27) at one operating point.

        Parameters
        ----------
        speed_rad_s : float
            Screw speed [rad/s].
        load_n : float
            Axial load [N].

        Returns
        -------
        numpy.ndarray
            The 2N x 2N state matrix; its eigenvalues lambda [1/s] give the modes.
        """
        return self.geometry.state_matrices(speed_rad_s, load_n)

    def predict(self, speed_rad_s: float, load_n: float | None = None) -> Prediction:
        """Squeak prediction at one operating point.

        Parameters
        ----------
        speed_rad_s : float
            Screw speed Omega [rad/s] (signed).
        load_n : float, optional
            Axial load F_z [N] (signed); `params.axial_load_n` when None.

        Returns
        -------
        Prediction
            Modes, stability and probability, or the validity verdict and its reason when the
            linearisation does not hold (then no numbers are given).

        Raises
        ------
        OperatingPointError
            Speed or load is not a finite real number of plausible magnitude.

        Examples
        --------
        The Table 1 screw at 20 rad/s and 200 N squeaks in its first two y-bending modes:

        >>> from leadscrew_ros.model import SqueakModel
        >>> p = SqueakModel().predict(20.0, 200.0)
        >>> p.stable
        False
        >>> [mode.label for mode in p.squeak_modes]
        ['B1y', 'B2y']
        >>> [round(hz) for hz in p.unstable_frequencies_hz]
        [224, 898]
        >>> round(p.max_growth_rate)
        74
        >>> p.probability > 0.9
        True

        Below `min_speed_rad_s` the linearisation does not hold: no numbers, a reason.

        >>> q = SqueakModel().predict(0.1)
        >>> q.valid, q.validity.name
        (False, 'BELOW_MIN_SPEED')
        >>> q.reason
        "outside the model's validity: |speed| = 0.1 rad/s is below min_speed_rad_s = ..."
        """
        speed, load = check_operating_point(
            speed_rad_s, self.params.axial_load_n if load_n is None else load_n
        )
        validity, reason = self.validity(speed, load)
        if validity is not Validity.OK:
            return Prediction(speed, load, self.params.formulation, validity, reason)
        matrix = self.state_matrix(speed, load)
        try:  # right vectors (the labels); P(squeak) gets the left ones from them
            eigen = eig_both(matrix, False)
        except np.linalg.LinAlgError as exc:  # LAPACK gave up: say so, no number
            return self._failed(speed, load, exc)
        estimate = (
            None
            if self._probability is None
            else self._probability.probability(speed, load, eigen, matrix)
        )
        return self._valid(speed, load, classify(eigen, self.labels), estimate)

    def predict_many(
        self,
        speeds_rad_s: ArrayLike,
        loads_n: ArrayLike,
        nut_positions_m: ArrayLike | None = None,
    ) -> list[Prediction]:
        """Predictions at many operating points: their state matrices in one vectorised step,
        then an eigen-solve each, and P(squeak) with the samples' friction at all of them at
        once.

        Parameters
        ----------
        speeds_rad_s : array_like
            Screw speeds [rad/s].
        loads_n : array_like
            Axial loads [N], broadcast against `speeds_rad_s`.
        nut_positions_m : array_like, optional
            The nut position z_o [m] of each point (broadcast): the contact is integrated
            there, the rest is this model's (parameters, scatter samples). A position the
            parameters do not allow gives `Validity.PARAMETERS_REJECTED`. Default: this
            model's nut position.

        Returns
        -------
        list of Prediction
            One prediction per point of the broadcast, flattened in C order.

        Raises
        ------
        OperatingPointError
            Any speed or load is not a finite real number of plausible magnitude.
        ParameterError
            `nut_positions_m` with scattered geometry fields (their estimate is per nut
            position: `with_params`).
        """
        arrays = [np.asarray(speeds_rad_s, float), np.asarray(loads_n, float)]
        if nut_positions_m is not None:
            arrays.append(np.asarray(nut_positions_m, float))
        speeds, loads, *nuts = (a.ravel() for a in np.broadcast_arrays(*arrays))
        points = [
            check_operating_point(s, f)
            for s, f in zip(speeds.tolist(), loads.tolist(), strict=True)
        ]
        out: list[Prediction | None] = [None] * len(points)
        ok, units, rows = list(range(len(points))), None, None
        if nuts:
            ok, units, rows = self._contact_at(nuts[0], points, out)
        for i in ok:
            validity, reason = self.validity(*points[i])
            if validity is not Validity.OK:
                out[i] = Prediction(*points[i], self.params.formulation, validity, reason)
        ok = [i for i in ok if out[i] is None]
        rows = None if rows is None else rows[ok]
        matrices = self.geometry.state_matrices(speeds[ok], loads[ok], units=units, rows=rows)
        groups, failed = eig_right_many(matrices, self.geometry.n)
        for k, exc in failed.items():
            out[ok[k]] = self._failed(*points[ok[k]], exc)
        if len(failed) < len(ok):
            for k, p in self._solved(
                [points[i] for i in ok], groups, matrices, units, rows
            ).items():
                out[ok[k]] = p
        filled = [p for p in out if p is not None]
        assert len(filled) == len(out)  # every point got its verdict
        return filled

    def _solved(
        self,
        points: list[tuple[float, float]],
        groups: list[tuple[list[int], Solves]],
        matrices: np.ndarray,
        units: np.ndarray | None = None,
        rows: np.ndarray | None = None,
    ) -> dict[int, Prediction]:
        """The valid predictions at the `points` the solves `groups` (right vectors, grouped:
        `stability.solves_of`) cover, by index: labels and P(squeak) in array steps over the
        solves of equal mode count; `matrices` the points' state matrices, `units` their
        contacts and `rows` each point's (see `predict_many`)."""
        if self._probability is None:
            estimates: list = [None] * len(points)
        elif self._probability.interpolates:  # one point at a time
            estimates = [None] * len(points)
            for index, solves in groups:
                for g, i in enumerate(index):
                    eigen = Eigen(solves.eigvals[g], solves.osc[g], solves.vr[g], None)
                    estimates[i] = self._probability.probability(*points[i], eigen, matrices[i])
        else:
            speeds, loads = (np.array(v, float) for v in zip(*points, strict=True))
            estimates = self._probability.estimates(speeds, loads, groups, matrices, units, rows)
        out = {}
        for index, solves in groups:
            for i, classified in zip(index, classify_solves(solves, self.labels), strict=True):
                out[i] = self._valid(*points[i], classified, estimates[i])
        return out

    def _contact_at(
        self, nuts: np.ndarray, points: list[tuple[float, float]], out: list
    ) -> tuple[list[int], np.ndarray, np.ndarray]:
        """The points whose nut position the parameters allow (the others get their verdict in
        `out`), the `lower_half_units` of the allowed positions, and every point's row in them
        (meaningful for the allowed points only)."""
        if geometry_fields(self.scatter):
            raise ParameterError(
                "scattered geometry fields: predict each nut position with its own model "
                "(with_params)"
            )
        distinct, inverse = np.unique(nuts, return_inverse=True)
        allowed = np.ones(len(distinct), bool)
        for d, z in enumerate(distinct.tolist()):
            try:
                self.params.with_(nut_position_m=z)
            except ParameterError:
                allowed[d] = False
        for i in np.flatnonzero(~allowed[inverse]).tolist():
            speed, load = points[i]
            out[i] = Prediction(
                speed,
                load,
                self.params.formulation,
                Validity.PARAMETERS_REJECTED,
                f"nut position {exact(float(nuts[i]))} m is not allowed by the parameters",
            )
        rows = np.full(len(distinct), -1)
        rows[allowed] = np.arange(int(allowed.sum()))
        units = lower_half_units_at(self.params, distinct[allowed])
        return np.flatnonzero(allowed[inverse]).tolist(), units, np.maximum(rows[inverse], 0)

    def _failed(self, speed: float, load: float, exc: Exception) -> Prediction:
        """The verdict where LAPACK gave up: say so, no number."""
        return Prediction(
            speed,
            load,
            self.params.formulation,
            Validity.SOLVER_FAILED,
            f"eigen-solver failed at this operating point: {exc}",
        )

    def _valid(
        self,
        speed: float,
        load: float,
        classified: tuple[tuple[ModeResult, ...], tuple[float, ...]],
        estimate: tuple[float, float] | None,
    ) -> Prediction:
        """The valid prediction of the `classified` modes and divergence rates; `estimate`:
        P(squeak) and its standard error, None without scatter (then P is the verdict)."""
        modes, divergence = classified
        if estimate is None:
            probability, stderr = float(any(m.unstable for m in modes)), None
        else:
            probability, stderr = estimate
        return Prediction(
            speed,
            load,
            self.params.formulation,
            Validity.OK,
            "",
            modes,
            divergence,
            probability,
            stderr,
        )
