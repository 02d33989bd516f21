# SPDX-License-Identifier: Apache-2.0
"""MoSQITo's tonality test signals through `leadscrew-squeak listen` (issue 30, "Tests and
numbers"): with nothing moving their steady tones are background and no squeak episode is
heard; with a growing tone added (the squeak's amplitude equation, from far below the noise
to saturation, at a frequency not in the file) that tone is heard as squeak, the steady ones
still are not. The signals are made again by `harness.mosqito_signals` (no network in CI)."""

from __future__ import annotations

import json
import math

import pytest

from harness.mosqito_signals import SIGNALS, growing_tone, mosqito_samples, write_pcm16
from leadscrew_ros.cli import main

SQUEAK_HZ = 1250.0  # in no file, no harmonic of their tones
FLOOR, SATURATION = 1e-4, 0.2  # full scale: 66 dB of growth, then held
# From a fifth of the file on: once saturated the squeak holds, steady, over most of the file,
# which made it an inferred background (no episode) before its measured growth told it apart.
START_SHARE = 0.2
TOLERANCE = 0.02  # relative: the detector's track tolerance
STATIONARY = ["white_noise_442_1768_Hz_stationary", "white_noise_200_2000_Hz_stationary"]


def _listen(capsys, wav, out) -> dict:
    """`listen WAV --out OUT --json`: heard.json (exit 0 asserted)."""
    code = main(["listen", str(wav), "--out", str(out), "--json"])
    printed, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(printed)


def _near(f: float, freqs) -> bool:
    return any(abs(f / g - 1) <= TOLERANCE for g in freqs)


def _background_hz(heard: dict) -> list[float]:
    return [b["frequency_hz"] for b in heard["background"]]


@pytest.mark.parametrize("name", STATIONARY)
def test_stationary_tones_are_background_not_squeak(tmp_path, capsys, name):
    signal = SIGNALS[name]
    _, x = mosqito_samples(signal)
    heard = _listen(capsys, write_pcm16(tmp_path / f"{name}.wav", x), tmp_path / "o")
    assert heard["episodes"] == []
    assert heard["background_source"] == "inferred"
    background = _background_hz(heard)
    assert all(_near(f, background) for f in signal.steady_hz), background
    for tone in signal.tones:  # at the tone's own level (a sine's mean square is a^2 / 2)
        [b] = [b for b in heard["background"] if _near(b["frequency_hz"], [tone.frequency_hz])]
        assert b["level_db"] == pytest.approx(
            20 * math.log10(tone.amplitude / math.sqrt(2)), abs=1.5
        )


@pytest.mark.parametrize("name", STATIONARY)
@pytest.mark.parametrize("growth_rate_per_s", [20.0, 60.0])
def test_a_growing_tone_is_squeak_beside_the_stationary_tones(
    tmp_path, capsys, name, growth_rate_per_s
):
    signal = SIGNALS[name]
    start_s = START_SHARE * signal.duration_s
    t, x = mosqito_samples(signal, seed=1)
    x = x + growing_tone(t, SQUEAK_HZ, start_s, growth_rate_per_s, SATURATION, FLOOR)
    heard = _listen(capsys, write_pcm16(tmp_path / "grown.wav", x), tmp_path / "o")
    [episode] = heard["episodes"]
    assert episode["frequency_hz"] == pytest.approx(SQUEAK_HZ, rel=TOLERANCE)
    saturated_s = start_s + math.log(SATURATION / FLOOR) / growth_rate_per_s
    assert start_s <= episode["start_s"] <= saturated_s
    assert episode["growth_rate_per_s"] == pytest.approx(growth_rate_per_s, rel=0.15)
    assert episode["end_s"] >= signal.duration_s - 0.1
    background = _background_hz(heard)
    assert all(_near(f, background) for f in signal.steady_hz), background
    assert not _near(SQUEAK_HZ, background)


def test_the_varying_signal_is_all_background(tmp_path, capsys):
    """`white_noise_442_1768_Hz_varying`: nothing moves (no speed); 442 Hz all along is
    background, and so is the 1768 Hz tone switched on from 1.0 to 2.0 s: it came in at once
    (a step, `Growth.step`), not grown from the floor as a squeak does. A growing tone beside
    them is the one squeak."""
    signal = SIGNALS["white_noise_442_1768_Hz_varying"]
    [switched] = signal.switched
    t, x = mosqito_samples(signal, seed=2)
    heard = _listen(capsys, write_pcm16(tmp_path / "varying.wav", x), tmp_path / "a")
    assert heard["episodes"] == []
    background = _background_hz(heard)
    assert all(_near(f, background) for f in [*signal.steady_hz, switched.frequency_hz])

    x = x + growing_tone(t, SQUEAK_HZ, START_SHARE * signal.duration_s, 20.0, SATURATION, FLOOR)
    heard = _listen(capsys, write_pcm16(tmp_path / "grown.wav", x), tmp_path / "b")
    [episode] = heard["episodes"]
    assert episode["frequency_hz"] == pytest.approx(SQUEAK_HZ, rel=TOLERANCE)
    assert episode["growth_rate_per_s"] == pytest.approx(20.0, rel=0.15)
    background = _background_hz(heard)
    assert all(_near(f, background) for f in [*signal.steady_hz, switched.frequency_hz])
