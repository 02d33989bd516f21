"""LivePredictor (the node's recompute policy) without ROS: deadbands, rate limit, coalescing,
input validation, validity, staleness, the diagnostic verdict and safe-speed advice.

Time is the `now` argument (monotonic seconds): nothing here sleeps."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadscrew_ros.live import Level, LivePredictor, LiveSettings
from leadscrew_ros.model import Prediction, SqueakModel
from leadscrew_ros.model.advice import speed_bands

MODEL = SqueakModel()                        # Table 1; unstable band ~0.81..55.2 rad/s at 200 N
LOAD = 200.0
SQUEAK, STABLE, NEAR_EDGE = 20.0, 100.0, 55.5  # rad/s: squeak / risk ~0.02 / stable, risk ~0.79


def live(**settings) -> LivePredictor:
    return LivePredictor(MODEL, LiveSettings(**settings))


def at(speed: float, load: float = LOAD, now: float = 0.0, **settings) -> LivePredictor:
    """A predictor that has computed one prediction at (speed, load)."""
    lp = live(**settings)
    assert lp.set_speed(speed, now) == "" and lp.set_load(load, now) == ""
    assert lp.due(now)
    lp.update(now)
    assert lp.wait_for_advice(timeout=60.0)
    return lp


def finite_numbers(p: Prediction, safe_speed: float | None) -> list[float]:
    numbers = [p.speed_rad_s, p.load_n, p.risk, *p.divergence_rates, *p.unstable_frequencies_hz]
    numbers += [v for m in p.modes for v in (m.frequency_hz, m.growth_rate, m.damping_ratio)]
    return numbers + ([] if safe_speed is None else [safe_speed])


# ----------------------------------------------------------------------------- start-up
def test_nothing_is_due_before_speed_and_load_arrive():
    lp = live()
    assert not lp.due(0.0) and lp.update(0.0) is None and lp.recomputes == 0
    lp.set_speed(SQUEAK, 0.0)
    assert not lp.due(0.0)                     # load still missing
    assert lp.status(0.0).level == Level.STALE
    lp.set_load(LOAD, 0.0)
    assert lp.due(0.0)


# ----------------------------------------------------------------------------- deadbands
@pytest.mark.parametrize("setter, below, above", [
    ("set_speed", STABLE + 0.05, STABLE + 0.2),           # speed_deadband_rad_s = 0.1
    ("set_speed", STABLE - 0.09, STABLE - 0.11),
    ("set_load", LOAD + 0.5, LOAD + 1.5),                 # load_deadband_n = 1
    ("set_nut_position", 0.15 + 0.0004, 0.15 + 0.0006),   # nut_deadband_m = 0.0005
])
def test_deadbands(setter, below, above):
    lp = at(STABLE)
    assert not lp.due(1.0)
    assert getattr(lp, setter)(below, 1.0) == ""
    assert not lp.due(1.0)
    assert getattr(lp, setter)(above, 1.0) == ""
    assert lp.due(1.0)


def test_deadband_is_measured_from_the_last_recompute_not_the_last_input():
    lp = at(STABLE)
    for i in range(1, 6):                      # creeping by 0.04 rad/s: 0.2 in total
        lp.set_speed(STABLE + 0.04 * i, 1.0)
    assert lp.due(1.0)


# ----------------------------------------------------------------------------- rate limit
def test_rate_limit():
    lp = at(STABLE, max_rate_hz=10.0)                    # computed at t = 0
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
    assert lp.recomputes == 2                  # the first one in at() and this one
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
    assert lp.due(duration + 0.01)             # the tick after the burst picks up the rest
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
]


GOOD = {"set_speed": SQUEAK, "set_load": LOAD, "set_nut_position": 0.15}


@pytest.mark.parametrize("setter, value, words", BAD_INPUTS,
                         ids=[f"{s}-{v!r:.20}" for s, v, _ in BAD_INPUTS])
def test_invalid_input_is_rejected_and_named(setter, value, words):
    lp = at(SQUEAK)
    good, safe, inputs = lp.prediction, lp.safe_speed_rad_s, vars(lp.inputs).copy()
    reason = getattr(lp, setter)(value, 1.0)
    for w in words:
        assert w in reason, (w, reason)
    status = lp.status(1.0)
    assert status.level == Level.ERROR
    assert status.message == f"invalid input: {reason}"
    assert vars(lp.inputs) == inputs           # the bad value is not stored
    assert not lp.due(1.0)                     # nothing to recompute
    assert lp.prediction is good and lp.safe_speed_rad_s == safe
    # a good value of the same input clears the error; the verdict is the prediction's again
    getattr(lp, setter)(GOOD[setter], 1.0)
    assert lp.status(1.0).message.startswith("squeak predicted")


def test_an_input_error_lasts_until_that_input_is_good_again():
    lp = at(SQUEAK)
    lp.set_speed(math.nan, 1.0)
    lp.set_load(LOAD, 1.0)                     # another input being fine does not hide it
    lp.set_nut_position(0.1, 1.0)
    assert lp.status(1.0).message == "invalid input: speed = nan is not finite (rad/s)"
    lp.set_load(None, 1.0)                     # two bad inputs: both named
    message = lp.status(1.0).message
    assert "speed = nan" in message and "load = None" in message
    lp.set_speed(SQUEAK, 1.0)
    assert lp.status(1.0).message == "invalid input: load = None is not a number (N)"
    lp.set_load(LOAD, 1.0)
    assert lp.status(1.0).level == Level.ERROR and "squeak" in lp.status(1.0).message


# ----------------------------------------------------------------------------- validity
@pytest.mark.parametrize("speed, words", [(0.1, "below min_speed_rad_s"),
                                          (-0.1, "below min_speed_rad_s"),
                                          (5000.0, "critical speed")])
def test_outside_validity_keeps_the_last_good_prediction(speed, words):
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
    assert status.values["valid"] == "false"
    assert not lp.due(1.5)                     # no retry until the point moves
    lp.set_speed(STABLE, 2.0)                  # back inside: a new prediction, verdict OK
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
    lp.set_speed(STABLE, 11.5)                 # fresh speed, load still old
    status = lp.status(11.6)
    assert status.level == Level.STALE
    assert "axial_load" in status.message and "motor_speed" not in status.message
    lp.set_load(LOAD, 11.6)
    assert lp.status(11.7).level == Level.OK
    assert lp.prediction is not None            # staleness never drops the last prediction


# ----------------------------------------------------------------------------- verdict
def test_squeak_is_error():
    lp = at(SQUEAK)
    status = lp.status(0.0)
    assert status.level == Level.ERROR
    assert status.message == "squeak predicted: B1y 224 Hz, B2y 898 Hz"
    assert status.values["risk"] == "1" and status.values["valid"] == "true"
    assert status.values["squeak_frequencies_hz"] == "224.3, 897.9"


def test_stable_but_risk_above_threshold_is_warn():
    lp = at(NEAR_EDGE)
    p = lp.prediction
    assert p.stable and 0.5 < p.risk < 1.0
    status = lp.status(0.0)
    assert status.level == Level.WARN and "above 0.5" in status.message
    assert at(NEAR_EDGE, risk_warn_threshold=0.9).status(0.0).level == Level.OK


def test_stable_low_risk_is_ok():
    lp = at(STABLE)
    assert lp.prediction.stable and lp.prediction.risk < 0.5
    status = lp.status(0.0)
    assert status.level == Level.OK and status.message.startswith("no squeak")


# ----------------------------------------------------------------------------- nut position
def test_nut_movement_beyond_the_deadband_changes_the_prediction():
    lp = at(SQUEAK)
    lp.set_nut_position(0.02, 1.0)
    assert lp.due(1.0)
    near_end = lp.update(1.0)
    lp.set_nut_position(0.12, 2.0)
    assert lp.due(2.0)
    middle = lp.update(2.0)
    expected = {z: MODEL.with_params(nut_position_m=z).predict(SQUEAK, LOAD).max_growth_rate
                for z in (0.02, 0.12)}
    assert near_end.max_growth_rate == pytest.approx(expected[0.02], rel=1e-9)
    assert middle.max_growth_rate == pytest.approx(expected[0.12], rel=1e-9)
    assert abs(near_end.max_growth_rate - middle.max_growth_rate) > 10.0   # 44.6 vs 81.8 1/s
    assert lp.status(2.0).values["nut_position_m"] == "0.12"


def test_contact_is_reintegrated_only_beyond_the_nut_deadband():
    """A speed change recomputes; a nut drift within nut_deadband_m keeps the same geometry."""
    lp = at(SQUEAK)
    lp.set_nut_position(0.1, 1.0)
    lp.update(1.0)
    built = lp._nut_model.geometry.contact
    lp.set_nut_position(0.1 + 0.0003, 2.0)             # within the 0.5 mm deadband
    lp.set_speed(SQUEAK + 1.0, 2.0)
    assert lp.update(2.0) is not None
    assert lp._nut_model.geometry.contact is built
    assert lp._nut_model.params.nut_position_m == 0.1
    lp.set_nut_position(0.1 + 0.0008, 3.0)             # beyond it
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
    assert p.unstable_frequencies_hz[0] == pytest.approx(2654.0, rel=1e-3)   # T1


# ----------------------------------------------------------------------------- safe speed
def test_safe_speed_of_a_stable_point_is_the_speed():
    assert at(STABLE).safe_speed_rad_s == STABLE
    assert at(-STABLE).safe_speed_rad_s == -STABLE


@pytest.mark.parametrize("speed", [SQUEAK, -SQUEAK])
def test_safe_speed_of_a_squeaking_point_is_outside_the_band(speed):
    lp = at(speed)
    safe = lp.safe_speed_rad_s
    assert not lp.prediction.stable
    assert safe != 0.0 and math.copysign(1.0, safe) == math.copysign(1.0, speed)
    for lo, hi in speed_bands(MODEL, LOAD, speed):
        assert not lo <= abs(safe) <= hi
    check = MODEL.predict(safe, LOAD)
    assert check.valid and check.stable


# ----------------------------------------------------------------------------- hypothesis
ANY_INPUT = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.none(), st.text(),
                      st.booleans(), st.sampled_from([SQUEAK, -SQUEAK, STABLE, 0.0, 0.1,
                                                      LOAD, -LOAD, 0.05, 0.24, 1e7]))
OPS = st.lists(st.tuples(st.sampled_from(["set_speed", "set_load", "set_nut_position"]),
                         ANY_INPUT), min_size=1, max_size=8)


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
            assert all(math.isfinite(v) for v in finite_numbers(lp.prediction,
                                                                  lp.safe_speed_rad_s))
            assert 0.0 <= lp.prediction.risk <= 1.0
        assert status.level in tuple(Level)
