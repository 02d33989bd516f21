# SPDX-License-Identifier: Apache-2.0
"""`bag.logsource`: the log an offline replay reads, MCAP or rosbag2 sqlite3 (.db3), as one
stream. Split files come in split order (numeric: _10 after _2), each file in file order (not
sorted by time); topics without messages are still declared; a .db3 file is read in insertion
order with the stored, installed or no message definition; broken or foreign files are one
LogError naming the file. rosbags' sqlite3 writer is the independent producer."""

import sqlite3
from pathlib import Path

import pytest
from mcap.writer import Writer
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter

from harness.logs import TYPESTORE, f64, write_mcap
from leadscrew_ros.bag import msgdefs
from leadscrew_ros.bag.logfile import LogError
from leadscrew_ros.bag.logsource import log_topics, open_log

FLOAT64 = "std_msgs/msg/Float64"
T0 = 1_700_000_000_000_000_000


def split_bag(directory: Path, indices=(0, 1, 2, 10)) -> dict[int, list]:
    """A bag directory of split files `bag_<i>.mcap`; each file's log times run backwards (so
    file order and time order differ); returns index -> (topic, value, t) written."""
    directory.mkdir()
    written = {}
    for i in indices:
        msgs = [("/motor_speed", 10.0 * i + k, T0 + (i * 10 + 5 - k) * 1000) for k in range(3)]
        write_mcap(directory / f"bag_{i}.mcap", [f64(*m) for m in msgs])
        written[i] = msgs
    return written


def with_silent_topic(path: Path, summary: bool = True) -> Path:
    """/motor_speed with two messages and /nut_position declared without any; `summary` False
    writes no summary section (readers must read the file through)."""
    kw = (
        {}
        if summary
        else dict(
            use_chunking=False,
            use_statistics=False,
            use_summary_offsets=False,
            repeat_channels=False,
            repeat_schemas=False,
        )
    )
    with open(path, "wb") as f:
        w = Writer(f, **kw)
        w.start(profile="ros2")
        schema = w.register_schema(FLOAT64, "ros2msg", msgdefs.definition(FLOAT64).encode())
        speed = w.register_channel("/motor_speed", "cdr", schema)
        w.register_channel("/nut_position", "cdr", schema)
        for k in range(2):
            w.add_message(speed, T0 + k, f64("/motor_speed", float(k), 0)[2], T0 + k)
        w.finish()
    return path


def db3(path: Path, topics, rows, definitions=None) -> Path:
    """A rosbag2 sqlite3 file written directly: topics (id, name, type, format), messages
    (topic_id, timestamp, data) in insertion order; `definitions` (type -> text) adds the
    message_definitions table of Iron and later."""
    con = sqlite3.connect(path)
    con.executescript("""
        CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
            serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
        CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
            timestamp INTEGER NOT NULL, data BLOB NOT NULL);""")
    con.executemany("INSERT INTO topics VALUES (?, ?, ?, ?, '')", topics)
    con.executemany("INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)", rows)
    if definitions is not None:
        con.execute(
            "CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT, "
            "encoding TEXT, encoded_message_definition TEXT, type_description_hash "
            "TEXT)"
        )
        con.executemany(
            "INSERT INTO message_definitions(topic_type, encoding, "
            "encoded_message_definition, type_description_hash) VALUES "
            "(?, 'ros2msg', ?, '')",
            definitions.items(),
        )
    con.commit()
    con.close()
    return path


def payload(value: float) -> bytes:
    return f64("/x", value, 0)[2]


# ----------------------------------------------------------------------------- MCAP
def test_split_files_stream_in_split_order_each_in_file_order(tmp_path):
    written = split_bag(tmp_path / "bag")
    source = open_log(tmp_path / "bag")
    assert not source.sqlite
    assert [f.name for f in source.files] == [
        "bag_0.mcap",
        "bag_1.mcap",
        "bag_2.mcap",
        "bag_10.mcap",
    ]
    got = [(f.name, m.topic.name, m.log_time_ns, m.data) for f, m in source.messages()]
    want = [
        (f"bag_{i}.mcap", t, time, payload(v)) for i in (0, 1, 2, 10) for t, v, time in written[i]
    ]
    assert got == want  # not sorted by log time (that runs backwards)
    assert list(source.topics) == ["/motor_speed"] and source.counts == {"/motor_speed": 12}


@pytest.mark.parametrize("summary", [True, False])
def test_topics_without_messages_are_declared(tmp_path, summary):
    log = with_silent_topic(tmp_path / "log.mcap", summary)
    source = open_log(log)
    # before reading: from the summary, or by reading the file through without one
    declared = log_topics(source)
    assert set(declared) == {"/motor_speed", "/nut_position"}
    assert declared["/nut_position"].type_name == FLOAT64
    assert declared["/nut_position"].message_encoding == "cdr"
    assert [m.data for _, m in source.messages()] == [payload(0.0), payload(1.0)]
    assert set(source.topics) == {"/motor_speed", "/nut_position"}
    assert source.counts == {"/motor_speed": 2, "/nut_position": 0}


def test_topics_of_a_cut_off_file_are_those_before_the_cut(tmp_path):
    """No summary to read (the tail is gone): the topics the readable part declares."""
    log = write_mcap(
        tmp_path / "cut.mcap",
        [f64("/motor_speed", 1.0, T0), f64("/axial_load", 2.0, T0 + 1)],
        chunked=False,
    )
    data = log.read_bytes()
    log.write_bytes(data[: int(len(data) * 0.8)])
    assert set(log_topics(open_log(log))) == {"/motor_speed", "/axial_load"}
    with pytest.raises(LogError, match="cut.mcap"):  # the strict read says why
        list(open_log(log).messages())


def test_mcap_is_preferred_when_a_directory_holds_both(tmp_path):
    bag = tmp_path / "bag"
    split_bag(bag, (0,))
    db3(bag / "bag_0.db3", [(1, "/motor_speed", FLOAT64, "cdr")], [])
    source = open_log(bag)
    assert not source.sqlite and source.files == [bag / "bag_0.mcap"]


@pytest.mark.parametrize(
    "make, problem",
    [
        (lambda d: d / "nothing.mcap", "no such file or directory"),
        (lambda d: d, "directory holds no .mcap or .db3 files"),
    ],
)
def test_no_log_is_one_error_naming_the_path(tmp_path, make, problem):
    with pytest.raises(LogError, match=problem) as e:
        open_log(make(tmp_path))
    assert str(e.value).startswith(str(make(tmp_path)))


# ----------------------------------------------------------------------------- sqlite3
def test_db3_messages_in_insertion_order_with_sequence_per_topic(tmp_path):
    rows = [
        (1, T0 + 30, payload(1.0)),
        (2, T0 + 10, payload(2.0)),
        (1, T0 + 20, payload(3.0)),
        (1, T0 + 5, payload(4.0)),
    ]
    log = db3(
        tmp_path / "a.db3",
        [
            (1, "/motor_speed", FLOAT64, "cdr"),
            (2, "/axial_load", FLOAT64, "cdr"),
            (3, "/nut_position", FLOAT64, "cdr"),
        ],
        rows,
    )
    source = open_log(log)
    assert source.sqlite and source.files == [log]
    got = [
        (m.topic.name, m.log_time_ns, m.publish_time_ns, m.sequence, m.data)
        for _, m in source.messages()
    ]
    assert got == [
        ("/motor_speed", T0 + 30, T0 + 30, 0, payload(1.0)),
        ("/axial_load", T0 + 10, T0 + 10, 0, payload(2.0)),
        ("/motor_speed", T0 + 20, T0 + 20, 1, payload(3.0)),
        ("/motor_speed", T0 + 5, T0 + 5, 2, payload(4.0)),
    ]
    assert source.counts == {"/motor_speed": 3, "/axial_load": 1, "/nut_position": 0}
    assert set(log_topics(source)) == {"/motor_speed", "/axial_load", "/nut_position"}


def test_db3_splits_are_in_split_order(tmp_path):
    bag = tmp_path / "bag"
    bag.mkdir()
    for i in (10, 2, 0, 1):
        db3(
            bag / f"bag_{i}.db3",
            [(1, "/motor_speed", FLOAT64, "cdr")],
            [(1, T0 + i, payload(float(i)))],
        )
    source = open_log(bag)
    assert source.sqlite and [f.name for f in source.files] == [
        "bag_0.db3",
        "bag_1.db3",
        "bag_2.db3",
        "bag_10.db3",
    ]
    assert [m.log_time_ns - T0 for _, m in source.messages()] == [0, 1, 2, 10]


def test_db3_message_definitions_stored_installed_or_none(tmp_path):
    stored = "float64 data  # as the file has it\n"
    topics = [(1, "/a", FLOAT64, "cdr"), (2, "/b", "no_such_pkg/msg/Thing", "cdr")]
    with_table = open_log(db3(tmp_path / "iron.db3", topics, [], {FLOAT64: stored}))
    assert {t.name: t.schema for t in log_topics(with_table).values()} == {"/a": stored, "/b": ""}
    humble = open_log(db3(tmp_path / "humble.db3", topics, []))
    found = log_topics(humble)
    assert found["/a"].schema == msgdefs.definition(FLOAT64)  # the installed one
    assert found["/b"].schema == "" and found["/b"].schema_encoding == "ros2msg"
    assert found["/a"].metadata == {"offered_qos_profiles": ""}


@pytest.mark.parametrize(
    "make, problem",
    [
        (
            lambda p: db3(p, [(1, "/a", FLOAT64, "json")], []),
            "foreign rosbag2 storage: topic /a is serialized as 'json', expected cdr",
        ),
        (
            lambda p: db3(p, [(1, "/a", FLOAT64, "cdr")], [(7, T0, b"x")]),
            "message on unknown topic id 7",
        ),
        (lambda p: p.write_text("not sqlite at all " * 100), "not a rosbag2 sqlite3 (.db3) file"),
    ],
)
def test_broken_or_foreign_db3_is_one_error_naming_the_file(tmp_path, make, problem):
    path = tmp_path / "bad.db3"
    make(path)
    with pytest.raises(LogError) as e:
        list(open_log(path).messages())
    assert str(e.value).startswith(f"{path}: {problem}")


def test_a_db3_written_by_rosbags_reads_as_rosbags_reads_it(tmp_path):
    bag = tmp_path / "rosbags_bag"
    with RosbagsWriter(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        speed = w.add_connection("/motor_speed", FLOAT64, typestore=TYPESTORE)
        load = w.add_connection("/axial_load", FLOAT64, typestore=TYPESTORE)
        for k in range(20):
            msg = TYPESTORE.types[FLOAT64](float(k))
            w.write(
                speed if k % 3 else load,
                T0 + 1000 * (20 - k),
                TYPESTORE.serialize_cdr(msg, FLOAT64),
            )
    with RosbagsReader(bag) as reader:
        theirs = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    source = open_log(bag)
    assert source.sqlite
    ours = [(m.topic.name, m.log_time_ns, m.data) for _, m in source.messages()]
    # rosbags yields by time; the file (and we) in insertion order
    assert sorted(ours, key=lambda m: m[1]) == theirs and ours[0][1] > ours[-1][1]
    assert {t.type_name for t in source.topics.values()} == {FLOAT64}
