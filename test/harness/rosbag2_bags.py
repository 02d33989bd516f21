# SPDX-License-Identifier: Apache-2.0
"""rosbag2 bags as rosbag2 wrote them over its releases, written here from scratch.

The structures of rosbag2's own test resources (`rosbag2_tests/resources`, `rosbag2_py/test/
resources`, `rosbag2_transport/test/resources`), without their files:

- sqlite3 (.db3) schema generations: Dashing (topics without QoS, no `schema` table), Foxy
  (`offered_qos_profiles`), Humble (`schema` version 3 and the `metadata` table), Iron and later
  (`schema` version 4, `type_description_hash` column, `message_definitions` table);
- MCAP files with zstd- or lz4-compressed chunks, as rosbag2's mcap plugin writes them;
- split files `<bag>_<k>.<ext>`, `metadata.yaml` of versions 4 to 8 with the keys each version
  added (4: QoS profiles, relative file paths; 5: per-file `files`; 6: `custom_data`;
  7: `type_description_hash`; 8: `ros_distro`), or no metadata.yaml at all;
- legacy type names (`std_msgs/Float64`, as in `test_bag_for_seek`), a service-event topic
  (`example_interfaces/srv/AddTwoInts_Event`, as in `bag_with_topics_and_service_events`) and a
  topic stored without its leading slash (`nut_position`, as `a_empty` in `convert_a`);
- a .db3 recorded in WAL mode (the `resilient` preset) whose newest messages are still in its
  `-wal` file.
"""

from __future__ import annotations

import shutil
import sqlite3
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.writer import CompressionType, Writer
from std_msgs.msg import Float64

from leadscrew_ros.bag import msgdefs

from .cdr_reference import cdr_payload

T0 = 1_700_000_000_000_000_000  # first message [ns]
STEP_NS = 50_000_000  # 20 Hz
QOS = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 0\n"
    "    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 1\n"
    "  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n"
    "  avoid_ros_namespace_conventions: false"
)
SERVICE_EVENT = ("/add_two_ints/_service_event", "example_interfaces/srv/AddTwoInts_Event")
GENERATIONS = ("dashing", "foxy", "humble", "jazzy")  # sqlite3 schema generations
# the service event's payload: a CDR header and bytes no reader here decodes
_EVENT_PAYLOAD = b"\x00\x01\x00\x00" + bytes(range(60))


@dataclass(frozen=True)
class Message:
    """One message as stored: topic name and type spelled as the bag spells them."""

    topic: str
    type_name: str
    data: bytes
    log_time_ns: int


@dataclass
class Bag:
    """A written bag: its directory, files and what they hold."""

    path: Path
    files: list[Path] = field(default_factory=list)
    counts: Counter = field(default_factory=Counter)  # per topic as stored

    @property
    def messages(self) -> int:
        """Messages written."""
        return sum(self.counts.values())


def drive_messages(n: int = 60, legacy_types: bool = False) -> list[Message]:
    """`n` steps of a drive through the squeak band: speed, load, a nut position stored without
    its leading slash, and every fifth step a service event."""
    f64 = "std_msgs/Float64" if legacy_types else "std_msgs/msg/Float64"
    out = []
    for k in range(n):
        t = T0 + k * STEP_NS
        out += [
            Message("/motor_speed", f64, cdr_payload(Float64(data=5.0 + 0.5 * k)), t),
            Message("/axial_load", f64, cdr_payload(Float64(data=200.0 + k)), t + 1000),
            Message("nut_position", f64, cdr_payload(Float64(data=0.05 + 1e-4 * k)), t + 2000),
        ]
        if k % 5 == 0:
            out.append(Message(*SERVICE_EVENT, _EVENT_PAYLOAD, t + 3000))
    return out


def _definition(type_name: str) -> str:
    parts = type_name.split("/")
    try:
        return msgdefs.definition(f"{parts[0]}/msg/{parts[-1]}" if len(parts) == 2 else type_name)
    except msgdefs.MessageDefinitionError:  # e.g. a service event of a package not installed
        return ""


def write_db3(path: Path, messages: list[Message], generation: str = "jazzy") -> Path:
    """A .db3 file with the tables of a rosbag2 `generation` (`GENERATIONS`)."""
    con = sqlite3.connect(path)
    try:
        _db3_tables(con, generation)
        _db3_rows(con, messages, generation)
        con.commit()
    finally:
        con.close()
    return path


def _db3_tables(con: sqlite3.Connection, generation: str) -> None:
    level = GENERATIONS.index(generation)
    columns = ["id INTEGER PRIMARY KEY", "name TEXT NOT NULL", "type TEXT NOT NULL"]
    columns.append("serialization_format TEXT NOT NULL")
    if level >= 1:
        columns.append("offered_qos_profiles TEXT NOT NULL")
    if level >= 3:
        columns.append("type_description_hash TEXT NOT NULL")
    con.execute(f"CREATE TABLE topics({', '.join(columns)})")
    con.execute(
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, "
        "timestamp INTEGER NOT NULL, data BLOB NOT NULL)"
    )
    con.execute("CREATE INDEX timestamp_idx ON messages (timestamp ASC)")
    if level >= 2:
        con.execute("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT)")
        con.execute("INSERT INTO schema VALUES (?, ?)", (level + 1, generation))
        con.execute(
            "CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, "
            "metadata TEXT NOT NULL)"
        )
    if level >= 3:
        con.execute(
            "CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, "
            "encoding TEXT NOT NULL, encoded_message_definition TEXT NOT NULL, "
            "type_description_hash TEXT NOT NULL)"
        )


def _db3_rows(
    con: sqlite3.Connection,
    messages: list[Message],
    generation: str,
    ids: dict[tuple[str, str], int] | None = None,
) -> None:
    """Insert `messages` (and their topics not in `ids`, topic -> row id, yet)."""
    level = GENERATIONS.index(generation)
    ids = {} if ids is None else ids
    for m in messages:
        key = (m.topic, m.type_name)
        if key not in ids:
            ids[key] = len(ids) + 1
            row = (
                [ids[key], m.topic, m.type_name, "cdr"] + [QOS] * (level >= 1) + [""] * (level >= 3)
            )
            con.execute(f"INSERT INTO topics VALUES ({', '.join('?' * len(row))})", row)
            if level >= 3:
                con.execute(
                    "INSERT INTO message_definitions(topic_type, encoding, "
                    "encoded_message_definition, type_description_hash) VALUES (?, ?, ?, '')",
                    (m.type_name, "ros2msg", _definition(m.type_name)),
                )
        con.execute(
            "INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)",
            (ids[key], m.log_time_ns, m.data),
        )


def write_wal_db3(path: Path, messages: list[Message], checkpointed: int) -> Path:
    """A .db3 recorded in WAL mode and copied while its recorder still held it open: the first
    `checkpointed` messages in the database file, the others only in `<name>.db3-wal` (with
    its `-shm` index), as a crash or a copy during recording leaves them."""
    work = path.parent / (path.name + ".recording")
    work.mkdir()
    live = work / path.name
    con = sqlite3.connect(live)
    try:
        con.execute("PRAGMA journal_mode=WAL")
        con.execute("PRAGMA wal_autocheckpoint=0")  # only the explicit checkpoint below
        _db3_tables(con, "jazzy")
        ids: dict[tuple[str, str], int] = {}
        _db3_rows(con, messages[:checkpointed], "jazzy", ids)
        con.commit()
        con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        _db3_rows(con, messages[checkpointed:], "jazzy", ids)
        con.commit()
        for suffix in ("", "-wal", "-shm"):
            shutil.copyfile(live.with_name(live.name + suffix), path.with_name(path.name + suffix))
    finally:
        con.close()
    shutil.rmtree(work)
    return path


def write_mcap(
    path: Path, messages: list[Message], compression: CompressionType = CompressionType.ZSTD
) -> Path:
    """An MCAP file as rosbag2's mcap plugin writes it: ros2 profile, compressed chunks, schema
    names and topic names as stored."""
    with open(path, "wb") as fh:
        w = Writer(fh, compression=compression, chunk_size=4096)
        w.start(profile="ros2", library="rosbag2 (test harness)")
        channels: dict[tuple[str, str], int] = {}
        for m in messages:
            key = (m.topic, m.type_name)
            if key not in channels:
                schema = w.register_schema(
                    m.type_name, "ros2msg", _definition(m.type_name).encode()
                )
                channels[key] = w.register_channel(
                    m.topic, "cdr", schema, {"offered_qos_profiles": QOS}
                )
            w.add_message(channels[key], m.log_time_ns, m.data, m.log_time_ns)
        w.finish()
    return path


def write_bag(
    path: Path,
    storage: str = "sqlite3",
    version: int | None = 8,
    splits: int = 1,
    generation: str = "jazzy",
    legacy_types: bool = False,
    compression: CompressionType = CompressionType.ZSTD,
    steps: int = 60,
) -> Bag:
    """A rosbag2 bag directory: `splits` files `<name>_<k>.db3|.mcap` and a metadata.yaml of
    `version` (None: none)."""
    path.mkdir(parents=True)
    messages = drive_messages(steps, legacy_types)
    bag = Bag(path)
    per_file = -(-len(messages) // splits)
    parts = []
    for k in range(splits):
        part = messages[k * per_file : (k + 1) * per_file]
        f = path / f"{path.name}_{k}.{'db3' if storage == 'sqlite3' else 'mcap'}"
        if storage == "sqlite3":
            write_db3(f, part, generation)
        else:
            write_mcap(f, part, compression)
        bag.files.append(f)
        bag.counts.update(m.topic for m in part)
        parts.append(part)
    if version is not None:
        (path / "metadata.yaml").write_text(
            yaml.safe_dump(metadata(version, storage, bag.files, parts), sort_keys=False)
        )
    return bag


def metadata(version: int, storage: str, files: list[Path], parts: list[list[Message]]) -> dict:
    """The metadata.yaml document rosbag2 of metadata `version` (4..8) writes for these files."""
    everything = [m for part in parts for m in part]
    start = min(m.log_time_ns for m in everything)
    end = max(m.log_time_ns for m in everything)
    counts = Counter((m.topic, m.type_name) for m in everything)
    topics = []
    for (name, type_name), n in counts.items():
        meta = {"name": name, "type": type_name, "serialization_format": "cdr"}
        meta["offered_qos_profiles"] = QOS
        if version >= 7:
            meta["type_description_hash"] = ""
        topics.append({"topic_metadata": meta, "message_count": n})
    info: dict = {
        "version": version,
        "storage_identifier": storage,
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": len(everything),
        "topics_with_message_count": topics,
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f.name for f in files],
    }
    if version >= 5:
        info["files"] = [
            {
                "path": f.name,
                "starting_time": {"nanoseconds_since_epoch": min(m.log_time_ns for m in part)},
                "duration": {
                    "nanoseconds": max(m.log_time_ns for m in part)
                    - min(m.log_time_ns for m in part)
                },
                "message_count": len(part),
            }
            for f, part in zip(files, parts, strict=True)
        ]
    if version >= 6:
        info["custom_data"] = {}
    if version >= 8:
        info["ros_distro"] = "rolling"
    return {"rosbag2_bagfile_information": info}
