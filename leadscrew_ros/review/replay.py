# SPDX-License-Identifier: Apache-2.0
"""Offline replay of a log: the node's predictions recomputed for the whole log.

read the log (`logsource`: MCAP via `logfile`, or rosbag2 sqlite3 .db3; strict: a damaged or
foreign file is a one-line `LogError`) -> input topics resolved in the log's input namespace
(`timeline.is_input`, as `replay --publish` selects them) ->
operating-point timeline with the node's deadbands (`timeline`) -> batched predictions with
the model's parameters and scatter (`timeline.ModelSpec`), in worker processes for long logs
-> squeak episodes and P(squeak) over time -> `<log>.annotated.mcap`: every original message
copied verbatim (channel, schema, times, sequence, bytes) plus the predictions on
`<out namespace>/squeak/{risk,margin,unstable_frequencies,active,modes}` with the node's types
(`bag.messages.PREDICTION_TOPICS`; squeak/risk is P(squeak)), each at the log time of the input
that triggered it; `episodes.json`, `summary.json` and `summary.txt`. Once they are written,
the annotated log gets `episodes.json` and `summary.json` as MCAP Attachments (the report adds
its PNGs: `attach`), the input log's `leadscrew_ros` metadata record (of its first file, as it
is) and a `leadscrew_ros.replay` record of the replay's model, scatter and inputs (`logmeta`),
so that one file holds the evidence.

P(squeak) over time is the node's: a recompute's probability holds until the next recompute
(none outside validity), and to the end of the log after the last one. Peak probability and
the time at or above the WARN and ERROR probabilities (`LiveSettings.warn_probability`,
`error_probability`, given in `InputSettings`) are counted over the log and per episode.

Memory does not grow with the log: messages stream through in segments (a segment is written
once its predictions are back, reading overlaps with the eigen-solves, at most
`_IN_FLIGHT_MESSAGES` held); episodes go to episodes.json as they end (the first
`EPISODES_KEPT` stay in the result); what the report draws is binned or sampled to a fixed size
(`decimation`).
"""

from __future__ import annotations

import json
import math
import multiprocessing
import re
import sys
import textwrap
import time
from collections import Counter, deque
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, TextIO

import numpy as np

from ..bag import logmeta, messages, msgdefs
from ..bag.logfile import LogError, LogMessage, Topic, metadata_problem
from ..bag.logsource import LogSource, log_topics, open_log, topic_types
from ..bag.mcapout import CHUNK_BYTES, McapOut
from ..model import SqueakModel
from ..model.uncertainty.scatter import LOG_NORMAL
from . import worker
from .commands import CommandTrace
from .decimation import Envelope, Reservoir
from .jsonsafe import json_safe
from .listen import Heard, PredictionTrace, SoundSettings, SpeedTrace, listen, write_heard
from .plots import plot_timeline
from .progress import progress_bar
from .timeline import (
    InputError,
    InputSettings,
    Job,
    ModelSpec,
    Timeline,
    _spec_model,
    input_namespaces,
)
from .worker import Payloads, Verdict, solve

if TYPE_CHECKING:
    from matplotlib.figure import Figure

DEFAULT_NAMESPACE = "/replay"
_BATCH_JOBS = 256  # predictions per batched solve (one worker task)
_SEGMENT_MESSAGES = 20_000  # a segment without predictions is written at this size
# Messages held while their predictions are computed (~250 bytes each): enough to read on
# through a rest while the workers solve the stroke before it.
_IN_FLIGHT_MESSAGES = 250_000
_CHUNK_BYTES = CHUNK_BYTES  # annotated MCAP chunk: buffered until this size, then compressed
EPISODES_KEPT = 1000  # episodes kept in the result (all of them in episodes.json)
_FREQUENCIES_KEPT = 512  # frequencies per mode and episode kept for its median
_NAME = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")
MAX_WORKERS = 64  # prediction processes (each ~170 MB): more only thrash a machine
MEDIA_TYPES = {".json": "application/json", ".png": "image/png"}  # of the attachments


@dataclass(frozen=True)
class ReplaySettings:
    """How a log is replayed (`replay`).

    Attributes
    ----------
    inputs : InputSettings
        Where the inputs are, the deadbands and the P(squeak) thresholds.
    namespace : str or None
        Of the inputs; None: the log's single input namespace.
    out_namespace : str or None
        Of the predictions; None: /replay + the input namespace.
    workers : int
        Prediction processes for long logs (0: all in this process).
    progress : bool
        A progress bar on stderr (a terminal only).
    listen : SoundSettings
        Where the sound of the drive is, its scale, the comparison of formulations.
    """

    inputs: InputSettings = field(default_factory=InputSettings)
    namespace: str | None = None
    out_namespace: str | None = None
    # Two workers: on a 2-core machine a log whose nut moves at every message keeps both busy
    # solving while this process reads and writes; where reading is the bottleneck (a log
    # mostly at rest) the second one idles.
    workers: int = 2
    progress: bool = True
    listen: SoundSettings = field(default_factory=SoundSettings)

    def __post_init__(self) -> None:
        for what, ns in (("namespace", self.namespace), ("output namespace", self.out_namespace)):
            if ns is not None and ns != "/" and not _NAME.fullmatch(ns):
                raise ValueError(f"{what} must be a ROS name like /seat_left, got {ns!r}")
        if not 0 <= self.workers <= MAX_WORKERS:
            raise ValueError(f"workers must be in [0, {MAX_WORKERS}], got {self.workers}")


@dataclass
class ProbabilityTime:
    """P(squeak) as published over an interval: its peak and the time it was at or above the
    WARN and ERROR probabilities (seconds; times from the log's first message)."""

    peak: float | None = None  # max P(squeak) [1]; None without a prediction
    peak_t_s: float | None = None  # when it was first reached
    above_warn_s: float = 0.0  # P >= warn_probability
    above_error_s: float = 0.0  # P >= error_probability

    def sample(self, t_s: float, probability: float) -> None:
        """A recompute's probability at time `t_s`."""
        if self.peak is None or probability > self.peak:
            self.peak, self.peak_t_s = probability, t_s

    def hold(self, probability: float, duration_s: float, warn: float, error: float) -> None:
        """`probability` held for `duration_s`."""
        if probability >= warn:
            self.above_warn_s += duration_s
        if probability >= error:
            self.above_error_s += duration_s

    def as_dict(self) -> dict[str, Any]:
        """The figures as a JSON-ready dict (times in s)."""
        return {
            "peak_probability": self.peak,
            "peak_probability_t_s": self.peak_t_s,
            "time_above_warn_s": self.above_warn_s,
            "time_above_error_s": self.above_error_s,
        }


@dataclass
class Episode:
    """A contiguous interval with squeak predicted at the nominal parameters (as squeak/active;
    seconds from the log's first message), and its P(squeak)."""

    start_s: float
    end_s: float
    peak_growth_rate: float  # 1/s
    speed_range_rad_s: tuple[float, float]
    load_range_n: tuple[float, float]
    predictions: int
    probability: ProbabilityTime = field(default_factory=ProbabilityTime)
    # mode -> Hz seen: every `stride`-th value, at most _FREQUENCIES_KEPT (bounded memory)
    frequencies: dict[str, list[float]] = field(default_factory=dict)
    _strides: Counter = field(default_factory=Counter, repr=False, compare=False)
    _seen: Counter = field(default_factory=Counter, repr=False, compare=False)

    def add_frequency(self, label: str, hz: float) -> None:
        """Keep every stride-th frequency of the mode; when full, every other and twice the
        stride (the median of a long episode from an even sample of it)."""
        stride = self._strides[label] or 1
        if self._seen[label] % stride == 0:
            kept = self.frequencies.setdefault(label, [])
            kept.append(hz)
            if len(kept) >= _FREQUENCIES_KEPT:
                del kept[1::2]
                self._strides[label] = 2 * stride
        self._seen[label] += 1

    @property
    def modes(self) -> list[str]:
        """Squeak modes, by median frequency."""
        return sorted(self.frequencies, key=lambda label: np.median(self.frequencies[label]))

    @property
    def frequencies_hz(self) -> list[float]:
        """The distinct squeak frequencies: each mode's median frequency, ascending."""
        return [float(np.median(self.frequencies[label])) for label in self.modes]

    def as_dict(self) -> dict[str, Any]:
        """The episode as a JSON-ready dict (times in s from the log's start)."""
        return {
            "start_s": self.start_s,
            "end_s": self.end_s,
            "duration_s": self.end_s - self.start_s,
            "frequencies_hz": self.frequencies_hz,
            "modes": self.modes,
            "peak_growth_rate": self.peak_growth_rate,
            "speed_min_rad_s": self.speed_range_rad_s[0],
            "speed_max_rad_s": self.speed_range_rad_s[1],
            "load_min_n": self.load_range_n[0],
            "load_max_n": self.load_range_n[1],
            "predictions": self.predictions,
            **self.probability.as_dict(),
        }


@dataclass
class PlotData:
    """What the report draws, in constant memory (seconds from the log's first message)."""

    # Per recompute: P(squeak) (NaN without prediction) and squeak at the nominal parameters
    # (1/0), binned over time.
    probability: Envelope = field(default_factory=lambda: Envelope(2))
    # Valid predictions: speed, load, nut position, squeak (1/0); a uniform sample.
    points: Reservoir = field(default_factory=lambda: Reservoir(4))
    # Squeak frequencies: speed, load, nut position, frequency [Hz]; a uniform sample.
    squeak: Reservoir = field(default_factory=lambda: Reservoir(4))

    def add(self, t: float, job: Job, p: Verdict) -> None:
        """Add the verdict `p` of `job`, predicted at `t` [s]."""
        squeak = p.valid and not p.stable
        probability = math.nan
        if p.valid:
            assert p.probability is not None  # a valid prediction has one
            probability = p.probability
        self.probability.add(t, probability, float(squeak))
        if p.valid:
            self.points.add(p.speed_rad_s, p.load_n, job.nut_position_m, float(squeak))
        for _, hz, _ in p.squeak:
            self.squeak.add(p.speed_rad_s, p.load_n, job.nut_position_m, hz)


@dataclass
class ReplayResult:
    """The offline replay of one log (`replay`): counts, squeak episodes, P(squeak) over time
    and what the report draws; `plot` draws its timeline. Times are seconds from the log's
    first message.

    Attributes
    ----------
    log : Path
        The log replayed (file or bag directory).
    files : list of Path
        Its files, in order.
    out_dir : Path
        The output directory.
    annotated : Path
        The annotated log written there.
    start_ns : int
        Log time of the first message [ns]: t = 0.
    duration_s : float
        To the last message [s].
    messages : int
        Original messages.
    inputs : Counter
        Input messages per topic.
    recomputes : int
        Operating points that moved beyond the deadbands.
    predictions : int
        Recomputes with a prediction (valid points).
    no_prediction : Counter
        Recomputes outside validity, by `Validity.label`.
    rejected : Counter
        Input values not taken, by reason.
    ignored : Counter
        joint_states messages ignored (no joint_name, no joint).
    episodes : list of Episode
        The first `EPISODES_KEPT` squeak episodes.
    episode_count : int
        All of them (in episodes.json).
    time_in_squeak_s : float
        Time with squeak predicted at the nominal parameters [s].
    probability : ProbabilityTime
        P(squeak) over the whole log.
    plot_data : PlotData
        What the report draws, binned or sampled to a fixed size.
    timeline : Timeline
        Counters, and the inputs over time (binned).
    namespace : str
        Of the inputs.
    out_namespace : str
        Of the predictions in the annotated log.
    warn_probability, error_probability : float
        The WARN and ERROR probabilities the times above are counted against.
    scatter : dict of str to float
        `Scatter.sd` of P(squeak).
    scatter_samples : int
        Samples of P(squeak).
    wall_s : float
        Wall time of the replay [s].
    outputs : list of Path
        The files written.
    heard : Heard or None
        What the microphone heard and how the predictions agree with it (`listen`); None
        without sound.
    audio_warnings : list of str
        Why the log's audio was not analysed, if it was not.
    commands : CommandTrace or None
        The squeak guard's raw and guarded speed command (`review.commands`); None when the
        log has neither.
    metadata_problem : str
        What is wrong with the bag directory's metadata.yaml, and how to mend it ('' if
        nothing, or not a bag directory): the files were read, but other tools refuse it.
    """

    log: Path
    files: list[Path]
    out_dir: Path
    annotated: Path
    start_ns: int
    duration_s: float
    messages: int
    inputs: Counter
    recomputes: int
    predictions: int
    no_prediction: Counter
    rejected: Counter
    ignored: Counter
    episodes: list[Episode]
    episode_count: int
    time_in_squeak_s: float
    probability: ProbabilityTime
    plot_data: PlotData
    timeline: Timeline
    namespace: str = "/"
    out_namespace: str = DEFAULT_NAMESPACE
    warn_probability: float = InputSettings.warn_probability
    error_probability: float = InputSettings.error_probability
    scatter: dict[str, float] = field(default_factory=dict)
    scatter_samples: int = 0
    wall_s: float = math.nan
    outputs: list[Path] = field(default_factory=list)
    heard: Heard | None = None
    audio_warnings: list[str] = field(default_factory=list)
    commands: CommandTrace | None = None
    metadata_problem: str = ""

    def plot(self, fig: Figure | None = None) -> Figure:
        """The timeline: speed, load, nut position and P(squeak) over time (`plot_timeline`).

        Parameters
        ----------
        fig : Figure, optional
            The figure to draw the panels into; default: a new figure.

        Returns
        -------
        Figure
            The figure drawn into.
        """
        return plot_timeline(self, fig=fig)

    @property
    def warnings(self) -> list[str]:
        """Sample-time problems: stale (backwards) and duplicated input times (header stamps
        or log times, `timeline`), per topic; a
        broken metadata.yaml."""
        tl, out = self.timeline, [self.metadata_problem] if self.metadata_problem else []
        clock = {t: "header stamp" if t in tl.stamped else "log time" for t in tl.inputs}
        for topic, n in sorted(tl.backwards.items()):
            out.append(
                f"{clock[topic]} goes backwards {n} time(s) on {topic} (up to "
                f"{tl.backwards_max_s:.6g} s): those messages were not applied"
            )
        for topic, n in sorted(tl.duplicates.items()):
            out.append(f"{clock[topic]} repeats {n} time(s) on {topic} (the later value applied)")
        return out + self.audio_warnings

    @property
    def x_real_time(self) -> float:
        """Log duration / wall time of the replay (x real time)."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else math.inf

    def summary(self) -> dict[str, Any]:
        """The replay in numbers (summary.json).

        Returns
        -------
        dict
            Counts, P(squeak) times, settings, warnings, wall time.
        """
        return {
            "log": str(self.log),
            "files": [str(f) for f in self.files],
            "annotated": str(self.annotated),
            "duration_s": self.duration_s,
            "messages": self.messages,
            "input_messages": dict(self.inputs),
            "recomputes": self.recomputes,
            "predictions": self.predictions,
            "no_prediction": dict(self.no_prediction),
            "rejected_inputs": dict(self.rejected),
            "rejected_examples": dict(self.timeline.rejected_example),
            "ignored_inputs": dict(self.ignored),
            "ignored_examples": dict(self.timeline.ignored_example),
            "episodes": self.episode_count,
            "time_in_squeak_s": self.time_in_squeak_s,
            **self.probability.as_dict(),
            "warn_probability": self.warn_probability,
            "error_probability": self.error_probability,
            "scatter": self.scatter,
            "scatter_samples": self.scatter_samples,
            "namespace": self.namespace,
            "out_namespace": self.out_namespace,
            "log_time": {
                "backwards": dict(self.timeline.backwards),
                "backwards_max_s": self.timeline.backwards_max_s,
                "duplicates": dict(self.timeline.duplicates),
            },
            "metadata_problem": self.metadata_problem,
            "warnings": self.warnings,
            "heard": self.heard.as_dict() if self.heard else None,
            "agreement_by_formulation": self.heard.by_formulation_dict() if self.heard else None,
            "detect_wall_s": self.heard.detect_s if self.heard else None,
            "speed_commands": self.commands.as_dict() if self.commands else None,
            "squeak_share": self._share(self.time_in_squeak_s),
            "warn_share": self._share(self.probability.above_warn_s),
            "wall_s": self.wall_s,
            "x_real_time": self.x_real_time,
        }

    def _share(self, seconds: float) -> float:
        """`seconds` as a share of the log's duration."""
        return seconds / self.duration_s if self.duration_s > 0 else 0.0

    def probability_text(self) -> str:
        """Peak P(squeak) and the time at or above WARN and ERROR.

        Returns
        -------
        str
            One line.
        """
        pt = self.probability
        if pt.peak is None:
            return "P(squeak): no prediction"
        return (
            f"P(squeak): peak {pt.peak:.3f} at {pt.peak_t_s:.2f} s; >= WARN "
            f"{self.warn_probability:g} for {pt.above_warn_s:.2f} s "
            f"({100 * self._share(pt.above_warn_s):.1f} % of the log), >= ERROR "
            f"{self.error_probability:g} for {pt.above_error_s:.2f} s"
        )

    def scatter_text(self) -> str:
        """The scatter P(squeak) is taken over.

        Returns
        -------
        str
            One line.
        """
        if not self.scatter:
            return "scatter: none (P(squeak) is the nominal verdict, 0 or 1)"
        log_normal = [name for name in self.scatter if name in LOG_NORMAL]
        return (
            "scatter: "
            + ", ".join(f"{name} {sd:g}" for name, sd in self.scatter.items())
            + " (relative SD"
            + (f"; SD of ln for {', '.join(log_normal)}" if log_normal else "")
            + f"), {self.scatter_samples} samples"
        )

    def summary_text(self) -> str:
        """The replay in words (summary.txt).

        Returns
        -------
        str
            One line per item, no final newline.
        """
        lines = [
            f"replay of {self.log}: {len(self.files)} file(s), {self.messages} messages "
            f"over {self.duration_s:.1f} s",
            "input messages: " + (", ".join(f"{k} {v}" for k, v in self.inputs.items()) or "none"),
            f"recomputes: {self.recomputes} ({self.predictions} with a prediction)",
            f"squeak episodes: {self.episode_count}, time in squeak "
            f"{self.time_in_squeak_s:.2f} s ({100 * self._share(self.time_in_squeak_s):.1f}"
            " % of the log)",
            self.probability_text(),
            self.scatter_text(),
        ]
        lines += self.heard.text() if self.heard else []
        lines += self.commands.text() if self.commands else []
        examples = {**self.timeline.rejected_example, **self.timeline.ignored_example}
        for title, counts in (
            ("no prediction (outside the model's validity)", self.no_prediction),
            ("rejected inputs", self.rejected),
            ("ignored inputs", self.ignored),
        ):
            lines += [
                f"{title}: {n} x {reason}"
                + (f" (first: {examples[reason]})" if reason in examples else "")
                for reason, n in sorted(counts.items())
            ]
        lines += [f"warning: {w}" for w in self.warnings]
        lines.append(f"wall time {self.wall_s:.2f} s ({ratio_text(self.x_real_time)} real time)")
        lines.append(f"annotated log: {self.annotated}")
        return "\n".join(lines)


def ratio_text(x: float) -> str:
    """A speed-up such as 'x real time' to two significant digits, whole above 10: '0.20x',
    '0.0040x', '3.5x', '154x' (a slow replay is never '0x')."""
    if not (math.isfinite(x) and x > 0):
        return f"{x:g}x"
    return f"{x:.{max(0, 1 - math.floor(math.log10(x)))}f}x"


def log_name(path: Path) -> str:
    """`run.mcap` -> `run`, a bag directory -> its name."""
    path = Path(path)
    return path.stem if path.is_file() else path.resolve().name


# ---------------------------------------------------------------------- the annotated log


class _AnnotatedWriter:
    """Original channels copied as they are, plus the prediction topics under `namespace`."""

    def __init__(self, fh: BinaryIO, namespace: str):
        self.writer = McapOut(fh, "ros2", "leadscrew_ros replay", _CHUNK_BYTES)
        self._schemas: dict[tuple[str, str, str], int] = {}
        self._channels: dict[int, tuple[Topic, int]] = {}  # id(topic) -> topic, channel
        self._by_value: dict[tuple, int] = {}
        self._outputs = [
            self._channel(
                Topic(
                    f"{namespace}/{topic}",
                    messages.OUTPUT_TYPES[topic],
                    "ros2msg",
                    msgdefs.definition(messages.OUTPUT_TYPES[topic]),
                    "cdr",
                    {"offered_qos_profiles": ""},
                )
            )
            for topic in messages.PREDICTION_TOPICS
        ]
        self._sequence = -1  # of the predictions: 0, 1, ... on every topic

    def _channel(self, t: Topic) -> int:
        key = (
            t.name,
            t.stored_schema_name,
            t.schema_encoding,
            t.schema,
            t.message_encoding,
            tuple(sorted(t.metadata.items())),
        )
        if key not in self._by_value:
            schema_key = (t.stored_schema_name, t.schema_encoding, t.schema)
            if schema_key not in self._schemas:
                self._schemas[schema_key] = self.writer.register_schema(
                    t.stored_schema_name, t.schema_encoding, t.schema.encode()
                )
            self._by_value[key] = self.writer.register_channel(
                t.name, t.message_encoding, self._schemas[schema_key], dict(t.metadata)
            )
        return self._by_value[key]

    def original(self, m: LogMessage) -> None:
        entry = self._channels.get(id(m.topic))
        if entry is None:  # holding the topic keeps its id from being reused
            entry = self._channels[id(m.topic)] = (m.topic, self._channel(m.topic))
        self.writer.add_message(entry[1], m.log_time_ns, m.data, m.publish_time_ns, m.sequence)

    def prediction(self, log_time_ns: int, payloads: Payloads) -> None:
        """One prediction: `payloads` of `messages.PREDICTION_TOPICS`, in that order."""
        self._sequence += 1
        add = self.writer.add_message
        for channel, data in zip(self._outputs, payloads, strict=True):
            add(channel, log_time_ns, data, log_time_ns, self._sequence)

    def finish(self) -> None:
        self.writer.finish()


# ---------------------------------------------------------------------- predictions
@dataclass
class _Segment:
    messages: list[LogMessage] = field(default_factory=list)
    jobs: list[Job] = field(default_factory=list)
    solved: Future | tuple[list[Verdict], list[Payloads | None]] | None = None
    args: tuple = ()  # of solve

    def done(self) -> bool:
        return not isinstance(self.solved, Future) or self.solved.done()

    def result(self) -> tuple[list[Verdict], list[Payloads | None]]:
        """The verdicts of the jobs and their payloads."""
        solved = self.solved
        if isinstance(solved, Future):
            try:
                solved = solved.result()
            except BrokenProcessPool:  # a worker died (killed, out of memory): solve here
                solved = solve(*self.args)
            self.solved = solved
        assert solved is not None  # submitted (`_Solver.submit`) before it is written
        return solved


class _Solver:
    """Batched predictions: in this process for short logs; from the second batch on (a long
    log) in `workers` spawned processes, while this one reads and writes."""

    def __init__(self, model: SqueakModel, workers: int):
        self.spec, self.workers = ModelSpec.of(model), workers
        self.batches = 0
        self.pool: ProcessPoolExecutor | None = None

    def submit(self, seg: _Segment) -> None:
        if not seg.jobs:
            seg.solved = [], []
            return
        seg.args = (
            self.spec,
            *(
                np.array([getattr(j, f) for j in seg.jobs])
                for f in ("speed_rad_s", "load_n", "model_nut_m")
            ),
        )
        self.batches += 1
        if self.workers and self.batches > 1 and self.pool is None:
            # spawn, not fork: the parent holds BLAS and tqdm threads
            self.pool = ProcessPoolExecutor(
                self.workers,
                multiprocessing.get_context("spawn"),
                initializer=worker.start,
                initargs=(self.spec, _spec_model(self.spec).samples),
            )
        if self.pool is not None:
            try:
                seg.solved = self.pool.submit(solve, *seg.args)
                return
            except BrokenProcessPool:
                self.pool.shutdown(wait=False)
                self.pool, self.workers = None, 0
        seg.solved = solve(*seg.args)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)


# ---------------------------------------------------------------------- episodes
class _Episodes:
    """Squeak episodes and P(squeak) over time from the predictions in log order.

    An episode starts at the first prediction with squeak (not stable) and ends at the next
    recompute that is stable or outside validity (motor at rest: no squeak), or at the end of
    the log. Each ended episode is written to `sink` (a JSON list); the first EPISODES_KEPT
    stay in `kept`. A valid recompute's P(squeak) holds until the next recompute or the end of
    the log, and counts towards the log's `probability` and the open episode's."""

    def __init__(self, sink: TextIO, warn_probability: float, error_probability: float) -> None:
        self.sink, self.keep = sink, EPISODES_KEPT
        self.thresholds = (warn_probability, error_probability)
        self.kept: list[Episode] = []
        self.open: Episode | None = None
        self.count, self.time_in_squeak_s = 0, 0.0
        self.probability = ProbabilityTime()
        self._held: tuple[float, float] | None = None  # (since [s], P) of the last recompute
        sink.write("[")

    def _hold(self, t: float) -> None:
        """The held probability, from its recompute to `t`."""
        if self._held is not None:
            since, probability = self._held
            for pt in [self.probability] + ([self.open.probability] if self.open else []):
                pt.hold(probability, t - since, *self.thresholds)

    def add(self, t: float, p: Verdict) -> None:
        self._hold(t)
        probability = p.probability if p.valid else None  # not None when valid
        self._held = None if probability is None else (t, probability)
        if probability is not None:
            self.probability.sample(t, probability)
        squeak = p.valid and not p.stable
        e = self.open
        if not squeak:
            if e is not None:
                self._end(t)
            return
        assert probability is not None  # squeak: a valid prediction
        growth = p.max_growth_rate if p.max_growth_rate is not None else -math.inf
        if e is None:
            e = self.open = Episode(
                t, t, growth, (p.speed_rad_s, p.speed_rad_s), (p.load_n, p.load_n), 0
            )
        e.end_s = t
        e.peak_growth_rate = max(e.peak_growth_rate, growth, *p.divergence_rates)
        e.speed_range_rad_s = (
            min(e.speed_range_rad_s[0], p.speed_rad_s),
            max(e.speed_range_rad_s[1], p.speed_rad_s),
        )
        e.load_range_n = (min(e.load_range_n[0], p.load_n), max(e.load_range_n[1], p.load_n))
        e.predictions += 1
        e.probability.sample(t, probability)
        for label, hz, _ in p.squeak:
            e.add_frequency(label, hz)

    def _end(self, t: float) -> None:
        e, self.open = self.open, None
        assert e is not None  # ended only while open
        e.end_s = t
        self.sink.write(
            ("," if self.count else "")
            + "\n"
            + textwrap.indent(json.dumps(json_safe(e.as_dict()), indent=1, allow_nan=False), " ")
        )
        self.count += 1
        self.time_in_squeak_s += e.end_s - e.start_s
        if len(self.kept) < self.keep:  # with each mode's median only: a few hundred bytes
            e.frequencies = dict(zip(e.modes, ([hz] for hz in e.frequencies_hz), strict=True))
            self.kept.append(e)

    def close(self, end_s: float) -> None:
        self._hold(end_s)
        self._held = None
        if self.open is not None:
            self._end(end_s)
        self.sink.write("\n]\n")


# ---------------------------------------------------------------------- the replay
def _message_total(files: list[Path]) -> int | None:
    """Message count from the files' summaries, for the progress bar (None if unknown)."""
    from mcap.reader import make_reader

    total = 0
    try:
        for f in files:
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
            if summary is None or summary.statistics is None:
                return None
            total += summary.statistics.message_count
    except Exception:  # only a hint: a damaged summary (or a .db3) shows no total
        return None
    return total


class _Run:
    """One replay in progress: messages go to the timeline and into segments; a segment is
    written (originals, predictions after their inputs) once its predictions are back."""

    def __init__(
        self,
        model: SqueakModel,
        inputs: InputSettings,
        workers: int,
        out: _AnnotatedWriter,
        episodes: TextIO,
        progress: Callable[[int], None] | None,
        listening: bool = False,
        types: dict[str, list[str]] | None = None,
        namespace: str = "/",
    ):
        self.out, self.progress = out, progress
        self.timeline = Timeline(model.params, inputs, types)
        self.commands = CommandTrace(namespace)  # the guard's, if the log has them
        # for `listen`: the recomputes and the speed samples, compact
        self.trace = PredictionTrace() if listening else None
        self.speeds = SpeedTrace()
        resolved = self.timeline.settings
        self._speed_topics = (
            {resolved.speed_topic, resolved.joint_states_topic} if listening else set()
        )
        self.solver = _Solver(model, workers)
        self.plot_data = PlotData()
        self.episodes = _Episodes(episodes, inputs.warn_probability, inputs.error_probability)
        self.no_prediction: Counter[str] = Counter()
        self.messages = self.predictions = 0
        self.start_ns: int | None = None  # log time of the first message [ns]
        self.end_ns = 0  # of the latest one (set with start_ns)
        self.queue: deque[_Segment] = deque()
        self.held = 0  # messages in `queue`
        self.segment = _Segment()

    def add(self, m: LogMessage) -> None:
        if self.start_ns is None:
            self.start_ns = self.end_ns = m.log_time_ns
        self.end_ns = max(self.end_ns, m.log_time_ns)
        self.messages += 1
        seg = self.segment
        seg.messages.append(m)
        job = self.timeline.feed(m, len(seg.messages) - 1)
        if job is not None:
            seg.jobs.append(job)
        if self.commands.takes(m.topic.name):  # rarely: no clock reading per message
            self.commands.add(m, self.timeline.seconds(self.timeline.now_ns))
        if m.topic.name in self._speed_topics and self.timeline.speed is not None:
            self.speeds.add(self.timeline.seconds(self.timeline.now_ns), self.timeline.speed)
        if len(seg.jobs) >= _BATCH_JOBS or len(seg.messages) >= _SEGMENT_MESSAGES:
            self._seal()
            while self.queue and (self.queue[0].done() or self.held > _IN_FLIGHT_MESSAGES):
                self._write(self.queue.popleft())

    def finish(self) -> None:
        self._seal()
        while self.queue:
            self._write(self.queue.popleft())
        self.out.finish()
        self.episodes.close(self.duration_s)
        self.commands.close(self.duration_s)

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9

    def _seal(self) -> None:
        self.solver.submit(self.segment)
        self.queue.append(self.segment)
        self.held += len(self.segment.messages)
        self.segment = _Segment()

    def _write(self, seg: _Segment) -> None:
        self.held -= len(seg.messages)
        jobs = iter(zip(seg.jobs, *seg.result(), strict=True))
        job, p, payloads = next(jobs, (None, None, None))
        for i, m in enumerate(seg.messages):
            self.out.original(m)
            if job is not None and job.index == i:
                assert p is not None and self.start_ns is not None  # with a job, after a message
                t = (job.clock_ns - self.start_ns) / 1e9
                if p.valid:
                    assert payloads is not None  # encoded for every valid prediction
                    self.out.prediction(job.log_time_ns, payloads)
                    self.predictions += 1
                else:
                    self.no_prediction[p.validity.label] += 1
                self.plot_data.add(t, job, p)
                self.episodes.add(t, p)
                if self.trace is not None:
                    self.trace.add(t, job, p)
                job, p, payloads = next(jobs, (None, None, None))
        if self.progress is not None:
            self.progress(len(seg.messages))


def _namespaces(source: LogSource, settings: ReplaySettings) -> tuple[str, str]:
    """(input namespace, output namespace): the one given, or the only one in the log whose
    topics are predictor inputs (as `replay --publish` selects them)."""
    ns = settings.namespace
    if ns is None:
        found = input_namespaces(log_topics(source).values(), settings.inputs)
        if len(found) > 1:
            raise LogError(
                source.path,
                f"predictor inputs in several namespaces "
                f"({', '.join(found)}); choose one with --namespace NS",
            )
        ns = found[0] if found else "/"
    out = settings.out_namespace or DEFAULT_NAMESPACE + ("" if ns == "/" else ns)
    return ns, out


def replay(
    log: Path | str,
    model: SqueakModel,
    out_dir: Path | str,
    settings: ReplaySettings = ReplaySettings(),
) -> ReplayResult:
    """Replay a log offline: the node's predictions recomputed for the whole log (the module's
    outputs).

    Parameters
    ----------
    log : path
        An MCAP or .db3 file, or a bag directory of split files.
    model : SqueakModel
        Its parameters, and its scatter and sample count for P(squeak) (e.g.
        `SqueakModel(params, scatter_settings.scatter, scatter_settings.samples)`, as the node
        builds it).
    out_dir : path
        Receives the annotated log, episodes.json, summary.json and summary.txt.
    settings : ReplaySettings
        Inputs, namespaces, worker processes, progress bar.

    Returns
    -------
    ReplayResult
        Counts, episodes, P(squeak) over time and what the report draws.

    Raises
    ------
    LogError
        The log is unreadable or foreign, or has none of the inputs.
    """
    t0 = time.perf_counter()
    log, out_dir = Path(log), Path(out_dir)
    source = open_log(log)
    if log.is_dir() and out_dir.resolve() == log.resolve():
        raise LogError(
            log,
            "the output directory must not be the log directory (the "
            "annotated log would become one of its split files)",
        )
    namespace, out_namespace = _namespaces(source, settings)
    inputs = settings.inputs.resolved(namespace)
    out_dir.mkdir(parents=True, exist_ok=True)
    annotated = out_dir / f"{log_name(log)}.annotated.mcap"
    episodes = out_dir / "episodes.json"
    partial = [p.with_name(p.name + ".partial") for p in (annotated, episodes)]
    show = settings.progress and sys.stderr.isatty()
    run = None
    try:
        with (
            open(partial[0], "wb") as fh,
            open(partial[1], "w", encoding="utf-8") as eh,
            progress_bar(
                _message_total(source.files) if show else None, "replay", unit="msg"
            ) as bar,
        ):
            run = _Run(
                model,
                inputs,
                settings.workers,
                _AnnotatedWriter(fh, out_namespace),
                eh,
                bar if show else None,
                settings.listen.enabled,
                topic_types(source),
                namespace,
            )
            for f, m in source.messages():
                try:
                    run.add(m)
                except InputError as exc:
                    raise LogError(f, str(exc)) from None
            run.finish()
        _check_inputs(log, run.timeline, source.counts)
        for p, final in zip(partial, (annotated, episodes), strict=True):
            p.replace(final)
    except BaseException:
        for p in partial:
            p.unlink(missing_ok=True)
        raise
    finally:
        if run is not None:
            run.solver.close()
    tl = run.timeline
    heard, audio_warnings = (
        (None, [])
        if run.trace is None
        else listen(
            log,
            log_topics(source),
            out_dir,
            settings.listen,
            run.trace,
            run.speeds,
            run.duration_s,
            model,
            solve,
            _BATCH_JOBS,
        )
    )
    result = ReplayResult(
        log=log,
        files=source.files,
        out_dir=out_dir,
        annotated=annotated,
        start_ns=run.start_ns or 0,
        duration_s=run.duration_s,
        messages=run.messages,
        inputs=tl.inputs,
        recomputes=tl.recomputes,
        predictions=run.predictions,
        no_prediction=run.no_prediction,
        rejected=tl.rejected,
        ignored=tl.ignored,
        episodes=run.episodes.kept,
        episode_count=run.episodes.count,
        time_in_squeak_s=run.episodes.time_in_squeak_s,
        probability=run.episodes.probability,
        plot_data=run.plot_data,
        timeline=tl,
        namespace=namespace,
        out_namespace=out_namespace,
        warn_probability=inputs.warn_probability,
        error_probability=inputs.error_probability,
        scatter=dict(model.scatter.sd),
        scatter_samples=model.sample_count,
        heard=heard,
        commands=run.commands if run.commands.found else None,
        audio_warnings=audio_warnings,
        metadata_problem=metadata_problem(log, source.infos) if log.is_dir() else "",
    )
    if heard is not None:
        with open(annotated, "r+b") as fh:
            writer = McapOut.reopen(fh)
            write_heard(writer, out_namespace, heard, result.start_ns)
            writer.finish()
    result.wall_s = time.perf_counter() - t0
    _write_json(out_dir / "summary.json", result.summary())
    (out_dir / "summary.txt").write_text(result.summary_text() + "\n", encoding="utf-8")
    result.outputs = [annotated, episodes, out_dir / "summary.json", out_dir / "summary.txt"]
    result.outputs += [path for path, _ in heard.clips] if heard else []
    attach(result, [episodes, out_dir / "summary.json"], _metadata(result, model))
    return result


def _metadata(result: ReplayResult, model: SqueakModel) -> dict[str, dict[str, str]]:
    """The annotated log's metadata: the input's `leadscrew_ros` record (its first file's, if
    it has a readable one) and the replay's own record, with the unit and hardware ids of the
    input's."""
    try:
        recorded = (
            logmeta.read_record(result.files[0]) if result.files[0].suffix == ".mcap" else None
        ) or {}
    except (OSError, ValueError):  # the messages were read: a record is only a bonus
        recorded = {}
    inputs = {
        f.name: getattr(result.timeline.settings, f.name) for f in fields(result.timeline.settings)
    }
    own = logmeta.LogMetadata(
        model.params.as_dict(),
        {**model.scatter.sd, "samples": model.sample_count},
        {
            **inputs,
            "log": str(result.log),
            "namespace": result.namespace,
            "out_namespace": result.out_namespace,
        },
        recorded.get("unit_id", ""),
        recorded.get("hardware_id", ""),
    )
    return {
        **({logmeta.RECORD_NAME: recorded} if recorded else {}),
        logmeta.REPLAY_RECORD_NAME: own.record(),
    }


def attach(
    result: ReplayResult, paths: list[Path], metadata: dict[str, dict[str, str]] | None = None
) -> None:
    """Add the files `paths` (.json, .png) to the replay's annotated log as MCAP Attachments
    named as the files (log time: the log's last message), and the `metadata` records.

    Only the end of the file is rewritten (`McapOut.reopen`); nothing per message. Raises
    OSError when a file cannot be read or written, ValueError when the annotated log is not one
    the replay finished.
    """
    end_ns, now_ns = result.start_ns + round(result.duration_s * 1e9), time.time_ns()
    with open(result.annotated, "r+b") as fh:
        out = McapOut.reopen(fh)
        for path in paths:
            out.add_attachment(
                path.name, MEDIA_TYPES[path.suffix], path.read_bytes(), end_ns, now_ns
            )
        for name, record in (metadata or {}).items():
            out.add_metadata(name, record)
        out.finish()


def _field_text(path: str) -> str:
    """Where an input's number is, for the missing-input error."""
    return "std_msgs/Float64" if path == "data" else f"field {path}"


def _check_inputs(log: Path, timeline: Timeline, counts: dict[str, int]) -> None:
    """A log without speed or load gives no prediction at all: say which topics it has, which
    of the input topics exist without messages, and how to choose others."""
    s = timeline.settings
    missing = [
        (what, where, topics)
        for what, where, topics, value in (
            (
                "speed",
                f"{_field_text(s.speed_field)} on {s.speed_topic} or a joint velocity on "
                f"{s.joint_states_topic}",
                (s.speed_topic, s.joint_states_topic),
                timeline.speed,
            ),
            (
                "axial load",
                f"{_field_text(s.load_field)} on {s.load_topic}",
                (s.load_topic,),
                timeline.load,
            ),
        )
        if value is None
    ]
    if not missing:
        return
    parts = []
    for what, where, topics in missing:
        empty = [t for t in topics if t in counts and not counts[t]]
        if empty:
            where += (
                f"; {' and '.join(empty)} exist{'s' if len(empty) == 1 else ''} in the "
                f"log but {'has' if len(empty) == 1 else 'have'} no messages"
            )
        parts.append(f"{what} ({where})")
    listed = ", ".join(f"{t}{'' if n else ' (empty)'}" for t, n in sorted(counts.items()))
    hint = (
        "choose the topics with --speed-topic, --load-topic, --joint-states-topic, "
        "--joint-name or --namespace"
    )
    if timeline.load is None and timeline.speed is not None:
        hint = f"for a log without load give a nominal load with --load N, or {hint}"
    ignored = "".join(
        f"; {n} x {reason} ({timeline.ignored_example[reason]})"
        for reason, n in sorted(timeline.ignored.items())
    )
    raise LogError(
        log,
        f"no {' and no '.join(parts)} in the log (its topics: {listed or 'none'}){ignored}; {hint}",
    )


def _write_json(path: Path, obj: Any) -> None:
    path.write_text(json.dumps(json_safe(obj), indent=1, allow_nan=False) + "\n", encoding="utf-8")
