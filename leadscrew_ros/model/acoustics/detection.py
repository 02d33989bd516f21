# SPDX-License-Identifier: Apache-2.0
"""Squeak episodes heard by a microphone: prominent tones that do not follow the motor orders.

Per frame (`DetectorSettings.frame_s` long, every `hop_s`), the tone candidates of `tonality`
that are prominent after ECMA-418-1 (TNR or PR at or above its limit) between `f_lo_hz` and
`f_hi_hz` are followed as tracks: a candidate joins the open track whose running median
frequency (over the last `min_duration_s`, at least 3 frames) is nearest within
`track_tolerance`, strongest candidates first; otherwise it opens a new track. A track with no
candidate for `max_gap_s` or more is closed; shorter gaps are bridged. A closed track of at
least `min_duration_s` is an episode, from half a hop before its first frame to half a hop after
its last (frame times are frame centres); offline, its start then moves back to where its tone
first stood the gate at its own frequency (`_onsets_back`).

Drive noise (motor, gear, commutator) moves with the speed at a fixed ratio to the screw's
rotation frequency f1 = |speed| / 2 pi, whatever the ratio (a worm gear of 37.3, its orders,
373 for a commutator); a squeak locks to a structural mode. A track is followed as the speed
moves: a frame's tone joins the track nearest either to its running median or to where its
speed ratio (the median of its recent f / f1) puts it now, so a sweep stays one track. Each
track is judged whole once it is closed, with f1 interpolated at its frames: r = median(f / f1)
in [`min_drive_ratio`, `max_drive_ratio`], `order_share` of its frames within `order_tolerance`
of r f1. Whether it *follows* the speed is judged from the relative rms deviations of its
frequencies from r f1 (r_ratio) and from their median (r_const), with a floor of a tenth of a
frequency bin against the frequency estimate's own scatter: r_const >= 3 r_ratio means the tone
moved with the speed (rejected as drive noise; r is learned as one of the drive's ratios,
`drive_orders`); r_ratio >= 3 r_const means it stayed while the speed moved (kept); otherwise
the speed hardly changed: rejected at one of the drive's ratios (learned, or given:
`drive_ratios`), or at a whole order k <= 0.25 / `order_tolerance` (12 at 2 %: the tolerance
windows of neighbouring orders cover at most half of the frequency axis, so a constant tone lies
on order k by chance only at the odds of a coin toss or less), kept otherwise, where by
frequency alone it cannot be told from a squeak. Tones of the background (what sounds while
the drive rests: `background`) are not followed unless clearly louder.

Where the background comes from (`Detection.background_source`): a background recording
(`detect`'s `background`: 'file'), the recording's own motor-off stretches ('motor-off'); without
either, it is inferred ('inferred'): a tone held by more than `background_infer_share` of the
frames at a steady level (`background_level_sd_db`), whatever the speed (a tone that moves with
it is no single tone) and, given a condition such as the prediction, on each side of it, is
background, unless it grew: where it comes in after an absence, its growth at that onset is
measured (`growth.onset_growth`) and has a rate (a squeak grows at Re(lambda) from the floor,
then may saturate and hold over most of the recording; a tone switched on, a step, or one whose
onset cannot be measured stays background). A recording with nothing moving is so judged as a
whole: a stationary tone is background, and so is an intermittent one that comes in at once (a
step: switched on, `Growth.step`); one that grows is not (`detect`'s `infer_background`: the
offline listening of a log or a recording; the node, which hears as it goes, cannot).
'none': nothing learned from.

`StreamingDetector` is the core: it frames the samples as they come, analyses each frame once,
and runs the tracks frame by frame with bounded memory. `detect` pushes the whole signal into
one and flushes it, so that the offline and live decisions are the same frame for frame.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from itertools import compress
from typing import Any

import numpy as np

from .background import BackgroundLearner, BackgroundTone
from .creak import Creak, find_creaks, sort_creaks
from .growth import Growth, growth_fields, onset_growth
from .samples import Samples, SampleTrack, span
from .settings import DetectorSettings
from .tonality import ToneAnalyzer, ToneCandidates, hann, hann_leakage, phasor, short_time_psd

P_REF_PA = 20e-6  #: reference sound pressure of dB SPL
#: Relative spacing of float32 numbers: the rounding of the samples the detector analyses.
FLOAT32_STEP = 2.0**-23
#: A frame whose varying part is within 6 dB of its rounding noise holds no sound (a constant,
#: muted or digitally silent signal): it is not analysed and not scored.
SILENT_FACTOR = 4.0
#: A tone candidate stands 10 dB over the rounding (quantisation) noise of its frame, all of it.
TONE_FLOOR_FACTOR = 10.0
# Full-scale integer PCM grids, coarsest first: 8, 16, 24 bits (x 2^(b-1) and 2^(b-1) - 1).
_PCM_GRIDS = (128.0, 127.0, 32768.0, 32767.0, 8388608.0)
LOUDNESS_RATE_HZ = 48000  #: ISO 532-1 after MOSQITO wants 48 kHz; other rates are resampled
#: A tone whose level changes this much from the frame before to the frame after it (0.15 s
#: apart) was cut or switched (`without_splatter`), not followed by another track.
CUT_DB = 10.0
#: A peak's three bins may hold this much less than its whole tone (`ToneCandidates.power`).
_GATE_MARGIN_DB = 3.0
_BLOCK_FRAMES = 256  # frames analysed per FFT block (bounded memory, same in every mode)
_MAX_WARNINGS = 100
_MAX_RATIOS = 100  # drive-ratio groups kept (bounded memory)
_WALK_FRAMES = 32  # frames measured at once as an onset is walked back (`_onsets_back`)


class AudioError(ValueError):
    """The audio cannot be analysed at all (an invalid sample rate)."""


GROWTH_NEIGHBOUR = 0.1  # a tone within 10 % sounded in the growth measurement's band
PATH_FRAMES = 3  #: a piece of a sweep is followed this many frame lengths beyond its ends


def _finite_or_none(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass(frozen=True)
class DriveOrder:
    """A ratio at which the drive was heard (tracks that moved with the speed).

    Attributes
    ----------
    ratio : float
        Frequency over the screw's rotation frequency |speed| / 2 pi.
    level_db : float
        Mean level of its tracks (dB SPL when calibrated, else dB re full scale).
    tracks : int
        Tracks heard at it.
    """

    ratio: float
    level_db: float
    tracks: int

    def as_dict(self) -> dict[str, float]:
        """{ratio, level_db, tracks} (JSON-ready)."""
        return {"ratio": self.ratio, "level_db": self.level_db, "tracks": self.tracks}


def _scatter(f: np.ndarray, f1: np.ndarray, r: float, bin_hz: float) -> tuple[float, float, float]:
    """A track's frequencies `f` [Hz] against r times the rotation `f1` [Hz]: their rms
    relative scatter about r f1 (r_ratio) and about their median (r_const), and the floor of
    both (a tenth of a bin: the frequency estimate's own scatter); module notes."""
    r_ratio = float(np.sqrt(np.mean((f / (r * f1) - 1.0) ** 2)))
    r_const = float(np.sqrt(np.mean((f / np.median(f) - 1.0) ** 2)))
    return r_ratio, r_const, 0.1 * bin_hz / float(np.median(f))


@dataclass
class Episode:
    """One squeak episode (or, in `Detection.rejected`, a tone that followed the orders).

    Attributes
    ----------
    start_s : float
        Half a hop before its first frame's centre [s].
    end_s : float
        Half a hop after its last frame's centre [s].
    frequency_hz : float
        Median frequency of its track [Hz].
    tnr_db : float
        Largest TNR of its frames [dB].
    pr_db : float
        Largest PR of its frames [dB] (nan where the upper band passes Nyquist).
    level_db : float
        Largest tone level of its frames: dB SPL re 20 uPa when calibrated, else dB re full
        scale (mean square re 1, a full-scale sine is -3 dB).
    loudness_sone : float or None
        Largest ISO 532-1 time-varying loudness (free field, MOSQITO `loudness_zwtv`) over the
        episode, or its last `loudness_max_s` [sone]; None when uncalibrated, disabled or
        MOSQITO is missing.
    order : int or None
        The whole order it followed (rejected episodes only; None at a ratio that is not
        whole).
    drive_ratio : float or None
        The ratio of its frequency to the screw's rotation frequency it followed (rejected
        episodes only: drive noise).
    background_hz : float or None
        The background tone it was (rejected episodes only; `background`) [Hz].
    harmonics_hz : list of float
        Its harmonics heard with it (2 to 5 times its frequency; `with_harmonics`) [Hz].
    growth : Growth or None
        Its growth rate at the onset, measured from the sound (`growth.onset_growth`;
        offline only: None live).
    track_times_s : numpy.ndarray
        Its frames' centres [s]; not in `as_dict`.
    track_hz : numpy.ndarray
        Its frames' frequencies [Hz] (nan in bridged gaps); not in `as_dict`.
    tracked_start_s : float or None
        Where the tracker took it [s], when the offline pass `_onsets_back` moved `start_s`
        earlier (to where the tone alone first stood the gate); None when it did not. The
        calibration's hearing model counts the tracker's crossings: they start and end an
        episode by one rule.
    """

    start_s: float
    end_s: float
    frequency_hz: float
    tnr_db: float
    pr_db: float
    level_db: float
    loudness_sone: float | None = None
    order: int | None = None
    drive_ratio: float | None = None
    background_hz: float | None = None
    harmonics_hz: list[float] = field(default_factory=list)
    growth: Growth | None = None
    track_times_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    track_hz: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    tracked_start_s: float | None = None

    @property
    def duration_s(self) -> float:
        """end_s - start_s [s]."""
        return self.end_s - self.start_s

    def as_dict(self) -> dict[str, Any]:
        """The episode as a JSON-safe dict (nan -> None), without the per-frame track.

        Returns
        -------
        dict
        """
        return dict(
            start_s=self.start_s,
            end_s=self.end_s,
            frequency_hz=self.frequency_hz,
            tnr_db=_finite_or_none(self.tnr_db),
            pr_db=_finite_or_none(self.pr_db),
            level_db=_finite_or_none(self.level_db),
            loudness_sone=_finite_or_none(self.loudness_sone),
            order=self.order,
            drive_ratio=self.drive_ratio,
            background_hz=self.background_hz,
            harmonics_hz=list(self.harmonics_hz),
            tracked_start_s=self.tracked_start_s,
            **growth_fields(self.growth),
        )


@dataclass
class Detection:
    """What `detect` heard.

    Attributes
    ----------
    frame_times_s : numpy.ndarray
        Frame centres [s].
    heard : numpy.ndarray
        Per frame: a squeak episode covers it.
    frequency_hz : numpy.ndarray
        Per frame: the heard frequency (the loudest episode's track; its median in a bridged
        gap), nan when none [Hz].
    episodes : list of Episode
        Squeak episodes, by start time.
    sample_rate_hz : float
        Sample rate of the input [Hz].
    scale : str
        'Pa' (calibrated: levels in dB SPL) or 'full scale'.
    warnings : list of str
        What was wrong with the input (non-finite samples, clipping, too short, ...).
    rejected : list of Episode
        Tones that followed the motor orders.
    usable : numpy.ndarray of bool, optional
        Per frame: it holds usable sound (no non-finite sample, not constant or digitally
        silent); None: all.
    background : list of BackgroundTone
        The tones that sounded while the drive was at rest (`background`).
    drive_orders : list of DriveOrder
        The speed ratios the drive was heard at.
    creaks : list of Creak
        Stick-slip pulse trains (`creak`; offline only): not squeak, their tonal fragments
        taken out of `episodes`.
    background_source : str
        Where `background` comes from: 'file' (a background recording), 'motor-off' (the
        recording's rest stretches), 'inferred' (steady tones, module notes) or 'none'.
    """

    frame_times_s: np.ndarray
    heard: np.ndarray
    frequency_hz: np.ndarray
    episodes: list[Episode]
    sample_rate_hz: float
    scale: str
    warnings: list[str]
    rejected: list[Episode] = field(default_factory=list)
    usable: np.ndarray | None = None
    background: list[BackgroundTone] = field(default_factory=list)
    drive_orders: list[DriveOrder] = field(default_factory=list)
    creaks: list[Creak] = field(default_factory=list)
    background_source: str = "none"

    @property
    def unusable_s(self) -> float:
        """Time whose frames hold no usable sound (non-finite samples, a constant or
        digitally silent signal): not scored [s]."""
        if self.usable is None or self.usable.size < 2:
            return 0.0
        return float(np.count_nonzero(~self.usable)) * self.hop_s

    def unusable_spans(self) -> list[tuple[float, float]]:
        """The runs of frames without usable sound as (start, end) [s], each frame standing
        for one hop around its centre.

        Returns
        -------
        list of (float, float)
        """
        if self.usable is None or self.usable.size < 2 or self.usable.all():
            return []
        bad = np.concatenate([[False], ~self.usable, [False]])
        edges = np.flatnonzero(bad[1:] != bad[:-1])
        t, half = self.frame_times_s, self.hop_s / 2
        return [
            (float(t[a] - half), float(t[b - 1] + half))
            for a, b in zip(edges[::2], edges[1::2], strict=True)
        ]

    @property
    def hop_s(self) -> float:
        """Spacing of the frames [s] (nan with fewer than two)."""
        t = self.frame_times_s
        return float(t[1] - t[0]) if t.size > 1 else math.nan

    def as_dict(self) -> dict[str, Any]:
        """The detection as a JSON-safe dict (no nan: None in its place).

        Returns
        -------
        dict
        """
        return dict(
            frame_times_s=self.frame_times_s.tolist(),
            heard=self.heard.tolist(),
            frequency_hz=[_finite_or_none(f) for f in self.frequency_hz.tolist()],
            episodes=[e.as_dict() for e in self.episodes],
            rejected=[e.as_dict() for e in self.rejected],
            sample_rate_hz=self.sample_rate_hz,
            scale=self.scale,
            warnings=list(self.warnings),
            unusable_s=self.unusable_s,
            background=[t.as_dict() for t in self.background],
            background_source=self.background_source,
            drive_orders=[d.as_dict() for d in self.drive_orders],
            creaks=[c.as_dict() for c in self.creaks],
        )


def _mono(samples: Any) -> Samples | None:
    """The samples as one contiguous float32 channel (several averaged over the shorter
    axis), a `SampleTrack` as it is (read by slices); None when they are not numbers."""
    if isinstance(samples, SampleTrack):
        return samples
    try:
        x = np.asarray(samples, dtype=np.float32)
    except (TypeError, ValueError):
        return None
    if x.ndim > 1:
        x = x.mean(axis=int(np.argmin(x.shape)))
    return np.ascontiguousarray(x.reshape(-1))


def format_step(samples: Samples) -> float | None:
    """Quantisation step of the samples' format in full-scale units: 1/2^(b-1) (or
    1/(2^(b-1) - 1)) for b-bit integer PCM, 0.0 for floating point (the rounding is then
    relative, `FLOAT32_STEP`); None when a chunk cannot tell (fewer than 256 non-zero samples).

    Parameters
    ----------
    samples : numpy.ndarray
        Samples in full-scale units (-1..1).

    Returns
    -------
    float or None
    """
    nonzero = np.zeros(0)  # the first 4096 non-zero samples, found without a whole copy
    for a in range(0, samples.size, 1 << 16):
        piece = samples[a : a + (1 << 16)]
        told = piece[(piece != 0) & np.isfinite(piece)]  # NaN/inf are set to 0 by `push`
        nonzero = np.concatenate([nonzero, told[: 4096 - nonzero.size]])
        if nonzero.size >= 4096:
            break
    if nonzero.size < 256:
        return None
    for grid in _PCM_GRIDS:
        # the first 256 refuse most grids at a sixteenth of the cost (every chunk is asked)
        if _on_grid(nonzero[:256], grid) and _on_grid(nonzero, grid):
            return 1.0 / grid
    return 0.0


def _on_grid(x: np.ndarray, grid: float) -> bool:
    """All of `x` on the grid 1 / `grid` within float32 rounding of the scaled value, never
    a coarser grid's fraction (a 16-bit step is 1/256 of an 8-bit one)."""
    y = x * grid
    return bool(np.all(np.abs(y - np.rint(y)) <= 2.0**-20 * np.maximum(np.abs(y), 1.0)))


def frame_powers(
    samples: np.ndarray, frame_len: int, hop: int, frames: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per frame (``samples[i * hop : i * hop + frame_len]``) the mean square of its varying
    part (its variance) and its mean square [unit^2]: from running sums, and from the frame
    itself where it is nearly constant (a constant signal has a variance of 0 exactly).

    Parameters
    ----------
    samples : numpy.ndarray
        1-D signal.
    frame_len, hop, frames : int
        Frame length and hop [samples]; the number of frames.

    Returns
    -------
    tuple of numpy.ndarray
        (variance, mean square), each (frames,).
    """
    x = np.asarray(samples, dtype=np.float64)
    shift = float(x.mean()) if x.size else 0.0
    # running sums over pieces of gcd(frame, hop) samples (a hop's when it divides the frame)
    g = math.gcd(frame_len, hop)
    pieces = (x[: max((frames - 1) * hop + frame_len, 0)] - shift).reshape(-1, g)
    c1 = np.concatenate([[0.0], np.cumsum(pieces.sum(axis=1))])
    c2 = np.concatenate([[0.0], np.cumsum(np.einsum("ij,ij->i", pieces, pieces))])
    starts = np.arange(frames) * (hop // g)
    m1 = (c1[starts + frame_len // g] - c1[starts]) / frame_len
    m2 = (c2[starts + frame_len // g] - c2[starts]) / frame_len
    variance = np.maximum(m2 - m1 * m1, 0.0)
    mean_square = np.maximum(m2 + 2.0 * shift * m1 + shift * shift, 0.0)
    # The running sums cancel to ~1e-16 of their size: where that could matter (a frame
    # near its rounding noise), the variance again from the frame itself.
    near = np.flatnonzero(variance <= 1e-12 * np.maximum(mean_square, 1e-300) + 1e-24)
    for i in near.tolist():
        variance[i] = float(np.var(x[i * hop : i * hop + frame_len]))
    return variance, mean_square


def _check_rate(sample_rate_hz: Any) -> float:
    try:
        rate = float(sample_rate_hz)
    except (TypeError, ValueError):
        raise AudioError(f"sample rate {sample_rate_hz!r} is not a number") from None
    if not math.isfinite(rate) or not 1000.0 <= rate <= 1e6:
        raise AudioError(f"sample rate {sample_rate_hz!r} Hz is not allowed, [1000, 1e6] Hz")
    return rate


class _Track:
    """One tone followed frame by frame."""

    __slots__ = (
        "first",
        "last",
        "frames",
        "hz",
        "f1",
        "recent",
        "median",
        "tnr",
        "pr",
        "power",
        "last_power",
        "checked_at",
        "order_now",
        "level_sum",
        "ratios",
        "ratio",
    )

    def __init__(
        self, i: int, f: float, f1: float, tnr: float, pr: float, power: float, window: int
    ) -> None:
        self.first = self.last = i
        self.frames: list[int] = []
        self.hz: list[float] = []
        self.f1: list[float] = []
        self.recent: deque[float] = deque(maxlen=window)
        self.median = f
        self.tnr = self.pr = self.power = -math.inf
        self.last_power = power
        self.checked_at = 0  # frames when `order_now` was last decided
        self.order_now: float | None = None
        self.level_sum = 0.0  # of 10 lg(power) over its frames: its mean level
        self.ratios: deque[float] = deque(maxlen=window)  # recent f / f1
        self.ratio = math.nan  # their median: where the track goes when the speed moves
        self.add(i, f, f1, tnr, pr, power)

    def add(self, i: int, f: float, f1: float, tnr: float, pr: float, power: float) -> None:
        self.last = i
        self.frames.append(i)
        self.hz.append(f)
        self.f1.append(f1)
        self.recent.append(f)
        r = sorted(self.recent)
        n = len(r)
        self.median = r[n // 2] if n % 2 else 0.5 * (r[n // 2 - 1] + r[n // 2])
        self.tnr = max(self.tnr, tnr)
        if pr == pr:  # not nan
            self.pr = max(self.pr, pr)
        self.power = max(self.power, power)
        self.last_power = power
        self.level_sum += 10.0 * math.log10(max(power, 1e-300))
        if f1 > 0:  # (nan compares False)
            self.ratios.append(f / f1)
            q = sorted(self.ratios)
            m = len(q)
            self.ratio = q[m // 2] if m % 2 else 0.5 * (q[m // 2 - 1] + q[m // 2])

    def distance(self, f: float, f1: float) -> float:
        """Relative distance of a frame's tone at `f` from where this track is: its running
        median, or where its speed ratio puts it at shaft frequency `f1` (a sweep)."""
        d = abs(f / self.median - 1.0)
        if f1 > 0 and self.ratio == self.ratio:
            d = min(d, abs(f / (self.ratio * f1) - 1.0))
        return d


class StreamingDetector:
    """The squeak detector fed chunk by chunk (the node's listening thread), bounded memory.

    Parameters
    ----------
    settings : DetectorSettings
        Detector settings.
    sample_rate_hz : float
        Sample rate [Hz], in [1000, 1e6].
    scale_pa : float, optional
        Pascal per full-scale unit (calibrated: dB SPL and loudness); None: uncalibrated.

    Raises
    ------
    AudioError
        For an invalid sample rate.

    Notes
    -----
    Frame i covers the samples ``i * hop`` to ``i * hop + frame`` counted from the start of
    the current segment; its time is its centre. A chunk whose `t0_s` is within
    ``max(max_gap_s, 2 / rate)`` of where the previous chunk ended continues the segment (time
    is counted in samples, so time-stamp jitter does not move frames); otherwise a warning is
    recorded, the open tracks are closed and a new segment starts at `t0_s`. `warnings` holds
    the last 100 warnings, `rejected` the last 100 rejected (order-following) episodes.
    """

    def __init__(
        self,
        settings: DetectorSettings = DetectorSettings(),
        sample_rate_hz: float = 48000.0,
        scale_pa: float | None = None,
    ) -> None:
        self.settings = settings
        self.scale_pa = None if scale_pa is None else float(scale_pa)
        if self.scale_pa is not None and not (math.isfinite(self.scale_pa) and self.scale_pa > 0):
            raise AudioError(f"scale_pa = {scale_pa!r} must be a positive number")
        self.warnings: deque[str] = deque(maxlen=_MAX_WARNINGS)
        self.rejected: deque[Episode] = deque(maxlen=_MAX_WARNINGS)
        self._loudness_missing = False
        self._format_step = 0.0  # of the latest chunk that told (`format_step`)
        self.unusable_frames = {"non-finite": 0, "silent": 0}  #: frames not analysed, by cause
        #: per frame of the current segment, usable sound (1) or not (0), when not None
        #: (`detect` keeps it; the node's detector does not: bounded memory)
        self.usable_log: bytearray | None = None
        self._reset(_check_rate(sample_rate_hz))
        #: the tones heard at rest (kept across segments and rate changes)
        self.background = BackgroundLearner(
            self.analyzer.df,
            settings.track_tolerance,
            settings.background_share,
            settings.background_margin_db,
            self._level_offset_db,
        )
        self._rest_frames = 0  # consecutive frames at rest
        # every frame so far at a known speed under motor_off_rad_s: nothing has slid, so
        # nothing heard can be squeak (live, the rest's sound is not learned as background
        # before `motor_off_min_s` of it; offline it is, first)
        self._never_moved = True
        # the drive's speed ratios heard: [sum of ratios, tracks, sum of levels (dB)]
        self._ratio_groups = np.zeros((0, 3))

    # -- state -------------------------------------------------------------------------------
    def _reset(self, rate: float) -> None:
        s = self.settings
        self.sample_rate_hz = rate
        self.frame_len = max(int(round(s.frame_s * rate)), 8)
        self.hop = max(int(round(s.hop_s * rate)), 1)
        self.hop_s = self.hop / rate
        self.analyzer = ToneAnalyzer(
            rate,
            self.frame_len,
            s.f_lo_hz,
            s.f_hi_hz,
            s.max_peaks,
            s.track_tolerance,
            s.max_harmonic,
        )
        if self.analyzer.empty:
            self._warn(
                f"sample rate {rate:g} Hz leaves no frequency to analyse above {s.f_lo_hz:g} Hz"
            )
        elif self.analyzer.f_hi_hz < s.f_hi_hz - self.analyzer.df:
            self._warn(
                f"sample rate {rate:g} Hz limits the analysis to {self.analyzer.f_hi_hz:.0f} Hz"
            )
        self._min_frames = max(int(math.ceil(s.min_duration_s / self.hop_s - 1e-9)), 1)
        self._allowed_missing = max(int(math.ceil(s.max_gap_s / self.hop_s - 1e-9)) - 1, 0)
        self._max_frames = max(int(s.max_episode_s / self.hop_s), self._min_frames)
        self._median_window = max(self._min_frames, 3)
        # frames dropped for non-finite samples are bridged up to what one short glitch
        # costs: every frame holding it, plus the gap allowed anyway
        self._max_dropped = -(-self.frame_len // self.hop) + self._allowed_missing
        self._keep = (
            int(math.ceil((s.loudness_max_s + 2 * s.frame_s + s.max_gap_s + 2 * s.hop_s) * rate))
            + self.frame_len
        )
        self._window = hann(self.frame_len)
        self._new_segment(None)

    def _new_segment(self, t0_s: float | None) -> None:
        self._seg_t0 = t0_s
        self._buf = np.zeros(0, np.float32)
        self._bad = np.zeros(0, bool)
        self._buf_start = 0  # segment sample index of _buf[0]
        self._n_samples = 0  # samples received in this segment
        self._next_frame = 0
        self._tracks: list[_Track] = []
        self._dropped_run = 0
        self._speed_t = np.zeros(0)
        self._speed_v = np.zeros(0)
        self._heard_now = False
        self._frequency_now = math.nan
        self._usable_now = True
        if self.usable_log is not None:
            self.usable_log = bytearray()

    @property
    def _level_offset_db(self) -> float:
        """dB SPL of a mean square of 1 when calibrated, else 0 (dB re full scale)."""
        return 0.0 if self.scale_pa is None else 20 * math.log10(self.scale_pa / P_REF_PA)

    def _warn(self, text: str) -> None:
        if not self.warnings or self.warnings[-1] != text:
            self.warnings.append(text)

    @property
    def heard_now(self) -> bool:
        """A track that has lasted `min_duration_s` and does not (so far) follow the orders
        covers the latest frame: provisional (the order test re-run as the track grows by an
        eighth), the episode is decided when it closes."""
        return self._heard_now

    @property
    def usable_now(self) -> bool:
        """The latest frame held usable sound (no non-finite sample, not constant or silent)."""
        return self._usable_now

    @property
    def frequency_now_hz(self) -> float:
        """Running median frequency of the strongest track behind `heard_now`, nan when
        none [Hz]."""
        return self._frequency_now

    @property
    def frames_done(self) -> int:
        """Frames analysed in the current segment."""
        return self._next_frame

    def frame_time(self, i: np.ndarray | int) -> np.ndarray:
        """Centre time [s] of frame(s) `i` of the current segment.

        Parameters
        ----------
        i : int or numpy.ndarray
            Frame index (or indices) in the current segment.

        Returns
        -------
        numpy.ndarray
            The frames' centre times [s].
        """
        t0 = 0.0 if self._seg_t0 is None else self._seg_t0
        return t0 + (np.asarray(i) * self.hop + self.frame_len / 2) / self.sample_rate_hz

    # -- input ---------------------------------------------------------------------------------
    def push(
        self,
        samples: Any,
        t0_s: float,
        speed_rad_s: Any = None,
        speed_times_s: Any = None,
        sample_rate_hz: float | None = None,
    ) -> list[Episode]:
        """Analyse a chunk of samples; return the squeak episodes closed by it.

        Parameters
        ----------
        samples : array_like
            Samples in full-scale units (-1..1); several channels (2-D) are averaged.
        t0_s : float
            Time of the first sample [s].
        speed_rad_s : float or array_like, optional
            Shaft speed [rad/s]: a float is the speed over this chunk; an array goes with
            `speed_times_s` (samples of the speed, interpolated linearly at the frame times,
            held beyond the last one known).
        speed_times_s : array_like, optional
            Times [s] of the speed samples.
        sample_rate_hz : float, optional
            A new sample rate: the open tracks are closed (their episodes returned), the
            detector restarts at this rate, with a warning.

        Returns
        -------
        list of Episode
            Squeak episodes closed during this chunk.

        Raises
        ------
        AudioError
            For an invalid new sample rate.
        """
        closed: list[Episode] = []
        if sample_rate_hz is not None:
            rate = _check_rate(sample_rate_hz)
            if rate != self.sample_rate_hz:
                self._warn(
                    f"sample rate changed from {self.sample_rate_hz:g} to {rate:g} Hz: "
                    "detector restarted"
                )
                closed += self.flush()
                self._reset(rate)
        x = self._as_samples(samples)
        try:
            t0 = float(t0_s)
        except (TypeError, ValueError):
            t0 = math.nan
        if not math.isfinite(t0):
            self._warn(f"chunk time {t0_s!r} is not finite: chunk treated as contiguous")
            t0 = self._expected_t0()
        if x.size == 0:
            return closed
        if self._seg_t0 is None:
            self._seg_t0 = t0
        elif abs(t0 - self._expected_t0()) > max(
            self.settings.max_gap_s, 2.0 / self.sample_rate_hz
        ):
            self._warn(
                f"audio discontinuity of {t0 - self._expected_t0():+.3f} s at "
                f"{t0:.3f} s: tracks closed, framing restarted"
            )
            closed += self.flush()
            self._new_segment(t0)
        t_end = self._seg_t0 + (self._n_samples + x.size) / self.sample_rate_hz
        self._add_speed(speed_rad_s, speed_times_s, self._expected_t0(), t_end)
        # A long chunk (offline: the whole recording) goes through in pieces of a block of
        # frames each: no copy of it is made whatever its length
        piece = _BLOCK_FRAMES * self.hop
        pieces = range(0, x.size, piece)
        n_bad = sum(int(np.count_nonzero(~np.isfinite(x[a : a + piece]))) for a in pieces)
        if n_bad:
            self._warn(
                f"{n_bad} non-finite samples (NaN/inf) set to 0; the frames holding "
                "them are dropped (tracks bridge one frame length of them)"
            )
        step = format_step(x)
        if step is not None:
            self._format_step = step
        clip = self.settings.clip_level
        n_clip = sum(int(np.count_nonzero(np.abs(x[a : a + piece]) >= clip)) for a in pieces)
        if n_clip:
            self._warn(
                f"clipped: {n_clip} samples at or beyond {self.settings.clip_level:g} "
                "of full scale (harmonics of clipped tones are not counted as squeak)"
            )
        for a in pieces:
            y = x[a : a + piece]
            bad = ~np.isfinite(y)
            if n_bad:
                y = np.where(bad, np.float32(0.0), y)
            self._buf = np.concatenate([self._buf, y])
            self._bad = np.concatenate([self._bad, bad])
            self._n_samples += y.size
            closed += self._run_frames()
        return closed

    def learn_held(
        self, episodes: list[Episode], speed_times_s: Any, speed_rad_s: Any
    ) -> list[Episode]:
        """Live: `episodes` (just closed by `push`) less the tones that lasted exactly as long
        as the speed held (`_held_with_speed`, judged on the speed history given, which must
        reach back before their stretch); their ratios are learned, so the drive's tones that
        sound only at constant speed (a commutator quiet at low speed) are drive noise from
        the next hold on. Offline, `detect` judges them over the whole log instead.

        Parameters
        ----------
        episodes : list of Episode
            Episodes closed by the last `push`.
        speed_times_s, speed_rad_s : array_like
            The recent speed samples: times [s], shaft speed [rad/s].

        Returns
        -------
        list of Episode
            The episodes that are not drive noise.
        """
        profile = _speed_profile(speed_times_s, speed_rad_s)
        if not episodes or profile is None:
            return episodes
        return _held_with_speed(self, episodes, *profile)

    def flush(self) -> list[Episode]:
        """Close every open track (end of the stream).

        Returns
        -------
        list of Episode
            The squeak episodes among the tracks closed.
        """
        out: list[Episode] = []
        for tr in self._tracks:
            ep = self._finish(tr)
            if ep is not None:
                out.append(ep)
        self._tracks = []
        self._heard_now, self._frequency_now = False, math.nan
        return sorted(out, key=lambda e: e.start_s)

    def _expected_t0(self) -> float:
        if self._seg_t0 is None:
            return 0.0
        return self._seg_t0 + self._n_samples / self.sample_rate_hz

    def _as_samples(self, samples: Any) -> Samples:
        x = _mono(samples)
        if x is None:
            self._warn("samples are not numbers: chunk ignored")
            return np.zeros(0, np.float32)
        if np.ndim(samples) > 1:
            self._warn(f"{min(np.shape(samples))} channels averaged")
        return x

    def _add_speed(self, speed: Any, times: Any, t_start: float, t_end: float) -> None:
        if speed is None:
            return
        try:
            v = np.asarray(speed, dtype=float).reshape(-1)
            t = (
                np.array([t_start, t_end])
                if times is None and v.size == 1
                else np.asarray(times, dtype=float).reshape(-1)
            )
            if v.size == 1 and t.size == 2:
                v = np.repeat(v, 2)
        except (TypeError, ValueError):
            self._warn("speed is not numeric: ignored")
            return
        if t.size != v.size:
            self._warn(f"{v.size} speeds for {t.size} speed times: ignored")
            return
        ok = np.isfinite(t) & np.isfinite(v)
        if not ok.all():
            self._warn(f"{int((~ok).sum())} non-finite speed samples dropped")
        t, v = np.concatenate([self._speed_t, t[ok]]), np.concatenate([self._speed_v, v[ok]])
        if t.size > 1 and np.any(np.diff(t) < 0):
            order = np.argsort(t, kind="stable")
            t, v = t[order], v[order]
        self._speed_t, self._speed_v = t, v

    # -- frames ----------------------------------------------------------------------------------
    def _run_frames(self) -> list[Episode]:
        closed: list[Episode] = []
        n_avail = (
            (self._n_samples - self.frame_len) // self.hop + 1
            if self._n_samples >= self.frame_len
            else 0
        )
        while self._next_frame < n_avail:
            i0 = self._next_frame
            i1 = min(n_avail, i0 + _BLOCK_FRAMES)
            closed += self._block(i0, i1)
            self._next_frame = i1
        self._trim()
        self._update_now()
        return closed

    def _block(self, i0: int, i1: int) -> list[Episode]:
        n, hop = self.frame_len, self.hop
        s0 = i0 * hop - self._buf_start
        seg = self._buf[s0 : s0 + (i1 - i0 - 1) * hop + n]
        if self.analyzer.empty:
            return []
        psd, floor, dropped, silent = self._spectra(
            seg, self._bad[s0 : s0 + seg.size], hop, i1 - i0, self._format_step
        )
        gated = self.background.has_spectrum
        cand = self.analyzer.candidates(psd, floor=floor, reference=self._gate() if gated else None)
        self._note_usable(i0, dropped, silent)
        level_db = 10 * np.log10(np.maximum(cand.power, 1e-300)) + self._level_offset_db
        # the background learned so far is not followed (a louder tone at its frequency is)
        background = self.background.covers(cand.frequency_hz, level_db)
        if gated:  # the gate: a stated SNR over the background's band
            snr_db = 10 * np.log10(
                np.maximum(cand.power, 1e-300) / self.background.band_power(cand.frequency_hz)
            )
            over = cand.valid & (snr_db >= self.settings.background_snr_db)
            prominent = self.analyzer.without_harmonics(
                cand.frequency_hz, cand.power, over & ~dropped[:, None] & ~background
            )
        else:  # nothing learned yet: ECMA-418-1's prominence
            prominent = cand.prominent & ~dropped[:, None] & ~background
        frame_t = self.frame_time(np.arange(i0, i1))
        if self._speed_t.size:
            f1 = np.abs(np.interp(frame_t, self._speed_t, self._speed_v)) / (2 * np.pi)
        else:
            f1 = np.full(frame_t.shape, np.nan)
        rest = 2 * np.pi * f1 < self.settings.motor_off_rad_s  # False where the speed is unknown
        rest_run = max(int(round(self.settings.motor_off_min_s / self.hop_s)), 1)
        self._never_moved = self._never_moved and bool(rest.all())
        closed: list[Episode] = []
        learning: list[int] = []
        for j in range(i1 - i0):
            self._rest_frames = self._rest_frames + 1 if rest[j] and not dropped[j] else 0
            if self._rest_frames >= rest_run and not silent[j]:  # no sound is no background
                learning.append(j)
        if learning:
            # the background's tones are all ECMA-418-1's, not only those over the gate
            if gated:
                quiet = self.analyzer.candidates(psd[learning], floor=floor[learning])
                _learn_tones(self.background, quiet, range(len(learning)))
            else:
                _learn_tones(self.background, cand, learning)
        # per frame, its prominent candidates strongest first (ties: by column), as Python
        # floats: the tracks are followed frame by frame
        n_found = np.count_nonzero(prominent, axis=1)
        order = np.argsort(np.where(prominent, -cand.power, np.inf), axis=1, kind="stable")
        order = order[:, : int(n_found.max(initial=0))]
        fields = np.stack([cand.frequency_hz, cand.tnr_db, cand.pr_db, cand.power], axis=-1)
        ranked = np.take_along_axis(fields, order[..., None], axis=1).tolist()
        counts = n_found.tolist()
        speeds = f1.tolist()
        for j in range(i1 - i0):
            if dropped[j]:
                self._dropped_run += 1
                if self._dropped_run <= self._max_dropped:  # a glitch: the tracks hold
                    for tr in self._tracks:
                        tr.last = i0 + j
                    continue
            else:
                self._dropped_run = 0
            if not counts[j] and not self._tracks:
                continue
            closed += self._step(i0 + j, ranked[j][: counts[j]], speeds[j])
        if learning:
            self.background.add_spectrum(psd[learning, : self.analyzer.used_bins])
        return closed

    def _spectra(
        self, seg: np.ndarray, bad: np.ndarray, hop: int, frames: int, step: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(psd, tone floor [unit^2], dropped, silent) of the `frames` frames `hop` apart of
        `seg` (`bad`: its non-finite samples, set to 0; `step`: the format's quantisation
        step): a frame holding a bad sample is dropped, one whose varying part is within
        `SILENT_FACTOR` of its rounding noise is silent."""
        n = self.frame_len
        variance, mean_square = frame_powers(seg, n, hop, frames)
        rounding = np.maximum(step, FLOAT32_STEP * np.sqrt(mean_square)) ** 2 / 12
        psd = short_time_psd(
            seg, self.sample_rate_hz, n, hop, self._window, self.analyzer.used_bins
        )
        if bad.any():
            bad_cum = np.concatenate([[0], np.cumsum(bad)])
            starts = np.arange(frames) * hop
            dropped = bad_cum[starts + n] - bad_cum[starts] > 0
        else:
            dropped = np.zeros(frames, bool)
        silent = ~dropped & (variance <= SILENT_FACTOR * rounding)
        return psd, TONE_FLOOR_FACTOR * rounding, dropped, silent

    def _gate(self) -> np.ndarray:
        """Per analysed bin, the power a peak's three bins must reach to be a candidate: the
        gate (`background_snr_db` over the background's band) less `_GATE_MARGIN_DB`."""
        an = self.analyzer
        bins_hz = np.arange(an.k_lo, an.k_hi + 1) * an.df
        snr_db = self.settings.background_snr_db - _GATE_MARGIN_DB
        return self.background.band_power(bins_hz) * 10 ** (snr_db / 10)

    def _note_usable(self, i0: int, dropped: np.ndarray, silent: np.ndarray) -> None:
        """Count the frames without usable sound; say once when the signal is constant."""
        n_silent = int(np.count_nonzero(silent))
        if n_silent and not self.unusable_frames["silent"]:
            t = float(self.frame_time(i0 + int(np.argmax(silent))))
            self._warn(
                f"no usable sound from {t:.3f} s: the signal is constant or digitally silent "
                "(a muted or disconnected microphone?); such frames are not scored"
            )
        self.unusable_frames["silent"] += n_silent
        if dropped.size:
            self._usable_now = not (dropped[-1] or silent[-1])
        self.unusable_frames["non-finite"] += int(np.count_nonzero(dropped))
        if self.usable_log is not None:
            self.usable_log += (~(dropped | silent)).astype(np.uint8).tobytes()

    def _step(self, i: int, found: list[list[float]], f1: float) -> list[Episode]:
        """Frame `i`: close the tracks it ends, then each tone found ([frequency, TNR, PR,
        power], strongest first) joins the nearest open track or opens one."""
        closed = []
        keep = []
        for tr in self._tracks:
            if (
                i - tr.last - 1 > self._allowed_missing
                or tr.last - tr.first + 1 >= self._max_frames
            ):
                ep = self._finish(tr)
                if ep is not None:
                    closed.append(ep)
            else:
                keep.append(tr)
        self._tracks = keep
        tol = self.settings.track_tolerance
        for f, tnr, pr, power in found:
            best, best_d = None, tol
            for tr in self._tracks:
                if tr.last == i:
                    continue
                d = tr.distance(f, f1)
                if d <= best_d:
                    best, best_d = tr, d
            if best is None:
                if len(self._tracks) >= self.settings.max_tracks:
                    continue
                self._tracks.append(_Track(i, f, f1, tnr, pr, power, self._median_window))
            else:
                best.add(i, f, f1, tnr, pr, power)
        return closed

    def _follows_drive(self, tr: _Track) -> float | None:
        """The speed ratio r of the drive noise the track is (rejected), else None; see the
        module notes."""
        s = self.settings
        if s.order_tolerance <= 0:
            return None
        f = np.asarray(tr.hz)
        f1 = np.asarray(tr.f1)
        ok = np.isfinite(f1) & (f1 > 0)
        if ok.sum() * 2 < f.size:
            return None
        f, f1 = f[ok], f1[ok]
        r = float(np.median(f / f1))
        if not s.min_drive_ratio <= r <= s.max_drive_ratio:
            return None
        share = float(np.mean(np.abs(f / (r * f1) - 1.0) <= s.order_tolerance))
        if share < s.order_share:
            return None
        r_ratio, r_const, floor = _scatter(f, f1, r, self.analyzer.df)
        if r_const >= max(3 * r_ratio, floor):  # the tone moved with the speed
            self._learn_ratio(r, tr.level_sum / len(tr.hz) + self._level_offset_db)
            return r
        moved = float(np.max(f1) / np.min(f1)) - 1.0 > s.order_tolerance  # not just its noise
        if moved and r_ratio >= max(3 * r_const, floor):  # it stayed while the speed moved
            return None
        # the speed hardly changed: the drive's ratios known or learned, else a low whole order
        if self._known_ratio(r):
            return r
        k = round(r)
        whole = k >= 1 and abs(r / k - 1.0) <= s.order_tolerance
        return r if whole and k <= 0.25 / s.order_tolerance else None

    def _learn_ratio(self, r: float, level: float) -> None:
        """Count a ratio the drive was heard at (moving with the speed, or held exactly as
        long as the speed), with its track's level [dB]."""
        g = self._ratio_groups
        if g.size:
            centre = g[:, 0] / g[:, 1]
            k = int(np.argmin(np.abs(centre / r - 1.0)))
            if abs(centre[k] / r - 1.0) <= self.settings.order_tolerance:
                g[k] += (r, 1.0, level)
                return
        if g.shape[0] < _MAX_RATIOS:
            self._ratio_groups = np.vstack([g, [r, 1.0, level]])

    def _known_ratio(self, r: float) -> bool:
        """`r` is one of the drive's ratios: given (`drive_ratios`) or learned."""
        tol = self.settings.order_tolerance
        g = self._ratio_groups
        known = list(self.settings.known_ratios) + list(g[:, 0] / g[:, 1] if g.size else [])
        return any(abs(r / k - 1.0) <= tol for k in known)

    @property
    def drive_orders(self) -> list[DriveOrder]:
        """The ratios the drive was heard at (tracks that moved with the speed), by ratio.

        Returns
        -------
        list of DriveOrder
        """
        return sorted(
            (DriveOrder(float(a / n), float(lv / n), int(n)) for a, n, lv in self._ratio_groups),
            key=lambda d: d.ratio,
        )

    def _finish(self, tr: _Track) -> Episode | None:
        if tr.last - tr.first + 1 < self._min_frames:
            return None
        half = self.hop_s / 2
        start = float(self.frame_time(tr.first)) - half
        end = float(self.frame_time(tr.last)) + half
        frames = np.arange(tr.first, tr.last + 1)
        hz = np.full(frames.size, np.nan)
        hz[np.asarray(tr.frames) - tr.first] = tr.hz
        if self.scale_pa is not None:
            level = 10 * math.log10(max(tr.power, 1e-300) * self.scale_pa**2 / P_REF_PA**2)
        else:
            level = 10 * math.log10(max(tr.power, 1e-300))
        ep = Episode(
            start_s=start,
            end_s=end,
            frequency_hz=float(np.median(tr.hz)),
            tnr_db=tr.tnr,
            pr_db=tr.pr if tr.pr > -math.inf else math.nan,
            level_db=level,
            track_times_s=self.frame_time(frames),
            track_hz=hz,
        )
        r = self._follows_drive(tr)
        if r is not None:
            ep.drive_ratio = r
            k = round(r)
            ep.order = k if k >= 1 and abs(r / k - 1.0) <= self.settings.order_tolerance else None
            self.rejected.append(ep)
            return None
        tone = self._background_tone(tr)
        if tone is not None:
            ep.background_hz = tone.frequency_hz
            self.rejected.append(ep)
            return None
        ep.loudness_sone = self._loudness(start, end)
        return ep

    def _background_tone(self, tr: _Track) -> BackgroundTone | None:
        """The background tone the track is (`background.BackgroundLearner.match`), or None."""
        level = tr.level_sum / len(tr.hz) + self._level_offset_db
        return self.background.match(float(np.median(tr.hz)), level)

    def _loudness(self, start: float, end: float) -> float | None:
        s = self.settings
        if self.scale_pa is None or s.loudness_max_s <= 0 or self._seg_t0 is None:
            return None
        rate = self.sample_rate_hz
        a = int(round((max(start, end - s.loudness_max_s) - s.frame_s - self._seg_t0) * rate))
        b = int(round((end - self._seg_t0) * rate))
        a, b = max(a, self._buf_start), min(b, self._buf_start + self._buf.size)
        if b - a < int(0.05 * rate):
            return None
        x = self._buf[a - self._buf_start : b - self._buf_start].astype(float) * self.scale_pa
        try:
            from mosqito.sq_metrics import loudness_zwtv
        except ImportError:
            if not self._loudness_missing:
                self._warn("mosqito is not importable: no loudness")
                self._loudness_missing = True
            return None
        if rate != LOUDNESS_RATE_HZ:
            from fractions import Fraction

            from scipy.signal import resample_poly

            r = Fraction(LOUDNESS_RATE_HZ / rate).limit_denominator(1000)
            x = resample_poly(x, r.numerator, r.denominator)
        try:
            n = loudness_zwtv(x, LOUDNESS_RATE_HZ, field_type="free")[0]
        except Exception as exc:  # MOSQITO's failure must not stop us
            self._warn(f"loudness failed: {exc}")
            return None
        return float(np.max(n)) if np.size(n) else None

    def _trim(self) -> None:
        keep_from = max(self._next_frame * self.hop - self._keep, self._buf_start)
        cut = keep_from - self._buf_start
        if cut > 0:
            self._buf = self._buf[cut:]
            self._bad = self._bad[cut:]
            self._buf_start = keep_from
        if self._speed_t.size > 2:
            t_next = float(self.frame_time(self._next_frame)) - self.settings.frame_s
            j = int(np.searchsorted(self._speed_t, t_next)) - 1
            if j > 0:
                self._speed_t, self._speed_v = self._speed_t[j:], self._speed_v[j:]

    def _update_now(self) -> None:
        latest = self._next_frame - 1
        best: _Track | None = None
        for tr in self._tracks:
            if (
                tr.last - tr.first + 1 < self._min_frames
                or latest - tr.last > self._allowed_missing
                or (best is not None and tr.last_power <= best.last_power)
            ):
                continue
            n = len(tr.hz)  # re-decided as the track grows by 1/8
            if n >= tr.checked_at + max(5, tr.checked_at // 8):
                tr.order_now, tr.checked_at = self._follows_drive(tr), n
                if tr.order_now is None and self._background_tone(tr) is not None:
                    tr.order_now = 0  # background: not heard as squeak either
            if tr.order_now is None:
                best = tr
        if self._never_moved:
            best = None
        self._heard_now = best is not None
        self._frequency_now = best.median if best is not None else math.nan


def detect(
    samples: Any,
    sample_rate_hz: float,
    *,
    t0_s: float = 0.0,
    speed_times_s: Any = None,
    speed_rad_s: Any = None,
    scale_pa: float | None = None,
    settings: DetectorSettings = DetectorSettings(),
    background: Any = None,
    background_rate_hz: float | None = None,
    infer_background: bool = False,
    condition_times_s: Any = None,
    condition: Any = None,
) -> Detection:
    """Squeak episodes in a recording (offline; the same decisions as `StreamingDetector`).

    Parameters
    ----------
    samples : array_like
        Samples in full-scale units (-1..1); several channels (2-D) are averaged.
    sample_rate_hz : float
        Sample rate [Hz], in [1000, 1e6].
    t0_s : float
        Time of the first sample [s].
    speed_times_s : array_like, optional
        Times [s] of the speed samples.
    speed_rad_s : float or array_like, optional
        The shaft speed [rad/s] at `speed_times_s` (interpolated linearly at the frame times);
        without it no tone is rejected as a motor order. A float alone is a constant speed.
    scale_pa : float, optional
        Pascal per full-scale unit: levels in dB SPL and loudness computed.
    settings : DetectorSettings
        Detector settings.
    background : array_like, optional
        A background recording (the drive off; same microphone and scale): learned as
        background first, as the motor-off stretches are.
    background_rate_hz : float, optional
        Its sample rate [Hz] (default `sample_rate_hz`; another one is resampled).
    infer_background : bool
        Without a background recording or motor-off time, infer the background from the
        whole recording (module notes): what the offline listening of a log or a recording
        does; a bare call hears every steady tone, as the node does.
    condition_times_s, condition : array_like, optional
        Times [s] and flags of a condition held until the next time (the prediction: squeak
        or not): a background inferred without motor-off time must be held on each side of it.

    Returns
    -------
    Detection
        Bad input (NaN/inf samples, no samples, fewer than one frame, clipping) gives warnings,
        never an exception.

    Raises
    ------
    AudioError
        For an invalid sample rate (or `scale_pa`).
    """
    det = StreamingDetector(settings, sample_rate_hz, scale_pa)
    det.usable_log = bytearray()
    if speed_rad_s is not None and speed_times_s is None and np.ndim(speed_rad_s) > 0:
        det._warn("speed_rad_s without speed_times_s: ignored")
        speed_rad_s = None
    source = "none"
    if background is not None and _learn_recording(det, background, background_rate_hz):
        source = "file"
    if speed_times_s is not None and speed_rad_s is not None:
        frames = det.background.frames
        _learn_at_rest(det, samples, t0_s, speed_times_s, speed_rad_s)
        if source == "none" and det.background.frames > frames:
            source = "motor-off"
    if (
        infer_background
        and source == "none"
        and _infer_background(det, samples, t0_s, condition_times_s, condition)
    ):
        source = "inferred"
    episodes = det.push(samples, t0_s, speed_rad_s, speed_times_s)
    n_samples = det._n_samples
    episodes += det.flush()
    mono = _mono(samples)
    if speed_times_s is not None and speed_rad_s is not None:
        episodes = _split_drive_ends(det, episodes, speed_times_s, speed_rad_s)
        episodes = _at_drive_ratios(det, episodes, speed_times_s, speed_rad_s)
        if mono is not None:
            episodes = _went_with_speed(det, episodes, speed_times_s, speed_rad_s, mono, t0_s)
    episodes = _inside_rejected(det, episodes)
    episodes = with_harmonics(episodes, settings.max_harmonic, settings.track_tolerance)
    creaks = (
        find_creaks(mono, det.sample_rate_hz, t0_s=t0_s, scale_pa=scale_pa, settings=settings)
        if mono is not None
        else []
    )
    episodes, creaks = sort_creaks(episodes, [*episodes, *det.rejected], creaks, settings.frame_s)
    if mono is not None:
        _measure_growth(episodes, [*episodes, *det.rejected], mono, det.sample_rate_hz, t0_s)
        episodes = without_splatter(det, episodes, [*episodes, *det.rejected], mono, t0_s)
        nothing_moves = speed_rad_s is None and condition_times_s is None
        if infer_background and source in ("none", "inferred") and nothing_moves:
            episodes = _switched_on(det, episodes, n_samples / det.sample_rate_hz)
            source = "inferred" if det.background.tones() else source
        _onsets_back(
            det, episodes, [*episodes, *det.rejected], mono, t0_s, speed_times_s, speed_rad_s
        )
    warnings = list(det.warnings)
    if n_samples == 0:
        warnings.append("no audio samples")
    elif det.frames_done == 0:
        warnings.append(
            f"{n_samples} samples are shorter than one frame "
            f"({det.frame_len} samples): nothing analysed"
        )
    times = det.frame_time(np.arange(det.frames_done)).astype(float)
    heard, freq = frames_heard(times, episodes)
    usable = np.frombuffer(bytes(det.usable_log), dtype=np.uint8).astype(bool)
    if usable.size and not usable.all():
        hop_s, counts = det.hop_s, det.unusable_frames
        warnings.append(
            f"sound unusable for {np.count_nonzero(~usable) * hop_s:.2f} of "
            f"{usable.size * hop_s:.2f} s (non-finite samples "
            f"{counts['non-finite'] * hop_s:.2f} s, constant or silent "
            f"{counts['silent'] * hop_s:.2f} s): not scored"
        )
    return Detection(
        frame_times_s=times,
        heard=heard,
        frequency_hz=freq,
        episodes=sorted(episodes, key=lambda e: e.start_s),
        sample_rate_hz=det.sample_rate_hz,
        scale="Pa" if scale_pa is not None else "full scale",
        warnings=warnings,
        rejected=list(det.rejected),
        usable=usable,
        background=det.background.tones(),
        drive_orders=det.drive_orders,
        creaks=creaks,
        background_source=source,
    )


def _switched_on(
    det: StreamingDetector, episodes: list[Episode], duration_s: float
) -> list[Episode]:
    """With nothing moving (no speed, no condition): the episodes whose sound came in at once
    (a step, `Growth.step`: switched on, not grown from the floor) are background tones; the
    rest are returned."""
    step = [e for e in episodes if e.growth is not None and e.growth.step]
    det.background.include(
        [
            BackgroundTone(e.frequency_hz, e.level_db, (e.end_s - e.start_s) / duration_s)
            for e in step
        ]
    )
    return [e for e in episodes if e not in step]


def _measure_growth(
    episodes: list[Episode], tones: list[Episode], samples: Samples, rate_hz: float, t0_s: float
) -> None:
    """Each episode's growth rate at its onset (`Episode.growth`), its quiet stretch after
    the last tone near its frequency (within `GROWTH_NEIGHBOUR`) that ended before it."""
    for e in episodes:
        quiet_from = max(
            (
                o.end_s
                for o in tones
                if o is not e
                and o.end_s <= e.start_s
                and abs(o.frequency_hz / e.frequency_hz - 1) <= GROWTH_NEIGHBOUR
            ),
            default=-math.inf,
        )
        e.growth = onset_growth(
            samples, rate_hz, t0_s, e.start_s, e.track_times_s, e.track_hz, quiet_from
        )


def without_splatter(
    det: StreamingDetector, episodes: list[Episode], tones: list[Episode], x: Samples, t0: float
) -> list[Episode]:
    """The episodes less a louder tone's splatter (offline: it needs the sound after a cut).

    A tone switched off or jumping to another frequency (a step, or a glide through the
    spectrum within a few ms), or switched on at once, is cut within a frame: the frames whose
    window holds the cut see its power spread over the spectrum (a step's falls only as 1 / d
    at d bins from it), so a loud tone's cut is heard at other frequencies for at most a
    frame. An episode lying within a frame (and a hop) of a cut of a louder tone heard for
    longer than that (`tones`: episodes and rejected tracks; a shorter one may be a cut's
    piece itself) is that cut, not a squeak of its own. A cut is the end of a tone whose level
    at its frequency changed by `CUT_DB` or more from the frame before it to the frame after
    it (a tone that sounds on where a track stopped following it was not cut), or the start
    of an episode whose onset was a step (`Growth.step`; a squeak grows from the floor, and a
    short tone beside its onset is its own). A cut squeak's episode takes the piece's span
    (its frames were heard), another tone's cut piece is dropped.

    Parameters
    ----------
    det : StreamingDetector
        The detector that heard them (frame, hop, window).
    episodes : list of Episode
        Squeak episodes.
    tones : list of Episode
        Every tone tracked (the squeak episodes and the rejected ones).
    x : Samples
        The recording, its first sample at `t0` [s].
    t0 : float
        [s].

    Returns
    -------
    list of Episode
        The episodes that are not splatter, in their order.
    """
    frame_s, hop_s = det.frame_len / det.sample_rate_hz, det.hop_s
    reach = frame_s + hop_s

    def ends(o: Episode) -> list[tuple[float, float, float, float]]:
        """(time of the cut, frequency, centre of the frame before it, of the frame after)."""
        hz = o.track_hz[np.isfinite(o.track_hz)] if o.track_hz.size else np.zeros(0)
        first, last = (hz[0], hz[-1]) if hz.size else (o.frequency_hz, o.frequency_hz)
        # a loud tone is heard from the first frame holding its switch-on to the last
        # holding its switch-off: the cut lies half a frame inside its episode
        out = [(o.end_s, float(last), o.end_s - frame_s, o.end_s + frame_s / 2)]
        if o.growth is not None and o.growth.step:  # switched on; a growing one is not cut
            out.append((o.start_s, float(first), o.start_s - frame_s / 2, o.start_s + frame_s))
        return out

    sources = [(o, ends(o)) for o in tones if o.duration_s > reach]
    cuts: dict[tuple[int, int], bool] = {}

    def cut(o: Episode, k: int, hz: float, before: float, after: float) -> bool:
        if (id(o), k) not in cuts:
            p = _tone_powers(det, x, t0, hz, np.array([before, after]), (-2, -1, 0, 1, 2))
            p = p.max(axis=1)  # the strongest of its bin and two each side
            change_db = 10 * np.log10(np.maximum(p[1], 1e-300) / np.maximum(p[0], 1e-300))
            cuts[id(o), k] = bool(np.isfinite(p).all() and abs(change_db) >= CUT_DB)
        return cuts[id(o), k]

    def cut_by(e: Episode) -> Episode | None:
        for o, marks in sources:
            for k, (at, hz, before, after) in enumerate(marks):
                if o is e or not (at - reach <= e.start_s and e.end_s <= at + reach):
                    continue
                if e.level_db < o.level_db and cut(o, k, hz, before, after):
                    return o
        return None

    kept = []
    for e in episodes:
        o = cut_by(e)
        if o is None:
            kept.append(e)
        elif any(o is k for k in episodes):  # its frames are the cut squeak's
            o.start_s, o.end_s = min(o.start_s, e.start_s), max(o.end_s, e.end_s)
    return kept


def _onsets_back(
    det: StreamingDetector,
    episodes: list[Episode],
    tones: list[Episode],
    x: Samples,
    t0: float,
    speed_times_s: Any,
    speed_rad_s: Any,
) -> None:
    """Move each episode's start back to where its tone first stood the gate (offline).

    The tracker takes a tone once a frame's peak is a valid candidate through the gate
    (`background_snr_db` over the background's band): a louder tone in its critical band
    (mains hum 2.5 bins away), a drive order sweeping a few bins from it, or a frequency
    estimate pulled across the band's edge by them keep a growing squeak out of the tracks for
    frames after it stood the gate. So, frame by frame before an episode's start (the
    detector's frames, centres a hop apart), the tone at the frequency its track began at (the
    median of its first five frames: a squeak is a mode's tone, it does not move as it grows)
    is measured alone, in the detector's frame and window (`_tone_powers`); the start moves
    to the earliest frame of the run where it stands `background_snr_db` over the
    background's band there and over the background tones' window leakage at its frequency
    (`tonality.hann_leakage` of their mean levels: a steady tone a few bins away).
    A frame with another sound within the window's main lobe of that frequency (two bins) over
    the window's main weight (its centre +- a quarter frame: a sweep moves) -- a drive ratio
    times the screw's rotation frequency, or a frame of another tone's track -- cannot tell the
    tone from it: it is bridged, and the start is never placed there. The walk stops at the
    end of another tone at the same frequency (within `track_tolerance`: that one's own sound),
    at a frame without usable sound, and where the episode would outlast `max_episode_s`. No
    episode is added or removed, its track is not extended; before a background is learned
    (no band to stand over) nothing moves."""
    s = det.settings
    if not det.background.has_spectrum or not episodes:
        return
    hop, lobe = det.hop_s, 2.0 * det.analyzer.df
    half = det.frame_len / det.sample_rate_hz / 2
    ratios = np.array([o.ratio for o in det.drive_orders] + list(s.known_ratios))
    st, sv = _speed_profile(speed_times_s, speed_rad_s) or (np.zeros(0), np.zeros(0))
    background = det.background.tones()
    tone_hz = np.array([b.frequency_hz for b in background])
    tone_power = 10 ** ((np.array([b.level_db for b in background]) - det._level_offset_db) / 10)
    others = []  # (episode, its frames' times, frequencies)
    for o in tones:
        ok = np.isfinite(o.track_hz)
        if ok.any():
            others.append((o, o.track_times_s[ok], o.track_hz[ok]))
    for e in episodes:
        ok = np.isfinite(e.track_hz)
        if not ok.any():
            continue
        f0 = float(np.median(e.track_hz[ok][:5]))
        # over the band, and over the background tones' window leakage at f0
        band = float(det.background.band_power(np.array([f0]))[0])
        leak = float(np.sum(tone_power * hann_leakage((f0 - tone_hz) / det.analyzer.df)))
        need = max(band, leak) * 10 ** (s.background_snr_db / 10)
        floor = max(
            t0 + half - hop / 2,
            e.end_s - s.max_episode_s,
            *(
                o.end_s
                for o, _, _ in others
                if o is not e
                and o.end_s <= e.start_s
                and abs(o.frequency_hz / f0 - 1) <= s.track_tolerance
            ),
        )
        centres = np.arange(e.start_s - hop / 2, floor + hop / 2 - 1e-9, -hop)
        if centres.size == 0:
            continue
        # a sound sweeping past is seen over the window's main weight (+- a quarter frame)
        busy = np.zeros(centres.size, bool)
        if ratios.size and st.size:
            f1 = np.interp(centres[:, None] + [-half / 2, 0.0, half / 2], st, sv) / (2 * np.pi)
            line = ratios[None, :, None] * f1[:, None, :]  # (frames, ratios, 3)
            busy |= np.any((line.min(axis=2) - lobe < f0) & (f0 < line.max(axis=2) + lobe), axis=1)
        for o, ot, of in others:
            near = ot[np.abs(of - f0) < lobe] if o is not e else np.zeros(0)
            if near.size:  # a frame of its track near f0 within that
                busy |= np.searchsorted(near, centres + half / 2, side="right") > np.searchsorted(
                    near, centres - half / 2, side="left"
                )
        start = e.start_s
        for a in range(0, centres.size, _WALK_FRAMES):
            block = centres[a : a + _WALK_FRAMES]
            power = _tone_powers(det, x, t0, f0, block)[:, 0]
            stop = False
            for c, p, b in zip(
                block.tolist(), power.tolist(), busy[a : a + _WALK_FRAMES], strict=True
            ):
                if b:
                    continue
                if not p >= need:  # under the gate, or no usable sound (nan)
                    stop = True
                    break
                start = c - hop / 2
            if stop:
                break
        if start < e.start_s:
            e.tracked_start_s, e.start_s = e.start_s, start


def _tone_basis(n: int, rate_hz: float, hz: np.ndarray) -> np.ndarray:
    """(n, len(hz)) complex64 columns: the Hann window of `n` samples at `rate_hz` times the
    conjugate phasor of each frequency [Hz]; a frame times a column is that frequency's DFT
    value."""
    k = np.arange(n) / rate_hz
    return hann(n)[:, None] * phasor(np.asarray(hz)[None, :] * k[:, None])


def _tone_powers(
    det: StreamingDetector,
    x: Samples,
    t0: float,
    hz: float,
    centres_s: np.ndarray,
    offsets_bins: tuple[int, ...] = (0,),
) -> np.ndarray:
    """Per frame of the detector's length and window centred at `centres_s` [s] (rows), the
    mean square [unit^2] of the tone at `hz` [Hz] plus each offset in bins (columns): a sine's
    own mean square at its frequency; nan where a frame leaves the recording or holds
    non-finite samples."""
    n, rate = det.frame_len, det.sample_rate_hz
    basis = _tone_basis(n, rate, hz + det.analyzer.df * np.asarray(offsets_bins, dtype=float))
    scale = 2.0 / float(np.sum(hann(n), dtype=np.float64)) ** 2  # a sine of amplitude a: a^2/2
    out = np.full((np.size(centres_s), basis.shape[1]), np.nan)
    for j, c in enumerate(np.asarray(centres_s, dtype=float).reshape(-1).tolist()):
        a = int(round((c - t0) * rate)) - n // 2
        if a < 0 or a + n > x.size:
            continue
        frame = np.asarray(x[a : a + n], dtype=np.float32)
        if np.all(np.isfinite(frame)):
            out[j] = scale * np.abs(frame @ basis) ** 2
    return out


def with_harmonics(episodes: list[Episode], max_harmonic: int, tolerance: float) -> list[Episode]:
    """The episodes with each one heard at m = 2..`max_harmonic` (at most 5) times another's
    frequency (within `tolerance`), overlapping it for at least half its own duration, merged
    into that one as a harmonic (`harmonics_hz`; its span joined): a squeak's overtones, also
    where they were louder than the fundamental in a frame, are the squeak, not squeaks of
    their own.

    Parameters
    ----------
    episodes : list of Episode
        Squeak episodes.
    max_harmonic : int
        Highest harmonic number merged (capped at 5).
    tolerance : float
        Relative frequency tolerance.

    Returns
    -------
    list of Episode
        By start time.
    """
    top = min(max_harmonic, 5)
    out = sorted(episodes, key=lambda e: e.frequency_hz)
    merged: set[int] = set()
    for i, e in enumerate(out):  # ascending: a fundamental before its harmonics
        if i in merged:
            continue
        for j in range(i + 1, len(out)):
            h = out[j]
            if j in merged:
                continue
            ratio = h.frequency_hz / e.frequency_hz
            m = round(ratio)
            overlap = min(e.end_s, h.end_s) - max(e.start_s, h.start_s)
            if 2 <= m <= top and abs(ratio / m - 1) <= tolerance and overlap >= 0.5 * h.duration_s:
                e.harmonics_hz.append(h.frequency_hz)
                e.start_s, e.end_s = min(e.start_s, h.start_s), max(e.end_s, h.end_s)
                merged.add(j)
    return sorted((e for k, e in enumerate(out) if k not in merged), key=lambda e: e.start_s)


def _speed_profile(speed_times_s: Any, speed_rad_s: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(times [s], |speed| [rad/s]) as flat float arrays of one size, or None where they are
    not numbers or differ in size (the passes that need the speed then leave the episodes
    as they are; the main pass says what is wrong)."""
    try:
        t = np.asarray(speed_times_s, dtype=float).reshape(-1)
        v = np.abs(np.asarray(speed_rad_s, dtype=float).reshape(-1))
    except (TypeError, ValueError):
        return None
    return (t, v) if t.size == v.size else None


def _at_drive_ratios(
    det: StreamingDetector, episodes: list[Episode], speed_times_s: Any, speed_rad_s: Any
) -> list[Episode]:
    """The episodes less those at one of the drive's ratios over the whole log (learned by
    then, or given): a tone held at constant speed, or a piece of a sweep too short to be
    judged, that closed before the ratio was heard moving (the order spectrum of the log's
    tracks, used after the fact), or heard held exactly as long as the speed held
    (`_held_with_speed`, judged first: a piece of its sweep into the hold is then known)."""
    s = det.settings
    profile = _speed_profile(speed_times_s, speed_rad_s)
    if s.order_tolerance <= 0 or profile is None or profile[0].size == 0:
        return episodes
    t, v = profile
    episodes = _held_with_speed(det, episodes, t, v)
    return _recurring_ratios(det, _at_known_ratios(det, episodes, t, v), t, v)


def _at_known_ratios(
    det: StreamingDetector, episodes: list[Episode], t: np.ndarray, v: np.ndarray
) -> list[Episode]:
    """The episodes less those at one of the drive's ratios learned so far or given
    (`order_share` of their frames within `order_tolerance` of it) at the speed (`t`, `v`)."""
    s = det.settings
    ratios = [o.ratio for o in det.drive_orders] + list(s.known_ratios)
    if not ratios:
        return episodes
    kept = []
    for ep in episodes:
        f1 = np.interp(ep.track_times_s, t, v) / (2 * np.pi)
        ok = np.isfinite(ep.track_hz) & (f1 > 0)
        share = (
            [
                float(np.mean(np.abs(ep.track_hz[ok] / (r * f1[ok]) - 1.0) <= s.order_tolerance))
                for r in ratios
            ]
            if ok.sum() * 2 >= ep.track_hz.size and ok.any()
            else [0.0]
        )
        best = int(np.argmax(share))
        if share[best] >= s.order_share:
            ep.drive_ratio = ratios[best]
            det.rejected.append(ep)
        else:
            kept.append(ep)
    return kept


def _split_drive_ends(
    det: StreamingDetector, episodes: list[Episode], speed_times_s: Any, speed_rad_s: Any
) -> list[Episode]:
    """The episodes with a drive tone's sweep split off their start or end.

    A track that followed r |speed| / 2 pi at one ratio r (within twice `order_tolerance`, at
    least `min_duration_s` of frames, its frequencies moving with the speed: r_const >= 3
    r_ratio, module notes) and then went on at frequencies off that path (beyond twice
    `order_tolerance` in `order_share` of its frames), or came from there onto it, is two
    sounds met where the drive's tone swept through the other's frequency (the tracker
    follows the nearest). The drive's part is rejected as drive noise (`drive_ratio` r), the
    rest is an episode of its own from the frame it left the path."""
    tol = det.settings.order_tolerance
    profile = _speed_profile(speed_times_s, speed_rad_s)
    if tol <= 0 or profile is None or profile[0].size < 2:
        return episodes
    t, v = profile
    need = max(det._min_frames, 3)
    out = []
    for ep in episodes:
        ok = np.flatnonzero(np.isfinite(ep.track_hz))
        f1 = np.interp(ep.track_times_s[ok], t, v) / (2 * np.pi)
        if ok.size < 2 * need or np.any(f1 <= 0):
            out.append(ep)
            continue
        hz = ep.track_hz[ok]
        split = None
        for forward in (True, False):  # a sweep at its start, at its end
            f, speed = (hz, f1) if forward else (hz[::-1], f1[::-1])
            r = f / speed
            lo, hi = np.minimum.accumulate(r), np.maximum.accumulate(r)
            m = int(np.argmin(hi <= lo * (1 + 2 * tol)))  # the first frame off one ratio
            if m < need or m > r.size - need:
                continue
            rm = float(np.median(r[:m]))
            r_ratio, r_const, floor = _scatter(f[:m], speed[:m], rm, det.analyzer.df)
            left = np.mean(np.abs(r[m:] / rm - 1) > 2 * tol) >= det.settings.order_share
            if left and r_const >= max(3 * r_ratio, floor):  # it moved with the speed, then not
                split = (m, rm) if forward else (r.size - m, -rm)
                break
        if split is None:
            out.append(ep)
            continue
        m, rm = split
        cut = det.hop_s / 2
        i = ok[m]  # the first frame of the second part
        head = replace(
            ep,
            end_s=float(ep.track_times_s[i - 1] + cut),
            track_times_s=ep.track_times_s[:i],
            track_hz=ep.track_hz[:i],
            frequency_hz=float(np.nanmedian(ep.track_hz[:i])),
        )
        tail = replace(
            ep,
            start_s=float(ep.track_times_s[i] - cut),
            track_times_s=ep.track_times_s[i:],
            track_hz=ep.track_hz[i:],
            frequency_hz=float(np.nanmedian(ep.track_hz[i:])),
        )
        drive, other = (head, tail) if rm > 0 else (tail, head)
        drive.drive_ratio = abs(rm)
        det.rejected.append(drive)
        out.append(other)
    return out


def _inside_rejected(det: StreamingDetector, episodes: list[Episode]) -> list[Episode]:
    """The episodes less the second tracks of a rejected tone: an episode whose span lies
    within a rejected track's (drive noise or background) and whose frequency stays within
    `track_tolerance` of that track's over it is the same tone, its peak split in two for a
    few frames (a neighbouring tone's leakage, beating), not a squeak; it is rejected as that
    tone was."""
    tol = det.settings.track_tolerance
    tones = []
    for r in det.rejected:
        ok = np.isfinite(r.track_hz)
        if np.count_nonzero(ok) >= 2:
            tones.append((r, r.track_times_s[ok], r.track_hz[ok]))
    kept = []
    for e in episodes:
        ok = np.isfinite(e.track_hz)
        same = None
        for r, rt, rf in tones if ok.any() else []:
            if not r.start_s <= e.start_s <= e.end_s <= r.end_s:
                continue
            along = np.interp(e.track_times_s[ok], rt, rf)
            if np.all(np.abs(e.track_hz[ok] / along - 1.0) <= tol):
                same = r
                break
        if same is None:
            kept.append(e)
        else:
            e.drive_ratio, e.order, e.background_hz = (
                same.drive_ratio,
                same.order,
                same.background_hz,
            )
            det.rejected.append(e)
    return kept


def _went_with_speed(
    det: StreamingDetector,
    episodes: list[Episode],
    speed_times_s: Any,
    speed_rad_s: Any,
    samples: Samples,
    t0_s: float,
) -> list[Episode]:
    """The episodes less the pieces of a sweep: a track at one ratio r to the screw's
    rotation over its frames (too short, or the speed too steady, to be seen moving) whose
    sound, followed beyond its ends for `PATH_FRAMES` frame lengths, went on along r |speed| /
    2 pi rather than staying at its own frequency f0: at the frames there where the two are
    more than twice `order_tolerance` apart (at least three), the median power of the
    Hann-windowed frame at r |speed| / 2 pi is four times (6 dB) that at f0 or more. Drive
    noise does so (its frequency is the speed's); a squeak's sound, before its growth and
    while it decays, stays at the mode's frequency. The ratio is then learned
    (`drive_orders`): the episodes left at it are held drive noise (`_at_known_ratios`)."""
    s = det.settings
    profile = _speed_profile(speed_times_s, speed_rad_s)
    try:
        t0 = float(t0_s)
    except (TypeError, ValueError):
        return episodes
    if s.order_tolerance <= 0 or profile is None or profile[0].size < 2 or not math.isfinite(t0):
        return episodes
    t, v = profile
    rate, n = det.sample_rate_hz, det.frame_len
    window = det._window.astype(np.float64)
    offsets = np.arange(n) / rate
    reach = PATH_FRAMES * s.frame_s
    kept = []
    for ep in episodes:
        ok = np.isfinite(ep.track_hz)
        f1 = np.interp(ep.track_times_s[ok], t, v) / (2 * np.pi)
        if not ok.any() or np.any(f1 <= 0):
            kept.append(ep)
            continue
        ratios = ep.track_hz[ok] / f1
        r, f0 = float(np.median(ratios)), float(np.median(ep.track_hz[ok]))
        if np.mean(np.abs(ratios / r - 1.0) <= s.order_tolerance) < s.order_share:
            kept.append(ep)  # it did not stay at one ratio: not a piece of a sweep
            continue
        centres = np.concatenate(
            [
                np.arange(ep.start_s - reach, ep.start_s, det.hop_s),
                np.arange(ep.end_s + det.hop_s, ep.end_s + reach, det.hop_s),
            ]
        )
        path = r * np.interp(centres, t, v) / (2 * np.pi)
        first = np.rint((centres - t0) * rate - n / 2).astype(int)
        use = (
            (np.abs(path / f0 - 1.0) > 2 * s.order_tolerance)
            & (first >= 0)
            & (first + n <= samples.size)
        )
        if np.count_nonzero(use) < 3:
            kept.append(ep)
            continue
        frames = np.stack([samples[a : a + n] for a in first[use].tolist()]) * window
        along = np.abs(np.einsum("ij,ij->i", frames, phasor(path[use, None] * offsets)))
        stayed = np.abs(frames @ phasor(f0 * offsets))
        along, stayed = np.median(along**2), np.median(stayed**2)
        if along >= 4.0 * stayed:
            ep.drive_ratio = r
            det.rejected.append(ep)
            if s.min_drive_ratio <= r <= s.max_drive_ratio:
                det._learn_ratio(r, ep.level_db)
        else:
            kept.append(ep)
    return _at_known_ratios(det, kept, t, v) if len(kept) < len(episodes) else kept


def _recurring_ratios(
    det: StreamingDetector, episodes: list[Episode], t: np.ndarray, v: np.ndarray
) -> list[Episode]:
    """The episodes less those heard again at the same ratio to the screw's rotation at
    another speed (by more than twice `order_tolerance`): each held at constant speed, too
    short to be seen moving, but together proportional to |speed|, so drive noise (a squeak's
    frequency is the structure's, not the speed's: at another speed it is at another ratio)."""
    s = det.settings
    rows = []  # (episode, its ratio, its speed)
    for ep in episodes:
        f1 = np.interp(ep.track_times_s, t, v) / (2 * np.pi) if t.size else np.zeros(0)
        ok = np.isfinite(ep.track_hz) & (f1 > 0)
        if not ok.any():
            continue
        r = ep.track_hz[ok] / f1[ok]
        mid = float(np.median(r))
        if np.mean(np.abs(r / mid - 1.0) <= s.order_tolerance) >= s.order_share:
            rows.append((ep, mid, float(np.median(f1[ok]))))
    drive: dict[int, float] = {}
    for i, (a, ra, fa) in enumerate(rows):
        for b, rb, fb in rows[i + 1 :]:
            if abs(ra / rb - 1) <= s.order_tolerance and abs(fa / fb - 1) > 2 * s.order_tolerance:
                drive[id(a)] = drive[id(b)] = (ra + rb) / 2
    kept = []
    for ep in episodes:
        if id(ep) in drive:
            ep.drive_ratio = drive[id(ep)]
            det.rejected.append(ep)
        else:
            kept.append(ep)
    return kept


def _held_with_speed(
    det: StreamingDetector, episodes: list[Episode], t: np.ndarray, v: np.ndarray
) -> list[Episode]:
    """The episodes less the tones that lasted exactly as long as the speed held still: tracks
    at constant speed (their frames' |speed| within `order_tolerance` of its median for
    `order_share` of them) at one ratio r to the screw's rotation that together start within
    `frame_s` of the speed arriving there and end within `frame_s` of the speed leaving (by
    more than `order_tolerance` either way), never more than half a frame outside that
    stretch, which is long enough for a track to touch neither end (two frames and
    `min_duration_s`: a ramp passing through is no stretch). Drive noise at any ratio does so:
    its frequency is r |speed| / 2 pi, it stops sweeping (is resolved in a frame) as the speed
    settles and moves off as the speed leaves, at once. A squeak's frequency is the mode's,
    which hardly depends on the speed: it starts when its growth from the floor has made it
    loud (not when the speed settles) and rings on at its frequency as the speed leaves until
    it decays. The speed is median-filtered over a frame (an encoder's noise does not end a
    stretch). Their ratio is learned (`drive_orders`). A tone at constant speed that does not
    so end is kept: by frequency alone it cannot be told from a squeak."""
    s = det.settings
    if s.order_tolerance <= 0 or t.size < 2 or not episodes:
        return episodes
    from scipy.ndimage import median_filter

    hop = det.hop_s
    grid = np.arange(float(t[0]), float(t[-1]) + hop / 2, hop)
    f1 = median_filter(np.interp(grid, t, v), size=max(int(round(s.frame_s / hop)), 1))
    f1 = f1 / (2 * np.pi)
    # per held track: (episode, ratio, first and last frame time, the stretch's ends)
    held: list[tuple[Episode, float, float, float, float, float]] = []
    for ep in episodes:
        ok = np.isfinite(ep.track_hz)
        times = ep.track_times_s[ok]
        at = np.interp(times, grid, f1)
        if times.size == 0 or 2 * np.pi * float(np.median(at)) < s.motor_off_rad_s:
            continue
        speed = float(np.median(at))
        r = float(np.median(ep.track_hz[ok] / np.maximum(at, 1e-300)))
        off = np.abs(f1 / speed - 1.0) > s.order_tolerance
        mid = float(np.median(times))
        before, after = grid[off & (grid < mid)], grid[off & (grid > mid)]
        if (
            s.min_drive_ratio <= r <= s.max_drive_ratio
            and np.mean(np.abs(at / speed - 1.0) <= s.order_tolerance) >= s.order_share
            and before.size
            and after.size
        ):
            held.append((ep, r, float(times[0]), float(times[-1]), before[-1], after[0]))
    drive: set[int] = set()
    for ep, r, _, _, a, b in held:  # the pieces at its ratio in its stretch, together
        group = [
            h for h in held if h[4] == a and h[5] == b and abs(h[1] / r - 1) <= s.order_tolerance
        ]
        first, last = min(h[2] for h in group), max(h[3] for h in group)
        if (
            b - a >= 2 * s.frame_s + s.min_duration_s
            and -s.frame_s / 2 <= first - a <= s.frame_s
            and -s.frame_s / 2 <= b - last <= s.frame_s
        ):
            drive.add(id(ep))
    for ep, r, *_ in held:
        if id(ep) in drive:
            ep.drive_ratio = r
            det._learn_ratio(r, ep.level_db)  # its largest level: a held tone is steady
    det.rejected.extend(ep for ep in episodes if id(ep) in drive)
    return [ep for ep in episodes if id(ep) not in drive]


def _learn_at_rest(
    det: StreamingDetector, samples: Any, t0_s: float, speed_times_s: Any, speed_rad_s: Any
) -> None:
    """Learn `det`'s background from every stretch of the recording where the drive rests for
    at least `motor_off_min_s` (its end too) before the detection runs, from where its sound
    has settled on: the first frame whose level is within `background_level_sd_db` of the
    stretch's median frame level (a steady level). A fan heard first when the drive already
    moves is then known as background, and what rings on as the drive stops (a squeak
    decaying, the room's tail) is not."""
    profile = _speed_profile(speed_times_s, speed_rad_s)
    try:
        x = det._as_samples(samples)
        t0 = float(t0_s)
    except (TypeError, ValueError):
        return  # the main pass says what is wrong with them
    s = det.settings
    if profile is None or profile[0].size < 2 or x.size < det.frame_len:
        return
    t, v = profile
    rest = np.concatenate([[False], np.isfinite(v) & (v < s.motor_off_rad_s), [False]])
    edges = np.flatnonzero(rest[1:] != rest[:-1])
    spans = [
        (_settled(det, x, t0, t[a], t[b - 1]), t[b - 1])
        for a, b in zip(edges[::2], edges[1::2], strict=True)
        if t[b - 1] - t[a] >= s.motor_off_min_s
    ]
    _learn_spans(det, det.background, x, t0, spans)


def _settled(det: StreamingDetector, x: Samples, t0: float, start: float, end: float) -> float:
    """Where the sound of the span (start, end) [s] of `x` (first sample at `t0`) has settled
    [s]: the centre of its first frame whose level (mean square of its varying part) is
    within `background_level_sd_db` of the span's median frame level; `start` when it has
    fewer than two frames."""
    rate, n, hop = det.sample_rate_hz, det.frame_len, det.hop
    i, j = max(int(math.ceil((start - t0) * rate)), 0), min(int((end - t0) * rate), x.size)
    frames = (j - i - n) // hop + 1 if j - i >= n else 0
    if frames < 2:
        return start
    variance = np.concatenate(  # by blocks of frames: memory bounded whatever the span
        [
            frame_powers(x[i + a * hop : i + (a + m - 1) * hop + n], n, hop, m)[0]
            for a in range(0, frames, _BLOCK_FRAMES)
            for m in [min(_BLOCK_FRAMES, frames - a)]
        ]
    )
    level = 10 * np.log10(np.maximum(variance, 1e-300))
    steady = level <= float(np.median(level)) + det.settings.background_level_sd_db
    return start + (int(np.argmax(steady)) * hop) / rate


def _learn_spans(
    det: StreamingDetector,
    learner: BackgroundLearner,
    x: Samples,
    t0: float,
    spans: list[tuple[float, float]],
) -> None:
    """The frames of the spans (start, end) [s] of the track `x` (first sample at `t0`) into
    `learner`, as `det` learns rest frames (each span is known to rest long enough): every
    frame from the span's start, its tones and its spectrum, unless it holds a non-finite
    sample or no usable sound; spans shorter than a frame are skipped."""
    rate, n, hop = det.sample_rate_hz, det.frame_len, det.hop
    if det.analyzer.empty:
        return
    for start, end in spans:
        i, j = max(int(math.ceil((start - t0) * rate)), 0), min(int((end - t0) * rate), x.size)
        frames = (j - i - n) // hop + 1 if j - i >= n else 0
        step = format_step(span(x, i, j)) or 0.0
        for a in range(0, frames, _BLOCK_FRAMES):
            m = min(_BLOCK_FRAMES, frames - a)
            seg = np.asarray(x[i + a * hop : i + (a + m - 1) * hop + n], dtype=np.float32)
            bad = ~np.isfinite(seg)
            if bad.any():
                seg = np.where(bad, np.float32(0.0), seg)
            psd, floor, dropped, silent = det._spectra(seg, bad, hop, m, step)
            keep = ~(dropped | silent)
            quiet = det.analyzer.candidates(psd[keep], floor=floor[keep])
            _learn_tones(learner, quiet, range(int(keep.sum())))
            learner.add_spectrum(psd[keep, : det.analyzer.used_bins])


def _learn_tones(learner: BackgroundLearner, quiet: ToneCandidates, rows: Iterable[int]) -> None:
    """The ECMA-418-1 tones (`ToneCandidates.tonal`) of the rows `rows` of `quiet`, rest
    frames' candidates without a gate, into `learner`, a frame each."""
    at = list(rows)
    for freq, power, tonal in zip(
        quiet.frequency_hz[at].tolist(),
        quiet.power[at].tolist(),
        quiet.tonal[at].tolist(),
        strict=True,
    ):
        learner.add(list(compress(freq, tonal)), list(compress(power, tonal)))


def _learn_recording(det: StreamingDetector, samples: Any, rate_hz: float | None) -> bool:
    """Learn `det`'s background from a background recording (resampled to `det`'s rate);
    True when it gave rest frames, else a warning says why not."""
    x = det._as_samples(samples)
    rate = det.sample_rate_hz if rate_hz is None else float(rate_hz)
    if not (math.isfinite(rate) and rate > 0):
        det._warn(f"background recording: sample rate {rate_hz!r} is not valid: not used")
        return False
    if rate != det.sample_rate_hz and x.size:
        from fractions import Fraction

        from scipy.signal import resample_poly

        r = Fraction(det.sample_rate_hz / rate).limit_denominator(1000)
        x = resample_poly(x, r.numerator, r.denominator).astype(np.float32)
    frames = det.background.frames
    _learn_spans(det, det.background, x, 0.0, [(0.0, x.size / det.sample_rate_hz)])
    if det.background.frames == frames:
        det._warn("background recording: no frame of usable sound in it: not used")
        return False
    return True


def _infer_background(
    det: StreamingDetector, samples: Any, t0_s: float, condition_times_s: Any, condition: Any
) -> bool:
    """Without a background heard at rest: the tones held by more than
    `background_infer_share` of the recording's frames at a steady level
    (`background_level_sd_db`), on each side of the condition where both sides last at least
    `motor_off_min_s` (module notes), included in `det`'s background. False when there was
    nothing to learn from (fewer samples than a frame)."""
    s = det.settings
    try:
        x = det._as_samples(samples)
        t0 = float(t0_s)
    except (TypeError, ValueError):
        return False
    if x.size < det.frame_len or not math.isfinite(t0):
        return False
    end = t0 + x.size / det.sample_rate_hz
    sides = [[(t0, end)]]
    try:
        ct = np.asarray(condition_times_s, dtype=float).reshape(-1)
        cv = np.asarray(condition, dtype=bool).reshape(-1)
    except (TypeError, ValueError):
        ct = cv = np.zeros(0)
    if condition_times_s is not None and ct.size == cv.size and ct.size:
        change = np.r_[True, cv[1:] != cv[:-1]]  # runs of one value: spans of frames
        ct, cv = ct[change], cv[change]
        bounds = np.r_[max(min(ct[0], end), t0), np.clip(ct[1:], t0, end), end]
        on = [(a, b) for a, b, c in zip(bounds[:-1], bounds[1:], cv, strict=True) if c]
        off = [(a, b) for a, b, c in zip(bounds[:-1], bounds[1:], cv, strict=True) if not c]
        both = [side for side in (on, off) if sum(b - a for a, b in side) >= s.motor_off_min_s]
        sides = both or sides
    kept: list[BackgroundTone] | None = None
    for spans in sides:
        learner = BackgroundLearner(
            det.analyzer.df,
            s.track_tolerance,
            s.background_infer_share,
            s.background_margin_db,
            det._level_offset_db,
        )
        _learn_spans(det, learner, x, t0, spans)
        steady = [
            t
            for t in learner.learned()
            if t.share > s.background_infer_share and t.level_sd_db <= s.background_level_sd_db
        ]
        steady = [t for t in steady if not _grew(det, x, t0, spans, t.frequency_hz)]
        kept = (
            steady
            if kept is None
            else [
                t
                for t in kept
                if any(
                    abs(u.frequency_hz / t.frequency_hz - 1) <= s.track_tolerance for u in steady
                )
            ]
        )
    det.background.include(kept or [])
    return True


def _grew(
    det: StreamingDetector, x: Samples, t0: float, spans: list[tuple[float, float]], f: float
) -> bool:
    """Whether the tone at `f` [Hz] grew out of the noise within the spans (start, end) [s] of
    `x` (first sample at `t0`): where it comes in after an absence (its level more than
    `background_margin_db` under its median: the power at its frequency in consecutive
    frames of the detector's length and window), its growth is measured
    (`growth.onset_growth`) and has a rate. A squeak grows at Re(lambda) from the floor and
    may then hold, steady, over most of a recording; a tone switched on (a step the band
    cannot resolve) or there all along is background when held so."""
    n, rate = det.frame_len, det.sample_rate_hz
    basis = _tone_basis(n, rate, np.array([f]))
    step = format_step(x) or 0.0
    per = max(_BLOCK_FRAMES * det.hop // n, 1)  # whole frames per read: the main pass's piece
    times, levels = [], []
    for start, end in spans:
        i, j = max(int(math.ceil((start - t0) * rate)), 0), min(int((end - t0) * rate), x.size)
        for b in range(i, j - n + 1, n * per):
            frames = x[b : min(b + n * per, j - (j - b) % n)].reshape(-1, n)
            ms = np.mean(np.square(frames, dtype=np.float64), axis=1)
            rounding = np.maximum(step, FLOAT32_STEP * np.sqrt(ms)) ** 2 / 12
            usable = np.isfinite(ms) & (
                np.var(frames, axis=1, dtype=np.float64) > SILENT_FACTOR * rounding
            )
            z = (frames[usable] @ basis)[:, 0]
            levels.append(10 * np.log10(np.maximum(np.abs(z) ** 2, 1e-300)))
            times.append(t0 + (b + (np.flatnonzero(usable) + 0.5) * n) / rate)
    level, t = np.concatenate([np.zeros(0), *levels]), np.concatenate([np.zeros(0), *times])
    if level.size < 2:
        return False
    absent = level < np.median(level) - det.settings.background_margin_db
    adjacent = np.diff(t) < 1.5 * n / rate  # not across a span's end or an unusable frame
    onsets = np.flatnonzero(absent[:-1] & ~absent[1:] & adjacent) + 1
    for o in onsets.tolist():
        g = onset_growth(x, rate, t0, float(t[o]) - n / (2 * rate), np.array([t[o]]), np.array([f]))
        if g.rate_per_s is not None:
            return True
    return False


def frames_heard(
    frame_times_s: np.ndarray, episodes: list[Episode]
) -> tuple[np.ndarray, np.ndarray]:
    """Per frame: covered by an episode, and the heard frequency (nan when none).

    Parameters
    ----------
    frame_times_s : numpy.ndarray
        Frame centres [s].
    episodes : list of Episode
        Episodes (e.g. collected from `StreamingDetector.push`).

    Returns
    -------
    heard : numpy.ndarray of bool
    frequency_hz : numpy.ndarray
        The loudest covering episode's track frequency, its median in a bridged gap [Hz].
    """
    t = np.asarray(frame_times_s, dtype=float)
    heard = np.zeros(t.shape, bool)
    freq = np.full(t.shape, np.nan)
    for ep in sorted(episodes, key=lambda e: e.level_db):  # the loudest wins
        inside = (t >= ep.start_s) & (t <= ep.end_s)
        heard |= inside
        if ep.track_times_s.size:  # the track has every frame of the episode
            hz = np.interp(
                t[inside], ep.track_times_s, np.nan_to_num(ep.track_hz, nan=ep.frequency_hz)
            )
        else:
            hz = np.full(int(inside.sum()), ep.frequency_hz)
        freq[inside] = hz
    return heard, freq
