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

`linearised` is the fast estimator for live use. Friction and damping enter A only through
three scalars: the friction level l = mu_o |F_z| c_f / (alpha R) (W1-W4), the friction slope
s = gamma |F_z| c_5 / alpha (W5) and the damping ratio xi (A is affine in l, s and xi at a fixed
operating point, `kernels.scales`). Each oscillatory eigenvalue is expanded to first order in
them, d lambda = (dl/dl) dl + ..., with the eigenvector formula (`sensitivity.EigenPairs`),
while l, s and xi of every sample are computed exactly (the friction law is the nonlinear part);
P is the share of samples in which some mode's expanded growth rate is > 0, so the modes'
correlation (one friction scatter drives them all) is kept. One eigen-solve per operating point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from .parameters import field_info
from .predictor import SqueakModel, Validity, check_operating_point
from .kernels import scales
from .scatter import Samples
from .sensitivity import EigenPairs
from .stability import unstable_mask


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


def _operating_point(model: SqueakModel, speed_rad_s: float, load_n: float,
                     samples: Samples) -> tuple[float, float] | None:
    """The checked point, None outside the model's validity; geometry scatter is refused (the
    estimators rescale one geometry)."""
    speed, load = check_operating_point(speed_rad_s, load_n)
    if model.validity(speed, load)[0] is not Validity.OK:
        return None
    if any(field_info(n)["geometry"] for n in samples.scatter.names):
        raise ValueError("the estimators scatter friction and damping only; geometry scatter "
                         "needs a model per sample")
    return speed, load


def squeaks(model: SqueakModel, speed_rad_s: float, load_n: float,
            values: dict[str, np.ndarray]) -> np.ndarray:
    """Whether each sample of non-geometry parameters squeaks at this operating point.

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
    valid = model.validity_code(np.full(len(next(iter(flat.values()))), speed_rad_s), load_n,
                                scattered=flat) == Validity.OK
    out = np.zeros(valid.shape, bool)
    if valid.any():
        sub = {k: v[valid] for k, v in flat.items()}
        lam = np.linalg.eigvals(model.geometry.state_matrices(speed_rad_s, load_n, sub))
        out[valid] = unstable_mask(lam).any(axis=-1)
    return out.reshape(shape)


def monte_carlo(model: SqueakModel, speed_rad_s: float, load_n: float,
                samples: Samples) -> ProbabilityEstimate | None:
    """Reference estimate of P(squeak) over `samples` (from `scatter.draw`).

    Parameters
    ----------
    model : SqueakModel
        The nominal model; `samples` must scatter non-geometry parameters only.
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
    ValueError
        The samples scatter a geometry parameter.
    """
    point = _operating_point(model, speed_rad_s, load_n, samples)
    if point is None:
        return None
    speed, load = point
    if not samples.scatter.names:
        p = model.predict(speed, load)
        return ProbabilityEstimate(float(bool(p.squeak_modes)), None, 0)
    return _from_hits(squeaks(model, speed, load, _values(model, samples)))


def _from_hits(hits: np.ndarray) -> ProbabilityEstimate:
    """The estimate from per-sample verdicts of shape (replicates, per_replicate)."""
    per_replicate = hits.mean(axis=1)
    stderr = float(per_replicate.std(ddof=1) / math.sqrt(len(per_replicate)))
    return ProbabilityEstimate(float(hits.mean()), stderr, hits.size)


def linearised(model: SqueakModel, speed_rad_s: float, load_n: float,
               samples: Samples) -> ProbabilityEstimate | None:
    """Fast estimate of P(squeak): first order in the friction level, slope and damping (see
    the module docstring), over the same samples as `monte_carlo`.

    Parameters
    ----------
    model : SqueakModel
        The nominal model; `samples` must scatter non-geometry parameters only.
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
    ValueError
        The samples scatter a geometry parameter.
    """
    point = _operating_point(model, speed_rad_s, load_n, samples)
    if point is None:
        return None
    speed, load = point
    pairs = EigenPairs(model, speed, load)
    if not samples.scatter.names:
        growing = pairs.lam.real > 0
        return ProbabilityEstimate(float(growing.any()), None, 0)
    p, alpha, w = model.params, model.geometry.contact.alpha, abs(speed)
    sign = math.copysign(1.0, speed)
    # d lambda per unit of level l (W1 = sign l, W3 = l / |Omega|) and of slope s
    # (W5q = Omega s, W5qdot = s), and per unit of xi
    rates = np.stack([pairs.coefficient_rate([sign, 0, 1 / w, 0, 0]).real,
                      pairs.coefficient_rate([0, speed, 0, 1, 0]).real,
                      pairs.damping_rate().real])                       # (3, M)
    values = {k: v.ravel() for k, v in _values(model, samples).items()}
    nominal = scales(p, speed, load, alpha)
    sampled = scales(SimpleNamespace(**{**p.as_dict(), **values}), speed, load, alpha)
    count = samples.count
    change = np.stack([np.broadcast_to(sampled["W3"] - nominal["W3"], (count,)) * w,
                       np.broadcast_to(sampled["W5qdot"] - nominal["W5qdot"], (count,)),
                       np.broadcast_to(values.get("modal_damping", p.modal_damping)
                                       - p.modal_damping, (count,))], axis=1)   # (count, 3)
    growth0 = pairs.lam.real
    reach = np.abs(change).max(axis=0) @ np.abs(rates)        # largest change of each mode
    candidates = growth0 + reach > 0                           # the others never squeak
    growth = growth0[candidates] + change @ rates[:, candidates]
    hits = (growth > 0).any(axis=1) if candidates.any() else np.zeros(count, bool)
    return _from_hits(hits.reshape(samples.u.shape[:2]))
