# SPDX-License-Identifier: Apache-2.0
"""Probability of squeak over the unit-to-unit scatter of the parameters (`scatter`).

    P(squeak) = probability that some oscillatory eigenvalue of (27) has Re(lambda) > 0

at one speed, load and nut position. `monte_carlo` is the reference estimator: scrambled Sobol
samples in independent replicates (standard error from their spread). Friction and damping do
not change the geometry: a sample only rescales the precomputed matrices
(`Geometry.state_matrices(..., scattered=)`), so thousands of samples cost one batched
eigenvalue solve. A sample counts as squeaking exactly when `SqueakModel(sample).predict` would
list a squeak mode (same thresholds; a sample outside the model's validity, e.g. self-locking,
does not squeak).

`linearised` is the fast estimator for live use (`perturbation.FirstOrderProbability`: each
oscillatory eigenvalue to first order in the friction level, slope, damping and any scattered
geometry field, those computed exactly per sample); `SqueakModel.predict` gives the same number
from its own eigen-solve as `Prediction.probability`.

A scattered geometry field (radius, nut position, ...) changes the modes and the contact
integrals: the reference then builds a model per sample (slow, but exact).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.parameters import GEOMETRY_FIELDS
from ..physics.stability import unstable_mask
from ..squeak_model import SqueakModel, Validity, check_operating_point
from ..uncertainty.perturbation import EigenPairs, FirstOrderProbability, estimate
from ..uncertainty.scatter import Samples, Scatter


@dataclass(frozen=True)
class ProbabilityEstimate:
    """P(squeak) at one operating point.

    Attributes
    ----------
    probability : float
        Estimated probability of squeak, in [0, 1].
    stderr : float or None
        Standard error of `probability` (None: not sampled, e.g. no scatter).
    count : int
        Samples used (0: not sampled).
    """

    probability: float
    stderr: float | None
    count: int


def _values(model: SqueakModel, samples: Samples) -> dict[str, np.ndarray]:
    """The samples' parameter values around this model's parameters (the scatter is relative,
    so a changed nominal value moves every sample with it)."""
    return samples.scatter.values(model.params, samples.u)


def _operating_point(
    model: SqueakModel, speed_rad_s: float, load_n: float
) -> tuple[float, float] | None:
    """The checked point, None outside the model's validity."""
    speed, load = check_operating_point(speed_rad_s, load_n)
    if model.validity(speed, load)[0] is not Validity.OK:
        return None
    return speed, load


def squeaks(
    model: SqueakModel, speed_rad_s: float, load_n: float, values: dict[str, np.ndarray]
) -> np.ndarray:
    """Whether each sample of parameters squeaks at this operating point.

    Parameters
    ----------
    model : SqueakModel
        The nominal model (its geometry is shared by every sample).
    speed_rad_s, load_n : float
        Operating point [rad/s], [N].
    values : dict of str to numpy.ndarray
        Sampled parameter values (non-geometry fields), all of one shape.

    Returns
    -------
    numpy.ndarray of bool
        True where the sample has a squeak mode, in the shape of the values.
    """
    shape = np.broadcast_shapes(*(np.shape(v) for v in values.values()))
    flat = {k: np.broadcast_to(v, shape).ravel() for k, v in values.items()}
    count = len(next(iter(flat.values())))
    geometry = [k for k in flat if k in GEOMETRY_FIELDS]
    if geometry:  # a model per sample: the reference, not the live path
        out = np.array(
            [
                bool(
                    SqueakModel(
                        model.params.with_(**{k: float(v[i]) for k, v in flat.items()}), Scatter({})
                    )
                    .predict(speed_rad_s, load_n)
                    .squeak_modes
                )
                for i in range(count)
            ]
        )
        return out.reshape(shape)
    valid = model.validity_code(np.full(count, speed_rad_s), load_n, scattered=flat) == Validity.OK
    out = np.zeros(valid.shape, bool)
    if valid.any():
        sub = {k: v[valid] for k, v in flat.items()}
        lam = np.linalg.eigvals(model.geometry.state_matrices(speed_rad_s, load_n, sub))
        out[valid] = unstable_mask(lam).any(axis=-1)
    return out.reshape(shape)


def monte_carlo(
    model: SqueakModel, speed_rad_s: float, load_n: float, samples: Samples
) -> ProbabilityEstimate | None:
    """Reference estimate of P(squeak) over `samples` (from `scatter.draw`).

    Parameters
    ----------
    model : SqueakModel
        The nominal model (the scatter is relative to its parameters).
    speed_rad_s, load_n : float
        Operating point [rad/s], [N].
    samples : Samples
        Scatter samples in replicates.

    Returns
    -------
    ProbabilityEstimate or None
        None when the nominal operating point is outside the model's validity.

    Raises
    ------
    OperatingPointError
        Speed or load is not a finite number of plausible magnitude.
    """
    point = _operating_point(model, speed_rad_s, load_n)
    if point is None:
        return None
    speed, load = point
    if not samples.scatter.names:
        p = model.predict(speed, load)
        return ProbabilityEstimate(float(bool(p.squeak_modes)), None, 0)
    return _from_hits(squeaks(model, speed, load, _values(model, samples)))


def _from_hits(hits: np.ndarray) -> ProbabilityEstimate:
    """The estimate from per-sample verdicts of shape (replicates, per_replicate)."""
    return ProbabilityEstimate(*estimate(hits), hits.size)


def linearised(
    model: SqueakModel, speed_rad_s: float, load_n: float, samples: Samples
) -> ProbabilityEstimate | None:
    """Fast estimate of P(squeak): first order in the friction level, slope and damping (see
    the module docstring), over the same samples as `monte_carlo`.

    Parameters
    ----------
    model : SqueakModel
        The nominal model (the scatter is relative to its parameters).
    speed_rad_s, load_n : float
        Operating point [rad/s], [N].
    samples : Samples
        Scatter samples in replicates.

    Returns
    -------
    ProbabilityEstimate or None
        None when the nominal operating point is outside the model's validity; the standard
        error is that of the sampling of the expansion.

    Raises
    ------
    OperatingPointError
        Speed or load is not a finite number of plausible magnitude.
    """
    point = _operating_point(model, speed_rad_s, load_n)
    if point is None:
        return None
    speed, load = point
    if not samples.scatter.names:
        return ProbabilityEstimate(float(bool(model.predict(speed, load).squeak_modes)), None, 0)
    estimator = FirstOrderProbability(model.params, model.geometry, samples)
    return _from_hits(estimator.hits(EigenPairs.solve(model.geometry, speed, load), load))
