# SPDX-License-Identifier: Apache-2.0
"""Logs that explain themselves: the node's recordings carry the `leadscrew_ros` MCAP Metadata
record in every file (read back with the `mcap` reader through `logmeta`; `rosbags` exposes no
MCAP metadata, so it is shown to read every message of such files), recovery keeps it, the
replay's annotated MCAP carries the review as attachments (the same bytes as the files it
writes) and the metadata records, and the Foxglove layout names only the node's topics."""

from __future__ import annotations

import dataclasses
import io
import json
import re
import shutil
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from rclpy.parameter import Parameter
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import Float64

from harness.squeak import LOAD
from leadscrew_ros import __version__
from leadscrew_ros.bag import logmeta
from leadscrew_ros.bag.logfile import is_complete, log_files, recover
from leadscrew_ros.bag.mcapout import McapOut
from leadscrew_ros.bag.messages import OUTPUT_TYPES, RISK
from leadscrew_ros.bag.recorder import Recorder, RecordSettings
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.uncertainty.scatter import ScatterSettings
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.report import QUICK, write_report
from leadscrew_ros.review.timeline import InputSettings
from leadscrew_ros.ros.node import INPUTS, OUTPUT_CLASSES
from leadscrew_ros.ros.parameters import PARAMETER_NAMES, PARAMETERS, log_metadata

REPO = Path(__file__).resolve().parents[1]
LAYOUT = REPO / "foxglove" / "squeak_predictor.json"
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
FLOAT64 = "std_msgs/msg/Float64"
CDR_ZERO = b"\x00\x01\x00\x00" + bytes(8)  # std_msgs/Float64 0.0


def records(path: Path) -> list[tuple[str, dict[str, str]]]:
    """(name, map) of every Metadata record of an MCAP file, through its summary index."""
    with open(path, "rb") as f:
        return [(m.name, dict(m.metadata)) for m in make_reader(f).iter_metadata()]


def rosbags_counts(path: Path) -> dict[str, int]:
    """Messages per topic that rosbags reads (and decodes) from a bag directory or file."""
    counts: dict[str, int] = {}
    with RosbagsReader(path) as reader:
        for conn, _, raw in reader.messages():
            TYPESTORE.deserialize_cdr(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    return counts


def mcap_counts(paths: list[Path]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for path in paths:
        with open(path, "rb") as f:
            for _, channel, _ in make_reader(f).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return counts


def default_values(**changes) -> dict:
    return {**{s.name: s.default for s in PARAMETERS}, **changes}


# ----------------------------------------------------------------------------- the node
def test_node_recording_describes_itself_in_every_file(ros, tmp_path):
    node = ros.start(
        **{"record.directory": str(tmp_path), "record.enabled": True, "unit_id": "seat-7"}
    )

    def drive(speed: float) -> None:
        ros.publisher("axial_load").publish(Float64(data=LOAD))
        ros.publisher("motor_speed").publish(Float64(data=speed))
        ros.spin_until(lambda: node.live.inputs.speed_rad_s == speed, what="the speed")
        ros.spin_until(lambda: not node.live.changed(), what="the recompute")
        ros.drain()

    drive(20.0)
    # a parameter change while recording: the recording goes on in a new file
    assert node.set_parameters([Parameter("speed_deadband_rad_s", value=0.2)])[0].successful
    drive(40.0)
    bag = node.recorder.bag
    node.destroy_node()
    ros.executor.remove_node(node)
    ros.node = None

    files = log_files(bag)
    assert len(files) == 2 and all(is_complete(f) for f in files)
    metas = [logmeta.read(f) for f in files]
    for f, meta in zip(files, metas, strict=True):
        assert [name for name, _ in records(f)] == [logmeta.RECORD_NAME]
        assert meta.unit_id == "seat-7" and meta.hardware_id == ros.hardware_id
        assert meta.version == __version__
        assert meta.params == ScrewParameters().as_dict()
        assert meta.formulation == ScrewParameters().formulation
        assert meta.screw_parameters() == ScrewParameters()
        assert meta.scatter == dataclasses.asdict(ScatterSettings())
        own = set(PARAMETER_NAMES) - set(meta.params) - {f"scatter.{k}" for k in meta.scatter}
        assert set(meta.node) == own and meta.node["unit_id"] == "seat-7"
        assert meta.node["record.directory"] == str(tmp_path)
    assert [m.node["speed_deadband_rad_s"] for m in metas] == [0.1, 0.2]
    # each file's record holds for its messages: the new parameters' outputs are in file 1
    assert all(mcap_counts([f]).get(f"{ros.ns}/{RISK}", 0) >= 1 for f in files)

    # rosbags (no MCAP metadata API) reads every message of the bag, metadata and all
    assert rosbags_counts(bag) == mcap_counts(files)


def test_unit_id_is_read_only_with_an_empty_default(ros):
    node = ros.start()
    assert node.get_parameter("unit_id").value == ""
    assert not node.set_parameters([Parameter("unit_id", value="x")])[0].successful
    assert node.recorder.metadata[logmeta.RECORD_NAME]["unit_id"] == ""


# ----------------------------------------------------------------------------- the recorder
def test_every_file_gets_the_records_current_when_it_opens(tmp_path):
    first = {logmeta.RECORD_NAME: log_metadata(default_values(unit_id="a")).record()}
    rec = Recorder(
        RecordSettings(directory=str(tmp_path), split_duration_s=1.0, compression="none"),
        metadata=first,
    )
    assert rec.start(now_ns=0)
    rec.write_serialized("/x", FLOAT64, CDR_ZERO, 1)
    rec.split(now_ns=10)  # split by the caller
    second = {
        logmeta.RECORD_NAME: log_metadata(default_values(unit_id="b")).record(),
        "other": {"k": "v"},
    }
    rec.metadata = second  # in the next file only
    rec.write_serialized("/x", FLOAT64, CDR_ZERO, 2)
    rec.tick(now_ns=2_000_000_000)  # split by duration
    rec.write_serialized("/x", FLOAT64, CDR_ZERO, 3)
    rec.stop()
    files = log_files(rec.bag)
    assert [dict(records(f)) for f in files] == [first, first, second]
    assert [logmeta.read(f).unit_id for f in files] == ["a", "a", "b"]
    assert rosbags_counts(rec.bag) == {"/x": 3}


def test_a_cut_off_file_and_its_recovery_keep_the_record(tmp_path):
    record = log_metadata(default_values(unit_id="c")).record()
    rec = Recorder(
        RecordSettings(directory=str(tmp_path / "rec")), metadata={logmeta.RECORD_NAME: record}
    )
    assert rec.start(now_ns=0)
    for i in range(10):
        rec.write_serialized("/x", FLOAT64, CDR_ZERO, i)
    rec.tick(now_ns=10**9)  # flushed: a crash keeps these
    cut = tmp_path / "cut.mcap"
    shutil.copy(rec.path, cut)  # the file as a crash leaves it
    rec.stop()
    assert not is_complete(cut)
    assert logmeta.read_record(cut) == record  # read from the start of the file
    info = recover(cut, tmp_path / "recovered.mcap")
    assert info.messages == 10 and info.metadata == {logmeta.RECORD_NAME: record}
    assert logmeta.read_record(tmp_path / "recovered.mcap") == record


# ----------------------------------------------------------------------------- the replay
@pytest.fixture(scope="module")
def reviewed(tmp_path_factory):
    """A synthetic log with a node's record, replayed with the report: (result, record,
    report paths)."""
    record = log_metadata(default_values(unit_id="seat-9", hardware_id="hw-9")).record()
    cycle = DutyCycle(duration_s=8.0, rate_hz=20.0, rest_s=0.5)
    bag = write_log(cycle, tmp_path_factory.mktemp("log"), metadata={logmeta.RECORD_NAME: record})
    out = tmp_path_factory.mktemp("out")
    model = SqueakModel()
    result = replay(
        bag,
        model,
        out,
        ReplaySettings(InputSettings(joint_name=cycle.joint_name), workers=0, progress=False),
    )
    pngs = write_report(result, model, out, QUICK)
    return result, record, pngs


def test_annotated_log_holds_the_review_as_attachments(reviewed):
    result, _, pngs = reviewed
    expected = [result.out_dir / "episodes.json", result.out_dir / "summary.json", *pngs]
    with open(result.annotated, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        attachments = list(reader.iter_attachments())
    assert [a.name for a in attachments] == [p.name for p in expected]
    for a, path in zip(attachments, expected, strict=True):
        assert a.data == path.read_bytes(), a.name  # the same bytes as the files
        assert a.media_type == ("image/png" if path.suffix == ".png" else "application/json")
        assert a.log_time == result.start_ns + round(result.duration_s * 1e9)
    assert json.loads(attachments[1].data)["episodes"] == result.episode_count
    stats = summary.statistics
    assert (stats.attachment_count, stats.metadata_count) == (len(expected), 2)
    assert [i.name for i in summary.attachment_indexes] == [p.name for p in expected]
    # every record and CRC of the file, read as a stream: attachments sit before the summary
    with open(result.annotated, "rb") as f:
        kinds = [type(r).__name__ for r in StreamReader(f, validate_crcs=True).records]
    data_end = kinds.index("DataEnd")
    assert kinds.count("Attachment") == len(expected)
    assert (
        max(i for i, k in enumerate(kinds) if k in ("Chunk", "Attachment", "Metadata"))
        < data_end
        < kinds.index("AttachmentIndex")
    )


def test_annotated_log_carries_the_input_record_and_the_replays_own(reviewed):
    result, record, _ = reviewed
    path = result.annotated
    assert logmeta.read_record(path) == record  # copied as it is
    own = logmeta.read(path, logmeta.REPLAY_RECORD_NAME)
    model = SqueakModel()
    assert own.params == model.params.as_dict() and own.version == __version__
    assert own.scatter == {**model.scatter.sd, "samples": model.sample_count}
    assert (own.unit_id, own.hardware_id) == ("seat-9", "hw-9")
    assert own.node["joint_name"] == DutyCycle.joint_name
    assert own.node["speed_deadband_rad_s"] == InputSettings.speed_deadband_rad_s
    assert (own.node["log"], own.node["namespace"], own.node["out_namespace"]) == (
        str(result.log),
        result.namespace,
        result.out_namespace,
    )


def test_annotated_log_still_reads_with_every_message(reviewed):
    result, _, _ = reviewed
    counts = mcap_counts([result.annotated])
    assert sum(counts.values()) == result.messages + 5 * result.predictions
    assert rosbags_counts(result.annotated) == counts


def test_replay_command_of_a_log_without_record(tmp_path):
    """`replay --no-report`: the JSON outputs attached, only the replay's own record."""
    bag = write_log(DutyCycle(duration_s=3.0, rate_hz=10.0, rest_s=0.5), tmp_path / "log")
    out = tmp_path / "out"
    assert (
        main(
            [
                "replay",
                str(bag),
                "--out",
                str(out),
                "--joint-name",
                DutyCycle.joint_name,
                "--workers",
                "0",
                "--no-report",
                "--quiet",
            ]
        )
        == 0
    )
    (annotated,) = out.glob("*.annotated.mcap")
    with open(annotated, "rb") as f:
        attachments = {a.name: a.data for a in make_reader(f).iter_attachments()}
    assert attachments == {
        name: (out / name).read_bytes() for name in ("episodes.json", "summary.json")
    }
    assert [name for name, _ in records(annotated)] == [logmeta.REPLAY_RECORD_NAME]
    assert logmeta.read(annotated, logmeta.REPLAY_RECORD_NAME).unit_id == ""


def test_reopen_refuses_a_file_it_did_not_finish(tmp_path):
    path = tmp_path / "cut.mcap"
    stream = io.BytesIO()
    out = McapOut(stream, "ros2", "test")
    out.finish()
    path.write_bytes(stream.getvalue()[:-20])  # cut off: no footer
    with open(path, "r+b") as f, pytest.raises(ValueError, match="not an MCAP file finished"):
        McapOut.reopen(f)


# ----------------------------------------------------------------------------- Foxglove
def _panels(node) -> list[str]:
    return [node] if isinstance(node, str) else _panels(node["first"]) + _panels(node["second"])


def test_foxglove_layout_names_only_the_nodes_topics():
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    assert sorted(_panels(layout["layout"])) == sorted(panels)  # every panel placed once
    types = {p.split("!")[0] for p in panels}
    assert {"Plot", "Indicator", "DiagnosticSummary"} <= types
    classes = {f"/{t}": c for t, c in {**OUTPUT_CLASSES, **INPUTS}.items()}
    paths = [p["value"] for c in panels.values() for p in c.get("paths", [])] + [
        c["path"] for c in panels.values() if "path" in c
    ]
    topics = {c["topicToRender"] for c in panels.values() if "topicToRender" in c}
    assert topics == {"/diagnostics"}
    for path in paths:  # '/topic.field[index]': a field of the topic's type
        topic, field = re.fullmatch(r"(/[\w/]+)\.(\w+)(\[\d+\])?", path).groups()[:2]
        assert topic in classes, path
        assert field in classes[topic].get_fields_and_field_types(), path
    shown = {re.match(r"[^.]+", p).group() for p in paths}
    assert {f"/{RISK}", "/squeak/active", "/squeak/unstable_frequencies", "/motor_speed"} <= shown
    assert set(OUTPUT_TYPES) >= {t[1:] for t in shown if t.startswith("/squeak/")}
