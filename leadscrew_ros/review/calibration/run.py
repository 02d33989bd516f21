# SPDX-License-Identifier: Apache-2.0
"""A whole calibration run: logs -> units -> per-unit posteriors -> the fleet's population ->
the held-out check (and, with both formulations, which one the data supports).

1. `gather.gather`: every input (log or replay output) to its observations, one Dask task each;
   `gather.by_unit` groups them into units (a unit's logs merged).
2. The units with observations are split, seeded (`CalibrationSettings.holdout`, the sampler's
   seed), into training and held-out units.
3. Per unit, one Dask task (`calibrate_task`): `sampling.calibrate_unit` (a unit with nothing
   to learn keeps the prior and says so; its seed derives from the run's and its unit id), and
   the heard frequencies matched with the unstable modes predicted at its posterior mean
   (`acoustics.agreement.MATCH_TOLERANCE`).
4. The population (`sampling.fit_population`) from the training units that were calibrated
   and converged, each unit's samples re-weighted to the bench's hearing learned from the
   other training units (`sampling.share_hearing`).
5. The held-out check: P(a heard squeak) at each distinct operating point of the held-out
   units (`heard_probabilities`: the share of the population's draws whose most unstable
   mode squeaks in the detector's band, the event the frames record), with the training
   units' population (`Population.params_and_scatter`) and with the prior; the Brier score
   over their frames, per unit and together, and the reliability curve (predicted P against
   the heard share of frames, in bins of P). Where every squeak mode lies in the band (the
   paper formulation's first bending modes) it is the node's P(squeak); the consistent
   formulation also squeaks unheard, above the band.
6. With both formulations, steps 3-5 (and 7) run for each, and the data's support (`compare`): the
   frequency match F (share of the heard frames, over all units, at an unstable mode predicted
   at the unit's posterior mean) and the held-out Brier score B with the calibrated
   population. When the F of the two differ by `FREQUENCY_DECISIVE` or more, the heard tones
   are at one formulation's modes and not the other's: that one is supported, 'strongly'
   unless B favours the other by `WEAK_Z` standard errors or more (then 'weakly, against the
   held-out score'). Then the growth-rate match G (share of the onsets' measured growth
   rates within two SDs of Re(lambda) at the unit's posterior mean) decides the same way.
   Otherwise the one with the lower B is supported; how strongly is the mean
   paired difference of B over the held-out units against its standard error z: 'strongly'
   at `STRONG_Z` or more, 'weakly' at `WEAK_Z` or more, else 'not distinguishably'.
7. The reported population (calibration.json, calibrated.yaml) is fitted again from every
   calibrated unit, the held-out ones included: the check of step 5 is done, and the held-out
   units' information narrows the fleet's estimate. The bench's hearing is shared again over
   all of them, from every unit's samples as drawn: a held-out unit left under the grid's
   prior would enter the fit (and be reported) with a posterior of another bench, widened and
   shifted by every threshold the prior allows (on a 16-unit paper bench it pulled the fleet's
   SD of ln damping from ~0.3 to 0.13, and the damping intervals covered 7 units of 16).
   Every calibrated unit's hierarchical posterior under it is the one reported.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...model import ScrewParameters, SqueakModel
from ...model.acoustics.agreement import MATCH_TOLERANCE, nearest_mode
from ...model.calibration import (
    CalibrationError,
    DetectionErrors,
    GrowthLikelihood,
    Observations,
    Prior,
    ThinSettings,
)
from ...model.calibration.amplitude import AmplitudeLikelihood, HearingPrior
from ...model.calibration.posterior import Population, UnitPosterior
from ...model.physics.parameters import ParameterError
from ...model.uncertainty.scatter import LIVE_SAMPLES, Scatter
from ..timeline import ModelSpec, predict_jobs
from .gather import Gathered, by_unit
from .sampling import SamplerSettings, calibrate_unit, fit_population, share_hearing, unit_seed
from .settings import CalibrationSettings

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# Fewer held-out units than this: the check says so. The held-out score's standard error (and
# the formulations' paired z) comes from the per-unit scatter: none from one unit, one degree
# of freedom from two (a single held-out unit went 0.007 -> 0.020, exit 0, no word: issue 31).
MIN_HELD_OUT = 3
STRONG_Z, WEAK_Z = 2.0, 1.0  # paired held-out Brier difference / its standard error
FREQUENCY_DECISIVE = 0.25  # a difference of the frequency match that decides alone
CALIBRATED = "calibrated"


# ---------------------------------------------------------------------- per unit (tasks)
def _model(spec: ModelSpec) -> SqueakModel:
    return SqueakModel(spec.params, Scatter(dict(spec.scatter)), spec.samples)


def heard_probabilities(
    spec: ModelSpec,
    obs: Observations,
    names: tuple[str, ...],
    errors: DetectionErrors,
    seed: int,
    hearing: HearingPrior | None = None,
    log_weight: np.ndarray | None = None,
) -> np.ndarray:
    """P(a heard squeak) for a held-out unit's frames under `spec`'s population: the share of
    `spec.samples` draws of `names` from its nominal values and scatter (seeded by `seed` and
    the unit) whose squeak the detector hears. With the frames in order, under the
    observation model (`AmplitudeLikelihood.heard_probability`, the bench's threshold and
    depth by `log_weight`), per scored frame; without, per distinct point where the most
    unstable mode squeaks in the detector's band (`GrowthLikelihood.squeaks`), nan where the
    model does not hold. Both expanded at the population's centre. The event the frames
    record: a squeak the detector cannot hear (above its band, the consistent formulation's
    T3 at ~13 kHz) is silence to it, so the node's P(squeak) of any mode would score a right
    prediction as a false alarm.

    Parameters
    ----------
    spec : ModelSpec
        The population (parameters, scatter, number of draws).
    obs : Observations
        A unit's frames.
    names : tuple of str
        The calibrated parameters (drawn; the others at `spec`'s values).
    errors : DetectionErrors
        The detector's band.
    seed : int
        The run's seed.
    hearing : HearingPrior, optional
        The observation model's grid; the defaults when None.
    log_weight : numpy.ndarray, optional
        The grid's weights (the bench's posterior); the prior's when None.

    Returns
    -------
    numpy.ndarray
        (rows, 3): P, frames, heard frames, per scored frame or distinct point.
    """
    model = _model(spec)
    prior = Prior(spec.params, model.scatter, names)
    growth = GrowthLikelihood(model, obs, names, errors)
    rng = np.random.default_rng(unit_seed(seed, obs.unit_id, "held-out"))
    theta = prior.from_u(prior.draw(spec.samples, rng))
    if not len(obs.sequence):
        p = np.where(growth.valid, growth.squeaks(theta).mean(axis=0), math.nan)
        return np.column_stack([p, obs.frames, obs.heard]).astype(float)
    likelihood = AmplitudeLikelihood(growth, hearing, log_weight)
    heard = obs.frame_heard[likelihood.scored]
    return np.column_stack(
        [likelihood.heard_probability(theta), np.ones(len(heard)), heard]
    ).astype(float)


def frequency_match(params: ScrewParameters, obs: Observations) -> tuple[int, int]:
    """How the heard frequencies match the unstable modes predicted at `params` (nominal, no
    scatter): a point's heard frames match when an unstable mode there lies within
    `MATCH_TOLERANCE` of its heard frequency.

    Parameters
    ----------
    params : ScrewParameters
        E.g. a unit's posterior mean.
    obs : Observations
        Its points.

    Returns
    -------
    tuple of (int, int)
        (heard frames matched, heard frames with a frequency).
    """
    idx = np.flatnonzero((obs.heard > 0) & np.isfinite(obs.heard_hz))
    if not idx.size:
        return 0, 0
    spec = ModelSpec(params, (), LIVE_SAMPLES)
    preds = predict_jobs(spec, obs.speed_rad_s[idx], obs.load_n[idx], obs.nut_position_m[idx])
    matched = 0
    for i, p in zip(idx.tolist(), preds, strict=True):
        f = float(obs.heard_hz[i])
        near = nearest_mode(f, [(m.label, m.frequency_hz) for m in p.squeak_modes])
        if near is not None and abs(near[1] - f) <= MATCH_TOLERANCE * f:
            matched += int(obs.heard[i])
    return matched, int(obs.heard[idx].sum())


def growth_match(
    params: ScrewParameters, obs: Observations, hearing: HearingPrior | None = None
) -> tuple[int, int]:
    """How the onsets' measured growth rates match Re(lambda) of the most unstable mode
    predicted at `params` (nominal, no scatter) at their frames' points: within two SDs of
    (A2)'s spread (`HearingPrior.onset_sd`); the resolved growths only, as in (A2).

    Parameters
    ----------
    params : ScrewParameters
        E.g. a unit's posterior mean.
    obs : Observations
        Its frames and onsets.
    hearing : HearingPrior, optional
        The model error of a rate; the defaults when None.

    Returns
    -------
    tuple of (int, int)
        (onsets matched, onsets at a point where the model holds).
    """
    if not len(obs.onsets) or not len(obs.sequence):
        return 0, 0
    hearing = hearing or HearingPrior()
    point = obs.sequence[obs.onsets[:, 0].astype(int)]
    keep = (point >= 0) & hearing.resolved(obs.onsets[:, 1], obs.onsets[:, 2])
    if not keep.any():
        return 0, 0
    idx = point[keep]
    spec = ModelSpec(params, (), LIVE_SAMPLES)
    preds = predict_jobs(spec, obs.speed_rad_s[idx], obs.load_n[idx], obs.nut_position_m[idx])
    sigma = np.array([math.nan if p.max_growth_rate is None else p.max_growth_rate for p in preds])
    rate, se = obs.onsets[keep, 1], obs.onsets[keep, 2]
    near = np.abs(rate - sigma) <= 2.0 * hearing.onset_sd(rate, se)
    return int(np.sum(near)), int(np.sum(np.isfinite(sigma)))


@dataclass
class UnitTask:
    """What a unit's task returns.

    Attributes
    ----------
    posterior : UnitPosterior or None
        The unit's own posterior (the prior's draws when it has nothing to learn); None when
        the calibration failed.
    status : str
        Its status, or why it failed.
    matched_frames, heard_frames : int
        `frequency_match` at the posterior mean.
    matched_onsets, onsets : int
        `growth_match` at the posterior mean.
    """

    posterior: UnitPosterior | None
    status: str
    matched_frames: int = 0
    heard_frames: int = 0
    matched_onsets: int = 0
    onsets: int = 0


def calibrate_task(
    spec: ModelSpec,
    obs: Observations,
    names: tuple[str, ...],
    errors: DetectionErrors,
    sampler: SamplerSettings,
    hearing: HearingPrior | None = None,
) -> UnitTask:
    """One unit (the body of a Dask task): `calibrate_unit` and, when it learned something,
    the frequency match at its posterior mean; what goes wrong is the unit's status, never an
    exception.

    Parameters
    ----------
    spec : ModelSpec
        The prior: nominal parameters, scatter, live samples.
    obs : Observations
        The unit's frames.
    names : tuple of str
        The calibrated parameters.
    errors : DetectionErrors
        The detection error model.
    sampler : SamplerSettings
        Walkers, steps, the run's seed.
    hearing : HearingPrior, optional
        The observation model's grid prior; the defaults when None.

    Returns
    -------
    UnitTask
    """
    try:
        post = calibrate_unit(_model(spec), obs, names, errors, sampler, hearing=hearing)
        if not post.learned or not len(post.samples):
            return UnitTask(post, post.status)
        mean = post.samples.mean(axis=0)
        try:
            params = spec.params.with_(
                **{n: float(v) for n, v in zip(post.names, mean, strict=True)}
            )
        except ParameterError:  # a mean outside the domain: no frequency to match there
            return UnitTask(post, post.status, 0, int(obs.heard.sum()))
        return UnitTask(
            post,
            post.status,
            *frequency_match(params, obs),
            *growth_match(params, obs, hearing),
        )
    except Exception as exc:  # this unit's reason, not the run's end
        return UnitTask(None, f"not calibrated: {type(exc).__name__}: {' '.join(str(exc).split())}")


@dataclass
class UnitResult:
    """One unit of a formulation's calibration.

    Attributes
    ----------
    unit_id : str
    logs : list of str
        Its inputs.
    status : str
        'calibrated', or why not (no sound, nothing to learn, not converged, ...).
    posterior : UnitPosterior or None
        Its own posterior (None without observations), its samples re-weighted to the bench's
        hearing learned from the other units of the fit it enters (`sampling.share_hearing`).
    sampled : UnitPosterior or None
        Its posterior as sampled, under the prior of the hearing grid: what `posterior` is
        re-weighted from, for each fit anew.
    hierarchical : UnitPosterior or None
        Its population-informed posterior (a training unit in the population fit).
    held_out : bool
        Held out of the population fit.
    observations : Observations or None
    matched_frames, heard_frames : int
        The frequency match at its posterior mean.
    matched_onsets, onsets : int
        The growth-rate match at its posterior mean.
    """

    unit_id: str
    logs: list[str]
    status: str
    posterior: UnitPosterior | None = None
    sampled: UnitPosterior | None = None
    hierarchical: UnitPosterior | None = None
    held_out: bool = False
    observations: Observations | None = None
    matched_frames: int = 0
    heard_frames: int = 0
    matched_onsets: int = 0
    onsets: int = 0

    @property
    def reported(self) -> UnitPosterior | None:
        """The posterior in calibration.json: the hierarchical one where there is one."""
        return self.hierarchical or self.posterior

    @property
    def calibrated(self) -> bool:
        """Calibrated, and its sampler converged."""
        return self.status == CALIBRATED

    def identifiability(self) -> dict[str, Any] | None:
        """What the unit's own data identified (before the population narrows it).

        Returns
        -------
        dict or None
            `UnitPosterior.identifiability` of its own posterior; None when it learned
            nothing.
        """
        post = self.posterior
        if post is None or not post.learned or not len(post.samples):
            return None
        return post.identifiability()

    def as_dict(self) -> dict[str, Any]:
        """calibration.json's unit.

        Returns
        -------
        dict
            unit_id, logs, status, posterior (the reported one's summary, None without),
            own (its own posterior's summary: what its data say, before the population),
            held_out, identifiability (`identifiability`), convergence.
        """
        post = self.reported
        return {
            "unit_id": self.unit_id,
            "logs": self.logs,
            "status": self.status,
            "posterior": post.summary() if post is not None else None,
            "own": self.posterior.summary() if self.posterior is not None else None,
            "held_out": self.held_out,
            "identifiability": self.identifiability(),
            "convergence": None
            if post is None
            else {
                "ess": post.ess,
                "converged": post.converged,
                "reexpansions": post.reexpansions,
                "evaluations": post.evaluations,
                "posterior": "hierarchical" if self.hierarchical is not None else "unit",
            },
        }


@dataclass
class HeldOut:
    """The held-out check of one formulation.

    Attributes
    ----------
    units : list of str
        The held-out units (with observations).
    frames : int
        Their frames counted (at valid operating points of both models).
    brier_prior, brier_calibrated : float or None
        Brier score of P(squeak) over those frames (None without held-out frames).
    per_unit : dict of str to (float, float)
        Unit -> (prior, calibrated) Brier score.
    points : numpy.ndarray
        Rows (P prior, P calibrated, frames, heard) of every scored frame (or distinct point,
        for observations without their order).
    background : tuple of (int, int)
        (heard, frames) of the held-out units' frames with the motor off: the detector's own
        false alarms in the room (no squeak can be there).
    frequency_match : tuple of (float or None, float or None)
        Share of the held-out units' heard frames (with a frequency) at an unstable mode of the
        prior's and of the calibrated population's centre (`frequency_match`); None when
        nothing was heard.
    """

    units: list[str] = field(default_factory=list)
    frames: int = 0
    brier_prior: float | None = None
    brier_calibrated: float | None = None
    per_unit: dict[str, tuple[float, float]] = field(default_factory=dict)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    background: tuple[int, int] = (0, 0)
    frequency_match: tuple[float | None, float | None] = (None, None)

    def warnings(self) -> list[str]:
        """What makes the check weak or bad: fewer than `MIN_HELD_OUT` units held out, or
        the calibrated population scoring worse than the prior ([] when neither).

        Returns
        -------
        list of str
            One line each.
        """
        out = []
        if len(self.units) < MIN_HELD_OUT:
            out.append(
                f"only {len(self.units)} units held out (fewer than {MIN_HELD_OUT}): the "
                "held-out check says little; hold out more (--holdout) or add units"
            )
        a, b = self.brier_prior, self.brier_calibrated
        if a is not None and b is not None and b > a:
            worse = sum(c > p for p, c in self.per_unit.values())
            out.append(
                f"the calibrated population predicts the held-out units worse than the prior "
                f"(Brier score {b:.3f} > {a:.3f}; {worse} of {len(self.per_unit)} units worse)"
            )
        return out

    def reliability(self, bins: int) -> dict[str, list[dict[str, float]]]:
        """Predicted P against the heard share of frames, in equal bins of P.

        Parameters
        ----------
        bins : int
            Bins over [0, 1].

        Returns
        -------
        dict
            'prior' and 'calibrated': per non-empty bin the frame-weighted mean P ('p'), the
            heard share of its frames ('heard') and its frames ('frames').
        """
        out: dict[str, list[dict[str, float]]] = {}
        frames, heard = self.points[:, 2], self.points[:, 3]
        for col, key in ((0, "prior"), (1, "calibrated")):
            p = self.points[:, col]
            k = np.minimum((p * bins).astype(int), bins - 1)
            rows = []
            for b in range(bins):
                sel = k == b
                n = float(frames[sel].sum())
                if n > 0:
                    rows.append(
                        {
                            "p": float((p[sel] * frames[sel]).sum() / n),
                            "heard": float(heard[sel].sum() / n),
                            "frames": n,
                        }
                    )
            out[key] = rows
        return out


def brier(p: np.ndarray, frames: np.ndarray, heard: np.ndarray) -> float:
    """Brier score over frames: at a point with P, `heard` frames score (1 - P)^2 and the
    others P^2."""
    return float(np.sum(heard * (1 - p) ** 2 + (frames - heard) * p**2) / np.sum(frames))


def held_out_check(
    units: list[UnitResult],
    prior: list[np.ndarray],
    calibrated: list[np.ndarray],
    matches: list[tuple[tuple[int, int], tuple[int, int]]] | None = None,
) -> HeldOut:
    """The held-out check from each held-out unit's rows (P, frames, heard) of
    `heard_probabilities` (prior, calibrated) and its `frequency_match` at the prior's and the
    calibrated population's centres."""
    rows, per_unit = [], {}
    for u, pp, pc in zip(units, prior, calibrated, strict=True):
        ok = np.isfinite(pp[:, 0]) & np.isfinite(pc[:, 0])
        if not ok.any():
            continue
        f, h = pp[ok, 1], pp[ok, 2]
        per_unit[u.unit_id] = (brier(pp[ok, 0], f, h), brier(pc[ok, 0], f, h))
        rows.append(np.column_stack([pp[ok, 0], pc[ok, 0], f, h]))
    off = [u.observations for u in units if u.observations is not None]
    background = (
        sum(o.motor_off_heard for o in off),
        sum(o.motor_off_frames for o in off),
    )
    matched = [sum(m[k][0] for m in matches or []) for k in (0, 1)]
    heard = sum(m[0][1] for m in matches or [])
    match = (matched[0] / heard, matched[1] / heard) if heard else (None, None)
    if not rows:
        return HeldOut([u.unit_id for u in units], background=background, frequency_match=match)
    pts = np.concatenate(rows)
    return HeldOut(
        [u.unit_id for u in units],
        int(pts[:, 2].sum()),
        brier(pts[:, 0], pts[:, 2], pts[:, 3]),
        brier(pts[:, 1], pts[:, 2], pts[:, 3]),
        per_unit,
        pts,
        background,
        match,
    )


@dataclass
class FormulationRun:
    """The calibration with one formulation.

    Attributes
    ----------
    formulation : str
    prior : ModelSpec
        The prior: nominal parameters (of this formulation), scatter, live samples.
    units : list of UnitResult
        Every unit, in order of first appearance.
    population : Population or None
        The fleet's population (None with fewer than two usable training units).
    population_status : str
        'calibrated', or why there is no (converged) population.
    params : ScrewParameters or None
        The calibrated nominal parameters (`Population.params_and_scatter`).
    scatter : Scatter or None
        The calibrated scatter (the prior's for the parameters not calibrated).
    held_out : HeldOut
    notes : list of str
        What `params` and `scatter` clipped to the valid ranges (`Population.notes`).
    hearing : numpy.ndarray or None
        (Kd, Kh) the bench's log posterior over the observation model's grid of detection
        threshold and floor depth, from the units of the reported population (all calibrated
        units; the training units' during the held-out check) (`sampling.share_hearing`); None
        without that model.
    """

    formulation: str
    prior: ModelSpec
    units: list[UnitResult]
    population: Population | None = None
    population_status: str = ""
    params: ScrewParameters | None = None
    scatter: Scatter | None = None
    held_out: HeldOut = field(default_factory=HeldOut)
    notes: list[str] = field(default_factory=list)
    hearing: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        """A converged population and no unit whose sampler did not converge."""
        return (
            self.population is not None
            and self.population_status == CALIBRATED
            and not any(u.status.startswith("not converged") for u in self.units)
        )

    @property
    def frequency_match(self) -> float | None:
        """Share of the heard frames (with a frequency) of the calibrated units matched by an
        unstable mode at their posterior mean; None when nothing was heard."""
        heard = sum(u.heard_frames for u in self.units)
        return sum(u.matched_frames for u in self.units) / heard if heard else None

    @property
    def growth_match(self) -> float | None:
        """Share of the measured onset growth rates of the calibrated units within two SDs of
        Re(lambda) at their posterior mean (`growth_match`); None without onsets."""
        onsets = sum(u.onsets for u in self.units)
        return sum(u.matched_onsets for u in self.units) / onsets if onsets else None

    @property
    def score(self) -> float | None:
        """The held-out Brier score with the calibrated population (lower is better)."""
        return self.held_out.brier_calibrated


@dataclass
class Comparison:
    """Which formulation the data supports (module docstring, step 6: the rule).

    Attributes
    ----------
    supported : str or None
        None without a held-out score or a frequency match for both.
    strength : str
        'strongly', 'weakly', 'weakly, against the held-out score', 'not distinguishably',
        or why there is no comparison.
    decided_by : str
        'frequency match' or 'held-out score' ('' without a comparison).
    z : float or None
        Mean paired held-out Brier difference (other - supported) over its standard error.
    """

    supported: str | None
    strength: str
    decided_by: str = ""
    z: float | None = None


def _paired_z(a: FormulationRun, b: FormulationRun) -> float | None:
    """Mean paired held-out Brier difference (b - a) over its standard error (inf or 0 when
    the differences do not scatter); None without a common held-out unit."""
    pa, pb = a.held_out.per_unit, b.held_out.per_unit
    d = np.array([pb[u][1] - pa[u][1] for u in pa if u in pb])
    if not d.size:
        return None
    sd = float(np.std(d, ddof=1)) if d.size >= 2 else 0.0
    if sd > 0:
        return float(d.mean() / (sd / math.sqrt(d.size)))
    return math.inf if d.mean() > 0 else -math.inf if d.mean() < 0 else 0.0


def compare(runs: dict[str, FormulationRun]) -> Comparison:
    """The module's rule (step 6) over two formulations' runs.

    Parameters
    ----------
    runs : dict of str to FormulationRun
        The two formulations' calibrations.

    Returns
    -------
    Comparison
    """
    (na, a), (nb, b) = runs.items()
    for label, (ma, mb) in (
        ("frequency match", (a.frequency_match, b.frequency_match)),
        ("growth-rate match", (a.growth_match, b.growth_match)),
    ):
        if ma is not None and mb is not None and abs(ma - mb) >= FREQUENCY_DECISIVE:
            best, other = (na, nb) if ma > mb else (nb, na)
            z = _paired_z(runs[best], runs[other])
            against = z is not None and z <= -WEAK_Z
            return Comparison(
                best,
                "weakly, against the held-out score" if against else "strongly",
                label,
                _finite(z),
            )
    if a.score is None or b.score is None:
        return Comparison(
            None,
            "no held-out score for both formulations and no decisive frequency or growth-rate "
            "match",
        )
    best, other = (na, nb) if (a.score, na) <= (b.score, nb) else (nb, na)
    z = _paired_z(runs[best], runs[other])
    zz = 0.0 if z is None else z
    strength = "strongly" if zz >= STRONG_Z else "weakly" if zz >= WEAK_Z else "not distinguishably"
    return Comparison(best, strength, "held-out score", _finite(z))


def _finite(z: float | None) -> float | None:
    return z if z is not None and math.isfinite(z) else None


@dataclass
class CalibrationResult:
    """A calibration run (`calibrate`): per formulation its units, population and held-out
    check; the one reported (the supported one with both); what was read.

    Attributes
    ----------
    runs : dict of str to FormulationRun
    chosen : str
        The formulation of the reported units, population and calibrated.yaml.
    comparison : Comparison or None
        With both formulations.
    gathered : list of Gathered
        Every input, read.
    settings : CalibrationSettings
    wall_s : float
        Wall time of the run [s].
    """

    runs: dict[str, FormulationRun]
    chosen: str
    comparison: Comparison | None
    gathered: list[Gathered]
    settings: CalibrationSettings
    wall_s: float = math.nan

    @property
    def run(self) -> FormulationRun:
        """The reported formulation's run."""
        return self.runs[self.chosen]

    @property
    def unusable(self) -> list[Gathered]:
        """Inputs that gave no observations."""
        return [g for g in self.gathered if g.observations is None]

    @property
    def converged(self) -> bool:
        """The reported formulation converged (`FormulationRun.converged`); with both
        formulations and none supported, both. The other formulation's non-convergence,
        once one is supported, is reported, not the run's failure: its numbers are not used."""
        if self.comparison is not None and self.comparison.supported is None:
            return all(r.converged for r in self.runs.values())
        return self.run.converged

    def plot(self, fig: Figure | None = None) -> Figure:
        """calibration.png (`plots.plot_calibration`).

        Parameters
        ----------
        fig : Figure, optional
            The figure to draw into; default: a new figure.

        Returns
        -------
        Figure
        """
        from ..plots import plot_calibration

        return plot_calibration(self, fig=fig)


# ---------------------------------------------------------------------- the run
def _split(units: list[str], fraction: float, seed: int) -> set[str]:
    """The held-out units: round(fraction * n) of them, at least one left for training,
    drawn with `seed` (independent of the order the units came in)."""
    n_out = min(int(round(fraction * len(units))), max(len(units) - 1, 0))
    pick = np.random.default_rng(seed).permutation(len(units))[:n_out]
    ordered = sorted(units)
    return {ordered[i] for i in pick.tolist()}


def _not_converged(post: UnitPosterior) -> str:
    low = {n: v for n, v in post.ess.items() if not (v == v and v > 0)}
    ess = ", ".join(f"{n} {v:.0f}" for n, v in post.ess.items() if v == v)
    return (
        "not converged"
        + (f" (effective sample size {ess})" if ess else "")
        + (f"; no estimate for {', '.join(low)}" if low else "")
    )


def population_task(
    spec: ModelSpec, posteriors: list[UnitPosterior], sampler: SamplerSettings
) -> tuple[Population | None, list[UnitPosterior], str]:
    """The population of the training units (the body of a Dask task): `fit_population`,
    or why there is none, never an exception.

    Parameters
    ----------
    spec : ModelSpec
        The prior the units were calibrated with.
    posteriors : list of UnitPosterior
        The training units' own posteriors.
    sampler : SamplerSettings
        The population sampler's settings.

    Returns
    -------
    tuple of (Population or None, list of UnitPosterior, str)
        The population, the units' hierarchical posteriors (in order), its status.
    """
    if len(posteriors) < 2:
        return (
            None,
            [],
            (f"no population: {len(posteriors)} calibrated training unit(s), at least 2 needed"),
        )
    try:
        population, hierarchical = fit_population(posteriors, _model(spec), sampler)
    except Exception as exc:  # the run's reason, not its end
        return None, [], f"no population: {' '.join(str(exc).split())}"
    return population, hierarchical, population.status


def _units(
    formulation: str,
    prior: SqueakModel,
    units: dict[str, tuple[list[Gathered], Observations | None, str]],
    held: set[str],
) -> FormulationRun:
    spec = ModelSpec(
        prior.params.with_(formulation=formulation),
        tuple(prior.scatter.sd.items()),
        prior.sample_count,
    )
    results = [
        UnitResult(
            unit_id,
            [g.log for g in items],
            reasons or "no observations",
            held_out=unit_id in held,
            observations=obs,
        )
        for unit_id, (items, obs, reasons) in units.items()
    ]
    return FormulationRun(formulation, spec, results)


def _result(future: Any) -> Any:
    """A task's result, or the exception when the task did not finish (its workers died)."""
    try:
        return future.result()
    except Exception as exc:
        return exc


def _failed(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"


def _calibrate_runs(runs: list[FormulationRun], settings: CalibrationSettings, client: Any) -> None:
    """Steps 3-5 of the module for every formulation on `client`'s cluster: each step's tasks
    of all formulations submitted together, so that the workers never wait for one."""
    futures = [
        {
            u.unit_id: client.submit(
                calibrate_task,
                run.prior,
                u.observations,
                settings.names,
                settings.errors,
                settings.sampler,
                settings.hearing,
                pure=False,
            )
            for u in run.units
            if u.observations is not None
        }
        for run in runs
    ]
    for run, tasks in zip(runs, futures, strict=True):
        for u in run.units:
            if u.unit_id in tasks:
                task = _result(tasks[u.unit_id])
                if isinstance(task, BaseException):
                    u.status = f"not calibrated: {_failed(task)}"
                    continue
                u.posterior = u.sampled = task.posterior
                u.status = task.status
                u.matched_frames, u.heard_frames = task.matched_frames, task.heard_frames
                u.matched_onsets, u.onsets = task.matched_onsets, task.onsets
    training = [[u for u in run.units if u.calibrated and not u.held_out] for run in runs]
    for run, units in zip(runs, training, strict=True):
        run.hearing = _share(units, settings)
    fits = _fit_populations(runs, training, settings, client)
    for run, units, done in zip(runs, training, fits, strict=True):
        if isinstance(done, BaseException):
            run.population_status = f"no population: {_failed(done)}"
            continue
        _install(run, units, done)
    checks: list[tuple[list[UnitResult], list[tuple[Any, Any]]]] = []
    for run in runs:
        held = [u for u in run.units if u.held_out and u.observations is not None]
        if run.params is None or run.scatter is None or not held:
            checks.append((held, []))
            continue
        calibrated = ModelSpec(run.params, tuple(run.scatter.sd.items()), run.prior.samples)
        checks.append(
            (
                held,
                [
                    tuple(
                        client.submit(
                            heard_probabilities,
                            spec,
                            u.observations,
                            settings.names,
                            settings.errors,
                            settings.sampler.seed,
                            settings.hearing,
                            run.hearing,
                            pure=False,
                        )
                        for spec in (run.prior, calibrated)
                    )
                    + tuple(
                        client.submit(frequency_match, spec.params, u.observations, pure=False)
                        for spec in (run.prior, calibrated)
                    )
                    for u in held
                ],
            )
        )
    for run, (held, jobs) in zip(runs, checks, strict=True):
        if not jobs:
            run.held_out = HeldOut([u.unit_id for u in held])
            continue
        p = [tuple(_result(f) for f in job) for job in jobs]
        if any(isinstance(x, BaseException) for job in p for x in job):
            run.held_out = HeldOut([u.unit_id for u in held])
            continue
        run.held_out = held_out_check(
            held, [j[0] for j in p], [j[1] for j in p], [(j[2], j[3]) for j in p]
        )
    _populations_of_all(runs, settings, client)


def _share(units: list[UnitResult], settings: CalibrationSettings) -> np.ndarray | None:
    """The bench's hearing from `units` (`sampling.share_hearing`), and each unit's posterior
    re-weighted to it from its samples as drawn: the units of a population fit share one
    bench, each under the others' hearing. Returns the bench's grid log posterior."""
    own = [u for u in units if u.sampled is not None]
    hearing, shared = share_hearing(
        [u.sampled for u in own if u.sampled is not None], settings.hearing, settings.sampler.seed
    )
    for u, post in zip(own, shared, strict=True):
        u.posterior = post
    return hearing


def _fit_populations(
    runs: list[FormulationRun],
    unit_sets: Sequence[list[UnitResult] | None],
    settings: CalibrationSettings,
    client: Any,
) -> list[Any]:
    """Each run's population from its set of units (None: no fit), all submitted together:
    per run `population_task`'s result, the exception that ended it, or None."""
    futures = [
        None
        if units is None
        else client.submit(
            population_task,
            run.prior,
            [u.posterior for u in units],
            settings.sampler,
            pure=False,
        )
        for run, units in zip(runs, unit_sets, strict=True)
    ]
    return [None if f is None else _result(f) for f in futures]


def _install(run: FormulationRun, units: list[UnitResult], done: tuple) -> None:
    """`population_task`'s result `done` as the run's population, with the hierarchical
    posteriors of `units` (the units it was fitted from, in order) and none for the others."""
    run.population, hierarchical, run.population_status = done
    for u in run.units:
        u.hierarchical = None
    for u, h in zip(units, hierarchical, strict=False):
        u.hierarchical = h
    if run.population is not None:
        run.params, run.scatter = run.population.params_and_scatter(run.prior.params)
        run.notes = run.population.notes(run.prior.params)


def _populations_of_all(
    runs: list[FormulationRun], settings: CalibrationSettings, client: Any
) -> None:
    """Step 7: the reported population from every calibrated unit, the held-out ones too
    (their check is done; leaving them out would only widen the fleet's estimate); where that
    fit fails, the training units' population stays, and says so."""
    every = [
        [u for u in run.units if u.calibrated]
        if run.population is not None and any(u.held_out and u.calibrated for u in run.units)
        else None
        for run in runs
    ]
    training = [
        (run.hearing, [u.posterior for u in run.units]) for run in runs
    ]  # kept where the fit of all units fails
    for run, units in zip(runs, every, strict=True):
        if units is not None:  # the held-out units' samples too are the bench's, not the prior's
            run.hearing = _share(units, settings)
    fits = _fit_populations(runs, every, settings, client)
    for run, units, done, (hearing, own) in zip(runs, every, fits, training, strict=True):
        if units is None:
            continue
        if isinstance(done, BaseException) or done[0] is None:
            why = _failed(done) if isinstance(done, BaseException) else done[2]
            run.population_status += f" (of the training units; with all units: {why})"
            run.hearing = hearing
            for u, post in zip(run.units, own, strict=True):
                u.posterior = post
            continue
        _install(run, units, done)


def calibrate(
    gathered: list[Gathered],
    prior: SqueakModel,
    settings: CalibrationSettings,
    client: Any,
    thin: ThinSettings | None = None,
) -> CalibrationResult:
    """The module's steps 2-6 over what `gather.gather` read.

    Parameters
    ----------
    gathered : list of Gathered
        Every input, read.
    prior : SqueakModel
        The prior: nominal parameters and scatter (its formulation is replaced by each one
        calibrated), live sample count.
    settings : CalibrationSettings
        What is calibrated and how.
    client : distributed.Client
        Of the cluster that runs the units' tasks.
    thin : ThinSettings, optional
        The bins the inputs were thinned with (`GatherSettings.thin`), for merging a unit's.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    CalibrationError
        No input gave observations.
    """
    t0 = time.perf_counter()
    units = by_unit(gathered, thin)
    usable = [u for u, (_, obs, _) in units.items() if obs is not None]
    if not usable:
        reasons = "; ".join(f"{g.source}: {g.reason}" for g in gathered[:3])
        more = f" (and {len(gathered) - 3} more)" if len(gathered) > 3 else ""
        raise CalibrationError(f"nothing to calibrate from: {reasons}{more}")
    held = _split(usable, settings.holdout, settings.sampler.seed)
    runs = {f: _units(f, prior, units, held) for f in settings.formulations}
    _calibrate_runs(list(runs.values()), settings, client)
    comparison = compare(runs) if len(runs) > 1 else None
    chosen = (
        comparison.supported
        if comparison is not None and comparison.supported is not None
        else settings.formulations[0]
    )
    return CalibrationResult(runs, chosen, comparison, gathered, settings, time.perf_counter() - t0)
