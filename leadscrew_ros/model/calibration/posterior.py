# SPDX-License-Identifier: Apache-2.0
"""Results of a calibration: a unit's posterior samples (`UnitPosterior`) and the fleet's
population (`Population`), with their summaries and what a params file holds.

Summaries give, per calibrated name and for the friction drop mu_s - mu_k, the mean, SD and
5 / 50 / 95 % quantiles of a unit's samples; for the population, per name the population's
centre and SD, each as {mean, q05, q95} over the hyper-posterior. For a log-normal name
(`scatter.LOG_NORMAL`) the population's centre is its median exp(mean of ln) in the field's
unit and its SD that of ln, as `scatter.*` means it.

Identifiability (`UnitPosterior.identifiability`): per name the posterior SD over the SD of
the prior the unit was sampled under, both in the prior's u (the prior truncated to the valid
domain, as it was sampled); at `PRIOR_ALONE_SD_RATIO` or above the name is learned from the
prior alone. And the posterior correlation of the friction drop and the damping: heard /
not-heard frames fix their ratio (the zero crossing of the growth rate), so near +1 says the
data fixed the ratio and not the scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..physics.parameters import ScrewParameters
from ..uncertainty.scatter import MAX_SCATTER, Scatter
from .prior import DAMPING, Prior

DROP = "friction_drop"  # mu_static - mu_kinetic
# A name is learned from the prior alone when its posterior SD is not below this share of the
# prior's: at 1/sqrt(2) the data carry as much information (inverse variance) as the prior, so
# above it the posterior is more prior than data.
PRIOR_ALONE_SD_RATIO = 1.0 / math.sqrt(2.0)
_PRIOR_SD_DRAWS = 4000  # draws of the (truncated) prior for its SD; a fixed seed: reproducible


def describe(x: np.ndarray) -> dict[str, float]:
    """Mean, SD and 5 / 50 / 95 % quantiles of samples.

    Parameters
    ----------
    x : numpy.ndarray
        (S,) samples.

    Returns
    -------
    dict of str to float
        Keys mean, sd, q05, q50, q95.
    """
    q05, q50, q95 = np.quantile(x, (0.05, 0.5, 0.95)).tolist()
    return {"mean": float(np.mean(x)), "sd": float(np.std(x)), "q05": q05, "q50": q50, "q95": q95}


def interval(x: np.ndarray) -> dict[str, float]:
    """Mean and 5 / 95 % quantiles of samples.

    Parameters
    ----------
    x : numpy.ndarray
        (S,) samples.

    Returns
    -------
    dict of str to float
        Keys mean, q05, q95.
    """
    q05, q95 = np.quantile(x, (0.05, 0.95)).tolist()
    return {"mean": float(np.mean(x)), "q05": q05, "q95": q95}


@dataclass
class UnitPosterior:
    """A unit's posterior (`review.calibration.calibrate_unit`).

    Attributes
    ----------
    unit_id : str
        The unit.
    logs : tuple of str
        Its logs.
    status : str
        'calibrated', or why not: 'nothing to learn: ...' (the samples are the prior's),
        'not converged: ...' (the samples are there, not to be trusted).
    names : tuple of str
        The calibrated parameters, the columns of `samples`.
    samples : numpy.ndarray
        (S, D) posterior samples in the fields' units (equal weights).
    ess : dict of str to float
        Effective sample size per name.
    converged : bool
        The sampler's convergence rule held (`SamplerSettings`).
    reexpansions : int
        Times the likelihood was re-expanded about the posterior mean.
    evaluations : int
        Likelihood evaluations (parameter draws).
    seconds : float
        Wall time of the calibration [s].
    prior : Prior
        The prior the samples are a posterior under: the interim prior, or the prior itself
        when nothing was learned (the population step divides it out). A hierarchical
        posterior (`fit_population`) keeps its unit's: it is not an input to another fit.
    learned : bool
        The likelihood varies over the prior's draws: the data say something.
    grid_weights : numpy.ndarray or None
        (S, K) per sample the posterior weights of the observation model's grid of detection
        threshold and floor depth (`amplitude.AmplitudeLikelihood.responsibilities`,
        flattened), under the grid weights it was sampled with; None without that model.
    """

    unit_id: str
    logs: tuple[str, ...]
    status: str
    names: tuple[str, ...]
    samples: np.ndarray
    ess: dict[str, float]
    converged: bool
    reexpansions: int
    evaluations: int
    seconds: float
    prior: Prior
    learned: bool
    grid_weights: np.ndarray | None = None

    def drop(self) -> np.ndarray:
        """(S,) the friction drop mu_s - mu_k of each sample (a name not calibrated at its
        nominal value).

        Returns
        -------
        numpy.ndarray
            The drops.
        """
        return self._drop_of(self.samples)

    def _drop_of(self, samples: np.ndarray) -> np.ndarray:
        def column(name: str) -> np.ndarray:
            if name in self.names:
                return samples[:, self.names.index(name)]
            return np.full(len(samples), float(getattr(self.prior.nominal, name)))

        return column("mu_static") - column("mu_kinetic")

    def summary(self) -> dict[str, dict[str, float]]:
        """Mean, SD, q05, q50, q95 of each name and of the friction drop.

        Returns
        -------
        dict
            {name: `describe` of its samples}, and 'friction_drop'.
        """
        out = {n: describe(self.samples[:, k]) for k, n in enumerate(self.names)}
        out[DROP] = describe(self.drop())
        return out

    def sd_ratios(self) -> dict[str, float]:
        """Each name's posterior SD over the SD of `prior` (the prior it was sampled under,
        truncated to the valid domain), both in the prior's u; and the friction drop's (in
        its unit) when mu_static or mu_kinetic is calibrated.

        Returns
        -------
        dict of str to float
            Name -> ratio (about 1: the data narrowed nothing).
        """
        prior_u = self.prior.draw(_PRIOR_SD_DRAWS, np.random.default_rng(0))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = self.prior.to_u(self.samples).std(axis=0) / prior_u.std(axis=0)
            out = dict(zip(self.names, ratio.tolist(), strict=True))
            if {"mu_static", "mu_kinetic"} & set(self.names):
                prior_drop = self._drop_of(self.prior.from_u(prior_u))
                out[DROP] = float(np.std(self.drop()) / np.std(prior_drop))
        return out

    def drop_damping_correlation(self) -> float | None:
        """Posterior correlation of the friction drop and the modal damping.

        Returns
        -------
        float or None
            Pearson's r of the samples; None unless both are calibrated (mu_static or
            mu_kinetic, and modal_damping), or when one does not vary.
        """
        if DAMPING not in self.names or not {"mu_static", "mu_kinetic"} & set(self.names):
            return None
        drop, damping = self.drop(), self.samples[:, self.names.index(DAMPING)]
        if len(drop) < 2 or not (np.std(drop) > 0 and np.std(damping) > 0):
            return None
        return float(np.corrcoef(drop, damping)[0, 1])

    def identifiability(self) -> dict[str, object]:
        """What the data identified (module docstring).

        Returns
        -------
        dict
            'sd_ratio' (`sd_ratios`), 'prior_alone' (the names, and the friction drop, at
            `PRIOR_ALONE_SD_RATIO` or above), 'drop_damping_correlation'
            (`drop_damping_correlation`).
        """
        ratios = self.sd_ratios()
        return {
            "sd_ratio": ratios,
            "prior_alone": [n for n, r in ratios.items() if r >= PRIOR_ALONE_SD_RATIO],
            "drop_damping_correlation": self.drop_damping_correlation(),
        }


@dataclass
class Population:
    """The fleet's population of the calibrated parameters (`review.calibration.fit_population`).

    Attributes
    ----------
    names : tuple of str
        The calibrated parameters.
    prior : Prior
        The prior (widen 1): the u coordinates' centre and SDs, the scatter of other names.
    hyper : numpy.ndarray
        (H, 2D) hyper-posterior samples: the centre mu and ln sigma of each name in u
        (`population` module).
    status : str
        'calibrated', or 'not converged: ...'.
    converged : bool
        The sampler's convergence rule held.
    ess : dict of str to float
        Effective sample size of each hyper-parameter ('mean.NAME', 'sd.NAME').
    units : tuple of str
        The units whose data entered (those with something learned).
    evaluations : int
        Hyper-likelihood evaluations.
    seconds : float
        Wall time of the fit [s].
    """

    names: tuple[str, ...]
    prior: Prior
    hyper: np.ndarray
    status: str
    converged: bool
    ess: dict[str, float]
    units: tuple[str, ...]
    evaluations: int
    seconds: float

    def field_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Per hyper draw, each name's population centre and SD as `scatter.*` means them.

        Returns
        -------
        centre : numpy.ndarray
            (H, D) mean in the field's unit (normal) or median exp(mean of ln) (log-normal).
        sd : numpy.ndarray
            (H, D) SD in the field's unit (normal) or SD of ln (log-normal).
        """
        p, d = self.prior, len(self.names)
        mu, sigma = self.hyper[:, :d], np.exp(self.hyper[:, d:])
        centre = p.theta0 * np.where(p.log, np.exp(p.sd * mu), 1.0 + p.sd * mu)
        return centre, np.where(p.log, p.sd, p.sd * p.theta0) * sigma

    def summary(self) -> dict[str, dict[str, dict[str, float]]]:
        """Each name's population centre and SD as {mean, q05, q95}, and the friction drop's
        (centre mean mu_s - mean mu_k, SD sqrt(sd_s^2 + sd_k^2): `Scatter` draws them
        independently; a name not calibrated at its nominal value and prior SD).

        Returns
        -------
        dict
            {name: {'mean': `interval`, 'sd': `interval`}}, and 'friction_drop'.
        """
        centre, sd = self.field_moments()
        out = {
            n: {"mean": interval(centre[:, k]), "sd": interval(sd[:, k])}
            for k, n in enumerate(self.names)
        }
        (ms, ss), (mk, sk) = (self._friction(centre, sd, n) for n in ("mu_static", "mu_kinetic"))
        out[DROP] = {"mean": interval(ms - mk), "sd": interval(np.sqrt(ss**2 + sk**2))}
        return out

    def _friction(
        self, centre: np.ndarray, sd: np.ndarray, name: str
    ) -> tuple[np.ndarray, np.ndarray]:
        if name in self.names:
            k = self.names.index(name)
            return centre[:, k], sd[:, k]
        nominal = float(getattr(self.prior.nominal, name))
        return np.full(len(centre), nominal), np.full(
            len(centre), nominal * self.prior.scatter.sd.get(name, 0.0)
        )

    def predictive(self) -> tuple[np.ndarray, np.ndarray]:
        """A new unit's distribution, moment-matched over the hyper-posterior: what the node's
        nominal values and `scatter.*` mean. Normal name: centre E[m], SD
        sqrt(E[sigma^2] + Var[m]) in the field's unit; log-normal name: the same in ln, the
        centre as exp(E[m of ln]).

        Returns
        -------
        centre : numpy.ndarray
            (D,) in the fields' units.
        sd : numpy.ndarray
            (D,) SD in the field's unit (normal) or of ln (log-normal).
        """
        p, d = self.prior, len(self.names)
        mu, sigma = self.hyper[:, :d], np.exp(self.hyper[:, d:])
        mean_u, sd_u = mu.mean(axis=0), np.sqrt(np.mean(sigma**2, axis=0) + mu.var(axis=0))
        centre = p.theta0 * np.where(p.log, np.exp(p.sd * mean_u), 1.0 + p.sd * mean_u)
        return centre, np.where(p.log, p.sd, p.sd * p.theta0) * sd_u

    def params_and_scatter(self, nominal: ScrewParameters) -> tuple[ScrewParameters, Scatter]:
        """The population as a params file holds it: nominal values at the predictive centre,
        `Scatter` SDs the predictive ones (relative for normal names, of ln for log-normal),
        other names' scatter the prior's; clipped to the valid ranges (`notes` says where).

        Parameters
        ----------
        nominal : ScrewParameters
            The other fields' values.

        Returns
        -------
        tuple of (ScrewParameters, Scatter)
            The calibrated parameters and scatter.
        """
        values, sds, _ = self._clipped(nominal)
        return nominal.with_(**values), Scatter({**self.prior.scatter.sd, **sds})

    def notes(self, nominal: ScrewParameters) -> list[str]:
        """What `params_and_scatter` clipped to the valid ranges ([] when nothing).

        Parameters
        ----------
        nominal : ScrewParameters
            As for `params_and_scatter`.

        Returns
        -------
        list of str
            One line per clipped value.
        """
        return self._clipped(nominal)[2]

    def _clipped(
        self, nominal: ScrewParameters
    ) -> tuple[dict[str, float], dict[str, float], list[str]]:
        centre, sd = self.predictive()
        notes: list[str] = []
        values: dict[str, float] = {}
        sds: dict[str, float] = {}
        for k, name in enumerate(self.names):
            f = next(f for f in fields(ScrewParameters) if f.name == name)
            md, value = f.metadata, float(centre[k])
            lo = math.nextafter(md["lo"], math.inf) if md["lo_open"] else md["lo"]
            hi = math.nextafter(md["hi"], -math.inf) if md["hi_open"] else md["hi"]
            if not lo <= value <= hi:
                notes.append(f"{name}: population centre {value:.6g} clipped to [{lo:g}, {hi:g}]")
                value = min(max(value, lo), hi)
            values[name] = value
            s = float(sd[k]) if self.prior.log[k] else float(sd[k]) / value if value else 0.0
            if s > MAX_SCATTER:
                notes.append(f"scatter.{name}: {s:.3g} clipped to {MAX_SCATTER:g}")
                s = MAX_SCATTER
            sds[name] = s
        mu_s = values.get("mu_static", nominal.mu_static)
        mu_k = values.get("mu_kinetic", nominal.mu_kinetic)
        if mu_k > mu_s:
            notes.append(f"mu_kinetic {mu_k:.6g} above mu_static {mu_s:.6g}: set to mu_static")
            values["mu_kinetic"] = mu_s
            if "mu_kinetic" in sds and mu_s > 0:  # its SD in the field's unit kept
                sds["mu_kinetic"] = min(sds["mu_kinetic"] * mu_k / mu_s, MAX_SCATTER)
        return values, sds, notes
