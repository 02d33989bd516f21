# SPDX-License-Identifier: Apache-2.0
"""A squeak's growth rate at its onset, measured from the sound (`acoustics.growth`): against
the amplitude equation's sigma on a clean tone and on a realistic bench (room, fan, mains hum,
a geared motor, pink noise), no rate and a reason where the onset is too weak, and the fields
each episode carries."""

from __future__ import annotations

import numpy as np
import pytest

from leadscrew_ros.model.acoustics import detect
from leadscrew_ros.model.acoustics.bench_sound import BenchSound, bench_microphone
from leadscrew_ros.model.acoustics.envelope import ENVELOPE_RATE_HZ, squeak_envelope
from leadscrew_ros.model.acoustics.growth import MIN_SNR_DB, hann_lowpass, onset_growth

FS = 48000.0
ON_S = 1.5  # sigma steps from -30 1/s to its value here and back at 3 s


def _episode(samples, f0, times=None, speed=None):
    d = detect(samples, FS, speed_times_s=times, speed_rad_s=speed)
    near = [e for e in d.episodes if abs(e.frequency_hz / f0 - 1) < 0.03]
    assert near, [e.frequency_hz for e in d.episodes]
    return near[0]


@pytest.mark.parametrize("f0", [224.0, 898.0, 2480.0])
@pytest.mark.parametrize("sigma", [10.0, 40.0, 80.0])
def test_the_rate_of_a_clean_tone_that_grows_and_saturates(sigma, f0):
    """A tone growing by the amplitude equation from 80 dB under its saturation, in white
    noise 40 dB under it: within 12 % of sigma, the standard error a fraction of it."""
    rng = np.random.default_rng(int(sigma + f0))
    grid = np.arange(0.0, 3.0, 1 / ENVELOPE_RATE_HZ)
    amplitude = squeak_envelope(
        np.where(grid >= ON_S, sigma, -50.0), 1 / ENVELOPE_RATE_HZ, 0.1, 1e-5
    )
    t = np.arange(int(3.0 * FS)) / FS
    x = np.interp(t, grid, amplitude) * np.sin(2 * np.pi * f0 * t) + rng.normal(0, 1e-3, t.size)
    g = _episode(x, f0).growth
    assert g is not None and g.rate_per_s is not None, g
    assert g.rate_per_s == pytest.approx(sigma, rel=0.12)
    assert 0 < g.se_per_s < 0.25 * sigma
    assert g.window_s[0] < g.window_s[1]


def test_the_rate_on_a_realistic_bench_of_known_growth():
    """The bench's sound (a room of RT60 0.3 s, a fan, mains hum, a worm gear at 37.3x and its
    commutator, pink noise) with sigma held through each onset: over the onsets measured 15 dB
    or more over the background in the squeak's band, the median of measured / sigma within
    0.85-1.15 (issue 30); the weak ones give no rate and say why."""
    ratios, reasons = [], []
    cases = [(s, f, d) for s in (15.0, 30.0, 60.0) for f in (898.0, 2480.0) for d in (-30, -40)]
    for k, (sigma, f0, level_db) in enumerate(cases):
        times = np.array([0.0, ON_S, ON_S + 1e-4, 3.0, 3.0 + 1e-4, 4.0])
        growth = np.array([-30.0, -30.0, sigma, sigma, -30.0, -30.0])
        speed = np.full(times.size, 40.0)
        bench = bench_microphone(
            times,
            speed,
            growth,
            np.full(times.size, f0),
            10 ** (level_db / 20),
            40.0,
            BenchSound(),
            FS,
            seed=k,
        )
        g = _episode(bench.samples, f0, times, speed).growth
        if g.rate_per_s is None:
            reasons.append(g.reason)
        elif g.snr_db >= 15.0:
            ratios.append(g.rate_per_s / sigma)
    assert len(ratios) >= 0.75 * len(cases), (ratios, reasons)
    assert 0.85 <= float(np.median(ratios)) <= 1.15, ratios
    assert all(reasons), reasons


def test_a_weak_onset_gives_no_rate_and_says_why():
    """A tone about as strong as the noise in its band (the detector would not follow it; given as a
    track here), no quiet stretch, no track: no rate, and the reason."""
    rng = np.random.default_rng(3)
    t = np.arange(int(3.0 * FS)) / FS
    x = 4e-4 * (t >= ON_S) * np.sin(2 * np.pi * 1000.0 * t) + rng.normal(0, 0.01, t.size)
    track_t = np.arange(ON_S, 2.5, 0.01)
    g = onset_growth(x, FS, 0.0, ON_S, track_t, np.full(track_t.size, 1000.0))
    assert g.rate_per_s is None and g.se_per_s is None
    assert g.snr_db < MIN_SNR_DB and g.reason.endswith(f"below {MIN_SNR_DB:g} dB")
    g = onset_growth(x, FS, 0.0, 0.2, track_t, np.full(track_t.size, 1000.0))
    assert g.rate_per_s is None and g.reason == "no quiet stretch before the onset"
    g = onset_growth(x, FS, 0.0, ON_S, track_t, np.full(track_t.size, np.nan))
    assert g.rate_per_s is None and g.reason == "no frequency track"


def test_a_tone_switched_on_is_a_step_not_a_growth():
    """A tone switched on at once, 30 dB over the noise: no rate, and a step (the sound crossed
    the fit's range within the band's window); one growing at 20 1/s from under the noise is
    no step."""
    rng = np.random.default_rng(4)
    t = np.arange(int(3.0 * FS)) / FS
    noise = rng.normal(0, 0.003, t.size)
    track_t = np.arange(ON_S, 2.5, 0.01)
    switched = 0.3 * (t >= ON_S) * np.sin(2 * np.pi * 1000.0 * t) + noise
    g = onset_growth(switched, FS, 0.0, ON_S, track_t, np.full(track_t.size, 1000.0))
    assert g.rate_per_s is None and g.step and "a step" in g.reason, g
    grown = 0.3 * np.minimum(np.exp(20.0 * (t - 2.0)), 1.0) * np.sin(2 * np.pi * 1000.0 * t)
    g = onset_growth(grown + noise, FS, 0.0, 1.85, track_t, np.full(track_t.size, 1000.0))
    assert g.rate_per_s == pytest.approx(20.0, rel=0.15) and not g.step, g


def test_the_episode_fields_are_json_safe_and_live_says_not_measured():
    from leadscrew_ros.model.acoustics import StreamingDetector

    rng = np.random.default_rng(4)
    grid = np.arange(0.0, 3.0, 1 / ENVELOPE_RATE_HZ)
    amplitude = squeak_envelope(
        np.where(grid >= ON_S, 40.0, -50.0), 1 / ENVELOPE_RATE_HZ, 0.1, 1e-5
    )
    t = np.arange(int(3.0 * FS)) / FS
    x = np.interp(t, grid, amplitude) * np.sin(2 * np.pi * 898.0 * t) + rng.normal(0, 1e-3, t.size)
    fields = _episode(x, 898.0).as_dict()
    assert set(fields) >= {
        "growth_rate_per_s",
        "growth_rate_se",
        "growth_window_s",
        "growth_snr_db",
    }
    assert isinstance(fields["growth_rate_per_s"], float) and len(fields["growth_window_s"]) == 2
    live = StreamingDetector(sample_rate_hz=FS)
    episodes = live.push(x.astype(np.float32), 0.0) + live.flush()
    assert episodes and all(e.as_dict()["growth_reason"] == "not measured" for e in episodes)


@pytest.mark.parametrize(
    "n, m, hop", [(82000, 4800, 96), (5000, 3, 7), (1000, 2000, 96), (500, 4, 1)]
)
def test_the_band_filter_is_the_hann_convolution_every_hop(n, m, hop):
    """`hann_lowpass` (running sums) gives what an FFT convolution with the normalised Hann
    window, centred, read every `hop` samples gives: windows longer than the signal too."""
    from scipy import signal

    rng = np.random.default_rng(n + m)
    z = rng.normal(size=n) + 1j * rng.normal(size=n)
    w = np.hanning(m)
    ref = signal.fftconvolve(z, w / w.sum(), mode="same")[::hop]
    got = hann_lowpass(z, m, hop)
    assert got.shape == ref.shape
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))
