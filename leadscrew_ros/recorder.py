"""MCAP recorder in rosbag2's layout, split by size and duration, safe against crashes.

Each recording is a rosbag2 bag directory `<directory>/squeak_<UTC start>/` holding
`squeak_<UTC start>_<index>.mcap` files and a `metadata.yaml`. Files use profile `ros2`, one
channel per topic, `ros2msg` schemas with the complete definition from the installed message
packages (`msgdefs`) and `cdr` payloads from `rclpy.serialization`.

Crash safety: the open chunk is finished and handed to the operating system every
`flush_period_s`, so SIGKILL loses at most that much (plus one housekeeping tick); the cut-off
file is read by `logfile.read_messages(strict=False)` and repaired by `logfile.recover`.
A failing disk (missing or read-only directory, file size limit, disk full) stops the recording
with `error` naming the path; nothing is raised to the caller.
"""

from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from . import msgdefs
from .bagmeta import METADATA, BagStats, FileStats, TopicStats
from .serialization import cdr_payload

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}
_CHUNK_BYTES = 4 << 20         # chunks are closed by the flush period long before this size


@dataclass(frozen=True)
class RecordSettings:
    directory: str = "."
    split_size_mb: float = 512.0          # 0: no split by size
    split_duration_s: float = 600.0       # 0: no split by duration
    compression: str = "zstd"
    flush_period_s: float = 0.5           # bound of the data lost to SIGKILL

    def __post_init__(self):
        if self.compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {', '.join(COMPRESSIONS)}, "
                             f"not {self.compression!r}")
        if not self.directory:
            raise ValueError("directory must not be empty")
        for name in ("split_size_mb", "split_duration_s"):
            value = getattr(self, name)
            if not value >= 0.0 or value == float("inf"):
                raise ValueError(f"{name} must be finite and >= 0, not {value}")
        if not 0.0 < self.flush_period_s <= 10.0:
            raise ValueError(f"flush_period_s must be in (0, 10], not {self.flush_period_s}")


@dataclass
class _Topic:
    name: str
    type_name: str
    count: int = 0
    channel_id: int | None = None       # in the current file


@dataclass
class Recorder:
    """Writes ROS messages to a split MCAP bag. Call `tick` periodically (flush and split)."""

    settings: RecordSettings = field(default_factory=RecordSettings)
    bag: Path | None = None              # directory of the recording in progress / last one
    error: str = ""                      # why the last recording stopped on its own
    files: list[FileStats] = field(default_factory=list)
    _out: object = None
    _writer: Writer | None = None
    _topics: dict[str, _Topic] = field(default_factory=dict)
    _file_start_ns: int = 0
    _last_flush_ns: int = 0

    @property
    def active(self) -> bool:
        return self._writer is not None

    @property
    def path(self) -> Path | None:
        """The file being written (None when not recording)."""
        return self.files[-1].path if self.active else None

    @property
    def messages(self) -> int:
        return sum(f.messages for f in self.files)

    def start(self, now_ns: int) -> bool:
        """Open a new bag; False (with `error`) if the directory cannot take it."""
        if self.active:
            return True
        self.error, self.files, self._topics = "", [], {}
        root = Path(self.settings.directory).expanduser().absolute()
        if not root.is_dir():
            self.error = f"{root}: record directory does not exist"
            return False
        stamp = _dt.datetime.fromtimestamp(now_ns / 1e9, _dt.timezone.utc).strftime(
            "%Y_%m_%d-%H_%M_%S_%f")[:-3]
        self.bag = root / f"squeak_{stamp}"
        try:
            self.bag.mkdir()
        except OSError as exc:
            self.error = f"{self.bag}: {exc.strerror or exc}"
            return False
        return self._open(now_ns)

    def stop(self) -> None:
        """Finish the current file (summary, index, footer) and write metadata.yaml."""
        if not self.active:
            return
        self._close(finish=True)
        self._write_metadata()

    def write(self, topic: str, msg, log_time_ns: int, publish_time_ns: int | None = None
              ) -> None:
        """Record one message (publish_time defaults to the header stamp, else log_time)."""
        if not self.active:
            return
        t = self._topics.get(topic)
        if t is None:
            t = self._topics[topic] = _Topic(topic, msgdefs.type_name(msg))
        if publish_time_ns is None:
            stamp = getattr(getattr(msg, "header", None), "stamp", None)
            publish_time_ns = (stamp.sec * 1_000_000_000 + stamp.nanosec if stamp is not None
                               else log_time_ns)
        try:
            if t.channel_id is None:
                t.channel_id = self._register(t)
            self._writer.add_message(t.channel_id, log_time_ns, cdr_payload(msg),
                                     publish_time_ns, t.count)
        except OSError as exc:
            self._fail(exc)
            return
        t.count += 1
        self.files[-1].add(log_time_ns)

    def tick(self, now_ns: int) -> None:
        """Flush when the flush period is over; split when the file is too big or too old."""
        if not self.active:
            return
        s = self.settings
        try:
            if now_ns - self._last_flush_ns >= s.flush_period_s * 1e9:
                self._writer.flush()
                self._last_flush_ns = now_ns
            too_big = s.split_size_mb > 0 and self._out.tell() >= s.split_size_mb * 1e6
            too_old = s.split_duration_s > 0 and now_ns - self._file_start_ns >= \
                s.split_duration_s * 1e9
        except OSError as exc:
            self._fail(exc)
            return
        if too_big or too_old:
            self._close(finish=True)
            if not self.error and self._open(now_ns):
                self._write_metadata()

    # ------------------------------------------------------------------ files
    def _open(self, now_ns: int) -> bool:
        path = self.bag / f"{self.bag.name}_{len(self.files)}.mcap"
        self.files.append(FileStats(path))
        try:
            self._out = open(path, "wb")
            self._writer = Writer(self._out, chunk_size=_CHUNK_BYTES,
                                  compression=COMPRESSIONS[self.settings.compression])
            self._writer.start(profile="ros2", library="leadscrew_ros recorder")
            self._out.flush()
        except OSError as exc:
            self._fail(exc)
            return False
        for t in self._topics.values():
            t.channel_id = None                  # each file registers its own channels
        self._file_start_ns = self._last_flush_ns = now_ns
        return True

    def _register(self, t: _Topic) -> int:
        schema = self._writer.register_schema(t.type_name, "ros2msg",
                                              msgdefs.definition(t.type_name).encode())
        return self._writer.register_channel(t.name, "cdr", schema,
                                             {"offered_qos_profiles": ""})

    def _close(self, finish: bool) -> None:
        writer, out, self._writer, self._out = self._writer, self._out, None, None
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
                pass                  # the buffer could not be written: already reported

    def _fail(self, exc: OSError, writer_gone: bool = False) -> None:
        path = exc.filename or (self.files[-1].path if self.files else self.bag)
        self.error = f"{path}: {exc.strerror or exc}; recording stopped"
        if not writer_gone and self._writer is not None:
            self._close(finish=False)

    def _write_metadata(self) -> None:
        """rosbag2 metadata.yaml, so that `ros2 bag info/play` and rosbags take the directory."""
        stats = BagStats(files=[f for f in self.files if f.path.exists()],
                         topics=[TopicStats(t.name, t.type_name, t.count)
                                 for t in self._topics.values()])
        try:
            stats.write(self.bag)
        except OSError as exc:
            self.error = self.error or f"{self.bag / METADATA}: {exc.strerror or exc}"
