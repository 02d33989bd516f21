# SPDX-License-Identifier: Apache-2.0
"""A recording is never lost, silently incomplete or unreplayable (issue 19): `recover` leaves a
file that is still being recorded alone; a file deleted or replaced under the node is an ERROR
and the recording goes on in a new file; every file starts with the node's input state, so that
its replay reproduces the node's predictions; a full disk turns `record.enabled` off with one
log line and a later start records cleanly. In-process node on the launch-free `Ros` world of
test_node.py."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from rclpy.parameter import Parameter

from leadscrew_ros.bag.logfile import inspect, is_complete, log_files
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main
from test_node import SQUEAK, STABLE, Ros, at


@pytest.fixture
def ros():
    r = Ros()
    try:
        yield r
    finally:
        r.close()


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def recording_node(ros: Ros, directory: Path):
    node = ros.start(**{"record.enabled": True, "record.directory": str(directory),
                        "record.flush_period_s": 0.05})
    at(ros, SQUEAK)
    return node


# ----------------------------------------------------------------------------- live writer
def test_recover_refuses_a_file_being_recorded_and_recovers_only_the_cut_off_bags(
        ros, tmp_path, capsys):
    directory = tmp_path / "bags"
    cut_bag = write_log(DutyCycle(duration_s=5.0, rest_s=1.0), directory)   # a crashed run
    cut_file = log_files(cut_bag)[0]
    cut_file.write_bytes(cut_file.read_bytes()[:-200])
    (cut_bag / "metadata.yaml").unlink()
    node = recording_node(ros, directory)
    live, bag = node.recorder.path, node.recorder.bag
    before = os.stat(live)

    for target in (bag, live):
        code, out, err = cli(capsys, "recover", target)
        assert code == 2 and out == "", (out, err)
        assert err.count("\n") == 1 and err.startswith("leadscrew-squeak: error: "), err
        assert f"{live}: is being recorded (live writer)" in err, err
    code, out, err = cli(capsys, "recover", directory)
    assert code == 0, err
    assert f"{bag}: skipped, is being recorded (live writer)" in out, out
    assert f"{cut_bag}: 1 file(s) recovered" in out, out
    assert is_complete(cut_file) and (cut_bag / "metadata.yaml").is_file()
    code, out, err = cli(capsys, "info", live)
    assert code == 0 and f"{live}: is being recorded (live writer)" in out, out
    assert "TRUNCATED" not in out
    code, out, err = cli(capsys, "replay", live, "--out", tmp_path / "r", "--no-report")
    assert code == 2 and "is being recorded (live writer)" in err, err

    after = os.stat(live)                            # the node's file, untouched
    assert (after.st_ino, after.st_dev) == (before.st_ino, before.st_dev)
    assert sorted(p.name for p in bag.iterdir()) == [live.name]
    at(ros, STABLE)
    assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
    info = inspect(live)
    assert info.complete and not info.live and not info.damage
    assert info.counts[f"{ros.ns}/squeak/risk"] == 2       # both predictions, in the one file
    code, out, err = cli(capsys, "recover", bag)
    assert code == 0 and "nothing to recover" in out, out     # it was never touched
