# SPDX-License-Identifier: Apache-2.0
"""Heard vs predicted: the log's microphone through the squeak detector, compared with the
replay's own predictions.

A replay with sound (`SoundSettings`) records, while it runs, two compact series of its own:
per recompute the time, the nominal verdict, P(squeak), the squeak modes (label, frequency) and
the operating point (`PredictionTrace`, about 60 bytes a recompute), and the speed samples it
took, kept where they move (`SpeedTrace`). Once the log is read, `listen` reads the audio
(`bag.audio.read_audio`: the log's audio topic or a WAV file beside it), runs the detector
(`model.acoustics.detection.detect`, with the speed: tones that follow the motor orders are not
squeak) and compares (`model.acoustics.agreement.agreement`: the prediction in force at each
detector frame, held to the end of the log, as the node publishes it). With
`compare_formulations` the recorded operating points are predicted again with the other
friction formulation (the same recomputes: the input rules do not depend on it) and compared
the same way.

What it leaves (`Heard`): the episodes, the agreement, the warnings, a spectrogram of at most
`SPECTROGRAM_COLUMNS` x `SPECTROGRAM_ROWS` cells (the audio is not kept), a WAV clip of each
heard episode (`CLIP_PAD_S` before and after, at most `MAX_CLIPS`, each at most `CLIP_MAX_S`)
in `clips/`, and the per-frame heard flag and frequency for the annotated log's
`squeak/heard` (std_msgs/Bool) and `squeak/heard_frequency` (std_msgs/Float64, 0 while nothing
is heard), written on changes (the frequency at every frame while heard).

Audio that cannot be read (no info, mp3, several audio topics and none chosen, ...) is one
warning of the replay and no `Heard`: the predictions stand without it.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..bag import cdr, msgdefs
from ..bag.audio import (
    FLOAT32_MULTI_ARRAY,
    AudioError,
    AudioTrack,
    MissingRateError,
    read_audio,
)
from ..bag.logfile import LogError, Topic
from ..model.acoustics.samples import SampleTrack
from ..model.acoustics.settings import DetectorSettings
from ..model.physics.metadata import check, documented, setting

if TYPE_CHECKING:
    from ..bag.mcapout import McapOut
    from ..model import SqueakModel
    from ..model.acoustics import Agreement, Detection

FORMULATIONS = ("paper", "consistent")
HEARD, HEARD_FREQUENCY = "squeak/heard", "squeak/heard_frequency"
CLIPS_DIR = "clips"
CLIP_PAD_S = 0.2  # a clip starts this before its episode and ends this after it
CLIP_MAX_S = 10.0  # longer episodes: the first CLIP_MAX_S of them
MAX_CLIPS = 100  # clips written (the first episodes)
SPECTROGRAM_F_HZ = (89.1, 11200.0)  # ECMA-418-1's analysis range: the panel's axis
SPECTROGRAM_COLUMNS = 600  # time columns at most (a long log: frames further apart)
SPECTROGRAM_ROWS = 160  # log-spaced frequency rows
SPECTROGRAM_FRAME = 4096  # samples per spectrogram frame (11.7 Hz bins at 48 kHz)
FULL_SHARE = 0.99  # below this share of the log heard, every report says how much
COLLAR_S = 0.05  # frames this close to a heard edge are not compared (half a frame)
# How a replay's warning (summary.json, summary.txt) starts when the log's sound is not analysed
NOT_ANALYSED = "audio not analysed"
SPEED_TOLERANCE = 0.002  # a speed sample is kept when it moved this much (relative)
SPEED_FLOOR_RAD_S = 1.0  # ... of at least this speed


@documented
@dataclass(frozen=True)
class SoundSettings:
    """Where a replay finds the sound of the drive and how it is scaled (`listen`); empty texts
    and zeros are 'not given'.

    Attributes
    ----------
    detector : DetectorSettings
        The squeak detector's settings (the node's `listen.*`: `--params-file`,
        `--listen-param`).
    """

    enabled: bool = setting(
        True,
        "",
        "compare the log's sound with the predictions when it has sound (false: --no-audio)",
    )
    topic: str = setting(
        "",
        "",
        "audio topic (ros-drivers AudioDataStamped, mgonzs13 "
        "AudioStamped or std_msgs/Float32MultiArray); '' is the log's only "
        "audio topic",
    )
    info_topic: str = setting(
        "",
        "",
        "ros-drivers AudioInfo topic; '' is <topic>_info, else the log's only AudioInfo topic",
    )
    channel: int = setting(0, "1", "channel of interleaved audio (0 the first)", 0, 255)
    rate_hz: float = setting(
        0.0,
        "Hz",
        "sample rate of std_msgs/Float32MultiArray audio, which carries none (0: the "
        "listen.sample_rate_hz in the log's metadata, where the node recorded it)",
        0.0,
        1e6,
    )
    file: str = setting("", "", "a WAV file to read instead of the log's audio topics")
    background: str = setting(
        "",
        "",
        "a background recording (the drive off): a WAV file, or a log whose audio is taken; "
        "learned as background before the analysis, as motor-off stretches are",
    )
    start_s: float = setting(
        0.0,
        "s",
        "time of the WAV file's first sample after the log's first message",
        -86400.0,
        86400.0,
    )
    scale_pa: float = setting(
        0.0,
        "Pa",
        "pascal per full-scale unit of the audio: levels in "
        "dB SPL and loudness in sone (0: uncalibrated, levels in dB re "
        "full scale, no loudness)",
        0.0,
        1e6,
    )
    compare_formulations: bool = setting(
        False,
        "",
        "also predict the log with the other friction formulation and compare both with the sound",
    )
    detector: DetectorSettings = field(default_factory=DetectorSettings)

    def __post_init__(self) -> None:
        check(self)

    def beside(self, log: Path) -> SoundSettings:
        """These settings with a relative `file` resolved beside `log` (in a bag directory,
        or in the folder of a log file): the review's per-log WAV.

        Parameters
        ----------
        log : Path
            The log (file or bag directory).

        Returns
        -------
        SoundSettings
            A copy, `file` absolute when given.
        """
        if not self.file or Path(self.file).is_absolute():
            return self
        where = log if log.is_dir() else log.parent
        return replace(self, file=str(where / self.file))


def read_background(path: str | Path, channel: int = 0) -> AudioTrack:
    """A background recording (`SoundSettings.background`): a WAV file (suffix .wav), else
    the audio of a log (its only audio topic).

    Parameters
    ----------
    path : str or Path
        The WAV file or log.
    channel : int
        Channel of interleaved audio (0 the first).

    Returns
    -------
    AudioTrack

    Raises
    ------
    AudioError, LogError
        It cannot be read (one line).
    """
    path = Path(path)
    if path.suffix.lower() == ".wav":
        return read_audio(wav=path, channel=channel)
    return read_audio(path, channel=channel)


def background_text(detection: Detection) -> str:
    """summary.txt's line on the background: where it came from and its tones."""
    tones = ", ".join(
        f"{t.frequency_hz:.0f} Hz ({t.level_db:.0f} dB)" for t in detection.background[:12]
    )
    more = len(detection.background) - 12
    tones = (tones + (f" and {more} more" if more > 0 else "")) or "no tone"
    where = {
        "file": "learned from the background recording",
        "motor-off": "learned while the drive was off",
        "inferred": "inferred (no motor-off time, no background recording): steady tones "
        "held over most of the recording",
        "none": "none (nothing to learn it from)",
    }[detection.background_source]
    return f"background {where}: {tones}"


def has_sound(topics: dict[str, Topic], settings: SoundSettings) -> bool:
    """True when there is sound to read: a WAV file given, or an audio-typed topic in the log
    (audio_common messages, or std_msgs/Float32MultiArray)."""
    return bool(settings.file) or any(
        t.type_name.startswith("audio_common_msgs/") or t.type_name == FLOAT32_MULTI_ARRAY
        for t in topics.values()
    )


class SpeedTrace:
    """The shaft speed over the log [rad/s], kept where it moves: a sample is kept when it
    differs from the last kept one by more than `SPEED_TOLERANCE` of it (at least of
    `SPEED_FLOOR_RAD_S`), together with the sample before it, so that linear interpolation
    between kept samples is within that tolerance of every sample taken."""

    def __init__(self) -> None:
        self.times, self.values = array("d"), array("d")
        self._pending: tuple[float, float] | None = None

    def add(self, t_s: float, speed_rad_s: float) -> None:
        """One speed sample taken at `t_s` [s]."""
        if self.values:
            last = self.values[-1]
            if abs(speed_rad_s - last) <= SPEED_TOLERANCE * max(abs(last), SPEED_FLOOR_RAD_S):
                self._pending = (t_s, speed_rad_s)
                return
            if self._pending is not None:
                self.times.append(self._pending[0])
                self.values.append(self._pending[1])
        self._pending = None
        self.times.append(t_s)
        self.values.append(speed_rad_s)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(times [s], speeds [rad/s]), the last sample taken included."""
        t, v = np.array(self.times), np.array(self.values)
        if self._pending is not None:
            t, v = np.r_[t, self._pending[0]], np.r_[v, self._pending[1]]
        return t, v


class PredictionTrace:
    """The replay's recomputes as compact arrays: time [s], nominal verdict, P(squeak) (nan
    outside validity), the operating point (speed, load, the nut the contact is integrated
    at) and the squeak modes (label, frequency), flattened."""

    def __init__(self) -> None:
        self.times, self.probability = array("d"), array("d")
        self.squeak = array("b")
        self.speed, self.load, self.model_nut = array("d"), array("d"), array("d")
        self.mode_start = array("q", [0])  # recompute i: modes [start[i], start[i+1])
        self.mode_label, self.mode_hz, self.mode_growth = array("H"), array("d"), array("d")
        self.labels: list[str] = []
        self._label_index: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self.times)

    def add(self, t_s: float, job: Any, verdict: Any) -> None:
        """Recompute `job` (`timeline.Job`) with its `replay.Verdict`, at `t_s` [s]."""
        self.times.append(t_s)
        self.squeak.append(int(verdict.valid and not verdict.stable))
        self.probability.append(verdict.probability if verdict.valid else math.nan)
        self.speed.append(job.speed_rad_s)
        self.load.append(job.load_n)
        self.model_nut.append(job.model_nut_m)
        self._modes(verdict.squeak)

    def _modes(self, modes: Any) -> None:
        for label, hz, growth in modes:
            k = self._label_index.get(label)
            if k is None:
                k = self._label_index[label] = len(self.labels)
                self.labels.append(label)
            self.mode_label.append(k)
            self.mode_hz.append(hz)
            self.mode_growth.append(growth)
        self.mode_start.append(len(self.mode_hz))

    def with_verdicts(self, verdicts: list[Any]) -> PredictionTrace:
        """The same recomputes with other verdicts (another model's), in order."""
        other = PredictionTrace()
        other.times, other.speed, other.load, other.model_nut = (
            self.times,
            self.speed,
            self.load,
            self.model_nut,
        )
        for v in verdicts:
            other.squeak.append(int(v.valid and not v.stable))
            other.probability.append(v.probability if v.valid else math.nan)
            other._modes(v.squeak)
        return other

    def modes(
        self, i: int, band_hz: tuple[float, float] = (0.0, math.inf)
    ) -> list[tuple[str, float, float]]:
        """The squeak modes (label, frequency [Hz], Re(lambda) [1/s]) of recompute `i` within
        `band_hz`."""
        lo, hi = band_hz
        return [
            (self.labels[self.mode_label[j]], self.mode_hz[j], self.mode_growth[j])
            for j in range(self.mode_start[i], self.mode_start[i + 1])
            if lo <= self.mode_hz[j] <= hi
        ]

    def squeak_points(self) -> np.ndarray:
        """(time [s], frequency [Hz], P(squeak)) of every predicted squeak mode, rows."""
        start = np.frombuffer(self.mode_start, np.int64)
        counts = np.diff(start)
        rows = np.repeat(np.arange(len(self.times)), counts)
        return np.column_stack(
            [
                np.asarray(self.times)[rows],
                np.asarray(self.mode_hz),
                np.asarray(self.probability)[rows],
            ]
        ).reshape(-1, 3)

    def compare(
        self, detection: Detection, end_s: float, band_hz: tuple[float, float]
    ) -> tuple[Agreement, float]:
        """`agreement` of these predictions with `detection`, held to `end_s` [s], counting
        only what the detector can hear: a recompute whose most unstable squeak mode (the one
        a squeak locks to) lies outside `band_hz` counts as not predicted, its P(squeak) as
        unknown; the frequency matches are with the modes inside the band. Frames within
        `COLLAR_S` of a heard episode's start or end are not compared (the detector places an
        edge to about half its 0.1 s frame).

        Returns
        -------
        tuple of (Agreement, float)
            The agreement, and the time [s] with the most unstable mode outside the band.
        """
        from ..model.acoustics.agreement import agreement

        start = np.frombuffer(self.mode_start, np.int64)
        has_modes = np.diff(start) > 0
        hz = np.asarray(self.mode_hz)  # the first of a recompute's: most unstable
        first_hz = hz[np.minimum(start[:-1], hz.size - 1)] if hz.size else np.zeros(len(self))
        squeak = np.asarray(self.squeak, bool)
        outside = squeak & has_modes & ~((first_hz >= band_hz[0]) & (first_hz <= band_hz[1]))
        p = np.where(outside, np.nan, np.asarray(self.probability))
        t = np.asarray(self.times)
        held = np.diff(np.r_[t, max(end_s, t[-1])]) if t.size else t
        return agreement(
            detection,
            t,
            squeak & ~outside,
            p,
            _Modes(self, band_hz),
            valid_until_s=end_s,
            collar_s=COLLAR_S,
        ), float(held[outside].sum())


class _Modes(Sequence):
    """The squeak modes within a band of each recompute of a trace, made when asked for (the
    agreement asks only for those during heard episodes)."""

    def __init__(self, trace: PredictionTrace, band_hz: tuple[float, float]) -> None:
        self.trace, self.band_hz = trace, band_hz

    def __len__(self) -> int:
        return len(self.trace)

    def __getitem__(self, i):
        return self.trace.modes(i, self.band_hz)


@dataclass
class Spectrogram:
    """A bounded spectrogram of the sound: `level_db` [column, row] is the largest power
    spectral density in the row's frequency band at the column's time (dB re the scale's
    unit squared per Hz: Pa or full scale).

    Attributes
    ----------
    times_s : numpy.ndarray
        Column centres [s].
    edges_hz : numpy.ndarray
        Row edges [Hz], log-spaced over `SPECTROGRAM_F_HZ` (one more than the rows).
    level_db : numpy.ndarray
        float32, shape (columns, rows); nan above the Nyquist frequency.
    """

    times_s: np.ndarray
    edges_hz: np.ndarray
    level_db: np.ndarray


def spectrogram(
    samples: np.ndarray | SampleTrack, rate_hz: float, t0_s: float, scale: float = 1.0
) -> Spectrogram:
    """`Spectrogram` of a track: at most `SPECTROGRAM_COLUMNS` Hann frames of
    `SPECTROGRAM_FRAME` samples, evenly over the track (half-overlapping for short tracks),
    their power binned into `SPECTROGRAM_ROWS` log-spaced bands (the maximum of each, the
    nearest bin for a band narrower than a bin)."""
    n = min(SPECTROGRAM_FRAME, samples.size)
    edges = np.geomspace(*SPECTROGRAM_F_HZ, SPECTROGRAM_ROWS + 1)
    if n < 16:
        return Spectrogram(np.zeros(0), edges, np.zeros((0, SPECTROGRAM_ROWS), np.float32))
    hop = max(n // 2, int(math.ceil((samples.size - n) / (SPECTROGRAM_COLUMNS - 1))), 1)
    starts = np.arange(0, samples.size - n + 1, hop)[:SPECTROGRAM_COLUMNS]
    window = np.hanning(n).astype(np.float32)
    frames = np.nan_to_num(np.stack([samples[a : a + n] for a in starts.tolist()]))
    frames *= window * np.float32(scale)
    psd = np.abs(np.fft.rfft(frames, axis=1)) ** 2 / (rate_hz * np.sum(window**2))
    psd[:, 1:-1] *= 2
    f = np.fft.rfftfreq(n, 1 / rate_hz)
    band = np.searchsorted(edges, f, side="right") - 1
    # a row narrower than a bin has the bin nearest its centre (nan above Nyquist)
    centre = np.sqrt(edges[:-1] * edges[1:])
    nearest = np.clip(np.searchsorted(f, centre), 0, f.size - 1)
    level = psd[:, nearest].copy()
    level[:, centre > f[-1]] = np.nan
    for k in np.unique(band[(band >= 0) & (band < SPECTROGRAM_ROWS)]).tolist():
        level[:, k] = psd[:, band == k].max(axis=1)
    db = 10 * np.log10(np.maximum(level, 1e-30))
    return Spectrogram(t0_s + (starts + n / 2) / rate_hz, edges, db.astype(np.float32))


@dataclass
class Heard:
    """What the microphone heard and how the predictions agree with it (`listen`).

    Attributes
    ----------
    source : str
        The audio topic or WAV file.
    sample_rate_hz : float
        Of the audio [Hz].
    scale : str
        'Pa' (calibrated: levels in dB SPL, loudness) or 'full scale'.
    detection : Detection
        The detector's frames and episodes.
    agreement : Agreement
        Of the replay's predictions (its formulation) with the detection.
    formulation : str
        The replay's friction formulation.
    by_formulation : dict of str to Agreement
        With `compare_formulations`: the agreement of each formulation; else empty.
    warnings : list of str
        Of the audio and the detector.
    spectrogram : Spectrogram
        Bounded, for the report.
    squeak_points : numpy.ndarray
        (time [s], frequency [Hz], P) of the predicted squeak modes, at most
        `SPECTROGRAM_COLUMNS` x 8 rows evenly over the log, for the report.
    clips : list of (Path, float)
        The WAV clips written, with the start of their episode [s].
    duration_s : float
        Of the audio [s].
    detect_s : float
        Wall time of the detection [s].
    band_hz : tuple of float
        The frequencies the detector analyses [Hz]: predicted squeak modes outside are not
        counted.
    out_of_band_s : dict of str to float
        Per formulation compared (the replay's at least): time [s] with squeak predicted
        whose most unstable mode lies outside `band_hz` (not counted).
    log_s : float
        Duration of the log [s]: the span the sound should cover (`sound_share`).
    detector : DetectorSettings
        The detector's settings.
    """

    source: str
    sample_rate_hz: float
    scale: str
    detection: Detection
    agreement: Agreement
    formulation: str
    by_formulation: dict[str, Agreement]
    warnings: list[str]
    spectrogram: Spectrogram
    squeak_points: np.ndarray
    clips: list[tuple[Path, float]] = field(default_factory=list)
    duration_s: float = 0.0
    detect_s: float = 0.0
    band_hz: tuple[float, float] = (0.0, 0.0)
    out_of_band_s: dict[str, float] = field(default_factory=dict)
    log_s: float = 0.0
    detector: DetectorSettings = field(default_factory=DetectorSettings)

    @property
    def usable_s(self) -> float:
        """Sound usable for the comparison within the log's span [0, log_s] [s]: frames of
        the track there, less those without usable samples (NaN, gaps, a muted microphone)."""
        d = self.detection
        if d.frame_times_s.size < 2:
            return 0.0
        inside = (d.frame_times_s >= 0.0) & (d.frame_times_s <= self.log_s)
        if d.usable is not None:
            inside &= d.usable
        return float(np.count_nonzero(inside)) * d.hop_s

    @property
    def sound_share(self) -> float | None:
        """How much of the log was heard: `usable_s` over the frames that a microphone
        recording all of the log would give (None for a log shorter than a frame)."""
        d = self.detection
        frame_s = self.detector.frame_s
        hop_s = d.hop_s if d.frame_times_s.size > 1 else self.detector.hop_s
        possible = math.floor((self.log_s - frame_s) / hop_s + 1e-9) + 1
        return min(self.usable_s / (possible * hop_s), 1.0) if possible > 0 else None

    def as_dict(self) -> dict[str, Any]:
        """summary.json's `heard`: source, rate, scale, episodes, agreement, warnings.

        Returns
        -------
        dict
            JSON-ready (nan as None).
        """
        return {
            "source": self.source,
            "sample_rate_hz": self.sample_rate_hz,
            "scale": self.scale,
            "level_unit": "dB SPL" if self.scale == "Pa" else "dB re full scale",
            "duration_s": self.duration_s,
            "unusable_s": self.detection.unusable_s,
            "unusable_spans": [list(s) for s in self.detection.unusable_spans()],
            "usable_s": self.usable_s,
            "log_s": self.log_s,
            "sound_share": self.sound_share,
            "detector": asdict(self.detector),
            "episodes": [e.as_dict() for e in self.detection.episodes],
            "background": [t.as_dict() for t in self.detection.background],
            "background_source": self.detection.background_source,
            "drive_orders": [o.as_dict() for o in self.detection.drive_orders],
            "creaks": [c.as_dict() for c in self.detection.creaks],
            "agreement": self.agreement.as_dict(),
            "band_hz": list(self.band_hz),
            "collar_s": COLLAR_S,
            "predicted_out_of_band_s": self.out_of_band_s[self.formulation],
            "clips": [f"{CLIPS_DIR}/{p.name}" for p, _ in self.clips],
            "warnings": list(self.warnings),
        }

    def by_formulation_dict(self) -> dict[str, dict[str, Any]] | None:
        """summary.json's `agreement_by_formulation`.

        Returns
        -------
        dict or None
            Formulation -> its `Agreement.as_dict` and `predicted_out_of_band_s`; None without
            the comparison.
        """
        return {
            k: {**a.as_dict(), "predicted_out_of_band_s": self.out_of_band_s[k]}
            for k, a in self.by_formulation.items()
        } or None

    def ranking(self) -> list[str]:
        """The compared formulations, best first.

        Returns
        -------
        list of str
            By lower Brier score, then higher recall, then higher precision (each to 3
            digits), then more heard episodes matched in frequency.
        """

        def key(name: str) -> tuple:
            a = self.by_formulation[name]
            return (
                _rounded(a.brier, math.inf),
                -_rounded(a.recall, -1.0),
                -_rounded(a.precision, -1.0),
                -sum(m.matched for m in a.frequency_match),
            )

        return sorted(self.by_formulation, key=key)

    def text(self) -> list[str]:
        """summary.txt's lines: heard vs predicted time and scores, the frequency matches,
        the calibration and, when compared, which formulation describes the drive better.

        Returns
        -------
        list of str
            Lines without newlines.
        """
        a = self.agreement
        heard_s, predicted_s = a.both_s + a.heard_only_s, a.both_s + a.predicted_only_s
        freqs = _distinct([e.frequency_hz for e in self.detection.episodes])
        at = f" at {', '.join(f'{f:.0f}' for f in freqs)} Hz" if freqs else ""
        lines = [
            f"heard squeak {heard_s:.1f} s{at}; predicted {predicted_s:.1f} s: "
            f"recall {_score(a.recall)}, precision {_score(a.precision)}, "
            f"Brier {_score(a.brier)} ({self.source}, {self.sample_rate_hz:g} Hz, "
            f"{len(self.detection.episodes)} episodes)"
        ]
        if a.frequency_match:
            lines.append("; ".join(_match_text(m) for m in _first_per_frequency(a.frequency_match)))
        if self.detection.creaks:
            lines.append(creak_text(self.detection.creaks))
        lines.append(background_text(self.detection))
        unusable = self.detection.unusable_s
        if unusable > 0:
            lines.append(
                f"sound unusable for {unusable:.1f} s of {self.duration_s:.1f} s (NaN/inf "
                "samples, gaps, a constant or silent microphone): those frames are not scored"
            )
        share = self.sound_share
        if share is not None and share < FULL_SHARE:
            lines.append(
                f"heard only {self.usable_s:.1f} s of the log's {self.log_s:.1f} s "
                f"({100 * share:.0f} %): heard vs predicted covers only that"
            )
        outside = self.out_of_band_s[self.formulation]
        if outside > 0:
            lines.append(
                f"squeak predicted at a most unstable mode outside the analysed "
                f"{self.band_hz[0]:.0f}-{self.band_hz[1]:.0f} Hz for {outside:.1f} s: "
                "not counted"
            )
        if self.scale == "Pa":
            lines.append("levels in dB SPL (calibrated: --audio-scale), loudness in sone")
        else:
            lines.append(
                "levels in dB re full scale, loudness not computed (uncalibrated: "
                "give --audio-scale PA)"
            )
        if self.by_formulation:
            rank = self.ranking()
            best, other = rank[0], rank[1:]
            lines.append(
                f"{best} describes the drive better than {', '.join(other)}: "
                + "; ".join(
                    f"{k} Brier {_score(b.brier)}, recall {_score(b.recall)}, precision "
                    f"{_score(b.precision)}, {sum(m.matched for m in b.frequency_match)}/"
                    f"{len(b.frequency_match)} frequencies matched"
                    for k, b in ((k, self.by_formulation[k]) for k in rank)
                )
            )
        return lines


def creak_text(creaks: list[Any]) -> str:
    """One line for the creaks: not squeak, not scored."""
    total = sum(c.end_s - c.start_s for c in creaks)
    rates = ", ".join(f"{c.pulse_rate_hz:.0f}" for c in creaks[:5])
    more = ", ..." if len(creaks) > 5 else ""
    return (
        f"creak (stick-slip pulses) {total:.1f} s in {len(creaks)} episodes at "
        f"{rates}{more} pulses/s: impulsive friction noise, not counted as squeak"
    )


def _rounded(value: float | None, none: float) -> float:
    return none if value is None else round(value, 3)


def _score(value: float | None) -> str:
    return (
        "n/a"
        if value is None
        else f"{value:.2f}"
        if value >= 0.01 or value == 0
        else f"{value:.1e}"
    )


def _distinct(frequencies: list[float], tolerance: float = 0.03) -> list[float]:
    """Frequencies within `tolerance` of a smaller one dropped, ascending."""
    out: list[float] = []
    for f in sorted(frequencies):
        if not out or f > out[-1] * (1 + tolerance):
            out.append(f)
    return out


def _first_per_frequency(matches: list[Any]) -> list[Any]:
    """One frequency match per distinct heard frequency (the first episode's)."""
    seen = _distinct([m.heard_hz for m in matches])
    out = []
    for f in seen:
        out.append(next(m for m in matches if abs(m.heard_hz - f) <= 0.03 * f))
    return out


def _match_text(m: Any) -> str:
    if m.label is None:
        return f"heard {m.heard_hz:.0f} Hz: no squeak predicted during it"
    verb = "matches" if m.matched else "does not match"
    growth = ""
    if m.heard_growth_per_s is not None and m.predicted_growth_per_s is not None:
        growth = (
            f", grew at {m.heard_growth_per_s:.0f} +- {m.heard_growth_se:.0f} 1/s "
            f"(Re(lambda) {m.predicted_growth_per_s:.0f} 1/s)"
        )
    return (
        f"heard {m.heard_hz:.0f} Hz {verb} {m.label} {m.predicted_hz:.0f} Hz "
        f"({100 * m.relative_error:+.1f} %){growth}"
    )


def _other_verdicts(
    model: SqueakModel,
    formulation: str,
    trace: PredictionTrace,
    solve: Callable[..., Any],
    batch: int,
) -> list[Any]:
    """The verdicts of `model` with `formulation` at the recorded operating points."""
    from .timeline import ModelSpec

    spec = ModelSpec.of(model.with_params(formulation=formulation))
    speed, load, nut = (np.asarray(a) for a in (trace.speed, trace.load, trace.model_nut))
    out: list[Any] = []
    for i in range(0, speed.size, batch):
        out += solve(spec, speed[i : i + batch], load[i : i + batch], nut[i : i + batch])[0]
    return out


def heard_status(summary: dict[str, Any]) -> str:
    """Whether a replay heard its log, from its summary (`summary.json`): 'analysed', 'no sound'
    (no audio topic or WAV file, or the audio off) or the warning saying why the sound was
    not analysed (`NOT_ANALYSED`...).

    Parameters
    ----------
    summary : dict
        The replay's summary (`ReplayResult.summary`).

    Returns
    -------
    str
        One line.
    """
    if summary.get("heard") is not None:
        return "analysed"
    why = [w for w in summary.get("warnings", []) if w.startswith(NOT_ANALYSED)]
    return why[0] if why else "no sound"


def listen(
    log: Path,
    topics: dict[str, Topic],
    out_dir: Path,
    settings: SoundSettings,
    trace: PredictionTrace,
    speed: SpeedTrace,
    end_s: float,
    model: SqueakModel,
    solve: Callable[..., Any],
    batch: int,
) -> tuple[Heard | None, list[str]]:
    """Read the sound, detect, compare (the module's steps).

    Parameters
    ----------
    log : Path
        The log replayed.
    topics : dict of str to Topic
        Its topics (`logsource.log_topics`).
    out_dir : Path
        The replay's output directory (the clips go to `clips/` in it).
    settings : SoundSettings
        Where the sound is, its scale, the comparison of formulations.
    trace : PredictionTrace
        The replay's recomputes.
    speed : SpeedTrace
        The speed samples it took.
    end_s : float
        End of the log [s]: the last prediction holds until then.
    model : SqueakModel
        The replay's model (the other formulation is derived from it).
    solve : callable
        `replay.solve` (the verdicts of operating points).
    batch : int
        Operating points per `solve` call.

    Returns
    -------
    tuple of (Heard or None, list of str)
        None without sound, or when the audio cannot be read at all; warnings of the replay
        (why the audio was not analysed).
    """
    import time

    from ..model.acoustics import AudioError as DetectorError
    from ..model.acoustics import StreamingDetector, detect

    if not settings.enabled or not has_sound(topics, settings):
        return None, []
    try:
        track = read_audio(
            None if settings.file else log,
            settings.topic or None,
            settings.info_topic or None,
            settings.channel,
            settings.rate_hz or None,
            settings.file or None,
            settings.start_s,
        )
    except MissingRateError as exc:
        return None, [f"{NOT_ANALYSED}: {exc}: give its rate with --audio-rate HZ"]
    except (AudioError, LogError) as exc:
        return None, [f"{NOT_ANALYSED}: {' '.join(str(exc).split())}"]
    scale = settings.scale_pa or None
    background, warnings = None, []
    if settings.background:
        try:
            background = read_background(settings.background, settings.channel)
            warnings += [f"background recording: {w}" for w in background.warnings]
        except (AudioError, LogError) as exc:
            warnings.append(f"background recording not used: {' '.join(str(exc).split())}")
    t0 = time.perf_counter()
    speed_t, speed_v = speed.arrays()
    try:
        detection = detect(
            track.samples,
            track.sample_rate_hz,
            t0_s=track.t0_s,
            speed_times_s=speed_t if speed_t.size else None,
            speed_rad_s=speed_v if speed_v.size else None,
            scale_pa=scale,
            settings=settings.detector,
            background=None if background is None else background.samples,
            background_rate_hz=None if background is None else background.sample_rate_hz,
            infer_background=True,
            condition_times_s=np.asarray(trace.times) if len(trace) else None,
            condition=np.asarray(trace.squeak, bool) if len(trace) else None,
        )
    except DetectorError as exc:
        return None, [f"{NOT_ANALYSED} ({track.source}): {exc}"]
    detect_s = time.perf_counter() - t0
    audible = track.samples  # NaN (not scored) is silence in the picture and the clips
    band = (
        settings.detector.f_lo_hz,
        StreamingDetector(settings.detector, sample_rate_hz=track.sample_rate_hz).analyzer.f_hi_hz,
    )
    agreement, outside = trace.compare(detection, end_s, band)
    formulation = model.params.formulation
    by: dict[str, Agreement] = {}
    out_of_band = {formulation: outside}
    if settings.compare_formulations:
        for name in FORMULATIONS:
            if name != formulation:
                by[name], out_of_band[name] = trace.with_verdicts(
                    _other_verdicts(model, name, trace, solve, batch)
                ).compare(detection, end_s, band)
            else:
                by[name] = agreement
    points = trace.squeak_points()
    if len(points) > SPECTROGRAM_COLUMNS * 8:
        points = points[np.linspace(0, len(points) - 1, SPECTROGRAM_COLUMNS * 8).astype(int)]
    heard = Heard(
        track.source,
        track.sample_rate_hz,
        detection.scale,
        detection,
        agreement,
        formulation,
        by,
        list(track.warnings) + warnings + list(detection.warnings),
        spectrogram(audible, track.sample_rate_hz, track.t0_s, scale or 1.0),
        points,
        duration_s=track.duration_s,
        detect_s=detect_s,
        band_hz=band,
        out_of_band_s=out_of_band,
        log_s=end_s,
        detector=settings.detector,
    )
    heard.clips = write_clips(
        audible, track.sample_rate_hz, track.t0_s, detection.episodes, out_dir / CLIPS_DIR
    )
    return heard, []


def write_clips(
    samples: np.ndarray | SampleTrack,
    rate_hz: float,
    t0_s: float,
    episodes: list[Any],
    directory: Path,
) -> list[tuple[Path, float]]:
    """A float32 WAV clip of each of the first `MAX_CLIPS` episodes, `CLIP_PAD_S` before and
    after it (at most `CLIP_MAX_S` of it), into `directory` (created when there is one).

    Parameters
    ----------
    samples : numpy.ndarray
        The track (full scale).
    rate_hz : float
        Its sample rate [Hz].
    t0_s : float
        Time of its first sample [s].
    episodes : list of Episode
        The heard episodes (start_s, end_s, frequency_hz).
    directory : Path
        Where the clips go: `heard_<k>_<start>s_<frequency>Hz.wav`.

    Returns
    -------
    list of (Path, float)
        The clips written, with their episode's start [s].
    """
    from scipy.io import wavfile

    paths = []
    for k, e in enumerate(episodes[:MAX_CLIPS]):
        a = max(int((e.start_s - CLIP_PAD_S - t0_s) * rate_hz), 0)
        b = min(
            int((min(e.end_s, e.start_s + CLIP_MAX_S) + CLIP_PAD_S - t0_s) * rate_hz), samples.size
        )
        if b <= a:
            continue
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"heard_{k:03d}_{e.start_s:.2f}s_{e.frequency_hz:.0f}Hz.wav"
        wavfile.write(path, int(round(rate_hz)), np.nan_to_num(samples[a:b]))
        paths.append((path, e.start_s))
    return paths


def write_heard(out: McapOut, namespace: str, heard: Heard, start_ns: int) -> None:
    """The heard flag and frequency into a reopened annotated log (`McapOut.reopen`) on
    `<namespace>/squeak/heard` (std_msgs/Bool) and `<namespace>/squeak/heard_frequency`
    (std_msgs/Float64 [Hz], 0 while nothing is heard): both at the first frame, the flag at
    every change, the frequency at every frame while heard and when it ends; and each clip as
    an attachment (audio/wav), at its episode's start.

    Parameters
    ----------
    out : McapOut
        The annotated log, reopened (finished by the caller).
    namespace : str
        Of the predictions (`ReplayResult.out_namespace`).
    heard : Heard
        What was heard.
    start_ns : int
        Log time of t = 0 [ns].
    """
    channels = []
    for topic, type_name in ((HEARD, cdr.BOOL), (HEARD_FREQUENCY, cdr.FLOAT64)):
        schema = out.register_schema(type_name, "ros2msg", msgdefs.definition(type_name).encode())
        channels.append(
            out.register_channel(
                f"{namespace}/{topic}", "cdr", schema, {"offered_qos_profiles": ""}
            )
        )
    d = heard.detection
    t_ns = start_ns + np.round(d.frame_times_s * 1e9).astype(np.int64)
    flags = d.heard.astype(bool)
    hz = np.where(flags, np.nan_to_num(d.frequency_hz, nan=0.0), 0.0)
    changed = np.r_[True, flags[1:] != flags[:-1]] if flags.size else flags
    seq = [0, 0]
    for i in np.flatnonzero(changed | flags).tolist():
        t = int(t_ns[i])
        if changed[i]:
            out.add_message(channels[0], t, cdr.encode_bool(bool(flags[i])), t, seq[0])
            seq[0] += 1
        out.add_message(channels[1], t, cdr.encode_float64(float(hz[i])), t, seq[1])
        seq[1] += 1
    for path, start_s in heard.clips:
        t = start_ns + int(round(start_s * 1e9))
        out.add_attachment(f"{CLIPS_DIR}/{path.name}", "audio/wav", path.read_bytes(), t, t)
