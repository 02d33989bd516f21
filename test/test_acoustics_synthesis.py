# SPDX-License-Identifier: Apache-2.0
"""The simulated microphone: the squeak tone is found, the motor orders are rejected."""

import numpy as np
import pytest

from leadscrew_ros.model.acoustics import detect, microphone
from leadscrew_ros.model.acoustics.tonality import short_time_psd

FS = 48000


def test_tone_found_and_orders_rejected():
    """A stroke: speed ramps 20 -> 300 rad/s and back; squeak at 2480 Hz from 1 s to 2 s."""
    t = np.linspace(0.0, 3.0, 301)
    speed = np.interp(t, [0.0, 0.5, 2.5, 3.0], [20.0, 300.0, 300.0, 20.0])
    sq = np.where((t >= 1.0) & (t < 2.0), 2480.0, np.nan)
    x = microphone(t, speed, sq, squeak_level=0.02, motor_level=0.3)
    assert x.dtype == np.float32 and x.size == 3 * FS + 1
    d = detect(x, FS, speed_times_s=t, speed_rad_s=speed)
    (ep,) = d.episodes
    assert ep.frequency_hz == pytest.approx(2480.0, rel=0.005)
    assert ep.start_s == pytest.approx(1.0, abs=0.05) and ep.end_s == pytest.approx(2.0, abs=0.05)
    assert ep.level_db == pytest.approx(10 * np.log10(0.02**2 / 2), abs=1.0)
    assert d.rejected and {e.order for e in d.rejected} <= {1, 2, 3, 4, 6, 8, 12}
    assert len(detect(x, FS).episodes) > 1  # without the speed the orders stay


def test_orders_follow_the_speed_and_the_envelope():
    t = np.array([0.0, 1.0])
    x = microphone(
        t, [100.0, 100.0], [np.nan, np.nan], motor_orders=(10,), motor_level=1.0, noise_level=0.0
    )
    psd = short_time_psd(x, FS, FS // 2, FS // 2)
    f = np.argmax(psd[0]) * 2.0
    assert f == pytest.approx(10 * 100 / (2 * np.pi), abs=2.0)
    assert np.sqrt(np.mean(x.astype(float) ** 2)) == pytest.approx(0.1 / np.sqrt(2), rel=0.01)
    t = np.linspace(0.0, 1.0, 101)
    sq = np.where(t >= 0.5, 1000.0, np.nan)
    y = microphone(t, np.zeros(t.size), sq, squeak_level=1.0, noise_level=0.0, onset_s=0.02)
    env = np.abs(y[int(0.47 * FS) : int(0.53 * FS)]).reshape(-1, 48).max(axis=1)
    assert env[0] < 1e-3 and env[-1] > 0.99  # raised cosine over 20 ms
    assert env[len(env) // 2] == pytest.approx(0.5, abs=0.1)
    assert np.all(np.diff(env) > -0.05)
    assert microphone([], [], []).size == 0
    assert np.array_equal(
        microphone(t, np.ones(t.size), sq, seed=3), microphone(t, np.ones(t.size), sq, seed=3)
    )
