# SPDX-License-Identifier: Apache-2.0
"""The calibration's observations and cheap likelihood (model/calibration): frames thinned to
distinct operating points, the first-order growth rates against exact eigen-solves of the
model at perturbed parameters, the vectorised likelihood against a per-draw loop and against
the error model written out, the valid domain, and bad input as one clear line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from harness.calibration import HOP_S, synthetic_unit
from leadscrew_ros.bag.virtual_bench import squeak_frequencies
from leadscrew_ros.live.settings import LiveSettings
from leadscrew_ros.model import ParameterError, ScrewParameters, SqueakModel
from leadscrew_ros.model.calibration import (
    CalibrationError,
    DetectionErrors,
    GrowthLikelihood,
    Prior,
    ThinSettings,
    merge,
    thin,
)
from leadscrew_ros.model.calibration.prior import DEFAULT_NAMES
from leadscrew_ros.model.physics.stability import GROWTH_TOL, oscillatory_mask
from leadscrew_ros.model.uncertainty.scatter import Scatter

NOMINAL = ScrewParameters()
NAMES = DEFAULT_NAMES


@pytest.fixture(scope="module")
def unit():
    """A unit of the test population (a 12-s stroke), its frames flipped by the error model."""
    return synthetic_unit("lik-0", np.random.default_rng(7))


@pytest.fixture(scope="module")
def likelihood(unit):
    return GrowthLikelihood(SqueakModel(NOMINAL), unit.obs, NAMES)


def exact_margins(
    params: ScrewParameters, obs, points, band: tuple[float, float] | None = None
) -> np.ndarray:
    """Margin of a heard squeak: the largest growth rate beyond the squeak threshold over the
    oscillatory modes the detector hears (`band` [Hz], the default detector's when None), less
    by how much a mode outside the band grows faster (the most unstable mode is heard), from an
    eigen-solve of the model's state matrix at `params` (numpy, not the expansion's LAPACK
    call), at the points' nut positions; -inf where no mode is in the band."""
    errors = DetectionErrors()
    lo, hi = band or (errors.band_lo_hz, errors.band_hi_hz)
    out = []
    for i in points:
        model = SqueakModel(params.with_(nut_position_m=float(obs.nut_position_m[i])), Scatter({}))
        lam = np.linalg.eigvals(model.state_matrix(float(obs.speed_rad_s[i]), float(obs.load_n[i])))
        hz = lam.imag / (2 * math.pi)
        osc = oscillatory_mask(lam)
        margin = lam.real - GROWTH_TOL * np.abs(lam)
        inband = osc & (hz >= lo) & (hz <= hi)
        g_in = float(margin[inband].max()) if inband.any() else -np.inf
        g_out = float(margin[osc & ~inband].max()) if (osc & ~inband).any() else -np.inf
        out.append(min(g_in, g_in - g_out))  # heard: the most unstable mode is in the band
    return np.array(out)


def perturbed(centre: np.ndarray, scale: float) -> np.ndarray:
    """mu_s up, mu_k down, decay up by `scale` (relative), damping by exp(10 scale)."""
    return centre * np.array([1 + scale, 1 - scale, 1 + scale, math.exp(10 * scale)])


@pytest.fixture(scope="module")
def near_threshold(likelihood):
    """Points where some mode is within 5 1/s of the threshold or beyond it (the band and
    its edges: where the verdicts are decided), every few."""
    margins = likelihood.margins(likelihood.centre[None])[0]
    points = np.flatnonzero(np.isfinite(margins) & (margins > -5.0))
    assert len(points) > 100
    return points[:: len(points) // 60]


# ------------------------------------------------------------------ observations
def test_thin_bins_frames_to_distinct_points_and_keeps_every_frame(unit):
    obs, s = unit.obs, ThinSettings()
    assert obs.frames.sum() == len(unit.squeaks)  # every frame in one point
    assert 300 < obs.points < 0.8 * len(unit.squeaks)  # thinned
    keys = s.keys(obs.speed_rad_s, obs.load_n, obs.nut_position_m)
    assert len(np.unique(keys, axis=0)) == obs.points  # distinct
    assert np.allclose(
        obs.nut_position_m / s.nut_step_m, np.round(obs.nut_position_m / s.nut_step_m)
    )
    assert np.all(np.isfinite(obs.heard_hz[obs.heard > 0])) and np.all(
        np.isnan(obs.heard_hz[obs.heard == 0])
    )


def test_the_nut_step_is_the_node_deadband():
    """One grid with the node and the virtual bench, which move the nut in these steps."""
    assert ThinSettings().nut_step_m == LiveSettings().nut_deadband_m


def test_speed_bins_are_absolute_at_low_speed_and_relative_above():
    s = ThinSettings()
    low = s.keys(np.array([0.8, 0.8 + 0.06]), np.zeros(2), np.zeros(2))
    high = s.keys(np.array([50.0, 50.0 * 1.01, 50.0 * 1.03]), np.zeros(3), np.zeros(3))
    assert low[0, 1] != low[1, 1]  # 0.06 rad/s apart at 0.8 rad/s: two bins
    assert high[0, 1] == high[1, 1] != high[2, 1]  # 1 % apart one bin, 3 % two


def test_merge_of_two_logs_is_the_thinning_of_both(unit):
    obs = unit.obs
    half = obs.points // 2
    parts = [
        thin(
            "u",
            [log],
            np.arange(n) * HOP_S,
            obs.speed_rad_s[sl].repeat(obs.frames[sl]),
            obs.load_n[sl].repeat(obs.frames[sl]),
            obs.nut_position_m[sl].repeat(obs.frames[sl]),
            np.concatenate(
                [np.arange(f) < h for f, h in zip(obs.frames[sl], obs.heard[sl], strict=True)]
            ),
            np.full(int(obs.frames[sl].sum()), 224.0),
            HOP_S,
        )  # fmt: skip
        for log, sl, n in (
            ("a", slice(0, half), int(obs.frames[:half].sum())),
            ("b", slice(half, None), int(obs.frames[half:].sum())),
        )
    ]
    merged = merge(parts + parts)  # the same frames twice: counts double, points the same
    assert merged.logs == ("a", "b", "a", "b")
    assert merged.points == obs.points
    assert np.array_equal(merged.frames, 2 * obs.frames)
    assert np.array_equal(merged.heard, 2 * obs.heard)
    assert np.allclose(merged.speed_rad_s, obs.speed_rad_s) and np.allclose(
        merged.load_n, obs.load_n
    )


def test_merge_refuses_other_units_and_hops(unit):
    other = unit.obs.__class__(**{**unit.obs.__dict__, "unit_id": "other"})
    with pytest.raises(CalibrationError, match="different units"):
        merge([unit.obs, other])
    slower = unit.obs.__class__(**{**unit.obs.__dict__, "frame_s": 0.02})
    with pytest.raises(CalibrationError, match="different detector hops"):
        merge([unit.obs, slower])


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.one_of(st.floats(-200, 200), st.sampled_from([math.nan, math.inf, -math.inf])),
            st.one_of(st.floats(-500, 500), st.just(math.nan)),
            st.floats(0, 0.24),
            st.booleans(),
        ),
        min_size=1,
        max_size=40,
    )
)
def test_thin_gives_observations_or_one_line(frames):
    """Any frames: Observations that keep every frame, or one CalibrationError line."""
    speed, load, nut, heard = (np.array(c) for c in zip(*frames, strict=True))
    try:
        obs = thin("h", ["h.mcap"], np.arange(len(frames)) * HOP_S, speed, load, nut, heard,
                   np.where(heard, 300.0, np.nan), HOP_S)  # fmt: skip
    except CalibrationError as exc:
        assert "\n" not in str(exc) and "not finite" in str(exc)
        assert not (np.all(np.isfinite(speed)) and np.all(np.isfinite(load)))
        return
    assert obs.frames.sum() == len(frames) and obs.heard.sum() == heard.sum()
    assert np.all(np.isfinite(obs.speed_rad_s)) and np.all(np.isfinite(obs.load_n))


@pytest.mark.parametrize(
    "change, message",
    [
        ({"speed_rad_s": [1.0, math.nan]}, "speed_rad_s is not finite at 1 of 2 frames"),
        ({"nut_position_m": [0.1, math.inf]}, "nut_position_m is not finite"),
        ({"times_s": [0.1, 0.0]}, "not in order"),
        ({"heard": [1, 0]}, "heard must be booleans"),
        ({"load_n": [1.0]}, "must be 1-D of one length"),
        ({"frame_s": "0.01"}, "is not a number"),
        ({"frame_s": -0.01}, "must be a number > 0"),
    ],
)
def test_bad_frames_are_one_clear_line(change, message):
    args = dict(
        times_s=[0.0, 0.01], speed_rad_s=[1.0, 2.0], load_n=[100.0, 100.0],
        nut_position_m=[0.1, 0.1], heard=[True, False], heard_hz=[224.0, math.nan],
        frame_s=0.01,
    )  # fmt: skip
    args.update(change)
    with pytest.raises(CalibrationError) as info:
        thin(
            "bad",
            ["bad.mcap"],
            **{k: (np.asarray(v) if isinstance(v, list) else v) for k, v in args.items()},
        )
    assert message in str(info.value) and "\n" not in str(info.value)
    assert "unit bad" in str(info.value)


# ------------------------------------------------------------------ the expansion
def test_the_expansion_is_exact_at_its_centre(likelihood, unit, near_threshold):
    margins = likelihood.margins(likelihood.centre[None])[0]
    assert np.allclose(
        margins[near_threshold],
        exact_margins(NOMINAL, unit.obs, near_threshold),
        rtol=1e-9,
        atol=1e-9,
    )
    squeaks = likelihood.squeaks(likelihood.centre[None])[0]
    valid = likelihood.valid
    assert np.array_equal(squeaks[valid], margins[valid] > 0)


def test_first_order_growth_rates_match_exact_eigen_solves(likelihood, unit, near_threshold):
    """0.3 % changes of friction (3 % of damping): the first-order growth is within 0.2 %
    of its exact change at every point near the threshold (measured: 0.02 %)."""
    theta = perturbed(likelihood.centre, 0.003)
    exact = exact_margins(
        NOMINAL.with_(**dict(zip(NAMES, theta, strict=True))), unit.obs, near_threshold
    )
    change = exact - exact_margins(NOMINAL, unit.obs, near_threshold)
    error = likelihood.margins(theta[None])[0][near_threshold] - exact
    assert np.all(np.abs(change) > 0.01)  # each point moved
    assert np.all(np.abs(error) <= 2e-3 * np.abs(change))


def test_recentring_makes_larger_changes_first_order_again(likelihood, unit, near_threshold):
    """5 % changes (one prior SD of friction): the error of the nominal expansion is second
    order (measured 1.3 % of the change); re-expanded halfway it is at least halved, and
    re-expanded at the point itself the margins are exact."""
    theta = perturbed(likelihood.centre, 0.05)
    target = NOMINAL.with_(**dict(zip(NAMES, theta, strict=True)))
    exact = exact_margins(target, unit.obs, near_threshold)
    change = np.abs(exact - exact_margins(NOMINAL, unit.obs, near_threshold))
    halfway = likelihood.recentred(
        NOMINAL.with_(**dict(zip(NAMES, (theta + likelihood.centre) / 2, strict=True)))
    )

    def worst(lik):
        return np.max(np.abs(lik.margins(theta[None])[0][near_threshold] - exact) / change)

    assert worst(likelihood) < 0.05
    assert worst(halfway) < 0.5 * worst(likelihood)
    assert np.allclose(
        likelihood.recentred(target).margins(theta[None])[0][near_threshold],
        exact,
        rtol=1e-9,
        atol=1e-9,
    )


def test_pruning_and_the_batch_bounds_do_not_change_a_verdict(likelihood):
    """`squeaks` (pairs skipped by batch bounds, modes pruned) equals the largest expanded
    growth over every mode kept, for draws of the interim prior, one by one and in a batch."""
    rng = np.random.default_rng(3)
    theta = likelihood.reach.from_u(likelihood.reach.draw(64, rng))
    batch = likelihood.squeaks(theta)
    assert np.array_equal(
        batch[:, likelihood.valid], (likelihood.margins(theta) > 0)[:, likelihood.valid]
    )
    single = np.array([likelihood.squeaks(t[None])[0] for t in theta[:8]])
    assert np.array_equal(single, batch[:8])
    assert (
        0 < batch[:, likelihood.valid].mean() < 1
        and batch.any(axis=0).sum() > batch.all(axis=0).sum()
    )


# ------------------------------------------------------------------ the likelihood
def test_vectorised_log_likelihood_equals_a_per_draw_loop(likelihood):
    rng = np.random.default_rng(4)
    theta = likelihood.reach.from_u(likelihood.reach.draw(48, rng))
    calls, evaluations = likelihood.calls, likelihood.evaluations
    batch = likelihood.log_likelihood(theta)
    loop = np.array([likelihood.log_likelihood(t[None])[0] for t in theta])
    assert np.allclose(batch, loop, rtol=0, atol=1e-9)
    assert likelihood.calls - calls == 49 and likelihood.evaluations - evaluations == 96
    assert np.ptp(batch) > 1.0  # the draws differ in what they explain


def test_the_log_likelihood_is_the_error_model_with_effective_counts(likelihood, unit):
    """Each frame counts hop / correlation_s of a Bernoulli trial with P(heard) =
    false_alarm + (1 - false_alarm - miss) squeak; points outside validity count nothing."""
    rng = np.random.default_rng(5)
    theta = likelihood.reach.from_u(likelihood.reach.draw(6, rng))
    errors, obs, valid = likelihood.errors, unit.obs, likelihood.valid
    weight = HOP_S / errors.correlation_s
    q = errors.heard_probability(likelihood.squeaks(theta))
    expected = np.sum(
        weight * valid * (obs.heard * np.log(q) + (obs.frames - obs.heard) * np.log1p(-q)), axis=1
    )
    assert np.allclose(likelihood.log_likelihood(theta), expected, rtol=1e-12, atol=1e-9)
    assert errors.frame_weight(HOP_S) == pytest.approx(0.1) and errors.frame_weight(1.0) == 1.0


def test_the_truth_explains_the_frames_better_than_the_prior(likelihood, unit):
    truth = np.array([getattr(unit.truth, n) for n in NAMES])
    rng = np.random.default_rng(6)
    prior = Prior(NOMINAL, Scatter(), NAMES)
    draws = prior.from_u(prior.draw(200, rng))
    assert likelihood.log_likelihood(truth[None])[0] > np.quantile(
        likelihood.log_likelihood(draws), 0.9
    )


def test_outside_the_valid_domain_the_likelihood_is_minus_infinity(likelihood):
    c = likelihood.centre
    bad = np.array(
        [
            [0.19, 0.2, c[2], c[3]],
            [c[0], c[1], -1.0, c[3]],
            [c[0], c[1], c[2], -1e-3],
            [c[0], c[1], c[2], 1.5],
        ]
    )
    assert np.all(likelihood.log_likelihood(bad) == -np.inf)
    assert np.isfinite(likelihood.log_likelihood(c[None])[0])


def test_a_geometry_field_enters_by_its_derivative(unit):
    """--calibrate radius_m: dA/dR at each point; small changes match exact eigen-solves
    (the growth oscillates in R with a period of about 1 %, so small is 0.01 %)."""
    scatter = Scatter({**Scatter().sd, "radius_m": 0.01})
    lik = GrowthLikelihood(SqueakModel(NOMINAL, scatter), unit.obs, ("mu_static", "radius_m"))
    margins = lik.margins(lik.centre[None])[0]
    points = np.flatnonzero(np.isfinite(margins) & (margins > -5.0))[::40]
    theta = lik.centre * np.array([1.001, 1.0001])
    exact = exact_margins(NOMINAL.with_(mu_static=theta[0], radius_m=theta[1]), unit.obs, points)
    change = exact - margins[points]
    error = lik.margins(theta[None])[0][points] - exact
    assert np.all(np.abs(error) <= 0.02 * np.abs(change) + 1e-3)


def test_bad_theta_and_missing_prior_are_one_clear_line(likelihood, unit):
    with pytest.raises(CalibrationError, match="not finite"):
        likelihood.log_likelihood(np.array([[0.25, math.nan, 10.0, 0.003]]))
    with pytest.raises(CalibrationError, match=r"shape \(walkers, 4\)"):
        likelihood.log_likelihood(np.zeros(4))
    with pytest.raises(ParameterError) as info:
        GrowthLikelihood(SqueakModel(NOMINAL), unit.obs, ("mu_static", "radius_m"))
    assert "--scatter radius_m=SD" in str(info.value) and "\n" not in str(info.value)
    for names, message in (
        ((), "at least one"),
        (("mu_static", "mu_static"), "twice"),
        (("nut_position_m",), "operating point"),
        (("formulation",), "not a scatterable"),
    ):
        with pytest.raises(ParameterError, match=message):
            Prior(NOMINAL, Scatter(), names)
    with pytest.raises(ParameterError, match="errors.miss"):
        DetectionErrors(miss=0.0)


def test_the_consistent_formulation_is_first_order_too(unit):
    """formulation 'consistent': the thread factor c = 1 / (1 + s mu_o tan beta) of each draw
    is exact in l and s; small changes match exact eigen-solves as for 'paper'."""
    nominal = NOMINAL.with_(formulation="consistent")
    lik = GrowthLikelihood(SqueakModel(nominal), unit.obs, NAMES)
    margins = lik.margins(lik.centre[None])[0]
    points = np.flatnonzero(np.isfinite(margins) & (margins > -5.0))[::25]
    assert len(points) > 10
    assert np.allclose(
        margins[points], exact_margins(nominal, unit.obs, points), rtol=1e-9, atol=1e-9
    )
    theta = perturbed(lik.centre, 0.003)
    exact = exact_margins(nominal.with_(**dict(zip(NAMES, theta, strict=True))), unit.obs, points)
    change = exact - margins[points]
    error = lik.margins(theta[None])[0][points] - exact
    assert np.all(np.abs(change) > 0.01)
    assert np.all(np.abs(error) <= 2e-3 * np.abs(change))


def test_a_squeak_outside_the_detector_band_is_not_heard(unit, likelihood):
    """With a band that leaves out the first y-bending mode (~224 Hz), its squeak does not
    count: points where only it squeaks have no squeak, as the exact modes in the band say."""
    band = (300.0, 20000.0)
    narrow = GrowthLikelihood(
        SqueakModel(NOMINAL),
        unit.obs,
        NAMES,
        DetectionErrors(band_lo_hz=band[0], band_hi_hz=band[1]),
    )
    wide, cut = (
        likelihood.squeaks(likelihood.centre[None])[0],
        narrow.squeaks(narrow.centre[None])[0],
    )
    lost = np.flatnonzero(wide & ~cut)
    assert len(lost) >= 3 and not np.any(cut & ~wide)  # the second mode squeaks too, mostly
    assert np.all(exact_margins(NOMINAL, unit.obs, lost, band) <= 0)
    assert np.all(exact_margins(NOMINAL, unit.obs, lost) > 0)
    with pytest.raises(ParameterError, match="band_lo_hz"):
        DetectionErrors(band_lo_hz=5000.0, band_hi_hz=4000.0)


def test_a_faster_mode_above_the_band_silences_the_one_in_it(unit):
    """The squeak heard is the most unstable mode's (the bench sounds that one): where a mode
    above the detector's band can be unstable beside one in it (formulation 'consistent',
    T3 at ~13 kHz), the verdict is decided per draw between them, as exact eigen-solves decide
    it, at the centre and for a draw away from it."""
    nominal = NOMINAL.with_(formulation="consistent")
    lik = GrowthLikelihood(SqueakModel(nominal), unit.obs, NAMES)
    assert len(lik.contested) > 0
    points = lik.contested
    assert np.array_equal(
        lik.squeaks(lik.centre[None])[0][points], exact_margins(nominal, unit.obs, points) > 0
    )
    theta = perturbed(lik.centre, 0.003)
    exact = exact_margins(nominal.with_(**dict(zip(NAMES, theta, strict=True))), unit.obs, points)
    clear = np.abs(exact) > 0.5  # away from a tie, where first order decides as exact does
    assert clear.sum() > 0.5 * len(points)
    assert np.array_equal(lik.squeaks(theta[None])[0][points][clear], exact[clear] > 0)


def test_the_consistent_expansion_from_the_prior_gives_the_truths_verdicts(unit):
    """Expanded about the prior's centre, the likelihood's verdict at a unit's true parameters
    (formulation 'consistent', its truth some prior SDs away) is the exact model's at its
    operating points: the bench's rule (`virtual_bench.squeak_frequencies`: the most unstable
    mode, heard in the detector's band), at >= 99 % of the points (measured: all, on a
    20-unit consistent bench, with either centre). The consistent calibration's bias is not
    the expansion's."""
    errors = DetectionErrors()
    nominal = NOMINAL.with_(formulation="consistent")
    truth = unit.truth.with_(formulation="consistent")
    lik = GrowthLikelihood(SqueakModel(nominal), unit.obs, NAMES, errors)
    theta = np.array([[getattr(truth, n) for n in NAMES]])
    assert np.linalg.norm(Prior(nominal, Scatter(), NAMES).to_u(theta)) > 1.0  # off centre
    obs = unit.obs
    hz = squeak_frequencies(truth, obs.speed_rad_s, obs.load_n, obs.nut_position_m)
    exact = (hz >= errors.band_lo_hz) & (hz <= errors.band_hi_hz)
    valid = lik.valid
    assert exact[valid].sum() > 20 and (~exact[valid]).sum() > 20  # both verdicts occur
    agree = lik.squeaks(theta)[0] == exact
    assert agree[valid].mean() >= 0.99, np.flatnonzero(valid & ~agree)


def test_growth_rates_are_the_expansions_max_over_every_mode(likelihood, unit):
    """growth_rates skips the pairs that cannot be the max; the answer is the max over every
    mode of the first-order expansion (the candidates') or the centre's value (the others'),
    and in_band says whether that max lies in the detector's band."""
    from leadscrew_ros.model.calibration.likelihood import _expanded

    prior = Prior(NOMINAL, SqueakModel(NOMINAL).scatter, NAMES)
    theta = prior.from_u(prior.draw(12, np.random.default_rng(5)) * 0.5)
    sigma, in_band = likelihood.growth_rates(theta)
    point, margin, rates, inband = likelihood._solved
    reach = likelihood._reach(point, rates)
    used = np.unique(point)
    changes = likelihood._changes(theta, likelihood._centre_at(used))
    full = _expanded(*changes, np.searchsorted(used, point), rates, margin)  # (pairs, W)
    # modes no draw in the box can make unstable are held at the centre
    full = np.where((margin + reach > 0)[:, None], full, margin[:, None])
    for i in np.flatnonzero(likelihood.valid)[::7].tolist():
        rows = np.flatnonzero(point == i)
        best = full[rows].max(axis=0)
        np.testing.assert_allclose(sigma[:, i], best, rtol=1e-12, atol=1e-9)
        top = rows[np.argmax(full[rows], axis=0)]
        assert np.array_equal(in_band[:, i], inband[top])
    assert np.all(sigma[:, ~likelihood.valid] == -np.inf)
