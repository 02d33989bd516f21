# SPDX-License-Identifier: Apache-2.0
"""MoSQITo's tonality test signals, made again here (CI has no network; no fetched file is kept).

MoSQITo (Eomys/MoSQITo, `tests/input`) tests its ECMA-418-1 TNR and PR
(`tests/sq_metrics/tonality/test_tnr_ecma_st.py`, `test_pr_ecma_st.py`, `test_tnr_ecma_tv.py`,
`test_pr_ecma_tv.py`, `test_tnr_ecma_freq.py`) on WAV files "generated using audacity: white
noise + tones at 442 and 1768 Hz". Their content, measured from the files (least-squares fit of
the tones, the residual's range and kurtosis 1.8: Audacity's uniform white noise):

- `white_noise_442_1768_Hz_stationary.wav`: 44.1 kHz, 16-bit mono, 3.0 s; uniform white noise
  of amplitude 0.2 and sines of amplitude 0.4 at 442 and 1768 Hz all along;
- `white_noise_442_1768_Hz_varying.wav`: the same noise and 442 Hz tone, the 1768 Hz tone of
  amplitude 0.6 switched on from 1.0 to 2.0 s only (peaks clipped at full scale);
- `white_noise_200_2000_Hz_stationary.wav`: 4.0 s; the noise and sines of amplitude 0.573 at
  200 and 2000 Hz (3.4 % of the samples clipped at full scale).

`mosqito_signal` writes one of them (another noise draw) as 16-bit PCM, optionally with a
growing tone added (`growing_tone`: the amplitude equation of `model.acoustics.envelope`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.io import wavfile

from leadscrew_ros.model.acoustics.envelope import squeak_envelope

RATE_HZ = 44100  #: the files' sample rate [Hz]
NOISE_AMPLITUDE = 0.2  #: Audacity's uniform white noise, -0.2..0.2 full scale


@dataclass(frozen=True)
class Tone:
    """A sine of the signal: frequency [Hz], amplitude [full scale], on from..to [s]."""

    frequency_hz: float
    amplitude: float
    on_s: tuple[float, float] | None = None  # None: all along


@dataclass(frozen=True)
class MosqitoSignal:
    """One of MoSQITo's tonality test files (module notes)."""

    name: str
    duration_s: float
    tones: tuple[Tone, ...] = field(default_factory=tuple)

    @property
    def steady_hz(self) -> list[float]:
        """The tones sounding all along [Hz]."""
        return [t.frequency_hz for t in self.tones if t.on_s is None]

    @property
    def switched(self) -> list[Tone]:
        """The tones switched on and off within the file."""
        return [t for t in self.tones if t.on_s is not None]


SIGNALS = {
    s.name: s
    for s in (
        MosqitoSignal(
            "white_noise_442_1768_Hz_stationary", 3.0, (Tone(442.0, 0.4), Tone(1768.0, 0.4))
        ),
        MosqitoSignal(
            "white_noise_442_1768_Hz_varying",
            3.0,
            (Tone(442.0, 0.4), Tone(1768.0, 0.6, (1.0, 2.0))),
        ),
        MosqitoSignal(
            "white_noise_200_2000_Hz_stationary", 4.0, (Tone(200.0, 0.573), Tone(2000.0, 0.573))
        ),
    )
}


def growing_tone(
    t_s: np.ndarray,
    frequency_hz: float,
    start_s: float,
    growth_rate_per_s: float,
    saturation: float,
    floor: float,
) -> np.ndarray:
    """A squeak: from `floor` at `start_s` growing at `growth_rate_per_s` [1/s] and
    saturating at `saturation` (amplitudes in full scale), silent before `start_s`."""
    step_s = 1.0 / RATE_HZ
    sigma = np.where(t_s >= start_s, growth_rate_per_s, 0.0)
    amplitude = squeak_envelope(sigma, step_s, saturation, floor) * (t_s >= start_s)
    return amplitude * np.sin(2 * np.pi * frequency_hz * t_s)


def mosqito_samples(signal: MosqitoSignal, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(times [s], samples [full scale, unclipped]) of `signal` with a noise draw of `seed`."""
    t = np.arange(int(round(signal.duration_s * RATE_HZ))) / RATE_HZ
    x = np.random.default_rng(seed).uniform(-NOISE_AMPLITUDE, NOISE_AMPLITUDE, t.size)
    for tone in signal.tones:
        gate = 1.0 if tone.on_s is None else (t >= tone.on_s[0]) & (t < tone.on_s[1])
        x += tone.amplitude * gate * np.sin(2 * np.pi * tone.frequency_hz * t)
    return t, x


def write_pcm16(path: Path, samples: np.ndarray) -> Path:
    """`samples` clipped at full scale and written as a 16-bit PCM WAV at `RATE_HZ`."""
    q = np.round(np.clip(samples, -1.0, 1.0) * 32767.0).astype(np.int16)
    wavfile.write(path, RATE_HZ, q)
    return path
