# SPDX-License-Identifier: Apache-2.0
"""Any robot's rosbag2 log: `info`, `replay`, `recover` and `review` on bags as rosbag2 wrote
them over its releases (`harness.rosbag2_bags`: sqlite3 schema generations, metadata.yaml
versions 4 to 8 and none, split files, zstd/lz4 MCAP chunks, legacy type names, service events,
a topic stored without its leading slash) and as rosbags writes them (version 9). Every count
is the one rosbags reads; no input file changes; no traceback."""

from __future__ import annotations

import hashlib
import json
import shutil
import sqlite3
from collections import Counter
from pathlib import Path

import pytest
from mcap.writer import CompressionType
from rosbags.rosbag2 import Reader, StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter

from harness.logs import TYPESTORE, cli
from harness.rosbag2_bags import (
    SERVICE_EVENT,
    Bag,
    drive_messages,
    write_bag,
    write_wal_db3,
)
from leadscrew_ros.bag.logsource import open_log
from leadscrew_ros.review.fleet import content_hash, stat_key

# (storage, metadata version or None, split files, sqlite3 generation, legacy type names,
# MCAP chunk compression)
CASES = [
    ("sqlite3", 4, 1, "foxy", False, None),
    ("sqlite3", 5, 3, "humble", True, None),
    ("sqlite3", 6, 2, "jazzy", False, None),
    ("sqlite3", 7, 1, "jazzy", False, None),
    ("sqlite3", 8, 2, "jazzy", False, None),
    ("sqlite3", None, 2, "dashing", True, None),
    ("mcap", 4, 1, "", False, CompressionType.ZSTD),
    ("mcap", 5, 2, "", True, CompressionType.ZSTD),
    ("mcap", 6, 1, "", False, CompressionType.LZ4),
    ("mcap", 7, 3, "", False, CompressionType.ZSTD),
    ("mcap", 8, 2, "", False, CompressionType.ZSTD),
    ("mcap", None, 2, "", False, CompressionType.ZSTD),
]


def case_id(case) -> str:
    storage, version, splits, generation, legacy, _ = case
    return (
        f"{storage}-v{version or 'none'}-{splits}files"
        + (f"-{generation}" if generation else "")
        + ("-legacy" if legacy else "")
    )


def rosbags_9(path: Path, storage: StoragePlugin) -> Bag:
    """A bag written by rosbags (metadata version 9), with the drive's topics."""
    bag = Bag(path)
    with RosbagsWriter(path, version=9, storage_plugin=storage) as w:
        conns = {}
        for m in drive_messages():
            if m.topic == SERVICE_EVENT[0]:
                continue  # rosbags' writer needs the type in its typestore
            if m.topic not in conns:
                conns[m.topic] = w.add_connection(m.topic, m.type_name, typestore=TYPESTORE)
            w.write(conns[m.topic], m.log_time_ns, m.data)
            bag.counts[m.topic] += 1
    bag.files = sorted(p for p in path.iterdir() if p.name != "metadata.yaml")
    return bag


def checksums(directory: Path) -> dict[str, str]:
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(directory.iterdir())
        if p.is_file()
    }


def full(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def rosbags_counts(bag: Bag) -> Counter:
    """Messages per topic as rosbags reads the bag's files (each file on its own: a bag
    without metadata.yaml too), names fully qualified."""
    counts: Counter = Counter()
    for f in bag.files:
        with Reader(f) as r:
            counts.update(full(c.topic) for c, _, _ in r.messages())
    return counts


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Bag]:
    root = tmp_path_factory.mktemp("rosbag2")
    out = {}
    for case in CASES:
        storage, version, splits, generation, legacy, compression = case
        out[case_id(case)] = write_bag(
            root / case_id(case).replace("-", "_"),
            storage,
            version,
            splits,
            generation or "jazzy",
            legacy,
            compression or CompressionType.ZSTD,
        )
    out["rosbags-mcap-v9"] = rosbags_9(root / "rosbags_mcap", StoragePlugin.MCAP)
    out["rosbags-sqlite3-v9"] = rosbags_9(root / "rosbags_sqlite3", StoragePlugin.SQLITE3)
    return out


@pytest.mark.parametrize(
    "name", [case_id(c) for c in CASES] + ["rosbags-mcap-v9", "rosbags-sqlite3-v9"]
)
def test_info_replay_recover_count_what_rosbags_reads_and_change_nothing(
    name, bags, tmp_path, capsys
):
    bag = bags[name]
    work = tmp_path / bag.path.name  # a copy: recover may add a missing metadata.yaml
    shutil.copytree(bag.path, work)
    bag = Bag(work, [work / f.name for f in bag.files], bag.counts)
    before = checksums(work)
    expected = rosbags_counts(bag)
    assert sum(expected.values()) == bag.messages  # rosbags reads every message written
    assert expected == Counter({full(t): n for t, n in bag.counts.items()})

    code, out, err = cli(capsys, "info", "--json", work)
    assert code == 0 and "Traceback" not in err, err
    files = json.loads(out)
    assert [f["file"] for f in files] == [str(f) for f in bag.files]
    counts: Counter = Counter()
    for f in files:
        counts.update({t["name"]: t["count"] for t in f["topics"]})
        assert f["metadata_problem"] == ""
    assert counts == expected
    types = {t["name"]: t["type"] for f in files for t in f["topics"]}
    assert types["/motor_speed"] == "std_msgs/msg/Float64"  # legacy std_msgs/Float64 too
    if SERVICE_EVENT[0] in types:
        assert types[SERVICE_EVENT[0]] == SERVICE_EVENT[1]
    code, text, err = cli(capsys, "info", work)
    assert code == 0 and "Traceback" not in err and str(bag.files[0]) in text

    code, out, err = cli(
        capsys, "replay", work, "--out", tmp_path / "replay", "--no-report", "--quiet",
        "--workers", "0",
    )  # fmt: skip
    assert code == 0 and "Traceback" not in err, err
    summary = json.loads((tmp_path / "replay" / "summary.json").read_text())
    assert summary["messages"] == sum(expected.values())
    assert summary["input_messages"] == {
        t: expected[t] for t in ("/motor_speed", "/axial_load", "/nut_position") if expected[t]
    }
    assert summary["metadata_problem"] == ""

    code, out, err = cli(capsys, "recover", work)
    assert code == 0 and "Traceback" not in err, err
    if work.joinpath(bag.files[0]).suffix == ".db3":
        assert out == (
            f"nothing to recover: {work} is a rosbag2 sqlite3 (.db3) log, which SQLite keeps "
            f"consistent ({sum(expected.values())} messages readable)\n"
        )
    elif "metadata.yaml" in before:
        assert out.splitlines()[-1].startswith("nothing to recover")
    else:  # recover writes the missing metadata.yaml, with which rosbags opens the bag
        with Reader(work) as r:
            assert Counter(full(c.topic) for c, _, _ in r.messages()) == expected
    after = checksums(work)
    assert {k: after[k] for k in before} == before


def test_review_reads_every_kind_of_bag(bags, tmp_path, capsys):
    code, out, err = cli(
        capsys, "review", *(b.path for b in bags.values()), "--out", tmp_path / "fleet",
        "--workers", "1", "--summary-only", "--quiet",
    )  # fmt: skip
    assert code == 0 and "Traceback" not in err, err
    rows = json.loads((tmp_path / "fleet" / "fleet.json").read_text())["rows"]
    assert sorted((r["status"], r["messages"]) for r in rows) == sorted(
        ("ok", sum(rosbags_counts(b).values())) for b in bags.values()
    )


def test_a_wal_mode_db3_is_read_with_its_wal_and_left_unchanged(tmp_path, capsys):
    """rosbag2's resilient preset records in WAL mode: until a checkpoint, the newest messages
    are only in <name>.db3-wal, which an immutable open of the .db3 ignores."""
    messages = drive_messages(40)
    db3 = write_wal_db3(tmp_path / "wal.db3", messages, checkpointed=50)
    wal = tmp_path / "wal.db3-wal"
    assert wal.stat().st_size > 0
    immutable = sqlite3.connect(f"{db3.as_uri()}?mode=ro&immutable=1", uri=True)
    try:  # the condition of the test: the database file alone holds the checkpointed ones
        assert immutable.execute("SELECT count(*) FROM messages").fetchone() == (50,)
    finally:
        immutable.close()
    before = checksums(tmp_path)
    source = open_log(db3)
    assert sum(1 for _ in source.messages()) == len(messages)
    assert source.counts == Counter(full(m.topic) for m in messages)
    code, out, err = cli(capsys, "info", "--json", db3)
    assert code == 0, err
    assert json.loads(out)[0]["messages"] == len(messages)
    assert checksums(tmp_path) == before


def test_review_sees_a_change_of_the_wal_alone(tmp_path):
    """Two recordings of one WAL-mode .db3, the same database file, more messages in the
    second's -wal: review's resume keys differ (a new message is never skipped as unchanged)."""
    messages = drive_messages(40)
    first = write_wal_db3(_mkdir(tmp_path / "a") / "wal.db3", messages[:-10], checkpointed=50)
    later = write_wal_db3(_mkdir(tmp_path / "b") / "wal.db3", messages, checkpointed=50)
    assert first.read_bytes() == later.read_bytes()  # the condition of the test
    assert content_hash(first) != content_hash(later)
    assert stat_key(first)[1][:2] != stat_key(later)[1][:2]  # the -wal's name and size


def _mkdir(path: Path) -> Path:
    path.mkdir()
    return path


def test_a_topic_without_leading_slash_is_found_either_way(tmp_path, capsys):
    """`nut_position` as stored is /nut_position: an input by its default name, and chosen
    by --nut-topic with or without the slash."""
    bag = write_bag(tmp_path / "bag", "sqlite3", 8, 1)
    for given in ("nut_position", "/nut_position"):
        out_dir = tmp_path / f"replay{len(given)}"
        code, _, err = cli(
            capsys, "replay", bag.path, "--out", out_dir, "--no-report", "--quiet",
            "--workers", "0", "--nut-topic", given,
        )  # fmt: skip
        assert code == 0, err
        summary = json.loads((out_dir / "summary.json").read_text())
        assert summary["input_messages"]["/nut_position"] == bag.counts["nut_position"]


def test_recover_of_a_db3_says_so_in_one_line(tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", "sqlite3", None, 1)
    before = checksums(bag.path)
    code, out, err = cli(capsys, "recover", bag.files[0])
    assert code == 0 and out.startswith("nothing to recover: ") and out.count("\n") == 1
    code, out, err = cli(capsys, "recover", bag.files[0], "-o", tmp_path / "out.mcap")
    assert code == 2 and err.startswith("leadscrew-squeak: error: ") and err.count("\n") == 1
    assert checksums(bag.path) == before and not (tmp_path / "out.mcap").exists()
