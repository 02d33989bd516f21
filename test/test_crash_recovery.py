# SPDX-License-Identifier: Apache-2.0
"""`bag.crash_recovery.CrashRecovery`: which bags of a record directory are this node's and cut
off, their recovery in place on a thread of its own (a bag whose file was truncated by a crash
comes back complete with the messages before the cut), and the diagnostic level and message
in every state. rclpy-free; the node's use of it is in test_recording.py."""

import threading
from pathlib import Path

import pytest

from leadscrew_ros.bag import crash_recovery
from leadscrew_ros.bag.crash_recovery import CrashRecovery
from leadscrew_ros.bag.logfile import METADATA, RECOVER_HINT, is_complete, log_files, read_log
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.live.status import Level

STAMP = "2026_01_01-00_00_00_000"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict[str, bytes]:
    """A complete bag of one file (3 topics at 100 Hz for 2 s): file name -> bytes."""
    bag = write_log(DutyCycle(duration_s=2.0, rest_s=0.5), tmp_path_factory.mktemp("rec"))
    assert len(log_files(bag)) == 1
    return {p.name: p.read_bytes() for p in bag.iterdir()}


def make_bag(
    directory: Path, name: str, recorded: dict[str, bytes], keep: float = 1.0, metadata: bool = True
) -> Path:
    """A copy of the recorded bag named `name`: its file cut to `keep` of its bytes (a crash
    mid-write), with or without metadata.yaml."""
    bag = directory / name
    bag.mkdir(parents=True)
    for file_name, data in recorded.items():
        if file_name == METADATA:
            if metadata:
                (bag / file_name).write_bytes(data)
            continue
        (bag / f"{name}_0.mcap").write_bytes(data[: int(len(data) * keep)])
    return bag


def messages(path: Path) -> list[tuple[str, int, bytes]]:
    return [(m.topic.name, m.log_time_ns, m.data) for m in read_log(path)]


def test_only_this_nodes_cut_off_bags_are_found(tmp_path, recorded):
    own_no_metadata = make_bag(tmp_path, f"squeak_{STAMP}", recorded, metadata=False)
    own_truncated = make_bag(tmp_path, f"squeak_{STAMP}_1", recorded, keep=0.6)
    make_bag(tmp_path, "squeak_2026_01_02-00_00_00_000", recorded)  # complete
    make_bag(tmp_path, f"seat_left_squeak_{STAMP}", recorded, keep=0.6)  # another node's
    make_bag(tmp_path, "squeak_backup", recorded, keep=0.6)  # not a bag name
    loose = tmp_path / f"squeak_{STAMP}.mcap"  # not a bag dir
    loose.write_bytes(next(v for k, v in recorded.items() if k != METADATA)[:100])
    crash = CrashRecovery(str(tmp_path), "squeak")
    assert crash.bags == [own_no_metadata, own_truncated]
    assert crash.pending == crash.bags and crash.state == (2, 0, 0)
    assert crash.level is Level.WARN
    assert crash.message == (
        f"2 bag(s) of an earlier run cut off (crash?): {own_no_metadata}, "
        f"{own_truncated}; run `{RECOVER_HINT} BAGDIR` on each"
    )
    # the prefix is literal text, the namespace part of another node's name included
    assert CrashRecovery(str(tmp_path), "seat_left_squeak").bags == [
        tmp_path / f"seat_left_squeak_{STAMP}"
    ]
    assert CrashRecovery(str(tmp_path), "seat.left_squeak").bags == []


@pytest.mark.parametrize("keep, whole", [(0.3, False), (0.7, False), (0.95, True)])
def test_a_truncated_file_is_recovered_with_every_message_before_the_cut(
    tmp_path, recorded, keep, whole
):
    """Cut in the data: the messages up to the cut (whole chunks); cut in the summary and
    index at the end of the file: every message."""
    original = make_bag(tmp_path / "orig", f"squeak_{STAMP}", recorded)
    before = messages(original)
    bag = make_bag(tmp_path, f"squeak_{STAMP}", recorded, keep=keep, metadata=False)
    [file] = log_files(bag)
    assert not is_complete(file)
    crash = CrashRecovery(str(tmp_path), "squeak")
    assert crash.bags == [bag]
    crash.start()
    crash.join()
    assert crash.recovered == [bag] and crash.failed == {} and crash.pending == []
    assert crash.state == (1, 1, 0) and crash.level is Level.OK
    assert crash.message == f"recovered 1 cut-off bag(s) of an earlier run: {bag}"
    assert is_complete(file) and (bag / METADATA).is_file()
    after = messages(bag)
    # what is left is the start of the recording, unchanged
    assert after == before[: len(after)] and len(after) > 0
    assert (len(after) == len(before)) == whole, (len(after), len(before))
    assert CrashRecovery(str(tmp_path), "squeak").bags == []  # nothing left to do


def test_a_bag_that_cannot_be_recovered_is_reported_with_its_reason(tmp_path, recorded):
    broken = tmp_path / f"squeak_{STAMP}"
    broken.mkdir()
    (broken / f"{broken.name}_0.mcap").write_bytes(b"not an MCAP file at all")
    good = make_bag(tmp_path, "squeak_2026_01_02-00_00_00_000", recorded, keep=0.7, metadata=False)
    crash = CrashRecovery(str(tmp_path), "squeak")
    assert crash.bags == [broken, good]
    crash.start()
    crash.join()
    assert crash.recovered == [good]  # one failure does not stop the others
    assert list(crash.failed) == [broken] and str(broken) in crash.failed[broken]
    assert crash.pending == [broken] and crash.state == (2, 1, 1)
    assert crash.level is Level.WARN
    assert crash.message == (
        f"recovered 1 cut-off bag(s) of an earlier run: {good}; 1 bag(s) of an earlier run "
        f"cut off (crash?): {broken}; run `{RECOVER_HINT} BAGDIR` on each "
        f"({crash.failed[broken]})"
    )


def test_while_the_thread_recovers_the_message_says_so(tmp_path, recorded, monkeypatch):
    bag = make_bag(tmp_path, f"squeak_{STAMP}", recorded, keep=0.5, metadata=False)
    entered, release = threading.Event(), threading.Event()
    recover = crash_recovery.recover_bag

    def held(path):
        entered.set()
        assert release.wait(30.0)
        return recover(path)

    monkeypatch.setattr(crash_recovery, "recover_bag", held)
    crash = CrashRecovery(str(tmp_path), "squeak")
    crash.start()
    try:
        assert entered.wait(30.0)
        assert crash.message == "recovering 1 cut-off bag(s) of an earlier run"
        assert crash.level is Level.WARN and crash.pending == [bag]
    finally:
        release.set()
        crash.join()
    assert crash.recovered == [bag] and crash.level is Level.OK


@pytest.mark.parametrize("directory", ["missing", "empty"])
def test_nothing_to_recover_says_nothing(tmp_path, directory):
    (tmp_path / "empty").mkdir()
    crash = CrashRecovery(str(tmp_path / directory), "squeak")
    assert crash.bags == [] and crash.pending == [] and crash.state == (0, 0, 0)
    assert crash.level is Level.OK and crash.message == ""
    crash.join()  # never started: returns at once


def test_the_directory_may_start_with_a_tilde(tmp_path, recorded, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    bag = make_bag(tmp_path / "bags", f"squeak_{STAMP}", recorded, metadata=False)
    assert CrashRecovery("~/bags", "squeak").bags == [bag]
