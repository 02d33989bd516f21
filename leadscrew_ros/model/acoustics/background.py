# SPDX-License-Identifier: Apache-2.0
"""The background of a bench: the tones that sound while the drive does not move.

A fan, mains hum and its harmonics, a neighbouring machine: whatever is prominent while the
drive is at rest is not squeak. `BackgroundLearner` collects the prominent tone candidates of
the detector's frames taken at rest (|speed| below `DetectorSettings.motor_off_rad_s` for at
least `motor_off_min_s`), groups them by frequency (within `DetectorSettings.track_tolerance`
or one and a half bins, whichever is wider) and keeps, per tone, how many rest frames held it
and its mean level. A tone held by at least `background_share` of the rest frames is a
background tone (`tones`). A track of the detector is background (`match`) when its median
frequency is within that tolerance of a background tone and its mean level is not more than
`background_margin_db` above the tone's: a squeak at the fan's frequency, clearly louder than
the fan, is still squeak.

Tones can also be given (`include`): those of a recording without motor-off time inferred as
background (`detection`: held at a steady frequency and level over most of it), which hold no
rest frames and no spectrum of their own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

_MAX_TONES = 256  # tone groups kept (the rarest are dropped first): bounded memory
_TINY = 1e-300


@dataclass(frozen=True)
class BackgroundTone:
    """One tone of the background.

    Attributes
    ----------
    frequency_hz : float
        Its mean frequency [Hz].
    level_db : float
        Its mean level over the rest frames holding it: dB SPL re 20 uPa when calibrated, else
        dB re full scale (mean square re 1).
    share : float
        The share of the rest frames that held it.
    level_sd_db : float
        Standard deviation of its level over those frames [dB]: a steady tone's is small.
    """

    frequency_hz: float
    level_db: float
    share: float
    level_sd_db: float = 0.0

    def as_dict(self) -> dict[str, float]:
        """{frequency_hz, level_db, share} (JSON-ready)."""
        return {
            "frequency_hz": self.frequency_hz,
            "level_db": self.level_db,
            "share": self.share,
        }


class BackgroundLearner:
    """Tones of the frames taken at rest, grouped by frequency (module notes).

    Parameters
    ----------
    bin_hz : float
        The detector's frequency resolution [Hz] (1 / frame_s).
    tolerance : float
        Relative frequency tolerance of a group.
    share : float
        Share of the rest frames a background tone is held by at least.
    margin_db : float
        How far above a background tone's level a tone at its frequency is not background.
    level_offset_db : float
        Added to 10 lg(power) to give the levels (the calibration: 20 lg(scale / 20 uPa)).
    """

    def __init__(
        self,
        bin_hz: float,
        tolerance: float,
        share: float,
        margin_db: float,
        level_offset_db: float = 0.0,
    ) -> None:
        self.bin_hz, self.tolerance = bin_hz, tolerance
        self.share, self.margin_db, self.level_offset_db = share, margin_db, level_offset_db
        self._narrowest_hz = 1.5 * bin_hz  # a group is at least one and a half bins wide
        self.frames = 0  #: rest frames seen
        self._spectrum: np.ndarray | None = None  # sum of the rest frames' PSD
        self._spectra = 0  # rest frames summed into it
        # per group: [sum of frequencies, frames holding it, sum of levels (dB), sum of their
        # squares]; Python floats: a rest frame holds a tone or two, a few groups in all
        self._groups: list[list[float]] = []
        self._tones: list[BackgroundTone] | None = None  # `tones`, until the next frame
        # `band_power`'s tables until the next frame: (cumulative power of the floor at the
        # bin edges, learned tones' frequencies, their powers)
        self._bands: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._given: list[BackgroundTone] = []  # `include`

    def _width_hz(self, f: np.ndarray | float) -> np.ndarray:
        return np.maximum(self.tolerance * np.asarray(f, dtype=float), self._narrowest_hz)

    def add(self, frequency_hz: ArrayLike, power: ArrayLike) -> None:
        """One rest frame's prominent tone candidates.

        Parameters
        ----------
        frequency_hz : array_like
            Their frequencies [Hz].
        power : array_like
            Their mean squares (full scale^2).
        """
        self.frames += 1
        g = self._groups
        freq, powers = np.asarray(frequency_hz, float).tolist(), np.asarray(power, float).tolist()
        for f, p in zip(freq, powers, strict=True):
            level = 10.0 * math.log10(max(p, _TINY)) + self.level_offset_db
            width = max(self.tolerance * f, self._narrowest_hz)  # `_width_hz` of a float
            best, k = math.inf, -1  # the nearest group within the width (ties: the first)
            for i, (s, n, _, _) in enumerate(g):
                d = abs(s / n - f)
                if d <= width and d < best:
                    best, k = d, i
            if k >= 0:
                row = g[k]
                row[0] += f
                row[1] += 1.0
                row[2] += level
                row[3] += level * level
            else:
                g.append([f, 1.0, level, level * level])
        if len(g) > _MAX_TONES:
            g.sort(key=lambda row: -row[1])  # stable: the rarest go, the first of a tie stays
            del g[_MAX_TONES:]
        self._tones, self._bands = None, None

    def add_spectrum(self, psd: np.ndarray) -> None:
        """Rest frames' power spectral densities (frames, bins) [unit^2/Hz], bins `bin_hz`
        apart from 0 Hz: the background's mean spectrum (`band_power`)."""
        rows = np.asarray(psd, dtype=np.float64)
        if rows.shape[0] == 0:
            return
        total = rows.sum(axis=0)
        if self._spectrum is None or self._spectrum.shape != total.shape:
            self._spectrum, self._spectra = np.zeros_like(total), 0
        self._spectrum += total
        self._spectra += rows.shape[0]
        self._bands = None

    @property
    def has_spectrum(self) -> bool:
        """A background spectrum was learned."""
        return self._spectra > 0

    def band_power(self, frequency_hz: np.ndarray) -> np.ndarray:
        """The background's mean power in the third-octave band around each frequency
        ([f 2^-1/6, f 2^1/6)) [unit^2]; nan before any rest frame.

        The band's edges cut the bins where they fall (not at whole bins), and a learned tone
        (`learned`) counts with its whole power where its frequency is inside the band, none
        where it is outside: the spectrum under its main lobe (+-2 bins of the Hann window) is
        the noise floor interpolated from the bins beside it, its excess over that floor is
        its power. So mains hum at 200 Hz is not in the band of a tone at 225 Hz (from
        200.4 Hz), though a 10-Hz bin holds both edges.

        Parameters
        ----------
        frequency_hz : numpy.ndarray
            Any shape [Hz].

        Returns
        -------
        numpy.ndarray
        """
        f = np.asarray(frequency_hz, dtype=float)
        if self._spectrum is None or not self._spectra:
            return np.full(f.shape, np.nan)
        cum, tone_hz, tone_power = self._band_tables()
        lo, hi = f * 2 ** (-1 / 6), f * 2 ** (1 / 6)
        edges = np.arange(cum.size) - 0.5  # bin k spans k -+ 1/2 bins
        power = np.interp(hi / self.bin_hz, edges, cum) - np.interp(lo / self.bin_hz, edges, cum)
        if tone_hz.size:
            inside = (lo[..., None] <= tone_hz) & (tone_hz < hi[..., None])
            power = power + np.sum(np.where(inside, tone_power, 0.0), axis=-1)
        return np.maximum(power, _TINY)

    def _band_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._bands is None:
            assert self._spectrum is not None
            mean = self._spectrum / self._spectra
            k = np.arange(mean.size)
            tones = [t.frequency_hz for t in self.learned()]
            centre = np.rint(np.asarray(tones) / self.bin_hz).astype(int)
            lobe = np.zeros(mean.size, bool)
            for c in centre.tolist():
                lobe[max(c - 2, 0) : c + 3] = True
            floor = mean.copy()
            if lobe.any() and not lobe.all():
                floor[lobe] = np.interp(k[lobe], k[~lobe], mean[~lobe])
            excess = np.maximum(mean - floor, 0.0) * self.bin_hz
            power = np.array(
                [excess[max(c - 2, 0) : c + 3].sum() for c in centre.tolist()], dtype=float
            )
            cum = np.concatenate([[0.0], np.cumsum(floor)]) * self.bin_hz
            self._bands = (cum, np.asarray(tones, dtype=float), power)
        return self._bands

    def learned(self, share: float | None = None) -> list[BackgroundTone]:
        """The tones of the frames seen held by at least `share` of them (default: the
        learner's), by frequency; the tones given by `include` are not among them.

        Parameters
        ----------
        share : float, optional
            Share of the frames.

        Returns
        -------
        list of BackgroundTone
        """
        if not self.frames:
            return []
        least = (self.share if share is None else share) * self.frames
        out = []
        for s, n, lv, lv2 in (row for row in self._groups if row[1] >= least):
            mean = lv / n
            sd = math.sqrt(max(lv2 / n - mean * mean, 0.0))
            out.append(BackgroundTone(s / n, mean, n / self.frames, sd))
        return sorted(out, key=lambda t: t.frequency_hz)

    def include(self, tones: list[BackgroundTone]) -> None:
        """Take `tones` as background tones too (inferred ones: module notes); a tone within
        `_width_hz` of one taken before is that one (a tone switched on and off again: its
        shares add up, its level is the louder)."""
        given = list(self._given)
        for t in tones:
            k = next(
                (
                    k
                    for k, g in enumerate(given)
                    if abs(g.frequency_hz - t.frequency_hz) <= self._width_hz(t.frequency_hz)
                ),
                None,
            )
            if k is None:
                given.append(t)
                continue
            g = given[k]
            share = g.share + t.share
            given[k] = BackgroundTone(
                (g.frequency_hz * g.share + t.frequency_hz * t.share) / share
                if share > 0
                else g.frequency_hz,
                max(g.level_db, t.level_db),
                share,
                max(g.level_sd_db, t.level_sd_db),
            )
        self._given = sorted(given, key=lambda t: t.frequency_hz)
        self._tones = None

    def tones(self) -> list[BackgroundTone]:
        """The background tones learned so far and those included, by frequency.

        Returns
        -------
        list of BackgroundTone
        """
        if self._tones is None:
            self._tones = sorted([*self.learned(), *self._given], key=lambda t: t.frequency_hz)
        return self._tones

    def covers(self, frequency_hz: np.ndarray, level_db: np.ndarray) -> np.ndarray:
        """Which tones (any shape) are a background tone: at its frequency, not more than
        `margin_db` above its level (vectorised `match`).

        Parameters
        ----------
        frequency_hz, level_db : numpy.ndarray
            The tones' frequencies [Hz] and levels, one shape.

        Returns
        -------
        numpy.ndarray of bool
        """
        f = np.asarray(frequency_hz, dtype=float)
        tones = self.tones()
        if not tones:
            return np.zeros(f.shape, bool)
        fb = np.array([t.frequency_hz for t in tones])
        lb = np.array([t.level_db for t in tones])
        near = np.abs(f[..., None] - fb) <= self._width_hz(f)[..., None]
        quiet = np.asarray(level_db, dtype=float)[..., None] <= lb + self.margin_db
        return np.any(near & quiet, axis=-1)

    def match(self, frequency_hz: float, level_db: float) -> BackgroundTone | None:
        """The background tone a tone of this frequency and (mean) level is, or None.

        Parameters
        ----------
        frequency_hz : float
            The tone's (median) frequency [Hz].
        level_db : float
            Its mean level, in the levels' unit.

        Returns
        -------
        BackgroundTone or None
        """
        for tone in self.tones():
            if abs(tone.frequency_hz - frequency_hz) <= float(self._width_hz(frequency_hz)):
                if level_db <= tone.level_db + self.margin_db:
                    return tone
        return None
