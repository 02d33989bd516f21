# SPDX-License-Identifier: Apache-2.0
"""A recording without a log (`leadscrew-squeak listen FILE.wav`): the squeak detector on a
WAV file, with the shaft speed from a CSV file when there is one.

The WAV (`bag.audio.read_audio`: 8/16/24/32-bit integer or float samples, mono or one channel
of several, `SoundSettings.channel`, the first by default) goes through the same detector as a
replay's sound (`model.acoustics.detection.detect`, `SoundSettings.detector`), with the same
background: a background recording (`SoundSettings.background`), else the motor-off stretches
of the speed (`read_speed_csv`: times [s] from the WAV's first sample and the screw's speed
[rad/s]), else inferred from the recording itself. Without a speed nothing moves: the whole
recording is one state, and a tone held steady over most of it is background, not squeak.

What it leaves (`write_listened`): `heard.json` (`Listened.as_dict`), `summary.txt`
(`Listened.text`) and `spectrogram.png` (`plots.plot_listened`).
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..bag.audio import AudioError, read_audio
from ..model.acoustics.detection import Detection, detect
from ..model.acoustics.settings import DetectorSettings
from .jsonsafe import json_safe
from .listen import (
    SoundSettings,
    Spectrogram,
    background_text,
    creak_text,
    read_background,
    spectrogram,
)

SPEED_CSV_HEADER = ("time_s", "speed_rad_s")
HEARD_JSON, SUMMARY_TXT, SPECTROGRAM_PNG = "heard.json", "summary.txt", "spectrogram.png"
SPECTROGRAM_DPI = 110


class RecordingError(ValueError):
    """A speed CSV or background recording that cannot be used (one line)."""


def read_speed_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The shaft speed of a recording from a CSV file with the header `time_s,speed_rad_s`.

    Parameters
    ----------
    path : str or Path
        The file: times [s] after the WAV's first sample, strictly increasing, and the
        screw's speed [rad/s], finite numbers, one row each.

    Returns
    -------
    tuple of numpy.ndarray
        (times [s], speeds [rad/s]).

    Raises
    ------
    RecordingError
        Unreadable, another header, a row that is not two finite numbers, times not
        increasing, no row (one line naming the file and the row).
    """
    where = f"--speed-csv {path}"
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except OSError as exc:
        raise RecordingError(f"{where}: cannot read it: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise RecordingError(f"{where}: not a text file (UTF-8)") from None
    rows = [r for r in rows if any(c.strip() for c in r)]
    header = tuple(c.strip() for c in rows[0]) if rows else ()
    if header != SPEED_CSV_HEADER:
        raise RecordingError(
            f"{where}: the first line must be {','.join(SPEED_CSV_HEADER)}, got "
            f"{','.join(header) or 'an empty file'!r}"
        )
    values = []
    for k, row in enumerate(rows[1:], start=2):
        try:
            t, v = (float(c) for c in row)
        except ValueError:
            t = v = math.nan
        if not (math.isfinite(t) and math.isfinite(v)):
            raise RecordingError(f"{where}: line {k} is not two finite numbers: {row!r}")
        values.append((t, v))
    if not values:
        raise RecordingError(f"{where}: no speed samples after the header")
    a = np.array(values)
    if a.shape[0] > 1 and np.any(np.diff(a[:, 0]) <= 0):
        k = int(np.flatnonzero(np.diff(a[:, 0]) <= 0)[0]) + 3
        raise RecordingError(f"{where}: time_s does not increase at line {k}")
    return a[:, 0], a[:, 1]


@dataclass
class Listened:
    """What `listen_recording` heard in a recording.

    Attributes
    ----------
    source : str
        The WAV file.
    channel, channels : int
        The channel analysed (0 the first) and the file's channel count.
    sample_rate_hz : float
        Of the WAV [Hz].
    scale : str
        'Pa' (calibrated: levels in dB SPL) or 'full scale'.
    detection : Detection
        The detector's frames, episodes, background and drive orders.
    spectrogram : Spectrogram
        Bounded, for the picture.
    warnings : list of str
        Of the WAV, the background recording and the detector.
    duration_s : float
        Of the WAV [s].
    speed : tuple of numpy.ndarray or None
        (times [s], speeds [rad/s]) of the speed CSV; None without.
    speed_file, background_file : str or None
        The speed CSV and the background recording given.
    detector : DetectorSettings
        The detector's settings.
    detect_s : float
        Wall time of the detection [s].
    """

    source: str
    channel: int
    channels: int
    sample_rate_hz: float
    scale: str
    detection: Detection
    spectrogram: Spectrogram
    warnings: list[str]
    duration_s: float
    speed: tuple[np.ndarray, np.ndarray] | None
    speed_file: str | None
    background_file: str | None
    detector: DetectorSettings
    detect_s: float = 0.0

    @property
    def unusable_s(self) -> float:
        """Time without usable sound (NaN, a constant or silent signal) [s]."""
        return self.detection.unusable_s

    @property
    def usable_s(self) -> float:
        """Time of the frames with usable sound [s]."""
        d = self.detection
        if d.frame_times_s.size < 2:
            return 0.0
        n = d.frame_times_s.size if d.usable is None else int(np.count_nonzero(d.usable))
        return n * d.hop_s

    def as_dict(self) -> dict[str, Any]:
        """heard.json: the source, the episodes, the background (`background_source`: where
        it came from), the drive orders, the warnings, the usable and unusable seconds.

        Returns
        -------
        dict
            JSON-ready (nan as None).
        """
        d = self.detection
        return {
            "source": self.source,
            "channel": self.channel,
            "channels": self.channels,
            "sample_rate_hz": self.sample_rate_hz,
            "scale": self.scale,
            "level_unit": "dB SPL" if self.scale == "Pa" else "dB re full scale",
            "duration_s": self.duration_s,
            "usable_s": self.usable_s,
            "unusable_s": self.unusable_s,
            "unusable_spans": [list(s) for s in d.unusable_spans()],
            "speed_file": self.speed_file,
            "background_file": self.background_file,
            "detector": asdict(self.detector),
            "episodes": [e.as_dict() for e in d.episodes],
            "background": [t.as_dict() for t in d.background],
            "background_source": d.background_source,
            "drive_orders": [o.as_dict() for o in d.drive_orders],
            "creaks": [c.as_dict() for c in d.creaks],
            "warnings": list(self.warnings),
        }

    def text(self) -> list[str]:
        """summary.txt's lines: the episodes, the background and where it came from, the
        drive orders, the usable sound, the warnings.

        Returns
        -------
        list of str
            Lines without newlines.
        """
        d = self.detection
        heard_s = sum(e.duration_s for e in d.episodes)
        freqs = sorted({round(e.frequency_hz) for e in d.episodes})
        at = f" at {', '.join(f'{f:.0f}' for f in freqs[:12])} Hz" if freqs else ""
        channel = f"channel {self.channel} of {self.channels}, " if self.channels > 1 else ""
        lines = [
            f"heard squeak {heard_s:.1f} s{at} ({len(d.episodes)} episodes) in "
            f"{Path(self.source).name} ({channel}{self.sample_rate_hz:g} Hz, "
            f"{self.duration_s:.1f} s)",
            background_text(d),
        ]
        if self.speed is None:
            lines.append("no speed given: nothing moves, no drive order")
        elif d.drive_orders:
            lines.append(
                "drive orders (x the screw's rotation frequency): "
                + ", ".join(f"{o.ratio:.3g} ({o.level_db:.0f} dB)" for o in d.drive_orders)
            )
        else:
            lines.append("no drive order heard")
        if d.creaks:
            lines.append(creak_text(d.creaks))
        lines.append(
            f"usable sound {self.usable_s:.1f} s, unusable {self.unusable_s:.1f} s (NaN/inf, "
            "a constant or silent signal: not analysed)"
        )
        lines.append(
            "levels in dB SPL (calibrated)"
            if self.scale == "Pa"
            else "levels in dB re full scale (uncalibrated)"
        )
        lines += [f"warning: {w}" for w in self.warnings]
        return lines


def listen_recording(
    wav: str | Path,
    settings: SoundSettings | None = None,
    speed_csv: str | Path | None = None,
) -> Listened:
    """The detector on a WAV file (module notes).

    Parameters
    ----------
    wav : str or Path
        The recording.
    settings : SoundSettings, optional
        Its channel, scale (`scale_pa`), background recording and the detector's settings
        (the log options are not used); default: `SoundSettings()`.
    speed_csv : str or Path, optional
        The shaft speed (`read_speed_csv`).

    Returns
    -------
    Listened

    Raises
    ------
    AudioError, LogError
        The WAV or the background recording cannot be read (one line).
    RecordingError
        The speed CSV cannot be used.
    """
    settings = settings or SoundSettings()
    track = read_audio(wav=wav, channel=settings.channel)
    speed = None if speed_csv is None else read_speed_csv(speed_csv)
    background = read_background(settings.background) if settings.background else None
    warnings = list(track.warnings)
    if background is not None:
        warnings += [f"background recording: {w}" for w in background.warnings]
    scale = settings.scale_pa or None
    t0 = time.perf_counter()
    try:
        detection = detect(
            track.samples,
            track.sample_rate_hz,
            speed_times_s=None if speed is None else speed[0],
            speed_rad_s=None if speed is None else speed[1],
            scale_pa=scale,
            settings=settings.detector,
            background=None if background is None else background.samples,
            background_rate_hz=None if background is None else background.sample_rate_hz,
            infer_background=True,
        )
    except ValueError as exc:  # an invalid sample rate
        raise AudioError(wav, str(exc)) from None
    detect_s = time.perf_counter() - t0
    return Listened(
        source=str(wav),
        channel=settings.channel,
        channels=track.channels,
        sample_rate_hz=track.sample_rate_hz,
        scale=detection.scale,
        detection=detection,
        spectrogram=spectrogram(track.samples, track.sample_rate_hz, 0.0, scale or 1.0),
        warnings=warnings + list(detection.warnings),
        duration_s=track.duration_s,
        speed=speed,
        speed_file=None if speed_csv is None else str(speed_csv),
        background_file=settings.background or None,
        detector=settings.detector,
        detect_s=detect_s,
    )


def write_listened(listened: Listened, out: Path) -> list[Path]:
    """heard.json, summary.txt and spectrogram.png of `listened` into `out` (created).

    Returns
    -------
    list of Path
        The files written.
    """
    import json

    from .plots import plot_listened

    out.mkdir(parents=True, exist_ok=True)
    paths = [out / HEARD_JSON, out / SUMMARY_TXT, out / SPECTROGRAM_PNG]
    paths[0].write_text(json.dumps(json_safe(listened.as_dict()), indent=1, allow_nan=False))
    paths[1].write_text("\n".join(listened.text()) + "\n")
    plot_listened(listened).savefig(paths[2], dpi=SPECTROGRAM_DPI)
    return paths


__all__ = [
    "Listened",
    "RecordingError",
    "listen_recording",
    "read_speed_csv",
    "write_listened",
]
