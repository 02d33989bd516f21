# SPDX-License-Identifier: Apache-2.0
"""The guard's policy (`live.guard`) without ROS: property tests over random command sequences,
limits, loads, nut positions and band layouts (limits, no reversal, the delay bound, pass
through where no band is, stops at once), and the fail-safe paths.

Acceleration and jerk are the output's finite differences a_k = (v_k - v_{k-1}) / dt,
j_k = (a_k - a_{k-1}) / dt, with a_k = 0 at a stop step (the tracker restarts from rest).
Limits are checked to a relative 1e-9 (float rounding)."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from leadscrew_ros.live.guard import GuardBands, GuardPolicy, GuardSettings, reach_time
from leadscrew_ros.live.recompute import band_bin

RTOL = 1e-9
REACH_STEPS = 4  # discrete steps the tracker may lag its continuous reach-time bound


def limits():
    return st.builds(
        lambda v, a, j, d, p: GuardSettings(
            max_speed_rad_s=v, max_accel_rad_s2=a, max_jerk_rad_s3=j, max_delay_s=d, p_max=p
        ),
        st.floats(20.0, 300.0),
        st.floats(50.0, 3000.0),
        st.floats(1e3, 1e5),
        st.floats(0.0, 1.0),
        st.floats(0.01, 1.0),
    )


@st.composite
def band_layouts(draw):
    """Disjoint |speed| bands in (0.3, 400) rad/s, ascending."""
    edges = sorted(draw(st.lists(st.floats(0.3, 400.0), min_size=0, max_size=6, unique=True)))
    edges = edges[: len(edges) // 2 * 2]
    return tuple((edges[i], edges[i + 1]) for i in range(0, len(edges), 2))


def policy_with(s, load, nut, up, down):
    """A policy whose cache holds the given bands for this load and nut position."""
    policy = GuardPolicy(s)
    for direction, intervals in ((1.0, up), (-1.0, down)):
        key = band_bin(load, nut, direction)
        policy.bands[key] = GuardBands(key, intervals)
    return policy


def check_limits(out, commands, stops, dt, s):
    """Limits on every step, no reversal, stops at zero commands."""
    a_prev, v_prev = 0.0, 0.0
    for v, c, stop in zip(out, commands, stops, strict=True):
        if c == 0.0:
            assert v == 0.0 and stop
        if stop:
            assert v == 0.0
            a_prev = v_prev = 0.0
            continue
        a = (v - v_prev) / dt
        assert abs(v) <= s.max_speed_rad_s * (1 + RTOL)
        assert abs(a) <= s.max_accel_rad_s2 * (1 + RTOL)
        assert abs(a - a_prev) <= s.max_jerk_rad_s3 * dt * (1 + RTOL) + 1e-9 * abs(a)
        if v * c < 0:  # on the other side of zero only while braking from the last direction
            assert v_prev * c < 0
        a_prev, v_prev = a, v


@st.composite
def held_commands(draw, s, dt):
    """Commands held long enough for the delay bound to be checked: (value, steps) pairs."""
    worst = reach_time(-s.max_speed_rad_s, -s.max_accel_rad_s2, s.max_speed_rad_s, s)
    steps = int(math.ceil((worst + s.max_delay_s) / dt)) + 2 * REACH_STEPS
    values = draw(
        st.lists(
            st.one_of(st.just(0.0), st.floats(-1.2 * s.max_speed_rad_s, 1.2 * s.max_speed_rad_s)),
            min_size=1,
            max_size=4,
        )
    )
    return [(v, steps) for v in values]


@settings(max_examples=60, deadline=None)
@given(
    s=limits(),
    dt=st.floats(0.002, 0.02),
    load=st.floats(10.0, 2000.0),
    nut=st.floats(0.0, 0.24),
    up=band_layouts(),
    down=band_layouts(),
    data=st.data(),
)
def test_limits_reversal_and_delay_bound(s, dt, load, nut, up, down, data):
    """Held commands: limits hold, no reversal, every command reached (|v - c| <= 1e-9 |c|
    and staying) within reach_time from the state when it was commanded + max_delay_s (+ a
    few steps), zero at once."""
    policy = policy_with(s, load, nut, up, down)
    segments = data.draw(held_commands(s, dt))
    policy.step(0.0, 0.0, load, nut)  # the clock starts
    out, commands, stops = [], [], []
    t, k = 0.0, 0
    v_prev = a_prev = 0.0
    for value, steps in segments:
        c = max(-s.max_speed_rad_s, min(s.max_speed_rad_s, value))
        t0 = (k + 1) * dt
        bound = t0 + reach_time(v_prev, a_prev, c, s) + s.max_delay_s + REACH_STEPS * dt
        reached = None
        for _ in range(steps):
            k += 1
            t = k * dt
            step = policy.step(t, value, load, nut)
            out.append(step.speed_rad_s)
            commands.append(c)
            stops.append(step.stopped)
            a_now = 0.0 if step.stopped else (step.speed_rad_s - v_prev) / dt
            v_prev, a_prev = step.speed_rad_s, a_now
            close = abs(step.speed_rad_s - c) <= 1e-9 * max(abs(c), 1e-9)
            if close and reached is None:
                reached = t
            elif not close:
                reached = None  # must stay
        assert reached is not None and reached <= bound + 1e-9, (value, reached, bound)
    check_limits(out, commands, stops, dt, s)


@st.composite
def smooth_commands(draw, s, dt):
    """A command within the limits from rest: random jerk integrated, |c| <= max_speed / 2."""
    n = draw(st.integers(5, 400))
    jerks = draw(st.lists(st.floats(-1.0, 1.0), min_size=n, max_size=n))
    v = a = 0.0
    out = []
    for j in jerks:
        a_new = (
            max(
                -0.9,
                min(
                    0.9,
                    a / s.max_accel_rad_s2 + 0.9 * j * s.max_jerk_rad_s3 * dt / s.max_accel_rad_s2,
                ),
            )
            * s.max_accel_rad_s2
        )
        if abs(v + a_new * dt) > s.max_speed_rad_s / 2:
            a_new = (
                0.0
                if abs(a) <= s.max_jerk_rad_s3 * dt * 0.9
                else a - math.copysign(0.9 * s.max_jerk_rad_s3 * dt, a)
            )
        if abs(v + a_new * dt) > s.max_speed_rad_s / 2:
            break
        v, a = v + a_new * dt, a_new
        out.append(v)
    return out


@settings(max_examples=80, deadline=None)
@given(
    s=limits(),
    dt=st.floats(0.002, 0.02),
    load=st.floats(10.0, 2000.0),
    nut=st.floats(0.0, 0.24),
    data=st.data(),
)
def test_equals_command_where_no_band(s, dt, load, nut, data):
    """P below p_max along the way (no band at any commanded speed) and a command within the
    limits: the output is the command."""
    assume(
        s.max_accel_rad_s2**2 / (2 * s.max_jerk_rad_s3) + s.max_accel_rad_s2 * dt
        <= s.max_speed_rad_s / 2
    )
    commands = data.draw(smooth_commands(s, dt))
    top = max((abs(c) for c in commands), default=0.0)
    policy = policy_with(s, load, nut, ((top * 1.01 + 1, top * 2 + 2),), ())
    policy.step(0.0, 0.0, load, nut)  # at rest when the clock starts
    for k, c in enumerate(commands, 1):
        step = policy.step(k * dt, c, load, nut)
        assert step.speed_rad_s == pytest.approx(c, rel=1e-9, abs=1e-9)
        assert not step.active


@settings(max_examples=40, deadline=None)
@given(
    commands=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), max_size=30),
)
def test_disabled_is_exact_pass_through(commands):
    policy = GuardPolicy(GuardSettings(enabled=False))
    for k, c in enumerate(commands):
        step = policy.step(0.01 * k, c, 100.0, 0.1)
        assert step.speed_rad_s == c or (math.isnan(c) and math.isnan(step.speed_rad_s))
        assert not step.active


def ramp_through(policy, **inputs):
    """A 0 -> 80 rad/s command in 2 s at 100 Hz; the outputs and the last reason."""
    out, reasons = [], []
    policy.step(0.0, 0.0, **inputs)  # at rest when the clock starts
    for k in range(1, 201):
        step = policy.step(0.01 * k, 0.4 * k, **inputs)
        out.append(step.speed_rad_s)
        reasons.append(step.reason)
    return np.array(out), reasons


BAND = ((1.0, 50.0),)


def banded(s=None):
    return policy_with(s or GuardSettings(), 200.0, 0.1, BAND, BAND)


def test_band_avoided():
    """The reference: with valid inputs the ramp leaves the band (the fault tests compare)."""
    out, reasons = ramp_through(banded(), load_n=200.0, nut_position_m=0.1)
    inside = (np.abs(out) > 1.0) & (np.abs(out) < 50.0)
    crossing = reach_time(0.0, 0.0, 50.0, GuardSettings())  # a move at the limits
    assert 0 < inside.sum() * 0.01 <= crossing + 0.02
    assert any("squeak band" in r for r in reasons)


@pytest.mark.parametrize(
    ("inputs", "said"),
    [
        (dict(load_n=None, nut_position_m=0.1), "no load or nut position"),
        (dict(load_n=math.nan, nut_position_m=0.1), "not finite"),
        (dict(load_n=200.0, nut_position_m=math.inf), "not finite"),
        (dict(load_n=200.0, nut_position_m=0.1, input_age_s=5.0), "older than"),
        (dict(load_n=200.0, nut_position_m=0.1, input_age_s=math.nan), "not finite"),
    ],
)
def test_bad_inputs_pass_through(inputs, said):
    """The command passes through (rate limits aside): the output is the plain tracker's."""
    out, reasons = ramp_through(banded(), **inputs)
    plain, _ = ramp_through(
        policy_with(GuardSettings(), 200.0, 0.1, (), ()), load_n=200.0, nut_position_m=0.1
    )
    np.testing.assert_allclose(out, plain, rtol=1e-12)
    assert all(said in r for r in reasons)


def test_model_error_and_missing_bands_pass_through():
    policy = GuardPolicy()
    key = band_bin(200.0, 0.1, 1.0)
    policy.bands[key] = GuardBands(key, (), "squeak band search failed: boom")
    out, reasons = ramp_through(policy, load_n=200.0, nut_position_m=0.1)
    assert np.allclose(out, 0.4 * np.arange(1, 201))  # within the limits: the command
    assert all("boom" in r and "passed through" in r for r in reasons)
    fresh = GuardPolicy()
    _, reasons = ramp_through(fresh, load_n=200.0, nut_position_m=0.1)
    assert key in fresh.wanted and all("not ready" in r for r in reasons)


def test_band_search_error_is_text():
    class Broken:
        def with_params(self, **_):
            raise RuntimeError("no geometry")

    bands = GuardBands.compute(Broken(), band_bin(200.0, 0.1, 1.0), 0.1)  # type: ignore[arg-type]
    assert bands.intervals == () and "no geometry" in bands.error


def test_deadline_missed_passes_through():
    now = [0.0]
    policy = banded()
    policy.clock = lambda: now[0]
    now[0] = 1.0  # every command arrived 1 s before its step
    out, reasons = ramp_through(policy, load_n=200.0, nut_position_m=0.1, arrived_s=0.0)
    assert all("deadline_s" in r for r in reasons)
    assert np.allclose(out, 0.4 * np.arange(1, 201))


def test_nan_command_keeps_the_last_good_one():
    policy = banded()
    policy.step(0.01, 60.0, 200.0, 0.1)
    good = [policy.step(0.01 * k, 60.0, 200.0, 0.1).speed_rad_s for k in range(2, 50)]
    step = policy.step(0.5, math.nan, 200.0, 0.1)
    assert "not a finite number" in step.reason and "kept 60" in step.reason
    assert math.isfinite(step.speed_rad_s) and step.speed_rad_s >= good[-1]


def test_stop_at_once_and_no_reversal():
    policy = banded()
    for k in range(1, 30):
        policy.step(0.01 * k, 80.0, 200.0, 0.1)
    step = policy.step(0.30, 0.0, 200.0, 0.1)
    assert step.speed_rad_s == 0.0 and step.stopped
    step = policy.step(0.31, -80.0, 200.0, 0.1)
    assert -80.0 < step.speed_rad_s < 0.0
