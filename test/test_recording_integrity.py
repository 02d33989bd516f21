# SPDX-License-Identifier: Apache-2.0
"""A recording is never lost, silently incomplete or unreplayable (issue 19): `recover` leaves a
file that is still being recorded alone; a file deleted or replaced under the node is an ERROR
and the recording goes on in a new file; every file starts with the node's input state, so that
its replay reproduces the node's predictions; a full disk turns `record.enabled` off with one
log line and a later start records cleanly. In-process node on the launch-free `ros` fixture
(harness.squeak.SqueakWorld)."""

from __future__ import annotations

import errno
import io
import os
import threading
import time
from pathlib import Path

import pytest
import yaml
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool

from harness.logs import cli
from harness.squeak import (
    LOAD,
    MODEL,
    SQUEAK,
    STABLE,
    SqueakWorld,
    at,
    modes_data,
    recording_status,
)
from leadscrew_ros.bag import recorder as recorder_module
from leadscrew_ros.bag.logfile import inspect, is_complete, log_files, read_log
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.ros.input_recording import InputRecording

ERROR = b"\x02"


def record(ros: SqueakWorld, on: bool) -> SetBool.Response:
    """Call the node's ~/record service."""
    client = ros.probe.create_client(SetBool, f"{ros.ns}/squeak_predictor/record")
    ros.spin_until(client.service_is_ready, 5.0, "the ~/record service")
    future = client.call_async(SetBool.Request(data=on))
    ros.spin_until(future.done, 5.0, "the service response")
    return future.result()


def speed(ros: SqueakWorld, value: float) -> None:
    """Send a speed only (the load is the node's state) and wait for its prediction."""
    core = MODEL.predict(value, LOAD)
    ros.send("motor_speed", value)
    ros.wait_for(
        "squeak/modes", lambda m: list(m.data) == pytest.approx(modes_data(core), rel=1e-9)
    )
    ros.wait_for("squeak/risk", lambda m: m.data == core.probability)


def floats(path: Path, topic: str) -> list[float]:
    """The Float64 values of `topic` in a log, in log order."""
    return [deserialize_message(m.data, Float64).data for m in read_log(path, {topic})]


def recording_node(ros: SqueakWorld, directory: Path):
    node = ros.start(
        **{
            "record.enabled": True,
            "record.directory": str(directory),
            "record.flush_period_s": 0.05,
        }
    )
    at(ros, SQUEAK)
    return node


# ----------------------------------------------------------------------------- live writer
def test_recover_refuses_a_file_being_recorded_and_recovers_only_the_cut_off_bags(
    ros, tmp_path, capsys
):
    directory = tmp_path / "bags"
    cut_bag = write_log(DutyCycle(duration_s=5.0, rest_s=1.0), directory)  # a crashed run
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

    after = os.stat(live)  # the node's file, untouched
    assert (after.st_ino, after.st_dev) == (before.st_ino, before.st_dev)
    assert sorted(p.name for p in bag.iterdir()) == [live.name]
    at(ros, STABLE)
    assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
    info = inspect(live)
    assert info.complete and not info.live and not info.damage
    assert info.counts[f"{ros.ns}/squeak/risk"] == 2  # both predictions, in the one file
    code, out, err = cli(capsys, "recover", bag)
    assert code == 0 and "nothing to recover" in out, out  # it was never touched


def test_a_file_deleted_or_replaced_under_the_node_is_an_error_and_recording_goes_on(ros, tmp_path):
    node = recording_node(ros, tmp_path)
    bag = node.recorder.bag
    first = node.recorder.path
    first.unlink()
    status = recording_status(ros, lambda s: s.level == ERROR and "deleted" in s.message)
    assert f"{first} was deleted while being recorded" in status.message, status.message
    second = node.recorder.path
    assert second != first and second.is_file()
    speed(ros, STABLE)

    foreign = tmp_path / "foreign.mcap"
    foreign.write_bytes(b"not ours")
    os.replace(foreign, second)
    status = recording_status(ros, lambda s: s.level == ERROR and "replaced" in s.message)
    assert f"{second} was replaced by another file while being recorded" in status.message
    third = node.recorder.path
    assert third not in (first, second) and third.is_file()
    speed(ros, 30.0)
    status = recording_status(ros, lambda s: True)
    assert status.level == ERROR, status.message  # never OK while data were lost
    assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful

    assert second.read_bytes() == b"not ours"  # the recorder never writes over it
    info = inspect(third)
    assert info.complete
    # the new file starts with the node's state (load and speed), then what came after
    assert floats(third, f"{ros.ns}/axial_load") == [LOAD]
    assert floats(third, f"{ros.ns}/motor_speed") == [STABLE, 30.0]
    assert floats(third, f"{ros.ns}/squeak/risk")[-1] == MODEL.predict(30.0, LOAD).probability
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == [third.name]
    assert meta["message_count"] == info.messages
    assert str(second) in meta["custom_data"]["incident"]


# ----------------------------------------------------------------------------- input state
def replayed(capsys, log: Path, out: Path, ns: str) -> dict[str, list]:
    """Replay `log` (CLI, no report) and return its risk and modes predictions."""
    code, stdout, err = cli(capsys, "replay", log, "--out", out, "--no-report", "--quiet")
    assert code == 0, err
    [annotated] = out.glob("*.annotated.mcap")
    return {
        "risk": floats(annotated, f"/replay{ns}/squeak/risk"),
        "modes": [
            list(deserialize_message(m.data, Float64MultiArray).data)
            for m in read_log(annotated, {f"/replay{ns}/squeak/modes"})
        ],
    }


def recorded(files: list[Path], ns: str) -> dict[str, list]:
    """The node's risk and modes predictions in `files`: all of the first file, of each later
    one what follows the outputs it starts with (copies of the last ones, its state)."""
    said = {"risk": [], "modes": []}
    for i, f in enumerate(files):
        start = min(m.log_time_ns for m in read_log(f))
        for key, topic, cls in (("risk", "risk", Float64), ("modes", "modes", Float64MultiArray)):
            said[key] += [
                deserialize_message(m.data, cls).data
                for m in read_log(f, {f"{ns}/squeak/{topic}"})
                if i == 0 or m.log_time_ns > start
            ]
    said["modes"] = [list(m) for m in said["modes"]]
    return said


def test_a_recording_starts_with_the_load_published_before_it_and_replays_to_the_nodes_predictions(
    ros, tmp_path, capsys
):
    node = ros.start(**{"record.directory": str(tmp_path / "bags")})
    ros.send("axial_load", LOAD)  # once, before recording starts
    ros.spin_until(lambda: node.live.inputs.load_n == LOAD, what="the load")
    assert record(ros, True).success
    for value in (SQUEAK, 40.0, STABLE, 10.0):
        speed(ros, value)
    # a parameter change goes on in a new file: that file alone replays too
    assert node.set_parameters([Parameter("diagnostics_period_s", value=0.5)])[0].successful
    for value in (50.0, 5.0):
        speed(ros, value)
    assert record(ros, False).success
    bag = node.recorder.bag
    files = log_files(bag)
    assert len(files) == 2

    node_says = recorded(files, ros.ns)
    assert len(node_says["risk"]) == 6
    replay_says = replayed(capsys, bag, tmp_path / "all", ros.ns)
    assert replay_says["risk"] == pytest.approx(node_says["risk"], rel=1e-12, abs=0)
    assert replay_says["modes"] == [pytest.approx(m, rel=1e-12) for m in node_says["modes"]]
    # The second file starts with load 200 N and the speed 5.0 rad/s was sent after them
    second = replayed(capsys, files[1], tmp_path / "second", ros.ns)
    assert floats(files[1], f"{ros.ns}/axial_load") == [LOAD]
    node_second = recorded(files[1:], ros.ns)
    assert second["risk"] == pytest.approx(node_second["risk"], rel=1e-12, abs=0)
    assert second["modes"] == [pytest.approx(m, rel=1e-12) for m in node_second["modes"]]


def test_inputs_still_queued_for_the_recording_when_it_stops_are_written(
    ros, tmp_path, monkeypatch
):
    """The recording thread may lag behind the model: the inputs whose predictions are in the
    bag must be there too."""
    node = recording_node(ros, tmp_path)
    received = InputRecording._received

    def lagging(self, e, data, info):  # the recording thread falls behind until stop
        while not self._stop.is_set():
            time.sleep(0.001)
        received(self, e, data, info)

    monkeypatch.setattr(InputRecording, "_received", lagging)
    speed(ros, 40.0)
    speed(ros, 5.0)
    assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
    [file] = log_files(node.recorder.bag)
    assert floats(file, f"{ros.ns}/motor_speed") == [SQUEAK, 40.0, 5.0]


# ----------------------------------------------------------------------------- disk full
class _Spy:
    """A node logger that also keeps what was logged at ERROR."""

    def __init__(self, logger):
        self._logger, self.errors = logger, []

    def error(self, message, **kwargs):
        self.errors.append(message)
        return self._logger.error(message, **kwargs)

    def __getattr__(self, name):
        return getattr(self._logger, name)


def test_disk_full_logs_once_turns_record_enabled_off_and_a_later_start_records_cleanly(
    ros, tmp_path, monkeypatch
):
    full = threading.Event()

    class Disk(io.FileIO):
        def write(self, data):
            if full.is_set():
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), self.name)
            return super().write(data)

    monkeypatch.setattr(
        recorder_module,
        "open",
        lambda path, mode: io.BufferedWriter(Disk(path, mode.replace("b", ""))),
        raising=False,
    )
    node = recording_node(ros, tmp_path)
    spy = _Spy(node.get_logger())
    monkeypatch.setattr(node, "get_logger", lambda: spy)
    full.set()
    status = recording_status(ros, lambda s: s.level == ERROR)
    assert "No space left on device" in status.message, status.message
    assert "~/record true" in status.message and "record.enabled" in status.message
    ros.spin_until(
        lambda: node.get_parameter("record.enabled").value is False,
        5.0,
        "record.enabled to turn false",
    )
    assert not node.recorder.active
    at(ros, STABLE)  # predictions go on
    at(ros, 30.0)
    lines = [e for e in spy.errors if "No space left on device" in e]
    assert len(lines) == 1, spy.errors  # once per failure episode
    assert "~/record true" in lines[0]

    full.clear()  # space again
    response = record(ros, True)
    assert response.success, response.message
    assert node.get_parameter("record.enabled").value is True
    status = recording_status(ros, lambda s: s.message.startswith("recording to"))
    assert status.level == b"\x00"
    speed(ros, SQUEAK)
    assert record(ros, False).success
    [file] = log_files(node.recorder.bag)
    info = inspect(file)
    assert info.complete and info.counts[f"{ros.ns}/squeak/risk"] >= 2  # state + new one
