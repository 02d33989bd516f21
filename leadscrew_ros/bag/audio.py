# SPDX-License-Identifier: Apache-2.0
"""Microphone audio from a log (or a WAV file beside it) as one float32 track.

`read_audio` takes, decoded from the schema text the log stores (`schema`; no ROS package):

1. ros-drivers audio_common `AudioDataStamped` (raw bytes in the `AudioInfo`'s
   `sample_format`: S8, U8, S16LE/BE, U16LE/BE, S24LE/BE (packed), S32LE/BE, U32LE/BE,
   F32LE/BE, F64LE/BE; interleaved channels), with the `AudioInfo` on `<topic>_info`, on the
   named `info_topic`, or on the log's only AudioInfo topic (latched once or repeated; a chunk
   takes the latest info logged at or before it, chunks before the first info the first one);
   its unstamped `AudioData` only when the log has no stamped audio topic;
2. mgonzs13 audio_common `AudioStamped` (the info in every message; the array named by
   `info.format`, a PortAudio constant; both the nested `audio.audio_data`/`audio.info` layout
   of the repository and a flat `audio`/`info` one);
3. `std_msgs/Float32MultiArray` chunks (no sample rate in the message: `sample_rate_hz`
   when given, else the `listen.sample_rate_hz` the node recorded in the log's `leadscrew_ros`
   metadata (`logmeta`); a 2-d layout is frames x channels);
4. a WAV file (`wav`, scipy.io.wavfile: int16, int32, uint8, float32/64 read by slices from
   the file, `WavTrack`; 24-bit, which cannot be memory-mapped, read whole), starting
   `wav_start_s` after the log's first message.

Samples become float32 full scale (-1..1): integers divided by 2^(bits-1) (unsigned ones
centred first), floats as they are; the channel `channel` is taken out of the interleaved
frames. Time: a chunk's header stamp is the time of its first sample (for messages without a
header, the log time minus the chunk's duration: a capture node publishes a chunk once it is
full); `t0_s` is the first sample's time after the log's first message (any topic), the
replay's time origin. Header stamps are checked against the log times first: stamps off them by
more than `AudioSettings.resync_s` as a whole are another clock (every chunk is then placed by its
log time), a single chunk off the stream's usual offset by more than that (a jump, stamps
running backwards) is placed by its log time plus that offset. Chunks are placed one after the
other; where a stamp says a chunk starts later than the samples before it end (beyond
`stamp_tolerance_s`), the gap is kept as NaN (no sound: the detector does not score it, counted)
up to `max_gap_s`; a longer gap ends the track there; a chunk stamped earlier has its overlap
trimmed (counted).

Everything questionable in the data is one line in `AudioTrack.warnings`: NaN/inf samples
(kept as NaN: the detector does not score the frames holding them), float samples beyond full
scale, a data array other than the one the format names, a sample format that does not divide
the data (partial frame dropped), empty or undecodable messages (counted), header stamps of
zero or off the log's clock (placed by log time), a sample rate, channel count or format
changing mid-log (the first one's segment kept). What cannot be read at all raises `AudioError`, one
line: no audio topic or several, an unknown sample format, a coding format other than PCM /
wave (e.g. mp3), no AudioInfo, no sample rate for Float32MultiArray (`MissingRateError`).

Memory: a 10-min 48 kHz mono log is 29 M samples (115 MB float32), two hours 1.4 GB. Each
message is converted as it is read and its samples appended to an anonymous temporary file
(unlinked at once: nothing is left behind, even by a crash); the track is a table of that
file's pieces on the sample grid (`SpilledTrack`), which the detector reads by slices. Memory
stays bounded whatever the log's length; disk use is the track's size while it is analysed.
"""

from __future__ import annotations

import os
import tempfile
from array import array
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..model.acoustics.samples import SampleTrack
from ..model.physics.metadata import check, setting
from . import audiomsgs, logmeta, schema
from .audiomsgs import PA_FLOAT32, PA_INT8, PA_INT16, PA_INT24, PA_INT32, PA_UINT8
from .logfile import LogError, Topic
from .logsource import LogSource, log_topics, open_log

PCM_CODINGS = ("", "wave", "wav", "pcm", "raw")
# The node parameter (in the log's metadata record) that gives Float32MultiArray audio its rate
RECORDED_RATE = "listen.sample_rate_hz"
# sample_format -> (numpy dtype, offset, full scale): x = (raw - offset) / scale
SAMPLE_FORMATS: dict[str, tuple[str, float, float]] = {
    "S8": ("i1", 0, 2.0**7),
    "U8": ("u1", 2.0**7, 2.0**7),
    "S16LE": ("<i2", 0, 2.0**15),
    "S16BE": (">i2", 0, 2.0**15),
    "U16LE": ("<u2", 2.0**15, 2.0**15),
    "U16BE": (">u2", 2.0**15, 2.0**15),
    "S24LE": ("<i3", 0, 2.0**23),
    "S24BE": (">i3", 0, 2.0**23),
    "S32LE": ("<i4", 0, 2.0**31),
    "S32BE": (">i4", 0, 2.0**31),
    "U32LE": ("<u4", 2.0**31, 2.0**31),
    "U32BE": (">u4", 2.0**31, 2.0**31),
    "F32LE": ("<f4", 0, 1.0),
    "F32BE": (">f4", 0, 1.0),
    "F64LE": ("<f8", 0, 1.0),
    "F64BE": (">f8", 0, 1.0),
}
# mgonzs13: PortAudio format -> (array field, full scale)
PORTAUDIO_FORMATS = {
    PA_FLOAT32: ("float32_data", 1.0),
    PA_INT32: ("int32_data", 2.0**31),
    PA_INT24: ("int24_data", 2.0**23),
    PA_INT16: ("int16_data", 2.0**15),
    PA_INT8: ("int8_data", 2.0**7),
    PA_UINT8: ("uint8_data", 2.0**7),
}
FLOAT32_MULTI_ARRAY = "std_msgs/msg/Float32MultiArray"
DRIVERS, DRIVERS_UNSTAMPED, MGONZS13, MULTI_ARRAY, INFO = (
    "ros-drivers AudioDataStamped",
    "ros-drivers AudioData",
    "mgonzs13 AudioStamped",
    "Float32MultiArray",
    "ros-drivers AudioInfo",
)


#: The warning of non-finite samples: kept as NaN, the detector frames holding them not scored.
NONFINITE = "{n} NaN/inf samples: the detector frames holding them are not scored"


class AudioError(LogError):
    """Audio that cannot be read at all; the message is one line naming the log or file."""


class MissingRateError(AudioError):
    """Float32MultiArray audio whose rate neither the caller nor the log's metadata gives;
    `problem` says so without naming how to give it (each caller names its own option)."""


@dataclass(frozen=True)
class AudioSettings:
    """How chunks are placed on the time line (SI units; metadata as for the node's)."""

    stamp_tolerance_s: float = setting(
        0.005,
        "s",
        "a chunk stamped within this of where the samples before it end follows "
        "them directly (stamp jitter); beyond it a gap is filled or an overlap trimmed",
        0.0,
        10.0,
    )
    max_gap_s: float = setting(
        60.0,
        "s",
        "gaps between chunks up to this long are kept as no sound (NaN: not scored); a "
        "longer one ends the track (warned, and the share of the log heard is reported)",
        0.0,
        3600.0,
    )
    resync_s: float = setting(
        1.0,
        "s",
        "a chunk whose header stamp is more than this off its log time (less the stream's "
        "usual offset) is placed by its log time; stamps off by more than this as a whole "
        "are another clock, and every chunk is placed by its log time",
        0.0,
        3600.0,
        lo_open=True,
    )

    def __post_init__(self) -> None:
        check(self)


@dataclass
class AudioTrack:
    """One channel of microphone audio.

    Attributes
    ----------
    samples : numpy.ndarray or SampleTrack
        float32, full scale -1..1 (a log's: a `SpilledTrack` on disk, read by slices; a
        WAV's: an array).
    sample_rate_hz : float
        Samples per second.
    t0_s : float
        Time of the first sample after the log's first message [s] (a WAV: `wav_start_s`).
    source : str
        The topic name, or the WAV file's path.
    warnings : list of str
        One line per kind of problem found (see the module docstring).
    channels : int
        Channels of the source (a WAV file's; 1 where not known): `samples` is one of them.
    """

    samples: np.ndarray | SampleTrack
    sample_rate_hz: float
    t0_s: float
    source: str
    warnings: list[str] = field(default_factory=list)
    channels: int = 1

    @property
    def duration_s(self) -> float:
        """Length of the track [s]."""
        return self.samples.size / self.sample_rate_hz if self.sample_rate_hz else 0.0


@dataclass
class _Chunk:
    stamp_ns: int  # of the first sample: the header stamp (else from the log time)
    samples: np.ndarray  # float32, the chosen channel
    key: tuple  # (rate, channels, format): a change ends the segment
    sent_ns: int  # the log time less the chunk's duration: its stamp on the log's clock


@dataclass
class _Problems:
    """What went wrong, counted; `lines` turns it into the warnings."""

    counts: Counter = field(default_factory=Counter)
    first: dict[str, str] = field(default_factory=dict)

    def add(self, kind: str, example: str = "", n: int = 1) -> None:
        self.counts[kind] += n
        self.first.setdefault(kind, example)

    def lines(self) -> list[str]:
        texts = {
            "undecodable": "{n} audio messages not decodable, skipped (first: {e})",
            "empty": "{n} empty audio messages",
            "partial": "{n} audio messages end in a partial frame of {e}, dropped (truncated "
            "or wrong sample format?)",
            "nonfinite": NONFINITE,
            "beyond": "float samples beyond full scale (peak {e}): wrong sample format or scaling?",
            "array": "{n} messages fill another array than their format names ({e}); used it",
            "zero_stamp": "{n} audio messages have a zero header stamp; their log times used",
            "gap": "{n} gaps between chunks ({e} s in all): no sound there, not scored",
            "clock": "the audio's header stamps are {e} s off the log's clock (another clock?): "
            "every chunk placed by its log time",
            "restamped": "{n} audio messages stamped more than resync_s off their log time "
            "(a stamp jump, stamps running backwards; first at {e}): placed by their log times",
            "overlap": "{n} chunks overlap the samples before them; {e} samples trimmed",
        }
        out = []
        for kind, n in self.counts.items():
            example = self.first[kind]
            if kind == "gap":
                example = f"{float(example):.4g}"
            out.append(texts[kind].format(n=n, e=example) if kind in texts else kind)
        return out


# ----------------------------------------------------------------------------- public
def read_audio(
    log: Path | str | None = None,
    topic: str | None = None,
    info_topic: str | None = None,
    channel: int = 0,
    sample_rate_hz: float | None = None,
    wav: Path | str | None = None,
    wav_start_s: float = 0.0,
    settings: AudioSettings | None = None,
) -> AudioTrack:
    """The microphone audio of a log, or of a WAV file beside it.

    Parameters
    ----------
    log : path, optional
        MCAP file, bag directory or .db3 (`logsource.open_log`); may be None with `wav`.
    topic : str, optional
        The audio topic; by default the log's only audio-typed topic.
    info_topic : str, optional
        ros-drivers AudioInfo topic; default `<topic>_info`, else the only AudioInfo topic.
    channel : int
        Which channel of interleaved frames (0 first).
    sample_rate_hz : float, optional
        Sample rate of Float32MultiArray chunks (default: the node's `listen.sample_rate_hz`
        in the log's metadata record; ignored with a warning for typed audio that carries
        its own).
    wav : path, optional
        Read this WAV file instead of the log's audio topics.
    wav_start_s : float
        Time of the WAV's first sample after the log's first message [s].
    settings : AudioSettings, optional
        Placement of chunks (gap and jitter tolerances).

    Returns
    -------
    AudioTrack
        Samples (float32, full scale), rate, start time, source and warnings.

    Raises
    ------
    MissingRateError
        Float32MultiArray audio and no sample rate, given or recorded (give `sample_rate_hz`).
    AudioError
        No audio to read, several audio topics and none chosen, an unknown sample format, a
        compressed coding format (mp3), no AudioInfo, a bad channel.
    LogError
        The log itself cannot be read.
    """
    settings = settings or AudioSettings()
    if channel < 0:
        raise AudioError(wav or log or "audio", f"channel {channel} must be >= 0")
    if wav is not None:
        return _read_wav(Path(wav), channel, wav_start_s)
    if log is None:
        raise AudioError("audio", "give a log or a WAV file")
    source = open_log(log)
    topics = _topics(source)
    kinds = {name: k for name, t in topics.items() if (k := _kind(t)) is not None}
    name, info_name = _choose_topics(source.path, topics, kinds, topic, info_topic)
    kind = kinds[name]
    if kind == MULTI_ARRAY:
        if sample_rate_hz is None:
            sample_rate_hz = _recorded_rate(source)
        if sample_rate_hz is None:
            raise MissingRateError(
                source.path,
                f"{name} is std_msgs/Float32MultiArray, which carries no sample rate, and the "
                f"log's metadata records no {RECORDED_RATE}",
            )
        if not (sample_rate_hz > 0 and np.isfinite(sample_rate_hz)):
            raise AudioError(source.path, f"sample_rate_hz = {sample_rate_hz!r} must be > 0")
    problems = _Problems()
    warnings: list[str] = []
    if sample_rate_hz is not None and kind != MULTI_ARRAY:
        warnings.append(f"sample_rate_hz = {sample_rate_hz:g} ignored: {name} carries its own")
    parsed = {n: _schema(source.path, topics[n]) for n in (name, info_name) if n}
    convert = {
        DRIVERS: _drivers,
        DRIVERS_UNSTAMPED: _drivers,
        MGONZS13: _mgonzs13,
        MULTI_ARRAY: _multi_array,
    }[kind]
    infos: list[tuple[int, dict]] = []
    context = _Context(source.path, name, channel, sample_rate_hz, infos, info_name, problems)
    # each message converted and spilled to disk as it is read: no copy of the sound is held
    chunks = _Spill(source.path)
    waiting: list[tuple[int, dict]] = []  # ros-drivers chunks logged before the first info
    first_ns: int | None = None
    decoded = 0
    for _, m in source.messages():
        if first_ns is None:
            first_ns = m.log_time_ns
        if m.topic.name not in parsed:
            continue
        try:
            msg = parsed[m.topic.name].decode(m.data)
        except schema.CdrError as exc:
            problems.add("undecodable", str(exc))
            continue
        if m.topic.name == info_name:
            infos.append((m.log_time_ns, msg))
            for t, early in waiting:  # they take the first info
                chunks.add(convert(context, t, early))
            waiting.clear()
            continue
        decoded += 1
        if info_name and not infos:
            waiting.append((m.log_time_ns, msg))
        else:
            chunks.add(convert(context, m.log_time_ns, msg))
    if not decoded:
        raise AudioError(source.path, f"audio topic {name} has no decodable messages")
    for t, early in waiting:  # no info at all: `info_at` says so
        chunks.add(convert(context, t, early))
    if not chunks.count:
        raise AudioError(source.path, f"audio topic {name} holds no samples")
    samples, rate, t0_ns, ended = _assemble(chunks, settings, problems, first_ns or 0)
    return AudioTrack(
        samples, rate, (t0_ns - (first_ns or 0)) / 1e9, name, warnings + problems.lines() + ended
    )


def _recorded_rate(source: LogSource) -> float | None:
    """The node's `listen.sample_rate_hz` from the log's `leadscrew_ros` metadata record (the
    rate its microphone input was analysed at), or None: no MCAP record, or none readable."""
    mcaps = [f for f in source.files if f.suffix == ".mcap"]
    try:
        meta = logmeta.read(mcaps[0]) if mcaps else None
    except (OSError, ValueError):  # the replay reports an unreadable record elsewhere
        return None
    rate = meta.node.get(RECORDED_RATE) if meta else None
    return float(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) else None


# ----------------------------------------------------------------------------- topics
def _topics(source: LogSource) -> dict[str, Topic]:
    """`log_topics`, with each MCAP topic's schema text from the file summaries (which
    `log_topics` leaves out)."""
    topics = log_topics(source)
    if source.sqlite:
        return topics
    from mcap.reader import make_reader

    texts: dict[str, str] = {}
    for f in source.files:
        try:
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
        except Exception:  # damaged or cut off: log_topics read it through
            summary = None
        if summary is None:
            continue
        for c in summary.channels.values():
            s = summary.schemas.get(c.schema_id)
            if s is not None:
                texts.setdefault(c.topic, s.data.decode("utf-8", "replace"))
    return {n: t if t.schema else replace(t, schema=texts.get(n, "")) for n, t in topics.items()}


def _schema(path: Path, topic: Topic) -> schema.MessageSchema:
    """The topic's parsed schema: from the log, else the bundled audio definitions."""
    text = topic.schema
    if not text and topic.type_name in audiomsgs.TEXTS[audiomsgs.DRIVERS]:
        text = audiomsgs.definition(topic.type_name)
    elif not text and topic.type_name in audiomsgs.TEXTS[audiomsgs.MGONZS13]:
        text = audiomsgs.definition(topic.type_name, audiomsgs.MGONZS13)
    try:
        return schema.parse(text, topic.type_name)
    except schema.SchemaError as exc:
        raise AudioError(path, f"topic {topic.name}: {exc}") from None


def _kind(topic: Topic) -> str | None:
    """Which audio input a topic is (None: not audio), from its type and schema fields."""
    if topic.type_name == FLOAT32_MULTI_ARRAY:
        return MULTI_ARRAY
    if not topic.type_name.startswith("audio_common_msgs/"):
        return None
    try:
        s = _schema(Path(""), topic)
    except AudioError:
        return None
    names = {f.name: f for f in s.fields()}
    if "sample_rate" in names and "sample_format" in names:
        return INFO
    if "data" in names and names["data"].type == "uint8":
        return DRIVERS_UNSTAMPED
    audio = names.get("audio")
    if "header" not in names or audio is None or audio.type not in s.types:
        return None
    inner = {f.name for f in s.fields(audio.type)}
    if "data" in inner:
        return DRIVERS
    if {"audio_data", "info"} <= inner or (
        "info" in names and any(n.endswith("_data") for n in inner)
    ):
        return MGONZS13
    return None


def audio_topics(
    log: str | Path, topic: str | None = None, info_topic: str | None = None
) -> tuple[str, str | None]:
    """The audio topic `read_audio` reads from `log` and its AudioInfo topic (None for types
    that carry their rate, or none), from the log's index alone: a wrong name is found before
    any work.

    Parameters
    ----------
    log : path
        The log (as `read_audio`).
    topic, info_topic : str, optional
        As `read_audio`.

    Returns
    -------
    tuple of (str, str or None)
        The audio topic and the AudioInfo topic.

    Raises
    ------
    AudioError
        As `read_audio` for the choice of topics: none, several and none chosen, a name that is
        not an audio (AudioInfo) topic of the log, with the log's audio topics listed.
    LogError
        The log itself cannot be read.
    """
    source = open_log(log)
    topics = _topics(source)
    kinds = {name: k for name, t in topics.items() if (k := _kind(t)) is not None}
    return _choose_topics(source.path, topics, kinds, topic, info_topic)


def _choose_topics(
    path: Path,
    topics: dict[str, Topic],
    kinds: dict[str, str],
    topic: str | None,
    info_topic: str | None,
) -> tuple[str, str | None]:
    name = _choose_topic(path, topics, kinds, topic)
    if kinds[name] in (DRIVERS, DRIVERS_UNSTAMPED):
        return name, _choose_info(path, kinds, name, info_topic)
    return name, None


def _choose_topic(
    path: Path, topics: dict[str, Topic], kinds: dict[str, str], topic: str | None
) -> str:
    audio = sorted(n for n, k in kinds.items() if k not in (INFO, DRIVERS_UNSTAMPED))
    audio = audio or sorted(n for n, k in kinds.items() if k == DRIVERS_UNSTAMPED)
    listed = ", ".join(f"{n} ({kinds[n]})" for n in audio) or "none"
    if topic is not None:
        if topic not in topics and "/" + topic.lstrip("/") in topics:
            topic = "/" + topic.lstrip("/")
        if topic not in kinds or kinds[topic] == INFO:
            raise AudioError(
                path, f"topic {topic} is not an audio topic of this log; audio topics: {listed}"
            )
        return topic
    if not audio:
        raise AudioError(
            path,
            "no audio topic (audio_common AudioDataStamped / AudioStamped, "
            "std_msgs/Float32MultiArray); give a WAV file instead",
        )
    if len(audio) > 1:
        raise AudioError(path, f"several audio topics, choose one: {listed}")
    return audio[0]


def _choose_info(path: Path, kinds: dict[str, str], name: str, info_topic: str | None) -> str:
    infos = sorted(n for n, k in kinds.items() if k == INFO)
    if info_topic is not None:
        if info_topic not in infos and "/" + info_topic.lstrip("/") in infos:
            info_topic = "/" + info_topic.lstrip("/")
        if info_topic not in infos:
            raise AudioError(
                path,
                f"{info_topic} is not an AudioInfo topic of this log; "
                f"AudioInfo topics: {', '.join(infos) or 'none'}",
            )
        return info_topic
    if name + "_info" in infos:
        return name + "_info"
    if len(infos) == 1:
        return infos[0]
    raise AudioError(
        path,
        f"no AudioInfo for {name} (looked for {name}_info); "
        f"AudioInfo topics: {', '.join(infos) or 'none'}",
    )


# ----------------------------------------------------------------------------- chunks
@dataclass
class _Context:
    path: Path
    topic: str
    channel: int
    sample_rate_hz: float | None
    infos: list[tuple[int, dict]]
    info_topic: str | None
    problems: _Problems
    _info_times: list[int] = field(default_factory=list)

    def info_at(self, log_time_ns: int) -> dict:
        """The latest AudioInfo logged at or before `log_time_ns` (else the first one)."""
        if not self.infos:
            raise AudioError(
                self.path,
                f"no AudioInfo message on {self.info_topic} for "
                f"{self.topic}: sample rate and format unknown",
            )
        if len(self._info_times) != len(self.infos):  # infos arrive as the log is read
            self._info_times = [t for t, _ in self.infos]
        k = int(np.searchsorted(self._info_times, log_time_ns, side="right")) - 1
        return self.infos[max(k, 0)][1]

    def pick(self, frames: np.ndarray, channels: int, where: str) -> np.ndarray:
        """The chosen channel of interleaved samples (AudioError if it has no such one)."""
        if self.channel >= channels:
            raise AudioError(
                self.path,
                f"channel {self.channel} asked of {where}, which has {channels} channel(s)",
            )
        if channels == 1:
            return frames
        usable = frames.size - frames.size % channels
        if usable != frames.size:
            self.problems.add("partial", f"{frames.size % channels} samples")
        return frames[:usable].reshape(-1, channels)[:, self.channel]


def _chunk(context: _Context, msg: dict, log_time_ns: int, x: np.ndarray, key: tuple) -> _Chunk:
    """The chunk of samples `x` (rate key[0]) and its time: header stamp and log time."""
    sent = log_time_ns - int(round(x.size / key[0] * 1e9))
    header = msg.get("header")
    if header is not None:
        stamp = header["stamp"]
        ns = int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"])
        if ns:
            return _Chunk(ns, x, key, sent)
        context.problems.add("zero_stamp")
    return _Chunk(sent, x, key, sent)


def _finite(context: _Context, x: np.ndarray, is_float: bool) -> np.ndarray:
    if not is_float or x.size == 0:
        return x
    bad = ~np.isfinite(x)
    if bad.any():
        context.problems.add("nonfinite", n=int(bad.sum()))
        x = np.where(bad, np.float32(np.nan), x)  # kept: the detector does not score them
    peak = float(np.nanmax(np.abs(x))) if not bad.all() else 0.0
    if peak > 1.0:
        context.problems.add("beyond", f"{peak:.3g}")
    return x


def _to_float(raw: np.ndarray, dtype: str, offset: float, scale: float) -> np.ndarray:
    if dtype[1:] == "i3":  # packed 24-bit
        b = raw.reshape(-1, 3).astype(np.int32)
        lo, hi = (0, 2) if dtype[0] == "<" else (2, 0)
        v = b[:, lo] | (b[:, 1] << 8) | (b[:, hi] << 16)
        v = np.where(v >= 1 << 23, v - (1 << 24), v)
        return (v / scale).astype(np.float32)
    x = raw.view(np.dtype(dtype))
    if offset:
        return ((x.astype(np.float64) - offset) / scale).astype(np.float32)
    return (x / np.float32(scale)).astype(np.float32) if scale != 1.0 else x.astype(np.float32)


def _drivers(context: _Context, log_time_ns: int, msg: dict) -> _Chunk | None:
    info = context.info_at(log_time_ns)
    coding = str(info.get("coding_format", "")).strip()
    if coding.lower() not in PCM_CODINGS:
        raise AudioError(
            context.path,
            f"{context.topic} is coded as {coding!r} (compressed), "
            f"not PCM/wave: decode it to WAV and pass wav=",
        )
    fmt = str(info.get("sample_format", "")).strip().upper()
    if fmt not in SAMPLE_FORMATS:
        raise AudioError(
            context.path,
            f"{context.topic}: unknown sample_format {fmt!r}; known: {', '.join(SAMPLE_FORMATS)}",
        )
    dtype, offset, scale = SAMPLE_FORMATS[fmt]
    channels, rate = int(info.get("channels", 0)), float(info.get("sample_rate", 0))
    if channels < 1 or rate <= 0:
        raise AudioError(
            context.path, f"{context.info_topic}: {channels} channels at {rate:g} Hz is not audio"
        )
    data = (msg["audio"] if "audio" in msg else msg)["data"]
    width = int(dtype[-1])
    if data.size == 0:
        context.problems.add("empty")
        return None
    if data.size % (width * channels):
        context.problems.add("partial", f"{data.size % (width * channels)} bytes")
        data = data[: data.size - data.size % (width * channels)]
        if data.size == 0:
            return None
    x = _finite(
        context, _to_float(np.ascontiguousarray(data), dtype, offset, scale), fmt.startswith("F")
    )
    x = context.pick(x, channels, context.topic)
    return _chunk(context, msg, log_time_ns, x, (rate, channels, fmt))


def _mgonzs13(context: _Context, log_time_ns: int, msg: dict) -> _Chunk | None:
    audio = msg["audio"]
    info = audio.get("info") or msg.get("info") or {}
    arrays = audio.get("audio_data", audio)
    fmt, channels, rate = (int(info.get(k, 0)) for k in ("format", "channels", "rate"))
    filled = [n for n, v in arrays.items() if isinstance(v, np.ndarray) and v.size]
    if not filled:
        context.problems.add("empty")
        return None
    wanted = PORTAUDIO_FORMATS.get(fmt, ("", 0.0))[0]
    if wanted in filled:
        name = wanted
    else:
        name = filled[0]
        context.problems.add("array", f"format {fmt} but {name} filled")
    scale = next((s for n, s in PORTAUDIO_FORMATS.values() if n == name), None)
    if scale is None:
        raise AudioError(context.path, f"{context.topic}: unknown audio array {name}")
    if channels < 1 or rate <= 0:
        raise AudioError(
            context.path, f"{context.topic}: {channels} channels at {rate} Hz is not audio"
        )
    values = arrays[name]
    if name == "uint8_data":
        x = ((values.astype(np.float32) - 128.0) / 128.0).astype(np.float32)
    else:
        x = (
            (values / np.float32(scale)).astype(np.float32)
            if scale != 1.0
            else values.astype(np.float32)
        )
    x = context.pick(_finite(context, x, name == "float32_data"), channels, context.topic)
    return _chunk(context, msg, log_time_ns, x, (float(rate), channels, name))


def _multi_array(context: _Context, log_time_ns: int, msg: dict) -> _Chunk | None:
    data, dims = msg["data"], msg["layout"]["dim"]
    if data.size == 0:
        context.problems.add("empty")
        return None
    channels = int(dims[1]["size"]) if len(dims) == 2 and dims[1]["size"] > 0 else 1
    x = context.pick(_finite(context, data.astype(np.float32), True), channels, context.topic)
    rate = float(context.sample_rate_hz or 0)
    return _chunk(context, msg, log_time_ns, x, (rate, channels, "F32"))


# ----------------------------------------------------------------------------- timeline
class _Spill:
    """The converted chunks: their samples appended to an anonymous temporary file (deleted
    when closed), their times, sizes and keys in compact arrays (hours of 20-ms chunks are
    hundreds of thousands)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.file = tempfile.TemporaryFile(prefix="leadscrew_audio_")
        except OSError as exc:
            raise self._error(exc) from None
        self.keys: list[tuple] = []
        self._columns = {k: array("q") for k in ("stamp_ns", "sent_ns", "size", "offset", "key")}
        self._written = 0  # samples

    def _error(self, exc: OSError) -> AudioError:
        return AudioError(
            self.path,
            f"no room for the audio track in the temporary directory "
            f"({tempfile.gettempdir()}: {exc.strerror or exc}); set TMPDIR to a larger disk",
        )

    @property
    def count(self) -> int:
        """Chunks spilled."""
        return len(self._columns["size"])

    def add(self, c: _Chunk | None) -> None:
        """Append a converted chunk (None: nothing to add)."""
        if c is None:
            return
        x = np.ascontiguousarray(c.samples, dtype=np.float32)
        try:
            self.file.write(x.tobytes())
        except OSError as exc:  # a full disk: the sound is not analysed, the rest goes on
            self.file.close()
            raise self._error(exc) from None
        if c.key not in self.keys:
            self.keys.append(c.key)
        for name, value in (
            ("stamp_ns", c.stamp_ns),
            ("sent_ns", c.sent_ns),
            ("size", x.size),
            ("offset", self._written),
            ("key", self.keys.index(c.key)),
        ):
            self._columns[name].append(value)
        self._written += x.size

    def column(self, name: str) -> np.ndarray:
        """One column of the table as an int64 array."""
        return np.frombuffer(self._columns[name], dtype=np.int64)


class SpilledTrack(SampleTrack):
    """A log's track on disk: the pieces of the spill file in their places on the sample grid
    (a gap is NaN), read by slices (`acoustics.samples`). The file (unlinked already) goes when
    the track is collected."""

    def __init__(self, file: Any, pieces: list[tuple[int, int]]) -> None:
        self._file = file
        self._source = np.array([p[0] for p in pieces], dtype=np.int64)  # -1: a gap
        lengths = np.array([p[1] for p in pieces], dtype=np.int64)
        self._starts = np.concatenate([[0], np.cumsum(lengths)])

    @property
    def size(self) -> int:
        """Number of samples."""
        return int(self._starts[-1])

    def read(self, start: int, stop: int) -> np.ndarray:
        """Samples [start, stop) as a new float32 array (NaN in gaps)."""
        out = np.empty(stop - start, np.float32)
        k = int(np.searchsorted(self._starts, start, side="right")) - 1
        at = start
        while at < stop:
            a, b = at - int(self._starts[k]), min(stop, int(self._starts[k + 1]))
            if self._source[k] < 0:
                out[at - start : b - start] = np.nan
            else:
                first = (int(self._source[k]) + a) * 4
                data = os.pread(self._file.fileno(), (b - at) * 4, first)
                out[at - start : b - start] = np.frombuffer(data, np.float32)
            at, k = b, k + 1
        return out


def _assemble(
    chunks: _Spill, settings: AudioSettings, problems: _Problems, first_ns: int
) -> tuple[SpilledTrack, float, int, list[str]]:
    """Place the chunks of the first (rate, channels, format) segment on one sample grid:
    a table of pieces of the spill file (contiguous ones joined) and gaps."""
    stamp = _on_log_clock(chunks, settings, problems, first_ns)
    order = np.argsort(stamp, kind="stable")
    sizes, offsets, keys = chunks.column("size"), chunks.column("offset"), chunks.column("key")
    key = int(keys[order[0]])
    rate = chunks.keys[key][0]
    t0_ns = int(stamp[order[0]])
    tolerance = settings.stamp_tolerance_s * rate
    pieces: list[tuple[int, int]] = []
    placed, gap_samples, trimmed = 0, 0, 0
    ended: list[str] = []

    def at(ns: int) -> str:
        return f"t = {(ns - first_ns) / 1e9:.3f} s"

    def piece(source: int, length: int) -> None:
        if pieces and pieces[-1][0] >= 0 and pieces[-1][0] + pieces[-1][1] == source:
            pieces[-1] = (pieces[-1][0], pieces[-1][1] + length)  # the next in the file
        elif length:
            pieces.append((source, length))

    for k, i in enumerate(order.tolist()):
        if int(keys[i]) != key:
            what = _describe_change(chunks.keys[key], chunks.keys[int(keys[i])])
            ended.append(
                f"{what} at {at(int(stamp[i]))}: the first segment kept, {len(order) - k} "
                f"messages after it ignored"
            )
            break
        offset = int(round((int(stamp[i]) - t0_ns) * rate / 1e9)) - placed
        source, size = int(offsets[i]), int(sizes[i])
        if offset > tolerance:
            if offset > settings.max_gap_s * rate:
                ended.append(
                    f"a gap of {offset / rate:.3g} s at {at(int(stamp[i]))} (> max_gap_s "
                    f"{settings.max_gap_s:g} s): the track ends there, "
                    f"{len(order) - k} messages after it ignored"
                )
                break
            pieces.append((-1, offset))
            placed += offset
            gap_samples += offset
            problems.add("gap", "0")
        elif offset < -tolerance:
            cut = min(-offset, size)
            trimmed += cut
            problems.add("overlap", "0")
            source, size = source + cut, size - cut
        piece(source, size)
        placed += size
    if gap_samples:
        problems.first["gap"] = str(gap_samples / rate)
    if trimmed:
        problems.first["overlap"] = str(trimmed)
    chunks.file.flush()
    return SpilledTrack(chunks.file, pieces), rate, t0_ns, ended


def _on_log_clock(
    chunks: _Spill, settings: AudioSettings, problems: _Problems, first_ns: int
) -> np.ndarray:
    """The chunks' stamps [ns] the log's clock can vouch for: header stamps that are off the
    log times by more than `resync_s` as a whole (another clock: a device's boot time, sim
    time) are all replaced by the log times; single chunks off by more than that from the
    stream's usual offset (a jump, stamps running backwards) by their log time plus it."""
    stamp, sent = chunks.column("stamp_ns").copy(), chunks.column("sent_ns")
    offsets = (stamp - sent).astype(np.float64)
    usual = float(np.median(offsets))
    limit = settings.resync_s * 1e9
    if abs(usual) > limit:
        problems.add("clock", f"{usual / 1e9:+.4g}")
        return sent.copy()
    off = np.flatnonzero(np.abs(offsets - usual) > limit)
    if off.size:
        problems.add("restamped", f"t = {(int(sent[off[0]]) - first_ns) / 1e9:.3f} s", off.size)
        stamp[off] = sent[off] + int(round(usual))
    return stamp


def _describe_change(old: tuple, new: tuple) -> str:
    names = ("sample rate", "channel count", "sample format")
    for name, a, b in zip(names, old, new, strict=True):
        if a != b:
            shown: Callable[[Any], str] = (lambda v: f"{v:g} Hz") if name == "sample rate" else str
            return f"{name} changed from {shown(a)} to {shown(b)}"
    return "stream changed"


# ----------------------------------------------------------------------------- WAV
def _read_wav(path: Path, channel: int, start_s: float) -> AudioTrack:
    from scipy.io import wavfile

    track: WavTrack | np.ndarray
    try:  # a memory map gives the layout; the samples are then read by slices (`WavTrack`)
        rate, data = wavfile.read(path, mmap=True)
        mapped = True
    except ValueError:  # 24-bit samples cannot be mapped: read whole (as int32, shifted up)
        mapped = False
        try:
            rate, data = wavfile.read(path)
        except (OSError, ValueError, EOFError) as exc:
            raise AudioError(path, f"not a readable WAV file: {exc}") from None
    except (OSError, EOFError) as exc:
        raise AudioError(path, f"not a readable WAV file: {exc}") from None
    dtype, shape = data.dtype, data.shape
    channels = shape[1] if len(shape) == 2 else 1
    if channel >= channels:
        raise AudioError(
            path,
            f"channel {channel} asked of a {channels}-channel WAV"
            if channels > 1
            else f"channel {channel} asked of a mono WAV",
        )
    if dtype.kind not in "uif" or (dtype.kind == "u" and dtype.itemsize != 1):
        raise AudioError(path, f"WAV samples of type {dtype} are not audio")
    if mapped:
        offset = int(data.offset)
        del data  # unmapped: its pages would count as the process's memory as they are read
        track = WavTrack(path, offset, dtype, channels, channel, shape[0])
    else:
        track = _pcm_to_float(data[:, channel] if channels > 1 else data)
    warnings: list[str] = []
    if dtype.kind == "f":
        bad, peak = 0, 0.0
        for i in range(0, track.size, WAV_BLOCK):  # one pass by blocks: bounded memory
            x = track[i : i + WAV_BLOCK]
            finite = np.isfinite(x)
            bad += int(x.size - np.count_nonzero(finite))
            if finite.any():
                peak = max(peak, float(np.max(np.abs(x[finite]))))
        if bad:
            warnings.append(NONFINITE.format(n=bad))
        if peak > 1.0:
            warnings.append(f"float samples beyond full scale (peak {peak:.3g}): wrong scaling?")
    if track.size == 0:
        warnings.append("the WAV file holds no samples")
    return AudioTrack(track, float(rate), float(start_s), str(path), warnings, channels)


WAV_BLOCK = 1 << 20  # samples per read of a WAV's checking pass


def _pcm_to_float(x: np.ndarray) -> np.ndarray:
    """WAV samples as float32 full scale: integers divided by 2^(bits-1) (8-bit unsigned
    centred first), floats with NaN for inf."""
    if x.dtype.kind == "u":
        return ((x.astype(np.float32) - 128.0) / 128.0).astype(np.float32)
    if x.dtype.kind == "i":
        return (x / np.float32(2.0 ** (8 * x.dtype.itemsize - 1))).astype(np.float32)
    y = x.astype(np.float32)
    return np.where(np.isfinite(y), y, np.float32(np.nan))


class WavTrack(SampleTrack):
    """One channel of a PCM WAV file read by slices from its data chunk (`acoustics.samples`):
    integers divided by 2^(bits-1) (8-bit unsigned centred first), floats as float32 with
    NaN for inf.

    Parameters
    ----------
    path : Path
        The WAV file (kept open).
    offset : int
        Byte offset of its data chunk.
    dtype : numpy.dtype
        The sample type (byte order included).
    channels, channel : int
        Interleaved channels, and the one read.
    frames : int
        Frames in the data chunk.
    """

    def __init__(
        self, path: Path, offset: int, dtype: np.dtype, channels: int, channel: int, frames: int
    ) -> None:
        self._file = open(path, "rb")  # closed when the track is collected
        self._offset, self._dtype = offset, np.dtype(dtype)
        self._channels, self._channel, self._frames = channels, channel, frames

    @property
    def size(self) -> int:
        """Number of samples (frames)."""
        return self._frames

    def read(self, start: int, stop: int) -> np.ndarray:
        """Samples [start, stop) of the channel as a new float32 array."""
        width = self._dtype.itemsize * self._channels
        raw = os.pread(self._file.fileno(), (stop - start) * width, self._offset + start * width)
        return _pcm_to_float(np.frombuffer(raw, self._dtype)[self._channel :: self._channels])


class LiveAudio:
    """The node's decoder of live ros-drivers AudioDataStamped chunks: the latest AudioInfo
    (sample rate, channels, sample format, coding) gives their samples, as `read_audio` reads
    them from a log (the same conversion, `_drivers`). rclpy-free: the node hands it the raw
    CDR payloads, `info` those of AudioInfo and a call those of each chunk.

    Parameters
    ----------
    channel : int
        The channel analysed (0: the first).
    """

    def __init__(self, channel: int = 0) -> None:
        self.channel = channel
        self.error = ""  # why the last AudioInfo was not taken ('' if it was)
        self._info: dict | None = None

    def info(self, payload: bytes) -> None:
        """Take an AudioInfo payload; a malformed one keeps the last good info (`error` says
        why), as this runs in a subscription callback.

        Parameters
        ----------
        payload : bytes
            The CDR payload of an audio_common_msgs/msg/AudioInfo.
        """
        try:
            self._info = audiomsgs.message_schema(audiomsgs.AUDIO_INFO).decode(payload)
            self.error = ""
        except ValueError as exc:
            self.error = f"AudioInfo not taken: {exc}"

    def __call__(self, payload: bytes) -> tuple[np.ndarray, float]:
        """The samples of an AudioDataStamped payload.

        Parameters
        ----------
        payload : bytes
            The CDR payload of an audio_common_msgs/msg/AudioDataStamped.

        Returns
        -------
        samples : numpy.ndarray
            float32 in full scale (-1..1), the chosen channel.
        rate : float
            The sample rate [Hz] of the latest AudioInfo.

        Raises
        ------
        ValueError
            No AudioInfo yet, a coding other than PCM, an unknown sample format, an empty or
            malformed payload (the listener counts it as malformed).
        """
        if self._info is None:
            raise ValueError("no AudioInfo yet: sample rate and format unknown")
        context = _Context(
            Path("live"), "audio", self.channel, None, [(0, self._info)], "audio_info", _Problems()
        )
        try:
            msg = audiomsgs.message_schema(audiomsgs.AUDIO_DATA_STAMPED).decode(payload)
            chunk = _drivers(context, 0, msg)
        except AudioError as exc:
            raise ValueError(exc.problem) from None
        if chunk is None:
            raise ValueError("empty audio message")
        return chunk.samples, float(chunk.key[0])
