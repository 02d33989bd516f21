# SPDX-License-Identifier: Apache-2.0
"""Creaks: impulsive friction noise, a stick-slip pulse train, told apart from squeak.

A creak is a train of short pulses (each slip a broadband click that rings at the structure's
resonances) repeating at the stick-slip rate, typically 5-200 Hz. The tonal detector sees its
ringing and the harmonics of its pulse rate as short tones and would report squeak fragments.
Here the pulses are found in the envelope of the high-passed sound (`creak_highpass_hz`, away
from hum and the drive's low orders), on 0.5 ms blocks:

* a peak is a block level `creak_pulse_db` over the running floor (the level between
  pulses) and as prominent (it falls back: a squeak's onset is a step, not a peak);
* peaks closer than 1 / `creak_min_rate_hz` form a train. Its period is the shortest lag
  after which nearly every peak has another (`_period`): a slip's ring-down can beat into
  secondary peaks (the ISO 532-1 door creak has two or three per slip), which follow only
  some peaks, and only at short lags. A period shorter than 1 / `creak_max_rate_hz` is a
  tone's waveform (a harmonic series in phase), not a creak;
* its pulses are the highest peak within `MAIN_SHARE` of the period; the train is a creak
  with `creak_min_pulses` of them when most consecutive intervals agree within a factor
  `REGULAR_FACTOR` (Poisson clicks agree in ~23 % of the pairs, stick-slip in most);
* its ringing frequencies are the peaks of the pulses' mean spectrum (each pulse's first
  `RING_S`, or less than an interval).

`sort_creaks` then drops the trains that are tones beating (ringing at a tone held through
them: two tones a few Hz apart swell and fade like slips) and takes the squeak episodes that
lie inside a creak at its ringing frequencies, at a harmonic of its pulse rate or for at most
two analysis frames out of the squeak episodes. numpy/scipy only.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import signal

from .samples import Samples, SampleTrack, span
from .settings import DetectorSettings

BLOCK_S = 0.5e-3  # envelope resolution: a slip's click lasts about a millisecond
CHUNK_SAMPLES = 1 << 18  # the high-pass filter runs over pieces this long: bounded memory
WINDOW_S = 60.0  # a long recording is searched in windows this long (bounded memory) ...
OVERLAP_S = 5.0  # ... widened by this on each side
FLOOR_S = 0.025  # the floor: a low percentile of each FLOOR_S segment, median of FLOOR_SEGMENTS
FLOOR_PERCENTILE = 20  # the troughs between dense pulses (steady noise: ~1 dB under its mean)
FLOOR_SEGMENTS = 9
PULSE_WINDOW_S = 0.04  # a pulse's prominence is judged within +-20 ms: its ring-down
LAG_TOLERANCE = 0.25  # lags within +-25 % are one (the jitter of stick-slip)
LAG_STEPS = 64  # lags tried, log-spaced (4-8 % apart over 5-200 Hz)
PERIOD_SHARE = 0.8  # the period: the shortest lag shared nearly as often as the most shared
MAIN_SHARE = 0.7  # a pulse is the highest peak within 0.7 of the period
REGULAR_FACTOR = 1.6  # consecutive intervals agree within this factor ...
REGULAR_SHARE = 0.8  # ... in this share of the pairs (Poisson clicks: ~23 %; the level
# fluctuations of a reverberant tone's 0.5 ms blocks reached 60 % on a realistic bench)
SETTLE_S = 0.1  # the high-pass started from rest this long before the pulses it is read at
RING_S = 0.02  # a pulse's ringing analysed over at most its first 20 ms
RING_PROMINENCE_DB = 6.0  # a ringing frequency stands this far over its spectral neighbourhood
RING_RANGE_DB = 20.0  # ... and within this of the strongest
MAX_RINGING = 3  # ringing frequencies reported per creak
FRAGMENT_RING_TOLERANCE = 0.15  # a fragment within 15 % of a ringing frequency (its width)
FRAGMENT_INSIDE = 0.8  # share of a fragment's duration inside the creak's span
BEAT_TOLERANCE = 0.03  # a creak ringing at a held tone (a line of it) is that tone beating
# A train with TONAL_LINES sustained tones at multiples of its pulse rate is a periodic sound's
# waveform (a motor's orders in phase), not slips: a creak's jitter smears its rate's harmonics.
TONAL_LINES = 2
HARMONIC_TOLERANCE = 0.1  # of the pulse rate
HARMONIC_MAX = 20  # above, a tenth of the rate is too wide a net (every tone within it)
HARMONIC_SHARE = 0.75
# Within a creak a tone heard for at most two analysis frames is the train's own line (each
# pulse rings a little differently, below the high-pass too); a squeak is sustained.
FRAGMENT_FRAMES = 2


@dataclass
class Creak:
    """One creak: a stick-slip pulse train.

    Attributes
    ----------
    start_s, end_s : float
        First and last pulse [s].
    pulse_rate_hz : float
        Median pulse rate (1 / median interval) [Hz].
    pulses : int
        Number of pulses.
    ringing_hz : list of float
        The pulses' ringing frequencies, strongest first [Hz].
    level_db : float
        Median pulse level: dB SPL re 20 uPa when calibrated, else dB re full scale (mean
        square of the high-passed sound over a 0.5 ms block).
    fragments_hz : list of float
        Frequencies of the squeak fragments it explained (`sort_creaks`) [Hz].
    pulse_times_s : numpy.ndarray
        The pulses' times [s]; not in `as_dict`.
    """

    start_s: float
    end_s: float
    pulse_rate_hz: float
    pulses: int
    ringing_hz: list[float]
    level_db: float
    fragments_hz: list[float] = field(default_factory=list)
    pulse_times_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def as_dict(self) -> dict[str, Any]:
        """The creak as a JSON-safe dict, without the pulse times.

        Returns
        -------
        dict
        """
        return dict(
            start_s=self.start_s,
            end_s=self.end_s,
            pulse_rate_hz=self.pulse_rate_hz,
            pulses=self.pulses,
            ringing_hz=list(self.ringing_hz),
            level_db=self.level_db if math.isfinite(self.level_db) else None,
            fragments_hz=list(self.fragments_hz),
        )


def find_creaks(
    samples: Samples,
    sample_rate_hz: float,
    *,
    t0_s: float = 0.0,
    scale_pa: float | None = None,
    settings: DetectorSettings = DetectorSettings(),
) -> list[Creak]:
    """The creaks in a recording.

    Parameters
    ----------
    samples : numpy.ndarray
        Mono samples in full-scale units; non-finite samples count as 0 (their frames are
        not scored by the tonal detector either).
    sample_rate_hz : float
        Sample rate [Hz].
    t0_s : float
        Time of the first sample [s].
    scale_pa : float, optional
        Pascal per full-scale unit (levels in dB SPL).
    settings : DetectorSettings
        The `creak_*` settings.

    Returns
    -------
    list of Creak
        By start time.
    """
    fs = float(sample_rate_hz)
    x = samples if isinstance(samples, SampleTrack) else np.asarray(samples).reshape(-1)
    step, over = round(WINDOW_S * fs), round(OVERLAP_S * fs)
    out: list[Creak] = []
    for a in range(0, max(x.size - over, 1), step):
        # each window reaches OVERLAP_S into its neighbours: a train at a boundary is seen whole
        # by one of them, and a longer one in pieces that `_joined` puts together
        first = max(a - over, 0)
        found = _creaks_in(
            span(x, first, a + step + over), fs, t0_s + first / fs, scale_pa, settings
        )
        out = _joined(out, found, 1.0 / settings.creak_min_rate_hz)
    return sorted(out, key=lambda c: c.start_s)


def _joined(before: list[Creak], found: list[Creak], longest_s: float) -> list[Creak]:
    """The creaks of the windows so far and those of the next one, a train seen by both (it
    crosses their boundary: it starts within `longest_s` of one's end, at a pulse rate within
    `LAG_TOLERANCE`) joined into one: its pulses merged, the longer part's ringing and level."""
    out = list(before)
    for c in found:
        k = next(
            (
                k
                for k, b in enumerate(out[: len(before)])
                if b.start_s <= c.start_s <= b.end_s + longest_s
                and abs(c.pulse_rate_hz / b.pulse_rate_hz - 1) <= LAG_TOLERANCE
            ),
            None,
        )
        if k is None:
            out.append(c)
            continue
        b = out[k]
        extra = c.pulse_times_s[c.pulse_times_s > b.end_s + 0.5 / b.pulse_rate_hz]
        t = np.concatenate([b.pulse_times_s, extra])
        main = b if b.pulses >= c.pulses else c
        out[k] = replace(
            main,
            start_s=float(t[0]),
            end_s=float(t[-1]),
            pulse_rate_hz=1.0 / float(np.median(np.diff(t))),
            pulses=int(t.size),
            pulse_times_s=t,
        )
    return out


def _creaks_in(
    x: Samples,
    fs: float,
    t0_s: float,
    scale_pa: float | None,
    settings: DetectorSettings,
) -> list[Creak]:
    """`find_creaks` in one window of the recording."""
    block = max(1, round(fs * BLOCK_S))
    seg = max(1, round(FLOOR_S / BLOCK_S))
    if x.size < 2 * seg * block:
        return []
    hp = min(settings.creak_highpass_hz, 0.45 * fs)
    sos = _highpass(hp, fs)
    n_blocks = x.size // block
    energy = np.concatenate(
        [
            np.mean(y[: y.size - y.size % block].reshape(-1, block) ** 2, axis=1)
            for _, y in _highpassed(span(x, 0, n_blocks * block), sos, block)
        ]
    )
    ref = (scale_pa / 20e-6) ** 2 if scale_pa is not None else 1.0
    level = 10 * np.log10(energy * ref + 1e-30)
    n_seg = n_blocks // seg
    seg_floor = np.percentile(level[: n_seg * seg].reshape(n_seg, seg), FLOOR_PERCENTILE, axis=1)
    seg_floor = np.asarray(signal.medfilt(seg_floor, min(FLOOR_SEGMENTS, 2 * (n_seg // 2) - 1)))
    centres = (np.arange(n_seg) + 0.5) * seg
    floor = np.interp(np.arange(n_blocks), centres, seg_floor)
    above = level - floor
    min_gap = max(1, int(fs / (settings.creak_max_rate_hz * block)))  # blocks per shortest interval
    window = 2 * round(PULSE_WINDOW_S / 2 / BLOCK_S) + 1
    pulse = dict(height=settings.creak_pulse_db, prominence=settings.creak_pulse_db, wlen=window)
    peaks, _ = signal.find_peaks(above, distance=min_gap, **pulse)
    every, _ = signal.find_peaks(above, **pulse)  # without the shortest interval
    if peaks.size < settings.creak_min_pulses:
        return []
    longest = fs / (settings.creak_min_rate_hz * block)  # blocks per longest interval
    breaks = np.flatnonzero(np.diff(peaks) > longest) + 1
    out = []
    for idx in np.split(np.arange(peaks.size), breaks):
        if idx.size < settings.creak_min_pulses:
            continue
        a, b = peaks[idx[0]], peaks[idx[-1]]
        within = every[(every >= a) & (every <= b)]
        if np.median(np.diff(within)) < min_gap:
            continue  # faster than a creak: the periods of a tone's waveform (harmonics in phase)
        period = _period(within, min_gap, longest)
        # One pulse per period: a slip's ring-down can beat into peaks of its own
        lo, hi = max(a - window, 0), min(b + window + 1, n_blocks)  # its whole ring-down
        keep = max(1, int(MAIN_SHARE * period))
        main, _ = signal.find_peaks(above[lo:hi], distance=keep, **pulse)
        main += lo
        if main.size < settings.creak_min_pulses:
            continue
        t = t0_s + (main + 0.5) * block / fs
        d = np.diff(t)
        pair = d[1:] / d[:-1]
        if np.mean((pair < REGULAR_FACTOR) & (pair > 1 / REGULAR_FACTOR)) < REGULAR_SHARE:
            continue
        interval = float(np.median(d))
        out.append(
            Creak(
                start_s=float(t[0]),
                end_s=float(t[-1]),
                pulse_rate_hz=1.0 / interval,
                pulses=int(main.size),
                ringing_hz=_ringing(x, sos, fs, main * block, interval),
                level_db=float(np.median(level[main])),
                pulse_times_s=t,
            )
        )
    return out


def _period(at: np.ndarray, shortest: float, longest: float) -> float:
    """A train's period [blocks]: the shortest lag L in [`shortest`, `longest`] for which
    nearly as many peaks (`PERIOD_SHARE` of the most for any lag) have a later peak within
    L (1 +- `LAG_TOLERANCE`), each peak counted once (so a long lag's wide window cannot
    count several periods). A pulse's secondary peaks follow only some peaks at a short lag;
    every peak has a successor one period on (and at its multiples: the shortest is taken).
    0 when no lag fits."""
    at = np.sort(at).astype(float)
    if at.size < 2 or longest <= shortest:
        return 0.0
    lags = np.geomspace(shortest, longest, LAG_STEPS)
    first = np.searchsorted(at, at[:, None] + lags * (1 - LAG_TOLERANCE))
    last = np.searchsorted(at, at[:, None] + lags * (1 + LAG_TOLERANCE), side="right")
    eligible = (at[:, None] + lags * (1 - LAG_TOLERANCE) <= at[-1]).sum(axis=0)
    share = (last > first).sum(axis=0) / np.maximum(eligible, 1)
    return float(lags[np.argmax(share >= PERIOD_SHARE * share.max())])


def _highpass(cutoff_hz: float, fs: float) -> np.ndarray:
    """The creak's 4th-order Butterworth high-pass (second-order sections), designed once
    per cut-off and rate (a copy: `sosfilt` wants a writable array)."""
    return np.array(_butter_highpass(cutoff_hz, fs))


@lru_cache(maxsize=8)
def _butter_highpass(cutoff_hz: float, fs: float) -> tuple[tuple[float, ...], ...]:
    sos = signal.butter(4, cutoff_hz, btype="highpass", fs=fs, output="sos")
    return tuple(tuple(float(v) for v in row) for row in sos)


def _highpassed(x: Samples, sos: np.ndarray, block: int) -> Iterator[tuple[int, np.ndarray]]:
    """`x` (non-finite samples as 0) through the filter `sos`, as (offset, piece) pieces of
    about `CHUNK_SAMPLES` (a multiple of `block`), the filter's state carried over: the same
    output as one `sosfilt` of the whole, with memory bounded whatever its length."""
    state = np.zeros((sos.shape[0], 2))
    step = max(CHUNK_SAMPLES // block, 1) * block
    for i in range(0, x.size, step):
        piece = np.asarray(x[i : i + step], dtype=float)
        if not np.isfinite(piece).all():
            piece = np.where(np.isfinite(piece), piece, 0.0)
        y, state = signal.sosfilt(sos, piece, zi=state)
        yield i, y


def _ringing(
    x: Samples, sos: np.ndarray, fs: float, starts: np.ndarray, interval_s: float
) -> list[float]:
    """The peaks of the pulses' mean power spectrum (the sound `x` high-passed by `sos`, each
    pulse from its block's start over min(`RING_S`, 0.8 interval)), `RING_PROMINENCE_DB`
    over their spectral neighbourhood and within `RING_RANGE_DB` of the strongest [Hz],
    strongest first."""
    n = max(8, round(fs * min(RING_S, 0.8 * interval_s)))
    starts = starts[starts + n <= x.size]
    if starts.size == 0:
        return []
    segments = np.zeros((starts.size, n))
    end = int(starts.max()) + n
    # filtered from SETTLE_S before the first pulse, from rest: it has settled by then (the
    # high-pass rings down within milliseconds), as if from the recording's start
    first = max(int(starts.min()) - round(SETTLE_S * fs), 0)
    for i0, y in _highpassed(span(x, first, end), sos, 1):  # the pulses' pieces only are kept
        i = first + i0
        for k in np.flatnonzero((starts < i + y.size) & (starts + n > i)).tolist():
            a, b = max(int(starts[k]), i), min(int(starts[k]) + n, i + y.size)
            segments[k, a - int(starts[k]) : b - int(starts[k])] = y[a - i : b - i]
    segments *= np.hanning(n)
    nfft = 1 << max(10, math.ceil(math.log2(n)))
    power = np.mean(np.abs(np.fft.rfft(segments, nfft, axis=1)) ** 2, axis=0)
    db = 10 * np.log10(power + 1e-30 * power.max() + 1e-300)
    peaks, _ = signal.find_peaks(db, prominence=RING_PROMINENCE_DB)
    peaks = peaks[(db[peaks] >= db.max() - RING_RANGE_DB) & (peaks > 0) & (peaks < db.size - 1)]
    strongest = peaks[np.argsort(db[peaks])[::-1][:MAX_RINGING]]
    a, b, c = db[strongest - 1], db[strongest], db[strongest + 1]
    offset = 0.5 * (a - c) / np.where(a - 2 * b + c == 0, -1e-30, a - 2 * b + c)
    return [float(f) for f in (strongest + offset) * fs / nfft]


def sort_creaks(
    episodes: list[Any], tones: list[Any], creaks: list[Creak], margin_s: float
) -> tuple[list[Any], list[Creak]]:
    """Squeak episodes and creaks told apart.

    A creak whose strongest ringing is a sustained tone (`tones`: squeak episodes and the
    drive's and background's) or one of its harmonics (up to the 5th, within
    `BEAT_TOLERANCE`) held over `FRAGMENT_INSIDE` of the creak's span is that tone beating
    with another, not a creak; one with `TONAL_LINES` sustained tones following whole
    multiples of its pulse rate is a periodic sound's waveform. Then an episode lying
    (`FRAGMENT_INSIDE` of it) within a creak's span widened by `margin_s` (an analysis frame
    around a pulse sees it) at one of its ringing frequencies (within
    `FRAGMENT_RING_TOLERANCE`), at a harmonic of its pulse rate (within a tenth of the rate)
    or lasting at most `FRAGMENT_FRAMES` frames is the creak heard as tones; its frequency
    goes to the creak's `fragments_hz`.

    Parameters
    ----------
    episodes : list of Episode
        Squeak episodes.
    tones : list of Episode
        Every tone tracked (the squeak episodes and the rejected ones).
    creaks : list of Creak
        The pulse trains of the same recording (`find_creaks`).
    margin_s : float
        Widening of each creak's span on both sides [s]: the tonal detector's frame length.

    Returns
    -------
    episodes : list of Episode
        The episodes that are not fragments, in their order.
    creaks : list of Creak
        The creaks that are not beats, their `fragments_hz` filled.
    """
    creaks = [
        c
        for c in creaks
        if not any(_beats(c, e, margin_s) for e in tones)
        and sum(_harmonic_of(c, e, margin_s) for e in tones) < TONAL_LINES
    ]
    kept = []
    for e in episodes:
        host = next((c for c in creaks if _fragment_of(e, c, margin_s)), None)
        if host is None:
            kept.append(e)
        else:
            host.fragments_hz.append(float(e.frequency_hz))
    return kept, creaks


def _beats(c: Creak, e: Any, margin_s: float) -> bool:
    if not c.ringing_hz or e.end_s - e.start_s <= FRAGMENT_FRAMES * margin_s:
        return False
    held = min(e.end_s, c.end_s) - max(e.start_s, c.start_s)
    if held < FRAGMENT_INSIDE * (c.end_s - c.start_s):
        return False
    lines = [m * e.frequency_hz for m in range(1, 6)] + list(e.harmonics_hz)
    return any(abs(c.ringing_hz[0] / f - 1) <= BEAT_TOLERANCE for f in lines)


def _harmonic_of(c: Creak, e: Any, margin_s: float) -> bool:
    """A sustained tone that stays at a whole multiple (up to `HARMONIC_MAX`) of the train's
    local pulse rate (`HARMONIC_SHARE` of its frames within `HARMONIC_TOLERANCE` of it)."""
    if e.end_s - e.start_s <= FRAGMENT_FRAMES * margin_s or c.pulse_times_s.size < 3:
        return False
    t, f = np.asarray(e.track_times_s, float), np.asarray(e.track_hz, float)
    pulses = c.pulse_times_s
    inside = np.isfinite(f) & (t >= pulses[0]) & (t <= pulses[-1])
    if inside.sum() < 2:
        return False
    rate = np.interp(t[inside], 0.5 * (pulses[1:] + pulses[:-1]), 1.0 / np.diff(pulses))
    ratio = f[inside] / rate
    whole = np.round(ratio)
    near = (np.abs(ratio - whole) <= HARMONIC_TOLERANCE) & (whole >= 1) & (whole <= HARMONIC_MAX)
    return bool(np.mean(near) >= HARMONIC_SHARE)


def _fragment_of(e: Any, c: Creak, margin_s: float) -> bool:
    inside = min(e.end_s, c.end_s + margin_s) - max(e.start_s, c.start_s - margin_s)
    if inside < FRAGMENT_INSIDE * max(e.end_s - e.start_s, 0.0):
        return False
    if e.end_s - e.start_s <= FRAGMENT_FRAMES * margin_s:
        return True
    f, rate = e.frequency_hz, c.pulse_rate_hz
    if any(abs(f / r - 1) <= FRAGMENT_RING_TOLERANCE for r in c.ringing_hz):
        return True
    return abs(f - round(f / rate) * rate) <= 0.1 * rate
