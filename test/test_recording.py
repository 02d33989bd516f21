# SPDX-License-Identifier: Apache-2.0
"""MCAP recording by the squeak_predictor node: round trip through three independent readers,
the ~/record service, splitting, compression, record directories (created, or the set
rejected), completeness under load and loss counting, sim time, cut-off bags reported on start,
and crash safety (SIGKILL/SIGTERM of a node process). Uses the launch-free world of
harness.squeak (the `ros` fixture) and harness.recording."""

from __future__ import annotations

import array
import dataclasses
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from std_srvs.srv import SetBool

from harness.cdr_reference import cdr_payload
from harness.recording import answering_node
from harness.ros import COLLECT
from harness.squeak import LOAD, SQUEAK, STABLE, SqueakWorld, at, recording_status
from leadscrew_ros.bag import cdr, msgdefs
from leadscrew_ros.bag.logfile import LogError, inspect, is_complete, log_files, read_log, recover
from leadscrew_ros.bag.messages import OUTPUT_TYPES, RISK
from leadscrew_ros.bag.recorder import (
    LOST_BY_TOPIC_KEY,
    LOST_KEY,
    Recorder,
    RecordSettings,
    TopicLoss,
)
from leadscrew_ros.live.status import Level
from leadscrew_ros.ros.diagnostics import KEY_MESSAGES, key_dds_rejected_on
from leadscrew_ros.ros.node import OUTPUT_CLASSES

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def plain(value):
    """A message (rclpy, mcap_ros2 or rosbags object) as nested Python lists/dicts/scalars."""
    if isinstance(value, (bytes, bytearray)) and len(value) == 1:
        return value[0]  # rclpy 'byte' fields
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        return [plain(v) for v in value]
    if isinstance(value, (np.generic,)):
        return value.item()
    fields = getattr(value, "get_fields_and_field_types", None)
    if fields is not None:  # rclpy
        names = list(fields())
    elif dataclasses.is_dataclass(value):  # rosbags, mcap_ros2
        names = [
            f.name
            for f in dataclasses.fields(value)  # not __msgtype__, constants
            if not f.name.startswith("_") and not f.name.isupper()
        ]
    else:
        names = [n for n in getattr(value, "__slots__", ()) if not n.startswith("_")]
    if names:
        return {n: plain(getattr(value, n)) for n in names}
    return value


def spy_publications(node) -> list[tuple[str, bytes, int | None]]:
    """Every (topic, CDR payload, publish time or None) the node publishes from now on."""
    published, publish = [], node._publish

    def spy(pub, data: bytes, publish_time_ns: int | None = None) -> None:
        published.append((pub.topic_name, data, publish_time_ns))
        publish(pub, data, publish_time_ns)

    node._publish = spy
    return published


def joint_state(angle: float, speed: float) -> JointState:
    js = JointState(name=["screw"], position=[angle], velocity=[speed])
    js.header.stamp.sec, js.header.stamp.nanosec = 1_700_000_000, 123_456_789
    return js


def drive(ros: SqueakWorld, node) -> list[tuple[str, object]]:
    """Inputs on all four topics through the squeak band and out; waits for each answer."""
    sent = []
    for speed, nut in ((5.0, 0.10), (SQUEAK, 0.12), (40.0, 0.12), (100.0, 0.14)):
        for topic, msg in (
            ("nut_position", Float64(data=nut)),
            ("axial_load", Float64(data=LOAD)),
            ("motor_speed", Float64(data=speed)),
        ):
            ros.publisher(topic).publish(msg)
            sent.append((f"{ros.ns}/{topic}", msg))
        ros.spin_until(lambda s=speed: node.live.inputs.speed_rad_s == s, what="the speed")
        ros.spin_until(lambda: not node.live.changed(), what="the recompute")
    js = joint_state(1.5, 30.0)
    ros.publisher("joint_states").publish(js)
    sent.append((f"{ros.ns}/joint_states", js))
    ros.spin_until(lambda: node.live.inputs.speed_rad_s == 30.0, what="joint_states")
    ros.drain()
    return sent


def test_round_trip_through_mcap_mcap_ros2_and_rosbags(ros, tmp_path):
    node = ros.start(**{"record.directory": str(tmp_path), "joint_name": "screw"})
    # a new bag starts with these (/diagnostics)
    latched = [(t, m.data, m.publish_time_ns) for t, m in node.latched.items()]
    assert [t for t, *_ in latched] == ["/diagnostics"]
    published = spy_publications(node)
    classes = {
        p.topic_name: p.msg_type for p in [*node.output_pubs.values(), node.diagnostics.publisher]
    }
    assert node.set_parameters([Parameter("record.enabled", value=True)])[0].successful
    sent = drive(ros, node)
    bag = node.recorder.bag
    ros.remove(node)  # closes the file cleanly
    ros.node = None
    outputs = latched + published  # (topic, bytes, publish time)
    expected = [(t, deserialize_message(d, classes[t])) for t, d, _ in outputs] + sent
    inputs = {t for t, _ in sent}
    assert {t for t, *_ in published} >= {
        f"{ros.ns}/squeak/risk",
        f"{ros.ns}/squeak/modes",
        f"{ros.ns}/squeak/unstable_frequencies",
        f"{ros.ns}/squeak/active",
        "/diagnostics",
    }
    files = log_files(bag)
    assert len(files) == 1 and is_complete(files[0])
    assert (bag / "metadata.yaml").is_file()

    # 1. the mcap library's indexed reader: layout as rosbag2 writes it
    by_topic: dict[str, list] = {}
    with open(files[0], "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary.statistics.message_count == len(expected)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert schema.data.decode() == msgdefs.definition(schema.name)
            by_topic.setdefault(channel.topic, []).append((schema.name, message))
    for topic in {t for t, _ in expected}:
        want = [m for t, m in expected if t == topic]
        got = by_topic[topic]
        assert [deserialize_message(m.data, type(want[0])) for _, m in got] == want, topic
        assert all(name == msgdefs.type_name(want[0]) for name, _ in got)
        times = [m.log_time for _, m in got]
        assert times == sorted(times)
        if topic in inputs:  # as rosbag2: the publisher's send time (same clock)
            assert all(0 <= m.log_time - m.publish_time < 2e9 for _, m in got)
            continue
        sent_out = [(d, pt) for t, d, pt in outputs if t == topic]
        assert [m.data for _, m in got] == [d for d, _ in sent_out], topic  # the same bytes
        for (_, m), w, (_, pt) in zip(got, want, sent_out, strict=True):
            stamp = getattr(getattr(w, "header", None), "stamp", None)  # outputs: header stamp
            assert pt == (None if stamp is None else stamp.sec * 10**9 + stamp.nanosec)
            assert m.publish_time == (m.log_time if pt is None else pt)

    # 2. mcap-ros2-support's dynamic decoder (from the schema text alone)
    decoded: dict[str, list] = {}
    with open(files[0], "rb") as f:
        for _, channel, _, msg in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            decoded.setdefault(channel.topic, []).append(plain(msg))
    for topic in decoded:
        want = [plain(m) for t, m in expected if t == topic]
        assert len(decoded[topic]) == len(want)
        for got, w in zip(decoded[topic], want, strict=True):
            assert got == w, (topic, got, w)

    # 3. rosbags, independent of both, reading the bag directory (metadata.yaml)
    from_rosbags: dict[str, list] = {}
    with RosbagsReader(bag) as reader:
        assert reader.message_count == len(expected)
        for conn, _, raw in reader.messages():
            from_rosbags.setdefault(conn.topic, []).append(
                plain(TYPESTORE.deserialize_cdr(raw, conn.msgtype))
            )
    assert set(from_rosbags) == {t for t, _ in expected}
    for topic in from_rosbags:
        assert from_rosbags[topic] == [plain(m) for t, m in expected if t == topic], topic


def test_recorded_outputs_are_the_bytes_a_raw_subscriber_receives(ros, tmp_path):
    received: dict[str, list[bytes]] = {t: [] for t in OUTPUT_TYPES}
    for topic in received:  # subscribed before the node exists: every message
        ros.probe.create_subscription(
            OUTPUT_CLASSES[topic], topic, received[topic].append, COLLECT, raw=True
        )
    node = ros.start(**{"record.enabled": True, "record.directory": str(tmp_path)})
    at(ros, SQUEAK)
    at(ros, STABLE)
    names = {t: f"{ros.ns}/{t}" for t in received}
    ros.spin_until(
        lambda: all(len(received[t]) == node.recorder.count(names[t]) for t in received),
        what="every recorded output",
    )
    bag = node.recorder.bag
    ros.remove(node)
    ros.node = None
    recorded = {t: [m.data for m in read_log(bag) if m.topic.name == names[t]] for t in received}
    assert len(recorded[RISK]) >= 2 and all(recorded.values()), recorded
    assert recorded == received


def test_message_definitions_come_from_the_installed_packages_with_every_dependency():
    text = msgdefs.definition("diagnostic_msgs/msg/DiagnosticArray")
    root, *deps = text.split(msgdefs.DELIMITER + "\n")
    assert root.rstrip("\n") == msgdefs.msg_text("diagnostic_msgs/msg/DiagnosticArray").rstrip()
    # depth first in field order, each once, as rosbag2 writes them
    assert [d.splitlines()[0] for d in deps] == [
        "MSG: std_msgs/msg/Header",
        "MSG: builtin_interfaces/msg/Time",
        "MSG: diagnostic_msgs/msg/DiagnosticStatus",
        "MSG: diagnostic_msgs/msg/KeyValue",
    ]
    for d in deps:
        name = d.splitlines()[0].removeprefix("MSG: ")
        assert d.split("\n", 1)[1].rstrip() == msgdefs.msg_text(name).rstrip()
    assert msgdefs.definition("std_msgs/msg/Float64") == msgdefs.msg_text("std_msgs/Float64")
    with pytest.raises(msgdefs.MessageDefinitionError):
        msgdefs.definition("no_such_pkg/msg/Nothing")


names = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)
floats = st.lists(st.floats(allow_nan=False), max_size=4)


@st.composite
def messages(draw):
    """Messages whose serialized length varies in every way alignment can care about."""
    kind = draw(st.sampled_from(["joint_state", "multi_array", "diagnostics"]))
    if kind == "joint_state":
        msg = JointState(
            name=draw(st.lists(names, max_size=3)),
            position=draw(floats),
            velocity=draw(floats),
            effort=draw(floats),
        )
        msg.header.frame_id = draw(names)
        return msg
    if kind == "multi_array":
        dims = [
            MultiArrayDimension(label=draw(names), size=draw(st.integers(0, 2**32 - 1)), stride=0)
            for _ in range(draw(st.integers(0, 2)))
        ]
        return Float64MultiArray(
            layout=MultiArrayLayout(dim=dims, data_offset=draw(st.integers(0, 2**32 - 1))),
            data=draw(floats),
        )
    return DiagnosticArray(
        status=[
            DiagnosticStatus(
                level=bytes([draw(st.integers(0, 3))]),
                name=draw(names),
                message=draw(names),
                values=[
                    KeyValue(key=draw(names), value=draw(names))
                    for _ in range(draw(st.integers(0, 2)))
                ],
            )
            for _ in range(draw(st.integers(0, 2)))
        ]
    )


@settings(max_examples=300, deadline=None)
@given(messages())
def test_cdr_payload_is_what_rclpy_and_rosbags_read(msg):
    """Fast CDR leaves padding uninitialised and up to 4 bytes of it after empty sequences;
    the recorder zeroes it and cuts the payload at the end of the data, which both readers
    take as the same message."""
    data = cdr_payload(msg)
    assert len(data) <= len(serialize_message(msg))
    assert data == cdr_payload(deserialize_message(data, type(msg)))  # deterministic
    assert deserialize_message(data, type(msg)) == msg
    assert plain(TYPESTORE.deserialize_cdr(data, msgdefs.type_name(msg))) == plain(msg)


def test_record_service_starts_and_stops_and_the_parameter_follows(ros, tmp_path):
    node = ros.start(**{"record.directory": str(tmp_path)})
    client = ros.probe.create_client(SetBool, f"{ros.ns}/squeak_predictor/record")
    ros.spin_until(client.service_is_ready, 5.0, "the ~/record service")

    def call(on: bool) -> SetBool.Response:
        future = client.call_async(SetBool.Request(data=on))
        ros.spin_until(future.done, 5.0, "the service response")
        return future.result()

    bags = []
    for _ in range(2):
        r = call(True)
        assert r.success and r.message.endswith(".mcap"), r.message
        assert node.get_parameter("record.enabled").value is True
        at(ros, SQUEAK)
        bags.append(node.recorder.bag)
        r = call(False)
        assert r.success and str(bags[-1]) in r.message
        assert node.get_parameter("record.enabled").value is False
    assert bags[0] != bags[1]
    for bag in bags:
        info = inspect(log_files(bag)[0])
        assert info.complete and info.counts[f"{ros.ns}/squeak/risk"] >= 1


def test_recording_splits_by_duration_and_by_size(ros, tmp_path):
    for split, value in (("record.split_duration_s", 0.3), ("record.split_size_mb", 0.004)):
        directory = tmp_path / split
        directory.mkdir()
        node = ros.start(
            **{
                "record.enabled": True,
                "record.directory": str(directory),
                "record.flush_period_s": 0.05,
                "record.compression": "none",
                split: value,
            }
        )
        end, i = time.monotonic() + 1.2, 0
        while time.monotonic() < end:
            ros.publisher("motor_speed").publish(Float64(data=10.0 + i % 20))
            ros.publisher("axial_load").publish(Float64(data=LOAD))
            # 5 ms of spinning per input pair: the node's EventsExecutor handles one event per
            # spin_once, in arrival order (timers have no priority), so a probe that sent
            # faster than the node handles would leave the housekeeping timer (which splits)
            # ever further behind
            pause = time.monotonic() + 0.005
            while (left := pause - time.monotonic()) > 0:
                ros.executor.spin_once(timeout_sec=left)
            i += 1
        bag = node.recorder.bag
        ros.remove(node)
        ros.node = None
        files = log_files(bag)
        assert len(files) >= 3, (split, files)
        assert all(is_complete(f) for f in files)
        assert [f.name for f in files] == [f"{bag.name}_{k}.mcap" for k in range(len(files))]
        messages = list(read_log(bag))
        times = [m.log_time_ns for m in messages]
        assert times == sorted(times)  # split files continue in order
        speeds = [m for m in messages if m.topic.name.endswith("/motor_speed")]
        assert len(speeds) == sum(inspect(f).counts[speeds[0].topic.name] for f in files)
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["relative_file_paths"] == [f.name for f in files]
        assert meta["message_count"] == len(messages)
        for f in files[:-1]:  # split at the first check past the limit
            if split == "record.split_size_mb":
                assert f.stat().st_size >= value * 1e6
            else:
                info = inspect(f)
                assert (info.end_ns - info.start_ns) / 1e9 <= value + 0.1


@pytest.mark.parametrize("compression, chunk", [("zstd", "zstd"), ("lz4", "lz4"), ("none", "")])
def test_compression_setting_reaches_the_chunks(tmp_path, compression, chunk):
    rec = Recorder(RecordSettings(directory=str(tmp_path), compression=compression))
    assert rec.start(time.time_ns())
    for i in range(200):
        rec.write_serialized(
            "/motor_speed", cdr.FLOAT64, cdr.encode_float64(float(i)), time.time_ns()
        )
    rec.stop()
    with open(log_files(rec.bag)[0], "rb") as f:
        indexes = make_reader(f).get_summary().chunk_indexes
    assert indexes and {c.compression for c in indexes} == {chunk}


@settings(max_examples=200, deadline=None)
@given(
    size=st.floats(),
    duration=st.floats(),
    flush=st.floats(),
    compression=st.sampled_from(["zstd", "lz4", "none", "gzip", "", "ZSTD"]),
)
def test_record_settings_accept_exactly_the_valid_values(size, duration, flush, compression):
    def within(name, value):  # the range in the field metadata, closed at both ends
        md = RecordSettings.__dataclass_fields__[name].metadata
        return md["lo"] <= value <= md["hi"]

    valid = (
        within("split_size_mb", size)
        and within("split_duration_s", duration)
        and within("flush_period_s", flush)
        and compression in ("zstd", "lz4", "none")
    )
    try:
        RecordSettings(
            split_size_mb=size,
            split_duration_s=duration,
            flush_period_s=flush,
            compression=compression,
        )
    except ValueError as exc:
        assert not valid, exc
    else:
        assert valid


@pytest.mark.parametrize(
    "name, value, words",
    [
        ("record.compression", "gzip", ["compression", "zstd"]),
        ("record.split_size_mb", -1.0, ["record.split_size_mb"]),
        ("record.flush_period_s", 0.0, ["record.flush_period_s"]),
        ("record.directory", "", ["directory"]),
    ],
)
def test_invalid_record_parameters_are_rejected(ros, name, value, words):
    node = ros.start()
    result = node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful
    assert all(w in result.reason for w in words), result.reason
    assert node.get_parameter(name).value != value


def test_a_missing_record_directory_is_created(ros, tmp_path):
    """Like `ros2 bag record -o`: mkdir -p, at start-up and when enabled later."""
    missing = tmp_path / "no" / "such" / "dir"
    node = ros.start(**{"record.enabled": True, "record.directory": str(missing)})
    assert node.recorder.active and node.recorder.bag.parent == missing
    status = recording_status(ros, lambda s: s.message.startswith("recording to"))
    assert status.level == b"\x00"
    later = tmp_path / "later" / "bags"
    assert node.set_parameters([Parameter("record.directory", value=str(later))])[0].successful
    assert node.recorder.active and node.recorder.bag.parent == later


def unusable_directories(tmp_path: Path) -> dict[str, Path]:
    """Directories no recording can use, and why."""
    plain = tmp_path / "plain_file"
    plain.write_text("not a directory")
    return {
        "proc": Path("/proc/leadscrew_bags"),
        "proc itself": Path("/proc"),
        "under a plain file": plain / "bags",
        "a plain file": plain,
        # root ignores file modes; the kernel's sysfs refuses anyone
        "read-only": Path("/sys/kernel") if os.geteuid() == 0 else Path("/"),
    }


def test_enabling_a_recording_that_cannot_start_is_rejected_with_the_reason(ros, tmp_path):
    good = tmp_path / "good"
    node = ros.start(**{"record.directory": str(good)})
    client = ros.probe.create_client(SetBool, f"{ros.ns}/squeak_predictor/record")
    ros.spin_until(client.service_is_ready, 5.0, "the ~/record service")
    for what, bad in unusable_directories(tmp_path).items():
        # enabling with a bad directory: the whole set is rejected, nothing records
        result = node.set_parameters_atomically(
            [Parameter("record.directory", value=str(bad)), Parameter("record.enabled", value=True)]
        )
        assert not result.successful, what
        assert str(bad) in result.reason and "cannot record" in result.reason, (what, result)
        assert node.get_parameter("record.enabled").value is False, what
        assert node.get_parameter("record.directory").value == str(good)
        assert not node.recorder.active
        # a bad directory while not recording is just a setting; the service then refuses
        assert node.set_parameters([Parameter("record.directory", value=str(bad))])[0].successful
        future = client.call_async(SetBool.Request(data=True))
        ros.spin_until(future.done, 5.0, "the service response")
        assert not future.result().success and str(bad) in future.result().message, what
        assert node.get_parameter("record.enabled").value is False, what
        # recording: moving it to a bad directory is rejected, the bag goes on
        assert node.set_parameters([Parameter("record.directory", value=str(good))])[0].successful
        assert node.set_parameters([Parameter("record.enabled", value=True)])[0].successful
        bag = node.recorder.bag
        result = node.set_parameters([Parameter("record.directory", value=str(bad))])[0]
        assert not result.successful and str(bad) in result.reason, what
        assert node.recorder.active and node.recorder.bag == bag
        assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
    at(ros, SQUEAK)  # still predicting


def test_start_up_with_an_unusable_directory_is_an_error_and_the_parameter_reads_false(
    ros, tmp_path
):
    bad = unusable_directories(tmp_path)["under a plain file"]
    node = ros.start(**{"record.enabled": True, "record.directory": str(bad)})
    status = recording_status(ros, lambda s: s.level == b"\x02")
    assert str(bad) in status.message and "Not a directory" in status.message, status.message
    assert node.get_parameter("record.enabled").value is False
    assert not node.recorder.active
    assert "recording" not in ros.latest["/diagnostics"].status[0].message  # prediction status
    at(ros, SQUEAK)  # still predicting


# ----------------------------------------------------------------------------- processes
def test_sigkill_loses_at_most_one_second_and_the_file_is_recoverable(tmp_path, ns):
    """What the node had recorded 1 s before the kill (flush period 0.5 s, plus a
    housekeeping tick and margin) is in the cut-off file: judged by the message counts of its
    own recording diagnostics, so that a busy machine, where inputs still in flight or a
    starved process shift the wall clock, cannot fail it."""
    margin_ns = 1_000_000_000

    def counted_before(t_ns: int) -> list[int]:
        return [
            int(next(kv.value for kv in s.values if kv.key == KEY_MESSAGES))
            for s, stamp in zip(feed.recording, feed.recording_stamps_ns, strict=True)
            if stamp <= t_ns
        ]

    with answering_node(tmp_path, ns) as (proc, directory, feed):
        feed.run(2.0)  # 2 s of 200 Hz speed + load
        deadline = time.monotonic() + 30
        while not any(counted_before(time.time_ns() - margin_ns)):
            assert time.monotonic() < deadline, "no recording status from the node"
            feed.run(0.1)
        killed_ns = time.time_ns()
        proc.kill()
        proc.wait(timeout=10)
    must_have = max(counted_before(killed_ns - margin_ns))
    files = log_files(next(directory.iterdir()))
    assert len(files) == 1 and not is_complete(files[0])
    with pytest.raises(LogError, match="recover"):
        list(read_log(files[0]))
    info = inspect(files[0])
    speed_topic = f"{ns}/motor_speed"
    assert info.counts[speed_topic] > 0
    loss_s = (killed_ns - info.end_ns) / 1e9
    print(
        f"SIGKILL: {info.messages} messages readable ({must_have} recorded 1 s before), last "
        f"one {loss_s:.3f} s before the kill ({info.damage or 'no damage'})"
    )
    assert must_have <= info.messages
    fixed = tmp_path / "recovered.mcap"
    recovered = recover(files[0], fixed)
    assert recovered.messages == info.messages and is_complete(fixed)
    with open(fixed, "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == info.messages
    with RosbagsReader(fixed) as reader:
        assert reader.message_count == info.messages


def test_sigterm_closes_the_file_with_summary_and_index(tmp_path, ns):
    with answering_node(tmp_path, ns) as (proc, directory, feed):
        feed.run(0.5)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    bag = next(directory.iterdir())
    files = log_files(bag)
    assert len(files) == 1 and is_complete(files[0])
    with open(files[0], "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == inspect(files[0]).messages > 100
    assert summary.chunk_indexes
    assert (bag / "metadata.yaml").is_file()


def test_disk_full_stops_the_recording_with_an_error_and_predictions_continue(tmp_path, ns):
    """RLIMIT_FSIZE makes every write beyond 3 MB fail with EFBIG, as a full disk would."""
    limit = 3_000_000

    def small_disk():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    with answering_node(
        tmp_path,
        ns,
        ["-p", "record.compression:=none", "-p", "record.flush_period_s:=0.1"],
        preexec_fn=small_disk,
    ) as (proc, directory, feed):
        deadline = time.monotonic() + 20
        while not any(s.level == b"\x02" for s in feed.recording):
            assert time.monotonic() < deadline, "no recording error while the disk filled up"
            feed.run(0.1, joints=200)  # ~8 kB per joint_states message
        error = next(s for s in feed.recording if s.level == b"\x02")
        assert str(directory) in error.message and "File too large" in error.message, error.message
        before = len(feed.risk)
        feed.run(0.5)
        assert len(feed.risk) > before  # still predicting
        assert proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    bag = next(directory.iterdir())
    info = inspect(log_files(bag)[0])  # what was written before stays readable
    assert info.messages > 0


# ----------------------------------------------------------------------------- completeness
BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_recording.py"


def bench_recording(tmp_path: Path, *args: str) -> dict:
    """benchmarks/bench_recording.py for 3 s (node and publisher processes): its raw numbers."""
    out = tmp_path / f"bench{len(list(tmp_path.glob('bench*')))}.json"
    proc = subprocess.run(
        [
            sys.executable,
            str(BENCH),
            "--seconds",
            "3",
            "--conditions",
            "quiet",
            "--json",
            str(out),
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=240,
        env=dict(os.environ),
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    print(proc.stdout)
    return json.loads(out.read_text())["new:quiet"]


def test_three_inputs_at_1_khz_from_another_process_are_all_recorded_or_counted(tmp_path):
    """3 topics x 1 kHz x 3 s into a recording node process: what the bag holds plus what the
    node counted as lost is exactly what was sent, per topic; and the deep recording queue
    on its own thread keeps (measured 100 %, also with the other core busy; the old code in
    the model's executor: 44 %) nearly everything even on a loaded machine."""
    r = bench_recording(tmp_path)
    for topic, t in r["topics"].items():
        assert t["recorded"] + t["lost"] == t["sent"], (topic, t)
        assert t["duplicates"] == 0
    assert r["sent"] >= 3 * 3000
    assert r["completeness"] >= 0.99, r


def test_messages_lost_to_a_stopped_node_are_counted_exactly(tmp_path):
    """A node process stopped (SIGSTOP) for 0.5 s mid-burst with a 10-deep recording queue
    certainly loses messages: each is counted."""
    r = bench_recording(tmp_path, "--queue-depth", "10", "--pause-s", "0.5")
    assert r["lost"] >= 1000, r
    for topic, t in r["topics"].items():
        assert t["recorded"] + t["lost"] == t["sent"], (topic, t)


def test_topic_loss_counts_sequence_gaps_of_one_publisher():
    loss = TopicLoss()
    for seq in (1, 2, 3, 7, 8, 20):  # 4..6 and 9..19 missing
        loss.received(seq, lambda: 1)
    assert loss.sequence_gaps == 14 and loss.lost == 14
    loss.received(1, lambda: 1)  # a new publisher starts at 1: nothing lost
    loss.received(2, lambda: 1)
    assert loss.lost == 14
    assert (loss.numbered, loss.taken) == (20 + 2, 8)
    assert loss.dds_event(12, 12) == ""  # DDS events are a subset of the gaps
    assert loss.dds_lost == 12 and loss.lost == 14
    several = TopicLoss()
    for seq in (1, 1, 2, 2, 5):  # two publishers interleave: no gap counting
        several.received(seq, lambda: 2)
    assert several.dds_event(3, 3) == ""
    assert not several.sequence_checked and several.lost == 3
    assert TopicLoss().as_dict() == {
        "lost": 0,
        "sequence_gaps": 0,
        "dds_lost": 0,
        "dds_rejected": "",
        "sequence_checked": True,
    }


class LostInfo:
    """What rclpy hands a message-lost callback (QoSMessageLostInfo): two counts."""

    def __init__(self, total_count, total_count_change):
        self.total_count, self.total_count_change = total_count, total_count_change


WRAPPED = 2**64 - 2**31  # the count of the hostile trial (issue 29): int32 -2**31 as size_t
# 13 of 40 numbered messages lost (9..15, 30..35), as the trial lost 11-15
GAPPY = [*range(1, 9), *range(16, 30), *range(36, 41)]
# event (total_count, total_count_change) -> what it is: a count or why not
FAKE_EVENTS = {
    "wrapped": ((WRAPPED, WRAPPED), "beyond DDS's 32-bit count"),
    "negative": ((-5, -5), "negative"),
    "more than the publisher sent": ((30, 30), "more than the publisher could have lost"),
    "not integers": ((2.5, 2.5), "not integers"),
    "change above total": ((4, 7), "the change is larger than the total"),
    "valid": ((13, 13), ""),
}


@pytest.mark.parametrize("name", FAKE_EVENTS)
def test_a_dds_lost_count_is_taken_only_when_it_is_one(name):
    """Issue 29: a DDS message-lost event said 2**64 - 2**31 while 13 were lost; the larger of
    the two counts was reported. A count that is none is said once and ignored for good (the
    DDS total is cumulative), the sequence gaps count."""
    (total, change), fault = FAKE_EVENTS[name]
    loss = TopicLoss()
    for seq in GAPPY:
        loss.received(seq, lambda: 1)
    assert loss.sequence_gaps == 13
    assert loss.dds_event(total, change) == loss.dds_rejected
    assert (fault in loss.dds_rejected) if fault else loss.dds_rejected == ""
    assert loss.lost == 13
    assert loss.as_dict()["dds_rejected"] == loss.dds_rejected
    if fault:
        assert str(total) in loss.dds_rejected and "sequence numbers" in loss.dds_rejected
        assert loss.dds_event(13, 0) == ""  # said once; later totals build on the bad one
        assert loss.dds_lost == 0 and loss.lost == 13
    else:
        assert loss.dds_lost == 13


def test_a_dds_count_that_shrinks_is_rejected_and_the_last_valid_one_stays_without_numbers():
    """Several publishers (no gap counting): the DDS total is the count; one below an earlier
    total, or wrapped, is rejected and the last valid total stays the count."""
    several = TopicLoss()
    for seq in (1, 1, 2, 2, 6):
        several.received(seq, lambda: 2)
    assert several.dds_event(4, 4) == "" and several.lost == 4
    reason = several.dds_event(3, 0)
    assert "below the earlier total 4" in reason and "last valid DDS total (4)" in reason
    assert several.dds_event(WRAPPED, WRAPPED) == ""  # said once
    assert several.lost == 4


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.integers(1, 60), max_size=40),
    st.lists(st.tuples(st.integers(-(2**65), 2**65), st.integers(-(2**65), 2**65)), max_size=6),
)
def test_no_dds_event_makes_the_count_more_than_the_publisher_could_have_lost(numbers, events):
    """Whatever a single publisher's numbers and the events say, the loss count is in
    [gaps, messages numbered - messages taken], and a rejection is said at most once."""
    loss = TopicLoss()
    said = 0
    for i in range(max(len(numbers), len(events))):
        if i < len(events):  # an event before the i-th message: the first before any
            said += bool(loss.dds_event(*events[i]))
        if i < len(numbers):
            loss.received(numbers[i], lambda: 1)
    assert said <= 1
    assert loss.sequence_gaps <= loss.lost <= max(loss.numbered - loss.taken, loss.sequence_gaps)
    assert 0 <= loss.dds_lost < 2**31


class _WarnSpy:
    """A node logger that also keeps what was logged at WARN."""

    def __init__(self, logger):
        self._logger, self.warnings = logger, []

    def warning(self, message, **kwargs):
        self.warnings.append(message)
        return self._logger.warning(message, **kwargs)

    def __getattr__(self, name):
        return getattr(self._logger, name)


@pytest.mark.parametrize("event", ["wrapped", "negative", "valid"])
def test_lost_inputs_are_in_the_recording_diagnostic_and_the_metadata(ros, tmp_path, event):
    """While the recorder is busy (its lock held: the recording thread waits) the 5-deep DDS
    queue of the recording subscription overflows; the gap shows at the next message. Then a
    DDS message-lost event (a fake QoSMessageLostInfo given to the recording's callback) that
    is no count (issue 29: 2**64 - 2**31; negative) is logged once and changes nothing; a valid
    one (the gaps seen) is taken. The diagnostic and metadata.yaml count exactly what was sent
    and not recorded."""
    node = ros.start(
        **{"record.enabled": True, "record.directory": str(tmp_path), "record.queue_depth": 5}
    )
    pub = ros.publisher("axial_load")
    ros.spin_until(lambda: pub.get_subscription_count() >= 2, 5.0, "the recording reader")
    recorded = lambda: node.recorder._topics.get(pub.topic_name)  # noqa: E731
    sent = 0
    while not recorded():  # the recording reader has matched us
        pub.publish(Float64(data=LOAD))
        sent += 1
        ros.spin_until(lambda: True)
        time.sleep(0.01)
    with node.recorder._lock:
        for i in range(300):
            pub.publish(Float64(data=LOAD + 0.001 * i))
        sent += 300
        time.sleep(0.2)
    pub.publish(Float64(data=LOAD))
    sent += 1
    loss = node.recorder.losses[pub.topic_name]
    ros.spin_until(lambda: recorded().count + loss.lost == sent, 5.0, "the loss count")
    assert loss.lost >= 300 - 5 - 1, loss
    missing = sent - recorded().count  # nothing is published from here on
    total = {"wrapped": WRAPPED, "negative": -7, "valid": loss.sequence_gaps}[event]
    recording = node._input_recording
    [entry] = [e for e in recording._inputs if e.topic == pub.topic_name]
    recording._logger = spy = _WarnSpy(recording._logger)
    for _ in range(2):  # the middleware repeats its cumulative count
        recording._dds_lost(entry, LostInfo(total, total))
    assert loss.lost == missing and recorded().count + missing == sent
    rejected = key_dds_rejected_on(pub.topic_name)
    if event == "valid":
        assert spy.warnings == [] and loss.dds_lost == total and not loss.dds_rejected
    else:
        [warning] = spy.warnings
        assert warning.startswith(f"{pub.topic_name}: ") and str(total) in warning
    # the diagnostic is periodic: one published while the gap was still being counted can
    # carry a smaller number, so wait for the one after the count settled
    final = f"{missing} input message(s) lost"
    status = recording_status(
        ros,
        lambda s: (
            s.level == bytes([Level.WARN])
            and final in s.message
            and (event == "valid" or any(kv.key == rejected for kv in s.values))
        ),
        timeout=5.0,
    )
    values = {kv.key: kv.value for kv in status.values}
    assert final in status.message, status.message
    assert f"{pub.topic_name} {missing}" in status.message
    assert values["lost"] == str(missing) and values[f"lost {pub.topic_name}"] == str(missing)
    assert (rejected in values) == (event != "valid")
    if event != "valid":
        assert str(total) in values[rejected] and "sequence numbers" in values[rejected]
    bag = node.recorder.bag
    assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    custom = meta["custom_data"]
    assert custom[LOST_KEY] == str(missing)
    by_topic = json.loads(custom[LOST_BY_TOPIC_KEY])[pub.topic_name]
    assert by_topic["lost"] == missing
    assert (str(total) in by_topic["dds_rejected"]) == (event != "valid")
    [topic] = [
        t
        for t in meta["topics_with_message_count"]
        if t["topic_metadata"]["name"] == pub.topic_name
    ]
    assert topic["message_count"] + missing == sent


# ----------------------------------------------------------------------------- sim time
def test_sim_time_bags_are_named_and_split_by_wall_clock_with_sim_log_times(ros, tmp_path):
    """No /clock yet, a /clock jump and a paused /clock: names by the wall clock (unique), no
    split by the jump, log times in sim time, off/on while paused works."""
    clock = ros.probe.create_publisher(Clock, "/clock", 10)

    def tick(sim_s: float) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = int(sim_s), int(round(sim_s % 1 * 1e9))
        clock.publish(msg)

    node = ros.start(
        use_sim_time=True, **{"record.directory": str(tmp_path), "record.split_duration_s": 30.0}
    )
    year = time.gmtime().tm_year
    assert node.get_clock().now().nanoseconds == 0  # no /clock yet
    assert node.set_parameters([Parameter("record.enabled", value=True)])[0].successful
    first = node.recorder.bag
    assert first.name.startswith(f"{ros.ns[1:]}_squeak_{year}_"), first.name
    ros.spin_until(lambda: clock.get_subscription_count() > 0, 5.0, "the /clock subscriber")
    tick(100.0)
    ros.spin_until(lambda: node.get_clock().now().nanoseconds == 100 * 10**9, 5.0, "sim time")
    at(ros, SQUEAK)
    tick(1_000_000.0)  # jump: 11.6 days of sim time
    ros.spin_until(lambda: node.get_clock().now().nanoseconds == 10**15, 5.0, "the jump")
    at(ros, 40.0)
    ros.drain()
    assert len(node.recorder.files) == 1  # split by wall clock only
    bags = [first]
    for _ in range(3):  # paused clock: off, on, off...
        assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
        assert node.set_parameters([Parameter("record.enabled", value=True)])[0].successful
        assert node.recorder.active, node.recorder.error
        bags.append(node.recorder.bag)
    assert node.set_parameters([Parameter("record.enabled", value=False)])[0].successful
    assert len(set(bags)) == len(bags) and all(
        b.name.startswith(f"{ros.ns[1:]}_squeak_{year}_") for b in bags
    ), bags
    times = [m.log_time_ns for m in read_log(first)]
    assert min(times) == 0 and max(times) == 10**15  # the node's clock, as rosbag2
    assert 100 * 10**9 in times
    for bag in bags[1:]:  # the latched state, at paused time
        assert {m.log_time_ns for m in read_log(bag)} == {10**15}


def test_bag_names_are_unique_within_a_millisecond(tmp_path):
    bags = []
    for _ in range(5):
        rec = Recorder(RecordSettings(directory=str(tmp_path)), name="seat_left_squeak")
        assert rec.start(), rec.error
        rec.stop()
        bags.append(rec.bag)
    assert len(set(bags)) == 5 and all((b / "metadata.yaml").is_file() for b in bags)


# ----------------------------------------------------------------------------- crash
def test_cut_off_bags_of_an_earlier_run_are_reported_on_start_and_auto_recovered(tmp_path, ns):
    """SIGKILL a recording node; the next node in the same namespace and directory reports the
    cut-off bag (WARN, the recover command); with record.auto_recover it recovers it. Another
    namespace's bag in the same directory is left alone."""
    with answering_node(tmp_path, ns) as (proc, directory, feed):
        feed.run(0.5)
        proc.kill()
        proc.wait(timeout=10)
    [cut] = list(directory.iterdir())
    other = directory / "seat_right_squeak_2025_01_01-00_00_00_000"
    other.mkdir()
    (other / f"{other.name}_0.mcap").write_bytes(b"\x89MCAP0\r\n")  # cut off, not ours
    with SqueakWorld(ns=ns) as r:
        node = r.start(**{"record.directory": str(directory)})
        status = recording_status(r, lambda s: s.level == bytes([Level.WARN]))
        assert str(cut) in status.message and "leadscrew-squeak recover BAGDIR" in status.message, (
            status.message
        )
        assert str(other) not in status.message
        values = {kv.key: kv.value for kv in status.values}
        assert values["cut_off_bags"] == str(cut)
        assert not (cut / "metadata.yaml").exists()  # only reported
        r.remove(node)
        node = r.start(**{"record.directory": str(directory), "record.auto_recover": True})
        status = recording_status(r, lambda s: "recovered 1 cut-off bag" in s.message, 20.0)
        assert status.level == bytes([Level.OK]) and str(cut) in status.message
        assert (cut / "metadata.yaml").is_file()
        with RosbagsReader(cut) as reader:
            assert reader.message_count > 0
        assert not (other / "metadata.yaml").exists()
