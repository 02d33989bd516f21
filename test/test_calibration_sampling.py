# SPDX-License-Identifier: Apache-2.0
"""The calibration's samplers (review/calibration): a synthetic fleet drawn from a population
unlike the prior (larger friction drop, smaller damping; exact verdicts along seat strokes,
frames flipped by the error model), each unit's posterior and the hierarchical population
against the hidden truth; the answer independent of the expansion centre; determinism;
nothing to learn; not converged; what a params file gets."""

from __future__ import annotations

import numpy as np
import pytest

from harness.calibration import POPULATION, synthetic_unit
from leadscrew_ros.model import ParameterError, ScrewParameters, SqueakModel
from leadscrew_ros.model.calibration import CalibrationError, Observations, Prior
from leadscrew_ros.model.calibration.prior import DEFAULT_NAMES
from leadscrew_ros.model.uncertainty.scatter import Scatter
from leadscrew_ros.review.calibration import (
    Population,
    SamplerSettings,
    calibrate_unit,
    fit_population,
    unit_seed,
)

# The module fixtures sample a synthetic fleet of 20 units: a minute or more on a loaded
# 2-core machine. The timeout is there to catch a hang, not to time the work.
pytestmark = pytest.mark.timeout(900)

NOMINAL = ScrewParameters()
MODEL = SqueakModel(NOMINAL)  # the prior: Table 1 and the default scatter
UNITS = 20
STROKE_S = 12.0  # the bench stroke
TRUE_DROP = POPULATION.mu_static - POPULATION.mu_kinetic  # 0.07; the prior's is 0.05
FAST = SamplerSettings(walkers=16, steps=120, first_steps=80, burn=40, max_reexpansions=1)
# The fleet's sampling: fewer walkers and steps than the defaults (the same rules, an ESS of
# ~250 per name), so the 20 units take half a minute
FLEET = SamplerSettings(walkers=24, steps=450, first_steps=225, burn=125)


def covers(summary: dict, value: float) -> bool:
    return summary["q05"] <= value <= summary["q95"]


@pytest.fixture(scope="module")
def fleet():
    """UNITS synthetic units, each calibrated (FLEET settings), and the population."""
    units = [
        synthetic_unit(f"fleet-{i:02d}", np.random.default_rng([51, i]), duration_s=STROKE_S)
        for i in range(UNITS)
    ]
    posteriors = [calibrate_unit(MODEL, u.obs, settings=FLEET) for u in units]
    population, hierarchical = fit_population(posteriors, MODEL, FLEET)
    return units, posteriors, population, hierarchical


@pytest.fixture(scope="module")
def one_unit():
    """A unit of a 6-s stroke (quick to sample)."""
    return synthetic_unit("single", np.random.default_rng(11), duration_s=6.0)


def test_every_unit_is_calibrated_and_its_interval_covers_the_truth(fleet):
    """The 90 % interval of each unit's friction drop covers its hidden truth in >= 80 % of
    the units (measured 100 %: the interim prior and the effective counts err wide)."""
    units, posteriors, _, _ = fleet
    assert [p.status for p in posteriors] == ["calibrated"] * UNITS
    assert all(p.converged and p.learned and min(p.ess.values()) >= 100 for p in posteriors)
    hits = [
        covers(p.summary()["friction_drop"], u.truth.mu_static - u.truth.mu_kinetic)
        for u, p in zip(units, posteriors, strict=True)
    ]
    assert np.mean(hits) >= 0.8


def test_the_units_learn_from_the_frames(fleet):
    """Each unit's posterior of the friction drop is narrower than its interim prior's and
    every summary is ordered."""
    _, posteriors, _, _ = fleet
    interim = posteriors[0].prior
    drop = np.diff(interim.from_u(interim.draw(20000, np.random.default_rng(0)))[:, 1::-1])
    interim_width = np.subtract(*np.quantile(drop, (0.95, 0.05)))
    for p in posteriors:
        s = p.summary()
        assert set(s) == {*DEFAULT_NAMES, "friction_drop"}
        for v in s.values():
            assert v["q05"] <= v["q50"] <= v["q95"] and v["sd"] > 0
        assert s["friction_drop"]["q95"] - s["friction_drop"]["q05"] < 0.8 * interim_width


def test_the_population_finds_the_fleet_unlike_the_prior(fleet):
    """The fleet mean of mu_s - mu_k: its 90 % interval covers the truth, lies above the
    prior's value and is at most half as wide as the prior's 90 % interval of the drop.

    A 90 % interval misses in one fleet in ten by design: of seven fleets of this kind
    measured (12-s strokes), six covered (the seventh's own 20 truths averaged 2.3 of their
    standard errors below the population's), widths 0.015-0.024 against the limit 0.026."""
    _, _, population, _ = fleet
    assert population.status == "calibrated" and population.converged
    assert len(population.units) == UNITS
    drop = population.summary()["friction_drop"]["mean"]
    prior = Prior(NOMINAL, Scatter(), DEFAULT_NAMES)
    prior_drop = np.diff(prior.from_u(prior.draw(20000, np.random.default_rng(1)))[:, 1::-1])
    prior_width = np.subtract(*np.quantile(prior_drop, (0.95, 0.05)))
    assert covers(drop, TRUE_DROP)
    assert drop["q05"] > NOMINAL.mu_static - NOMINAL.mu_kinetic
    assert drop["q95"] - drop["q05"] <= 0.5 * prior_width
    damping = population.summary()["modal_damping"]["mean"]
    assert covers(damping, POPULATION.modal_damping)


def test_the_hierarchical_posteriors_cover_the_truth(fleet):
    """Population-informed posteriors: narrower than the units' own, still covering."""
    units, posteriors, _, hierarchical = fleet
    assert [h.unit_id for h in hierarchical] == [p.unit_id for p in posteriors]
    width = [
        (lambda s: s["q95"] - s["q05"])(p.summary()["friction_drop"])
        for p in (*posteriors, *hierarchical)
    ]
    assert np.median(width[UNITS:]) < np.median(width[:UNITS])
    hits = [
        covers(h.summary()["friction_drop"], u.truth.mu_static - u.truth.mu_kinetic)
        for u, h in zip(units, hierarchical, strict=True)
    ]
    assert np.mean(hits) >= 0.8


def test_the_population_as_a_params_file(fleet):
    """Nominal values at the predictive centre, scatter the predictive SDs: a model loads
    them, and they say what the fleet is (more drop, less damping than the prior)."""
    _, _, population, _ = fleet
    params, scatter = population.params_and_scatter(NOMINAL)
    assert population.notes(NOMINAL) == []
    centre, sd = population.predictive()
    assert [getattr(params, n) for n in DEFAULT_NAMES] == pytest.approx(centre.tolist())
    assert scatter.sd["modal_damping"] == pytest.approx(sd[3])  # SD of ln
    assert scatter.sd["mu_static"] == pytest.approx(sd[0] / centre[0])  # relative SD
    assert params.mu_static - params.mu_kinetic > NOMINAL.mu_static - NOMINAL.mu_kinetic
    assert params.modal_damping < NOMINAL.modal_damping
    assert SqueakModel(params, scatter).predict(20.0, 200.0).probability is not None


def test_the_population_fit_is_reproducible(fleet):
    _, posteriors, population, hierarchical = fleet
    again, rehier = fit_population(posteriors, MODEL, FLEET)
    assert np.array_equal(again.hyper, population.hyper)
    assert all(
        np.array_equal(a.samples, b.samples) for a, b in zip(hierarchical, rehier, strict=True)
    )


def test_the_answer_does_not_depend_on_the_expansion_centre(one_unit):
    """Started from an expansion two prior SDs off in friction and one in damping, the
    re-expanded posterior is the one started at the prior's centre, within sampling error."""
    start = NOMINAL.with_(mu_static=0.275, mu_kinetic=0.18, modal_damping=0.0021)
    a = calibrate_unit(MODEL, one_unit.obs)
    b = calibrate_unit(MODEL, one_unit.obs, centre=start)
    assert a.status == b.status == "calibrated"
    sa, sb = a.summary(), b.summary()
    for k, name in enumerate(DEFAULT_NAMES):
        error = sa[name]["sd"] * np.sqrt(1 / a.ess[name] + 1 / b.ess[name])
        assert abs(sa[name]["mean"] - sb[name]["mean"]) < 4 * error + 0.05 * sa[name]["sd"], name
        assert sb[name]["sd"] == pytest.approx(sa[name]["sd"], rel=0.25), name
        assert not np.array_equal(a.samples[:, k], b.samples[:, k])


def test_the_same_seed_gives_the_same_samples_in_any_order(one_unit):
    """Each unit's seed comes from the run's seed and its id, not the order of execution."""
    other_unit = synthetic_unit("other", np.random.default_rng(12), duration_s=6.0)
    first = [calibrate_unit(MODEL, u.obs, settings=FAST) for u in (one_unit, other_unit)]
    second = [calibrate_unit(MODEL, u.obs, settings=FAST) for u in (other_unit, one_unit)][::-1]
    for a, b in zip(first, second, strict=True):
        assert np.array_equal(a.samples, b.samples) and a.ess == b.ess
    other = calibrate_unit(
        MODEL, one_unit.obs, settings=SamplerSettings(**{**FAST.__dict__, "seed": 1})
    )
    assert not np.array_equal(other.samples, first[0].samples)
    assert unit_seed(0, "a").entropy == unit_seed(0, "a").entropy != unit_seed(0, "b").entropy


def never_heard(speed: float, frames: int = 600) -> Observations:
    return Observations(
        unit_id=f"quiet-{speed:g}",
        logs=("quiet.mcap",),
        speed_rad_s=np.array([speed]),
        load_n=np.array([200.0]),
        nut_position_m=np.array([0.1]),
        frames=np.array([frames]),
        heard=np.array([0]),
        heard_hz=np.array([np.nan]),
        frame_s=0.01,
    )


@pytest.mark.parametrize(
    "speed, reason", [(200.0, "never heard, and no prior draw"), (0.2, "no logged operating point")]
)
def test_nothing_to_learn_keeps_the_prior(speed, reason, fleet):
    """Far above the band (no prior draw squeaks there) or below the valid speed: the unit
    says so, keeps the prior, and the population ignores it."""
    quiet = calibrate_unit(MODEL, never_heard(speed))
    assert quiet.status.startswith("nothing to learn: " + reason), quiet.status
    assert not quiet.learned and quiet.prior.widen == 1.0
    prior_sd = Prior(NOMINAL, Scatter(), DEFAULT_NAMES).field_sd
    s = quiet.summary()
    for k, name in enumerate(DEFAULT_NAMES):
        if name != "modal_damping":
            assert s[name]["mean"] == pytest.approx(getattr(NOMINAL, name), abs=0.1 * prior_sd[k])
            assert s[name]["sd"] == pytest.approx(prior_sd[k], rel=0.1)
    population, hierarchical = fit_population([*fleet[1][:3], quiet], MODEL, FAST)
    assert quiet.unit_id not in population.units and len(population.units) == 3
    assert hierarchical[-1].status == quiet.status
    with pytest.raises(CalibrationError, match="no unit has anything to learn"):
        fit_population([quiet], MODEL)


def test_a_short_run_says_it_did_not_converge(one_unit):
    short = SamplerSettings(walkers=8, steps=30, first_steps=25, burn=10, max_reexpansions=0)
    post = calibrate_unit(MODEL, one_unit.obs, settings=short)
    assert post.status.startswith("not converged: ") and not post.converged
    assert "autocorrelation times" in post.status or "ESS" in post.status
    assert len(post.samples) > 0 and post.learned


class ScriptedSampler:
    """An ensemble whose walkers' positions in u are scripted per run: N(mean, 0.3) in every
    name, the mean per step from `means(step)` (what `_ensemble` returns, in its place)."""

    def __init__(self, walkers: int, dims: int, means, rng: np.random.Generator):
        self.walkers, self.dims, self.means, self.rng = walkers, dims, means, rng
        self.steps: list[np.ndarray] = []

    def run_mcmc(self, position, steps: int) -> None:
        for _ in range(steps):
            mean = self.means(len(self.steps))
            self.steps.append(mean + 0.3 * self.rng.standard_normal((self.walkers, self.dims)))

    def get_chain(self, discard: int = 0) -> np.ndarray:
        return np.array(self.steps[discard:])

    def get_last_sample(self):
        return type("State", (), {"coords": self.steps[-1]})()


def test_a_run_that_moves_after_its_check_is_re_expanded(one_unit, monkeypatch):
    """The first run's first steps sit at the expansion centre, its continued steps 0.6 prior
    SDs off (a wide posterior's short run looked settled by chance): the kept run decides, so
    the likelihood is re-expanded there, and the next run, centred, converges."""
    from leadscrew_ros.review.calibration import sampling

    settings = SamplerSettings(walkers=16, steps=120, first_steps=80, burn=40)
    rng = np.random.default_rng(3)
    runs: list[ScriptedSampler] = []

    def scripted(log_prob, walkers, dims, _rng):
        if not runs:  # 0 until its check, then 0.6: the kept steps' mean 0.3, SD ~0.42
            runs.append(ScriptedSampler(walkers, dims, lambda k: 0.0 if k < 80 else 0.6, rng))
        else:
            runs.append(ScriptedSampler(walkers, dims, lambda k: 0.3, rng))
        return runs[-1]

    monkeypatch.setattr(sampling, "_ensemble", scripted)
    post = calibrate_unit(MODEL, one_unit.obs, settings=settings)
    assert len(runs) == 2 and post.reexpansions == 1
    assert post.converged and post.status == "calibrated", post.status


def test_a_field_without_prior_scatter_asks_for_one(one_unit):
    with pytest.raises(ParameterError, match=r"--scatter radius_m=SD"):
        calibrate_unit(MODEL, one_unit.obs, names=("mu_static", "radius_m"))


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"walkers": 31}, "must be even"),
        ({"burn": 700}, "must be below"),
        ({"first_steps": 700}, "first_steps"),
        ({"prior_widen": 0.5}, "prior_widen"),
    ],
)
def test_bad_sampler_settings_are_one_line(changes, message):
    with pytest.raises(ParameterError, match=message):
        SamplerSettings(**changes)


def test_params_and_scatter_clip_to_the_valid_ranges():
    """A population whose centre leaves the allowed ranges is clipped, and says so."""
    prior = Prior(NOMINAL, Scatter(), DEFAULT_NAMES)
    hyper = np.zeros((10, 8))
    hyper[:, 1] = 9.0  # mu_k 0.2 (1 + 0.05 * 9) = 0.29 > mu_s 0.25
    hyper[:, 4] = 4.0  # sd of mu_s e^4 prior SDs: 0.68 relative
    hyper[:, 7] = 1.5  # sd of ln damping 0.35 e^1.5 = 1.57 > 1
    population = Population(
        names=DEFAULT_NAMES, prior=prior, hyper=hyper, status="calibrated", converged=True,
        ess={}, units=(), evaluations=0, seconds=0.0,
    )  # fmt: skip
    params, scatter = population.params_and_scatter(NOMINAL)
    notes = population.notes(NOMINAL)
    assert params.mu_kinetic == params.mu_static
    assert scatter.sd["modal_damping"] == 1.0
    assert any("mu_kinetic" in n for n in notes) and any(
        "scatter.modal_damping" in n for n in notes
    )


def test_the_population_refuses_units_of_another_prior(fleet):
    with pytest.raises(CalibrationError, match="another model's prior"):
        fit_population(fleet[1], SqueakModel(NOMINAL.with_(mu_static=0.3)), FAST)
    with pytest.raises(CalibrationError, match="another model's prior"):
        fit_population(fleet[1], SqueakModel(NOMINAL, Scatter({**Scatter().sd, "mu_static": 0.1})))


def test_a_units_hierarchical_posterior_averages_the_populations_each_normalised():
    """p(u | all) is the mean over hyper draws of p(u | phi, its data), each normalised: two
    equally likely populations N(-1, 0.5^2) and N(+1, 0.5^2), a unit whose likelihood is
    N(u; 0.8, 0.5^2) sampled under the interim N(0, 2^2). Given each population the unit's
    posterior is N((mu + 0.8) / 2, 1/8): -0.1 and 0.9, so the mixture's mean is 0.4 and its
    variance 1/8 + 0.25. Weighting each population by how well it fits the unit (unnormalised
    ratios) counts its data twice and gives ~0.86, the nearer population's alone."""
    from leadscrew_ros.model.calibration.population import HyperModel, reweighted

    names = ("modal_damping",)
    prior = Prior(NOMINAL, Scatter(), names)
    rng = np.random.default_rng(7)
    var = 1.0 / (1.0 / 4.0 + 1.0 / 0.25)  # the unit's posterior under the interim prior
    u = (0.8 / 0.25 * var + np.sqrt(var) * rng.standard_normal(200_000))[:, None]
    log_own = -0.5 * (u[:, 0] / 2.0) ** 2
    model = HyperModel(prior, 2.0, u[None, :1000], log_own[None, :1000])
    hyper = np.array([[-1.0, np.log(0.5)], [1.0, np.log(0.5)]])
    w = reweighted(model, hyper, u, log_own)
    mean = float(w @ u[:, 0])
    assert mean == pytest.approx(0.4, abs=0.01)
    assert float(w @ (u[:, 0] - mean) ** 2) == pytest.approx(1.0 / 8.0 + 0.25, abs=0.01)
