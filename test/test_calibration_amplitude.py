# SPDX-License-Identifier: Apache-2.0
"""The calibration's observation model (model/calibration/amplitude.py): the scan of the
amplitude equation against a frame-by-frame loop, the slow passage's onset delay against its
closed form, the grid likelihood against the error model written out, the bench's threshold
recovered from frames it generated, the onset growth rates as data, the bench's grid posterior,
and the frame sequence kept by thin and merge."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadscrew_ros.model.calibration import (
    AmplitudeLikelihood,
    CalibrationError,
    DetectionErrors,
    HearingPrior,
    Observations,
    merge,
    thin,
)
from leadscrew_ros.model.calibration.amplitude import NP_PER_DB, bench_posterior

HOP_S = 0.01


class StubGrowth:
    """What AmplitudeLikelihood needs of a GrowthLikelihood: sigma per point is the point's
    base rate times theta[:, 0] (+ theta[:, 1] when given), every mode in the band."""

    def __init__(self, obs: Observations, base: np.ndarray, in_band: np.ndarray | None = None):
        self.obs, self.base = obs, np.asarray(base, float)
        self.in_band = np.ones(obs.points, bool) if in_band is None else in_band
        self.errors = DetectionErrors()
        self.names = ("scale", "offset")
        self.centre = np.array([1.0, 0.0])
        self.bounds = (np.array([0.0, -1e3]), np.array([10.0, 1e3]))
        self.valid = np.ones(obs.points, bool)
        self.evaluations = 0

    def in_domain(self, theta: np.ndarray) -> np.ndarray:
        return np.all((theta >= self.bounds[0]) & (theta <= self.bounds[1]), axis=1)

    def growth_rates(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = np.atleast_2d(theta)
        sigma = theta[:, :1] * self.base + theta[:, 1:2]
        return sigma, np.broadcast_to(self.in_band, sigma.shape)


def observations(
    sequence: np.ndarray,
    heard: np.ndarray,
    reset: np.ndarray | None = None,
    onsets: np.ndarray | None = None,
    counted: np.ndarray | None = None,
) -> Observations:
    """Observations of `points = max(sequence) + 1` points with the given frame sequence."""
    points = int(sequence.max()) + 1
    n = len(sequence)
    counted = np.ones(n, bool) if counted is None else counted
    use = counted & (sequence >= 0)
    frames = np.bincount(sequence[use], minlength=points)
    hits = np.bincount(sequence[use & heard], minlength=points)
    reset = np.r_[True, np.zeros(n - 1, bool)] if reset is None else reset
    return Observations(
        unit_id="u",
        logs=("log",),
        speed_rad_s=np.linspace(5.0, 20.0, points),
        load_n=np.full(points, 100.0),
        nut_position_m=np.zeros(points),
        frames=frames,
        heard=hits,
        heard_hz=np.full(points, np.nan),
        frame_s=HOP_S,
        sequence=sequence.astype(np.int64),
        frame_heard=heard,
        frame_counted=counted,
        frame_reset=reset,
        onsets=np.zeros((0, 3)) if onsets is None else onsets,
    )


def likelihood(obs: Observations, base: np.ndarray, **kw: Any) -> AmplitudeLikelihood:
    return AmplitudeLikelihood(StubGrowth(obs, base), **kw)  # type: ignore[arg-type]


def loop_amplitude(
    sigma: np.ndarray, sequence: np.ndarray, reset: np.ndarray, depth: float
) -> np.ndarray:
    """(A1) frame by frame: the reference the scan must equal."""
    a, out = 0.0, []
    for point, new in zip(sequence.tolist(), reset.tolist(), strict=True):
        if new:
            a = 0.0
        a = 0.0 if point < 0 else min(max(a + sigma[point] * HOP_S, 0.0), depth)
        out.append(a)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), depth=st.floats(0.5, 12.0))
def test_the_scan_is_the_amplitude_equation_frame_by_frame(seed, depth):
    rng = np.random.default_rng(seed)
    n, points = int(rng.integers(2, 600)), int(rng.integers(1, 8))
    # runs of a few frames at one point, some without a point, some resets
    sequence = np.repeat(rng.integers(-1, points, n), rng.integers(1, 30, n))[:n]
    sequence[0] = max(sequence[0], 0)
    sequence[sequence.argmax()] = points - 1
    reset = rng.random(n) < 0.01
    reset[0] = True
    base = rng.uniform(-300.0, 300.0, points)
    obs = observations(sequence, np.zeros(n, bool), reset)
    lik = likelihood(obs, base)
    theta = np.array([[1.0, 0.0], [0.3, 5.0]])
    for row in range(len(theta)):
        a, _ = lik.amplitude(theta, depth)
        sigma = theta[row, 0] * base + theta[row, 1]
        expected = loop_amplitude(sigma, sequence, reset, depth)
        np.testing.assert_allclose(
            a[row], expected[lik.scored], rtol=0, atol=1e-4 * max(depth, 1.0)
        )  # float32
    assert np.array_equal(lik.scored, np.flatnonzero(sequence >= 0))


def test_slow_passage_delays_the_onset_to_the_closed_form():
    """sigma = s t from t = 0: a reaches h at sqrt(2 h / s) (module docstring's delay)."""
    s, h_db = 20.0, 26.0
    n = 200
    times = (np.arange(n) + 1) * HOP_S
    obs = observations(np.arange(n), np.zeros(n, bool))
    lik = likelihood(obs, s * (times - HOP_S / 2))  # sigma held over each frame: the midpoint
    a, _ = lik.amplitude(np.array([[1.0, 0.0]]), 60 * NP_PER_DB)
    onset = times[np.argmax(a[0] >= h_db * NP_PER_DB)]
    assert onset == pytest.approx(math.sqrt(2 * h_db * NP_PER_DB / s), abs=HOP_S)
    assert onset > 0.5  # half a second after sigma crossed zero: not heard where sigma > 0


def test_the_grid_likelihood_is_the_error_model_written_out():
    rng = np.random.default_rng(3)
    n, points = 480, 40
    sequence = np.repeat(np.arange(points), n // points)
    heard = rng.random(n) < 0.4
    counted = rng.random(n) < 0.9
    base = np.sin(np.arange(points) / 4.0) * 60.0
    in_band = rng.random(points) < 0.8
    obs = observations(sequence, heard, counted=counted)
    growth = StubGrowth(obs, base, in_band)
    lik = AmplitudeLikelihood(growth)  # type: ignore[arg-type]
    theta = np.array([[1.0, 0.0], [1.5, -10.0]])
    grid = lik.grid_log_likelihood(theta)
    errors, w = growth.errors, growth.errors.frame_weight(HOP_S)
    for row in range(len(theta)):
        for d, depth in enumerate(lik.depth_np):
            a, hearable = lik.amplitude(theta, depth)
            for k, h in enumerate(lik.threshold_np):
                q = errors.heard_probability((a[row] >= h) & hearable[row])
                y = heard[lik.scored]
                expected = w * np.sum(np.where(y, np.log(q), np.log1p(-q)))
                assert grid[row, d, k] == pytest.approx(expected, rel=1e-10, abs=1e-9)


def test_the_bench_threshold_is_recovered_from_the_frames_it_made():
    """Frames heard where a >= h_true (depth 55 dB): the grid's posterior favours the cell
    nearest h_true over cells 2 grid steps away, at the true parameters."""
    hearing = HearingPrior(threshold_points=8, depth_points=1)
    h_grid = hearing.grid()[0]
    truth = float(h_grid[4])
    t = np.arange(1200) * HOP_S
    sigma = 40.0 * np.sin(2 * np.pi * t / 4.0)  # two squeaks a stroke, slow passages
    sequence = np.arange(len(t))
    obs = observations(sequence, np.zeros(len(t), bool))
    lik = likelihood(obs, sigma, hearing=hearing)
    a, _ = lik.amplitude(np.array([[1.0, 0.0]]), float(lik.depth_np[0]))
    obs = observations(sequence, a[0] >= truth)
    lik = likelihood(obs, sigma, hearing=hearing)
    r = lik.responsibilities(np.array([[1.0, 0.0]]))[0, 0]
    assert int(np.argmax(r)) == 4
    assert r[4] > 10 * max(r[2], r[6])


def test_onset_rates_favour_the_sigma_that_matches_them():
    n = 100
    sequence = np.arange(n)
    onsets = np.array([[30.0, 50.0, 2.0], [70.0, 50.0, 2.0]])
    obs = observations(sequence, np.zeros(n, bool), onsets=onsets)
    lik = likelihood(obs, np.full(n, 50.0))
    ll = lik.log_likelihood(np.array([[1.0, 0.0], [1.5, 0.0], [3.0, 0.0]]))
    assert ll[0] > ll[1] > ll[2]
    # an outlier costs a bounded amount: the mixture's floor, not a Gaussian's tail
    grid_only = logsumexp_grid(lik, np.array([[10.0, 0.0]]))
    outlier = 2 * math.log(lik.hearing.onset_outlier / lik.hearing.max_rate_per_s)
    assert lik.log_likelihood(np.array([[10.0, 0.0]]))[0] - grid_only == pytest.approx(
        outlier, rel=1e-3
    )


def test_an_onset_rate_within_two_standard_errors_of_zero_is_no_growth_and_left_out():
    """A rate heard again after a dropout, 10 +- 20 1/s where the model decays at 40 1/s,
    says nothing of sigma: it moves no draw's likelihood. At 10 +- 2 1/s it is a growth."""
    n = 100
    sequence = np.arange(n)
    theta = np.array([[1.0, 0.0], [1.0, -80.0], [0.3, 0.0]])  # sigma 40, -40, 12 1/s

    def onset_term(rate: float, se: float, hearing: HearingPrior | None = None) -> np.ndarray:
        obs = observations(sequence, np.zeros(n, bool), onsets=np.array([[50.0, rate, se]]))
        lik = likelihood(obs, np.full(n, 40.0), hearing=hearing)
        return lik.log_likelihood(theta) - np.array([logsumexp_grid(lik, t[None]) for t in theta])

    assert np.all(onset_term(10.0, 20.0) == 0.0)
    assert np.all(onset_term(-5.0, 1.0) == 0.0)  # a falling level is no growth either
    resolved = onset_term(10.0, 2.0)
    assert resolved[2] > resolved[0] + 5.0  # sigma 12 against 40: the measured 10 decides
    # the rule is a setting: with onset_min_t 0 the weak rate enters (A2) too
    assert np.ptp(onset_term(10.0, 20.0, HearingPrior(onset_min_t=0.0))) > 0.1


def logsumexp_grid(lik: AmplitudeLikelihood, theta: np.ndarray) -> float:
    from scipy.special import logsumexp

    return float(logsumexp(lik.grid_log_likelihood(theta)[0] + lik.log_weight))


def test_the_bench_posterior_multiplies_the_units():
    hearing = HearingPrior(threshold_points=4, depth_points=2)
    log_prior = hearing.grid()[2]
    rng = np.random.default_rng(0)
    units = []
    for _ in range(3):
        p = np.where(np.isfinite(log_prior), rng.random(log_prior.shape), 0.0)
        units.append(p / p.sum())
    post = np.exp(bench_posterior(log_prior, units))
    prior = np.exp(log_prior)
    expected = np.where(
        prior > 0, units[0] * units[1] * units[2] / np.where(prior > 0, prior, 1) ** 2, 0
    )
    np.testing.assert_allclose(post, expected / expected.sum(), rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(np.exp(bench_posterior(log_prior, [])), prior, rtol=1e-12)


def test_the_grid_prior_keeps_the_threshold_under_the_limit_cycle():
    h, depth, log_weight = HearingPrior(threshold_db=40, depth_db=45).grid()
    assert math.isclose(float(np.exp(log_weight).sum()), 1.0)
    allowed = np.isfinite(log_weight)
    assert np.all(h[None, :][allowed.any(axis=0, keepdims=True)] > 0)
    assert np.all((h[None, :] <= depth[:, None] - 3 * NP_PER_DB)[allowed])
    assert not allowed.all()  # some cells have the threshold over the depth: no mass
    with pytest.raises(Exception, match="no threshold lies under the depth"):
        HearingPrior(threshold_db=150, threshold_sd_db=1, depth_db=40, depth_sd_db=1).grid()


def test_thin_keeps_the_frames_in_order_and_merge_chains_the_logs():
    n = 50
    times = np.arange(n) * HOP_S
    speed = np.where(np.arange(n) < 10, 0.0, 10.0 + np.arange(n) * 0.5)
    valid = speed > 0
    counted = valid & (np.arange(n) % 7 != 0)
    heard = (np.arange(n) > 30) & (np.arange(n) < 40)
    onsets = [(0.31, 40.0, 3.0), (math.nan, 1.0, 1.0)]
    obs = thin(
        "u",
        ["a"],
        times,
        np.where(valid, speed, np.nan),
        np.full(n, 100.0),
        np.full(n, 0.01),
        heard,
        np.where(heard, 900.0, np.nan),
        HOP_S,
        counted=counted,
        valid=valid,
        onsets=onsets,
    )
    assert np.all(obs.sequence[~valid] == -1) and np.all(obs.sequence[valid] >= 0)
    np.testing.assert_allclose(obs.speed_rad_s[obs.sequence[valid]], speed[valid], rtol=0.02)
    assert int(obs.frames.sum()) == int(counted.sum())
    assert int(obs.heard.sum()) == int((heard & counted).sum())
    assert obs.onsets.tolist() == [[31.0, 40.0, 3.0]]  # the NaN row dropped
    assert obs.frame_reset.tolist() == [True] + [False] * (n - 1)
    both = merge([obs, obs])
    assert len(both.sequence) == 2 * n
    assert both.frame_reset[0] and both.frame_reset[n] and both.frame_reset.sum() == 2
    assert both.onsets[:, 0].tolist() == [31.0, 31.0 + n]
    for half in (slice(0, n), slice(n, 2 * n)):
        mapped = both.sequence[half][valid]
        np.testing.assert_allclose(both.speed_rad_s[mapped], obs.speed_rad_s[obs.sequence[valid]])
    assert int(both.frames.sum()) == 2 * int(counted.sum())


def test_a_gap_between_frames_restarts_from_the_floor():
    times = np.r_[np.arange(10) * HOP_S, 5.0 + np.arange(10) * HOP_S]
    obs = thin(
        "u",
        ["a"],
        times,
        np.full(20, 10.0),
        np.full(20, 50.0),
        np.zeros(20),
        np.zeros(20, bool),
        np.full(20, np.nan),
        HOP_S,
    )
    assert np.flatnonzero(obs.frame_reset).tolist() == [0, 10]


def test_observations_without_their_order_are_refused_by_the_observation_model():
    obs = observations(np.arange(5), np.zeros(5, bool))
    plain = Observations(
        "u",
        ("l",),
        obs.speed_rad_s,
        obs.load_n,
        obs.nut_position_m,
        obs.frames,
        obs.heard,
        obs.heard_hz,
        HOP_S,
    )
    with pytest.raises(CalibrationError, match="no frame sequence"):
        likelihood(plain, np.zeros(5))
    with pytest.raises(CalibrationError, match="point that does not exist"):
        observations(np.array([0, 1, 7]), np.zeros(3, bool)).__class__(
            **{**obs.__dict__, "sequence": np.array([0, 1, 9, 2, 3])}
        )


def test_units_share_the_bench_threshold_learned_from_the_others():
    """share_hearing: a unit whose own frames cannot tell h has its samples re-weighted to
    the cell the other units favour; the bench's posterior is the product of the units'."""
    from leadscrew_ros.model.calibration.posterior import UnitPosterior
    from leadscrew_ros.review.calibration.sampling import share_hearing

    hearing = HearingPrior(threshold_points=2, depth_points=1)

    def unit(uid: str, samples: np.ndarray, weights: np.ndarray) -> UnitPosterior:
        return UnitPosterior(
            uid, (uid,), "calibrated", ("x",), samples[:, None], {"x": float(len(samples))},
            True, 0, 0,
            0.0, None, True, weights,  # type: ignore[arg-type]
        )  # fmt: skip

    n = 4000
    x = np.linspace(0.0, 1.0, n)
    # unit a: x < 0.5 goes with cell 0, x >= 0.5 with cell 1, half its samples each
    a = unit("a", x, np.column_stack([x < 0.5, x >= 0.5]).astype(float))
    # units b and c favour cell 1, 9:1 each
    b = unit("b", x, np.tile([0.1, 0.9], (n, 1)))
    c = unit("c", x, np.tile([0.1, 0.9], (n, 1)))
    bench, shared = share_hearing([a, b, c], hearing, seed=1)
    assert bench is not None
    cell1 = float(np.exp(bench).ravel()[1])
    assert cell1 == pytest.approx(0.5 * 0.9**2 / (0.5 * 0.9**2 + 0.5 * 0.1**2), rel=1e-9)
    # a's samples: re-weighted 81:1 towards x >= 0.5
    share = float(np.mean(shared[0].samples[:, 0] >= 0.5))
    assert share == pytest.approx(81 / 82, abs=0.01)
    assert shared[0].ess["x"] == pytest.approx(n * 82**2 / (2 * (1 + 81**2)), rel=1e-6)  # Kish
    assert shared[1].unit_id == "b" and np.all(
        shared[0].grid_weights[:, 1] == (shared[0].samples[:, 0] >= 0.5)
    )
    one, alone = share_hearing([a], hearing)
    assert alone[0] is a and one is not None


def test_motor_off_frames_count_once_a_squeak_has_rung_down():
    from leadscrew_ros.review.calibration.gather import RING_DOWN_S, _rested

    t = np.arange(0.0, 6.0, HOP_S)
    stands = (t < 1.0) | (t >= 3.0)  # rest, a stroke from 1 to 3 s, rest
    rested = _rested(t, stands)
    assert np.all(rested[t < 1.0])  # before the first movement: nothing rings
    moved = 3.0 - HOP_S  # the last moving frame
    assert not rested[(t >= 1.0) & (t < moved + RING_DOWN_S - HOP_S / 2)].any()
    assert np.all(rested[t >= moved + RING_DOWN_S + HOP_S / 2])


def test_the_hearing_model_counts_an_episode_from_where_the_tracker_took_it():
    """An onset walked back offline (`Episode.tracked_start_s`) is reported earlier, but the
    calibration's frames start the episode where the tracker took it, as it ends it; an
    episode the walk did not move, or a summary written before it, keeps its start."""
    from leadscrew_ros.review.calibration.gather import _episodes

    heard = {
        "episodes": [
            {"start_s": 2.0, "end_s": 3.0, "frequency_hz": 224.0, "tracked_start_s": 2.15},
            {"start_s": 5.0, "end_s": 6.0, "frequency_hz": 898.0, "tracked_start_s": None},
            {"start_s": 0.0, "end_s": 0.5, "frequency_hz": 224.0, "tracked_start_s": 0.0},
            {"start_s": 7.0, "end_s": 7.5, "frequency_hz": 224.0},
        ]
    }
    assert [(e.start_s, e.end_s) for e in _episodes(heard)] == [
        (2.15, 3.0),
        (5.0, 6.0),
        (0.0, 0.5),
        (7.0, 7.5),
    ]
