# SPDX-License-Identifier: Apache-2.0
"""Sampling the calibration posteriors with emcee (Foreman-Mackey et al. 2013): each unit under
an interim prior (`calibrate_unit`), then the fleet's hierarchical population from the units'
samples (`fit_population`).

Why emcee: the likelihood is a sum over operating points of terms that switch where a mode's
growth rate crosses the squeak threshold, so it is piecewise constant in the parameters; no
gradient exists, which rules out HMC/NUTS (PyMC, NumPyro), and nested sampling (dynesty) spends
most of its evaluations on the prior volume. emcee's affine-invariant ensemble needs no
gradient, no tuning beyond walkers and steps, is numpy only (one small dependency), evaluates
a half-ensemble in one vectorised call, and is seeded through its random state.

Per unit:

1. Nothing to learn? `SamplerSettings.check_draws` draws of the interim prior: if the
   log-likelihood is the same for all (never heard, and no draw squeaks where the unit ran;
   or no valid operating point), the status says so and the prior is kept.
2. Re-expansion: run the ensemble for `first_steps` (the first `burn` discarded), take the
   posterior mean, re-expand the likelihood there (`GrowthLikelihood.recentred`), run again
   from the last positions, until the mean is within `recentre_tolerance` posterior SDs of
   the expansion centre it was sampled with, or `max_reexpansions` are done; that run is
   continued to `steps`, and its kept steps are the samples. If the continued run's mean is
   no longer within the tolerance (a wide posterior's short run can look settled by chance),
   it is re-expanded there too while re-expansions are left.
3. Convergence: the integrated autocorrelation time tau of each name (emcee's estimator over
   the kept steps); ESS = walkers * kept steps / tau. Converged when the re-expansion settled,
   the kept steps are at least `autocorr_multiple` tau for every name and every ESS is at
   least `min_ess`; otherwise the status says which failed.

The seed of a unit comes from the run's seed and the unit's id (`unit_seed`), never from the
order of execution: units calibrated in parallel give what they give one after another.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import emcee
import numpy as np
from emcee.autocorr import integrated_time
from threadpoolctl import threadpool_limits

from ...model.calibration.amplitude import AmplitudeLikelihood, HearingPrior, bench_posterior
from ...model.calibration.likelihood import DetectionErrors, GrowthLikelihood
from ...model.calibration.observations import CalibrationError, Observations
from ...model.calibration.population import HyperModel, reweighted
from ...model.calibration.posterior import Population, UnitPosterior
from ...model.calibration.prior import DEFAULT_NAMES, INTERIM_WIDEN, Prior
from ...model.physics.metadata import check, documented, setting
from ...model.physics.parameters import ParameterError, ScrewParameters
from ...model.squeak_model import SqueakModel

PRIOR_SAMPLES = 2000  # prior draws that stand for a unit with nothing to learn


@documented
@dataclass(frozen=True)
class SamplerSettings:
    """Walkers, steps, seeds and rules of the calibration's samplers (module docstring).

    Defaults measured on synthetic Table 1 units of 12-s strokes (four names, ~750 distinct
    points): the autocorrelation time is ~20-35 steps, so 32 walkers x 500 steps (150 burnt)
    give an ESS of ~400-500 per name (the rule asks 100 and 10 autocorrelation times); the
    walkers start at the best of `check_draws` interim-prior draws, burn in within ~5
    autocorrelation times, and one or two re-expansions settle the mean (0.5 posterior SD: the
    expansion's error is second order in the distance from its centre, and the posterior spans
    +-2 SDs anyway). About 1.3-2.2 s of one core per unit; the population fit ~2 s.
    """

    walkers: int = setting(
        32, "1", "emcee walkers per unit (even, at least 2 per name + 2)", 4, 4096
    )
    steps: int = setting(500, "1", "steps of each run of a unit's walkers", 10, 10**6)
    burn: int = setting(150, "1", "steps discarded at the start of each run", 0, 10**6)
    first_steps: int = setting(
        250,
        "1",
        "steps of a run before its re-expansion check (a settled run is continued to steps)",
        10,
        10**6,
    )
    seed: int = setting(
        0, "1", "seed of the run (a unit's seed derives from it and its id)", 0, 2**31 - 1
    )
    prior_widen: float = setting(
        INTERIM_WIDEN,
        "1",
        "factor on the prior's SDs of the interim prior that units are sampled under",
        1.0,
        10.0,
    )
    max_reexpansions: int = setting(
        4, "1", "re-expansions of the likelihood about the posterior mean, at most", 0, 100
    )
    recentre_tolerance: float = setting(
        0.5,
        "1",
        "the posterior mean settled: within this many posterior SDs of the expansion centre",
        0.0,
        10.0,
        lo_open=True,
    )
    min_ess: float = setting(
        100.0, "1", "converged: effective sample size per name at least", 1.0, 1e7
    )
    autocorr_multiple: float = setting(
        10.0,
        "1",
        "converged: the kept steps at least this many autocorrelation times per name",
        1.0,
        1e4,
    )
    check_draws: int = setting(
        512, "1", "interim-prior draws that decide whether a unit has anything to learn", 16, 10**6
    )
    population_samples: int = setting(
        256, "1", "samples of each unit that enter the population's hyper-likelihood", 10, 10**6
    )
    hyper_walkers: int = setting(
        32, "1", "emcee walkers of the population (even, > 4 per name)", 8, 4096
    )
    hyper_steps: int = setting(1000, "1", "steps of the population's walkers", 10, 10**6)
    hyper_burn: int = setting(300, "1", "population steps discarded at the start", 0, 10**6)
    hyper_draws: int = setting(
        400, "1", "hyper-posterior draws that reweight the units' samples", 10, 10**6
    )

    def __post_init__(self) -> None:
        check(self, ParameterError, "sampler.")
        for walkers, steps, burn in (
            ("walkers", "steps", "burn"),
            ("hyper_walkers", "hyper_steps", "hyper_burn"),
        ):
            if getattr(self, walkers) % 2:
                raise ParameterError(f"sampler.{walkers} = {getattr(self, walkers)} must be even")
            if getattr(self, burn) >= getattr(self, steps):
                raise ParameterError(
                    f"sampler.{burn} = {getattr(self, burn)} must be below "
                    f"sampler.{steps} = {getattr(self, steps)}"
                )
        if not self.burn < self.first_steps <= self.steps:
            raise ParameterError(
                f"need sampler.burn < sampler.first_steps <= sampler.steps, got {self.burn}, "
                f"{self.first_steps} and {self.steps}"
            )


def unit_seed(seed: int, unit_id: str, purpose: str = "unit") -> np.random.SeedSequence:
    """The seed of one unit's sampling: from the run's seed, the unit's id and the purpose
    (a hash, not Python's salted one), so it does not depend on the order of execution.

    Parameters
    ----------
    seed : int
        The run's seed.
    unit_id : str
        The unit.
    purpose : str
        What it seeds ('unit', 'population').

    Returns
    -------
    numpy.random.SeedSequence
        Its seed sequence.
    """
    digest = hashlib.sha256(f"{purpose}\0{unit_id}".encode()).digest()
    return np.random.SeedSequence([seed, *np.frombuffer(digest[:16], np.uint32).tolist()])


def _ensemble(
    log_prob: Callable[[np.ndarray], np.ndarray], walkers: int, dims: int, rng: np.random.Generator
) -> emcee.EnsembleSampler:
    sampler = emcee.EnsembleSampler(walkers, dims, log_prob, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    return sampler


def _tau(chain: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time per dimension of a (steps, walkers, D) chain (emcee's
    estimator; the length rule is ours)."""
    return np.asarray(integrated_time(chain, tol=0, quiet=True), float)


def _start(u: np.ndarray, log_post: np.ndarray, walkers: int) -> np.ndarray:
    """The walkers' start: the draws of highest posterior (distinct, finite)."""
    finite = np.flatnonzero(np.isfinite(log_post))
    if len(finite) < walkers:
        raise CalibrationError(
            f"only {len(finite)} of {len(u)} prior draws are possible; need {walkers} to start"
        )
    return u[finite[np.argsort(-log_post[finite], kind="stable")[:walkers]]]


def calibrate_unit(
    model: SqueakModel,
    obs: Observations,
    names: Sequence[str] = DEFAULT_NAMES,
    errors: DetectionErrors | None = None,
    settings: SamplerSettings | None = None,
    centre: ScrewParameters | None = None,
    hearing: HearingPrior | None = None,
) -> UnitPosterior:
    """One unit's posterior of `names` given its observations (module docstring).

    Parameters
    ----------
    model : SqueakModel
        Nominal parameters and scatter: the prior (its SDs widened by
        `SamplerSettings.prior_widen` for the interim prior).
    obs : Observations
        The unit's heard / not-heard frames.
    names : sequence of str
        The calibrated parameters.
    errors : DetectionErrors, optional
        The detection error model; the defaults when None.
    settings : SamplerSettings, optional
        Walkers, steps, seed and rules; the defaults when None.
    centre : ScrewParameters, optional
        The first expansion centre; the model's parameters when None (the answer does not
        depend on it beyond the sampling error).
    hearing : HearingPrior, optional
        The observation model's grid prior (`amplitude`); the defaults when None. Used when
        the observations keep their frame sequence; without it the frames are taken as heard
        where the model squeaks (`GrowthLikelihood`).

    Returns
    -------
    UnitPosterior
        Samples in the fields' units, status, ESS and counts.

    Raises
    ------
    ParameterError
        A name that cannot be calibrated, or one without a prior SD (``--scatter NAME=SD``).
    """
    with threadpool_limits(limits=1, user_api="blas"):  # small products: threads only spin
        return _calibrate_unit(model, obs, names, errors, settings, centre, hearing)


Likelihood = GrowthLikelihood | AmplitudeLikelihood


def _likelihood(
    model: SqueakModel,
    obs: Observations,
    names: Sequence[str],
    errors: DetectionErrors,
    reach: Prior,
    hearing: HearingPrior | None,
) -> Likelihood:
    """The observation model where the frames keep their order, else heard-where-it-squeaks."""
    growth = GrowthLikelihood(model, obs, names, errors, reach)
    return AmplitudeLikelihood(growth, hearing) if len(obs.sequence) else growth


def _grid_weights(likelihood: Likelihood, samples: np.ndarray) -> np.ndarray | None:
    """(S, K) the samples' grid responsibilities (None without the observation model)."""
    if not isinstance(likelihood, AmplitudeLikelihood):
        return None
    chunks = [
        likelihood.responsibilities(samples[k : k + 256]) for k in range(0, len(samples), 256)
    ]
    return np.concatenate(chunks).reshape(len(samples), -1)


def _calibrate_unit(
    model: SqueakModel,
    obs: Observations,
    names: Sequence[str],
    errors: DetectionErrors | None,
    settings: SamplerSettings | None,
    centre: ScrewParameters | None,
    hearing: HearingPrior | None = None,
) -> UnitPosterior:
    start_time = time.perf_counter()
    settings, errors = settings or SamplerSettings(), errors or DetectionErrors()
    prior = Prior(model.params, model.scatter, names)
    interim = prior.widened(settings.prior_widen)
    rng = np.random.default_rng(unit_seed(settings.seed, obs.unit_id))
    centre_model = model if centre is None else SqueakModel(centre, model.scatter)
    likelihood = _likelihood(centre_model, obs, interim.names, errors, interim, hearing)
    evaluations = 0

    def log_prob(u: np.ndarray) -> np.ndarray:  # the likelihood is -inf outside the domain
        return likelihood.log_likelihood(interim.from_u(u)) - 0.5 * np.sum(
            (u / interim.widen) ** 2, axis=1
        )

    def result(status, samples, ess, converged, reexpansions, learned, density):
        return UnitPosterior(
            unit_id=obs.unit_id,
            logs=obs.logs,
            status=status,
            names=interim.names,
            samples=samples,
            ess=dict(zip(interim.names, np.asarray(ess, float).tolist(), strict=True)),
            converged=converged,
            reexpansions=reexpansions,
            evaluations=evaluations + likelihood.evaluations,
            seconds=time.perf_counter() - start_time,
            prior=density,
            learned=learned,
            grid_weights=_grid_weights(likelihood, samples),
        )

    u = interim.draw(settings.check_draws, rng)
    log_like = likelihood.log_likelihood(interim.from_u(u))
    possible = log_like[np.isfinite(log_like)]
    if not len(possible) or np.ptp(possible) == 0.0:
        count = PRIOR_SAMPLES
        kept = prior.draw(count, rng)
        return result(
            _nothing_to_learn(obs, likelihood),
            prior.from_u(kept),
            np.full(len(names), float(count)),
            True,
            0,
            False,
            prior,
        )
    position = _start(u, log_like + interim.log_density_u(u), settings.walkers)
    kept_steps = settings.steps - settings.burn

    def moments(sampler: emcee.EnsembleSampler) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kept chain (steps, walkers, D) in u, and how far the mean is from the
        expansion centre in posterior SDs (D,)."""
        chain = sampler.get_chain(discard=settings.burn)
        theta = interim.from_u(chain.reshape(-1, chain.shape[-1]))
        mean, sd = theta.mean(axis=0), theta.std(axis=0)
        return chain, mean, np.abs(mean - likelihood.centre) / np.where(sd > 0, sd, np.inf)

    for reexpansions in range(settings.max_reexpansions + 1):
        sampler = _ensemble(log_prob, settings.walkers, len(interim.names), rng)
        sampler.run_mcmc(position, settings.first_steps)
        chain, mean, moved = moments(sampler)
        last = reexpansions == settings.max_reexpansions
        if np.all(moved < settings.recentre_tolerance) or last:
            sampler.run_mcmc(None, settings.steps - settings.first_steps)  # the same chain
            chain, mean, moved = moments(sampler)
            # a wide posterior's short run can look settled by chance: the kept run decides
            if np.all(moved < settings.recentre_tolerance) or last:
                break
        position = sampler.get_last_sample().coords
        evaluations += likelihood.evaluations
        likelihood = likelihood.recentred(interim.values(mean))
    settled = bool(np.all(moved < settings.recentre_tolerance))
    theta = interim.from_u(chain)
    tau = _tau(chain)
    ess = settings.walkers * kept_steps / tau
    reasons = []
    if not settled:
        reasons.append(
            f"the posterior mean still moved {moved.max():.2f} SDs after "
            f"{settings.max_reexpansions} re-expansions"
        )
    if np.any(kept_steps < settings.autocorr_multiple * tau):
        reasons.append(
            f"{kept_steps} kept steps are fewer than {settings.autocorr_multiple:g} "
            f"autocorrelation times ({tau.max():.0f} steps)"
        )
    if np.any(ess < settings.min_ess):
        reasons.append(f"ESS {ess.min():.0f} below {settings.min_ess:g}")
    thin = max(1, int(tau.min() / 2))
    return result(
        "calibrated" if not reasons else "not converged: " + "; ".join(reasons),
        theta[::thin].reshape(-1, chain.shape[-1]),
        ess,
        not reasons,
        reexpansions,
        True,
        interim,
    )


def _nothing_to_learn(obs: Observations, likelihood: Likelihood) -> str:
    valid = likelihood.valid
    heard = int(obs.heard[valid].sum())
    if not valid.any():
        return (
            "nothing to learn: no logged operating point is in the model's valid range "
            "(speed between min_speed_rad_s and the first critical speed); the prior is kept"
        )
    what = "never heard" if not heard else f"heard {heard} of {int(obs.frames[valid].sum())} frames"
    return (
        f"nothing to learn: {what}, and no prior draw changes the predicted squeak at the "
        f"{int(valid.sum())} valid operating points; the prior is kept"
    )


def share_hearing(
    units: list[UnitPosterior], hearing: HearingPrior | None = None, seed: int = 0
) -> tuple[np.ndarray | None, list[UnitPosterior]]:
    """The bench's detection threshold and floor depth from all its units, and each unit's
    samples re-weighted to it (`amplitude`: the grid is the bench's, not the unit's).

    A unit was sampled with the grid's prior; its posterior given the other units' data is
    its samples re-weighted by sum_k r_k(theta) q(k) / p(k), with r_k the sample's grid
    responsibilities and q the bench's grid posterior from the other units (its own data
    are in its likelihood already), then resampled (seeded by its id).

    Parameters
    ----------
    units : list of UnitPosterior
        The units of one bench (one run, one formulation).
    hearing : HearingPrior, optional
        The grid's prior; the defaults when None.
    seed : int
        The run's seed.

    Returns
    -------
    log_posterior : numpy.ndarray or None
        (Kd, Kh) the bench's grid log posterior from all units; None when no unit has the
        observation model.
    units : list of UnitPosterior
        In order; the re-weighted ones with their ESS capped at the weights' (Kish) size.
    """
    hearing = hearing or HearingPrior()
    _, _, log_prior = hearing.grid()
    grid = [k for k, u in enumerate(units) if u.grid_weights is not None and len(u.samples)]
    if not grid:
        return None, units
    own = [np.asarray(units[k].grid_weights).mean(axis=0) for k in grid]
    flat = log_prior.ravel()
    finite = np.isfinite(flat)
    out = list(units)
    for j, k in enumerate(grid if len(grid) > 1 else []):
        unit = units[k]
        others = bench_posterior(flat, own[:j] + own[j + 1 :])
        ratio = np.where(finite, np.exp(others - np.where(finite, flat, 0.0)), 0.0)
        weights = np.asarray(unit.grid_weights)
        w = weights @ ratio
        if not (np.all(np.isfinite(w)) and w.sum() > 0):
            continue
        w = w / w.sum()
        rng = np.random.default_rng(unit_seed(seed, unit.unit_id, "hearing"))
        pick = rng.choice(len(w), size=len(w), p=w)
        kish = 1.0 / float(np.sum(w * w))
        out[k] = replace(
            unit,
            samples=unit.samples[pick],
            grid_weights=weights[pick],
            ess={n: min(e, kish) for n, e in unit.ess.items()},
        )
    return bench_posterior(flat, own).reshape(log_prior.shape), out


def fit_population(
    units: list[UnitPosterior], model: SqueakModel, settings: SamplerSettings | None = None
) -> tuple[Population, list[UnitPosterior]]:
    """The fleet's hierarchical population, and each unit's population-informed posterior.

    The hyper-posterior (`model.calibration.population`) is sampled with emcee from the units
    that learned something (each with `population_samples` of its samples, evenly spaced);
    every unit's samples are then reweighted by p(theta | population) / p(theta | its prior),
    normalised per draw and averaged over `hyper_draws` hyper-posterior draws
    (`population.reweighted`), and resampled (seeded per unit).

    Parameters
    ----------
    units : list of UnitPosterior
        The units' posteriors (`calibrate_unit`), one set of names.
    model : SqueakModel
        The model they were calibrated with (the prior's centre and SDs).
    settings : SamplerSettings, optional
        As for the units; the defaults when None.

    Returns
    -------
    population : Population
        The hyper-posterior, its status and ESS.
    posteriors : list of UnitPosterior
        The units' hierarchical posteriors, in order (status and convergence as before, ESS
        the reweighted samples' effective number).

    Raises
    ------
    CalibrationError
        No unit learned anything, the units have different names, or they were calibrated
        with another prior than `model`'s.
    """
    with threadpool_limits(limits=1, user_api="blas"):  # small products: threads only spin
        return _fit_population(units, model, settings)


def _fit_population(
    units: list[UnitPosterior], model: SqueakModel, settings: SamplerSettings | None
) -> tuple[Population, list[UnitPosterior]]:
    start_time = time.perf_counter()
    settings = settings or SamplerSettings()
    if not units or len({u.names for u in units}) != 1:
        raise CalibrationError("the population needs units calibrated with one set of names")
    names = units[0].names
    prior = Prior(model.params, model.scatter, names)
    if any(u.prior.nominal != model.params or u.prior.scatter != model.scatter for u in units):
        raise CalibrationError("the units were calibrated with another model's prior")
    used = [u for u in units if u.learned]
    if not used:
        raise CalibrationError("no unit has anything to learn: no population can be fitted")
    per = min(settings.population_samples, min(len(u.samples) for u in used))
    u_all = np.stack(
        [
            prior.to_u(u.samples[np.linspace(0, len(u.samples) - 1, per).round().astype(int)])
            for u in used
        ]
    )
    log_interim = np.stack([_log_own(u, x) for u, x in zip(used, u_all, strict=True)])
    hyper_model = HyperModel(prior, max(u.prior.widen for u in used), u_all, log_interim)
    rng = np.random.default_rng(unit_seed(settings.seed, "", "population"))
    d = len(names)
    means = u_all.mean(axis=1)  # each unit's posterior mean in u
    centre = np.concatenate([means.mean(axis=0), np.log(means.std(axis=0) + 0.3)])
    start = centre + 0.05 * rng.standard_normal((settings.hyper_walkers, 2 * d))
    sampler = _ensemble(hyper_model.log_posterior, settings.hyper_walkers, 2 * d, rng)
    sampler.run_mcmc(start, settings.hyper_steps)
    chain = sampler.get_chain(discard=settings.hyper_burn)
    kept_steps = settings.hyper_steps - settings.hyper_burn
    tau = _tau(chain)
    ess = settings.hyper_walkers * kept_steps / tau
    reasons = []
    if np.any(kept_steps < settings.autocorr_multiple * tau):
        reasons.append(
            f"{kept_steps} kept steps are fewer than {settings.autocorr_multiple:g} "
            f"autocorrelation times ({tau.max():.0f} steps)"
        )
    if np.any(ess < settings.min_ess):
        reasons.append(f"ESS {ess.min():.0f} below {settings.min_ess:g}")
    hyper = chain.reshape(-1, 2 * d)
    labels = [f"mean.{n}" for n in names] + [f"sd.{n}" for n in names]
    population = Population(
        names=names,
        prior=prior,
        hyper=hyper,
        status="calibrated" if not reasons else "not converged: " + "; ".join(reasons),
        converged=not reasons,
        ess=dict(zip(labels, ess.tolist(), strict=True)),
        units=tuple(u.unit_id for u in used),
        evaluations=hyper_model.evaluations,
        seconds=0.0,
    )
    draws = hyper[np.linspace(0, len(hyper) - 1, settings.hyper_draws).round().astype(int)]
    posteriors = [_hierarchical(u, prior, hyper_model, draws, settings.seed) for u in units]
    population.seconds = time.perf_counter() - start_time
    return population, posteriors


def _log_own(unit: UnitPosterior, u: np.ndarray) -> np.ndarray:
    """Log density of samples u under the prior the unit was sampled with (in the prior's u:
    the same centre and SDs, widened), up to a constant of the unit."""
    return -0.5 * np.sum((u / unit.prior.widen) ** 2, axis=-1)


def _hierarchical(
    unit: UnitPosterior, prior: Prior, model: HyperModel, draws: np.ndarray, seed: int
) -> UnitPosterior:
    """The unit's samples reweighted by the population and resampled (seeded by its id)."""
    u = prior.to_u(unit.samples)
    w = reweighted(model, draws, u, _log_own(unit, u))
    rng = np.random.default_rng(unit_seed(seed, unit.unit_id, "hierarchical"))
    pick = rng.choice(len(u), size=len(u), p=w)
    kish = 1.0 / float(np.sum(w * w))
    return UnitPosterior(
        unit_id=unit.unit_id,
        logs=unit.logs,
        status=unit.status,
        names=unit.names,
        samples=unit.samples[pick],
        ess={n: min(e, kish) for n, e in unit.ess.items()},
        converged=unit.converged,
        reexpansions=unit.reexpansions,
        evaluations=unit.evaluations,
        seconds=unit.seconds,
        prior=unit.prior,
        learned=unit.learned,
        grid_weights=None if unit.grid_weights is None else unit.grid_weights[pick],
    )
