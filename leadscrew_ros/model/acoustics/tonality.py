# SPDX-License-Identifier: Apache-2.0
"""Tone prominence after ECMA-418-1 (formerly ECMA-74 Annex D), on short-time spectra,
vectorised over frames.

A tone is prominent when its tone-to-noise ratio (TNR, D.8: the tone's power against the
masking noise in the critical band around it) or its prominence ratio (PR, D.9: the power of the
critical band around it against the mean of the two adjacent bands) reaches the frequency-
dependent limit (`tnr_limit_db`, `pr_limit_db`).

The critical band is ECMA-418-1's, as MOSQITO computes it: width 25 + 75 (1 + 1.4 (f/kHz)^2)^0.69
Hz (about 100 Hz up to 500 Hz, 18 % of f at 2.6 kHz, 20 % at 11 kHz), centred arithmetically on
f below 500 Hz and geometrically above; the adjacent bands of the PR are ECMA's polynomials.
ECMA-74's older "100 Hz below 500 Hz, 0.2 f above" differs from it by up to 1.1 dB around
2-3 kHz, more than the limits' precision, so it is not used.

Differences from ECMA's stationary 1 Hz spectrum, all deliberate for a detector that decides
every 10 ms: the spectra are short-time (Hann, one frame each, no averaging; `frame_s` of
`DetectorSettings`); the tone's power is the peak bin and the neighbours within 10 dB of it that
the Hann main lobe: the peak bin, both neighbours and the next bin on the side the
interpolated peak leans to (ECMA sums the neighbours within 10 dB that keep falling, which at
10 Hz bins leaves up to 5 % of an off-bin tone's power in the noise and caps the TNR near
13 dB), and the noise density excludes exactly those bins (ECMA: "the bandwidth of the tone",
which MOSQITO takes as one bin); the tone candidates are the local
maxima with the largest TNR against its limit (a cheap three-bin TNR ranks them), `max_peaks`
per frame and every one within 3 dB of its limit (given a gate, `candidates`' `reference`:
every peak through it, and only those); a candidate with a stronger candidate inside its
critical band is suppressed (ECMA: only the highest tone of a band, which also removes the
Hann side lobes of a strong tone; with a gate, also one under a stronger one's side lobes
anywhere: `hann_leakage`); the hearing threshold screening of ECMA is not applied (levels need
not be calibrated).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.fft

#: Below this the lower adjacent band of the PR is cut at 20 Hz and scaled to 100 Hz (D.9).
PR_LOW_HZ = 171.4
_TINY = 1e-30
#: A peak whose three-bin TNR is this far (3 dB) under its limit cannot reach it.
_NEAR_LIMIT = 10 ** (-3 / 10)
#: A tone of its own stands 10 dB over a stronger tone's window leakage at its distance.
_LEAKAGE_MARGIN = 10.0
#: Frames ranked at a time without a gate (`ToneAnalyzer._ranked`).
_RANK_ROWS = 32


def _columns(selected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The selected columns of each row of `selected` (rows, columns), in order, padded to
    the most any row has (at least one): (columns, valid), both (rows, width)."""
    counts = np.count_nonzero(selected, axis=1)
    width = max(int(counts.max(initial=0)), 1)
    f, c = np.divmod(np.flatnonzero(selected), selected.shape[1])  # faster than a 2-D nonzero
    place = np.arange(f.size) - np.repeat(np.cumsum(counts) - counts, counts)
    columns = np.zeros((selected.shape[0], width), np.int64)
    valid = np.zeros((selected.shape[0], width), bool)
    columns[f, place] = c
    valid[f, place] = True
    return columns, valid


def _ranges(
    p: np.ndarray, rows: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """p[rows[i], a[i]:b[i]] (at least one bin each) of every i, one after the other, and
    where each begins: for a `ufunc.reduceat` over them."""
    n = np.maximum(b - a, 1)
    starts = np.cumsum(n) - n
    bins = np.repeat(a - starts, n) + np.arange(int(n.sum()))
    return p[np.repeat(rows, n), bins], starts


def _band_sums(p: np.ndarray, rows: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sum(p[rows[i], a[i]:b[i]]) for each i, in float64 (0 where b <= a)."""
    out = np.zeros(np.size(a))
    some = b > a
    if some.any():
        values, starts = _ranges(p, rows[some], a[some], b[some])
        out[some] = np.add.reduceat(values.astype(np.float64), starts)
    return out


def hann_leakage(offset_bins: np.ndarray) -> np.ndarray:
    """Envelope of the Hann window's side lobes at `offset_bins` from a tone, as a power
    ratio to its peak: (pi x (x^2 - 1))^-2 (-32 dB at 2.5 bins, -18 dB per octave beyond),
    1 inside the main lobe (|x| < 2).

    Parameters
    ----------
    offset_bins : numpy.ndarray
        Distance from the tone [bins].

    Returns
    -------
    numpy.ndarray
        Power ratio.
    """
    x = np.maximum(np.abs(np.asarray(offset_bins, dtype=float)), 2.0)
    return np.where(x > 2.0, (np.pi * x * (x * x - 1.0)) ** -2, 1.0)


def tnr_limit_db(f_hz: np.ndarray | float) -> np.ndarray:
    """ECMA-418-1 TNR limit of a prominent tone: 8 dB from 1 kHz on, 8 + 8.33 lg(1000 / f)
    below.

    Parameters
    ----------
    f_hz : float or array of float
        Tone frequency [Hz], > 0.

    Returns
    -------
    numpy.ndarray
        Limit [dB], the shape of `f_hz`.
    """
    f = np.maximum(np.asarray(f_hz, dtype=float), 1e-9)
    return np.where(f < 1000.0, 8.0 + 8.33 * np.log10(1000.0 / f), 8.0)


def pr_limit_db(f_hz: np.ndarray | float) -> np.ndarray:
    """ECMA-418-1 PR limit of a prominent tone: 9 dB from 1 kHz on, 9 + 10 lg(1000 / f) below.

    Parameters
    ----------
    f_hz : float or array of float
        Tone frequency [Hz], > 0.

    Returns
    -------
    numpy.ndarray
        Limit [dB], the shape of `f_hz`.
    """
    f = np.maximum(np.asarray(f_hz, dtype=float), 1e-9)
    return np.where(f < 1000.0, 9.0 + 10.0 * np.log10(1000.0 / f), 9.0)


def critical_band(f_hz: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Edges (f1, f2) [Hz] of the critical band centred on `f_hz` (ECMA-418-1)."""
    f = np.asarray(f_hz, dtype=float)
    width = 25.0 + 75.0 * (1.0 + 1.4 * (f / 1000.0) ** 2) ** 0.69
    f1 = np.where(f < 500.0, f - width / 2, -width / 2 + np.sqrt(width**2 + 4 * f**2) / 2)
    return f1, f1 + width


def lower_band(f_hz: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Edges [Hz] of the critical band just below the one centred on `f_hz` (D.9)."""
    f = np.asarray(f_hz, dtype=float)
    f2, _ = critical_band(f)
    f1 = np.where(
        f < PR_LOW_HZ,
        20.0,
        np.where(f <= 1600.0, -149.5 + 1.001 * f - 6.9e-5 * f**2, 6.8 + 0.806 * f - 8.2e-6 * f**2),
    )
    return f1, f2


def upper_band(f_hz: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Edges [Hz] of the critical band just above the one centred on `f_hz` (D.9)."""
    f = np.asarray(f_hz, dtype=float)
    _, f1 = critical_band(f)
    f2 = np.where(f <= 1600.0, 149.5 + 1.035 * f + 7.7e-5 * f**2, 3.3 + 1.215 * f + 2.16e-5 * f**2)
    return f1, f2


def phasor(cycles: np.ndarray) -> np.ndarray:
    """exp(-2 pi i `cycles`), complex64: float32 sine and cosine (vectorised, several times
    faster than a complex exponential) of the phase within its cycle, off by at most 4e-7
    rad (1e-13, -130 dB, of a tone's power moved out of it).

    Parameters
    ----------
    cycles : numpy.ndarray
        Phase [cycles], any shape.

    Returns
    -------
    numpy.ndarray
        complex64, the shape of `cycles`.
    """
    c = np.asarray(cycles, dtype=np.float64)
    # in place, into the result's own halves: each temporary of a long segment is a fresh
    # mapping page-faulted in, which cost more than the arithmetic
    frac = np.empty_like(c)
    np.floor(c, out=frac)
    np.subtract(c, frac, out=frac)
    frac *= 2 * np.pi
    phase = frac.astype(np.float32)
    out = np.empty(phase.shape, np.complex64)
    np.cos(phase, out=out.real)
    np.sin(phase, out=out.imag)
    np.negative(out.imag, out=out.imag)
    return out


def hann(n: int) -> np.ndarray:
    """Periodic Hann window of `n` points, float32."""
    return (0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / n)).astype(np.float32)


def short_time_psd(
    samples: np.ndarray,
    sample_rate_hz: float,
    frame_len: int,
    hop: int,
    window: np.ndarray | None = None,
    bins: int | None = None,
) -> np.ndarray:
    """One-sided power spectral density of every frame, all frames in one real FFT.

    Parameters
    ----------
    samples : numpy.ndarray
        1-D signal (float32 is fastest).
    sample_rate_hz : float
        Sample rate [Hz].
    frame_len : int
        Frame length [samples].
    hop : int
        Hop [samples]; frame i is ``samples[i * hop : i * hop + frame_len]`` (strided view, no
        copy before windowing).
    window : numpy.ndarray, optional
        Window of `frame_len` points (default `hann`).
    bins : int, optional
        Only the first `bins` bins (the detector's analysed range: the squares of the rest
        are not taken).

    Returns
    -------
    numpy.ndarray
        (frames, frame_len // 2 + 1 or `bins`) float32, [unit^2 / Hz]: summed over all the
        bins times the bin spacing it is the frame's window-weighted mean square.
    """
    x = np.asarray(samples, dtype=np.float32)
    total = frame_len // 2 + 1
    bins = total if bins is None else min(bins, total)
    if x.size < frame_len:
        return np.zeros((0, bins), np.float32)
    w = hann(frame_len) if window is None else np.asarray(window, np.float32)
    frames = np.lib.stride_tricks.sliding_window_view(x, frame_len)[::hop]
    psd = np.empty((frames.shape[0], bins), np.float32)
    # by pieces of about a megabyte: the allocator reuses them, where a whole block's
    # temporaries (megabytes each) were mapped afresh and page-faulted in, which cost more
    # than their FFT
    rows = max((1 << 20) // (4 * frame_len), 1)
    for a in range(0, frames.shape[0], rows):
        spec = scipy.fft.rfft(frames[a : a + rows] * w, axis=1)[:, :bins]
        np.add(spec.real**2, spec.imag**2, out=psd[a : a + rows])
    psd *= np.float32(2.0 / (sample_rate_hz * float(np.sum(w.astype(float) ** 2))))
    psd[:, 0] *= 0.5
    if frame_len % 2 == 0 and bins == total:
        psd[:, -1] *= 0.5
    return psd


@dataclass
class ToneCandidates:
    """Tone candidates of each frame: (frames, peaks) arrays, strongest first is not
    guaranteed; entries with `valid` False are padding (no peak there)."""

    frequency_hz: np.ndarray  #: interpolated peak frequency [Hz]
    power: np.ndarray  #: the tone's mean square [unit^2]
    tnr_db: np.ndarray  #: tone-to-noise ratio [dB]
    pr_db: np.ndarray  #: prominence ratio [dB]; nan where the upper band passes Nyquist
    valid: np.ndarray  #: a peak that no stronger one inside its critical band suppresses
    tonal: np.ndarray  #: valid, TNR or PR at or above its limit (a harmonic too)
    analyzer: ToneAnalyzer = field(repr=False)  #: the analyzer that found them

    @cached_property
    def prominent(self) -> np.ndarray:
        """Tonal and not a harmonic of a tonal one (`ToneAnalyzer.without_harmonics`, taken
        when first asked: a gated detector does not)."""
        return self.analyzer.without_harmonics(self.frequency_hz, self.power, self.tonal)


class ToneAnalyzer:
    """Tone candidates of short-time spectra of one frame length and sample rate.

    Parameters
    ----------
    sample_rate_hz : float
        Sample rate [Hz].
    frame_len : int
        Frame length [samples] (the spectra have ``frame_len // 2 + 1`` bins).
    f_lo_hz : float
        Lowest tone frequency considered [Hz].
    f_hi_hz : float
        Highest tone frequency considered [Hz], lowered to the highest bin whose critical band
        lies below the Nyquist frequency (`self.f_hi_hz`).
    max_peaks : int
        Peaks evaluated per frame at least without a gate (`candidates`).
    harmonic_tolerance : float
        Relative tolerance of the harmonic test.
    max_harmonic : int
        Harmonic numbers 2..max_harmonic are tested (1: no harmonic test).
    """

    def __init__(
        self,
        sample_rate_hz: float,
        frame_len: int,
        f_lo_hz: float,
        f_hi_hz: float,
        max_peaks: int = 8,
        harmonic_tolerance: float = 0.02,
        max_harmonic: int = 10,
    ) -> None:
        self.df = sample_rate_hz / frame_len
        self.n_bins = frame_len // 2 + 1
        self.max_peaks = max_peaks
        self.harmonic_tolerance = harmonic_tolerance
        self.max_harmonic = max_harmonic
        last = self.n_bins - 1  # the Nyquist bin is excluded from any band
        f = np.arange(self.n_bins) * self.df
        f1, f2 = critical_band(f)
        a, b = self._bins(f1), self._bins(f2)
        fits = (b <= last) & (np.arange(self.n_bins) + 3 <= last)
        k_lo = max(int(np.ceil(f_lo_hz / self.df)), 2)
        k_hi = min(
            int(np.floor(f_hi_hz / self.df)), int(np.nonzero(fits)[0].max()) if fits.any() else -1
        )
        self.k_lo, self.k_hi = k_lo, max(k_hi, k_lo - 1)
        self.f_hi_hz = self.k_hi * self.df
        k = np.arange(self.k_lo, self.k_hi + 1)
        lf1, lf2 = lower_band(f[k])
        uf1, uf2 = upper_band(f[k])
        self.width_hz = (f2 - f1)[k]
        self.a, self.b = a[k], b[k]
        self.la, self.lb = np.maximum(self._bins(lf1), 0), self._bins(lf2)
        self.ua, self.ub = self._bins(uf1), self._bins(uf2)
        self.pr_ok = self.ub <= last
        self.ub = np.minimum(self.ub, last)
        self.lower_scale = np.where(f[k] < PR_LOW_HZ, 100.0 / np.maximum(lf2 - lf1, 1e-9), 1.0)
        self.f1, self.f2 = f1[k], f2[k]
        self.used_bins = min(
            int(max(self.ub.max(initial=0), self.b.max(initial=0), self.k_hi + 2)) + 1, self.n_bins
        )
        self.tnr_limit = tnr_limit_db(np.maximum(f[k], 1e-9))
        self._rank_scale = self.width_hz * 10.0 ** (self.tnr_limit / 10.0)
        self._noise_hz = np.maximum(self.b - self.a - 3, 1) * self.df  # beside 3 tone bins
        self.pr_limit = pr_limit_db(np.maximum(f[k], 1e-9))
        # a tone of its own stands this far over a stronger one's leakage, by their distance
        self._leakage = hann_leakage(np.arange(self.n_bins)) * _LEAKAGE_MARGIN

    def _bins(self, f_hz: np.ndarray) -> np.ndarray:
        return np.rint(np.asarray(f_hz) / self.df).astype(np.int64)

    @property
    def empty(self) -> bool:
        """No bin in the analysed range (the sample rate is too low for it)."""
        return self.k_hi < self.k_lo

    def candidates(
        self,
        psd: np.ndarray,
        floor: np.ndarray | None = None,
        reference: np.ndarray | None = None,
    ) -> ToneCandidates:
        """The tone candidates of every frame of `psd` (frames, bins), see `ToneCandidates`.

        Parameters
        ----------
        psd : numpy.ndarray
            (frames, bins) short-time spectra (`short_time_psd`).
        floor : numpy.ndarray, optional
            Per frame, mean square [unit^2]: peaks weaker than it are no candidates, so that
            rounding noise never takes a candidate's place (`max_peaks`) from a real tone.
        reference : numpy.ndarray, optional
            Per analysed bin (`k_lo` .. `k_hi`), mean square [unit^2] a peak's three bins must
            reach (a gate: the background's band power and an SNR). Given, the candidates are
            every peak through it and only those, however many. Without it, the `max_peaks`
            peaks with the largest TNR against its limit, and every peak within 3 dB of it.
        """
        n_frames = psd.shape[0]
        n_peaks = min(self.max_peaks, max(self.k_hi - self.k_lo + 1, 0))
        if n_frames == 0 or n_peaks == 0:
            z = np.zeros((n_frames, 0))
            return ToneCandidates(z, z, z, z, z.astype(bool), z.astype(bool), self)
        p = psd[:, : self.used_bins]
        floor = None if floor is None else np.asarray(floor, dtype=np.float64)
        if reference is not None:
            peak, tone3 = self._peaks(p, floor)
            # every peak through the gate, and only those: no rank needed, and the band
            # powers only at those peaks (not a cumulative sum over every bin of every frame)
            rel, valid = _columns(peak & (tone3 >= reference) & (tone3 > 0))
            f, c = np.nonzero(valid)
            sums = np.zeros((3,) + rel.shape)
            sums[:, f, c] = self.df * np.stack(
                [
                    _band_sums(p, f, self.a[rel[f, c]], self.b[rel[f, c]]),
                    _band_sums(p, f, self.la[rel[f, c]], self.lb[rel[f, c]]),
                    _band_sums(p, f, self.ua[rel[f, c]], self.ub[rel[f, c]]),
                ]
            )
            total, lower, upper = sums
        else:  # the `max_peaks` best by a cheap TNR against its limit, and every one near it
            rel, valid, total, lower, upper = self._ranked(p, floor, n_peaks)
        k = rel + self.k_lo  # absolute peak bins
        rows = np.arange(n_frames)[:, None, None]
        near = p[rows, k[..., None] + np.arange(-2, 3)].astype(np.float64)  # (frames, peaks, 5)
        p0 = near[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ln = np.log(np.maximum(near[..., 1:4], _TINY))
            den = ln[..., 0] - 2 * ln[..., 1] + ln[..., 2]
            delta = np.clip(
                np.where(den < 0, 0.5 * (ln[..., 0] - ln[..., 2]) / den, 0.0), -0.5, 0.5
            )
        freq = (k + delta) * self.df
        # the Hann main lobe: the peak, both neighbours, and the next bin on the side the
        # interpolated peak leans to
        tone = (
            near[..., 1]
            + p0
            + near[..., 3]
            + np.where(delta > 0, near[..., 4], 0.0)
            + np.where(delta < 0, near[..., 0], 0.0)
        ) * self.df
        n_tone = np.where(delta != 0, 4, 3)
        a, b = self.a[rel], self.b[rel]
        noise = (
            np.maximum(total - tone, _TINY)
            * self.width_hz[rel]
            / (np.maximum(b - a - n_tone, 1) * self.df)
        )
        tnr = 10.0 * np.log10(np.maximum(tone, _TINY) / noise)
        lower = lower * self.lower_scale[rel]
        pr = 10.0 * np.log10(np.maximum(total, _TINY) / np.maximum(0.5 * (lower + upper), _TINY))
        pr = np.where(self.pr_ok[rel], pr, np.nan)
        # a stronger peak inside the critical band suppresses a candidate (ties: lower index)
        fi = freq[:, :, None]
        stronger = (p0[:, :, None] > p0[:, None, :]) | (
            (p0[:, :, None] == p0[:, None, :]) & (rel[:, :, None] < rel[:, None, :])
        )
        inside = (fi >= self.f1[rel][:, None, :]) & (fi <= self.f2[rel][:, None, :])
        if reference is None:
            valid &= ~np.any(valid[:, :, None] & stronger & inside, axis=1)
        else:  # anything stronger in the band, not only a candidate; and a loud tone's leakage
            leak = (
                p0[:, None, :]
                < p0[:, :, None] * self._leakage[np.abs(k[:, :, None] - k[:, None, :])]
            )
            valid &= ~np.any(valid[:, :, None] & stronger & leak, axis=1)
            valid &= ~self._louder_in_band(p, k, p0, valid)
        tonal = valid & ((tnr >= self.tnr_limit[rel]) | (pr >= self.pr_limit[rel]))
        return ToneCandidates(freq, tone, tnr, pr, valid, tonal, self)

    def _peaks(self, p: np.ndarray, floor: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """(local maxima of `p` in the analysed bins reaching `floor`, their three-bin power)."""
        lo, hi = self.k_lo, self.k_hi + 1
        mid = p[:, lo:hi]
        peak = (mid > p[:, lo - 1 : hi - 1]) & (mid >= p[:, lo + 1 : hi + 1])
        tone3 = (mid + p[:, lo - 1 : hi - 1] + p[:, lo + 1 : hi + 1]) * self.df
        if floor is not None:
            peak &= tone3 >= floor[:, None]
        return peak, tone3

    def _ranked(
        self, p: np.ndarray, floor: np.ndarray | None, n_peaks: int
    ) -> tuple[np.ndarray, ...]:
        """Without a gate: per frame of `p`, the columns (relative to `k_lo`) of the peaks
        (`_peaks`) with the largest cheap TNR against its limit, at least `n_peaks` of them
        and as many as any frame has within 3 dB of its limit (`_NEAR_LIMIT`); with (valid,
        the critical band's power, the lower and the upper band's) at each.

        By pieces of `_RANK_ROWS` frames, whose temporaries stay in the cache; a piece ranked
        with fewer columns than another needed is ranked again with as many."""
        pieces = [slice(a, a + _RANK_ROWS) for a in range(0, p.shape[0], _RANK_ROWS)]

        def rank(rows: slice, n: int) -> tuple[int, tuple[np.ndarray, ...]]:
            return self._rank_piece(p[rows], None if floor is None else floor[rows], n)

        done = [rank(rows, n_peaks) for rows in pieces]
        most = max(n for n, _ in done)
        out = [
            d if d[0] == most else rank(rows, most) for d, rows in zip(done, pieces, strict=True)
        ]
        return tuple(np.concatenate(part) for part in zip(*(d[1] for d in out), strict=True))

    def _rank_piece(
        self, p: np.ndarray, floor: np.ndarray | None, n_peaks: int
    ) -> tuple[int, tuple[np.ndarray, ...]]:
        """`_ranked` of a piece: (the number of columns, at least `n_peaks`, the arrays)."""
        peak, tone3 = self._peaks(p, floor)
        cum = np.zeros((p.shape[0], self.used_bins + 1))
        np.cumsum(p, axis=1, dtype=np.float64, out=cum[:, 1:])
        cum *= self.df
        # `take`, not fancy indexing, for the band edges: the same values, a fraction of the time
        band = cum.take(self.b, axis=1) - cum.take(self.a, axis=1)
        density = np.maximum(band - tone3, _TINY) / self._noise_hz
        score = np.where(peak, tone3 / (density * self._rank_scale), 0.0)
        n_peaks = max(n_peaks, int(np.count_nonzero(score >= _NEAR_LIMIT, axis=1).max()))
        n_peaks = min(n_peaks, score.shape[1])
        if n_peaks < score.shape[1]:
            rel = np.argpartition(-score, n_peaks - 1, axis=1)[:, :n_peaks]
        else:
            rel = np.broadcast_to(np.arange(score.shape[1]), score.shape).copy()
        at = np.arange(score.shape[0])[:, None]
        return n_peaks, (
            rel,
            np.take_along_axis(score, rel, axis=1) > 0.0,
            cum[at, self.b[rel]] - cum[at, self.a[rel]],
            cum[at, self.lb[rel]] - cum[at, self.la[rel]],
            cum[at, self.ub[rel]] - cum[at, self.ua[rel]],
        )

    def _louder_in_band(
        self, p: np.ndarray, k: np.ndarray, p0: np.ndarray, which: np.ndarray
    ) -> np.ndarray:
        """(frames, peaks): where a bin of the peak's critical band is above its peak bin
        (evaluated where `which`)."""
        out = np.zeros(which.shape, bool)
        f, c = np.nonzero(which)
        if f.size == 0:
            return out
        kk = k[f, c] - self.k_lo
        values, starts = _ranges(p, f, self.a[kk], self.b[kk])  # the band's bins: a .. b - 1
        out[f, c] = np.maximum.reduceat(values, starts) > p0[f, c]
        return out

    def without_harmonics(self, freq: np.ndarray, tone: np.ndarray, kept: np.ndarray) -> np.ndarray:
        """`kept` (frames, peaks) less the candidates at m = 2..`max_harmonic` times a kept
        one's frequency (within `harmonic_tolerance`) whose amplitude is at most 1.5 / m of
        it: harmonics of a tone (clipping gives 1 / m), not tones of their own."""
        if self.max_harmonic < 2:
            return kept
        fi, fj = freq[:, :, None], freq[:, None, :]
        ratio = fj / np.maximum(fi, _TINY)
        m = np.rint(ratio)
        harmonic = (
            (m >= 2)
            & (m <= self.max_harmonic)
            & (np.abs(ratio - m) <= self.harmonic_tolerance * ratio)
            & (tone[:, None, :] * m**2 <= 2.25 * tone[:, :, None])
        )
        return kept & ~np.any(kept[:, :, None] & harmonic, axis=1)
