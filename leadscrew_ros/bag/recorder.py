# SPDX-License-Identifier: Apache-2.0
"""MCAP recorder in rosbag2's layout, split by size and duration, safe against crashes.

Each recording is a rosbag2 bag directory `<directory>/<name>_<UTC wall-clock start>/` holding
`<bag>_<index>.mcap` files and a `metadata.yaml`; the directory is created if missing (like
`ros2 bag record -o`). Bags are named and split by the wall clock (unique even within one
millisecond; a file too old is closed by `tick` or, as rosbag2 does, by the first message
written past the limit); each message's log time is whatever the caller gives (the node's
clock, which may be sim time, as rosbag2 does). Files use profile `ros2`, one channel per
topic, `ros2msg` schemas with the complete definition from the installed message packages
(`msgdefs`) and `cdr` payloads serialized by the caller (`write_serialized`: bytes as received
from DDS, or from the encoders of `cdr`).

Every file starts with the MCAP Metadata records in `metadata` (name -> string map; the node
puts its `leadscrew_ros` record there, `logmeta`) as they are when the file is opened, so each
split file describes itself; `split` starts the next file at once (the node does when its
parameters change, so that a file's record holds for every message in it). Every file then
starts with the messages of `state` (the node: its last accepted input on each topic and its
latched outputs), logged at the file's start time as rosbag2 records transient-local messages,
so that each file, read on its own, replays to the node's predictions.

Thread safe: the node's input recording thread and its model thread write concurrently.
Messages the recorder never got are counted per topic (`TopicLoss`: gaps in the publishers'
sequence numbers and DDS message-lost events) and stored in the bag's `metadata.yaml`
(`custom_data`).

Crash safety: the open chunk is finished and handed to the operating system every
`flush_period_s`, so SIGKILL loses at most that much (plus one housekeeping tick); the cut-off
file is read by `logfile.read_messages(strict=False)` and repaired by `logfile.recover`.
A failing disk (missing or read-only directory, file size limit, disk full) stops the recording
with `error` naming the path; nothing is raised to the caller.

While a file is written the recorder holds an advisory lock on it (`livelock`), so that
`recover` and `info` tell it from a file cut off by a crash. `tick` checks, a few times a
second, that the file is still at its path; a file deleted or replaced under the recorder is
an `incident` (its messages are lost), and the recording goes on in the bag's next file.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from mcap.writer import CompressionType, Writer

from ..model.physics.metadata import check, documented, setting
from . import livelock, msgdefs
from .bagmeta import METADATA, BagStats, FileStats, TopicStats

COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
_CHUNK_BYTES = 4 << 20  # chunks are closed by the flush period long before this size
LOST_KEY, LOST_BY_TOPIC_KEY = "lost_messages", "lost_messages_by_topic"  # metadata custom_data
INCIDENT_KEY = "incident"  # metadata custom_data: a file lost while recording
_CHECK_PERIOD_NS = 200_000_000  # how often `tick` checks that the file is still there
# A message every file starts with: topic, 'pkg/msg/Type', CDR payload, publish time (None:
# the log time)
StateMessage = tuple[str, str, bytes, "int | None"]


def ensure_directory(directory: str) -> Path:
    """`directory` as an absolute path, created if missing (`mkdir -p`) and checked writable by
    creating and removing a probe directory in it; raises OSError with a one-line reason
    naming the path (e.g. /proc, a path under a plain file, a read-only file system)."""
    root = Path(directory).expanduser().absolute()
    try:
        root.mkdir(parents=True, exist_ok=True)
        os.rmdir(tempfile.mkdtemp(prefix=".probe_", dir=root))
    except OSError as exc:
        raise OSError(
            exc.errno, f"{exc.filename or root}: {exc.strerror or exc}; cannot record into {root}"
        ) from None
    return root


@documented
@dataclass(frozen=True)
class RecordSettings:
    """How a recording is written (SI units; default, unit, range and description are the
    field metadata, from which the node's `record.*` parameters are made)."""

    directory: str = setting(
        ".",
        "",
        "directory that receives one [<namespace>_]squeak_<UTC wall-clock time> bag "
        "per recording; created if missing (mkdir -p)",
    )
    split_size_mb: float = setting(
        512.0, "MB", "start a new file beyond this size (0: never)", 0.0, 1e6
    )
    split_duration_s: float = setting(
        600.0, "s", "start a new file after this long (0: never)", 0.0, 1e7
    )
    compression: str = setting("zstd", "", "chunk compression", choices=tuple(COMPRESSIONS))
    flush_period_s: float = setting(
        0.5,
        "s",
        "hand recorded data to the OS this often: the most a killed process loses",
        0.05,
        10.0,
    )
    queue_depth: int = setting(
        10000,
        "1",
        "DDS history of each input recording subscription: messages held per "
        "topic while the process is busy (10 s at 1 kHz)",
        1,
        1_000_000,
    )

    def __post_init__(self):
        check(self)
        if not self.directory:
            raise ValueError("directory must not be empty")


# DDS status counts (SampleLostStatus.total_count) are 32-bit signed: rmw hands them on as size_t,
# so a count that went negative in the middleware arrives as 2**64 - n
DDS_COUNT_LIMIT = 2**31


@dataclass
class TopicLoss:
    """Messages of one recorded topic that never reached the recorder.

    `sequence_gaps` counts missing publication sequence numbers of the publisher (whatever
    dropped them: the DDS reader's queue overflowing while the recorder was busy, or the
    transport); `dds_lost` counts DDS message-lost events (Fast DDS reports transport gaps, not
    queue overflow). With several publishers on a topic their numbers interleave and rclpy gives
    no publisher id, so only the DDS events count there (`sequence_checked` False).

    A DDS count is taken only when it is one (`dds_event`): an integer in [0, 2**31), never below
    an earlier total, and, while the sequence numbers are checked, at most the messages the
    publisher numbered that the recorder did not get. The first that is not makes the topic's
    DDS counts untrusted (`dds_rejected` says why; they are cumulative, so every later total
    carries the error): the loss count is then the sequence gaps (with several publishers: the
    last valid DDS total).
    """

    sequence_gaps: int = 0
    dds_lost: int = 0
    sequence_checked: bool = True
    dds_rejected: str = ""  # why the DDS counts of this topic are not trusted ('' if they are)
    numbered: int = 0  # messages the publisher sent up to the last number taken (all its runs)
    taken: int = 0  # messages taken while the sequence numbers were checked
    _last: int | None = None

    def received(self, sequence: int | None, publishers: Callable[[], int]) -> None:
        """A message with publication sequence number `sequence` was taken; `publishers`
        (called only when the sequence does not continue) counts the topic's publishers."""
        last, self._last = self._last, sequence
        if sequence is None:  # the middleware does not number its messages
            self.sequence_checked = False
        if not self.sequence_checked:
            return
        assert sequence is not None  # a None sequence is unchecked: returned above
        self.taken += 1
        if last is None or sequence == last + 1:  # RTPS numbers a writer's messages from 1
            self.numbered += sequence - (last or 0)  # a first number counts those before it
            return
        if publishers() > 1:
            self.sequence_checked = False
        elif sequence > last + 1:
            self.sequence_gaps += sequence - last - 1
            self.numbered += sequence - last
        else:  # a lower number from a single publisher: a new publisher, nothing lost
            self.numbered += sequence

    def dds_event(self, total_count: object, total_count_change: object) -> str:
        """Take the totals of a DDS message-lost event (rclpy's QoSMessageLostInfo) if they are
        a count; else mark the topic's DDS counts untrusted.

        Parameters
        ----------
        total_count, total_count_change
            The event's cumulative count of lost messages and its increase since the last event.

        Returns
        -------
        str
            Why the DDS counts are ignored from now on, when this event made them untrusted
            (to be said once), else ''.
        """
        if self.dds_rejected:
            return ""
        why = self._dds_fault(total_count, total_count_change)
        if not why:
            assert isinstance(total_count, int)  # checked by _dds_fault
            self.dds_lost = total_count
            return ""
        fallback = (
            "the loss count comes from the sequence numbers"
            if self.sequence_checked
            else f"the loss count stays at the last valid DDS total ({self.dds_lost})"
        )
        self.dds_rejected = (
            f"DDS message-lost event with total_count {total_count!r}, total_count_change "
            f"{total_count_change!r}: {why}; DDS loss counts ignored, {fallback}"
        )
        return self.dds_rejected

    def _dds_fault(self, total: object, change: object) -> str:
        """What makes an event's totals no count ('' when they are one)."""
        if not all(isinstance(n, int) and not isinstance(n, bool) for n in (total, change)):
            return "not integers"
        assert isinstance(total, int) and isinstance(change, int)
        if min(total, change) < 0:
            return "negative"
        if max(total, change) >= DDS_COUNT_LIMIT:
            return (
                f"beyond DDS's 32-bit count ({DDS_COUNT_LIMIT - 1}): a negative count wrapped "
                "around in the middleware"
            )
        if change > total:
            return "the change is larger than the total"
        if total < self.dds_lost:
            return f"below the earlier total {self.dds_lost} (the count only grows)"
        if self.sequence_checked and total > self.numbered - self.taken:
            return (
                f"more than the publisher could have lost: it numbered {self.numbered} "
                f"messages, {self.taken} of which were recorded"
            )
        return ""

    @property
    def lost(self) -> int:
        """Best count of the lost messages (the DDS events are a subset of the gaps)."""
        if not self.sequence_checked:
            return self.dds_lost
        return self.sequence_gaps if self.dds_rejected else max(self.sequence_gaps, self.dds_lost)

    def as_dict(self) -> dict:
        """The counts as a JSON-ready dict."""
        return {
            "lost": self.lost,
            "sequence_gaps": self.sequence_gaps,
            "dds_lost": self.dds_lost,
            "dds_rejected": self.dds_rejected,
            "sequence_checked": self.sequence_checked,
        }


@dataclass
class _Topic:
    name: str
    type_name: str
    count: int = 0
    channel_id: int | None = None  # in the current file
    in_file: int = 0  # messages in the current file
    dropped: int = 0  # messages in files lost under the recorder


@dataclass
class Recorder:
    """Writes serialized ROS messages to a split MCAP bag. Call `tick` periodically (flush and
    split). Thread-safe.

    Attributes
    ----------
    settings : RecordSettings
        Directory, splitting, compression, flush period.
    name : str
        Bag directory prefix (the node adds its namespace).
    clock : callable
        Log time [ns] of a message written without one.
    bag : Path or None
        Directory of the recording in progress, or of the last one.
    error : str
        Why the last recording stopped on its own.
    incident : str
        A file of this recording lost under the recorder (deleted or replaced), if any.
    files : list of FileStats
        The files of the recording.
    losses : dict of str to TopicLoss
        Topic -> what never arrived.
    metadata : dict of str to dict
        Metadata records written at the start of every file: name -> string map.
    state : callable or None
        The messages every file starts with (the node's input state and latched outputs),
        called under the recorder's lock when a file opens.
    schemas : dict of str to str
        'pkg/msg/Type' -> its ros2msg schema text, for types `msgdefs` has no definition of
        (e.g. `audiomsgs`' audio types).
    """

    settings: RecordSettings = field(default_factory=RecordSettings)
    name: str = "squeak"  # bag directory prefix (the node adds its namespace)
    clock: Callable[[], int] = time.time_ns  # log time [ns] of a message written without one
    bag: Path | None = None  # directory of the recording in progress / last one
    error: str = ""  # why the last recording stopped on its own
    incident: str = ""  # a file of this recording lost under the recorder
    files: list[FileStats] = field(default_factory=list)
    losses: dict[str, TopicLoss] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    state: Callable[[], list[StateMessage]] | None = None
    schemas: dict[str, str] = field(default_factory=dict)
    _out: IO[bytes] | None = None
    _writer: Writer | None = None
    _topics: dict[str, _Topic] = field(default_factory=dict)
    _file_start_ns: int = 0
    _base_offset_ns: int = 0  # the time base of `start` less the monotonic clock
    _last_flush_ns: int = 0
    _last_check_ns: int = 0
    _lost_files: set[Path] = field(default_factory=set)
    _lock: threading.RLock = field(default_factory=threading.RLock, repr=False)

    @property
    def active(self) -> bool:
        """A recording is in progress."""
        return self._writer is not None

    @property
    def _dir(self) -> Path:
        """`bag`, set by `start` before any file of the recording opens."""
        assert self.bag is not None
        return self.bag

    @property
    def path(self) -> Path | None:
        """The file being written (None when not recording)."""
        return self.files[-1].path if self.active else None

    @property
    def messages(self) -> int:
        """Messages of this recording in its files (not those of a file lost under it)."""
        return sum(f.messages for f in self.files if f.path not in self._lost_files)

    def count(self, topic: str) -> int:
        """Messages of one topic written in this recording so far.

        Parameters
        ----------
        topic : str
            The topic's name.

        Returns
        -------
        int
            The count.
        """
        with self._lock:
            t = self._topics.get(topic)
            return 0 if t is None else t.count

    @property
    def lost(self) -> int:
        """Messages of this recording counted as lost before they reached the recorder."""
        return sum(loss.lost for loss in list(self.losses.values()))

    def start(self, now_ns: int | None = None, topics: tuple[str, ...] = ()) -> bool:
        """Open a new bag named by the wall clock.

        Parameters
        ----------
        now_ns : int, optional
            Starts the time base of `tick` [ns] (default: a monotonic wall clock).
        topics : tuple of str
            Topics that get a loss counter each (`losses`).

        Returns
        -------
        bool
            False (with `error`) if the directory cannot take it.
        """
        with self._lock:
            if self.active:
                return True
            self.error, self.incident, self.files, self._topics = "", "", [], {}
            self._lost_files = set()
            self.losses = {t: TopicLoss() for t in topics}
            try:
                root = ensure_directory(self.settings.directory)
                self.bag = _new_bag(root, self.name)
            except OSError as exc:
                self.error = exc.strerror or str(exc)
                return False
            now_ns = time.monotonic_ns() if now_ns is None else now_ns
            self._base_offset_ns = now_ns - time.monotonic_ns()
            return self._open(now_ns)

    def stop(self) -> None:
        """Finish the current file (summary, index, footer) and write metadata.yaml."""
        with self._lock:
            if not self.active:
                return
            self._close(finish=True)
            self._write_metadata()

    def write_serialized(
        self,
        topic: str,
        type_name: str,
        data: bytes,
        log_time_ns: int | None = None,
        publish_time_ns: int | None = None,
    ) -> None:
        """Record one serialized (CDR) message (nothing when not recording).

        Parameters
        ----------
        topic : str
            Its topic.
        type_name : str
            Its type, 'pkg/msg/Type'.
        data : bytes
            The CDR payload.
        log_time_ns : int, optional
            Default: `clock()` read under the lock, so that writers on several threads keep a
            file in log time order.
        publish_time_ns : int, optional
            Default: the log time.
        """
        with self._lock:
            if not self.active:
                return
            now_ns = time.monotonic_ns() + self._base_offset_ns
            if self.files[-1].messages and self._too_old(now_ns):
                # as rosbag2 splits: the first message past the limit opens the next file, so
                # no file outlasts split_duration_s however late the next `tick` runs
                self._split(now_ns)
                if not self.active:
                    return
            if log_time_ns is None:  # after the new file's state: the file stays in order
                log_time_ns = self.clock()
            t = self._topics.get(topic)
            if t is None:
                t = self._topics[topic] = _Topic(topic, type_name)
            try:
                if t.channel_id is None:
                    t.channel_id = self._register(t)
                assert self._writer is not None  # active
                self._writer.add_message(
                    t.channel_id,
                    log_time_ns,
                    data,
                    log_time_ns if publish_time_ns is None else publish_time_ns,
                    t.count,
                )
            except OSError as exc:
                self._fail(exc)
                return
            t.count += 1
            t.in_file += 1
            self.files[-1].add(log_time_ns)

    def tick(self, now_ns: int | None = None) -> None:
        """Flush when the flush period is over; split when the file is too big or too old.

        Parameters
        ----------
        now_ns : int, optional
            On the time base given to `start` [ns] (default: the monotonic wall clock).
        """
        with self._lock:
            if not self.active:
                return
            now_ns = time.monotonic_ns() if now_ns is None else now_ns
            s = self.settings
            assert self._writer is not None and self._out is not None  # active
            try:
                if now_ns - self._last_flush_ns >= s.flush_period_s * 1e9:
                    self._writer.flush()
                    self._last_flush_ns = now_ns
                too_big = s.split_size_mb > 0 and self._out.tell() >= s.split_size_mb * 1e6
                too_old = self._too_old(now_ns)
                gone = ""
                if now_ns - self._last_check_ns >= _CHECK_PERIOD_NS:
                    self._last_check_ns = now_ns
                    gone = self._file_gone()
            except OSError as exc:
                self._fail(exc)
                return
            if gone:
                self._lose_file(gone, now_ns)
            elif too_big or too_old:
                self._split(now_ns)

    def _too_old(self, now_ns: int) -> bool:
        """The file is `split_duration_s` old at `now_ns` (on the time base of `start`)."""
        d = self.settings.split_duration_s
        return d > 0 and now_ns - self._file_start_ns >= d * 1e9

    def split(self, now_ns: int | None = None) -> None:
        """Finish the current file and go on in the next one, which gets the `metadata` of now
        (nothing when not recording).

        Parameters
        ----------
        now_ns : int, optional
            As for `tick`.
        """
        with self._lock:
            if self.active:
                self._split(time.monotonic_ns() if now_ns is None else now_ns)

    # ------------------------------------------------------------------ files
    def _split(self, now_ns: int) -> None:
        self._close(finish=True)
        if not self.error and self._open(now_ns):
            self._write_metadata()

    def _file_gone(self) -> str:
        """How the file being written left its path ('' if it did not): a deleted file (or
        bag) takes the data nowhere, with every write still succeeding."""
        path = self.files[-1].path
        assert self._out is not None  # called while recording
        mine = os.fstat(self._out.fileno())
        try:
            there = os.stat(path)
        except FileNotFoundError:
            return "deleted"
        if (there.st_ino, there.st_dev) != (mine.st_ino, mine.st_dev):
            return "replaced by another file"
        return ""

    def _lose_file(self, what: str, now_ns: int) -> None:
        """The file was deleted or replaced under the recorder: its messages are lost; go on
        in the bag's next file (the bag directory made again if it went too)."""
        lost = self.files[-1]
        self._close(finish=False)
        self._lost_files.add(lost.path)
        for t in self._topics.values():
            t.dropped += t.in_file
        self.incident = (
            f"{lost.path} was {what} while being recorded ({lost.messages} "
            f"messages lost with it); recording continues in "
            f"{self._dir / self._file_name(len(self.files))}"
        )
        try:
            self._dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            self._fail(exc, writer_gone=True)
            return
        self._open(now_ns)

    def _file_name(self, index: int) -> str:
        return f"{self._dir.name}_{index}.mcap"

    def _open(self, now_ns: int) -> bool:
        path = self._dir / self._file_name(len(self.files))
        self.files.append(FileStats(path))
        try:
            self._out = open(path, "xb")  # never over another file
            livelock.hold(self._out.fileno())
            self._writer = Writer(
                self._out,
                chunk_size=_CHUNK_BYTES,
                compression=COMPRESSIONS[self.settings.compression],
            )
            self._writer.start(profile="ros2", library="leadscrew_ros recorder")
            for name, record in self.metadata.items():
                self._writer.add_metadata(name, record)
            self._out.flush()
        except OSError as exc:
            self._fail(exc)
            return False
        for t in self._topics.values():
            t.channel_id, t.in_file = None, 0  # each file registers its own channels
        self._file_start_ns = self._last_flush_ns = self._last_check_ns = now_ns
        if self.state is not None:  # the file starts with the current state
            start_ns = self.clock()
            for topic, type_name, data, publish_time_ns in self.state():
                self.write_serialized(topic, type_name, data, start_ns, publish_time_ns)
        return self.active

    def _register(self, t: _Topic) -> int:
        text = self.schemas.get(t.type_name) or msgdefs.definition(t.type_name)
        assert self._writer is not None  # registered while writing a message
        schema = self._writer.register_schema(t.type_name, "ros2msg", text.encode())
        return self._writer.register_channel(t.name, "cdr", schema, {"offered_qos_profiles": ""})

    def _close(self, finish: bool) -> None:
        writer, out, self._writer, self._out = self._writer, self._out, None, None
        assert writer is not None and out is not None  # closed only while recording
        try:
            if finish:
                writer.finish()
            out.flush()
            os.fsync(out.fileno())
        except OSError as exc:
            if finish:
                self._fail(exc, writer_gone=True)
        finally:
            try:
                out.close()
            except OSError:
                pass  # the buffer could not be written: already reported

    def _fail(self, exc: OSError, writer_gone: bool = False) -> None:
        path = exc.filename or (self.files[-1].path if self.files else self.bag)
        self.error = f"{path}: {exc.strerror or exc}; recording stopped"
        if not writer_gone and self._writer is not None:
            self._close(finish=False)

    def _write_metadata(self) -> None:
        """rosbag2 metadata.yaml, so that `ros2 bag info/play` and rosbags take the directory."""
        losses = {topic: loss.as_dict() for topic, loss in list(self.losses.items())}
        custom = {LOST_KEY: str(self.lost), LOST_BY_TOPIC_KEY: json.dumps(losses, sort_keys=True)}
        if self.incident:
            custom[INCIDENT_KEY] = self.incident
        stats = BagStats(
            files=[f for f in self.files if f.path.exists() and f.path not in self._lost_files],
            topics=[
                TopicStats(t.name, t.type_name, t.count - t.dropped) for t in self._topics.values()
            ],
            custom_data=custom,
        )
        try:
            stats.write(self._dir)
        except OSError as exc:
            self.error = self.error or f"{self._dir / METADATA}: {exc.strerror or exc}"


def _new_bag(root: Path, name: str) -> Path:
    """Create `root/<name>_<UTC wall-clock time, ms>`, `_1`, `_2`... if that exists."""
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y_%m_%d-%H_%M_%S_%f")[:-3]
    base = root / f"{name}_{stamp}"
    for n in range(1000):
        bag = base if n == 0 else base.with_name(f"{base.name}_{n}")
        try:
            bag.mkdir()
            return bag
        except FileExistsError:
            continue
        except OSError as exc:
            raise OSError(exc.errno, f"{bag}: {exc.strerror or exc}") from None
    raise OSError(f"{base}: 1000 bags of this name exist")
