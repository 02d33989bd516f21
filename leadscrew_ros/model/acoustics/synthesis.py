# SPDX-License-Identifier: Apache-2.0
"""A simulated bench microphone: motor orders that follow the speed, broadband noise, and the
squeak tone whenever there is one (the virtual bench and the demo's microphone).

Assumptions (all parameters with defaults): the microphone is linear and its signal is in
full-scale units; the motor/gear noise is a sum of sinusoids at k |speed| / 2 pi for the given
orders, amplitude ``motor_level / k`` (falling with order), phases integrated from the
instantaneous frequency (so they stay continuous through speed changes) and randomised at the
start, faded out below `HIGH_PASS_HZ` (an AC-coupled microphone: no DC at standstill); the
background is white Gaussian noise of rms `noise_level`; the squeak is one tone at the
predicted frequency (interpolated linearly while it lasts, phase integrated), of amplitude
`squeak_level`, switched on and off with a raised-cosine envelope `onset_s` long centred on the
switching time (half amplitude at the nominal onset); no room, no microphone response, no
clipping (values beyond full scale are returned as they are).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.signal

#: Default motor/gear orders of the shaft speed (resolvable by frequency alone at constant
#: speed with `DetectorSettings.order_tolerance` 2 %, see `detection`).
MOTOR_ORDERS = (1, 2, 3, 4, 6, 8, 12)
#: The microphone is AC-coupled: an order's amplitude fades linearly to 0 below this [Hz].
HIGH_PASS_HZ = 20.0


def shaft_orders(
    shaft_hz: np.ndarray,
    sample_rate_hz: float,
    orders: Sequence[float],
    amplitudes: Sequence[Any],
    rng: np.random.Generator,
) -> np.ndarray:
    """Tones at `orders` of a shaft's rotation frequency, phase-continuous through speed
    changes (integrated from the instantaneous frequency, random start), each faded out
    linearly below `HIGH_PASS_HZ` (an AC-coupled microphone: no DC at standstill) and
    silent above the Nyquist frequency.

    Parameters
    ----------
    shaft_hz : numpy.ndarray
        Shaft rotation frequency [Hz] at each sample (>= 0).
    sample_rate_hz : float
        Sample rate [Hz].
    orders : sequence of float
        Orders (multiples of the rotation frequency, whole or not).
    amplitudes : sequence of float or numpy.ndarray
        Amplitude [FS] of each order (per sample where an array).
    rng : numpy.random.Generator
        Draws one start phase per order, in order.

    Returns
    -------
    numpy.ndarray
        The sum of the tones (zeros without orders).
    """
    shaft_turns = np.cumsum(shaft_hz) / sample_rate_hz  # shaft angle [turns]
    nyquist = sample_rate_hz / 2.0  # none above it (it would alias)
    out = np.zeros(shaft_hz.size)
    for k, amplitude in zip(orders, amplitudes, strict=True):
        fade = np.clip(k * shaft_hz / HIGH_PASS_HZ, 0.0, 1.0) * (k * shaft_hz < nyquist)
        out += fade * amplitude * np.sin(2 * np.pi * (k * shaft_turns + rng.random()))
    return out


def microphone(
    times_s: Any,
    speed_rad_s: Any,
    squeak_hz: Any,
    squeak_level: Any = 0.05,
    sample_rate_hz: float = 48000.0,
    seed: int = 0,
    motor_orders: tuple[int, ...] = MOTOR_ORDERS,
    motor_level: float = 0.02,
    noise_level: float = 0.003,
    onset_s: float = 0.02,
) -> np.ndarray:
    """Microphone samples of a stroke: motor orders, noise and the squeak tone.

    Parameters
    ----------
    times_s : array_like
        Increasing times [s] of the profile; the samples run from the first to the last.
    speed_rad_s : array_like
        Shaft speed [rad/s] at `times_s` (interpolated linearly; its magnitude counts).
    squeak_hz : array_like
        Squeak frequency [Hz] at `times_s`, nan when silent (held until the next time).
    squeak_level : float or array_like
        Squeak amplitude [full scale] (per time: interpolated).
    sample_rate_hz : float
        Sample rate [Hz].
    seed : int
        Seed of the noise and of the order phases.
    motor_orders : tuple of int
        Orders of the shaft speed present (empty: none).
    motor_level : float
        Amplitude of order 1 [full scale]; order k has ``motor_level / k``.
    noise_level : float
        Rms of the white background noise [full scale].
    onset_s : float
        Length of the raised-cosine onset and decay of the squeak [s].

    Returns
    -------
    numpy.ndarray
        float32 samples at `sample_rate_hz`, from ``times_s[0]``.
    """
    times = np.asarray(times_s, dtype=float).reshape(-1)
    if times.size == 0:
        return np.zeros(0, np.float32)
    fs = float(sample_rate_hz)
    n = int(np.floor((times[-1] - times[0]) * fs)) + 1
    t = times[0] + np.arange(n) / fs
    rng = np.random.default_rng(seed)
    shaft_hz = np.abs(
        np.interp(t, times, np.broadcast_to(np.asarray(speed_rad_s, float), times.shape))
    ) / (2 * np.pi)
    out = noise_level * rng.standard_normal(n)
    out += shaft_orders(shaft_hz, fs, motor_orders, [motor_level / k for k in motor_orders], rng)
    f_sq = np.broadcast_to(np.asarray(squeak_hz, float), times.shape)
    on_at = np.isfinite(f_sq)
    if on_at.any():
        idx = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 1)
        gate = on_at[idx].astype(float)
        filled = np.where(on_at, f_sq, np.interp(times, times[on_at], f_sq[on_at]))
        freq = np.interp(t, times, filled)
        level = np.interp(t, times, np.broadcast_to(np.asarray(squeak_level, float), times.shape))
        m = max(int(round(onset_s * fs)), 1)
        if m > 1:
            kernel = np.hanning(m + 2)[1:-1]
            gate = np.clip(
                scipy.signal.oaconvolve(
                    np.pad(gate, (m, m), mode="edge"), kernel / kernel.sum(), mode="same"
                )[m:-m],
                0.0,
                1.0,
            )
        phase = 2 * np.pi * np.cumsum(freq) / fs
        out += gate * level * np.sin(phase)
    return out.astype(np.float32)
