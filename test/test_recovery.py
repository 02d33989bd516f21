# SPDX-License-Identifier: Apache-2.0
"""Crash recovery closes the loop: `leadscrew-squeak recover BAGDIR|FILE` (`logfile.recover_bag`)
leaves a bag that rosbags, the mcap reader and `replay` open; in place, verified, idempotent.
The crash is a real SIGKILL of a recording node process (harness.recording)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from harness.recording import answering_node
from leadscrew_ros.bag.logfile import (
    LogError,
    cut_off_bags,
    inspect,
    is_complete,
    log_files,
    read_log,
    read_messages,
    recover_bag,
)
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main

CYCLE = DutyCycle(duration_s=30.0, rest_s=5.0)  # 3 topics at 100 Hz: 9000 messages


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def rosbags_messages(bag: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time, raw payload) of every message rosbags reads from a bag directory."""
    with AnyReader([bag]) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def ours(path: Path) -> list[tuple[str, int, bytes]]:
    return [(m.topic.name, m.log_time_ns, m.data) for m in read_log(path)]


def snapshot(directory: Path) -> dict[str, tuple[bytes, int]]:
    """Every file of a directory: contents and modification time."""
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(directory.iterdir())}


def cut(path: Path, fraction: float) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])


@pytest.fixture(scope="module")
def split_bag_bytes(tmp_path_factory) -> dict[str, bytes]:
    bag = write_log(CYCLE, tmp_path_factory.mktemp("split"), split_duration_s=10.0)
    return {p.name: p.read_bytes() for p in bag.iterdir()}


@pytest.fixture
def split_bag(tmp_path, split_bag_bytes) -> Path:
    """A fresh copy of a complete bag of three split files and its metadata.yaml."""
    bag = tmp_path / "squeak_2026_01_01-00_00_00_000"
    bag.mkdir()
    for name, data in split_bag_bytes.items():
        (bag / name).write_bytes(data)
    assert len(log_files(bag)) == 3
    return bag


def test_sigkill_then_recover_bagdir_every_tool_reads_it_and_a_second_run_is_a_no_op(
    tmp_path, capsys, ns
):  # noqa: F811
    with answering_node(tmp_path, ns) as (proc, directory, feed):
        feed.run(1.5)
        proc.kill()
        proc.wait(timeout=10)
    (bag,) = directory.iterdir()
    (file,) = log_files(bag)
    assert not is_complete(file) and not (bag / "metadata.yaml").exists()
    assert cut_off_bags(directory) == [bag]
    readable = inspect(file)
    assert readable.counts[f"{ns}/motor_speed"] > 0
    with pytest.raises(Exception):  # noqa: B017  rosbags' own error type; no metadata.yaml
        rosbags_messages(bag)

    # the round trip of the issue: each tool names `recover BAGDIR` ...
    hint = f"leadscrew-squeak recover {bag}"
    code, _, err = cli(capsys, "replay", bag, "--out", tmp_path / "r0", "--quiet", "--no-report")
    assert code == 2 and hint in err
    code, out, _ = cli(capsys, "info", bag)
    assert code == 0 and hint in out
    # ... and after it every tool reads the bag
    code, out, err = cli(capsys, "recover", bag)
    assert code == 0 and err == "", err
    assert f"{file}: recovered {readable.messages} messages" in out
    assert "metadata.yaml regenerated" in out.splitlines()[-1]
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", file.name]  # no .broken
    assert is_complete(file) and cut_off_bags(directory) == []

    read = rosbags_messages(bag)
    assert len(read) == readable.messages
    assert read == [
        (m.topic.name, m.log_time_ns, m.data) for m in read_messages(file)
    ]  # same messages, same order, same bytes
    with open(file, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == readable.messages
        assert sum(1 for _ in reader.iter_messages()) == readable.messages
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == readable.messages
    assert {
        t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]
    } == dict(readable.counts)
    code, _, err = cli(
        capsys,
        "replay",
        bag,
        "--out",
        tmp_path / "r1",
        "--quiet",
        "--no-report",
        "--speed-topic",
        f"{ns}/motor_speed",
        "--load-topic",
        f"{ns}/axial_load",
    )
    assert code == 0 and err == "", err

    before = snapshot(bag)
    code, out, err = cli(capsys, "recover", bag)
    assert code == 0 and out.splitlines()[-1] == (
        f"nothing to recover: {bag} is complete ({readable.messages} messages)"
    )
    assert snapshot(bag) == before


def test_truncated_file_in_the_middle_of_a_split_bag(split_bag, capsys):
    whole = ours(split_bag)
    middle = log_files(split_bag)[1]
    cut(middle, 0.6)
    untouched = {p.name: p.read_bytes() for p in log_files(split_bag) if p != middle}
    with pytest.raises(Exception):  # noqa: B017  any rosbags error: metadata, footer disagree
        rosbags_messages(split_bag)

    code, out, err = cli(capsys, "recover", split_bag)
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].endswith("_0.mcap: complete, 3003 messages")
    assert f"{middle}: recovered " in lines[1] and lines[2].endswith(
        "_2.mcap: complete, 2997 messages"
    )
    read = rosbags_messages(split_bag)
    recovered = ours(middle)
    assert 0 < len(recovered) < 3000
    # what survives is the whole of files 0 and 2 and a prefix of file 1, unchanged
    assert read == whole[: 3003 + len(recovered)] + whole[-2997:]
    assert {p.name: p.read_bytes() for p in log_files(split_bag) if p != middle} == untouched
    meta = yaml.safe_load((split_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert [f["message_count"] for f in meta["files"]] == [3003, len(recovered), 2997]
    assert meta["message_count"] == len(read)
    before = snapshot(split_bag)
    assert not recover_bag(split_bag).changed
    assert snapshot(split_bag) == before


def test_recover_one_file_of_a_bag_also_regenerates_the_bag_metadata(split_bag, capsys):
    last = log_files(split_bag)[2]
    cut(last, 0.5)
    code, out, err = cli(capsys, "recover", last)
    assert code == 0 and err == ""
    assert out.startswith(f"{last}: recovered ") and "metadata.yaml regenerated" in out
    assert len(rosbags_messages(split_bag)) == 3003 + 3000 + inspect(last).messages


def test_a_loose_file_is_recovered_in_place_and_o_still_writes_a_copy(split_bag, tmp_path, capsys):
    loose = tmp_path / "loose.mcap"
    loose.write_bytes(log_files(split_bag)[0].read_bytes())
    cut(loose, 0.7)
    data = loose.read_bytes()
    code, out, _ = cli(capsys, "recover", loose, "-o", tmp_path / "copy.mcap")
    assert code == 0 and loose.read_bytes() == data and is_complete(tmp_path / "copy.mcap")
    code, out, _ = cli(capsys, "recover", loose)
    assert code == 0 and is_complete(loose) and out.startswith(f"{loose}: recovered ")
    assert ours(loose) == ours(tmp_path / "copy.mcap")
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == ["copy.mcap", "loose.mcap"]
    assert not (tmp_path / "metadata.yaml").exists()
    code, out, _ = cli(capsys, "recover", loose)
    assert code == 0 and out.splitlines()[-1].startswith("nothing to recover")


def test_nothing_to_recover(split_bag, tmp_path, capsys):
    before = snapshot(split_bag)
    code, out, err = cli(capsys, "recover", split_bag)
    assert code == 0 and err == ""
    assert out.splitlines()[-1] == f"nothing to recover: {split_bag} is complete (9000 messages)"
    assert snapshot(split_bag) == before
    # a record directory of complete bags, and an empty one
    for directory in (tmp_path, tmp_path / "empty"):
        directory.mkdir(exist_ok=True)
        assert cut_off_bags(directory) == []
        code, out, err = cli(capsys, "recover", directory)
        assert (code, out, err) == (
            0,
            f"nothing to recover: no cut-off recording in {directory}\n",
            "",
        )
    assert snapshot(split_bag) == before


def test_a_record_directory_recovers_each_cut_off_bag_and_loose_file(split_bag, tmp_path, capsys):
    other = tmp_path / "other_bag"
    other.mkdir()
    (other / "other_bag_0.mcap").write_bytes(log_files(split_bag)[0].read_bytes())  # no yaml
    loose = tmp_path / "loose.mcap"
    loose.write_bytes(log_files(split_bag)[1].read_bytes())
    cut(loose, 0.5)
    cut(log_files(split_bag)[2], 0.5)
    assert cut_off_bags(tmp_path) == [loose, other, split_bag]
    code, out, err = cli(capsys, "recover", tmp_path)
    assert code == 0 and err == ""
    assert cut_off_bags(tmp_path) == []
    assert len(rosbags_messages(other)) == 3003
    assert len(rosbags_messages(split_bag)) == 6003 + inspect(log_files(split_bag)[2]).messages


def test_a_file_damaged_before_its_end_keeps_its_original(split_bag, capsys):
    first = log_files(split_bag)[0]
    data = bytearray(first.read_bytes())
    data[len(data) // 2] ^= 0xFF  # inside a compressed chunk: CRC mismatch
    first.write_bytes(bytes(data))
    assert is_complete(first) and inspect(first).damage
    code, out, err = cli(capsys, "recover", split_bag)
    assert code == 0 and err == ""
    broken = first.with_name(first.name + ".broken")
    assert broken.read_bytes() == bytes(data) and "original kept as" in out
    assert len(rosbags_messages(split_bag)) == inspect(first).messages + 3000 + 2997
    assert not recover_bag(split_bag).changed


def test_a_file_without_a_whole_message_is_set_aside(split_bag, capsys):
    last = log_files(split_bag)[2]
    cut(last, 0.001)  # the header, no message
    code, out, _ = cli(capsys, "recover", split_bag)
    assert code == 0 and f"{last}: no whole message" in out
    assert not last.exists() and last.with_name(last.name + ".broken").is_file()
    assert len(rosbags_messages(split_bag)) == 6003
    assert not recover_bag(split_bag).changed


def test_a_recovery_killed_between_its_renames_starts_over(split_bag, split_bag_bytes):
    middle = log_files(split_bag)[1]
    cut(middle, 0.6)
    cut_data = middle.read_bytes()
    # the state a SIGKILL between the two renames leaves: original set aside, rewrite unverified
    os.replace(middle, middle.with_name(middle.name + ".broken"))
    middle.with_name(middle.name + ".recovering").write_bytes(cut_data[:100])
    result = recover_bag(split_bag)
    assert [f.action for f in result.files] == ["complete", "recovered", "complete"]
    assert sorted(p.name for p in split_bag.iterdir()) == sorted(split_bag_bytes)
    assert len(rosbags_messages(split_bag)) == 6000 + inspect(middle).messages


def test_a_foreign_file_is_an_error_and_stays_as_it_was(tmp_path, capsys):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes(b"not an mcap file at all")
    code, out, err = cli(capsys, "recover", bag)
    assert code == 2 and err.count("\n") == 1 and "not an MCAP file" in err
    assert sorted(p.name for p in bag.iterdir()) == ["bag_0.mcap"]
    with pytest.raises(LogError):
        recover_bag(bag / "missing.mcap")
