# SPDX-License-Identifier: Apache-2.0
"""LivePredictor (the node's recompute policy) without ROS: deadbands, rate limit, coalescing,
input validation, validity, staleness, the diagnostic verdict and safe-speed advice.

Time is the `now` argument (monotonic seconds): nothing here sleeps. The background advice
search is held and released with events, never timed."""

import math
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import lapack

from leadscrew_ros.live import recompute as live_module
from leadscrew_ros.live.recompute import LatestWorker, LivePredictor, LiveSettings, Superseded
from leadscrew_ros.live.status import (
    KEY_MARGIN,
    KEY_NUT_POSITION,
    KEY_PROBABILITY,
    KEY_PROBABILITY_STDERR,
    KEY_SAFE_SPEED_ERROR,
    KEY_SAFE_SPEED_PENDING,
    KEY_SQUEAK_FREQUENCIES,
    KEY_VALID,
    KEY_VALIDITY,
    Level,
    prediction_status,
)
from leadscrew_ros.model import Prediction, SqueakModel, Validity
from leadscrew_ros.model.studies.advice import (
    _BAND_POINTS,
    _MAX_REFINE,
    _SCAN_BATCH,
    EDGE_RTOL,
    band_around,
    band_score,
    speed_bands,
)
from leadscrew_ros.model.studies.fields import growth_field
from leadscrew_ros.model.uncertainty.scatter import Scatter

# Table 1, 200 N, paper, default scatter: the nominal squeak band is ~0.81..55.2 rad/s; P(squeak)
# is 0.997 at 20 rad/s, 0.43 at 55.5 (nominally stable), 0.12 at 60, 0.002 at 68, 0 from ~70 on.
MODEL = SqueakModel()
LOAD = 200.0
SQUEAK, STABLE, NEAR_EDGE = 20.0, 100.0, 55.5  # rad/s
SAFE = LiveSettings().safe_probability  # 0.01: squeak/safe_speed has P below it


def live(**settings) -> LivePredictor:
    """A predictor whose predictions take no time (the `now` arguments are all the time)."""
    return LivePredictor(MODEL, LiveSettings(**settings), clock=lambda: 0.0)


def at(speed: float, load: float = LOAD, now: float = 0.0, **settings) -> LivePredictor:
    """A predictor that has computed one prediction at (speed, load)."""
    lp = live(**settings)
    assert lp.set_speed(speed, now) == "" and lp.set_load(load, now) == ""
    assert lp.due(now)
    lp.update(now)
    assert lp.wait_for_advice(timeout=60.0)
    return lp


def finite_numbers(p: Prediction, safe_speed: float | None) -> list[float]:
    numbers = [
        p.speed_rad_s,
        p.load_n,
        p.probability,
        *p.divergence_rates,
        *p.unstable_frequencies_hz,
        *([] if p.margin is None else [p.margin]),
    ]
    numbers += [v for m in p.modes for v in (m.frequency_hz, m.growth_rate, m.damping_ratio)]
    return numbers + ([] if safe_speed is None else [safe_speed])


# ----------------------------------------------------------------------------- start-up
def test_nothing_is_due_before_speed_and_load_arrive():
    lp = live()
    assert not lp.due(0.0) and lp.update(0.0) is None and lp.recomputes == 0
    lp.set_speed(SQUEAK, 0.0)
    assert not lp.due(0.0)  # load still missing
    assert lp.status(0.0).level == Level.STALE
    lp.set_load(LOAD, 0.0)
    assert lp.due(0.0)


# ----------------------------------------------------------------------------- deadbands
@pytest.mark.parametrize(
    "setter, below, above",
    [
        ("set_speed", STABLE + 0.05, STABLE + 0.2),  # speed_deadband_rad_s = 0.1
        ("set_speed", STABLE - 0.09, STABLE - 0.11),
        ("set_load", LOAD + 0.5, LOAD + 1.5),  # load_deadband_n = 1
        ("set_nut_position", 0.15 + 0.0004, 0.15 + 0.0006),  # nut_deadband_m = 0.0005
    ],
)
def test_deadbands(setter, below, above):
    lp = at(STABLE)
    assert not lp.due(1.0)
    assert getattr(lp, setter)(below, 1.0) == ""
    assert not lp.due(1.0)
    assert getattr(lp, setter)(above, 1.0) == ""
    assert lp.due(1.0)


def test_deadband_is_measured_from_the_last_recompute_not_the_last_input():
    lp = at(STABLE)
    for i in range(1, 6):  # creeping by 0.04 rad/s: 0.2 in total
        lp.set_speed(STABLE + 0.04 * i, 1.0)
    assert lp.due(1.0)


# ----------------------------------------------------------------------------- rate limit
def test_rate_limit():
    lp = at(STABLE, max_rate_hz=10.0)  # computed at t = 0
    lp.set_speed(STABLE + 5.0, 0.01)
    for t in (0.01, 0.05, 0.0999):
        assert lp.changed() and not lp.due(t), t
    assert lp.due(0.1)
    lp.update(0.1)
    lp.set_speed(STABLE + 10.0, 0.15)
    assert not lp.due(0.15) and lp.due(0.2)


# ----------------------------------------------------------------------------- coalescing
def test_a_burst_of_inputs_is_one_recompute_at_the_latest_value():
    lp = at(STABLE)
    for i in range(10_000):
        assert lp.set_speed(STABLE + (i % 50), 1.0) == ""
    lp.set_speed(123.0, 1.0)
    assert lp.due(1.0)
    p = lp.update(1.0)
    assert p.speed_rad_s == 123.0 and lp.prediction is p
    assert lp.recomputes == 2  # the first one in at() and this one
    assert not lp.due(2.0)


def test_burst_recomputes_are_bounded_by_the_rate_limit():
    """The node's loop: store each input, recompute when due. 10,000 inputs in 0.1 s at
    max_rate_hz = 100 give at most 0.1 * 100 + 1 recomputes, and the last input wins."""
    lp, n, duration = live(max_rate_hz=100.0), 10_000, 0.1
    lp.set_load(LOAD, 0.0)
    for i in range(n):
        now = i * duration / n
        lp.set_speed(60.0 + (i % 100), now)
        if lp.due(now):
            lp.update(now)
    assert 1 <= lp.recomputes <= duration * 100.0 + 1
    assert lp.due(duration + 0.01)  # the tick after the burst picks up the rest
    lp.update(duration + 0.01)
    assert lp.prediction.speed_rad_s == 60.0 + (n - 1) % 100
    assert lp.recomputes <= duration * 100.0 + 2


# ----------------------------------------------------------------------------- invalid input
BAD_INPUTS = [
    ("set_speed", math.nan, ["speed", "nan", "not finite"]),
    ("set_speed", math.inf, ["speed", "inf", "not finite"]),
    ("set_speed", -math.inf, ["speed", "-inf", "not finite"]),
    ("set_speed", "abc", ["speed", "'abc'", "not a number"]),
    ("set_speed", None, ["speed", "None", "not a number"]),
    ("set_speed", True, ["speed", "True", "not a number"]),
    ("set_load", math.nan, ["load", "nan", "not finite"]),
    ("set_load", "abc", ["load", "'abc'", "not a number"]),
    ("set_load", None, ["load", "None", "not a number"]),
    ("set_load", 1e12, ["load", "1e+12", "exceeds"]),
    ("set_load", -1e12, ["load", "-1e+12", "exceeds"]),
    ("set_nut_position", math.nan, ["nut position", "nan"]),
    ("set_nut_position", math.inf, ["nut position", "inf"]),
    ("set_nut_position", "abc", ["nut position", "'abc'", "not a number"]),
    ("set_nut_position", None, ["nut position", "None", "not a number"]),
    ("set_nut_position", 10**400, ["nut position", "not a number"]),
    ("set_nut_position", 0.25, ["nut position", "0.25", "off the screw", "z_o + b <= L"]),
    ("set_nut_position", -0.01, ["nut position", "-0.01", "off the screw"]),
    (
        "set_nut_position",
        0.2400001,
        ["nut position 0.2400001 m is off the screw", "allowed [0, 0.24] m"],
    ),
]


GOOD = {"set_speed": SQUEAK, "set_load": LOAD, "set_nut_position": 0.15}


@pytest.mark.parametrize(
    "setter, value, words", BAD_INPUTS, ids=[f"{s}-{v!r:.20}" for s, v, _ in BAD_INPUTS]
)
def test_invalid_input_is_rejected_and_named(setter, value, words):
    lp = at(SQUEAK)
    good, safe, inputs = lp.prediction, lp.safe_speed_rad_s, vars(lp.inputs).copy()
    reason = getattr(lp, setter)(value, 1.0)
    for w in words:
        assert w in reason, (w, reason)
    status = lp.status(1.0)
    assert status.level == Level.ERROR
    assert status.message == f"invalid input: {reason}"
    assert vars(lp.inputs) == inputs  # the bad value is not stored
    assert not lp.due(1.0)  # nothing to recompute
    assert lp.prediction is good and lp.safe_speed_rad_s == safe
    # a good value of the same input clears the error; the verdict is the prediction's again
    getattr(lp, setter)(GOOD[setter], 1.0)
    assert lp.status(1.0).message.startswith("squeak predicted")


def test_an_input_error_lasts_until_that_input_is_good_again():
    lp = at(SQUEAK)
    lp.set_speed(math.nan, 1.0)
    lp.set_load(LOAD, 1.0)  # another input being fine does not hide it
    lp.set_nut_position(0.1, 1.0)
    assert lp.status(1.0).message == "invalid input: speed = nan is not finite (rad/s)"
    lp.set_load(None, 1.0)  # two bad inputs: both named
    message = lp.status(1.0).message
    assert "speed = nan" in message and "load = None" in message
    lp.set_speed(SQUEAK, 1.0)
    assert lp.status(1.0).message == "invalid input: load = None is not a number (N)"
    lp.set_load(LOAD, 1.0)
    assert lp.status(1.0).level == Level.ERROR and "squeak" in lp.status(1.0).message


# ----------------------------------------------------------------------------- validity
@pytest.mark.parametrize(
    "speed, words, validity",
    [
        (0.1, "below min_speed_rad_s", Validity.BELOW_MIN_SPEED),
        (-0.1, "below min_speed_rad_s", Validity.BELOW_MIN_SPEED),
        (5000.0, "critical speed", Validity.AT_CRITICAL_SPEED),
    ],
)
def test_outside_validity_keeps_the_last_good_prediction(speed, words, validity):
    lp = at(SQUEAK)
    good, safe = lp.prediction, lp.safe_speed_rad_s
    lp.set_speed(speed, 1.0)
    assert lp.due(1.0)
    assert lp.update(1.0) is None
    assert lp.prediction is good and lp.safe_speed_rad_s == safe
    status = lp.status(1.0)
    assert status.level == Level.WARN
    assert status.message.startswith("no prediction: outside the model's validity")
    assert words in status.message
    assert status.values[KEY_VALID] == "false" and status.values[KEY_VALIDITY] == validity.name
    assert not lp.due(1.5)  # no retry until the point moves
    lp.set_speed(STABLE, 2.0)  # back inside: a new prediction, verdict OK
    lp.set_load(LOAD, 2.0)
    assert lp.update(2.0).speed_rad_s == STABLE and lp.status(2.0).level == Level.OK


# ----------------------------------------------------------------------------- staleness
def test_stale_after_the_timeout():
    lp = at(STABLE, now=10.0, stale_timeout_s=1.0)
    assert lp.status(10.99).level == Level.OK
    status = lp.status(11.01)
    assert status.level == Level.STALE
    assert "motor_speed" in status.message and "axial_load" in status.message
    assert "1 s" in status.message
    lp.set_speed(STABLE, 11.5)  # fresh speed, load still old
    status = lp.status(11.6)
    assert status.level == Level.STALE
    assert "axial_load" in status.message and "motor_speed" not in status.message
    lp.set_load(LOAD, 11.6)
    assert lp.status(11.7).level == Level.OK
    assert lp.prediction is not None  # staleness never drops the last prediction


# ----------------------------------------------------------------------------- verdict
def test_squeak_is_error():
    lp = at(SQUEAK)
    p, status = lp.prediction, lp.status(0.0)
    assert p.probability == pytest.approx(0.997, abs=0.003) and not p.stable
    assert status.level == Level.ERROR
    assert status.message == "squeak predicted: P(squeak) 1 (B1y 224 Hz, B2y 898 Hz)"
    assert float(status.values[KEY_PROBABILITY]) == pytest.approx(p.probability, rel=1e-5)
    assert float(status.values[KEY_PROBABILITY_STDERR]) == pytest.approx(
        p.probability_stderr, rel=1e-5
    )
    assert float(status.values[KEY_MARGIN]) == pytest.approx(p.margin, rel=1e-5)
    assert p.margin < 0
    assert status.values[KEY_VALID] == "true"
    assert status.values[KEY_VALIDITY] == Validity.OK.name
    assert status.values[KEY_SQUEAK_FREQUENCIES] == "224.3, 897.9"


# Points of known P (module comment): the level follows P and the thresholds, not whether the
# nominal parameters squeak (55 rad/s squeaks nominally, 55.5 and 60 do not).
@pytest.mark.parametrize(
    "speed, low, high, level, message",
    [
        (20.0, 0.99, 1.0, Level.ERROR, "squeak predicted: P(squeak) 1 (B1y 224 Hz, B2y 898 Hz)"),
        (55.0, 0.4, 0.5, Level.WARN, "squeak possible: P(squeak) 0.46 >= 0.1 (B1y 225 Hz)"),
        (55.5, 0.4, 0.5, Level.WARN, "squeak possible: P(squeak) 0.43 >= 0.1"),
        (60.0, 0.1, 0.2, Level.WARN, "squeak possible: P(squeak) 0.12 >= 0.1"),
        (70.0, 0.0, 0.0, Level.OK, "no squeak: P(squeak) 0 < 0.1"),
        (STABLE, 0.0, 0.0, Level.OK, "no squeak: P(squeak) 0 < 0.1"),
    ],
)
def test_diagnostic_level_by_probability(speed, low, high, level, message):
    lp = at(speed)
    assert low <= lp.prediction.probability <= high
    status = lp.status(0.0)
    assert (status.level, status.message) == (level, message)


def test_probability_thresholds_are_settings():
    p = at(60.0).prediction  # P 0.12
    assert at(60.0, warn_probability=0.13).status(0.0).level == Level.OK
    assert at(60.0, warn_probability=0.12, error_probability=0.12).status(0.0).level == Level.ERROR
    assert (
        at(60.0, warn_probability=0.05, error_probability=p.probability).status(0.0).message
        == "squeak predicted: P(squeak) 0.12109375"
    )  # >= it; 0.12 would be below
    assert at(55.0, error_probability=0.4).status(0.0).level == Level.ERROR


def test_without_scatter_the_verdict_is_the_nominal_one():
    """No scatter: P is 0 or 1, so the level is the nominal verdict (OK or ERROR)."""
    lp = LivePredictor(MODEL.with_scatter(Scatter({})), clock=lambda: 0.0)
    lp.set_load(LOAD, 0.0)
    for speed, probability, level in (
        (55.0, 1.0, Level.ERROR),
        (55.5, 0.0, Level.OK),
        (60.0, 0.0, Level.OK),
        (20.0, 1.0, Level.ERROR),
    ):
        lp.set_speed(speed, 0.0)
        p = lp.update(0.0)
        assert (p.probability, p.probability_stderr) == (probability, None)
        assert lp.status(0.0).level == level
        assert lp.status(0.0).values[KEY_PROBABILITY_STDERR] == ""


def made(probability: float, divergence: tuple[float, ...] = ()) -> Prediction:
    return Prediction(60.0, LOAD, "paper", Validity.OK, "", (), divergence, probability, None)


@pytest.mark.parametrize(
    "probability, level, message",
    [
        (0.0996, Level.OK, "no squeak: P(squeak) 0.0996 < 0.1"),  # not rounded onto 0.1
        (0.1, Level.WARN, "squeak possible: P(squeak) 0.1 >= 0.1"),
        (0.4996, Level.WARN, "squeak possible: P(squeak) 0.4996 >= 0.1"),
        (0.5, Level.ERROR, "squeak predicted: P(squeak) 0.5"),
        (0.0123, Level.OK, "no squeak: P(squeak) 0.012 < 0.1"),
    ],
)
def test_probability_is_never_rounded_across_a_threshold(probability, level, message):
    status = prediction_status(made(probability), LiveSettings())
    assert (status.level, status.message) == (level, message)


def test_divergence_is_error_whatever_the_probability():
    status = prediction_status(made(0.0, (3.25,)), LiveSettings())
    assert (status.level, status.message) == (
        Level.ERROR,
        "divergence predicted: P(squeak) 0 (divergence 3.25 1/s)",
    )


# ----------------------------------------------------------------------------- nut position
def test_nut_movement_beyond_the_deadband_changes_the_prediction():
    lp = at(SQUEAK)
    lp.set_nut_position(0.02, 1.0)
    assert lp.due(1.0)
    near_end = lp.update(1.0)
    lp.set_nut_position(0.12, 2.0)
    assert lp.due(2.0)
    middle = lp.update(2.0)
    expected = {
        z: MODEL.with_params(nut_position_m=z).predict(SQUEAK, LOAD).max_growth_rate
        for z in (0.02, 0.12)
    }
    assert near_end.max_growth_rate == pytest.approx(expected[0.02], rel=1e-9)
    assert middle.max_growth_rate == pytest.approx(expected[0.12], rel=1e-9)
    assert abs(near_end.max_growth_rate - middle.max_growth_rate) > 10.0  # 44.6 vs 81.8 1/s
    assert lp.status(2.0).values[KEY_NUT_POSITION] == "0.12"


def test_contact_is_reintegrated_only_beyond_the_nut_deadband():
    """A speed change recomputes; a nut drift within nut_deadband_m keeps the same geometry."""
    lp = at(SQUEAK)
    lp.set_nut_position(0.1, 1.0)
    lp.update(1.0)
    built = lp._nut_model.geometry.contact
    lp.set_nut_position(0.1 + 0.0003, 2.0)  # within the 0.5 mm deadband
    lp.set_speed(SQUEAK + 1.0, 2.0)
    assert lp.update(2.0) is not None
    assert lp._nut_model.geometry.contact is built
    assert lp._nut_model.params.nut_position_m == 0.1
    lp.set_nut_position(0.1 + 0.0008, 3.0)  # beyond it
    lp.update(3.0)
    assert lp._nut_model.geometry.contact is not built
    assert lp._nut_model.params.nut_position_m == pytest.approx(0.1008)


# ----------------------------------------------------------------------------- parameters
def test_new_model_recomputes_with_the_new_parameters():
    lp = at(SQUEAK)
    lp.set_model(MODEL.with_params(formulation="consistent"))
    assert lp.due(1.0)
    p = lp.update(1.0)
    assert p.formulation == "consistent"
    assert p.unstable_frequencies_hz[0] == pytest.approx(2654.0, rel=1e-3)  # T1


# ----------------------------------------------------------------------------- safe speed
@pytest.mark.parametrize("speed", [STABLE, -STABLE, 68.0, -68.0])
def test_safe_speed_of_a_safe_point_is_the_speed(speed):
    """P below safe_probability (0 at 100 rad/s, 0.002 at 68 rad/s): the speed itself."""
    lp = at(speed)
    assert lp.prediction.probability < SAFE and lp.safe_speed_rad_s == speed


@pytest.mark.parametrize("speed", [SQUEAK, -SQUEAK])
def test_safe_speed_of_a_squeaking_point_is_outside_the_band(speed):
    lp = at(speed)
    safe = lp.safe_speed_rad_s
    assert not lp.prediction.stable
    assert safe != 0.0 and math.copysign(1.0, safe) == math.copysign(1.0, speed)
    for lo, hi in speed_bands(MODEL, LOAD, speed, safe_probability=SAFE):
        assert not lo <= abs(safe) <= hi
    check = MODEL.predict(safe, LOAD)
    assert check.valid and check.stable and check.probability < SAFE


@pytest.mark.parametrize("speed", [57.0, 58.0, 60.0, -60.0])
def test_a_nominally_stable_speed_near_the_band_is_advised_to_where_p_is_safe(speed):
    """Table 1, 200 N, paper: just above the nominal band (55.2 rad/s) P is 0.1..0.3, so the
    advice moves on, to the edge where P drops below safe_probability (~65.5 rad/s), and a
    speed a little nearer still has P >= it; with the default margin 5 % beyond that edge."""
    lp = at(speed, safe_speed_margin=0.0)
    assert lp.prediction.stable and 0.1 <= lp.prediction.probability <= 0.35
    safe = lp.safe_speed_rad_s
    assert math.copysign(1.0, safe) == math.copysign(1.0, speed) and 65.0 < abs(safe) < 66.0
    assert MODEL.predict(safe, LOAD).probability < SAFE
    assert MODEL.predict(safe * (1 - 3 * EDGE_RTOL), LOAD).probability >= SAFE
    with_margin = at(speed).safe_speed_rad_s
    assert with_margin == pytest.approx(safe * 1.05, rel=2 * EDGE_RTOL)
    assert MODEL.predict(with_margin, LOAD).probability < SAFE


def test_safe_probability_sets_the_band():
    """At 58 rad/s P is 0.24: safe for safe_probability 0.3, inside the band for 0.2 (whose
    edge lies where P drops below 0.2, before 60 rad/s where P is 0.12)."""
    assert at(58.0, safe_probability=0.3).safe_speed_rad_s == 58.0
    safe = at(58.0, safe_probability=0.2, safe_speed_margin=0.0).safe_speed_rad_s
    assert 58.0 < safe < 60.0
    assert MODEL.predict(safe, LOAD).probability < 0.2
    assert MODEL.predict(safe * (1 - 3 * EDGE_RTOL), LOAD).probability >= 0.2


def full_search_safe_speed(
    model: SqueakModel, load: float, speed: float, margin: float = 0.05
) -> float:
    """The advice of the former synchronous path: every band (speed_bands), then the nearer
    edge of the one containing the speed, moved out by the margin, within the valid range."""
    w = abs(speed)
    for lo, hi in speed_bands(model, load, speed, safe_probability=SAFE):
        if lo <= w <= hi:
            options = [
                v
                for v in (lo * (1 - margin), hi * (1 + margin))
                if model.params.min_speed_rad_s <= v < model.critical_speed_rad_s
            ]
            return math.copysign(min(options, key=lambda v: abs(v - w)), speed) if options else 0.0
    return speed


POINTS = [
    (20.0, 200.0),
    (-20.0, 200.0),
    (3.0, 200.0),
    (50.0, 200.0),
    (-50.0, 200.0),
    (20.0, 600.0),
    (-20.0, 600.0),
    (1.0, 50.0),
    (20.0, 50.0),
    (-20.0, -200.0),
]


@pytest.mark.parametrize("scatter", ["default", "none"])
@pytest.mark.parametrize("formulation", ["paper", "consistent"])
@pytest.mark.parametrize("speed, load", POINTS)
def test_band_search_gives_the_advice_of_the_full_search(formulation, scatter, speed, load):
    """Same safe speed as the full search within the edge tolerance (both refine to
    EDGE_RTOL), and band_around's edges are exact to EDGE_RTOL: P - safe_probability changes
    sign across them; without scatter they are the nominal band's, where the growth rate
    changes sign."""
    model = MODEL.with_params(formulation=formulation)
    if scatter == "none":
        model = model.with_scatter(Scatter({}))
    p = model.predict(speed, load)
    if not p.valid or p.probability < SAFE:
        assert band_around(model, load, speed, safe_probability=SAFE) is None
        return
    band = band_around(model, load, speed, safe_probability=SAFE)
    lowest, highest = model.params.min_speed_rad_s, model.critical_speed_rad_s
    new = band.safe_speed(speed, lowest, highest, 0.05)
    old = full_search_safe_speed(model, load, speed)
    assert new == pytest.approx(old, rel=3 * EDGE_RTOL)
    score = band_score(model, load, speed, SAFE)
    for edge, end in ((band.low_rad_s, band.below), (band.high_rad_s, band.above)):
        if end == "edge":
            across = edge * np.array([1 - 2 * EDGE_RTOL, 1 + 2 * EDGE_RTOL])
            s = score(across)
            assert (s[0] >= 0) != (s[1] >= 0), (edge, s)
            if scatter == "none":
                g = growth_field(model, math.copysign(1.0, speed) * across, load)
                assert g.max_growth_rate[0] * g.max_growth_rate[1] < 0, (edge, g)
    check = model.predict(new, load)
    assert new == 0.0 or (check.valid and check.probability < SAFE)


def test_band_score_rejects_a_threshold_outside_0_1():
    for bad in (0.0, -0.1, 1.5, math.nan, True, "0.1"):
        with pytest.raises(ValueError, match="safe_probability"):
            band_score(MODEL, LOAD, 1.0, bad)


def test_band_search_of_40_modes_matches_at_table_1():
    model = MODEL.with_params(n_bending=40, n_torsion=40)
    band = band_around(model, LOAD, SQUEAK, safe_probability=SAFE)
    safe = band.safe_speed(SQUEAK, model.params.min_speed_rad_s, model.critical_speed_rad_s)
    span = model.critical_speed_rad_s - model.params.min_speed_rad_s
    assert safe == pytest.approx(full_search_safe_speed(model, LOAD, SQUEAK), rel=3 * EDGE_RTOL)
    assert 0 < span and model.predict(safe, LOAD).probability < SAFE


@pytest.fixture
def solves(monkeypatch):
    """Counts the eigen-solves (one LAPACK dgeev per prediction)."""
    count = [0]
    dgeev = lapack.dgeev

    def counted(*args, **kwargs):
        count[0] += 1
        return dgeev(*args, **kwargs)

    monkeypatch.setattr(lapack, "dgeev", counted)
    return count


@pytest.mark.parametrize("speed, most", [(SQUEAK, 0.8), (50.0, 0.4), (1.0, 0.8)])
def test_band_search_solves_a_bounded_fraction_of_the_full_search(solves, speed, most):
    """The full search solves its 64-point grid and refines every band edge; band_around only
    the grid points between the speed and the edge that decides, and refines only that one.
    At 200 N the band of P >= 0.01 reaches min_speed_rad_s, so from 20 or 1 rad/s the whole
    lower part must be scanned to learn that it offers no nearer safe speed (85 solves in
    the full search; 66, 30 and 62 from 20, 50 and 1 rad/s)."""
    speed_bands(MODEL, LOAD, speed, safe_probability=SAFE)
    full, solves[0] = solves[0], 0
    band_around(MODEL, LOAD, speed, safe_probability=SAFE)
    assert solves[0] <= most * full, (solves[0], full)
    assert solves[0] <= 1 + _BAND_POINTS + _SCAN_BATCH + 2 * _MAX_REFINE


def test_a_speed_jittering_inside_a_band_settles_on_extended_bands(monkeypatch):
    """Each search decides the advice for its own speed only. A later speed a little further
    into the band extends the band found before instead of searching again from scratch, and
    a speed decided by what is known does not cancel a search of the same bin, so a speed
    jittering inside the band (recomputes back to back, as in the node) needs a few searches,
    however slow they are, not one every few recomputes (before: 59 in 500; 26 in another
    run on a loaded machine)."""
    lp = at(SQUEAK)
    searches = []
    submit = lp._worker.submit
    monkeypatch.setattr(lp._worker, "submit", lambda job: searches.append(job) or submit(job))
    speeds = SQUEAK + np.random.default_rng(1).uniform(-0.5, 0.5, 500)
    for i, speed in enumerate(speeds, 1):
        lp.set_speed(float(speed), float(i))
        lp.update(float(i))
        lp.poll_advice()
    assert lp.wait_for_advice(timeout=60.0)
    assert lp.safe_speed_rad_s == pytest.approx(
        full_search_safe_speed(MODEL, LOAD, speeds[-1]), abs=2e-3
    )
    assert len(searches) <= 10, len(searches)


# ----------------------------------------------------------------------------- rate vs cost
def test_recomputes_leave_the_executor_half_its_time():
    """A prediction that takes 30 ms (with 40/40 modes one takes 20-80 ms): the next recompute
    starts at least two prediction times after the start of the last one, whatever
    max_rate_hz allows."""
    ticks = iter([0.0, 0.03, 1.0, 1.001])  # the clock around each prediction
    lp = LivePredictor(MODEL, LiveSettings(max_rate_hz=1000.0), clock=lambda: next(ticks))
    lp.set_speed(STABLE, 0.0)
    lp.set_load(LOAD, 0.0)
    lp.update(0.0)  # took 30 ms
    assert lp.min_interval_s == pytest.approx(0.06)
    lp.set_speed(STABLE + 5.0, 0.0)
    assert not lp.due(0.0599) and lp.due(0.06)
    lp.update(0.06)  # took 1 ms: the rate limit rules again
    assert lp.min_interval_s == pytest.approx(0.002)
    lp.set_speed(STABLE + 10.0, 0.06)
    assert not lp.due(0.0615) and lp.due(0.062)


def test_a_real_40_mode_prediction_sets_the_interval():
    lp = LivePredictor(
        MODEL.with_params(n_bending=40, n_torsion=40), LiveSettings(max_rate_hz=10000.0)
    )
    lp.set_speed(STABLE, 0.0)
    lp.set_load(LOAD, 0.0)
    lp.update(0.0)
    assert lp.min_interval_s > 0.0005  # a 240x240 eig takes > 0.25 ms


# ----------------------------------------------------------------------------- background
def wait_until(condition, timeout: float = 30.0) -> None:
    done = threading.Event()
    deadline = threading.Timer(timeout, done.set)
    deadline.start()
    try:
        while not condition():
            assert not done.wait(0.001), "timed out"
    finally:
        deadline.cancel()


def worker_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "squeak-advice"]


def test_worker_runs_a_job_and_ends_its_thread():
    w, go = LatestWorker(), threading.Event()
    ident = w.submit(lambda checkpoint: go.wait() and "band")
    assert w.busy and w.take() is None  # pending
    [thread] = worker_threads()
    assert thread.daemon  # never keeps the process alive
    go.set()
    assert w.wait(30.0) and not w.busy
    assert w.take() == (ident, "band", None) and w.take() is None  # ready, once
    wait_until(lambda: not thread.is_alive())  # idle: no thread left


def test_worker_latest_request_wins():
    w = LatestWorker()
    first_started, release, log = threading.Event(), threading.Event(), []

    def first(checkpoint):
        first_started.set()
        release.wait(30.0)
        try:
            checkpoint()  # stale by now: abandoned here
        except Superseded:
            log.append("first abandoned")
            raise
        log.append("first finished")

    def job(name):
        def run(checkpoint):
            checkpoint()
            log.append(name)
            return name

        return run

    w.submit(first)
    assert first_started.wait(30.0)
    w.submit(job("second"))  # waits; then replaced by
    last = w.submit(job("third"))  # the third: no queue
    release.set()
    assert w.wait(30.0)
    assert w.take() == (last, "third", None)
    assert log == ["first abandoned", "third"]


def test_worker_reports_errors_and_stops_on_close():
    w = LatestWorker()
    ident = w.submit(lambda checkpoint: 1 / 0)
    assert w.wait(30.0)
    done = w.take()
    assert done[0] == ident and isinstance(done[2], ZeroDivisionError)
    spinning, stopped = threading.Event(), threading.Event()

    def endless(checkpoint):
        spinning.set()
        try:
            while True:
                checkpoint()
        finally:
            stopped.set()

    w.submit(endless)
    assert spinning.wait(30.0)
    w.close(timeout=30.0)
    assert stopped.is_set() and not worker_threads()
    w.submit(lambda checkpoint: "late")  # closed: nothing runs any more
    assert not w.busy and not worker_threads() and w.take() is None


@pytest.fixture
def gate(monkeypatch):
    """Holds every advice search until `gate.set()`; records the (load, speed) searched."""
    go, searched = threading.Event(), []
    search = live_module.band_around

    def held(model, load, speed, margin, checkpoint=None, known=None, *, safe_probability):
        searched.append((load, speed))
        go.models.append(model)
        assert go.wait(30.0)
        return search(
            model,
            load,
            speed,
            margin,
            checkpoint=checkpoint,
            known=known,
            safe_probability=safe_probability,
        )

    monkeypatch.setattr(live_module, "band_around", held)
    go.searched, go.models = searched, []
    return go


def test_advice_is_kept_until_the_new_one_is_ready(gate):
    gate.set()
    lp = at(STABLE)
    assert lp.safe_speed_rad_s == STABLE and not lp.advice_pending
    gate.clear()
    lp.set_speed(SQUEAK, 1.0)
    lp.update(1.0)  # returns at once: search held
    assert lp.advice_pending and lp.safe_speed_rad_s == STABLE
    assert lp.status(1.0).values[KEY_SAFE_SPEED_PENDING] == "true"
    assert not lp.poll_advice() and lp.safe_speed_rad_s == STABLE
    gate.set()
    wait_until(lambda: lp.poll_advice())
    assert not lp.advice_pending
    assert lp.safe_speed_rad_s == pytest.approx(
        full_search_safe_speed(MODEL, LOAD, SQUEAK), abs=2e-3
    )
    assert lp.status(1.0).values[KEY_SAFE_SPEED_PENDING] == "false"
    lp.set_speed(SQUEAK - 1.0, 2.0)  # same band and bin, decided by what is known of it
    lp.update(2.0)
    assert not lp.advice_pending and gate.searched == [(LOAD, SQUEAK)]
    assert lp.safe_speed_rad_s == pytest.approx(
        full_search_safe_speed(MODEL, LOAD, SQUEAK - 1.0), abs=2e-3
    )


def test_the_search_predicts_on_the_live_model(gate):
    """The search on its thread uses the model the executor predicts with (same screw,
    scatter and samples; `SqueakModel.predict` is thread-safe, test_probability.py), so its
    probabilities are the ones the node publishes."""
    gate.set()
    lp = at(SQUEAK)
    [model] = gate.models
    assert model is lp._nut_model
    assert model.predict(SQUEAK, LOAD).probability == lp.prediction.probability


def test_advice_is_for_the_latest_bin(gate):
    lp = live()
    lp.set_speed(SQUEAK, 0.0)
    for i, load in enumerate([LOAD, 300.0, 450.0]):  # three 5 % load bins
        lp.set_load(load, float(i))
        lp.update(float(i))
        assert lp.advice_pending and lp.safe_speed_rad_s is None
    gate.set()
    assert lp.wait_for_advice(timeout=30.0)
    assert lp.safe_speed_rad_s == pytest.approx(
        full_search_safe_speed(MODEL, 450.0, SQUEAK), abs=2e-3
    )
    assert 1 <= len(gate.searched) <= 3 and gate.searched[-1] == (450.0, SQUEAK)


def test_a_squeak_free_point_cancels_the_search(gate):
    lp = live()
    lp.set_speed(SQUEAK, 0.0)
    lp.set_load(LOAD, 0.0)
    lp.update(0.0)
    assert lp.advice_pending
    lp.set_speed(STABLE, 1.0)
    lp.update(1.0)
    assert not lp.advice_pending and lp.safe_speed_rad_s == STABLE
    gate.set()
    assert lp.wait_for_advice(timeout=30.0) and lp.safe_speed_rad_s == STABLE


def test_a_failed_search_keeps_the_last_advice(monkeypatch):
    lp = at(STABLE)

    def broken(*args, **kwargs):
        raise np.linalg.LinAlgError("Eigenvalues did not converge")

    monkeypatch.setattr(live_module, "band_around", broken)
    lp.set_speed(SQUEAK, 1.0)
    lp.update(1.0)
    assert lp.wait_for_advice(timeout=30.0)
    assert lp.safe_speed_rad_s == STABLE
    assert "did not converge" in lp.status(1.0).values[KEY_SAFE_SPEED_ERROR]
    lp.set_speed(SQUEAK + 1.0, 2.0)  # no retry within the bin
    lp.update(2.0)
    assert not lp.advice_pending


def test_close_stops_the_search(gate):
    lp = live()
    lp.set_speed(SQUEAK, 0.0)
    lp.set_load(LOAD, 0.0)
    lp.update(0.0)
    assert lp.advice_pending and worker_threads()
    lp.close()  # the held search is abandoned
    gate.set()
    wait_until(lambda: not worker_threads())
    assert not lp.advice_pending and lp.wait_for_advice(timeout=1.0)


# ----------------------------------------------------------------------------- hypothesis
ANY_INPUT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.none(),
    st.text(),
    st.booleans(),
    st.sampled_from([SQUEAK, -SQUEAK, STABLE, 0.0, 0.1, LOAD, -LOAD, 0.05, 0.24, 1e7]),
)
OPS = st.lists(
    st.tuples(st.sampled_from(["set_speed", "set_load", "set_nut_position"]), ANY_INPUT),
    min_size=1,
    max_size=8,
)


def diagnostic_numbers(status) -> list[float]:
    """Every number in the diagnostic values (comma-separated lists too; NaN and inf parse)."""
    numbers = []
    for value in status.values.values():
        for token in value.split(","):
            try:
                numbers.append(float(token))
            except ValueError:
                pass  # text: formulation, validity, ...
    return numbers


@settings(max_examples=150, deadline=None, derandomize=True)
@given(ops=OPS)
def test_arbitrary_inputs_never_raise_and_never_publish_nan(ops):
    lp, now = live(), 0.0
    for setter, value in ops:
        now += 0.02
        reason = getattr(lp, setter)(value, now)
        assert isinstance(reason, str)
        status = lp.status(now)
        if reason:
            assert status.level == Level.ERROR and reason in status.message
        if lp.due(now):
            p = lp.update(now)
            if p is not None:
                assert p is lp.prediction and p.valid
        if lp.prediction is not None:
            assert all(math.isfinite(v) for v in finite_numbers(lp.prediction, lp.safe_speed_rad_s))
            assert 0.0 <= lp.prediction.probability <= 1.0
        assert all(math.isfinite(x) for x in diagnostic_numbers(status))
