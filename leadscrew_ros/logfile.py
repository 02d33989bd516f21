"""Reading ROS 2 MCAP logs (ours, rosbag2's, rosbags') defensively, and recovering cut-off files.

Records are parsed sequentially from a memory map, so a damaged length can never make the
reader allocate or wait for more than the file holds; chunk sizes, CRCs and the footer are
checked. Every problem becomes a one-line `LogError` naming the file. A recording cut off by a
crash (no summary, no footer) is read in `strict=False` mode up to the last whole record, and
`recover` rewrites that into a finished file.
"""

from __future__ import annotations

import io
import mmap
import re
import struct
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.records import Channel, Header, Schema
from mcap.writer import CompressionType, Writer

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END = (
    0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x0F)
_FOOTER_LEN = 20                      # summary_start u64, summary_offset_start u64, crc u32
_MAX_INFLATION = 1000                 # a larger uncompressed/compressed ratio means corruption
_RECORD = struct.Struct("<BQ")
_MESSAGE = struct.Struct("<HIQQ")
_CHUNK = struct.Struct("<QQQI")
ENCODINGS = {"cdr"}
SCHEMA_ENCODINGS = {"ros2msg", "ros2idl"}
RECOVER_HINT = "leadscrew-squeak recover"


class LogError(Exception):
    """A log that cannot be read as asked; the message is one line naming the file."""

    def __init__(self, path: Path | str, problem: str):
        super().__init__(f"{path}: {' '.join(str(problem).split())}")
        self.path, self.problem = Path(path), problem


@dataclass(frozen=True)
class Topic:
    name: str
    type_name: str              # 'pkg/msg/Type'
    schema_encoding: str
    schema: str                 # complete message definition
    message_encoding: str
    metadata: dict[str, str]
    schema_name: str = ""       # as stored (e.g. 'pkg/Type'); copies keep it verbatim

    @property
    def stored_schema_name(self) -> str:
        return self.schema_name or self.type_name


@dataclass(frozen=True)
class LogMessage:
    topic: Topic
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes                 # serialized (CDR) payload


@dataclass
class LogInfo:
    """What reading a file found: header, topics, counts, and where it stopped if damaged."""

    path: Path
    profile: str = ""
    library: str = ""
    topics: dict[str, Topic] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    start_ns: int | None = None
    end_ns: int | None = None
    complete: bool = False            # footer reached
    damage: str = ""                  # why reading stopped early ('' if it did not)

    @property
    def messages(self) -> int:
        return sum(self.counts.values())


def log_files(path: Path | str) -> list[Path]:
    """The MCAP files of a log: the file itself, or a directory's *.mcap files in split order
    (rosbag2 and our recorder number splits `<name>_<index>.mcap`)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("*.mcap"), key=_split_key)
        if not files:
            raise LogError(path, "directory holds no .mcap files")
        return files
    if not path.exists():
        raise LogError(path, "no such file or directory")
    return [path]


def _split_key(p: Path):
    m = re.search(r"_(\d+)\.mcap$", p.name)
    return (p.name[:m.start()] if m else p.stem, int(m.group(1)) if m else -1, p.name)


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


def read_messages(path: Path | str, topics: set[str] | None = None, strict: bool = True,
                  info: LogInfo | None = None) -> Iterator[LogMessage]:
    """Messages of one MCAP file in file order (topics: only these). strict=True raises
    LogError for a file without footer; strict=False stops quietly at the first damaged or
    missing record and notes why in `info.damage`."""
    path = Path(path)
    info = info if info is not None else LogInfo(path)
    if strict and path.is_file() and not is_complete(path):
        raise LogError(path, _incomplete(path))
    try:
        with open(path, "rb") as f:
            size = f.seek(0, io.SEEK_END)
            if size == 0:
                raise LogError(path, "empty file")
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                yield from _records(path, buf, topics, strict, info)
    except IsADirectoryError:
        raise LogError(path, "is a directory, not an MCAP file") from None
    except OSError as exc:
        raise LogError(path, exc.strerror or exc) from None


def _incomplete(path: Path) -> str:
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if not head:
        return "empty file"
    if head != MAGIC:
        return "not an MCAP file (bad magic)"
    return (f"truncated: no footer (the recording was interrupted); "
            f"recover it with `{RECOVER_HINT} {path}`")


class _Damage(Exception):
    pass


def _records(path: Path, buf, topics, strict: bool, info: LogInfo) -> Iterator[LogMessage]:
    size = len(buf)
    if buf[:len(MAGIC)] != MAGIC:
        raise LogError(path, "not an MCAP file (bad magic)")
    schemas: dict[int, tuple[str, str, str]] = {}
    channels: dict[int, Topic | None] = {}            # None: channel filtered out
    pos = len(MAGIC)
    try:
        while True:
            if pos == size:
                raise _Damage(f"ends after {size} bytes without a footer (interrupted)")
            if pos + 9 > size:
                raise _Damage(f"cut off at byte {pos} of {size}")
            op, length = _RECORD.unpack_from(buf, pos)
            body = pos + 9
            if length > size - body:
                raise _Damage(f"record at byte {pos} claims {length} bytes, "
                              f"only {size - body} remain")
            if pos == len(MAGIC) and op != OP_HEADER:
                raise _Damage("first record is not an MCAP header")
            if op == OP_HEADER:
                header = Header.read(_stream(buf, body, length))
                info.profile, info.library = header.profile, header.library
                if header.profile != "ros2":
                    raise LogError(path, f"foreign MCAP: profile {header.profile!r}, "
                                         f"expected 'ros2'")
            elif op == OP_SCHEMA:
                s = Schema.read(_stream(buf, body, length))
                schemas[s.id] = (s.name, s.encoding, s.data.decode())
            elif op == OP_CHANNEL:
                _channel(path, Channel.read(_stream(buf, body, length)), schemas, channels,
                         topics, info)
            elif op == OP_MESSAGE:
                m = _message(buf, body, length, channels, info)
                if m is not None:
                    yield m
            elif op == OP_CHUNK:
                for kind, rec in _chunk(buf, body, length):
                    if kind == OP_SCHEMA:
                        schemas[rec.id] = (rec.name, rec.encoding, rec.data.decode())
                    elif kind == OP_CHANNEL:
                        _channel(path, rec, schemas, channels, topics, info)
                    else:
                        m = _message(rec, 0, len(rec), channels, info)
                        if m is not None:
                            yield m
            elif op == OP_FOOTER:
                if buf[body + length:body + length + len(MAGIC)] != MAGIC:
                    raise _Damage("no closing magic after the footer")
                info.complete = True
                return
            pos = body + length
    except LogError:
        raise
    except _Damage as exc:
        problem = str(exc)
    except (Exception, MemoryError) as exc:       # any parse error of a damaged record
        problem = f"damaged record near byte {pos}: {type(exc).__name__}: {exc}"
    if strict:
        raise LogError(path, problem)
    info.damage = problem


def _stream(buf, start: int, length: int) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(buf[start:start + length]))


def _channel(path: Path, c: Channel, schemas, channels, topics, info: LogInfo) -> None:
    if topics is not None and c.topic not in topics:
        channels[c.id] = None
        return
    if c.schema_id not in schemas:
        raise _Damage(f"channel {c.topic!r} refers to unknown schema {c.schema_id}")
    name, encoding, text = schemas[c.schema_id]
    if c.message_encoding not in ENCODINGS or encoding not in SCHEMA_ENCODINGS:
        raise LogError(path, f"foreign MCAP: topic {c.topic} is {c.message_encoding!r} with "
                             f"a {encoding!r} schema, expected cdr with ros2msg")
    topic = Topic(c.topic, _full_type(name), encoding, text, c.message_encoding,
                  dict(c.metadata), name)
    channels[c.id] = info.topics.setdefault(c.topic, topic)


def _full_type(name: str) -> str:
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[-1]}" if len(parts) in (2, 3) else name


def _message(buf, start: int, length: int, channels, info: LogInfo) -> LogMessage | None:
    if length < _MESSAGE.size:
        raise _Damage(f"message record of {length} bytes")
    channel_id, sequence, log_time, publish_time = _MESSAGE.unpack_from(buf, start)
    if channel_id not in channels:
        raise _Damage(f"message on unknown channel {channel_id}")
    topic = channels[channel_id]
    if topic is None:
        return None
    info.counts[topic.name] += 1
    info.start_ns = log_time if info.start_ns is None else min(info.start_ns, log_time)
    info.end_ns = log_time if info.end_ns is None else max(info.end_ns, log_time)
    return LogMessage(topic, log_time, publish_time, sequence,
                      bytes(buf[start + _MESSAGE.size:start + length]))


def _chunk(buf, body: int, length: int) -> Iterator[tuple[int, object]]:
    """Schemas, channels and raw message records of a chunk, after size and CRC checks."""
    _, _, usize, crc = _CHUNK.unpack_from(buf, body)
    p = body + _CHUNK.size
    (clen,) = struct.unpack_from("<I", buf, p)
    compression = bytes(buf[p + 4:p + 4 + clen]).decode()
    p += 4 + clen
    (dlen,) = struct.unpack_from("<Q", buf, p)
    data = buf[p + 8:p + 8 + dlen]
    if p + 8 + dlen > body + length or len(data) != dlen:
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
            yield OP_MESSAGE, raw[start:start + rlen]
        elif op == OP_SCHEMA:
            yield OP_SCHEMA, Schema.read(ReadDataStream(io.BytesIO(raw[start:start + rlen])))
        elif op == OP_CHANNEL:
            yield OP_CHANNEL, Channel.read(ReadDataStream(io.BytesIO(raw[start:start + rlen])))
        pos = start + rlen


def read_log(path: Path | str, topics: set[str] | None = None,
             strict: bool = True) -> Iterator[LogMessage]:
    """Messages of a log file or of a directory of split files, file after file."""
    for f in log_files(path):
        yield from read_messages(f, topics, strict)


def inspect(path: Path | str) -> LogInfo:
    """Read a whole file tolerantly: topics, counts, time span, complete or where damaged."""
    info = LogInfo(Path(path))
    for _ in read_messages(path, strict=False, info=info):
        pass
    return info


def recover(src: Path | str, dst: Path | str,
            compression: CompressionType = CompressionType.ZSTD) -> LogInfo:
    """Rewrite every whole message of a cut-off (or damaged) file into a finished file."""
    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise LogError(dst, "recovery output must differ from its input")
    info = LogInfo(src)
    try:
        with open(dst, "wb") as out:
            writer = Writer(out, compression=compression)
            writer.start(profile="ros2", library="leadscrew_ros recover")
            ids: dict[str, int] = {}
            for m in read_messages(src, strict=False, info=info):
                if m.topic.name not in ids:
                    ids[m.topic.name] = _register(writer, m.topic)
                writer.add_message(ids[m.topic.name], m.log_time_ns, m.data, m.publish_time_ns,
                                   m.sequence)
            for t in info.topics.values():             # channels that had no message yet
                if t.name not in ids:
                    _register(writer, t)
            writer.finish()
    except OSError as exc:
        raise LogError(dst, exc.strerror or exc) from None
    if not info.messages:
        dst.unlink(missing_ok=True)
        raise LogError(src, info.damage or "no messages to recover")
    return info


def _register(writer: Writer, t: Topic) -> int:
    schema = writer.register_schema(t.stored_schema_name, t.schema_encoding, t.schema.encode())
    return writer.register_channel(t.name, t.message_encoding, schema, t.metadata)
