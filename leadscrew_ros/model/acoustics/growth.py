# SPDX-License-Identifier: Apache-2.0
"""A squeak's growth rate at its onset, measured from the sound.

Near a Hopf bifurcation the squeak's amplitude A obeys d(ln A)/dt = sigma (1 - (A / S)^2)
(`envelope`): it grows at sigma = Re(lambda) of the mode from the noise floor and saturates at
the limit cycle S. A^2 is then logistic, so

    ln(S^2 / A^2 - 1) = c - 2 sigma t

is a straight line in t from the floor to saturation, and its slope gives sigma without the
bias a plain exponential fit takes near saturation.

The measurement (`onset_growth`), per episode: the sound around its start is demodulated along
its frequency track (the track's first frequency before it is heard) and low-passed by a Hann
window of `WINDOW_CYCLES` periods (within `WINDOW_S`; a narrow band keeps a drive's order a few
per cent away out of it), read every `HOP_S`: P(t), the power in a band that follows the
squeak. The background there, B, is P's mean over the quiet stretch before the onset (from
`LOOKBACK_S` before, or the end of the last tone near its frequency, to `QUIET_GAP_S` before
the start; the mean of an exponential from its median). The saturation S^2 is the largest
P - B within `AHEAD_S` after the start. The line is fitted by least squares to the points
within `FIT_SPAN_S` of the start where P - B is `FIT_OVER_DB` over B and `FIT_UNDER_DB` under
S^2; its standard error is that of the slope, widened by sqrt(window / hop) (neighbouring
points share the window: fewer independent ones). A rate faster than 1 / window is measured
again with that window (the knee would be smeared); one still faster than 5 / window is a
step the band cannot resolve. No rate, and a reason, when the
saturation stands less than `MIN_SNR_DB` over the background or fewer than `MIN_POINTS`
points are left. numpy/scipy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .samples import Samples
from .tonality import phasor

HOP_S = 0.002  # P(t) every 2 ms: a fast onset (200 1/s, 17 dB in 10 ms) gets several points
WINDOW_CYCLES = 60  # the band: a Hann window of 60 periods (+-3 %: a motor order 4 % away
WINDOW_S = (0.01, 0.1)  # beat with it), within 10-100 ms (any keeps an exponential's slope)
MIN_CYCLES = 10  # a fast onset's second pass: 1 / rate, at least 10 periods; a rate over
MAX_RATE_WINDOW = 5.0  # 5 / window even then is not resolved (a sound switched on)
LOOKBACK_S = 1.0  # the quiet stretch before the onset starts at most this early ...
QUIET_GAP_S = 0.3  # ... and ends this before the heard start (the squeak grows before it)
MIN_QUIET_S = 0.1  # a shorter quiet stretch gives no background: no rate
AHEAD_S = 0.5  # the saturation is looked for this long after the start
FIT_OVER_DB = 12.0  # fitted points stand this far over the background (nearer, the points
# picked are those the noise lifted over the bound: a flatter line) ...
FIT_UNDER_DB = 6.0  # ... and this far under the saturation (a room smears the knee)
FIT_SPAN_S = 0.1  # ... and within this of the heard start: sigma moves with the operating point
MIN_SNR_DB = 12.0  # the stated SNR: a saturation less far over the background gives no rate
MIN_POINTS = 4


@dataclass(frozen=True)
class Growth:
    """An onset's growth rate, measured.

    Attributes
    ----------
    rate_per_s : float or None
        sigma = d(ln A)/dt while A grows unsaturated [1/s]; None with a `reason`.
    se_per_s : float or None
        Its standard error [1/s].
    window_s : tuple of float or None
        The span of the fitted points [s].
    snr_db : float or None
        The saturation's level over the background in the squeak's band [dB].
    reason : str
        Why there is no rate ('' with one).
    step : bool
        The sound came in at once: from the fit's lower bound to its upper one within the
        band's window (its response time), or faster than the band resolves (a sound
        switched on, not a growth from the floor).
    """

    rate_per_s: float | None
    se_per_s: float | None
    window_s: tuple[float, float] | None
    snr_db: float | None
    reason: str = ""
    step: bool = False


def onset_growth(
    samples: Samples,
    sample_rate_hz: float,
    t0_s: float,
    start_s: float,
    track_times_s: np.ndarray,
    track_hz: np.ndarray,
    quiet_from_s: float = -math.inf,
) -> Growth:
    """The growth rate of a squeak episode at its start.

    Parameters
    ----------
    samples : numpy.ndarray or SampleTrack
        Mono samples (full scale; non-finite ones make the measurement fail with a reason).
    sample_rate_hz : float
        Sample rate [Hz].
    t0_s : float
        Time of the first sample [s].
    start_s : float
        The episode's start [s].
    track_times_s, track_hz : numpy.ndarray
        Its frequency track: frame times [s] and frequencies [Hz] (nan in bridged gaps).
    quiet_from_s : float
        The quiet stretch starts no earlier than this (the previous episode's end) [s].

    Returns
    -------
    Growth
        Measured with a band of `WINDOW_CYCLES` periods; again with a window of 1 / rate
        (at least `MIN_CYCLES` periods) when the rate is faster than the window (the
        logistic's knee would be smeared).
    """
    f = np.asarray(track_hz, float)
    tt = np.asarray(track_times_s, float)
    ok = np.isfinite(f)
    if not ok.any():
        return Growth(None, None, None, None, "no frequency track")
    tt, f = tt[ok], f[ok]
    f0 = float(np.median(f[: min(5, f.size)]))
    args = (samples, float(sample_rate_hz), t0_s, start_s, tt, f, quiet_from_s)
    window = float(np.clip(WINDOW_CYCLES / f0, *WINDOW_S))
    g = _measure(*args, window)
    if g.rate_per_s is not None and g.rate_per_s * window > 1.0:
        window = max(1.0 / g.rate_per_s, MIN_CYCLES / f0, WINDOW_S[0])
        g = _measure(*args, window)
        if g.rate_per_s is not None and g.rate_per_s * window > MAX_RATE_WINDOW:
            return Growth(
                None,
                None,
                None,
                g.snr_db,
                f"faster than the band resolves ({MAX_RATE_WINDOW / window:.0f} 1/s at "
                f"{f0:.0f} Hz): a step, not a growth",
                step=True,
            )
    return g


def _measure(
    samples: Samples,
    sample_rate_hz: float,
    t0_s: float,
    start_s: float,
    tt: np.ndarray,
    f: np.ndarray,
    quiet_from_s: float,
    window: float,
) -> Growth:
    """`onset_growth` with a band of window `window` [s]; `tt`, `f` the finite track."""
    fs = sample_rate_hz
    quiet_lo = max(start_s - LOOKBACK_S, quiet_from_s, t0_s + window)
    quiet_hi = start_s - QUIET_GAP_S
    if quiet_hi - quiet_lo < MIN_QUIET_S:
        return Growth(None, None, None, None, "no quiet stretch before the onset")
    i0 = max(int((quiet_lo - window - t0_s) * fs), 0)
    i1 = min(int((start_s + AHEAD_S + window - t0_s) * fs), samples.size)
    seg = np.asarray(samples[i0:i1], float)
    if seg.size < fs * (MIN_QUIET_S + window) or not np.isfinite(seg).all():
        return Growth(None, None, None, None, "no usable sound around the onset")
    t = t0_s + (i0 + np.arange(seg.size)) / fs
    freq = np.interp(t, tt, f, left=f[0], right=f[-1])
    z = seg * phasor(np.cumsum(freq) / fs)  # the squeak at 0 Hz
    hop = max(1, round(HOP_S * fs))
    low = hann_lowpass(z, max(3, round(window * fs)), hop)
    p, tp = np.abs(low) ** 2, t[::hop]
    inside = (tp >= t[0] + window / 2) & (tp <= t[-1] - window / 2)
    p, tp = p[inside], tp[inside]
    quiet = (tp >= quiet_lo) & (tp <= quiet_hi)
    if quiet.sum() < MIN_POINTS:
        return Growth(None, None, None, None, "no quiet stretch before the onset")
    background = float(np.median(p[quiet])) / math.log(2)  # mean of an exponential
    excess = p - background
    after = (tp >= start_s) & (tp <= start_s + AHEAD_S)
    if not after.any() or background <= 0:
        return Growth(None, None, None, None, "no sound after the onset")
    saturation = float(excess[after].max())
    snr = 10 * math.log10(max(saturation, 1e-300) / background)
    if snr < MIN_SNR_DB:
        return Growth(
            None, None, None, snr, f"{snr:.0f} dB over the background, below {MIN_SNR_DB:g} dB"
        )
    fit = (
        (excess >= background * 10 ** (FIT_OVER_DB / 10))
        & (excess <= saturation * 10 ** (-FIT_UNDER_DB / 10))
        & (np.abs(tp - start_s) <= FIT_SPAN_S)
    )
    run = np.flatnonzero(fit)  # noise flickers around the bounds: no contiguity asked
    if run.size < MIN_POINTS:
        step = _rise_s(tp, excess, background, saturation, quiet_hi) <= window
        return Growth(
            None,
            None,
            None,
            snr,
            "rose within the band's response time: a step, not a growth"
            if step
            else "too few points between the floor and saturation",
            step=step,
        )
    x, y = tp[run], np.log(saturation / excess[run] - 1.0)
    slope, intercept = np.polyfit(x, y, 1)
    residual = y - (slope * x + intercept)
    spread = float(np.sum((x - x.mean()) ** 2))
    se = math.sqrt(float(np.sum(residual**2)) / max(x.size - 2, 1) / spread) / 2.0
    se *= math.sqrt(max(window / HOP_S, 1.0))
    return Growth(-slope / 2.0, se, (float(x[0]), float(x[-1])), snr)


def hann_lowpass(z: np.ndarray, m: int, hop: int) -> np.ndarray:
    """`z` low-passed by the normalised Hann window of `m` points (``np.hanning(m)``, centred as
    ``scipy.signal.fftconvolve(z, w / w.sum(), mode="same")``), every `hop`-th sample.

    The window is 1/2 - cos(theta j)/2 (theta = 2 pi / (m - 1)): a boxcar and two boxcars
    modulated by exp(+-i theta j), each a difference of running sums, so the cost is
    O(len z) whatever `m`, against an FFT of the whole segment.

    Parameters
    ----------
    z : numpy.ndarray
        1-D complex signal.
    m : int
        Window length [samples], >= 3.
    hop : int
        Output every `hop`-th sample, from the first.

    Returns
    -------
    numpy.ndarray
        (ceil(len z / hop),) complex.
    """
    n = z.size
    s = np.arange(0, n, hop) - m // 2  # each output's first window sample
    a, b = np.clip(s, 0, n), np.clip(s + m, 0, n)
    theta = 2 * np.pi / (m - 1)
    period = np.exp(1j * theta * np.arange(m - 1))
    turn, back = np.tile(period, n // (m - 1) + 1)[:n], period[np.mod(s, m - 1)].conj()
    low = np.zeros(s.size, complex)
    c = np.zeros(n + 1, complex)
    for weight, rot in ((0.5, None), (-0.25, 1), (-0.25, -1)):
        np.cumsum(z if rot is None else z * (turn if rot > 0 else turn.conj()), out=c[1:])
        part = c[b] - c[a]
        if rot is not None:  # from exp(i theta j) to exp(i theta (j - s)): the window's phase
            part *= back if rot > 0 else back.conj()
        low += weight * part
    return low / (0.5 * (m - 1))


def _rise_s(
    tp: np.ndarray, excess: np.ndarray, background: float, saturation: float, after_s: float
) -> float:
    """How long the sound took after `after_s` [s] from the fit's lower bound to its upper
    one (inf when it did not get there)."""
    high = np.flatnonzero((excess > saturation * 10 ** (-FIT_UNDER_DB / 10)) & (tp >= after_s))
    if not high.size:
        return math.inf
    low = np.flatnonzero(excess[: high[0]] < background * 10 ** (FIT_OVER_DB / 10))
    return float(tp[high[0]] - tp[low[-1]]) if low.size else math.inf


def growth_fields(growth: Growth | None) -> dict[str, Any]:
    """An episode's growth as JSON-safe fields (`Episode.as_dict`).

    Parameters
    ----------
    growth : Growth or None
        None: not measured (live).

    Returns
    -------
    dict
        growth_rate_per_s, growth_rate_se, growth_window_s, growth_snr_db, growth_reason.
    """
    if growth is None:
        return dict(
            growth_rate_per_s=None,
            growth_rate_se=None,
            growth_window_s=None,
            growth_snr_db=None,
            growth_reason="not measured",
        )
    return dict(
        growth_rate_per_s=growth.rate_per_s,
        growth_rate_se=growth.se_per_s,
        growth_window_s=list(growth.window_s) if growth.window_s else None,
        growth_snr_db=growth.snr_db,
        growth_reason=growth.reason,
    )
