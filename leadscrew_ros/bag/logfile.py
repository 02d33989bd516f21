# SPDX-License-Identifier: Apache-2.0
"""Reading ROS 2 MCAP logs (ours, rosbag2's, rosbags') defensively, and recovering cut-off files.

Records are parsed sequentially with buffered reads of one record at a time (not a memory map:
its pages would stay resident, so memory would grow with the file, and a file truncated under
it would kill the process with SIGBUS); a length is checked against the file size before it is
read, so a damaged length can never make the reader allocate or wait for more than the file
holds; chunk sizes, CRCs and the footer are checked. Every problem becomes a one-line
`LogError` naming the file. A recording cut off by a crash (no summary, no footer) is read in
`strict=False` mode up to the last whole record, and `recover` rewrites that into a finished
file; `recover_bag` does so in place for every cut-off file of a rosbag2 bag directory and
regenerates its `metadata.yaml` (like `ros2 bag reindex`), so that every tool opens the bag
afterwards. A file still being recorded (`livelock`) is never recovered.
"""

from __future__ import annotations

import io
import os
import re
import struct
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import lz4.frame
import yaml
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.records import Channel, Header, Metadata, Schema
from mcap.writer import CompressionType, Writer

from . import bagmeta
from .bagmeta import METADATA, BagStats, FileStats, TopicStats
from .livelock import LIVE, is_live, live_files

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_METADATA = (
    0x01,
    0x02,
    0x03,
    0x04,
    0x05,
    0x06,
    0x0C,
)
_FOOTER_LEN = 20  # summary_start u64, summary_offset_start u64, crc u32
_MAX_INFLATION = 1000  # a larger uncompressed/compressed ratio means corruption
_RECORD = struct.Struct("<BQ")
_READ_BUFFER = 1 << 16
_PARSED = frozenset(
    (OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_METADATA)
)
_MESSAGE = struct.Struct("<HIQQ")
_CHUNK = struct.Struct("<QQQI")
ENCODINGS = {"cdr"}
SCHEMA_ENCODINGS = {"ros2msg", "ros2idl"}
RECOVER_HINT = "leadscrew-squeak recover"
BROKEN_SUFFIX = ".broken"  # `<name>.mcap.broken`: an original set aside by recover
_REWRITE_SUFFIX = ".recovering"  # `<name>.mcap.recovering`: a rewrite not yet verified


class LogError(Exception):
    """A log that cannot be read as asked; the message is one line naming the file."""

    def __init__(self, path: Path | str, problem: str):
        super().__init__(f"{path}: {' '.join(str(problem).split())}")
        self.path, self.problem = Path(path), problem


@dataclass(frozen=True)
class Topic:
    """A channel of a log with its schema: what a copy needs to write it back verbatim."""

    name: str  # fully qualified ('/motor_speed'), as ROS 2 resolves the stored name
    type_name: str  # 'pkg/msg/Type', 'pkg/srv/Type_Event'
    schema_encoding: str
    schema: str  # complete message definition
    message_encoding: str
    metadata: dict[str, str]
    schema_name: str = ""  # as stored (e.g. 'pkg/Type'); copies keep it verbatim
    topic_name: str = ""  # as stored (e.g. 'motor_speed'), when it differs from `name`

    @property
    def stored_schema_name(self) -> str:
        """The schema name as stored, or the type name when the log stored none."""
        return self.schema_name or self.type_name

    @property
    def stored_name(self) -> str:
        """The topic name as stored: copies and metadata.yaml keep it verbatim."""
        return self.topic_name or self.name


def log_topic(
    name: str,
    stored_type: str,
    schema_encoding: str,
    schema: str,
    message_encoding: str,
    metadata: dict[str, str],
) -> Topic:
    """The `Topic` of a channel or .db3 `topics` row as stored: its name fully qualified (a
    name stored without the leading slash, as rosbags and other writers allow, is relative to
    the root namespace) and its type in the 'pkg/<interface kind>/Type' form (legacy
    'pkg/Type' names are messages), the stored spellings kept for verbatim copies."""
    full = name if name.startswith("/") else "/" + name
    return Topic(
        full,
        _full_type(stored_type),
        schema_encoding,
        schema,
        message_encoding,
        metadata,
        stored_type,
        name if name != full else "",
    )


@dataclass(frozen=True)
class LogMessage:
    """One message of a log: its topic, times [ns], sequence and serialized payload."""

    topic: Topic
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes  # serialized (CDR) payload


@dataclass
class LogInfo:
    """What reading a file found: header, topics, counts, and where it stopped if damaged."""

    path: Path
    storage: str = "mcap"  # or 'sqlite3' (rosbag2 .db3)
    profile: str = ""
    library: str = ""
    topics: dict[str, Topic] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    start_ns: int | None = None
    end_ns: int | None = None
    complete: bool = False  # footer reached
    damage: str = ""  # why reading stopped early ('' if it did not)
    cut_off: bool = False  # damage is only a missing tail: every byte before it read
    live: bool = False  # a recorder is writing the file: its tail is still to come
    # MCAP Metadata records read (e.g. `logmeta`'s), name -> string map; kept by `recover`
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    # A topic recorded with more than one type (MCAP channels, .db3 `topics` rows of one
    # name): `topics` holds its first type, these the others by (name, type), with their
    # messages (which `counts` includes)
    retyped: dict[tuple[str, str], Topic] = field(default_factory=dict)
    retyped_counts: Counter = field(default_factory=Counter)

    @property
    def messages(self) -> int:
        """Messages read, over all topics."""
        return sum(self.counts.values())

    def add_topic(self, topic: Topic) -> Topic:
        """The topic a channel (or .db3 topic row) of `topic` gets: the one of its name and
        type already known, or `topic`, kept in `topics` or, for a further type, `retyped`."""
        known = self.topics.setdefault(topic.name, topic)
        if known.type_name == topic.type_name:
            return known
        return self.retyped.setdefault((topic.name, topic.type_name), topic)

    def count(self, topic: Topic) -> None:
        """One message of `topic` read."""
        self.counts[topic.name] += 1
        if self.retyped and topic is not self.topics[topic.name]:
            self.retyped_counts[topic.name, topic.type_name] += 1

    def type_counts(self) -> list[tuple[Topic, int]]:
        """Every (topic, messages) by name, then type: a topic recorded with several types
        once per type."""
        out = []
        for name, t in self.topics.items():
            others = [
                (o, self.retyped_counts[key]) for key, o in self.retyped.items() if key[0] == name
            ]
            out.append((t, self.counts[name] - sum(n for _, n in others)))
            out += others
        return sorted(out, key=lambda tn: (tn[0].name, tn[0].type_name))


def log_files(path: Path | str) -> list[Path]:
    """The MCAP files of a log: the file itself, or a directory's .mcap files in split order
    (rosbag2 and our recorder number splits `<name>_<index>.mcap`)."""
    path = Path(path)
    if path.is_dir():
        refuse_compressed(path)
        files = _split_files(path)
        if not files:
            raise LogError(path, "directory holds no .mcap files")
        return files
    if not path.exists():
        raise LogError(path, "no such file or directory")
    return [path]


def refuse_compressed(bag: Path) -> None:
    """LogError if the `metadata.yaml` of bag directory `bag` declares rosbag2 compression
    (FILE: whole `.mcap.zstd` / `.db3.zstd` files; MESSAGE: each payload compressed), which no
    reader here decodes: the error names the storage and compression and how to convert.
    A missing or unreadable metadata.yaml is left to the readers."""
    try:
        info = yaml.safe_load((bag / METADATA).read_text(encoding="utf-8"))
        info = info["rosbag2_bagfile_information"]
        mode, fmt = info.get("compression_mode") or "", info.get("compression_format") or ""
        storage = info.get("storage_identifier") or "unknown"
    except (OSError, UnicodeDecodeError, yaml.YAMLError, TypeError, KeyError, AttributeError):
        return
    if str(mode).lower() in ("", "none"):
        return
    raise LogError(
        bag,
        f"rosbag2 bag with {str(mode).upper()} compression ({fmt}, storage "
        f"{storage}), which is not read here; convert it to an uncompressed "
        f"bag: rosbags-convert --src {bag} --dst {bag.name}_plain --dst-storage "
        f"mcap (or ros2 bag convert with compression_mode: none)",
    )


def _split_files(directory: Path) -> list[Path]:
    return sorted(directory.glob("*.mcap"), key=_split_key)


def _split_key(p: Path) -> tuple[str, int, str]:
    m = re.search(r"_(\d+)\.mcap$", p.name)
    return (p.name[: m.start()] if m else p.stem, int(m.group(1)) if m else -1, p.name)


def is_complete(path: Path | str) -> bool:
    """True if the file ends with a footer and the closing magic (it was closed cleanly)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, io.SEEK_END)
            size = f.tell()
            if size < 2 * len(MAGIC) + 9 + _FOOTER_LEN:
                return False
            f.seek(size - len(MAGIC) - 9 - _FOOTER_LEN)
            tail = f.read()
    except OSError:
        return False
    op, length = _RECORD.unpack_from(tail)
    return op == OP_FOOTER and length == _FOOTER_LEN and tail.endswith(MAGIC)


def read_messages(
    path: Path | str,
    topics: set[str] | None = None,
    strict: bool = True,
    info: LogInfo | None = None,
) -> Iterator[LogMessage]:
    """Messages of one MCAP file in file order (topics: only these, fully qualified names).
    strict=True raises LogError for a file without footer; strict=False stops quietly at the
    first damaged or missing record and notes why in `info.damage`."""
    path = Path(path)
    info = info if info is not None else LogInfo(path)
    if strict and path.is_file() and not is_complete(path):
        raise LogError(path, _incomplete(path))
    try:
        with open(path, "rb", buffering=_READ_BUFFER) as f:
            size = f.seek(0, io.SEEK_END)
            if size == 0:
                raise LogError(path, "empty file")
            f.seek(0)
            yield from _records(path, f, size, topics, strict, info)
    except IsADirectoryError:
        raise LogError(path, "is a directory, not an MCAP file") from None
    except OSError as exc:
        raise LogError(path, exc.strerror or str(exc)) from None


def _incomplete(path: Path) -> str:
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if not head:
        return "empty file"
    if head != MAGIC:
        return "not an MCAP file (bad magic)"
    if is_live(path):
        return f"{LIVE}: it gets its footer when the recording stops; read it then"
    return (
        f"truncated: no footer (the recording was interrupted); "
        f"recover it with `{RECOVER_HINT} {bag_of(path) or path}`"
    )


def bag_of(path: Path | str) -> Path | None:
    """The rosbag2 bag directory a log file belongs to (its parent holds `metadata.yaml`, or
    the file is named `<directory name>_<index>.mcap` (or `.db3`) as rosbag2 and our recorder
    name splits); None for a loose file."""
    path = Path(path)
    parent = path.parent
    if (parent / METADATA).is_file() or re.fullmatch(
        re.escape(parent.name) + r"_\d+\.(mcap|db3)", path.name
    ):
        return parent
    return None


class _Damage(Exception):
    pass


class _CutOff(_Damage):
    """The file ends inside or right after a whole record: a recording cut off, not corrupted."""


def _records(
    path: Path, f: IO[bytes], size: int, topics: set[str] | None, strict: bool, info: LogInfo
) -> Iterator[LogMessage]:
    """The messages of the open file `f` of `size` bytes, read record by record."""
    if f.read(len(MAGIC)) != MAGIC:
        raise LogError(path, "not an MCAP file (bad magic)")
    schemas: dict[int, tuple[str, str, str]] = {}
    channels: dict[int, Topic | None] = {}  # None: channel filtered out
    pos = len(MAGIC)
    try:
        while True:
            if pos == size:
                raise _CutOff(f"ends after {size} bytes without a footer (interrupted)")
            if pos + 9 > size:
                raise _CutOff(f"cut off at byte {pos} of {size}")
            op, length = _RECORD.unpack(_read(f, 9))
            body = pos + 9
            if length > size - body:
                raise _CutOff(
                    f"record at byte {pos} claims {length} bytes, only {size - body} remain"
                )
            if pos == len(MAGIC) and op != OP_HEADER:
                raise _Damage("first record is not an MCAP header")
            if op in _PARSED:
                rec = _read(f, length)
            else:  # indexes, attachments...: not read
                f.seek(length, io.SEEK_CUR)
            if op == OP_HEADER:
                header = Header.read(_stream(rec))
                info.profile, info.library = header.profile, header.library
                if header.profile != "ros2":
                    raise LogError(
                        path, f"foreign MCAP: profile {header.profile!r}, expected 'ros2'"
                    )
            elif op == OP_SCHEMA:
                s = Schema.read(_stream(rec))
                schemas[s.id] = (s.name, s.encoding, s.data.decode())
            elif op == OP_CHANNEL:
                _channel(path, Channel.read(_stream(rec)), schemas, channels, topics, info)
            elif op == OP_MESSAGE:
                m = _message(rec, 0, length, channels, info)
                if m is not None:
                    yield m
            elif op == OP_CHUNK:
                for _, chunk_rec in _chunk(rec):
                    if isinstance(chunk_rec, Schema):
                        schemas[chunk_rec.id] = (
                            chunk_rec.name,
                            chunk_rec.encoding,
                            chunk_rec.data.decode(),
                        )
                    elif isinstance(chunk_rec, Channel):
                        _channel(path, chunk_rec, schemas, channels, topics, info)
                    else:
                        m = _message(chunk_rec, 0, len(chunk_rec), channels, info)
                        if m is not None:
                            yield m
            elif op == OP_METADATA:
                record = Metadata.read(_stream(rec))
                info.metadata.setdefault(record.name, record.metadata)
            elif op == OP_FOOTER:
                if f.read(len(MAGIC)) != MAGIC:
                    raise _Damage("no closing magic after the footer")
                info.complete = True
                return
            pos = body + length
    except LogError:
        raise
    except _Damage as exc:
        problem = str(exc)
        info.cut_off = isinstance(exc, _CutOff)
    except (Exception, MemoryError) as exc:  # any parse error of a damaged record
        problem = f"damaged record near byte {pos}: {type(exc).__name__}: {exc}"
    if strict:
        raise LogError(path, problem)
    info.damage = problem


def _read(f: IO[bytes], n: int) -> bytes:
    """`n` bytes at the file position (checked against the size first, by the caller)."""
    data = f.read(n)
    if len(data) != n:
        raise _CutOff(f"file shrank while it was read ({len(data)} of {n} bytes there)")
    return data


def _stream(rec: bytes) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(rec))


def _channel(
    path: Path,
    c: Channel,
    schemas: dict[int, tuple[str, str, str]],
    channels: dict[int, Topic | None],
    topics: set[str] | None,
    info: LogInfo,
) -> None:
    if c.schema_id not in schemas:
        raise _Damage(f"channel {c.topic!r} refers to unknown schema {c.schema_id}")
    name, encoding, text = schemas[c.schema_id]
    if c.message_encoding not in ENCODINGS or encoding not in SCHEMA_ENCODINGS:
        raise LogError(
            path,
            f"foreign MCAP: topic {c.topic} is {c.message_encoding!r} with "
            f"a {encoding!r} schema, expected cdr with ros2msg",
        )
    topic = log_topic(c.topic, name, encoding, text, c.message_encoding, dict(c.metadata))
    if topics is not None and topic.name not in topics:
        channels[c.id] = None
        return
    channels[c.id] = info.add_topic(topic)


def _full_type(name: str) -> str:
    """'pkg/msg/Type' of a legacy 'pkg/Type'; 'pkg/srv/Type_Event' and the like stay."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


def _message(
    buf: bytes, start: int, length: int, channels: dict[int, Topic | None], info: LogInfo
) -> LogMessage | None:
    if length < _MESSAGE.size:
        raise _Damage(f"message record of {length} bytes")
    channel_id, sequence, log_time, publish_time = _MESSAGE.unpack_from(buf, start)
    if channel_id not in channels:
        raise _Damage(f"message on unknown channel {channel_id}")
    topic = channels[channel_id]
    if topic is None:
        return None
    info.count(topic)
    info.start_ns = log_time if info.start_ns is None else min(info.start_ns, log_time)
    info.end_ns = log_time if info.end_ns is None else max(info.end_ns, log_time)
    return LogMessage(
        topic, log_time, publish_time, sequence, bytes(buf[start + _MESSAGE.size : start + length])
    )


def _chunk(rec: bytes) -> Iterator[tuple[int, bytes | Schema | Channel]]:
    """Schemas, channels and raw message records of a chunk record's body, after size and CRC
    checks."""
    buf = memoryview(rec)
    _, _, usize, crc = _CHUNK.unpack_from(buf, 0)
    p = _CHUNK.size
    (clen,) = struct.unpack_from("<I", buf, p)
    compression = bytes(buf[p + 4 : p + 4 + clen]).decode()
    p += 4 + clen
    (dlen,) = struct.unpack_from("<Q", buf, p)
    data = buf[p + 8 : p + 8 + dlen]
    if p + 8 + dlen > len(buf) or len(data) != dlen:
        raise _Damage("chunk data overruns its record")
    if usize > max(_MAX_INFLATION * dlen, 1 << 20):
        raise _Damage(f"chunk claims {usize} bytes uncompressed from {dlen}")
    if compression == "zstd":
        raw = zstandard.ZstdDecompressor().stream_reader(data).read(usize + 1)
    elif compression == "lz4":
        raw = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=usize + 1)
    elif compression == "":
        raw = bytes(data)
    else:
        raise _Damage(f"unknown chunk compression {compression!r}")
    if len(raw) != usize:
        raise _Damage(f"chunk inflates to {len(raw)} bytes, header says {usize}")
    if crc and zlib.crc32(raw) != crc:
        raise _Damage("chunk CRC mismatch (corrupted data)")
    pos, end = 0, len(raw)
    while pos < end:
        if pos + 9 > end:
            raise _Damage("chunk records cut off")
        op, rlen = _RECORD.unpack_from(raw, pos)
        start = pos + 9
        if rlen > end - start:
            raise _Damage("chunk record overruns its chunk")
        if op == OP_MESSAGE:
            yield OP_MESSAGE, raw[start : start + rlen]
        elif op == OP_SCHEMA:
            yield OP_SCHEMA, Schema.read(ReadDataStream(io.BytesIO(raw[start : start + rlen])))
        elif op == OP_CHANNEL:
            yield OP_CHANNEL, Channel.read(ReadDataStream(io.BytesIO(raw[start : start + rlen])))
        pos = start + rlen


def read_log(
    path: Path | str, topics: set[str] | None = None, strict: bool = True
) -> Iterator[LogMessage]:
    """Messages of a log file or of a directory of split files, file after file."""
    for f in log_files(path):
        yield from read_messages(f, topics, strict)


def inspect(path: Path | str) -> LogInfo:
    """Read a whole file tolerantly: topics, counts, time span, complete or where damaged."""
    info = LogInfo(Path(path), live=is_live(path))
    for _ in read_messages(path, strict=False, info=info):
        pass
    return info


def _refuse_live(path: Path, files: list[Path]) -> None:
    """Raise LogError if a recorder writes any of `files`: recovering would replace the file
    under it, and it would go on writing into the replaced copy."""
    live = [f for f in files if is_live(f)]
    if live:
        raise LogError(
            live[0],
            f"{LIVE}; `{RECOVER_HINT}` leaves {path} alone until the "
            f"recording stops (nothing changed)",
        )


def recover(
    src: Path | str, dst: Path | str, compression: CompressionType = CompressionType.ZSTD
) -> LogInfo:
    """Rewrite every whole message of a cut-off (or damaged) file into a finished file.

    Parameters
    ----------
    src : path
        The damaged MCAP file.
    dst : path
        The file to write (removed again when nothing could be recovered).
    compression : CompressionType
        Chunk compression of `dst`.

    Returns
    -------
    LogInfo
        What reading `src` found: topics, counts, where it stopped.

    Raises
    ------
    LogError
        No whole message to recover, or `src` is still being recorded (a live writer holds
        its lock: `bag.livelock`).
    """
    _refuse_live(Path(src), [Path(src)])
    info = _rewrite(src, dst, compression)
    if not info.messages:
        Path(dst).unlink(missing_ok=True)
        raise LogError(src, info.damage or "no messages to recover")
    return info


def _rewrite(
    src: Path | str, dst: Path | str, compression: CompressionType = CompressionType.ZSTD
) -> LogInfo:
    """`recover` without the check for messages: dst is finished and synced even if empty."""
    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise LogError(dst, "recovery output must differ from its input")
    info = LogInfo(src)
    try:
        dst.parent.mkdir(parents=True, exist_ok=True)  # like `replay --out DIR`
        with open(dst, "wb") as out:
            writer = Writer(out, compression=compression)
            writer.start(profile="ros2", library="leadscrew_ros recover")
            ids: dict[tuple[str, str], int] = {}  # a channel per topic and type
            for m in read_messages(src, strict=False, info=info):
                key = (m.topic.name, m.topic.type_name)
                if key not in ids:
                    ids[key] = _register(writer, m.topic)
                writer.add_message(ids[key], m.log_time_ns, m.data, m.publish_time_ns, m.sequence)
            for t in [*info.topics.values(), *info.retyped.values()]:  # without messages yet
                if (t.name, t.type_name) not in ids:
                    _register(writer, t)
            for name, record in info.metadata.items():  # e.g. the `leadscrew_ros` record
                writer.add_metadata(name, record)
            writer.finish()
            out.flush()
            os.fsync(out.fileno())
    except OSError as exc:
        dst.unlink(missing_ok=True)
        raise LogError(dst, exc.strerror or str(exc)) from None
    except LogError:  # foreign or not MCAP: nothing written
        dst.unlink(missing_ok=True)
        raise
    return info


def _register(writer: Writer, t: Topic) -> int:
    schema = writer.register_schema(t.stored_schema_name, t.schema_encoding, t.schema.encode())
    return writer.register_channel(t.stored_name, t.message_encoding, schema, t.metadata)


# ----------------------------------------------------------------------------- bag recovery
@dataclass
class FileRecovery:
    """What `recover_bag` did to one MCAP file."""

    path: Path
    action: str  # 'complete' (untouched), 'recovered' or 'set aside'
    messages: int  # whole messages the file holds now (0 if set aside)
    topics: int = 0
    damage: str = ""  # why the original could not be read to its end
    broken: Path | None = None  # the original, kept as `<name>.mcap.broken`
    info: LogInfo | None = field(default=None, repr=False)  # of the file as it is now

    def line(self) -> str:
        """One line for the user."""
        if self.action == "complete":
            return f"{self.path}: complete, {self.messages} messages"
        if self.action == "set aside":
            return f"{self.path}: no whole message ({self.damage}); moved to {self.broken}"
        kept = (
            f"; original kept as {self.broken} (damaged before its end: a specialised tool "
            f"may get more out of it)"
            if self.broken
            else ""
        )
        return (
            f"{self.path}: recovered {self.messages} messages on {self.topics} topics "
            f"(was: {self.damage}){kept}"
        )


@dataclass
class BagRecovery:
    """What `recover_bag` did: per file, and whether the bag's `metadata.yaml` was written."""

    path: Path  # the bag directory or file asked for
    bag: Path | None  # the bag directory (None: a loose file)
    files: list[FileRecovery] = field(default_factory=list)
    metadata_written: bool = False
    still_cut_off: list[Path] = field(default_factory=list)  # other files of the bag

    @property
    def changed(self) -> bool:
        """True if the recovery rewrote a file or wrote the metadata."""
        return self.metadata_written or any(f.action != "complete" for f in self.files)

    @property
    def messages(self) -> int:
        """Messages in the recovered files."""
        return sum(f.messages for f in self.files)

    def summary(self) -> str:
        """The one-line result."""
        what = self.bag or self.path
        if not self.changed:
            return f"nothing to recover: {what} is complete ({self.messages} messages)"
        done = [f"{sum(f.action == 'recovered' for f in self.files)} file(s) recovered"]
        if self.metadata_written:
            assert self.bag is not None  # metadata is written only for a bag directory
            done.append(f"{self.bag / METADATA} regenerated")
        rest = (
            f"; {len(self.still_cut_off)} other file(s) of the bag still cut off: "
            f"`{RECOVER_HINT} {self.bag}`"
            if self.still_cut_off
            else ""
        )
        return f"{what}: " + ", ".join(done) + f"; {self.messages} messages readable" + rest


def cut_off_bags(directory: Path | str) -> list[Path]:
    """Recordings under `directory` that need `recover_bag`: bag directories directly under it
    with .mcap files but no `metadata.yaml`, or with a file lacking its footer, and loose .mcap
    files lacking their footer; not those still being recorded (`live_recordings`). Cheap
    (reads file tails only), so a node can call it on start."""
    return _scan(directory)[0]


def live_recordings(directory: Path | str) -> list[Path]:
    """Bag directories and loose .mcap files directly under `directory` that a recorder (of any
    process) is writing now."""
    return _scan(directory)[1]


def _scan(directory: Path | str) -> tuple[list[Path], list[Path]]:
    """(cut off, live) recordings directly under `directory`."""
    cut, live = [], []
    try:
        entries = sorted(Path(directory).iterdir())
    except OSError:
        return [], []
    for entry in entries:
        if entry.is_dir():
            files = list(entry.glob("*.mcap"))
            if files and live_files(entry):
                live.append(entry)
            elif files and (
                not (entry / METADATA).is_file() or not all(is_complete(f) for f in files)
            ):
                cut.append(entry)
        elif entry.suffix == ".mcap" and entry.is_file() and not is_complete(entry):
            (live if is_live(entry) else cut).append(entry)
    return cut, live


def recover_bag(path: Path | str) -> BagRecovery:
    """Make a bag directory, or one MCAP file, readable by every tool; idempotent.

    Each cut-off or damaged file is rewritten complete beside itself (`<name>.mcap.recovering`),
    the original renamed `<name>.mcap.broken`, the rewrite moved to the original name and read
    back in full; only when it holds exactly the recovered messages per topic is the original
    removed. An original damaged before its end (not just cut off) is kept as `.broken`; one
    without a single whole message is moved there and left out of the bag. A bag's
    `metadata.yaml` is regenerated from its files when it is missing or does not match them
    (keeping its `custom_data` and QoS profiles). Raises LogError (nothing changed for the
    file concerned) for a file that is not a ros2 MCAP or a rewrite that does not verify, and
    (nothing changed) when a file of the bag is still being recorded.
    """
    path = Path(path)
    bag = path if path.is_dir() else bag_of(path)
    _refuse_live(path, log_files(bag or path) if bag is not None else [path])
    _restore_interrupted(path if path.is_dir() else path.parent)
    result = BagRecovery(path, bag, [_recover_file(f) for f in log_files(path)])
    if bag is not None:
        result.metadata_written = _reindex(bag, result.files)
        result.still_cut_off = [f for f in _split_files(bag) if f != path and not is_complete(f)]
    return result


def _restore_interrupted(directory: Path) -> None:
    """A recovery killed between its two renames left `<name>.mcap.broken` and the unverified
    `<name>.mcap.recovering` without `<name>.mcap`: put the original back, so this run starts
    over from it. A file set aside for want of messages has no `.recovering` and stays."""
    for rewrite in directory.glob("*.mcap" + _REWRITE_SUFFIX):
        original = rewrite.with_name(rewrite.name[: -len(_REWRITE_SUFFIX)])
        broken = original.with_name(original.name + BROKEN_SUFFIX)
        if not original.exists() and broken.exists():
            os.replace(broken, original)
        rewrite.unlink()


def _recover_file(path: Path) -> FileRecovery:
    if is_complete(path):
        info = inspect(path)
        if not info.damage:
            return FileRecovery(path, "complete", info.messages, len(info.topics), info=info)
    rewrite = path.with_name(path.name + _REWRITE_SUFFIX)
    broken = path.with_name(path.name + BROKEN_SUFFIX)
    try:
        info = _rewrite(path, rewrite)
    except LogError as exc:
        if path.stat().st_size or path.suffix != ".mcap":  # foreign, not MCAP, or not a
            raise  # split file: leave it alone
        info = LogInfo(path, damage=exc.problem)  # an empty file: set it aside
    if not info.messages:
        rewrite.unlink(missing_ok=True)
        os.replace(path, broken)
        return FileRecovery(path, "set aside", 0, damage=info.damage, broken=broken)
    os.replace(path, broken)
    os.replace(rewrite, path)
    _sync_directory(path.parent)
    check = LogInfo(path)
    try:
        for _ in read_messages(path, strict=True, info=check):
            pass
        problem = (
            ""
            if check.counts == info.counts
            else (f"read back {check.messages} messages, expected {info.messages}")
        )
    except LogError as exc:
        problem = exc.problem
    if problem:
        os.replace(broken, path)  # the original back in place
        raise LogError(path, f"recovery did not verify ({problem}); the file is unchanged")
    kept: Path | None = broken
    if info.cut_off:
        broken.unlink()
        kept = None
    return FileRecovery(
        path, "recovered", info.messages, len(info.topics), info.damage, kept, check
    )


def _sync_directory(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def bag_stats(infos: list[LogInfo], old: dict | None = None) -> BagStats:
    """What metadata.yaml should say of a bag whose files, in split order, read as `infos`
    (custom data and QoS profiles of the `rosbag2_bagfile_information` `old`, if given); a
    topic recorded with two types is listed once per type."""
    old = old or {}
    old_qos = {
        (t.get("topic_metadata") or {}).get("name"): (t.get("topic_metadata") or {}).get(
            "offered_qos_profiles"
        )
        for t in old.get("topics_with_message_count") or []
        if isinstance(t, dict) and isinstance(t.get("topic_metadata") or {}, dict)
    }
    custom = old.get("custom_data")
    stats = BagStats(custom_data=dict(custom) if isinstance(custom, dict) else {})
    topics: dict[tuple[str, str], TopicStats] = {}
    for info in infos:
        stats.files.append(FileStats(info.path, info.start_ns, info.end_ns, info.messages))
        for t, n in info.type_counts():
            key = (t.name, t.type_name)
            if key not in topics:  # the name as stored: what rosbags and ros2 bag read
                qos = old_qos.get(t.stored_name) or t.metadata.get("offered_qos_profiles", "")
                topics[key] = TopicStats(t.stored_name, t.type_name, 0, str(qos))
            topics[key].count += n
    stats.topics = list(topics.values())
    return stats


def metadata_problem(bag: Path, infos: list[LogInfo] | None = None) -> str:
    """What is wrong with the metadata.yaml of bag directory `bag` (`bagmeta.problem`, against
    the files as read into `infos` when given) and how to mend it; '' if nothing."""
    problem = bagmeta.problem(bag, None if infos is None else bag_stats(infos))
    if not problem:
        return ""
    mend = (
        f"`{RECOVER_HINT} {bag}` mends it"
        if _split_files(bag)
        else f"`ros2 bag reindex {bag}` mends it"
    )
    return f"{problem}; other tools (rosbags, ros2 bag) refuse or misread the bag; {mend}"


def _reindex(bag: Path, done: list[FileRecovery]) -> bool:
    """Write `bag/metadata.yaml` from the bag's files unless nothing was recovered and it
    already passes `bagmeta.problem` against them; True if written."""
    known = {f.path: f.info for f in done}
    stats = bag_stats([known.get(f) or inspect(f) for f in _split_files(bag)], _read_metadata(bag))
    if (
        all(f.action == "complete" for f in done)
        and (bag / METADATA).is_file()
        and not bagmeta.problem(bag, stats)
    ):
        return False
    try:
        stats.write(bag)
    except OSError as exc:
        raise LogError(bag / METADATA, exc.strerror or str(exc)) from None
    return True


def _read_metadata(bag: Path) -> dict:
    """The `rosbag2_bagfile_information` of an existing metadata.yaml ({} if none or bad)."""
    try:
        doc = yaml.safe_load((bag / METADATA).read_text(encoding="utf-8"))
        info = doc["rosbag2_bagfile_information"]
    except (OSError, UnicodeDecodeError, yaml.YAMLError, TypeError, KeyError):
        return {}
    return info if isinstance(info, dict) else {}
