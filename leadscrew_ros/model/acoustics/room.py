# SPDX-License-Identifier: Apache-2.0
"""A small room: a synthetic impulse response (direct sound and an exponentially decaying
noise tail of reverberation time RT60) and the convolution with it (FFT, overlap-add).

The response keeps the signal's energy on average: the direct sound carries
`DIRECT_TO_REVERBERANT_DB` more energy than the tail (a microphone near the drive in a small
room), the two together unit energy, so a tone keeps its level on average over frequency
(at one frequency the tail's random phase moves it by a few dB) and a level stated at the
source is the level at the microphone. The tail starts `PRE_DELAY_S` after the direct sound
and its amplitude falls 60 dB in RT60; it is cut there.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

DIRECT_TO_REVERBERANT_DB = 6.0  # energy of the direct sound re the tail's
PRE_DELAY_S = 0.002  # from the direct sound to the first reflection
_DECAY_60 = 3.0 * np.log(10.0)  # amplitude exp(-_DECAY_60 t / RT60): -60 dB at RT60


def _shares() -> tuple[float, float]:
    """Energy of the direct sound and of the tail (summing to 1)."""
    ratio = 10.0 ** (DIRECT_TO_REVERBERANT_DB / 10.0)
    return ratio / (1.0 + ratio), 1.0 / (1.0 + ratio)


def impulse_response(rt60_s: float, sample_rate_hz: float, rng: np.random.Generator) -> np.ndarray:
    """The room's impulse response at `sample_rate_hz`, unit energy (see the module).

    Parameters
    ----------
    rt60_s : float
        Reverberation time [s] (> 0).
    sample_rate_hz : float
        Sample rate [Hz].
    rng : numpy.random.Generator
        Draws the tail's noise.

    Returns
    -------
    numpy.ndarray
        The response, first sample the direct sound.
    """
    direct, tail = _shares()
    delay = max(int(round(PRE_DELAY_S * sample_rate_hz)), 1)
    t = np.arange(max(int(round(rt60_s * sample_rate_hz)), 1)) / sample_rate_hz
    noise = rng.standard_normal(t.size) * np.exp(-_DECAY_60 * t / rt60_s)
    h = np.zeros(delay + t.size)
    h[0] = np.sqrt(direct)
    h[delay:] = noise * np.sqrt(tail / np.sum(noise**2))
    return h


def reverberate(
    samples: np.ndarray, rt60_s: float, sample_rate_hz: float, rng: np.random.Generator
) -> np.ndarray:
    """`samples` heard in the room (as long as they are: the last tail is cut)."""
    h = impulse_response(rt60_s, sample_rate_hz, rng)
    return scipy.signal.oaconvolve(samples, h)[: samples.size]


def energy_response(rt60_s: float, rate_hz: float) -> np.ndarray:
    """The room's expected energy response on a grid of `rate_hz` (sums to 1): what the
    room makes of a mean-square envelope sampled there (its direct share at lag 0, the
    tail's share decaying 60 dB in `rt60_s` from `PRE_DELAY_S`)."""
    direct, tail = _shares()
    t = np.arange(max(int(round((PRE_DELAY_S + rt60_s) * rate_hz)), 2)) / rate_hz
    decay = np.where(t >= PRE_DELAY_S, np.exp(-2.0 * _DECAY_60 * (t - PRE_DELAY_S) / rt60_s), 0.0)
    kernel = tail * decay / decay.sum()
    kernel[0] += direct
    return kernel
