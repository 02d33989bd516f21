# SPDX-License-Identifier: Apache-2.0
"""Creaks: a stick-slip pulse train is one creak (its pulse rate and ringing frequencies), not
squeak fragments, and is not counted as squeak; a squeak beside it, steady tones, random
clicks and noise make no creak."""

from __future__ import annotations

import numpy as np
import pytest

from leadscrew_ros.model.acoustics import DetectorSettings, detect
from leadscrew_ros.model.acoustics import creak as creak_module
from leadscrew_ros.model.acoustics.creak import find_creaks

FS = 48000.0


def creak(
    rate_hz, rings_hz, tau_s, *, amp=0.3, jitter=0.1, span=(1.0, 2.5), dur=4.0, seed=0, bounces=()
):
    """Noise (-50 dB re full scale) and a pulse train from span[0] to span[1]: pulses at
    `rate_hz` (intervals uniformly +-`jitter`), each a sum of sines at `rings_hz` (random
    phase, each 0.6 of the previous) decaying with `tau_s`, amplitude 0.6-1 x `amp`; each
    followed by secondary slips (`bounces`: (delay s, relative amplitude)), as the ISO 532-1
    door creak (Annex B.5 signal 19) has them: two or three peaks per slip."""
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 10 ** (-50 / 20), int(FS * dur))
    times, t = [], span[0]
    while t < span[1]:
        times.append(t)
        t += (1 + jitter * rng.uniform(-1, 1)) / rate_hz
    tt = np.arange(int(FS * 6 * tau_s)) / FS
    for p in times:
        for delay, share in ((0.0, 1.0), *bounces):
            ring = sum(
                0.6**k * np.sin(2 * np.pi * f * tt + rng.uniform(0, 2 * np.pi))
                for k, f in enumerate(rings_hz)
            )
            i = int((p + delay) * FS)
            x[i : i + tt.size] += share * amp * rng.uniform(0.6, 1.0) * ring * np.exp(-tt / tau_s)
    return x, np.array(times)


CASES = [  # rate, ringing, decay: a slow creak to a buzz at the highest rate, one ring or two
    (8.0, (1400.0, 2900.0), 0.004),
    (25.0, (800.0,), 0.004),
    (60.0, (3000.0, 5200.0), 0.004),
    (120.0, (1900.0,), 0.004),
    (40.0, (600.0, 2100.0), 0.008),
    (180.0, (2500.0,), 0.002),
]


@pytest.mark.parametrize(
    "rate, rings, tau, jitter",
    # +-30 % as well where the shortest interval stays over 1 / creak_max_rate_hz (5 ms)
    [(*case, j) for case in CASES for j in (0.1, 0.3) if case[0] * (1 + j) < 200.0],
)
def test_a_pulse_train_is_one_creak_with_its_rate_and_ringing(rate, rings, tau, jitter):
    x, times = creak(rate, rings, tau, jitter=jitter, seed=int(rate))
    [c] = find_creaks(x, FS)
    # a pulse's peak block lies within its first few ms (its rings beat)
    assert c.start_s == pytest.approx(times[0], abs=0.004)
    assert c.end_s == pytest.approx(times[-1], abs=0.004)
    assert c.pulses >= 0.9 * times.size
    assert c.pulse_rate_hz == pytest.approx(1 / np.median(np.diff(times)), rel=0.05)
    assert c.ringing_hz[0] == pytest.approx(rings[0], rel=0.05)
    for f in rings:
        assert any(abs(r / f - 1) < 0.05 for r in c.ringing_hz), (f, c.ringing_hz)


@pytest.mark.parametrize("bounces", [((0.0055, 0.7),), ((0.0055, 0.7), (0.013, 0.4))])
def test_a_slip_that_bounces_is_one_pulse(bounces):
    """Slips of a door creak's kind (55 ms apart, each with peaks 5.5 and 13 ms after it):
    one pulse per slip, at the slips' rate, not the peaks'."""
    x, times = creak(18.0, (760.0, 1480.0), 0.003, jitter=0.2, bounces=bounces, span=(0.5, 2.5))
    [c] = find_creaks(x, FS)
    assert c.pulse_rate_hz == pytest.approx(1 / np.median(np.diff(times)), rel=0.05)
    assert abs(c.pulses - times.size) <= 1


def test_a_creak_is_not_squeak_and_a_squeak_beside_it_is():
    """The tonal detector alone hears the creak's ringing as squeak; with the creak found those
    fragments are its own (`fragments_hz`), the frames of the creak are not heard as squeak
    (the agreement's input), and a squeak that follows is kept whole."""
    x, times = creak(25.0, (1400.0, 2900.0), 0.004)
    t = np.arange(x.size) / FS
    x[t >= 3.0] += 0.05 * np.sin(2 * np.pi * 1234.0 * t[t >= 3.0])
    d = detect(x, FS)
    [c] = d.creaks
    assert c.fragments_hz and all(
        any(abs(f / r - 1) < 0.05 for r in (1400.0, 2900.0)) for f in c.fragments_hz
    )
    [e] = d.episodes
    assert e.frequency_hz == pytest.approx(1234.0, rel=0.01)
    assert e.start_s == pytest.approx(3.0, abs=0.06)
    inside = (d.frame_times_s > times[0]) & (d.frame_times_s < times[-1])
    assert inside.any() and not d.heard[inside].any()
    assert d.as_dict()["creaks"][0]["pulses"] == c.pulses


def test_random_clicks_steady_tones_and_noise_make_no_creak():
    rng = np.random.default_rng(5)
    n = int(FS * 10)
    t = np.arange(n) / FS
    tones = 0.01 * rng.normal(size=n) + 0.2 * np.sin(2 * np.pi * 900 * t) * (t > 3)
    tones += sum(0.05 * np.sin(2 * np.pi * f * t) for f in (224.0, 448.0, 672.0, 896.0))
    assert find_creaks(tones, FS) == []
    clicks = 0.003 * rng.normal(size=n)
    pulse = 0.3 * np.exp(-np.arange(200) / 40) * np.sin(np.arange(200) * 0.5)
    for p in np.cumsum(rng.exponential(0.04, 240)):  # Poisson, 25 per second
        i = int(p * FS)
        if i + pulse.size < n:
            clicks[i : i + pulse.size] += pulse
    assert find_creaks(clicks, FS) == []


def test_too_few_pulses_or_a_pause_are_no_creak():
    s = DetectorSettings()
    x, _ = creak(25.0, (1400.0,), 0.004, span=(1.0, 1.0 + (s.creak_min_pulses - 1.5) / 25.0))
    assert find_creaks(x, FS, settings=s) == []
    x, _ = creak(25.0, (1400.0,), 0.004, span=(1.0, 1.5))
    y, _ = creak(25.0, (1400.0,), 0.004, span=(2.0, 2.5), seed=1)
    assert len(find_creaks(x + y, FS)) == 2  # 0.5 s apart: more than 1 / creak_min_rate_hz


@pytest.mark.parametrize("samples", [np.zeros(10), np.full(48000, np.nan), np.ones(96000)])
def test_short_silent_or_broken_input_gives_no_creak(samples):
    assert find_creaks(samples, FS) == []


def test_listen_reports_a_creak_in_a_recording(tmp_path):
    """`leadscrew-squeak listen FILE.wav`: heard.json's creaks and summary.txt's line."""
    import json

    from scipy.io import wavfile

    from leadscrew_ros.cli import main

    x, times = creak(25.0, (1400.0, 2900.0), 0.004)
    wavfile.write(tmp_path / "creak.wav", int(FS), x.astype(np.float32))
    assert main(["listen", str(tmp_path / "creak.wav"), "--out", str(tmp_path / "out")]) == 0
    heard = json.loads((tmp_path / "out" / "heard.json").read_text())
    [c] = heard["creaks"]
    assert c["pulses"] >= 0.9 * times.size and heard["episodes"] == []
    summary = (tmp_path / "out" / "summary.txt").read_text()
    assert "creak (stick-slip pulses)" in summary and "not counted as squeak" in summary


@pytest.mark.parametrize("window_s", [0.7, 1.3])
def test_a_long_recording_is_searched_in_windows_and_a_train_across_them_is_one_creak(
    monkeypatch, window_s
):
    """A recording longer than a window is searched window by window (bounded memory); a
    train crossing window boundaries is still one creak with the pulses of the whole, and a
    second train after a pause is its own. Windows shrunk so a short test crosses several."""
    x, times = creak(25.0, (800.0,), 0.004, span=(0.5, 3.2), dur=5.0, seed=3)
    later, times2 = creak(60.0, (3000.0,), 0.004, span=(0.3, 0.9), dur=1.0, seed=4)
    x[int(3.9 * FS) : int(4.9 * FS)] += later[: int(1.0 * FS)]
    whole = find_creaks(x, FS)
    monkeypatch.setattr(creak_module, "WINDOW_S", window_s)
    monkeypatch.setattr(creak_module, "OVERLAP_S", 0.2)
    windowed = find_creaks(x, FS)
    assert len(whole) == len(windowed) == 2
    for a, b, t in zip(whole, windowed, (times, times2 + 3.9), strict=True):
        assert b.start_s == pytest.approx(t[0], abs=0.004)
        assert b.end_s == pytest.approx(t[-1], abs=0.004)
        assert abs(b.pulses - a.pulses) <= 1
        assert b.pulse_rate_hz == pytest.approx(a.pulse_rate_hz, rel=0.02)
        assert b.ringing_hz[0] == pytest.approx(a.ringing_hz[0], rel=0.05)
