# SPDX-License-Identifier: Apache-2.0
"""A topic recorded with two types (issue 19): `/motor_speed` as std_msgs/Float64 and as
std_msgs/Float32, on two MCAP channels or in two .db3 `topics` rows, both written by rosbags.
The replay takes the Float64 messages and counts the Float32 ones as rejected with a reason
naming both types, with the same summary counts and predictions from both storages, whichever
type comes first; `info` lists both types and `recover` keeps a channel per type."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter

from harness.logs import TYPESTORE, cli, decoded, run_replay
from leadscrew_ros.bag.logfile import inspect, recover

F64, F32 = "std_msgs/msg/Float64", "std_msgs/msg/Float32"
T0 = 1_700_000_000_000_000_000
SAMPLES = 60
STORAGES = {"mcap": StoragePlugin.MCAP, "db3": StoragePlugin.SQLITE3}
REASON = (
    f"/motor_speed: {F32} messages not taken (the topic is recorded with two types; its "
    f"{F64} messages are the input)"
)


def _payload(type_name: str, value: float) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(TYPESTORE.types[type_name](value), type_name))


def two_type_bag(path: Path, storage: str, float32_first: bool) -> Path:
    """Load, then a speed ramp on /motor_speed in Float64 with a Float32 message (of another
    value) 1 ns after each."""
    with RosbagsWriter(path, version=9, storage_plugin=STORAGES[storage]) as w:
        order = [F32, F64] if float32_first else [F64, F32]
        conn = {t: w.add_connection("/motor_speed", t, typestore=TYPESTORE) for t in order}
        load = w.add_connection("/axial_load", F64, typestore=TYPESTORE)
        w.write(load, T0, _payload(F64, 400.0))
        for k in range(SAMPLES):
            t = T0 + (k + 1) * 20_000_000
            w.write(conn[F64], t, _payload(F64, 2.0 + 1.5 * k))
            w.write(conn[F32], t + 1, _payload(F32, -7.0))
    return path


def _counts(summary: dict) -> dict:
    keys = (
        "messages",
        "input_messages",
        "recomputes",
        "predictions",
        "no_prediction",
        "rejected_inputs",
        "ignored_inputs",
        "episodes",
        "peak_probability",
    )
    return {k: summary[k] for k in keys}


def _risk(annotated: Path) -> list[tuple[int, float]]:
    return [(row[1], row[5].data) for row in decoded(annotated, ["/replay/squeak/risk"])]


@pytest.mark.parametrize("float32_first", [False, True])
def test_both_storages_give_the_same_counts_and_predictions(tmp_path, float32_first):
    runs = {}
    for storage in STORAGES:
        bag = two_type_bag(tmp_path / storage, storage, float32_first)
        runs[storage] = run_replay(bag, tmp_path / f"{storage}_out")
    mcap, db3 = runs["mcap"], runs["db3"]
    assert mcap.files[0].suffix == ".mcap" and db3.files[0].suffix == ".db3"
    summary = _counts(mcap.summary())
    assert summary == _counts(db3.summary())
    assert summary["messages"] == 2 * SAMPLES + 1
    assert summary["input_messages"] == {"/axial_load": 1, "/motor_speed": SAMPLES}
    assert summary["rejected_inputs"] == {REASON: SAMPLES}  # names both types
    assert summary["predictions"] > 0
    assert _risk(mcap.annotated) == _risk(db3.annotated) and _risk(mcap.annotated)
    # every original message copied, each on a channel of its own type
    for r in (mcap, db3):
        copied = [
            (row[0], type(row[5]).__name__)
            for row in decoded(r.annotated)
            if row[0] == "/motor_speed"
        ]
        assert sorted(set(copied)) == [("/motor_speed", "Float32"), ("/motor_speed", "Float64")]
        assert len(copied) == 2 * SAMPLES


def test_an_input_recorded_only_in_a_type_without_a_number_is_still_refused(tmp_path, capsys):
    # (a Float32 alone is read at its `data` since issue 29; a String's `data` is no number)
    bag = tmp_path / "text"
    string = "std_msgs/msg/String"
    with RosbagsWriter(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        speed = w.add_connection("/motor_speed", string, typestore=TYPESTORE)
        w.write(speed, T0, bytes(TYPESTORE.serialize_cdr(TYPESTORE.types[string]("3"), string)))
    code, _, err = cli(capsys, "replay", bag, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith("leadscrew-squeak: error: ")
    assert f"--speed-field data: {string}: data is a string, not a number" in err


def test_info_lists_the_topic_once_per_type(tmp_path, capsys):
    bag = two_type_bag(tmp_path / "bag", "mcap", float32_first=True)
    code, out, _ = cli(capsys, "info", bag)
    assert code == 0 and "metadata.yaml" not in out  # rosbags' metadata agrees
    lines = [ln.split() for ln in out.splitlines() if ln.startswith("  /motor_speed")]
    assert lines == [["/motor_speed", F32, str(SAMPLES)], ["/motor_speed", F64, str(SAMPLES)]]
    code, out, _ = cli(capsys, "info", "--json", bag)
    (entry,) = json.loads(out)
    assert [t for t in entry["topics"] if t["name"] == "/motor_speed"] == [
        {"name": "/motor_speed", "type": F32, "count": SAMPLES},
        {"name": "/motor_speed", "type": F64, "count": SAMPLES},
    ]


def test_recover_keeps_a_channel_per_type(tmp_path):
    bag = two_type_bag(tmp_path / "bag", "mcap", float32_first=False)
    (src,) = bag.glob("*.mcap")
    data = src.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 3 // 4])  # cut off before its summary
    info = recover(cut, tmp_path / "recovered.mcap")
    assert info.retyped_counts[("/motor_speed", F32)] > 0
    kinds = {(row[0], type(row[5]).__name__) for row in decoded(tmp_path / "recovered.mcap")}
    assert {("/motor_speed", "Float32"), ("/motor_speed", "Float64")} <= kinds
    again = inspect(tmp_path / "recovered.mcap")
    assert again.complete and again.type_counts() == info.type_counts()
