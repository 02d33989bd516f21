# SPDX-License-Identifier: Apache-2.0
"""The hierarchical population of the calibrated parameters, from the units' interim posterior
samples by importance reweighting (Hogg, Myers & Bovy 2010, ApJ 725, 2166).

In the prior's standardised coordinates u (`prior.Prior`), a population is, per name, a normal
N(mu, sigma^2) in u: normal in the field's units for a normal name, in ln for a log-normal one,
as `Scatter` means its SDs (so it can be written as nominal values and `scatter.*`); the names
independent, as `Scatter` draws them; truncated to mu_s >= mu_k (its normaliser Z depends on
the population and is kept; the other field ranges lie many SDs out and are left out).

The hyper-likelihood of the population phi = (mu, ln sigma) is, with each unit's samples u_s
drawn from its posterior under the interim prior p_int:

    L(phi) = prod over units of  mean over s of  p(u_s | phi) / p_int(u_s)

Hyper-priors (weak, documented): mu ~ N(0, w^2) per name, w the interim widening (the
population centre lies where the interim prior reaches, else the reweighting has no samples
there); ln sigma ~ N(0, 1) per name, centred on the prior's SD (sigma = 1 in u) and a factor
e wide either way at one SD.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.special import log_ndtr, logsumexp

from .prior import Prior

HYPER_LOG_SD = 1.0  # SD of the hyper-prior of ln sigma


def pair_index(names: tuple[str, ...]) -> tuple[int | None, int | None]:
    """Columns of mu_static and mu_kinetic among `names` (None where not calibrated)."""
    s = names.index("mu_static") if "mu_static" in names else None
    k = names.index("mu_kinetic") if "mu_kinetic" in names else None
    return s, k


class HyperModel:
    """Log hyper-posterior of populations phi = (mu, ln sigma), vectorised over rows of phi.

    Parameters
    ----------
    prior : Prior
        The prior (widen 1): centre and SDs of the u coordinates.
    widen : float
        The interim widening w (the hyper-prior of mu is N(0, w^2)).
    u : numpy.ndarray
        (U, S, D) each unit's interim posterior samples in u.
    log_interim : numpy.ndarray
        (U, S) log density of each sample under its unit's interim prior (in u, up to a
        constant common to a unit).
    """

    def __init__(self, prior: Prior, widen: float, u: np.ndarray, log_interim: np.ndarray):
        self.prior, self.widen = prior, widen
        self.units, self.per_unit, self.dims = u.shape
        flat = u.reshape(-1, self.dims)
        self._u, self._u2 = flat.T.copy(), (flat * flat).T.copy()  # (D, U*S)
        self._log_interim = log_interim.reshape(-1)
        self.evaluations = 0

    def log_density(self, phi: np.ndarray, u: np.ndarray) -> np.ndarray:
        """log p(u | phi) for populations phi (H, 2D) and samples u (N, D), normalised over
        the valid domain.

        Parameters
        ----------
        phi : numpy.ndarray
            (H, 2D): mu then ln sigma per name.
        u : numpy.ndarray
            (N, D) standardised coordinates.

        Returns
        -------
        numpy.ndarray
            (H, N) log densities.
        """
        return self._log_density(phi, u.T, (u * u).T)

    def _log_density(self, phi: np.ndarray, u_t: np.ndarray, u2_t: np.ndarray) -> np.ndarray:
        d = self.dims
        mu, log_sigma = phi[:, :d], phi[:, d:]
        a = np.exp(-2.0 * log_sigma)  # 1 / sigma^2
        out = -0.5 * (a @ u2_t) + (a * mu) @ u_t
        out -= (0.5 * np.sum(a * mu * mu, axis=1) + np.sum(log_sigma, axis=1))[:, None]
        return out - self.log_truncation(phi)[:, None] - 0.5 * d * math.log(2 * math.pi)

    def log_truncation(self, phi: np.ndarray) -> np.ndarray:
        """ln Z(phi) = ln P(mu_s >= mu_k) under each population (0 without friction names).

        Parameters
        ----------
        phi : numpy.ndarray
            (H, 2D) populations.

        Returns
        -------
        numpy.ndarray
            (H,) ln Z.
        """
        s_col, k_col = pair_index(self.prior.names)
        if s_col is None and k_col is None:
            return np.zeros(len(phi))
        mean_s, sd_s = self._field_moments(phi, s_col, "mu_static")
        mean_k, sd_k = self._field_moments(phi, k_col, "mu_kinetic")
        return log_ndtr((mean_s - mean_k) / np.sqrt(sd_s**2 + sd_k**2))

    def _field_moments(self, phi: np.ndarray, col: int | None, name: str) -> tuple[Any, Any]:
        """Mean and SD in the field's units of a normal name (its nominal value, SD 0, when
        not calibrated)."""
        if col is None:
            return float(getattr(self.prior.nominal, name)), 0.0
        d, p = self.dims, self.prior
        scale = p.theta0[col] * p.sd[col]
        return p.theta0[col] + scale * phi[:, col], scale * np.exp(phi[:, d + col])

    def log_prior(self, phi: np.ndarray) -> np.ndarray:
        """Log hyper-prior (module docstring), up to a constant.

        Parameters
        ----------
        phi : numpy.ndarray
            (H, 2D) populations.

        Returns
        -------
        numpy.ndarray
            (H,) log densities.
        """
        d = self.dims
        return -0.5 * (
            np.sum((phi[:, :d] / self.widen) ** 2, axis=1)
            + np.sum((phi[:, d:] / HYPER_LOG_SD) ** 2, axis=1)
        )

    def log_posterior(self, phi: np.ndarray) -> np.ndarray:
        """Log hyper-posterior up to a constant: hyper-prior plus the reweighted likelihood.

        Parameters
        ----------
        phi : numpy.ndarray
            (H, 2D) populations.

        Returns
        -------
        numpy.ndarray
            (H,) log densities; -inf where not finite.
        """
        phi = np.atleast_2d(np.asarray(phi, float))
        self.evaluations += len(phi)
        ratio = self._log_density(phi, self._u, self._u2) - self._log_interim
        per_unit = logsumexp(ratio.reshape(len(phi), self.units, self.per_unit), axis=2)
        out = self.log_prior(phi) + per_unit.sum(axis=1) - self.units * math.log(self.per_unit)
        return np.where(np.isfinite(out), out, -np.inf)


def reweighted(
    model: HyperModel, hyper: np.ndarray, u: np.ndarray, log_own: np.ndarray
) -> np.ndarray:
    """Normalised weights of one unit's samples for its population-informed posterior
    p(u | all data), the mean over hyper draws phi of p(u | phi, its data).

    With r_s(phi) = p(u_s | phi) / p_own(u_s),

        w_s = mean over phi of  r_s(phi) / sum_s' r_s'(phi)

    Each draw's weights are normalised before they are averaged: p(u | phi, its data) is the
    unit's likelihood times p(u | phi) over their integral E(phi) (the sum of r). Averaging r
    unnormalised weighs each draw by E(phi) as well, the unit's own data counted a second time
    beside the hyper-posterior that holds them already: the draws that fit this unit best
    (for a unit near the centre, the narrow populations) decide its posterior.

    Parameters
    ----------
    model : HyperModel
        The population's densities.
    hyper : numpy.ndarray
        (H, 2D) hyper-posterior draws.
    u : numpy.ndarray
        (S, D) the unit's samples in u.
    log_own : numpy.ndarray
        (S,) their log density under the prior they were drawn under.

    Returns
    -------
    numpy.ndarray
        (S,) weights summing to 1.
    """
    ratio = model.log_density(hyper, u) - log_own  # (H, S)
    log_w = logsumexp(ratio - logsumexp(ratio, axis=1, keepdims=True), axis=0)
    w = np.exp(log_w - log_w.max())
    return w / w.sum()
