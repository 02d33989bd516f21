# SPDX-License-Identifier: Apache-2.0
"""The log an offline replay reads: MCAP files (`logfile`) or rosbag2's sqlite3 storage (.db3,
the default before Iron), as one stream of `LogMessage` records in file order.

A .db3 file is read with Python's sqlite3 (read-only, immutable; no extra dependency): the
`topics` table gives names, types and QoS, `messages` is read in insertion order (the order
rosbag2 received them), and the message definitions come from the `message_definitions` table
(Iron and later) or else from the installed ROS 2 message files (copies into the annotated MCAP
need them), or stay empty for types that are not installed. A file recorded in WAL mode
(rosbag2's `resilient` preset) keeps its newest messages in `<name>.db3-wal` until a
checkpoint, which an immutable open ignores: such a file (or one with a rollback journal) is
copied with its `-wal`/`-shm`/`-journal` to a temporary directory and opened there, where
SQLite may replay them; the log itself is never written.
"""

from __future__ import annotations

import shutil
import sqlite3
import tempfile
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

from . import msgdefs
from .logfile import (
    ENCODINGS,
    LogError,
    LogInfo,
    LogMessage,
    Topic,
    _split_key,
    inspect,
    log_files,
    log_topic,
    read_messages,
    refuse_compressed,
)

DB3 = ".db3"
# SQLite's files beside a database whose content a reader must see: the write-ahead log (WAL
# mode; its index `-shm` is rebuilt from it) and the rollback journal of an interrupted write
_SIDECARS = ("-wal", "-journal")


@dataclass
class LogSource:
    """A log's files and, once read, every topic it declares with its message count.

    Attributes
    ----------
    path : Path
        The log (file or bag directory).
    files : list of Path
        Its files in split order.
    sqlite : bool
        rosbag2 sqlite3 (.db3) files, not MCAP.
    topics : dict of str to Topic
        Every topic the files declare, once `messages` has run.
    counts : Counter
        Messages per topic, once `messages` has run.
    infos : list of LogInfo
        What reading each file found, once `messages` has run (`logfile.metadata_problem`).
    """

    path: Path
    files: list[Path]
    sqlite: bool = False
    topics: dict[str, Topic] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    infos: list[LogInfo] = field(default_factory=list)

    def messages(self) -> Iterator[tuple[Path, LogMessage]]:
        """Every message of the log; collects `topics` (including those without messages) and
        `counts` on the way.

        Returns
        -------
        iterator of (Path, LogMessage)
            (file, message) of every file in split order, each file in file order.
        """
        for f in self.files:
            info = LogInfo(f)
            for m in _db3_messages(f, info) if self.sqlite else read_messages(f, info=info):
                yield f, m
            for name, topic in info.topics.items():
                self.topics.setdefault(name, topic)
            self.counts.update({name: info.counts[name] for name in info.topics})
            self.infos.append(info)

    def inspect(self) -> list[LogInfo]:
        """Every file read through (`logfile.inspect` for MCAP: a damaged or cut-off file
        is read up to its damage; a .db3 file is read whole or raises LogError).

        Returns
        -------
        list of LogInfo
            One per file, in split order.
        """
        if not self.sqlite:
            return [inspect(f) for f in self.files]
        infos = []
        for f in self.files:
            info = LogInfo(f)
            for _ in _db3_messages(f, info):
                pass
            infos.append(info)
        return infos


def file_messages(
    path: Path, topics: set[str] | None = None, info: LogInfo | None = None
) -> Iterator[LogMessage]:
    """The messages of one file of a log (`LogSource.files`) in file order, read strictly: a
    .db3 file, or an MCAP file (`logfile.read_messages`: LogError without footer).

    Parameters
    ----------
    path : Path
        The file.
    topics : set of str, optional
        Only these topics (fully qualified names).
    info : LogInfo, optional
        Receives what reading found (topics, counts, times).

    Returns
    -------
    iterator of LogMessage
        The file's messages.
    """
    info = info if info is not None else LogInfo(path)
    if path.suffix != DB3:
        yield from read_messages(path, topics, strict=True, info=info)
        return
    for m in _db3_messages(path, info):
        if topics is None or m.topic.name in topics:
            yield m


def open_log(path: Path | str) -> LogSource:
    """Open a log (its files are read by `LogSource.messages`).

    Parameters
    ----------
    path : path
        An .mcap or .db3 file, or a bag directory of split files (MCAP preferred when both are
        present), with or without metadata.yaml.

    Returns
    -------
    LogSource
        The log's files.

    Raises
    ------
    LogError
        There is no log at `path`.
    """
    path = Path(path)
    if path.is_dir():
        refuse_compressed(path)
    if path.is_dir() and not any(path.glob("*.mcap")):
        db3 = sorted(path.glob(f"*{DB3}"), key=lambda p: _split_key(p.with_suffix(".mcap")))
        if not db3:
            raise LogError(path, f"directory holds no .mcap or {DB3} files")
        return LogSource(path, db3, sqlite=True)
    if path.is_file() and path.suffix == DB3:
        return LogSource(path, [path], sqlite=True)
    return LogSource(path, log_files(path))


def log_topics(source: LogSource) -> dict[str, Topic]:
    """Every topic the log declares, before reading its messages: from the MCAP summaries or
    the sqlite3 `topics` tables (a file without summary is read through)."""
    topics: dict[str, Topic] = {}
    for t in _declared(source):
        topics.setdefault(t.name, t)
    return topics


def topic_types(source: LogSource) -> dict[str, list[str]]:
    """Every type each topic of the log is declared with (a topic recorded with two types,
    e.g. on two MCAP channels or two .db3 `topics` rows, has both), in the order declared."""
    types: dict[str, list[str]] = {}
    for t in _declared(source):
        if t.type_name not in types.setdefault(t.name, []):
            types[t.name].append(t.type_name)
    return types


def _declared(source: LogSource) -> list[Topic]:
    """Every topic of every file (once per channel or topics row) in file order."""
    out: list[Topic] = []
    for f in source.files:
        if source.sqlite:
            with _connect(f) as con:
                out += _db3_topics(f, con).values()
        else:
            out += _mcap_topics(f)
    return out


def _mcap_topics(path: Path) -> list[Topic]:
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as fh:
            summary = make_reader(fh).get_summary()
    except Exception:  # damaged or foreign: the strict read says why later
        summary = None
    if summary is None:
        info = LogInfo(path)
        for _ in read_messages(path, strict=False, info=info):
            pass
        return [*info.topics.values(), *info.retyped.values()]
    out = []
    for _, c in sorted(summary.channels.items()):
        s = summary.schemas.get(c.schema_id)
        if s is not None:
            out.append(
                log_topic(c.topic, s.name, s.encoding, "", c.message_encoding, dict(c.metadata))
            )
    return out


# ----------------------------------------------------------------------------- sqlite3
def sidecars(path: Path) -> list[Path]:
    """The non-empty WAL and journal files beside the .db3 file `path` (whose content is part
    of the database), in `_SIDECARS` order."""
    out = []
    for suffix in _SIDECARS:
        f = path.with_name(path.name + suffix)
        if f.is_file() and f.stat().st_size:
            out.append(f)
    return out


@contextmanager
def _connect(path: Path) -> Iterator[sqlite3.Connection]:
    """A connection to the .db3 file `path`, read-only and immutable, or to a copy of it when
    it has `sidecars` (SQLite writes when it replays them, never into the log); closed, and
    the copy removed, on exit."""
    if not path.is_file():
        raise LogError(path, "no such file")
    with tempfile.TemporaryDirectory(prefix="leadscrew_db3_") as tmp:
        uri = f"{path.resolve().as_uri()}?mode=ro&immutable=1"
        if sidecars(path):
            copy = Path(tmp) / path.name
            try:
                for f in (path, *sidecars(path)):  # SQLite rebuilds the WAL's index (-shm)
                    shutil.copyfile(f, copy.with_name(f.name))
            except OSError as exc:
                raise LogError(path, f"cannot copy it to read its WAL: {exc}") from None
            uri = copy.as_uri()
        try:
            con = sqlite3.connect(uri, uri=True)
        except sqlite3.Error as exc:
            raise LogError(path, f"not a rosbag2 sqlite3 (.db3) file: {exc}") from None
        try:
            try:
                con.execute("SELECT id, name, type, serialization_format FROM topics LIMIT 1")
                con.execute("SELECT topic_id, timestamp, data FROM messages LIMIT 1")
            except sqlite3.Error as exc:
                raise LogError(path, f"not a rosbag2 sqlite3 (.db3) file: {exc}") from None
            yield con
        finally:
            con.close()


def _db3_topics(path: Path, con: sqlite3.Connection) -> dict[int, Topic]:
    """Topic id -> Topic, with the stored or installed message definition."""
    stored: dict[str, tuple[str, str]] = {}
    try:
        stored = {
            t: (enc, text)
            for t, enc, text in con.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
            )
        }
    except sqlite3.Error:  # before Iron: no definitions in the file
        pass
    columns = {row[1] for row in con.execute("PRAGMA table_info(topics)")}
    qos_column = "offered_qos_profiles" if "offered_qos_profiles" in columns else "''"
    topics = {}
    for tid, name, stored_type, encoding, qos in con.execute(
        f"SELECT id, name, type, serialization_format, {qos_column} FROM topics"
    ):
        if encoding not in ENCODINGS:
            raise LogError(
                path,
                f"foreign rosbag2 storage: topic {name} is serialized as "
                f"{encoding!r}, expected cdr",
            )
        topic = log_topic(name, stored_type, "", "", encoding, {"offered_qos_profiles": qos or ""})
        schema_encoding, text = stored.get(stored_type, ("ros2msg", ""))
        if not text:
            try:
                text = msgdefs.definition(topic.type_name)
            except msgdefs.MessageDefinitionError:
                text = ""
        topics[tid] = replace(topic, schema_encoding=schema_encoding or "ros2msg", schema=text)
    return topics


def _db3_messages(path: Path, info: LogInfo) -> Iterator[LogMessage]:
    info.storage, info.complete = "sqlite3", True  # SQLite commits whole transactions
    with _connect(path) as con:
        # a name in two rows (two types): each its own topic, as two MCAP channels are
        topics = {tid: info.add_topic(t) for tid, t in _db3_topics(path, con).items()}
        sequence: Counter[int] = Counter()
        try:
            for tid, stamp, data in con.execute(
                "SELECT topic_id, timestamp, data FROM messages ORDER BY id"
            ):
                topic = topics.get(tid)
                if topic is None:
                    raise LogError(path, f"message on unknown topic id {tid}")
                info.count(topic)
                info.start_ns = stamp if info.start_ns is None else min(info.start_ns, stamp)
                info.end_ns = stamp if info.end_ns is None else max(info.end_ns, stamp)
                yield LogMessage(topic, stamp, stamp, sequence[tid], bytes(data))
                sequence[tid] += 1
        except sqlite3.Error as exc:
            raise LogError(path, f"damaged sqlite3 file: {exc}") from None
